"""The preview beside VTK's CPU ray caster on one volume: ``mdtf preview``
of a pack (whole process: manifest, decode, empty-space table, rays, PNG)
against ``vtkFixedPointVolumeRayCastMapper`` rendering the same value
volume at the same image size, with a 1D colour/opacity TF and a gradient
opacity ramp standing in for the pack's 2D/3D TF (VTK has no
multidimensional TF), shaded, half-voxel steps. VTK's first render also
computes its gradients and their encoding; a second render of the same
view reuses them: both are reported, each the best of ``--reps``.

Run under an X server (VTK renders offscreen through one):

    xvfb-run -a python crates/preview/bench/bench_vtk_preview.py --mdtf target/release/mdtf PACK [PACK ...]

where each PACK is an `mdtf run` output's `pack` folder (e.g. of
`pipelines/slicer-3dtf.toml --set input.size=256`).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import vtk
from vtk.util import numpy_support


def pack_value(pack: Path) -> tuple[np.ndarray, list[float]]:
    """The pack's value channel v (else its first channel: a multi-field
    pack's first field) decoded (z, y, x), and its spacing."""
    manifest = json.loads((pack / "manifest.json").read_text())
    dims = manifest["geometry"]["dims"]
    w = manifest["geometry"]["world_from_voxel"]
    spacing = [float(np.linalg.norm([w[0][a], w[1][a], w[2][a]])) for a in range(3)]
    entry = next((c for c in manifest["channels"] if c["name"] == "v"), manifest["channels"][0])
    tex = next(t for t in manifest["textures"] if t["name"] == entry["texture"])
    dtype = {"u8": np.uint8, "u16": np.uint16, "f16": np.float16, "f32": np.float32}[tex["dtype"]]
    raw = np.fromfile(pack / tex["data"], dtype=dtype).reshape(dims[2], dims[1], dims[0], tex["components"])
    codes = raw[..., entry["component"]].astype(np.float32)
    d = entry["decode"]
    if tex["dtype"] in ("u8", "u16"):
        codes = np.float32(d["offset"]) + np.float32(d["scale"]) * codes
    return np.ascontiguousarray(codes), spacing


def save_png(window: vtk.vtkRenderWindow, path: Path) -> None:
    """The window's picture as a PNG (to look at beside mdtf's)."""
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.Update()
    writer = vtk.vtkPNGWriter()
    writer.SetFileName(str(path))
    writer.SetInputConnection(grab.GetOutputPort())
    writer.Write()


def vtk_render(v: np.ndarray, spacing: list[float], size: int, reps: int, png: Path | None = None) -> dict:
    """Best first-render and re-render times of VTK's fixed-point ray caster, seconds."""
    lo, hi = float(v.min()), float(v.max())
    image = vtk.vtkImageData()
    image.SetDimensions(v.shape[2], v.shape[1], v.shape[0])
    image.SetSpacing(*spacing)
    image.GetPointData().SetScalars(numpy_support.numpy_to_vtk(v.ravel(), deep=True))
    colour = vtk.vtkColorTransferFunction()
    colour.AddRGBPoint(lo, 0.2, 0.4, 1.0)
    colour.AddRGBPoint(hi, 1.0, 0.7, 0.3)
    opacity = vtk.vtkPiecewiseFunction()
    opacity.AddPoint(lo, 0.0)
    opacity.AddPoint(lo + 0.3 * (hi - lo), 0.0)
    opacity.AddPoint(lo + 0.5 * (hi - lo), 0.3)
    opacity.AddPoint(hi, 0.6)
    gradient = vtk.vtkPiecewiseFunction()
    gradient.AddPoint(0.0, 0.0)
    gradient.AddPoint(0.05 * (hi - lo), 1.0)
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(colour)
    prop.SetScalarOpacity(opacity)
    prop.SetGradientOpacity(gradient)
    prop.ShadeOn()
    prop.SetInterpolationTypeToLinear()
    best_first, best_again = float("inf"), float("inf")
    for _ in range(reps):
        mapper = vtk.vtkFixedPointVolumeRayCastMapper()
        mapper.SetInputData(image)
        mapper.SetSampleDistance(0.5 * min(spacing))
        mapper.SetAutoAdjustSampleDistances(False)
        volume = vtk.vtkVolume()
        volume.SetMapper(mapper)
        volume.SetProperty(prop)
        renderer = vtk.vtkRenderer()
        renderer.AddVolume(volume)
        window = vtk.vtkRenderWindow()
        window.SetOffScreenRendering(1)
        window.SetSize(size, size)
        window.AddRenderer(renderer)
        renderer.ResetCamera()
        renderer.GetActiveCamera().Azimuth(30)
        renderer.GetActiveCamera().Elevation(20)
        t = time.perf_counter()
        window.Render()
        best_first = min(best_first, time.perf_counter() - t)
        t = time.perf_counter()
        renderer.GetActiveCamera().Azimuth(1e-3)
        window.Render()
        best_again = min(best_again, time.perf_counter() - t)
        if png is not None:
            save_png(window, png)
        window.Finalize()
    return {"vtk_first_render_s": round(best_first, 3), "vtk_render_again_s": round(best_again, 3),
            "vtk_threads": vtk.vtkMultiThreader.GetGlobalDefaultNumberOfThreads()}


def mdtf_preview(mdtf: Path, pack: Path, size: int, reps: int) -> float:
    """Best whole-process time of ``mdtf preview``, seconds."""
    best = float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(reps):
            t = time.perf_counter()
            subprocess.run([mdtf, "-q", "preview", pack, "--size", str(size), "-o", Path(tmp) / "p.png"], check=True)
            best = min(best, time.perf_counter() - t)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mdtf", type=Path, required=True)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--pictures", type=Path, default=None, help="a folder for both pictures of each pack")
    ap.add_argument("packs", type=Path, nargs="+")
    args = ap.parse_args()
    for pack in args.packs:
        v, spacing = pack_value(pack)
        result = {"pack": str(pack), "dims": list(v.shape[::-1]), "size": args.size}
        result["mdtf_preview_s"] = round(mdtf_preview(args.mdtf.resolve(), pack, args.size, args.reps), 3)
        png = None
        if args.pictures:
            args.pictures.mkdir(parents=True, exist_ok=True)
            png = args.pictures / f"{pack.parent.name}-vtk.png"
            subprocess.run([args.mdtf.resolve(), "-q", "preview", pack, "--size", str(args.size), "-o",
                            args.pictures / f"{pack.parent.name}-mdtf.png"], check=True)
        result.update(vtk_render(v, spacing, args.size, args.reps, png))
        result["vtk_first_over_mdtf"] = round(result["vtk_first_render_s"] / result["mdtf_preview_s"], 2)
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
