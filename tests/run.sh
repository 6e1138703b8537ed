#!/usr/bin/env bash
# The README's test command: sets up what the tests need, then runs them all.
#
#   bash tests/run.sh [extra cargo test arguments]
#
# - a virtual environment with the pinned reference packages of
#   tests/requirements.txt (created once in target/test-venv, or $MDTF_VENV;
#   rebuilt when the requirements change), exported as MDTF_PYTHON;
# - Debian's python3-venv when the interpreter cannot make one, dcm2niix (a
#   reference DICOM converter), ParaView's pvbatch with xvfb-run (the export
#   test opens its script in ParaView) and Mesa's EGL (VTK renders offscreen
#   with it), Chromium and its driver (the report test opens report.html in
#   it), as root with apt-get; otherwise the command to run is printed;
# - a real scan from a Debian package (Colin27's T1 MRI, mricron-data) in
#   target/real-data, or $MDTF_REAL_DATA, exported as MDTF_REAL_DATA;
# - cargo test --workspace;
# - the Python package: `pip install ./crates/python` (maturin's PEP 517
#   backend; here the dev profile, which reuses the tests'
#   compiled dependencies and runs the mdtf crates optimised) into that
#   environment, then its pytest tests against the mdtf command.
set -euo pipefail
cd "$(dirname "$0")/.."

say() { printf '== %s\n' "$*" >&2; }
die() { printf 'error: %s\n' "$*" >&2; exit 1; }

command -v cargo >/dev/null || die "cargo is missing: install the Rust toolchain (https://rustup.rs), then run this again"
# need COMMAND WHY PACKAGE...: the Debian packages installed with apt-get as root, else the command to run
need() {
  local cmd=$1 why=$2
  shift 2
  command -v "$cmd" >/dev/null && return 0
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    say "installing $* (apt-get; $why)"
    apt-get update -qq && apt-get install -y -qq "$@" >/dev/null
  else
    die "$cmd is missing ($why): sudo apt-get install $*"
  fi
}
need python3 "the tests' reference packages run in it" python3 python3-venv
need cmake "CharLS, the DICOM JPEG-LS decoder, is built with it" cmake
need dcm2niix "the DICOM tests compare with it" dcm2niix

# what the export tests run: pvbatch (Debian's ParaView) under xvfb-run, and the vtk wheel offscreen through Mesa's EGL
missing=()
command -v pvbatch >/dev/null || missing+=(python3-paraview python3-numpy)
command -v xvfb-run >/dev/null || missing+=(xvfb xauth)
ldconfig -p 2>/dev/null | grep -q libEGL_mesa || missing+=(libegl1 libegl-mesa0 libgl1-mesa-dri)
# what the report test runs: headless Chromium driven through chromedriver
command -v chromium >/dev/null || missing+=(chromium)
command -v chromedriver >/dev/null || missing+=(chromium-driver)
if [ "${#missing[@]}" -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    say "installing ${missing[*]} (apt-get)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    die "${missing[*]} missing (the export tests render with ParaView and VTK, the report test opens its page in Chromium): sudo apt-get install ${missing[*]}"
  fi
fi

venv="${MDTF_VENV:-$PWD/target/test-venv}"
stamp="$venv/.requirements"
if [ ! -x "$venv/bin/python" ] || ! cmp -s tests/requirements.txt "$stamp"; then
  say "python packages for the interop tests ($venv)"
  rm -rf "$venv"
  mkdir -p "$(dirname "$venv")"
  if ! python3 -m venv "$venv" 2>/dev/null; then
    rm -rf "$venv"
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      say "installing python3-venv (apt-get)"
      apt-get update -qq && apt-get install -y -qq python3-venv >/dev/null
      python3 -m venv "$venv"
    else
      die "python3 cannot create a virtual environment: install python3-venv (sudo apt-get install python3-venv)"
    fi
  fi
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r tests/requirements.txt \
    || die "pip could not install tests/requirements.txt into $venv"
  cp tests/requirements.txt "$stamp"
fi
export MDTF_PYTHON="$venv/bin/python"

# a real MRI for the tests of figures, default TFs and the report: Debian's
# mricron-data ships Colin27's T1 (ch2.nii.gz); apt-get download needs no root
real="${MDTF_REAL_DATA:-$PWD/target/real-data}"
if [ ! -f "$real/ch2.nii.gz" ] || [ ! -f "$real/ch2bet.nii.gz" ]; then
  command -v apt-get >/dev/null || die "the real-data tests need ch2.nii.gz (Debian package mricron-data) in $real"
  say "fetching real scans (Debian mricron-data: ch2.nii.gz, ch2bet.nii.gz) into $real"
  tmp="$(mktemp -d)"
  (cd "$tmp" && apt-get download -qq mricron-data 2>/dev/null \
    || { [ "$(id -u)" = 0 ] && apt-get update -qq && apt-get download -qq mricron-data; }) \
    || die "apt-get download mricron-data failed"
  dpkg-deb -x "$tmp"/mricron-data_*.deb "$tmp/x"
  mkdir -p "$real"
  # ch2bet: the same T1 with everything but the brain removed (the second field of a real stack)
  cp "$tmp/x/usr/share/mricron/templates/ch2.nii.gz" "$tmp/x/usr/share/mricron/templates/ch2bet.nii.gz" "$real/"
  cp "$tmp/x/usr/share/doc/mricron-data/copyright" "$real/mricron-data.copyright"
  rm -rf "$tmp"
fi
export MDTF_REAL_DATA="$real"

say "cargo test --workspace"
cargo test --workspace --locked "$@"

say "python package (pip install ./crates/python; pytest crates/python/tests)"
cargo build --locked --quiet -p mdtf-cli --bin mdtf
MATURIN_PEP517_ARGS="--profile dev --locked" "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
  --force-reinstall --no-deps ./crates/python \
  || die "pip could not build and install the Python package (crates/python)"
MDTF_BIN="$PWD/target/debug/mdtf" "$venv/bin/python" -m pytest -q -p no:cacheprovider crates/python/tests
