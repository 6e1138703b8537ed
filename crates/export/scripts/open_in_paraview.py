"""Open an mdtf export in ParaView with its 2D transfer function.

Written by `mdtf export --to paraview`. Run it with ParaView 5.11 or later:

    pvpython open_in_paraview.py                          # a window
    pvbatch open_in_paraview.py --screenshot shot.png     # offscreen, one picture

or in the ParaView GUI: View > Python Shell > Run Script. It loads
volume.vti, shows it as a volume coloured by the TF's X array, selects the
2D transfer-function mode with the TF's Y array (not the gradient computed
by ParaView), and installs mdtf's table, calibrated to the arrays' ranges
as VTK's 2D mode reads it (see mdtf_vtk_tf.py). ParaView's own 2D TF
editor edits boxes; mdtf's table is installed on the volume's property, so
editing the TF in the GUI replaces it. The volume is shown in its grid's
own frame (voxel (i, j, k) at (i sx, j sy, k sz)): ParaView 5.11 misplaces
and VTK's ray caster misshades images with rotated axes (see
mdtf_vtk_tf.in_grid_frame). `--world` places it by the grid's origin and
axes instead, to line it up with other data.
"""

import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import mdtf_vtk_tf as mdtf  # noqa: E402
from paraview import simple as pv  # noqa: E402


# a Programmable Filter's scripts: the input image with origin 0 and axes along x, y, z
GRID_FRAME_SCRIPT = """
out = self.GetOutput()
out.ShallowCopy(self.GetInput())
out.SetOrigin(0.0, 0.0, 0.0)
out.SetDirectionMatrix(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
"""
GRID_FRAME_INFORMATION = """
from paraview import util
info = self.GetInputInformation(0, 0)
extent = info.Get(vtk.vtkStreamingDemandDrivenPipeline.WHOLE_EXTENT())
util.SetOutputWholeExtent(self, extent)
"""


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--screenshot", help="write this PNG and exit")
    ap.add_argument("--view", default="30,20", help="AZIMUTH,ELEVATION in degrees, as mdtf preview (default 30,20)")
    ap.add_argument("--size", type=int, default=512, help="screenshot width and height, pixels (default 512)")
    ap.add_argument("--step", type=float, default=0.5, help="sample spacing, in L_min (default 0.5)")
    ap.add_argument(
        "--world",
        action="store_true",
        help="place the volume in the world (the grid's origin and axes) instead of its own frame; "
        "ParaView 5.11 misplaces and misshades images with rotated axes",
    )
    args = ap.parse_args(argv)
    info = mdtf.load_export(HERE)
    tf = info.get("tf")
    if not tf:
        raise SystemExit("this export has no transfer function: " + "; ".join(info["notes"]))

    reader = pv.XMLImageDataReader(registrationName="mdtf volume", FileName=[os.path.join(HERE, info["volume"])])
    source = reader
    if not args.world:
        # the grid's own frame, where VTK's ray caster shades correctly (see mdtf_vtk_tf.in_grid_frame)
        source = pv.ProgrammableFilter(registrationName="mdtf volume (grid frame)", Input=reader)
        source.OutputDataSetType = "vtkImageData"
        source.Script = GRID_FRAME_SCRIPT
        source.RequestInformationScript = GRID_FRAME_INFORMATION
    view = pv.GetActiveViewOrCreate("RenderView")
    view.OrientationAxesVisibility = 0
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.Background = [0.0, 0.0, 0.0]
    display = pv.Show(source, view)
    display.SetRepresentationType("Volume")
    pv.ColorBy(display, ("POINTS", tf["x"]))
    display.UseTransfer2D = 1
    display.UseGradientForTransfer2D = 0
    display.ColorArray2Name = ["POINTS", tf["y"]]
    ambient, diffuse, specular, power = info["lighting"]
    display.Shade = 1 if info["shade"] else 0
    display.Ambient, display.Diffuse, display.Specular, display.SpecularPower = ambient, diffuse, specular, power
    pv.Render(view)

    # mdtf's table replaces the one ParaView built from its (empty) box list
    renderer = view.GetRenderer()
    volumes = renderer.GetVolumes()
    volumes.InitTraversal()
    volume = volumes.GetNextVolume()
    if volume is None:
        raise SystemExit("ParaView made no volume of volume.vti (is its volume rendering available?)")
    image = source.GetClientSideObject().GetOutput()
    x_range = mdtf.array_range(image, tf["x"])
    y_range = mdtf.array_range(image, tf["y"])
    sample_distance = args.step * tf["opacity_unit"]
    table = mdtf.read_vti(os.path.join(HERE, tf["file"]))
    prop = volume.GetProperty()
    prop.SetTransferFunction2D(mdtf.calibrated_tf(table, tf, x_range, y_range, sample_distance))
    prop.SetTransferFunctionModeTo2D()
    mapper = volume.GetMapper()
    if hasattr(mapper, "SetAutoAdjustSampleDistances"):
        mapper.SetAutoAdjustSampleDistances(0)
        mapper.SetSampleDistance(sample_distance)

    azimuth, elevation = (float(t) for t in args.view.split(","))
    mdtf.mdtf_view(renderer, info, azimuth, elevation, world=args.world)
    camera = renderer.GetActiveCamera()
    view.CameraPosition = list(camera.GetPosition())
    view.CameraFocalPoint = list(camera.GetFocalPoint())
    view.CameraViewUp = list(camera.GetViewUp())
    view.CameraParallelProjection = 1
    view.CameraParallelScale = camera.GetParallelScale()
    # the preview's light instead of ParaView's light kit
    view.UseLight = 0
    light = pv.AddLight(view=view)
    light.Coords = "Camera"
    light.Type = "Directional"
    light.Position = [0.0, 0.3, 1.0]
    light.FocalPoint = [0.0, 0.0, 0.0]
    pv.Render(view)
    # ParaView's light proxy has no ambient colour (black in VTK by default)
    lights = renderer.GetLights()
    lights.InitTraversal()
    for _ in range(lights.GetNumberOfItems()):
        lights.GetNextItem().SetAmbientColor(1.0, 1.0, 1.0)
    renderer.SetTwoSidedLighting(True)
    if args.screenshot:
        view.ViewSize = [args.size, args.size]
        pv.SaveScreenshot(args.screenshot, view, ImageResolution=[args.size, args.size])
        print(f"wrote {args.screenshot}")
    else:
        pv.Render(view)
        pv.Interact(view)


if __name__ == "__main__":
    main(sys.argv[1:])
