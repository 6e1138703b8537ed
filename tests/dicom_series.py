"""Writes the DICOM series of tests/dicom.rs with pydicom, and reads the
regular ones back with SimpleITK's ImageSeriesReader (GDCM) as the
independent reference. Prints one JSON object: for each case the truth
(values z, y, x order, as float) and SimpleITK's geometry and values (LPS).

usage: python dicom_series.py OUT_DIR
"""

import json
import os
import shutil
import sys
import uuid

import numpy as np
import pydicom
import SimpleITK as sitk
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

ENHANCED_CT = "1.2.840.10008.5.1.4.1.1.2.1"
rng = np.random.default_rng(7)
out_dir = sys.argv[1]
result = {}


def base(sop_class, series_uid, number, desc):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = sop_class
    sop = generate_uid()
    meta.MediaStorageSOPInstanceUID = sop
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = sop
    ds.Modality = "CT"
    ds.StudyInstanceUID = STUDY
    ds.FrameOfReferenceUID = FRAME
    ds.SeriesInstanceUID = series_uid
    ds.SeriesNumber = number
    ds.SeriesDescription = desc
    # patient attributes that must never appear in mdtf's output
    ds.PatientName = "Doe^Jane"
    ds.PatientID = "PID-93731"
    ds.PatientBirthDate = "19230417"
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    return ds


STUDY = generate_uid()
FRAME = generate_uid()


def write_slice(folder, stored, ipp, iop, ps, rescale, series_uid, number=1, desc="test", name=None,
                instance=1, bits_stored=16, signed=True):
    os.makedirs(folder, exist_ok=True)
    ds = base(CTImageStorage, series_uid, number, desc)
    ds.InstanceNumber = instance
    ds.ImagePositionPatient = [float(v) for v in ipp]
    ds.ImageOrientationPatient = [float(v) for v in iop]
    ds.PixelSpacing = [float(v) for v in ps]
    ds.SliceThickness = 1.0
    ds.Rows, ds.Columns = stored.shape
    ds.BitsAllocated = 16
    ds.BitsStored = bits_stored
    ds.HighBit = bits_stored - 1
    ds.PixelRepresentation = 1 if signed else 0
    ds.RescaleSlope = f"{rescale[0]:.6g}"
    ds.RescaleIntercept = f"{rescale[1]:.6g}"
    ds.PixelData = stored.astype("<i2" if signed else "<u2").tobytes()
    path = os.path.join(folder, name or f"{uuid.uuid4().hex}.dcm")
    ds.save_as(path, enforce_file_format=True)
    return path


def rotation(ax, ay):
    cx, sx, cy, sy = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    return ry @ rx


def sitk_read(folder, files=None):
    r = sitk.ImageSeriesReader()
    r.SetFileNames(files or r.GetGDCMSeriesFileNames(folder))
    r.SetOutputPixelType(sitk.sitkFloat64)
    img = r.Execute()
    return {
        "origin": list(img.GetOrigin()),
        "spacing": list(img.GetSpacing()),
        "direction": list(img.GetDirection()),
        "size": list(img.GetSize()),
        "values": sitk.GetArrayFromImage(img).ravel().tolist(),
    }


def stack(folder, nz, gap, rows=12, cols=10, ps=(0.8, 0.6), rot=(0.3, -0.2), origin=(-40.0, 25.0, 10.0),
          series_uid=None, number=1, desc="test", shear=(0.0, 0.0), varying_rescale=True, skip=(),
          value=None):
    """A stack of slices; value(x, y, z) of LPS world position gives each pixel's value."""
    series_uid = series_uid or generate_uid()
    r = rotation(*rot)
    row_dir, col_dir, normal = r[:, 0], r[:, 1], r[:, 2]
    iop = list(row_dir) + list(col_dir)
    value = value or (lambda x, y, z: 3.0 * x - 2.0 * y + 5.0 * z)
    order = rng.permutation(nz)
    truth = {}
    paths = {}
    for k in order:
        if k in skip:
            continue
        ipp = np.array(origin) + k * gap * normal + k * (shear[0] * row_dir + shear[1] * col_dir)
        j, i = np.mgrid[0:rows, 0:cols]
        world = ipp[:, None, None] + i * ps[1] * row_dir[:, None, None] + j * ps[0] * col_dir[:, None, None]
        slope, inter = (1.0 + 0.25 * (k % 3), -1024.0 + 7 * k) if varying_rescale else (1.0, -1024.0)
        stored = np.round((value(*world) - inter) / slope).astype(np.int16)
        truth[int(k)] = (stored * slope + inter).astype(np.float64)
        paths[int(k)] = write_slice(folder, stored, ipp, iop, ps, (slope, inter), series_uid, number, desc,
                                    instance=int(rng.integers(1, 1000)))
    return truth, paths, series_uid


def ordered(truth):
    return np.stack([truth[k] for k in sorted(truth)]).ravel().tolist()


# a regular oblique stack, shuffled names and InstanceNumbers, rescale varying per slice
d = os.path.join(out_dir, "oblique")
truth, paths, _ = stack(d, 9, 1.5)
result["oblique"] = {"truth": ordered(truth), "sitk": sitk_read(d)}

# one rescale for the whole series, as dcm2niix (one scl_slope per file) can store it
d = os.path.join(out_dir, "oblique-uniform")
truth_u, _, _ = stack(d, 7, 2.5, rot=(0.25, 0.4), varying_rescale=False)
result["oblique-uniform"] = {"truth": ordered(truth_u)}

# the same files named by a list, in another order
with open(os.path.join(out_dir, "oblique.txt"), "w") as f:
    for p in sorted(paths.values(), reverse=True):
        f.write(os.path.relpath(p, out_dir) + "\n")

# two series in one folder
d = os.path.join(out_dir, "two")
t7, _, uid7 = stack(d, 3, 2.0, number=7, desc="first")
t9, _, uid9 = stack(d, 4, 2.0, number=9, desc="second", value=lambda x, y, z: x + y + z + 500)
result["two"] = {"uid9": uid9, "truth9": ordered(t9), "truth7": ordered(t7)}

# a missing slice: values linear in position, so linear interpolation is exact
d = os.path.join(out_dir, "missing")
truth, _, _ = stack(d, 8, 2.0, varying_rescale=False, skip=(5,), rot=(0.0, 0.0))
full, _, _ = stack(os.path.join(out_dir, "missing-full"), 8, 2.0, varying_rescale=False, rot=(0.0, 0.0))
result["missing"] = {"truth_full": ordered(full)}

# two different images at one position, and a copied file
d = os.path.join(out_dir, "dup")
truth, paths, uid = stack(d, 4, 2.0)
ds = pydicom.dcmread(paths[2])
ds.SOPInstanceUID = generate_uid()
ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
ds.save_as(os.path.join(d, "another-at-2.dcm"), enforce_file_format=True)
d = os.path.join(out_dir, "copy")
truth, paths, uid = stack(d, 4, 2.0)
shutil.copy(paths[1], os.path.join(d, "copy-of-1.dcm"))
result["copy"] = {"truth": ordered(truth)}

# gantry tilt: each slice shifted 0.5 mm along the rows per 2 mm step (14.0 degrees)
d = os.path.join(out_dir, "tilt")
tilt_value = lambda x, y, z: 10.0 * x + 4.0 * y - 3.0 * z + 100.0
truth, _, _ = stack(d, 6, 2.0, shear=(0.5, 0.0), varying_rescale=False, value=tilt_value, rows=12, cols=16)
result["tilt"] = {"rot": rotation(0.3, -0.2).tolist()}

# unsigned 12-bit samples with overlay bits above the high bit
d = os.path.join(out_dir, "bits12")
stored = rng.integers(0, 4096, size=(6, 5)).astype(np.uint16)
junk = stored | (rng.integers(0, 16, size=stored.shape).astype(np.uint16) << 12)
write_slice(d, junk, (0, 0, 0), (1, 0, 0, 0, 1, 0), (1, 1), (1.0, 0.0), generate_uid(), bits_stored=12, signed=False)
result["bits12"] = {"truth": stored.astype(np.float64).ravel().tolist()}

# an enhanced CT: one file, frames in reverse order, per-frame positions
nz, rows, cols = 5, 4, 3
r = rotation(0.1, 0.2)
row_dir, col_dir, normal = r[:, 0], r[:, 1], r[:, 2]
ds = base(ENHANCED_CT, generate_uid(), 3, "enhanced")
ds.InstanceNumber = 1
ds.NumberOfFrames = nz
ds.Rows, ds.Columns = rows, cols
ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 1
shared = Dataset()
pm = Dataset()
pm.PixelSpacing = [0.7, 0.9]
pm.SliceThickness = 1.25
po = Dataset()
po.ImageOrientationPatient = list(row_dir) + list(col_dir)
pv = Dataset()
pv.RescaleSlope, pv.RescaleIntercept, pv.RescaleType = 2, -100, "HU"
shared.PixelMeasuresSequence = [pm]
shared.PlaneOrientationSequence = [po]
shared.PixelValueTransformationSequence = [pv]
ds.SharedFunctionalGroupsSequence = [shared]
frames = []
values = []
for f in range(nz):
    k = nz - 1 - f
    pos = Dataset()
    pos.ImagePositionPatient = list(np.array([5.0, -3.0, 20.0]) + k * 1.25 * normal)
    item = Dataset()
    item.PlanePositionSequence = [pos]
    frames.append(item)
    values.append(np.arange(rows * cols, dtype=np.int16).reshape(rows, cols) + 100 * k)
ds.PerFrameFunctionalGroupsSequence = frames
ds.PixelData = np.stack(values).astype("<i2").tobytes()
ds.save_as(os.path.join(out_dir, "enhanced.dcm"), enforce_file_format=True)
result["enhanced"] = {
    "truth": (np.stack(values[::-1]).astype(np.float64) * 2 - 100).ravel().tolist(),
    "origin_lps": [5.0, -3.0, 20.0],
    "dirs_lps": [list(row_dir), list(col_dir), list(normal)],
}

# pydicom's own test files, and what pydicom decodes from the uncompressed ones
data = os.path.dirname(pydicom.data.get_testdata_file("CT_small.dcm"))
result["pydicom_data"] = data
for name in ["CT_small.dcm", "MR_small.dcm", "rtdose.dcm"]:
    ds = pydicom.dcmread(os.path.join(data, name))
    arr = pydicom.pixels.apply_rescale(ds.pixel_array, ds) if "RescaleSlope" in ds else ds.pixel_array
    if name == "rtdose.dcm":
        arr = ds.pixel_array * float(ds.DoseGridScaling)
    result[name] = {"values": np.asarray(arr, dtype=np.float64).ravel().tolist()}
dicomdir = os.path.join(data, "dicomdirtests")
smartscore = "1.3.6.1.4.1.5962.1.1.0.0.0.1194734704.16302.0.6"
files = []
for root, _, names in os.walk(dicomdir):
    for n in names:
        p = os.path.join(root, n)
        try:
            if pydicom.dcmread(p, stop_before_pixels=True).get("SeriesInstanceUID") == smartscore:
                files.append(p)
        except Exception:
            pass
reader = sitk.ImageSeriesReader()
result["dicomdir"] = {"uid": smartscore, "sitk": sitk_read(None, list(reader.GetGDCMSeriesFileNames(os.path.dirname(files[0]), smartscore)))}

print(json.dumps(result))
