"""How a pipeline run on a dask cluster scales: ``mdtf run`` in one process
on one thread, then ``mdtf.dask.run`` on ``LocalCluster``s of 1 and 2
process workers of one thread each, on one OME-Zarr store of a noisy erf
sphere, with the best wall time of ``--reps`` runs, the calling process's CPU
time and the workers' (so the caller's share of the work), each process's
peak memory and whether the outputs equal ``mdtf run``'s byte for byte.
Run with the package installed as a release build (``pip install
'./crates/python[dask]'``) and a release ``mdtf`` command:

    python crates/python/bench/bench_dask_run.py --mdtf target/release/mdtf [--size 384] [--pipelines distance-tf slicer-3dtf]
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

import mdtf.dask as mdask

REPO = Path(__file__).resolve().parents[3]


def cpu_seconds() -> float:
    """This process's CPU time (user + system), seconds."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def peak_rss_mib() -> float:
    """This process's peak resident memory, MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def outputs(folder: Path) -> dict[str, bytes]:
    """Every file of a run but its report and page (timings, how it was cut)."""
    skip = {"run_report.json", "report.html", ".mdtf-output"}
    return {str(f.relative_to(folder)): f.read_bytes() for f in folder.rglob("*") if f.is_file() and f.name not in skip}


def one_process(mdtf: Path, pipeline: Path, store: Path, out: Path, reps: int) -> float:
    """The best wall time of ``mdtf run --threads 1`` over ``reps`` runs."""
    best = float("inf")
    for _ in range(reps):
        shutil.rmtree(out, ignore_errors=True)
        t = time.perf_counter()
        subprocess.run([mdtf, "-q", "--threads", "1", "run", pipeline, "--input", store, "-o", out, "--set", "preview=false"],
                       check=True)
        best = min(best, time.perf_counter() - t)
    return best


def on_cluster(workers: int, pipeline: Path, store: Path, out: Path, reps: int, slab: int) -> dict:
    """The best of ``reps`` runs of ``mdask.run`` on ``workers`` one-thread process workers."""
    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
    runs = []
    with distributed.Client(cluster) as client:
        for _ in range(reps):
            shutil.rmtree(out, ignore_errors=True)
            w0, c0 = sum(client.run(cpu_seconds).values()), cpu_seconds()
            t = time.perf_counter()
            report = mdask.run(pipeline, out, input=store, client=client, slab_planes=slab, preview=False)
            wall = time.perf_counter() - t
            caller, tasks = cpu_seconds() - c0, sum(client.run(cpu_seconds).values()) - w0
            runs.append((wall, caller, tasks, report))
        peaks = client.run(peak_rss_mib)
    cluster.close()
    wall, caller, tasks, report = min(runs, key=lambda r: r[0])
    return {
        "wall_s": round(wall, 2),
        "caller_cpu_s": round(caller, 2),
        "workers_cpu_s": round(tasks, 2),
        "caller_share": round(caller / (caller + tasks), 3),
        "worker_peak_mib": [round(m) for m in peaks.values()],
        "stage_seconds": {s["stage"]: round(s["seconds"], 2) for s in report["stages"]},
        "tasks": report["slabs"]["tasks"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mdtf", type=Path, default=REPO / "target" / "release" / "mdtf")
    ap.add_argument("--size", type=int, default=384)
    ap.add_argument("--slab", type=int, default=64, help="z-planes per task")
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--pipelines", nargs="+", default=["distance-tf", "slicer-3dtf"])
    ap.add_argument("--dir", type=Path, default=None, help="where the store and outputs go (default: a temporary folder)")
    args = ap.parse_args()
    work = args.dir or Path(tempfile.mkdtemp(prefix="mdtf-bench-dask-"))
    work.mkdir(parents=True, exist_ok=True)
    nrrd, store = work / f"sphere{args.size}.nrrd", work / f"sphere{args.size}.ome.zarr"
    if not store.exists():
        subprocess.run([args.mdtf, "synth", "erf-sphere", "--size", str(args.size), "--sigma", "3", "--noise", "2",
                        "--type", "u16", "-o", nrrd, "-q"], check=True)
        subprocess.run([args.mdtf, "convert", nrrd, store, "-q"], check=True)
        nrrd.unlink()
    results = []
    for name in args.pipelines:
        pipeline = REPO / "pipelines" / f"{name}.toml"
        one = one_process(args.mdtf, pipeline, store, work / "one", args.reps)
        one_workers = on_cluster(1, pipeline, store, work / "dask1", args.reps, args.slab)
        two_workers = on_cluster(2, pipeline, store, work / "dask2", args.reps, args.slab)
        want = outputs(work / "one")
        results.append({
            "pipeline": name,
            "size": args.size,
            "mdtf_run_1_thread_s": round(one, 2),
            "dask_1x1": one_workers,
            "dask_2x1": two_workers,
            "speed_up_1_to_2_workers": round(one_workers["wall_s"] / two_workers["wall_s"], 3),
            "dask_1x1_over_mdtf_run": round(one_workers["wall_s"] / one, 3),
            "outputs_equal": outputs(work / "dask1") == want and outputs(work / "dask2") == want,
        })
        print(json.dumps(results[-1]), flush=True)
    json.dump(results, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
