"""Stages called from Python on an erf sphere: derive (g, f2), the
bilateral filter and the boundary chain, median of repeated runs, beside
what one copy of the input costs (numpy's; the bindings read the array in
place, so this is what zero-copy input saves). Run with the package installed (a release build:
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
    # a smooth sphere whose outside and inside are exactly 0 and 255 (a logistic's tiny tails
    # would make the filter's weights subnormal floats, several times slower to compute)
    v = (127.5 * (1 - np.tanh((r - 0.3 * n) / 1.5, dtype=np.float32))).astype(np.float32)
    mvox = n**3 / 1e6
    copy = median_seconds(lambda: v.copy(), args.repeat)
    derive = median_seconds(lambda: mdtf.derive(v, 1.0, items=["g", "f2"]), args.repeat)
    print(f"{n}^3, {mdtf.threads()} threads, mdtf {mdtf.__version__}")
    print(f"input copy (numpy):   {copy * 1e3:8.1f} ms")
    print(f"derive g, f2:         {derive * 1e3:8.1f} ms  ({mvox / derive:.0f} Mvoxel/s; a copy would add {copy / derive:.1%})")
    fast = median_seconds(lambda: mdtf.bilateral(v, 1.0, mode="fast"), args.repeat)
    print(f"bilateral, fast:      {fast * 1e3:8.1f} ms  ({mvox / fast:.0f} Mvoxel/s)")
    if n <= 256:
        chain = median_seconds(lambda: mdtf.boundary(v, 1.0), max(1, args.repeat // 2))
        print(f"boundary chain:       {chain * 1e3:8.1f} ms  ({mvox / chain:.1f} Mvoxel/s)")


if __name__ == "__main__":
    main()
