#!/usr/bin/env bash
# Whole-process read of a 512 x 512 x 300 uncompressed CT series: mdtf
# against SimpleITK's ImageSeriesReader on the same folder, and against mdtf
# reading the same volume as uncompressed NIfTI. Runs alternate (A B A B ...)
# so that drift of the machine falls on both; prints each run and the medians.
#
#   bash tests/bench_dicom_read.sh [RUNS]     (after cargo build --release)
#
# Needs the test venv of tests/run.sh (pydicom, SimpleITK, nibabel).
set -euo pipefail
cd "$(dirname "$0")/.."
runs="${1:-7}"
py="${MDTF_PYTHON:-$PWD/target/test-venv/bin/python}"
mdtf="$PWD/target/release/mdtf"
[ -x "$mdtf" ] || { echo "build first: cargo build --release" >&2; exit 1; }
work="${TMPDIR:-/tmp}/mdtf-bench-dicom"
if [ ! -f "$work/ct.nii" ]; then
  mkdir -p "$work"
  "$py" tests/bench_dicom_series.py "$work/ct"
fi
sitk='import sys, SimpleITK as s; r = s.ImageSeriesReader(); r.SetFileNames(r.GetGDCMSeriesFileNames(sys.argv[1])); r.Execute()'
wall() { local t0 t1; t0=$(date +%s.%N); "$@" >/dev/null 2>&1; t1=$(date +%s.%N); echo "$t1 - $t0" | bc; }
median() { sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
: >"$work/a"; : >"$work/b"; : >"$work/c"
for _ in $(seq "$runs"); do
  wall "$mdtf" info "$work/ct" >>"$work/a"
  wall "$py" -c "$sitk" "$work/ct" >>"$work/b"
  wall "$mdtf" info "$work/ct.nii" >>"$work/c"
done
a=$(median <"$work/a"); b=$(median <"$work/b"); c=$(median <"$work/c")
echo "mdtf info (DICOM series, 300 files):   median $a s  [$(tr '\n' ' ' <"$work/a")]"
echo "SimpleITK ImageSeriesReader:           median $b s  [$(tr '\n' ' ' <"$work/b")]"
echo "mdtf info (the same volume as NIfTI):  median $c s  [$(tr '\n' ' ' <"$work/c")]"
echo "SimpleITK / mdtf: $(echo "scale=2; $b / $a" | bc)x   mdtf DICOM / mdtf NIfTI: $(echo "scale=2; $a / $c" | bc)x"
