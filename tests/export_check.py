"""Independent checks of `mdtf export` output, run by tests/export.rs.

    export_check.py vti PACK EXPORT   -> JSON: volume.vti read by vtk and by the file format's
                                         documented layout, against the pack decoded from its manifest
    export_check.py vp PACK EXPORT    -> JSON: volume_property.vp parsed by Slicer's documented
                                         layout, against the marginals of the pack's 2D table
    export_check.py nrrd PACK EXPORT  -> JSON: v.nrrd read by pynrrd against the pack's v

The pack is decoded here from manifest.json alone (value = offset + scale * code), not by mdtf.
"""

import json
import os
import sys
import xml.etree.ElementTree as ET
import zlib

import numpy as np


def pack_channels(pack):
    """Every channel of the pack, decoded from the manifest: name -> (z, y, x) float64 array, its scale."""
    m = json.load(open(os.path.join(pack, "manifest.json")))
    nx, ny, nz = m["geometry"]["dims"]
    out = {}
    for t in m["textures"]:
        dtype = {"u8": "<u1", "u16": "<u2", "f16": "<f2", "f32": "<f4"}[t["dtype"]]
        codes = np.fromfile(os.path.join(pack, t["data"]), dtype=dtype).reshape(nz, ny, nx, t["components"])
        for c in m["channels"]:
            if c["texture"] == t["name"] and c["name"] not in out:
                d = c["decode"]
                out[c["name"]] = (d["offset"] + d["scale"] * codes[..., c["component"]].astype(np.float64), d["scale"])
    return m, out


def vti_by_layout(path):
    """A .vti with appended raw zlib data, read by the layout VTK documents (UInt64 headers)."""
    raw = open(path, "rb").read()
    start = raw.index(b"<AppendedData")
    under = raw.index(b"_", start) + 1
    root = ET.fromstring(raw[:start].decode() + "</VTKFile>")
    assert root.get("header_type") == "UInt64" and root.get("compressor") == "vtkZLibDataCompressor"
    image = root.find("ImageData")
    arrays = {}
    for a in image.find("Piece").find("PointData").findall("DataArray"):
        at = under + int(a.get("offset"))
        words = lambda i, n: np.frombuffer(raw, "<u8", n, at + 8 * i)  # noqa: E731
        nblocks, block, last = (int(w) for w in words(0, 3))
        sizes = [int(s) for s in words(3, nblocks)]
        data, pos = b"", at + 8 * (3 + nblocks)
        for k, s in enumerate(sizes):
            piece = zlib.decompress(raw[pos : pos + s])
            assert len(piece) == (last if k == nblocks - 1 and last else block)
            data += piece
            pos += s
        arrays[a.get("Name")] = np.frombuffer(data, "<f4").reshape(-1, int(a.get("NumberOfComponents")))
    floats = lambda k: [float(x) for x in image.get(k).split()]  # noqa: E731
    return {"origin": floats("Origin"), "spacing": floats("Spacing"), "direction": floats("Direction")}, arrays


def vti_by_vtk(path):
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkIOXML import vtkXMLImageDataReader

    r = vtkXMLImageDataReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    pd = img.GetPointData()
    arrays = {pd.GetArrayName(i): numpy_support.vtk_to_numpy(pd.GetArray(i)).reshape(img.GetNumberOfPoints(), -1)
              for i in range(pd.GetNumberOfArrays())}
    m = img.GetDirectionMatrix()
    direction = [m.GetElement(r, c) for r in range(3) for c in range(3)]
    geometry = {"origin": list(img.GetOrigin()), "spacing": list(img.GetSpacing()), "direction": direction,
                "dims": list(img.GetDimensions())}
    return geometry, arrays


def check_vti(pack, export):
    m, channels = pack_channels(pack)
    g = m["geometry"]
    w = np.array(g["world_from_voxel"])
    spacing = np.array(g["spacing"])
    want = {"origin": list(w[:3, 3]), "spacing": list(spacing), "direction": list((w[:3, :3] / spacing).ravel())}
    report = {}
    for reader, (geometry, arrays) in (("vtk", vti_by_vtk(os.path.join(export, "volume.vti"))),
                                       ("layout", vti_by_layout(os.path.join(export, "volume.vti")))):
        worst = 0.0
        names = []
        for name, (values, scale) in channels.items():
            if name in ("nx", "ny", "nz"):
                got = arrays["normal"][:, "xyz".index(name[1])]
            else:
                got = arrays[name][:, 0]
            names.append(name)
            # in units of a quantisation step; 0.5 is the tolerance the issue allows
            worst = max(worst, float(np.max(np.abs(got - values.ravel())) / scale))
        report[reader] = {
            "worst_steps": worst,
            "channels": sorted(names),
            "arrays": sorted(arrays),
            "geometry_error": max(float(np.max(np.abs(np.array(geometry[k]) - np.array(want[k])))) for k in want),
            "dims": geometry.get("dims", g["dims"]),
        }
    print(json.dumps(report))


def parse_vp(path):
    """volume_property.vp by the layout of Slicer's volume-rendering docs."""
    lines = [ln.split() for ln in open(path).read().strip().split("\n")]
    settings = [float(ln[0]) for ln in lines[:6]]
    funcs = []
    for ln, per in zip(lines[6:9], (2, 2, 4)):
        n = int(ln[0])
        values = np.array([float(x) for x in ln[1:]])
        assert len(values) == n and n % per == 0, (n, len(values))
        funcs.append(values.reshape(-1, per))
    assert len(lines) == 9
    return settings, funcs


def check_vp(pack, export):
    import nrrd

    m = json.load(open(os.path.join(pack, "manifest.json")))
    info = json.load(open(os.path.join(export, "export.json")))
    lut = next(t for t in m["luts"] if t["name"] == info["tf"]["source"])
    table, _ = nrrd.read(os.path.join(pack, lut["file_f32"]), index_order="C")  # (ny, nx, 4)
    (ax, ay) = lut["axes"]
    alpha, rgb = table[..., 3].astype(np.float64), table[..., :3].astype(np.float64)
    cx = ax["min"] + (np.arange(ax["size"]) + 0.5) * (ax["max"] - ax["min"]) / ax["size"]
    cy = ay["min"] + (np.arange(ay["size"]) + 0.5) * (ay["max"] - ay["min"]) / ay["size"]
    scalar = alpha.max(axis=0)
    weight = alpha.sum(axis=0)
    colour = np.where(weight[:, None] > 0, (alpha[..., None] * rgb).sum(axis=0) / np.maximum(weight, 1e-300)[:, None], 1.0)
    gradient = alpha.max(axis=1) / alpha.max() if alpha.max() > 0 else np.zeros(ay["size"])
    settings, (so, go, co) = parse_vp(os.path.join(export, "volume_property.vp"))
    print(json.dumps({
        "settings": settings,
        "scalar_error": float(max(np.abs(so[:, 0] - cx).max(), np.abs(so[:, 1] - scalar).max())),
        "gradient_error": float(max(np.abs(go[:, 0] - cy).max(), np.abs(go[:, 1] - gradient).max())),
        "colour_error": float(max(np.abs(co[:, 0] - cx).max(), np.abs(co[:, 1:] - colour).max())),
        "points": [len(so), len(go), len(co)],
        "peak_scalar_opacity": float(scalar.max()),
    }))


def check_nrrd(pack, export):
    import nrrd

    m, channels = pack_channels(pack)
    data, header = nrrd.read(os.path.join(export, "v.nrrd"), index_order="C")
    values, scale = channels["v"]
    w = np.array(m["geometry"]["world_from_voxel"])
    directions = np.array(header["space directions"], float)  # rows: axes
    origin = np.array(header["space origin"], float)
    # NRRD in LPS or RAS: bring it to RAS as the manifest is
    flip = np.array([-1.0, -1.0, 1.0]) if header["space"] in ("left-posterior-superior", "LPS") else np.ones(3)
    print(json.dumps({
        "worst_steps": float(np.max(np.abs(data.astype(np.float64) - values)) / scale),
        "geometry_error": float(max(np.abs(directions * flip - w[:3, :3].T).max(), np.abs(origin * flip - w[:3, 3]).max())),
        "encoding": header["encoding"],
    }))


if __name__ == "__main__":
    {"vti": check_vti, "vp": check_vp, "nrrd": check_nrrd}[sys.argv[1]](sys.argv[2], sys.argv[3])
