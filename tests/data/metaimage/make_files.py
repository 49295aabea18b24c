#!/usr/bin/python3
"""Writes the small MetaImage files the importer tests read, with VTK's own vtkMetaImageWriter
(VTK's copy of MetaIO, the library ITK and 3D Slicer use).

Run with the system Python that has python3-vtk9
(apt-get install -y --no-install-recommends python3-vtk9):
    /usr/bin/python3 tests/data/metaimage/make_files.py
It writes into the directory holding this script. Every volume is 7x6x5 voxels (7x6 for the
2D image), x fastest, and every value is a known formula of the voxel's index, shared with
tests/preprocess/test_metaimage.cpp:
    f(x, y, z) = (x*7 + y*13 + z*29) % 251          (0 .. 223 on these grids)

    short_attached.mha          MET_SHORT, raw, .mha     f - 100          (negative values)
    uchar_detached.mhd/.raw     MET_UCHAR, raw, .mhd     f                spacing 0.5 1.25 2,
                                                                          offset -3.5 1 10.25
    float_compressed.mha        MET_FLOAT, zlib, .mha    (f - 100) / 4    (exact in f32)
    ushort_compressed.mhd/.zraw MET_USHORT, zlib, .mhd   f * 100
    int_attached.mha            MET_INT, raw, .mha       (f - 100) * 65536 (within 2^24: exact)
    double_attached.mha         MET_DOUBLE, raw, .mha    (f - 100) / 10   (rounded to f32)
    uchar_2d.mha                MET_UCHAR, zlib, NDims 2 f at z = 0

vtkMetaImageWriter writes only the machine's byte order and an identity TransformMatrix, so
the tests write their big-endian and rotated files by hand.
"""
import os

import vtk

HERE = os.path.dirname(os.path.abspath(__file__))
DIMS = (7, 6, 5)


def f(x, y, z):
    return (x * 7 + y * 13 + z * 29) % 251


def image(vtk_type, value, dims=DIMS, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0)):
    img = vtk.vtkImageData()
    img.SetDimensions(*dims)
    img.SetSpacing(*spacing)
    img.SetOrigin(*origin)
    img.AllocateScalars(vtk_type, 1)
    scalars = img.GetPointData().GetScalars()
    nx, ny, nz = dims
    for z in range(nz):
        for y in range(ny):
            for x in range(nx):
                scalars.SetValue(x + nx * (y + ny * z), value(f(x, y, z)))
    return img


def write(img, name, compressed, raw_name=None):
    writer = vtk.vtkMetaImageWriter()
    writer.SetInputData(img)
    writer.SetFileName(name)
    if raw_name:
        writer.SetRAWFileName(raw_name)
    writer.SetCompression(compressed)
    writer.Write()


def main():
    # Relative names: the .mhd files then name their data file relative to themselves.
    os.chdir(HERE)
    write(image(vtk.VTK_SHORT, lambda v: v - 100), "short_attached.mha", False)
    write(image(vtk.VTK_UNSIGNED_CHAR, lambda v: v, spacing=(0.5, 1.25, 2.0), origin=(-3.5, 1.0, 10.25)),
          "uchar_detached.mhd", False, "uchar_detached.raw")
    write(image(vtk.VTK_FLOAT, lambda v: (v - 100) / 4.0), "float_compressed.mha", True)
    write(image(vtk.VTK_UNSIGNED_SHORT, lambda v: v * 100), "ushort_compressed.mhd", True, "ushort_compressed.zraw")
    write(image(vtk.VTK_INT, lambda v: (v - 100) * 65536), "int_attached.mha", False)
    write(image(vtk.VTK_DOUBLE, lambda v: (v - 100) / 10.0), "double_attached.mha", False)
    write(image(vtk.VTK_UNSIGNED_CHAR, lambda v: v, dims=(7, 6, 1)), "uchar_2d.mha", True)


if __name__ == "__main__":
    main()
