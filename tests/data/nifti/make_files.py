#!/usr/bin/python3
"""Writes the small NIfTI files the importer tests read (tests/preprocess/test_nifti.cpp), with
nibabel's own writers, so that the tests read what real tools write.

Run with the system Python that has python3-nibabel (apt-get install python3-nibabel):
    /usr/bin/python3 tests/data/nifti/make_files.py
It writes into the directory holding this script, the same bytes every run (no timestamps).

Every volume is 7x6x5 voxels (x fastest on disk) of one formula, which the C++ test computes too:
    f(x, y, z) = (x*7 + y*13 + z*29) % 251 - 100        (integers in [-100, 150])
    int16.nii           int16 f; sform (code 1) spacing 0.5,0.75,1.25, origin 10.5,-20.25,30;
                        a qform (code 1) with another origin, which the sform overrides
    float32.nii.gz      float32 f/4 (exact), gzip
    uint8.hdr/.img      uint8 f+100, an ANALYZE-style pair of files (NIfTI-1 "ni1")
    nifti2.nii          NIfTI-2, uint16 (f+100)*200 (up to 50000: beyond i16)
    bigendian.nii       int16 f, big-endian header and data
    scaled_uint8.nii    uint8 f+100 with scl_slope 2, scl_inter -1024: values 2(f+100)-1024
    scaled_float.nii    int16 f with scl_slope 0.5, scl_inter 0.25: values f/2+1/4
    int32.nii           int32 f*40000 (|v| <= 6,000,000 < 2^24: exact in f32)
    4d.nii              int16 7x6x5x3, step t holds f+1000t
    qform.nii           uint8 f+100, qform only (code 1): spacing 1,2,3, origin -3,4.5,7
    slice2d.nii         uint8 f+100 of z = 0 only: 7x6x1
    complex64.nii       complex64 2x2x2 (a type brickyard refuses)
"""
import os
import struct

import nibabel as nib
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DIMS = (7, 6, 5)


def f(dims=DIMS):
    x, y, z = np.meshgrid(*(np.arange(n) for n in dims), indexing="ij")
    return (x * 7 + y * 13 + z * 29) % 251 - 100


def affine(spacing, origin):
    a = np.diag(list(spacing) + [1.0])
    a[:3, 3] = origin
    return a


def save(img, name, qform=None, qcode=0, sform=None, scode=0):
    # Codes and forms explicitly: nibabel's defaults differ between versions.
    img.set_qform(qform if qform is not None else img.affine, code=qcode)
    img.set_sform(sform if sform is not None else img.affine, code=scode)
    nib.save(img, os.path.join(HERE, name))


def set_scaling(name, slope, inter, big_endian=False):
    # nibabel recomputes scl_slope/scl_inter from in-memory arrays when it saves, so the
    # scaling is written into the saved NIfTI-1 header (bytes 112 and 116) afterwards.
    with open(os.path.join(HERE, name), "r+b") as fh:
        fh.seek(112)
        fh.write(struct.pack(">ff" if big_endian else "<ff", slope, inter))


def main():
    v = f()
    std = affine((0.5, 0.75, 1.25), (10.5, -20.25, 30.0))
    save(nib.Nifti1Image(v.astype(np.int16), std), "int16.nii",
         qform=affine((0.5, 0.75, 1.25), (1.0, 2.0, 3.0)), qcode=1, sform=std, scode=1)

    gz = nib.Nifti1Image((v / 4.0).astype(np.float32), std)
    save(gz, "float32.nii.gz", scode=1)
    # gzip's header holds the file's name and a time: zero the time so reruns are identical.
    path = os.path.join(HERE, "float32.nii.gz")
    with open(path, "r+b") as fh:
        fh.seek(4)
        fh.write(b"\0\0\0\0")

    save(nib.Nifti1Pair((v + 100).astype(np.uint8), std), "uint8.hdr", scode=1)

    save(nib.Nifti2Image(((v + 100) * 200).astype(np.uint16), std), "nifti2.nii", scode=1)

    hdr = nib.Nifti1Header(endianness=">")
    hdr.set_data_dtype(">i2")  # a header's own dtype (float32) wins over the array's
    big = nib.Nifti1Image(v.astype(">i2"), std, header=hdr)
    save(big, "bigendian.nii", scode=1)

    save(nib.Nifti1Image((v + 100).astype(np.uint8), std), "scaled_uint8.nii", scode=1)
    set_scaling("scaled_uint8.nii", 2.0, -1024.0)
    save(nib.Nifti1Image(v.astype(np.int16), std), "scaled_float.nii", scode=1)
    set_scaling("scaled_float.nii", 0.5, 0.25)

    save(nib.Nifti1Image((v * 40000).astype(np.int32), std), "int32.nii", scode=1)

    steps = np.stack([v + 1000 * t for t in range(3)], axis=3).astype(np.int16)
    save(nib.Nifti1Image(steps, std), "4d.nii", scode=1)

    q = affine((1.0, 2.0, 3.0), (-3.0, 4.5, 7.0))
    save(nib.Nifti1Image((v + 100).astype(np.uint8), q), "qform.nii", qform=q, qcode=1, scode=0)

    flat = f((7, 6, 1))
    save(nib.Nifti1Image((flat + 100).astype(np.uint8), std), "slice2d.nii", scode=1)

    c = np.zeros((2, 2, 2), dtype=np.complex64)
    save(nib.Nifti1Image(c, np.eye(4)), "complex64.nii", scode=1)


if __name__ == "__main__":
    main()
