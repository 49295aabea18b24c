#!/usr/bin/python3
"""Writes the small DICOM series the importer tests read (tests/preprocess/test_dicom.cpp and the
bad-input census), with pydicom, so that the tests read what a DICOM toolkit writes.

Run with the system Python that has python3-pydicom (apt-get install python3-pydicom):
    /usr/bin/python3 tests/data/dicom/make_files.py
It rewrites the directories below beside this script, the same bytes every run: UIDs come from
pydicom's generate_uid with fixed entropy, and no dates or times are written.

Every slice is 8 columns (x) by 7 rows (y). Values follow one formula, which the C++ test computes
too, of the voxel's place in the volume once sorted (z counts slices along the slice normal):
    g(x, y, z) = (x*7 + y*13 + z*29) % 251 - 100        (integers in [-100, 150])

    ct/           CT, int16 (PixelRepresentation 1), 5 slices, RescaleSlope 1, RescaleIntercept
                  -1024: stored pixel 10*g + 1024, so the value is 10*g (i16, exact).
                  Orientation 1,0,0 / 0,1,0 (normal +z); PixelSpacing 0.75\\0.5 (rows 0.75 apart,
                  columns 0.5: x spacing 0.5, y spacing 0.75); slice z at (-20, 30.5, -40 + 2.5 z).
                  The files are named in shuffled order (ct_0.dcm holds z = 3, ...); ct_4.dcm is
                  Implicit VR Little Endian, the others Explicit VR Little Endian. notes.txt is
                  not DICOM (skipped).
    mr/           MR, uint16 (PixelRepresentation 0), 4 slices, RescaleSlope 0.5, intercept 0:
                  stored pixel (g + 100) * 200 (up to 50000), value (g + 100) * 100 (stored f32).
                  Sagittal: orientation 0,1,0 / 0,0,-1, normal (-1, 0, 0); PixelSpacing 1.5\\1.25;
                  slice z at (16 - 2 z, -5, 20) (x falls as z rises). mr_1.dcm is Explicit VR Big
                  Endian.
    multiframe/   one Enhanced MR file, uint8, 3 frames, RLE Lossless: stored pixel g + 100.
                  Frame f holds z = 2 - f (the frames run against the normal); per-frame
                  positions (1, 2, 5 + 1.5 z); shared orientation 1,0,0 / 0,1,0 and
                  PixelSpacing 0.8\\0.6.
    irregular/    uint8, 4 slices at z = 0, 1, 2, 3.5 mm: the last gap is 1.5, the median 1.
    bad_rows/     uint8, 2 slices; rows_1.dcm has 6 rows, rows_0.dcm 7.
    duplicate/    uint8, 2 slices at the same position.
    orientation/  uint8, 2 slices; orient_1.dcm is turned (orientation 0,1,0 / -1,0,0).
    bad_pixels/   uint8, 2 slices; pixels_1.dcm has 50 bytes of pixel data where 56 are needed.
"""
import os
import shutil

import numpy as np
import pydicom
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.sequence import Sequence
from pydicom.uid import (ExplicitVRBigEndian, ExplicitVRLittleEndian, ImplicitVRLittleEndian, RLELossless,
                         generate_uid)

HERE = os.path.dirname(os.path.abspath(__file__))
COLS, ROWS = 8, 7
CT_IMAGE = "1.2.840.10008.5.1.4.1.1.2"
MR_IMAGE = "1.2.840.10008.5.1.4.1.1.4"
ENHANCED_MR_IMAGE = "1.2.840.10008.5.1.4.1.1.4.1"
IMPLEMENTATION = generate_uid(entropy_srcs=["brickyard", "implementation"])


def uid(*parts):
    return generate_uid(entropy_srcs=["brickyard-test"] + [str(p) for p in parts])


def g(z, rows=ROWS, cols=COLS):
    """The formula's slice z as a rows x cols array (y, x)."""
    y, x = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    return (x * 7 + y * 13 + z * 29) % 251 - 100


def image(series, sop, sop_class, modality, pixels, signed, position, orientation, spacing, rescale=None,
          bits=None):
    """A single-frame image dataset (without its file meta) holding `pixels` (rows x cols)."""
    ds = Dataset()
    ds.SOPClassUID = sop_class
    ds.SOPInstanceUID = sop
    ds.Modality = modality
    ds.StudyInstanceUID = uid("study")
    ds.SeriesInstanceUID = series
    ds.ImagePositionPatient = [float(v) for v in position]
    ds.ImageOrientationPatient = [float(v) for v in orientation]
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.Rows, ds.Columns = pixels.shape
    ds.PixelSpacing = [float(v) for v in spacing]
    bits = bits or pixels.dtype.itemsize * 8
    ds.BitsAllocated = bits
    ds.BitsStored = bits
    ds.HighBit = bits - 1
    ds.PixelRepresentation = 1 if signed else 0
    if rescale:
        ds.RescaleIntercept, ds.RescaleSlope = rescale[1], rescale[0]
    ds.PixelData = pixels.tobytes()
    return ds


def save(ds, path, syntax=ExplicitVRLittleEndian):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = ds.SOPClassUID
    meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
    meta.TransferSyntaxUID = syntax
    meta.ImplementationClassUID = IMPLEMENTATION
    ds.file_meta = meta
    ds.preamble = b"\0" * 128
    ds.is_little_endian = syntax != ExplicitVRBigEndian
    ds.is_implicit_VR = syntax == ImplicitVRLittleEndian
    if syntax == ExplicitVRBigEndian and ds.BitsAllocated == 16:
        arr = np.frombuffer(ds.PixelData, dtype="<i2" if ds.PixelRepresentation else "<u2")
        ds.PixelData = arr.astype(arr.dtype.newbyteorder(">")).tobytes()
    ds.save_as(path, write_like_original=False)


def fresh(name):
    d = os.path.join(HERE, name)
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    return d


def ct():
    d = fresh("ct")
    series = uid("ct")
    for i, z in enumerate([3, 0, 4, 1, 2]):
        pixels = (10 * g(z) + 1024).astype("<i2")
        ds = image(series, uid("ct", z), CT_IMAGE, "CT", pixels, True, (-20, 30.5, -40 + 2.5 * z), (1, 0, 0, 0, 1, 0),
                   (0.75, 0.5), rescale=(1, -1024))
        ds.InstanceNumber = 5 - z
        save(ds, os.path.join(d, f"ct_{i}.dcm"), ImplicitVRLittleEndian if i == 4 else ExplicitVRLittleEndian)
    with open(os.path.join(d, "notes.txt"), "w") as f:
        f.write("Not DICOM: the importer skips this file.\n")


def mr():
    d = fresh("mr")
    series = uid("mr")
    for i, z in enumerate([2, 0, 3, 1]):
        pixels = ((g(z) + 100) * 200).astype("<u2")
        ds = image(series, uid("mr", z), MR_IMAGE, "MR", pixels, False, (16 - 2 * z, -5, 20), (0, 1, 0, 0, 0, -1),
                   (1.5, 1.25), rescale=(0.5, 0))
        save(ds, os.path.join(d, f"mr_{i}.dcm"), ExplicitVRBigEndian if i == 1 else ExplicitVRLittleEndian)


def multiframe():
    d = fresh("multiframe")
    frames = [2, 1, 0]  # frame f holds z = 2 - f
    ds = Dataset()
    ds.SOPClassUID = ENHANCED_MR_IMAGE
    ds.SOPInstanceUID = uid("multiframe", "sop")
    ds.Modality = "MR"
    ds.StudyInstanceUID = uid("study")
    ds.SeriesInstanceUID = uid("multiframe")
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.NumberOfFrames = len(frames)
    ds.Rows, ds.Columns = ROWS, COLS
    ds.BitsAllocated = ds.BitsStored = 8
    ds.HighBit = 7
    ds.PixelRepresentation = 0
    measures = Dataset()
    measures.PixelSpacing = [0.8, 0.6]
    measures.SliceThickness = 1.5
    orientation = Dataset()
    orientation.ImageOrientationPatient = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    shared = Dataset()
    shared.PixelMeasuresSequence = Sequence([measures])
    shared.PlaneOrientationSequence = Sequence([orientation])
    ds.SharedFunctionalGroupsSequence = Sequence([shared])
    per_frame = []
    for z in frames:
        position = Dataset()
        position.ImagePositionPatient = [1.0, 2.0, 5 + 1.5 * z]
        item = Dataset()
        item.PlanePositionSequence = Sequence([position])
        per_frame.append(item)
    ds.PerFrameFunctionalGroupsSequence = Sequence(per_frame)
    arr = np.stack([(g(z) + 100).astype(np.uint8) for z in frames])
    ds.file_meta = FileMetaDataset()
    ds.is_little_endian, ds.is_implicit_VR = True, False
    ds.compress(RLELossless, arr, encoding_plugin="pydicom")
    meta = ds.file_meta
    meta.MediaStorageSOPClassUID = ds.SOPClassUID
    meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID
    meta.ImplementationClassUID = IMPLEMENTATION
    ds.preamble = b"\0" * 128
    ds.save_as(os.path.join(d, "enhanced_mr.dcm"), write_like_original=False)


def small_series(name, prefix, zs, edit=None):
    """uint8 slices of g(z) + 100 at (0, 0, z_mm) for each z_mm of `zs`; edit(i, ds) changes one."""
    d = fresh(name)
    series = uid(name)
    for i, z_mm in enumerate(zs):
        ds = image(series, uid(name, i), MR_IMAGE, "MR", (g(i) + 100).astype(np.uint8), False, (0, 0, z_mm),
                   (1, 0, 0, 0, 1, 0), (1, 1))
        if edit:
            edit(i, ds)
        save(ds, os.path.join(d, f"{prefix}_{i}.dcm"))


def fewer_rows(i, ds):
    if i == 1:
        ds.Rows = ROWS - 1
        ds.PixelData = ds.PixelData[:COLS * (ROWS - 1)]


def turned(i, ds):
    if i == 1:
        ds.ImageOrientationPatient = [0.0, 1.0, 0.0, -1.0, 0.0, 0.0]


def short_pixels(i, ds):
    if i == 1:
        ds.PixelData = ds.PixelData[:50]


def main():
    ct()
    mr()
    multiframe()
    small_series("irregular", "irr", [0, 1, 2, 3.5])
    small_series("bad_rows", "rows", [0, 1], fewer_rows)
    small_series("duplicate", "dup", [4, 4])
    small_series("orientation", "orient", [0, 1], turned)
    small_series("bad_pixels", "pixels", [0, 1], short_pixels)


if __name__ == "__main__":
    main()
