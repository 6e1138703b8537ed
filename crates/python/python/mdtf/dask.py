"""mdtf's stages over dask arrays, block by block on any dask scheduler
(threads, processes, a ``dask.distributed`` cluster on Slurm or Kubernetes).

Each block is computed with the halo its stage reads (the kernel's reach
for ``derive``, the filter's box for ``bilateral``), with no padding at the
volume's own edges, so every voxel gets exactly what the whole-volume call
gives it: the results are bit-identical to ``mdtf.derive`` and
``mdtf.bilateral`` for any chunking. What a block cannot know alone (the
value range behind derive's epsilon and the filter's fractional range
sigma) is reduced over the whole array first, exactly (min and max).

Read an OME-Zarr store with ``mdtf.dask.from_ome_zarr`` and write results
with ``mdtf.dask.to_ome_zarr`` (each block writes only its own chunks).

``mdtf.dask.run`` runs a whole pipeline file as ``mdtf run`` does, its
passes spread over the cluster as one task per z-slab; the outputs are
``mdtf run``'s, byte for byte.

Needs ``dask[array]`` (and ``zarr`` for stores, ``distributed`` for a cluster).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from . import SpacingLike, _f32, _mdtf, _overrides, _run, _triple

try:
    import dask
    import dask.array as da
    from dask.array.overlap import overlap, trim_internal
except ImportError as e:  # pragma: no cover - the message is the point
    raise ImportError("mdtf.dask needs dask: pip install 'dask[array]' (and distributed for a cluster)") from e

__all__ = ["derive", "bilateral", "boundary", "lower_median", "run", "from_ome_zarr", "to_ome_zarr", "da"]


def _value_range(arr: da.Array) -> tuple[float, float]:
    """The array's min and max, over every block (exact)."""
    lo, hi = dask.compute(arr.min(), arr.max())
    return float(lo), float(hi)


def _at_least(chunks: tuple[int, ...], need: int) -> tuple[int, ...]:
    """Chunks along one axis with a first or last chunk of fewer than
    ``need`` samples merged into its neighbour (an edge block gets a halo on
    one side only, and a stage refuses blocks thinner than its kernel)."""
    c = list(chunks)
    if len(c) > 1 and c[-1] < need:
        c[-2:] = [c[-2] + c[-1]]
    if len(c) > 1 and c[0] < need:
        c[:2] = [c[0] + c[1]]
    return tuple(c)


def _with_halo(arr: da.Array, reach: tuple[int, int, int], block: Any, count: int, wrap: bool = False) -> da.Array:
    """``block(b, first)`` (``b`` a (z, y, x) block with its halo, ``first``
    the global index of its first voxel; returns (count, z, y, x)) over
    every block of ``arr`` grown by ``reach``, trimmed back. No padding at
    the volume's edges, where the stage's own border rule applies, except
    for a periodic (``wrap``) border, whose halo comes from the other side."""
    chunks = tuple(_at_least(c, 2 * r + 1) for c, r in zip(arr.chunks, reach))
    if chunks != arr.chunks:
        arr = arr.rechunk(chunks)
    starts = [np.concatenate([[0], np.cumsum(c)[:-1]]) for c in chunks]
    depth = {0: reach[0], 1: reach[1], 2: reach[2]}
    boundary = "periodic" if wrap else "none"
    grown = overlap(arr, depth, boundary=boundary)

    def placed(b: np.ndarray, block_info: dict | None = None) -> np.ndarray:
        where = block_info[0]["chunk-location"] if block_info else (0, 0, 0)
        grown_by = [0 if (k == 0 and not wrap) else r for k, r in zip(where, reach)]
        first = tuple(int(s[k]) - g for s, k, g in zip(starts, where, grown_by))
        return block(b, first)

    meta = np.empty((0, 0, 0, 0), np.float32)
    out = grown.map_blocks(placed, new_axis=0, chunks=((count,), *grown.chunks), dtype=np.float32, meta=meta)
    return trim_internal(out, {0: 0, 1: reach[0], 2: reach[1], 3: reach[2]}, boundary=boundary)


def derive(
    arr: Any,
    spacing: SpacingLike = 1.0,
    items: Iterable[str] = ("g", "f2"),
    kernel: str | None = None,
    border: str | None = None,
    epsilon: float | None = None,
) -> dict[str, da.Array]:
    """``mdtf.derive`` of one field held as a dask array (z, y, x): one lazy
    array per component, as ``mdtf.derive`` names them. Without
    ``epsilon``, the array's value range is computed first (one pass).
    ``shade`` (it needs the whole volume's largest g) and the multi-field
    items are not available block by block."""
    arr = da.asarray(arr).astype(np.float32)
    if arr.ndim != 3:
        raise ValueError(f"expected a 3-D (z, y, x) array, got shape {arr.shape}")
    items = list(items)
    if "shade" in items:
        raise ValueError("shade needs the whole volume's largest g: use mdtf.derive")
    names = _mdtf.derive_components(items)
    sp = _triple(spacing, "spacing")
    reach = _mdtf.kernel_reach(sp, kernel)
    if epsilon is None:
        lo, hi = _value_range(arr)
        epsilon = _mdtf.default_epsilon(np.float32(hi) - np.float32(lo), min(sp))

    def block(b: np.ndarray, _first: tuple[int, int, int]) -> np.ndarray:
        d = _mdtf.derive([("v", _f32(b, "block"))], sp, items, kernel, border, float(epsilon))
        return np.stack([d[n] for n in names])

    # a periodic border's block sees the other side through its halo; its own border rule then never applies
    out = _with_halo(arr, reach, block, len(names), wrap=border == "wrap")
    return {n: out[k] for k, n in enumerate(names)}


def bilateral(
    arr: Any,
    spacing: SpacingLike = 1.0,
    sigma_d: float = 1.0,
    sigma_r: float = 0.05,
    range_units: str = "fraction",
    mode: str = "exact",
    k: float | None = None,
) -> da.Array:
    """``mdtf.bilateral`` of a dask array (z, y, x), lazily. A fractional
    ``sigma_r`` is of the whole array's value range (computed first)."""
    arr = da.asarray(arr).astype(np.float32)
    if arr.ndim != 3:
        raise ValueError(f"expected a 3-D (z, y, x) array, got shape {arr.shape}")
    sp = _triple(spacing, "spacing")
    reach = _mdtf.bilateral_reach(sp, sigma_d, mode, k)
    if range_units == "fraction":
        lo, hi = _value_range(arr)
        sigma_r = sigma_r * (hi - lo)
    elif range_units != "value":
        raise ValueError(f"range_units: unknown value '{range_units}' (valid: fraction, value)")

    def block(b: np.ndarray, _first: tuple[int, int, int]) -> np.ndarray:
        return _mdtf.bilateral(_f32(b, "block"), sp, sigma_d, sigma_r, "value", mode, k)[np.newaxis]

    return _with_halo(arr, reach, block, 1)[0]


def lower_median(arr: da.Array) -> float | None:
    """The lower median (the ((n - 1) // 2)-th smallest) of the finite,
    non-negative samples of ``arr``, exactly, in two passes of counts over
    its blocks: the high 16 bits of the samples' float32 patterns (which sort
    as the values do), then the low 16 bits within the bucket the median
    falls in. None without any such sample."""
    bits = da.where(da.isfinite(arr) & (arr >= 0), arr.astype(np.float32), np.float32(np.nan))

    def counts(b: np.ndarray, bucket: int | None) -> np.ndarray:
        u = b[np.isfinite(b)].view(np.uint32)
        u = (u[(u >> 16) == bucket] & 0xFFFF) if bucket is not None else u >> 16
        return np.bincount(u, minlength=1 << 16).astype(np.int64)

    def total(bucket: int | None) -> np.ndarray:
        parts = [dask.delayed(counts)(b, bucket) for b in bits.to_delayed().ravel()]
        return dask.delayed(sum)(parts).compute()

    high = total(None)
    n = int(high.sum())
    if n == 0:
        return None
    k = (n - 1) // 2
    cum = np.cumsum(high)
    bucket = int(np.searchsorted(cum, k, side="right"))
    before = int(cum[bucket - 1]) if bucket > 0 else 0
    low = np.cumsum(total(bucket))
    rest = int(np.searchsorted(low, k - before, side="right"))
    return float(np.array([(bucket << 16) | rest], np.uint32).view(np.float32)[0])


def boundary(
    arr: Any,
    spacing: SpacingLike = 1.0,
    kernel: str | None = None,
    g_min: float | None = None,
    g_hit_min: float | None = None,
    step: float | None = None,
    d_max: float | None = None,
    tolerance: float | None = None,
) -> dict[str, da.Array]:
    """``mdtf.boundary`` of a dask array (z, y, x), lazily: ``distance``,
    ``g_hit``, ``hit`` and ``dot``, bit-identical to the whole-volume call.
    The whole array's value range, and (for a default g_min or g_hit_min)
    the exact median of g behind the noise floor, are computed first; the
    array is then traced in z-slabs of whole planes (its z chunks), each
    grown by d_max and the kernel's reach, with the same thresholds. No
    pre-filter block by block yet."""
    arr = da.asarray(arr).astype(np.float32)
    if arr.ndim != 3:
        raise ValueError(f"expected a 3-D (z, y, x) array, got shape {arr.shape}")
    sp = _triple(spacing, "spacing")
    lo, hi = _value_range(arr)
    value_range = float(np.float32(hi) - np.float32(lo))
    epsilon = _mdtf.default_epsilon(np.float32(hi) - np.float32(lo), min(sp))
    median = None
    if g_min is None or g_hit_min is None:
        median = lower_median(derive(arr, sp, items=["g"], kernel=kernel, epsilon=epsilon)["g"])
    g_min, g_hit_min, step, d_max, tolerance = _mdtf.boundary_thresholds(
        arr.shape, sp, value_range, median, g_min, g_hit_min, step, d_max, tolerance
    )
    # z-slabs of whole planes, as the slab-by-slab run: rays are traced in the whole volume's
    # coordinates along z, so each slab needs its place (first plane), and no x or y halo
    slabs = arr.rechunk({1: -1, 2: -1})
    reach = (_mdtf.kernel_reach(sp, kernel)[0] + _mdtf.trace_reach(sp, d_max)[0], 0, 0)
    names = ["distance", "g_hit", "hit", "dot"]

    def block(b: np.ndarray, first: tuple[int, int, int]) -> np.ndarray:
        arrays, _ = _mdtf.boundary(
            _f32(b, "block"), sp, kernel, None, g_min, g_hit_min, step, d_max, tolerance, float(epsilon), first[0]
        )
        return np.stack([arrays[n] for n in names])

    out = _with_halo(slabs, reach, block, len(names))
    return {n: out[k] for k, n in enumerate(names)}


def from_ome_zarr(path: str | os.PathLike[str], level: int = 0, chunks: Any = None) -> tuple[da.Array, tuple[float, float, float]]:
    """A single-field OME-Zarr image (NGFF 0.4 or 0.5) as a dask array (z,
    y, x) and its spacing (z, y, x) at ``level``, read with zarr-python.
    ``chunks`` rechunks it (default: the store's chunks)."""
    root = Path(path)
    meta_file = root / "zarr.json"
    if meta_file.is_file():
        attrs = json.loads(meta_file.read_text()).get("attributes", {}).get("ome", {})
    else:
        attrs = json.loads((root / ".zattrs").read_text())
    multiscale = attrs["multiscales"][0]
    axes = [a["name"] if isinstance(a, dict) else a for a in multiscale["axes"]]
    dataset = multiscale["datasets"][level]
    scale = next(t["scale"] for t in dataset["coordinateTransformations"] if t["type"] == "scale")
    arr = da.from_zarr(str(root / dataset["path"]))
    keep = [i for i, a in enumerate(axes) if a in ("z", "y", "x")]
    if len(keep) != 3:
        raise ValueError(f"{path}: expected axes z, y, x, got {axes}")
    for i, a in enumerate(axes):
        if i not in keep and arr.shape[i] != 1:
            raise ValueError(f"{path}: axis {a} has {arr.shape[i]} entries; give a one-field image")
    arr = arr[tuple(slice(None) if i in keep else 0 for i in range(arr.ndim))]
    if chunks is not None:
        arr = arr.rechunk(chunks)
    return arr, tuple(float(scale[i]) for i in keep)  # type: ignore[return-value]


def to_ome_zarr(
    arr: Any,
    path: str | os.PathLike[str],
    spacing: SpacingLike = 1.0,
    origin: SpacingLike = 0.0,
    compute: bool = True,
) -> Any:
    """Writes a dask array (z, y, x) as an OME-Zarr 0.5 image (Zarr v3,
    zstd; one chunk per dask block, the blocks rechunked to one regular
    shape first), each block writing only its own chunk, so a rerun block
    rewrites the same bytes. The store is built beside ``path`` and renamed
    into place when every block is written (with ``compute=False``: when the
    returned task is computed); an existing ``path`` is refused."""
    import shutil
    import tempfile

    import zarr

    target = Path(path)
    if target.exists():
        raise FileExistsError(f"{target} exists: mdtf.dask does not replace a store")
    arr = da.asarray(arr)
    if arr.ndim != 3:
        raise ValueError(f"expected a 3-D (z, y, x) array, got shape {arr.shape}")
    chunk = tuple(int(c) for c in arr.chunksize)
    arr = arr.rechunk(chunk)
    sp, org = _triple(spacing, "spacing"), _triple(origin, "origin")
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    axes = [{"name": a, "type": "space"} for a in ("z", "y", "x")]
    transforms = [{"type": "scale", "scale": list(sp)}, {"type": "translation", "translation": list(org)}]
    try:
        group = zarr.open_group(store=str(staging), mode="w", zarr_format=3)
        group.attrs["ome"] = {
            "version": "0.5",
            "multiscales": [{"axes": axes, "datasets": [{"path": "0", "coordinateTransformations": transforms}]}],
        }
        image = group.create_array(
            "0",
            shape=arr.shape,
            chunks=chunk,
            dtype=arr.dtype,
            compressors=zarr.codecs.ZstdCodec(level=3),
            dimension_names=["z", "y", "x"],
        )
        stored = da.to_zarr(arr, image, compute=False)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise

    def publish(_: Any) -> str:
        os.replace(staging, target)
        return str(target)

    task = dask.delayed(publish)(stored)
    if not compute:
        return task
    try:
        return task.compute()
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def _slab_task(job: str, start: int, end: int, threads: int) -> bool:
    """One task of ``run``: ``job``'s pass on the z-planes ``start:end`` on
    ``threads`` threads (a module function, so that workers import it
    rather than unpickle it); False when it found its slab done (a resumed run)."""
    return _mdtf.slab_task(job, start, end, threads)


class _PassProgress:
    """How far the tasks of one pass of ``run`` are, on stderr: ``done`` of
    ``total`` counted in place on a terminal, one line when they finish."""

    def __init__(self, job: str, total: int, shown: bool) -> None:
        kind = next(iter(json.loads(job)["pass"]), "pass")
        self.name = "boundary" if kind == "Trace" else kind.lower()
        self.total, self.shown, self.start, self.done = total, shown, time.monotonic(), -1
        self.live = shown and sys.stderr.isatty()

    def update(self, done: int) -> None:
        if self.live and done != self.done:
            self.done = done
            print(f"\rmdtf.dask.run: {self.name}: {done}/{self.total} tasks", end="", file=sys.stderr, flush=True)

    def finished(self, ran: Iterable[bool]) -> None:
        if self.shown:
            took = time.monotonic() - self.start
            line = f"mdtf.dask.run: {self.name}: {self.total}/{self.total} tasks in {took:.1f} s"
            done_before = sum(not r for r in ran)
            if done_before:
                line += f" ({done_before} found their slab done by the run this one resumes)"
            print(("\r" if self.live else "") + line, file=sys.stderr, flush=True)


def _all_done(futures: list[Any], within: float) -> bool:
    """Whether every future has finished, waiting at most ``within``
    seconds: it returns as soon as the last one finishes (the next pass
    starts without a polling delay)."""
    from distributed import TimeoutError as NotYet
    from distributed import wait

    try:
        wait(futures, timeout=within)
    except NotYet:
        return False
    return True


def _executing(dask_worker: Any) -> int:
    """How many tasks a worker is running (for ``client.run``)."""
    return len(dask_worker.state.executing)


def _current_client() -> Any:
    """The ``dask.distributed`` client in use, or None."""
    try:
        from distributed import get_client
    except ImportError:
        return None
    try:
        return get_client()
    except ValueError:
        return None


def run(
    pipeline: str | os.PathLike[str],
    output: str | os.PathLike[str],
    input: str | os.PathLike[str] | None = None,
    settings: Mapping[str, Any] | Iterable[str] | None = None,
    *,
    client: Any = None,
    slab_planes: int | None = None,
    memory_budget: int | None = None,
    retries: int = 3,
    task_threads: int = 1,
    progress: bool = True,
    resume: bool = True,
    **overrides: Any,
) -> dict[str, Any]:
    """Runs a pipeline file like ``mdtf.run`` (``mdtf run``), slab by slab,
    its passes as tasks on a dask cluster: reading an OME-Zarr input,
    derive, pre-filter, tracing, and the histograms with the pack's
    textures. The outputs in ``output`` are ``mdtf run``'s, byte for byte:
    each task hands back its part of every whole-volume reduction (ranges,
    percentile tails, medians, histogram counts, the histogram volume's
    sums), which this process merges exactly.

    The tasks read the input and read and write the run's channel store
    and pack inside the output's staging folder, so ``input`` and
    ``output`` must be on a file system every worker sees (the cluster's
    shared disk). A task writes only its own slab's planes: a task lost
    with its worker is rerun (up to ``retries`` times) with the same
    result. An input that is not an OME-Zarr store (any format
    ``mdtf.read`` takes; a dask array: write it with ``to_ome_zarr``
    first) is read by this process. This process also writes the kept
    volumes, the histogram files, the tables and the report.

    ``client``: a ``dask.distributed`` client (default: the current one, if
    any, else dask's default scheduler in this process). ``slab_planes``
    z-planes per task (default 64), or ``memory_budget`` bytes per task.
    ``task_threads``: threads each task computes on (default 1: a worker
    runs as many tasks at once as it has threads, so give workers one
    thread per core; 0: one per core of the worker's machine, for workers
    of one thread).
    ``resume``: a run whose caller was killed (``kill -9``, a lost node, a
    job's time limit) leaves its partial folder beside ``output``
    (``.mdtf-partial-<name>-XXXXXX``); the next run into ``output`` with the
    same pipeline, settings, input files (names, sizes and modification
    times) and slabs takes it over and runs only the tasks that had not
    finished: a task whose slab is done (its partial there, and every byte
    it wrote still hashing as it recorded) does nothing. The report's
    ``slabs.resumed`` says so and ``slabs.tasks[].reused`` counts those
    tasks. A run whose task fails for good (a worker out of memory, a full
    disk) after some tasks finished keeps its partial folder too, and its
    error says where: rerun once the cause is fixed. ``resume=False``
    starts afresh. Ctrl-C is not a kill: it cancels the run and removes its
    partial folder. Tasks a killed caller left
    running on workers write the same bytes as the new run's, and publish
    nothing (each checks the run's token first).
    ``settings`` and keyword overrides as for ``mdtf.run``. Returns the run
    report (run_report.json)."""
    client = client if client is not None else _current_client()

    def submit(job: str, slabs: list[tuple[int, int]], cancelled: Any) -> None:
        shown = _PassProgress(job, len(slabs), progress)
        if client is None:
            ran = dask.compute(*[dask.delayed(_slab_task, pure=False)(job, a, b, task_threads) for a, b in slabs])
            shown.finished(ran)
            return
        starts, ends = [a for a, _ in slabs], [b for _, b in slabs]
        threads = [task_threads] * len(slabs)
        futures = client.map(_slab_task, [job] * len(slabs), starts, ends, threads, pure=False, retries=retries)
        # Ctrl-C in the caller sets cancelled(): the tasks are dropped and the run ends as cancelled
        while not _all_done(futures, 0.25):
            if cancelled():
                client.cancel(futures)
                # a task already running cannot be stopped: the run removes its store only after
                # them, or one could write into the folder while it is being removed
                deadline = time.monotonic() + 120
                while any(client.run(_executing).values()) and time.monotonic() < deadline:
                    time.sleep(0.05)
                return
            shown.update(sum(f.done() for f in futures))
        shown.finished(client.gather(futures))

    return _run(pipeline, output, input, _overrides(settings, overrides), memory_budget, slab_planes, submit, resume)
