"""Render an mdtf export with VTK's GPU ray caster in its 2D transfer-function mode.

Written by `mdtf export --to vtk`. Needs the `vtk` Python package (9.3 or
later) and numpy. Offscreen on a machine without a display:
VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow (or vtkOSOpenGLRenderWindow).

    python render_vtk.py -o render.png --view 30,20 --size 512
    python render_vtk.py --window
"""

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import mdtf_vtk_tf as mdtf  # noqa: E402
from vtkmodules.vtkIOImage import vtkPNGWriter  # noqa: E402
from vtkmodules.vtkRenderingCore import (  # noqa: E402
    vtkRenderer,
    vtkRenderWindow,
    vtkRenderWindowInteractor,
    vtkVolume,
    vtkVolumeProperty,
    vtkWindowToImageFilter,
)
from vtkmodules.vtkRenderingVolume import vtkGPUVolumeRayCastMapper  # noqa: E402
import vtkmodules.vtkRenderingOpenGL2  # noqa: E402,F401  (the OpenGL back end)
import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: E402,F401


def pair(text, name):
    try:
        a, b = (float(t) for t in text.split(","))
    except ValueError:
        raise SystemExit(f"{name}: expected two numbers A,B, got {text!r}")
    return a, b


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folder", nargs="?", default=mdtf.HERE, help="export folder (default: this script's)")
    ap.add_argument("-o", "--output", default="render.png", help="PNG to write (default render.png)")
    ap.add_argument("--view", default="30,20", help="AZIMUTH,ELEVATION in degrees, as mdtf preview (default 30,20)")
    ap.add_argument("--size", type=int, default=512, help="image width and height, pixels (default 512)")
    ap.add_argument("--step", type=float, default=0.5, help="sample spacing, in L_min (default 0.5)")
    ap.add_argument("--window", action="store_true", help="open an interactive window instead of writing a PNG")
    ap.add_argument(
        "--y-range",
        help="LO,HI: stretch the table's Y axis over this range instead of the Y array's data range "
        "(for experiments: anything but the data range misplaces the table)",
    )
    args = ap.parse_args()
    info = mdtf.load_export(args.folder)
    tf = info.get("tf")
    if not tf:
        raise SystemExit("this export has no transfer function to render with: " + "; ".join(info["notes"]))
    volume = mdtf.read_vti(os.path.join(args.folder, info["volume"]))
    # rendered in the grid's own frame, where VTK shades correctly (see in_grid_frame)
    mdtf.in_grid_frame(volume)
    table = mdtf.read_vti(os.path.join(args.folder, tf["file"]))
    x_range = mdtf.array_range(volume, tf["x"])
    y_range = list(pair(args.y_range, "--y-range")) if args.y_range else mdtf.array_range(volume, tf["y"])
    sample_distance = args.step * tf["opacity_unit"]

    prop = vtkVolumeProperty()
    prop.SetTransferFunction2D(mdtf.calibrated_tf(table, tf, x_range, y_range, sample_distance))
    prop.SetTransferFunctionModeTo2D()
    prop.SetInterpolationTypeToLinear()
    mdtf.apply_lighting(prop, info)

    mapper = vtkGPUVolumeRayCastMapper()
    mapper.SetInputData(volume)
    mapper.SetScalarModeToUsePointFieldData()
    mapper.SelectScalarArray(tf["x"])
    mapper.SetTransfer2DYAxisArray(tf["y"])
    mapper.SetAutoAdjustSampleDistances(0)
    mapper.SetSampleDistance(sample_distance)
    mapper.SetUseJittering(0)

    actor = vtkVolume()
    actor.SetMapper(mapper)
    actor.SetProperty(prop)
    renderer = vtkRenderer()
    renderer.SetBackground(0.0, 0.0, 0.0)
    renderer.AddVolume(actor)
    window = vtkRenderWindow()
    window.AddRenderer(renderer)
    window.SetSize(args.size, args.size)
    window.SetMultiSamples(0)
    azimuth, elevation = pair(args.view, "--view")
    mdtf.mdtf_view(renderer, info, azimuth, elevation, world=False)
    mdtf.mdtf_light(renderer)
    if args.window:
        from vtkmodules.vtkInteractionStyle import vtkInteractorStyleTrackballCamera

        interactor = vtkRenderWindowInteractor()
        interactor.SetRenderWindow(window)
        interactor.SetInteractorStyle(vtkInteractorStyleTrackballCamera())
        window.Render()
        interactor.Start()
        return
    window.SetOffScreenRendering(1)
    window.Render()
    grab = vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.SetInputBufferTypeToRGB()
    grab.ReadFrontBufferOff()
    grab.Update()
    writer = vtkPNGWriter()
    writer.SetFileName(args.output)
    writer.SetInputConnection(grab.GetOutputPort())
    writer.Write()
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
