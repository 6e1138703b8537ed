"""Helpers shared by render_vtk.py and open_in_paraview.py (written by `mdtf export`).

VTK's 2D transfer-function mode looks its table up at (x, y), each array's
value normalised by that array's own data range, and uses the table's
opacity per sample as it is. mdtf's table is over the pack's channel units
with opacity per L_min (the smallest grid spacing) of path. `calibrated_tf`
turns the one into the other.
"""

import json
import math
import os

import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonDataModel import vtkImageData
from vtkmodules.vtkIOXML import vtkXMLImageDataReader
from vtkmodules.vtkRenderingCore import vtkLight

HERE = os.path.dirname(os.path.abspath(__file__))
LARGEST_TABLE = 4096
SUPERSAMPLING = 4


def load_export(folder=HERE):
    """export.json of the export folder, as a dict."""
    with open(os.path.join(folder, "export.json"), encoding="utf-8") as f:
        return json.load(f)


def read_vti(path):
    """A .vti file as vtkImageData."""
    reader = vtkXMLImageDataReader()
    reader.SetFileName(path)
    reader.Update()
    if reader.GetErrorCode() or reader.GetOutput().GetNumberOfPoints() == 0:
        raise SystemExit(f"{path}: not a readable VTK image")
    return reader.GetOutput()


def array_range(image, name):
    """[min, max] of point array `name`, as VTK normalises it."""
    array = image.GetPointData().GetArray(name)
    if array is None:
        names = [image.GetPointData().GetArrayName(i) for i in range(image.GetPointData().GetNumberOfArrays())]
        raise SystemExit(f"the volume has no array {name!r} (it has {', '.join(names)})")
    return list(array.GetRange(0))


def table_cells(span_data, span_table, cells):
    """Texels along an axis: SUPERSAMPLING per table cell over the data range.

    VTK interpolates the table linearly where mdtf's renderers take the
    nearest cell; with several texels per cell the two differ only within
    1 / (2 SUPERSAMPLING) of a cell of each cell edge.
    """
    per_cell = SUPERSAMPLING * cells / span_table if span_table > 0 else SUPERSAMPLING
    return int(min(LARGEST_TABLE, max(cells, math.ceil(per_cell * span_data))))


def calibrated_tf(tf_image, tf, x_range, y_range, sample_distance):
    """The table of `tf_image` (`tf` its export.json entry) as VTK's 2D mode needs it.

    Texel (i, j) of the result holds the table's cell at
    x = x_range[0] + (i + 1/2) (x_range[1] - x_range[0]) / nx (and likewise y),
    so that VTK's lookup at the normalised array values reads the cell mdtf
    reads; values outside the table take its edge cells, as mdtf's renderers
    do. Opacity a per opacity_unit becomes 1 - (1 - a)^(sample_distance /
    opacity_unit) per sample.
    """
    nx, ny = tf["cells"]
    rgba = numpy_support.vtk_to_numpy(tf_image.GetPointData().GetScalars()).reshape(ny, nx, 4)
    (x0, x1), (y0, y1) = tf["x_range"], tf["y_range"]
    mx = table_cells(x_range[1] - x_range[0], x1 - x0, nx)
    my = table_cells(y_range[1] - y_range[0], y1 - y0, ny)
    xs = x_range[0] + (np.arange(mx) + 0.5) * (x_range[1] - x_range[0]) / mx
    ys = y_range[0] + (np.arange(my) + 0.5) * (y_range[1] - y_range[0]) / my
    ix = np.clip(np.floor((xs - x0) / (x1 - x0) * nx), 0, nx - 1).astype(int)
    iy = np.clip(np.floor((ys - y0) / (y1 - y0) * ny), 0, ny - 1).astype(int)
    out = rgba[iy[:, None], ix[None, :]].astype(np.float64)
    alpha = np.minimum(out[..., 3], 0.999)
    out[..., 3] = 1.0 - (1.0 - alpha) ** (sample_distance / tf["opacity_unit"])
    image = vtkImageData()
    image.SetDimensions(mx, my, 1)
    array = numpy_support.numpy_to_vtk(out.reshape(-1, 4).astype(np.float32), deep=1)
    array.SetName("rgba")
    image.GetPointData().SetScalars(array)
    return image


def frame(info, world=True):
    """Centre, radius, and the grid-to-world rotation of the pack's grid.

    In the grid's own frame (`world=False`: voxel (i, j, k) at (i sx, j sy,
    k sz)) the rotation is the identity.
    """
    g = info["geometry"]
    dims, spacing = np.array(g["dims"], float), np.array(g["spacing"], float)
    m = np.array(g["world_from_voxel"], float)
    rotation = m[:3, :3] / spacing[None, :] if world else np.eye(3)
    origin = m[:3, 3] if world else np.zeros(3)
    extent = (dims - 1.0) * spacing
    centre = origin + rotation @ (extent / 2.0)
    return centre, float(np.linalg.norm(extent)) / 2.0, rotation


def in_grid_frame(image):
    """Places `image` in its grid's own frame: origin 0, axes along x, y, z.

    VTK's GPU ray caster (9.7) lights an image whose axes are rotated (by
    its direction matrix or the volume's matrix) as if its gradients were
    not, so shading is right only for an axis-aligned image; the picture
    of a grid seen from a camera turned with it is the same.
    """
    image.SetOrigin(0.0, 0.0, 0.0)
    image.SetDirectionMatrix(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


def mdtf_view(renderer, info, azimuth, elevation, world=True):
    """Points the renderer's camera as `mdtf preview --view AZ,EL` does.

    Orthographic, looking along -(cos el cos az, cos el sin az, sin el) in
    the grid's frame, the image framing the grid's diagonal; for an image
    placed in the world (`world`), that view turned with the grid. A grid
    whose axes form a left-handed frame shows mirrored against the preview
    there, which renders in the grid's frame.
    """
    centre, radius, rotation = frame(info, world)
    az, el = math.radians(azimuth), math.radians(elevation)
    d = np.array([-math.cos(el) * math.cos(az), -math.cos(el) * math.sin(az), -math.sin(el)])
    right = np.array([-math.sin(az), math.cos(az), 0.0])
    up = -np.cross(d, right)
    d, up = rotation @ d, rotation @ up
    camera = renderer.GetActiveCamera()
    camera.ParallelProjectionOn()
    camera.SetFocalPoint(*centre)
    camera.SetPosition(*(centre - 4.0 * radius * d))
    camera.SetViewUp(*up)
    camera.SetParallelScale(radius)
    renderer.ResetCameraClippingRange()


def mdtf_light(renderer):
    """The preview's light: from the camera, tilted 0.3 towards its up vector; two-sided."""
    light = vtkLight()
    light.SetLightTypeToCameraLight()
    light.SetPosition(0.0, 0.3, 1.0)
    light.SetFocalPoint(0.0, 0.0, 0.0)
    # the ambient term is lit by the light's ambient colour, black by default
    light.SetAmbientColor(1.0, 1.0, 1.0)
    renderer.AutomaticLightCreationOff()
    renderer.RemoveAllLights()
    renderer.AddLight(light)
    renderer.SetTwoSidedLighting(True)


def apply_lighting(prop, info):
    """Shading on (with the preview's coefficients) when the pack has normals."""
    ambient, diffuse, specular, power = info["lighting"]
    if info["shade"]:
        prop.ShadeOn()
        prop.SetAmbient(ambient)
        prop.SetDiffuse(diffuse)
        prop.SetSpecular(specular)
        prop.SetSpecularPower(power)
    else:
        prop.ShadeOff()
