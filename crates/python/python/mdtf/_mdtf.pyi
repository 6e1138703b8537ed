"""Type stubs of mdtf's native module (the public API is in mdtf/__init__.py)."""

from typing import Any, Callable

import numpy as np
import numpy.typing as npt

Triple = tuple[float, float, float]
F32 = npt.NDArray[np.float32]

class MdtfError(Exception):
    """An mdtf stage failed (the message is the one the mdtf command prints)."""

def set_threads(threads: int) -> None:
    """Uses `threads` worker threads for every later call (0: one per core)."""

def threads() -> int:
    """The number of worker threads calls use."""

def version() -> str: ...
def read(path: str, level: int = 0, nan: str = "refuse") -> tuple[list[tuple[str, F32]], dict[str, Any]]: ...
def write(
    path: str,
    fields: list[tuple[str, F32]],
    spacing: Triple,
    origin: Triple,
    world_from_voxel: list[list[float]] | None = None,
    gzip: bool = False,
) -> None: ...
def derive(
    fields: list[tuple[str, F32]],
    spacing: Triple,
    items: list[str],
    kernel: str | None = None,
    border: str | None = None,
    epsilon: float | None = None,
) -> dict[str, F32]: ...
def bilateral(
    values: F32,
    spacing: Triple,
    sigma_d: float = 1.0,
    sigma_r: float = 0.05,
    range_units: str = "fraction",
    mode: str = "exact",
    k: float | None = None,
) -> F32: ...
def boundary(
    values: F32,
    spacing: Triple,
    kernel: str | None = None,
    prefilter: tuple[float, float] | None = None,
    g_min: float | None = None,
    g_hit_min: float | None = None,
    step: float | None = None,
    d_max: float | None = None,
    tolerance: float | None = None,
    epsilon: float | None = None,
    first_plane: int = 0,
) -> tuple[dict[str, F32], dict[str, Any]]: ...
def histogram(
    channels: list[F32],
    axes: list[tuple[str, tuple[float, float] | None, int | None]],
    mask: npt.NDArray[np.bool_] | None = None,
) -> tuple[npt.NDArray[np.uint64], list[tuple[str, float, float, int]]]: ...
def quantise(
    values: F32, min: float, max: float, dtype: str = "u8", signed: bool = False, name: str = "channel"
) -> tuple[npt.NDArray[Any], float, float]: ...
def run(
    pipeline: str,
    output: str,
    input: str | None = None,
    overrides: list[str] = ...,
    memory_budget: int | None = None,
    slab_planes: int | None = None,
    submit: Callable[[str, list[tuple[int, int]], Callable[[], bool]], None] | None = None,
    resume: bool = False,
) -> str: ...
def plan(pipeline: str, input: str | None = None, overrides: list[str] = ...) -> tuple[str, tuple[int, int, int]]: ...
def slab_task(job: str, start: int, end: int, threads: int = 0) -> bool: ...
def kernel_reach(spacing: Triple, kernel: str | None = None) -> tuple[int, int, int]: ...
def bilateral_reach(spacing: Triple, sigma_d: float = 1.0, mode: str = "exact", k: float | None = None) -> tuple[int, int, int]: ...
def default_epsilon(span: float, min_spacing: float) -> float: ...
def derive_components(items: list[str]) -> list[str]: ...
def trace_reach(spacing: Triple, d_max: float) -> tuple[int, int, int]: ...
def boundary_thresholds(
    shape: tuple[int, int, int],
    spacing: Triple,
    value_range: float,
    median_g: float | None = None,
    g_min: float | None = None,
    g_hit_min: float | None = None,
    step: float | None = None,
    d_max: float | None = None,
    tolerance: float | None = None,
) -> tuple[float, float, float, float, float]: ...
