"""Writes the benchmark CT of tests/bench_dicom_read.sh: a 512 x 512 x 300
int16 series (pydicom, uncompressed, shuffled file names) and the same
volume as an uncompressed NIfTI beside it.

usage: python bench_dicom_series.py OUT_FOLDER   (also writes OUT_FOLDER.nii)
"""
import sys, os, numpy as np, pydicom
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import ExplicitVRLittleEndian, generate_uid, CTImageStorage
out = sys.argv[1]; nx, ny, nz = 512, 512, 300
os.makedirs(out, exist_ok=True)
rng = np.random.default_rng(1)
series = generate_uid(); study = generate_uid(); frame = generate_uid()
yy, xx = np.mgrid[0:ny, 0:nx]
vol = np.empty((nz, ny, nx), np.int16)
for k in range(nz):
    r = np.hypot(xx - 256, yy - 256)
    sl = np.where(r < 200, 40, -1000) + np.where(r < 60 + 30*np.sin(k/20), 1000, 0)
    vol[k] = (sl + rng.normal(0, 10, sl.shape)).astype(np.int16) + 1024
for k in rng.permutation(nz):
    m = FileMetaDataset(); m.MediaStorageSOPClassUID = CTImageStorage; sop = generate_uid(); m.MediaStorageSOPInstanceUID = sop
    m.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset(); ds.file_meta = m
    ds.SOPClassUID = CTImageStorage; ds.SOPInstanceUID = sop; ds.Modality = "CT"
    ds.SeriesInstanceUID = series; ds.StudyInstanceUID = study; ds.FrameOfReferenceUID = frame
    ds.SeriesNumber = 1; ds.InstanceNumber = k + 1; ds.SeriesDescription = "bench"
    ds.PatientName = "Bench^Phantom"; ds.PatientID = "BENCH"
    ds.ImagePositionPatient = [-250.0, -250.0, -300.0 + 2.0 * k]
    ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
    ds.PixelSpacing = [0.9765625, 0.9765625]; ds.SliceThickness = 2.0
    ds.Rows = ny; ds.Columns = nx; ds.SamplesPerPixel = 1; ds.PhotometricInterpretation = "MONOCHROME2"
    ds.BitsAllocated = 16; ds.BitsStored = 16; ds.HighBit = 15; ds.PixelRepresentation = 1
    ds.RescaleSlope = 1; ds.RescaleIntercept = -1024
    ds.PixelData = vol[k].tobytes()
    ds.save_as(os.path.join(out, f"{sop}.dcm"), enforce_file_format=True)
import nibabel as nib
aff = np.diag([-0.9765625, -0.9765625, 2.0, 1.0]); aff[:3, 3] = [250, 250, -300]
img = nib.Nifti1Image(np.transpose(vol, (2, 1, 0)), aff); img.header.set_slope_inter(1, -1024)
nib.save(img, out + ".nii")
