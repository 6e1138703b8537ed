"""mdtf: volume data prepared for multidimensional transfer functions.

Derivatives (g, f'', normals, multi-field ||G||), the bilateral filter,
distance to the nearest boundary, joint histograms and quantised codes,
on numpy arrays; volume files in every format mdtf reads; and pipeline
runs (``mdtf run``) into an output folder.

Arrays are (z, y, x), C order, float32 (others are converted first), and
are read where numpy holds them, without a copy. Spacing and origin are
(z, y, x) in world units (mm for a scan), or a mapping with keys ``z``,
``y``, ``x``, or one number for isotropic voxels. Outputs are numpy arrays mdtf hands over without a
copy. Every call releases the GIL while it runs; ``set_threads`` sets the
number of worker threads. ``run`` stops between stages and slabs on Ctrl-C
(KeyboardInterrupt) and leaves no partial output; the stage functions
finish their call first.

Errors of mdtf's stages are raised as :class:`MdtfError` with the message
the ``mdtf`` command prints; unknown names of items, kernels or modes as
``ValueError``; a file or folder that does not exist as
:class:`MdtfFileNotFoundError`, both an ``MdtfError`` and a
``FileNotFoundError`` (``errno.ENOENT``, its ``filename`` the path); arrays
mdtf cannot take as they are (complex values, values beyond float32's range,
fields or a mask of another shape) as :class:`MdtfValueError`, both an
``MdtfError`` and a ``ValueError``.
"""

from __future__ import annotations

import errno
import json
import os
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from . import _mdtf
from ._mdtf import MdtfError, set_threads, threads

__all__ = [
    "MdtfError",
    "MdtfFileNotFoundError",
    "MdtfValueError",
    "Volume",
    "Histogram",
    "Boundary",
    "read",
    "write",
    "derive",
    "bilateral",
    "boundary",
    "histogram",
    "quantise",
    "run",
    "plan",
    "halo",
    "set_threads",
    "threads",
]

__version__: str = _mdtf.version()



class MdtfFileNotFoundError(MdtfError, FileNotFoundError):
    """A file or folder given to mdtf does not exist: caught as ``MdtfError``
    and as ``FileNotFoundError`` (``OSError``) alike."""


class MdtfValueError(MdtfError, ValueError):
    """An array mdtf cannot take as it is (complex, beyond float32's range,
    another shape than its companions): caught as ``MdtfError`` and as
    ``ValueError`` alike."""


def _existing(path: str | os.PathLike[str]) -> str:
    """``path`` as a string, when it exists; else MdtfFileNotFoundError."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise MdtfFileNotFoundError(errno.ENOENT, "no such file or folder", p)
    return p


Triple = tuple[float, float, float]
SpacingLike = float | Sequence[float] | Mapping[str, float]


def _triple(value: SpacingLike, name: str) -> Triple:
    """(z, y, x) from one number, a 3-sequence or a mapping with keys z, y, x."""
    if isinstance(value, Mapping):
        try:
            return (float(value["z"]), float(value["y"]), float(value["x"]))
        except KeyError as e:
            raise ValueError(f"{name}: a mapping needs the keys z, y and x (missing {e})") from None
    if np.isscalar(value):
        v = float(value)  # type: ignore[arg-type]
        return (v, v, v)
    t = tuple(float(v) for v in value)  # type: ignore[union-attr]
    if len(t) != 3:
        raise ValueError(f"{name}: give three numbers (z, y, x), got {len(t)}")
    return t  # type: ignore[return-value]


def _f32(a: Any, name: str) -> np.ndarray:
    """A C-contiguous float32 (z, y, x) array (no copy when it already is one).
    Complex values, and finite values beyond float32's range (which the cast
    would turn into infinities), are refused rather than changed."""
    src = np.asarray(a)
    if np.iscomplexobj(src):
        raise MdtfValueError(
            f"{name}: complex values ({src.dtype}); mdtf takes real volumes: pass .real, .imag or abs() of the array"
        )
    with np.errstate(over="ignore"):  # an overflow is reported below, with its count
        arr = np.ascontiguousarray(src, dtype=np.float32)
    if arr.ndim != 3:
        raise MdtfValueError(f"{name}: expected a 3-D (z, y, x) array, got shape {arr.shape}")
    if src.dtype.kind == "f" and src.dtype.itemsize > 4 and np.isinf(arr).any():
        overflow = np.isinf(arr) & np.isfinite(src)
        if overflow.any():
            big = float(np.abs(src[overflow]).max())
            raise MdtfValueError(
                f"{name}: {int(overflow.sum())} value(s) up to {big:.6g} exceed float32's range "
                f"(±{float(np.finfo(np.float32).max):.6g}), in which mdtf computes: scale the array first"
            )
    return arr


def _same_shape(arrays: Sequence[tuple[str, np.ndarray]], what: str) -> None:
    """Refuses arrays of different shapes, naming them."""
    shapes = {n: a.shape for n, a in arrays}
    if len(set(shapes.values())) > 1:
        listed = ", ".join(f"{n} {s}" for n, s in shapes.items())
        raise MdtfValueError(f"{what} must share one (z, y, x) shape: {listed}")


def _fields(data: Any, name: str = "data") -> list[tuple[str, np.ndarray]]:
    """Named fields from one array ("v"), a mapping name -> array, or a Volume."""
    if isinstance(data, Volume):
        data = data.fields
    if isinstance(data, Mapping):
        fields = [(str(k), _f32(v, f"{name}[{k!r}]")) for k, v in data.items()]
        _same_shape(fields, f"the fields of {name}")
        return fields
    return [("v", _f32(data, name))]


@dataclass
class Volume:
    """A volume read from a file: its fields and its grid.

    ``fields`` maps each field's name to its (z, y, x) float32 array;
    ``spacing`` and ``origin`` are (z, y, x) in world units;
    ``world_from_voxel`` is the 4 x 4 matrix taking voxel (i, j, k, 1) to
    world (x, y, z, 1), orientation included (as NIfTI's sform).
    """

    fields: dict[str, np.ndarray]
    spacing: Triple
    origin: Triple
    world_from_voxel: list[list[float]]
    format: str = ""
    warnings: list[str] = field(default_factory=list)

    @property
    def data(self) -> np.ndarray:
        """The first field's array (the only one of a scalar volume)."""
        return next(iter(self.fields.values()))


def read(path: str | os.PathLike[str], level: int = 0, nan: str = "refuse") -> Volume:
    """Reads a volume file or folder: NIfTI, NRRD, MetaImage, TIFF stack,
    DICOM series, OME-Zarr (``level`` picks the multiscale level; 0 is full
    resolution). ``nan``: "refuse" (the default), "zero" or "keep"."""
    fields, meta = _mdtf.read(_existing(path), level, nan)
    return Volume(
        fields=dict(fields),
        spacing=tuple(meta["spacing"]),
        origin=tuple(meta["origin"]),
        world_from_voxel=meta["world_from_voxel"],
        format=meta["format"],
        warnings=list(meta["warnings"]),
    )


def write(
    path: str | os.PathLike[str],
    data: Any,
    spacing: SpacingLike = 1.0,
    origin: SpacingLike = 0.0,
    world_from_voxel: Sequence[Sequence[float]] | None = None,
    gzip: bool = False,
) -> None:
    """Writes an array, a mapping name -> array (several fields) or a
    Volume; the extension picks the format (``.nii``, ``.nii.gz``,
    ``.nrrd``, ``.nhdr``, ``.mha``, ``.mhd``, ``.ome.zarr``). The file
    appears whole or not at all. A Volume keeps its own grid."""
    if isinstance(data, Volume) and world_from_voxel is None:
        world_from_voxel = data.world_from_voxel
    wfv = None if world_from_voxel is None else [[float(x) for x in row] for row in world_from_voxel]
    _mdtf.write(
        os.fspath(path), _fields(data), _triple(spacing, "spacing"), _triple(origin, "origin"), wfv, gzip
    )


def derive(
    data: Any,
    spacing: SpacingLike = 1.0,
    items: str | Iterable[str] = ("g", "f2"),
    kernel: str | None = None,
    border: str | None = None,
    epsilon: float | None = None,
) -> dict[str, np.ndarray]:
    """Derivative measures of a (z, y, x) array, or of several fields (a
    mapping name -> array) for the multi-field items (gnorm, jacobian).

    ``items``: value, grad, g, normal, hessian, f2, laplacian, curvature, inv_g, shade,
    gnorm, jacobian (one name, or several). ``kernel``: central, central4 (the default), bspline3,
    catmull-rom or gauss:SIGMA (voxels). ``border``: clamp (the default),
    mirror or wrap. Derivatives are per world unit. Returns one array per
    component, by item name (``g``, ``f2``) or component name (``nx``,
    ``ny``, ``nz`` for the normal; ``gx`` ... for grad)."""
    names = [items] if isinstance(items, str) else list(items)
    return _mdtf.derive(_fields(data), _triple(spacing, "spacing"), names, kernel, border, epsilon)


def bilateral(
    data: Any,
    spacing: SpacingLike = 1.0,
    sigma_d: float = 1.0,
    sigma_r: float = 0.05,
    range_units: str = "fraction",
    mode: str = "exact",
    k: float | None = None,
) -> np.ndarray:
    """The 3-D bilateral filter: spatial sigma ``sigma_d`` in world units,
    range sigma ``sigma_r`` as a fraction of the value range
    (``range_units="value"``: in value units). ``mode``: "exact" (every
    neighbour within ``k`` sigma_d, default k 2.5) or "fast"."""
    return _mdtf.bilateral(
        _f32(data, "data"), _triple(spacing, "spacing"), sigma_d, sigma_r, range_units, mode, k
    )


@dataclass
class Boundary:
    """The distance to the nearest boundary, per voxel.

    ``distance`` (world units; -1 where no boundary was kept), ``g_hit`` (g
    at the boundary), ``hit`` (1 hit, 0 not traced, 2 no crossing within
    d_max, 3 rejected as too weak), ``dot`` (unit gradients at the voxel and
    the boundary), and the ``g`` and ``f2`` the tracing followed (after the
    pre-filter, when one ran). ``summary``: the thresholds used (noise_floor,
    g_min, g_hit_min, step, d_max, tolerance), the counts per hit code, and
    the warnings (boundaries the thresholds left out).
    """

    distance: np.ndarray
    g_hit: np.ndarray
    hit: np.ndarray
    dot: np.ndarray
    g: np.ndarray
    f2: np.ndarray
    summary: dict[str, Any]


def boundary(
    data: Any,
    spacing: SpacingLike = 1.0,
    kernel: str | None = None,
    prefilter: tuple[float, float] | None = None,
    g_min: float | None = None,
    g_hit_min: float | None = None,
    step: float | None = None,
    d_max: float | None = None,
    tolerance: float | None = None,
) -> Boundary:
    """Traces every voxel of a (z, y, x) value array along its gradient to
    the nearest zero crossing of f'' (as ``mdtf boundary --input``).

    ``prefilter``: (sigma_d, sigma_r) of a bilateral filter of g and f''.
    Thresholds in value units per world unit, ``step`` and ``d_max`` in
    world units, ``tolerance`` in voxels; None takes mdtf's default (the
    noise floor, twice it, L_min / 5, 15 L_min, 1e-3)."""
    arrays, summary = _mdtf.boundary(
        _f32(data, "data"),
        _triple(spacing, "spacing"),
        kernel,
        prefilter,
        g_min,
        g_hit_min,
        step,
        d_max,
        tolerance,
    )
    return Boundary(summary=summary, **arrays)


@dataclass
class Histogram:
    """Integer counts over 1 to 3 axes.

    ``counts`` (uint64: a bin of a large volume holds more than 2^32 voxels)
    has shape (bins of the last axis, ..., bins of the first), as
    mdtf's NRRD counts files store them (first axis fastest); ``axes`` lists
    (name, min, max, bins); bin b of an axis spans
    [min + b (max - min) / bins, min + (b + 1) (max - min) / bins).
    """

    counts: np.ndarray
    axes: list[tuple[str, float, float, int]]

    def edges(self, axis: int) -> np.ndarray:
        """The bin edges of axis ``axis`` (bins + 1 values)."""
        _, lo, hi, bins = self.axes[axis]
        return np.linspace(lo, hi, bins + 1)


def histogram(
    channels: Mapping[str, Any],
    ranges: Mapping[str, tuple[float, float]] | None = None,
    bins: int | Mapping[str, int] | None = None,
    mask: Any = None,
) -> Histogram:
    """The joint histogram of 1 to 3 named channels (``{"v": v, "g": g}``),
    the first the fastest axis. A range not given is the channel's finite
    range, clipped as Teem's qbert clips it (0.002 % each end for g, 0.004 %
    for f2, none for the others); bins not given are one per integer for
    integer data spanning at most 4096 values, else 256. ``mask``: only
    the voxels where it is true."""
    names = list(channels)
    ranges = dict(ranges or {})
    axes = []
    for n in names:
        b = bins.get(n) if isinstance(bins, Mapping) else bins
        r = ranges.get(n)
        axes.append((n, None if r is None else (float(r[0]), float(r[1])), None if b is None else int(b)))
    arrays = [_f32(channels[n], n) for n in names]
    m = None if mask is None else np.ascontiguousarray(mask, dtype=bool)
    _same_shape(list(zip(names, arrays)) + ([] if m is None else [("mask", m)]), "the channels and the mask")
    counts, out_axes = _mdtf.histogram(arrays, axes, m)
    return Histogram(counts=counts, axes=out_axes)


def quantise(
    data: Any, min: float, max: float, dtype: str = "u8", signed: bool = False
) -> tuple[np.ndarray, float, float]:
    """Codes of a (z, y, x) array over [min, max] as the pack stores a
    channel: value = offset + scale * code, codes clamped to the type
    ("u8", "u16"; "f16" and "f32" store the values themselves). With
    ``signed`` and min < 0 < max, 0 is exactly a code. Returns (codes,
    offset, scale)."""
    codes, offset, scale = _mdtf.quantise(_f32(data, "data"), float(min), float(max), dtype, signed)
    if dtype == "f16":
        codes = codes.view(np.float16)
    return codes, offset, scale


def _overrides(settings: Mapping[str, Any] | Iterable[str] | None, kwargs: Mapping[str, Any]) -> list[str]:
    """``section.key=value`` strings from a mapping (or strings as given) and
    keyword arguments, where a double underscore stands for the dot."""
    out: list[str] = []
    if isinstance(settings, Mapping):
        items = list(settings.items())
    else:
        out.extend(str(s) for s in settings or [])
        items = []
    items += [(k.replace("__", "."), v) for k, v in kwargs.items()]
    for key, value in items:
        if isinstance(value, bool):
            text = "true" if value else "false"
        elif isinstance(value, (int, float, str, list, tuple)):
            text = json.dumps(list(value) if isinstance(value, tuple) else value)
        else:
            raise ValueError(f"{key}: give a number, string, bool or list, got {type(value).__name__}")
        out.append(f"{key}={text}")
    return out


def run(
    pipeline: str | os.PathLike[str],
    output: str | os.PathLike[str],
    input: str | os.PathLike[str] | None = None,
    settings: Mapping[str, Any] | Iterable[str] | None = None,
    memory_budget: int | None = None,
    slab_planes: int | None = None,
    **overrides: Any,
) -> dict[str, Any]:
    """Runs a pipeline file (``mdtf run``) into the folder ``output``,
    written whole at the end: a failed or interrupted run leaves nothing.

    ``input`` replaces the pipeline's input. Settings are overridden by
    ``settings`` (``{"boundary.d_max": 4.0}`` or ``["boundary.d_max=4"]``)
    and keyword arguments with ``__`` for the dot
    (``input__size=64``). ``memory_budget`` (bytes) or ``slab_planes`` run
    it slab by slab. Returns the run report (run_report.json)."""
    return _run(pipeline, output, input, _overrides(settings, overrides), memory_budget, slab_planes)


def _run(
    pipeline: str | os.PathLike[str],
    output: str | os.PathLike[str],
    input: str | os.PathLike[str] | None,
    overrides: list[str],
    memory_budget: int | None,
    slab_planes: int | None,
    submit: Any = None,
    resume: bool = False,
) -> dict[str, Any]:
    """``run``, and ``mdtf.dask.run`` with its ``submit`` of the tasks (and
    whether it resumes a killed run): the run report."""
    path = None if input is None else _existing(input)
    text = _mdtf.run(_existing(pipeline), os.fspath(output), path, overrides, memory_budget, slab_planes, submit, resume)
    return json.loads(text)


def plan(
    pipeline: str | os.PathLike[str],
    input: str | os.PathLike[str] | None = None,
    settings: Mapping[str, Any] | Iterable[str] | None = None,
    **overrides: Any,
) -> str:
    """The plan of a pipeline on its input, as ``mdtf run --plan`` prints it."""
    text, _ = _mdtf.plan(_existing(pipeline), None if input is None else _existing(input), _overrides(settings, overrides))
    return text


def halo(
    pipeline: str | os.PathLike[str],
    input: str | os.PathLike[str] | None = None,
    settings: Mapping[str, Any] | Iterable[str] | None = None,
    **overrides: Any,
) -> tuple[int, int, int]:
    """The halo (z, y, x voxels) a block of this pipeline needs on its
    input: how far its derivatives, pre-filter and tracing read beyond the
    block (the overlap for ``dask.array.map_overlap``)."""
    _, h = _mdtf.plan(_existing(pipeline), None if input is None else _existing(input), _overrides(settings, overrides))
    return h
