"""What a call from Python costs over mdtf's own work: times derive (g, f2)
and the boundary chain on an erf sphere from Python, and the one copy of
the input the bindings make (numpy's own copy of the same array), median
of repeated runs. Run with the package installed (a release build:
`pip install ./crates/python`):

    python crates/python/bench/bench_bindings.py [--size 256] [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import mdtf


def median_seconds(f, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    n = args.size
    c = (n - 1) / 2
    z, y, x = np.ogrid[:n, :n, :n]
    r = np.sqrt((x - c) ** 2 + (y - c) ** 2 + (z - c) ** 2, dtype=np.float32)
    v = (255 / (1 + np.exp(np.clip((r - 0.3 * n) / 1.5, -60, 60)))).astype(np.float32)
    mvox = n**3 / 1e6
    copy = median_seconds(lambda: v.copy(), args.repeat)
    derive = median_seconds(lambda: mdtf.derive(v, 1.0, items=["g", "f2"]), args.repeat)
    print(f"{n}^3, {mdtf.threads()} threads, mdtf {mdtf.__version__}")
    print(f"input copy (numpy):   {copy * 1e3:8.1f} ms")
    print(f"derive g, f2:         {derive * 1e3:8.1f} ms  ({mvox / derive:.0f} Mvoxel/s; the copy is {copy / derive:.1%})")
    if n <= 256:
        chain = median_seconds(lambda: mdtf.boundary(v, 1.0), max(1, args.repeat // 2))
        print(f"boundary chain:       {chain * 1e3:8.1f} ms  ({mvox / chain:.1f} Mvoxel/s; the copy is {copy / chain:.1%})")


if __name__ == "__main__":
    main()
