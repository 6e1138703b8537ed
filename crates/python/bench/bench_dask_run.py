"""A pipeline run on a dask cluster against the same run in one process:
``mdtf run`` (the command, whole volume or slab by slab as it chooses)
and ``mdtf.dask.run`` on a ``LocalCluster`` of process workers, on one
OME-Zarr store of an erf sphere, with wall time, the peak memory of each
process, the halo overhead of the slabs and whether the outputs are equal.
Run with the package installed as a release build (``pip install
'./crates/python[dask]'``) and a release ``mdtf`` command:

    python crates/python/bench/bench_dask_run.py --mdtf target/release/mdtf [--size 512] [--slab 64]
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import distributed

import mdtf
import mdtf.dask as mdask

REPO = Path(__file__).resolve().parents[3]


def peak_rss_mib() -> float:
    """This process's peak resident memory, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def same_files(a: Path, b: Path) -> bool:
    skip = {"run_report.json", "report.html", ".mdtf-output"}
    files = lambda d: {str(f.relative_to(d)): f.read_bytes() for f in d.rglob("*") if f.is_file() and f.name not in skip}  # noqa: E731
    return files(a) == files(b)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mdtf", type=Path, default=REPO / "target" / "release" / "mdtf")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--slab", type=int, default=64, help="z-planes per task")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--pipeline", default="distance-tf")
    ap.add_argument("--dir", type=Path, default=None, help="where the store and outputs go (default: a temporary folder)")
    args = ap.parse_args()
    work = args.dir or Path(tempfile.mkdtemp(prefix="mdtf-bench-dask-"))
    pipeline = REPO / "pipelines" / f"{args.pipeline}.toml"
    nrrd, store = work / f"sphere{args.size}.nrrd", work / f"sphere{args.size}.ome.zarr"
    if not store.exists():
        subprocess.run([args.mdtf, "synth", "erf-sphere", "--size", str(args.size), "--sigma", "3", "--noise", "2",
                        "--type", "u16", "-o", nrrd, "-q"], check=True)
        subprocess.run([args.mdtf, "convert", nrrd, store, "-q"], check=True)
        nrrd.unlink()
    for out in ("one", "dask"):
        shutil.rmtree(work / out, ignore_errors=True)

    t = time.perf_counter()
    one = subprocess.run(["/usr/bin/time", "-f", "%M", str(args.mdtf), "run", str(pipeline), "--input", str(store),
                          "-o", str(work / "one"), "--set", "preview=false", "-q"], capture_output=True, text=True, check=True)
    one_s = time.perf_counter() - t
    one_mib = int(one.stderr.strip().splitlines()[-1]) / 1024

    cluster = distributed.LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=None)
    with distributed.Client(cluster) as client:
        client.run(lambda: mdtf.set_threads(1))
        t = time.perf_counter()
        report = mdask.run(pipeline, work / "dask", input=store, client=client, slab_planes=args.slab, preview=False)
        dask_s = time.perf_counter() - t
        workers = client.run(peak_rss_mib)
    cluster.close()

    n = args.size
    stages = {s["stage"]: round(s["seconds"], 2) for s in report["stages"]}
    slabs = [(z, min(z + args.slab, n)) for z in range(0, n, args.slab)]
    _, (hz, _, _) = mdtf._mdtf.plan(str(pipeline), str(store), [])
    kz = mdtf._mdtf.kernel_reach((1.0, 1.0, 1.0), None)[0]
    grown = lambda h: sum(min(b + h, n) - max(a - h, 0) for a, b in slabs) / n  # noqa: E731
    result = {
        "size": n,
        "pipeline": args.pipeline,
        "workers": args.workers,
        "slab_planes": args.slab,
        "tasks_per_pass": len(slabs),
        "one_process_s": round(one_s, 2),
        "one_process_peak_mib": round(one_mib),
        "dask_s": round(dask_s, 2),
        "ratio_dask_over_one": round(dask_s / one_s, 3),
        "client_peak_mib": round(peak_rss_mib()),
        "worker_peak_mib": {w: round(m) for w, m in workers.items()},
        "dask_stage_seconds": stages,
        # derive tasks compute their slab grown by the kernel's reach; tracing tasks read theirs
        # grown by d_max plus the support but trace only their own planes
        "derive_halo_planes": kz,
        "derive_computed_over_owned": round(grown(kz), 3),
        "trace_halo_planes": hz,
        "trace_read_over_owned": round(grown(hz), 3),
        "outputs_equal": same_files(work / "one", work / "dask"),
    }
    json.dump(result, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
