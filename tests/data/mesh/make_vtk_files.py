#!/usr/bin/python3
"""Writes the small VTK files the mesh reader tests read, with VTK's own writers.

Run with the system Python that has python3-vtk9 (apt-get install python3-vtk9):
    /usr/bin/python3 tests/data/mesh/make_vtk_files.py
It writes into the directory holding this script. Every point array is a known formula of
the point's position, so the tests check exact values:
    temperature (Float64) = x + 2y + 3z (+ 10 s in step s of the .pvd collection)
    id (Int32)            = 10 * point index
    velocity (Float64, 3 components) = (x, y, z): not a scalar, skipped by readers
"""
import os

import vtk

HERE = os.path.dirname(os.path.abspath(__file__))


def add_point_arrays(grid, step=0):
    pts = grid.GetPoints()
    temperature = vtk.vtkDoubleArray()
    temperature.SetName("temperature")
    ids = vtk.vtkIntArray()
    ids.SetName("id")
    velocity = vtk.vtkDoubleArray()
    velocity.SetName("velocity")
    velocity.SetNumberOfComponents(3)
    for i in range(pts.GetNumberOfPoints()):
        x, y, z = pts.GetPoint(i)
        temperature.InsertNextValue(x + 2 * y + 3 * z + 10 * step)
        ids.InsertNextValue(10 * i)
        velocity.InsertNextTuple3(x, y, z)
    grid.GetPointData().AddArray(temperature)
    grid.GetPointData().AddArray(ids)
    grid.GetPointData().AddArray(velocity)


def hex_grid(nx, ny, nz, dz=0.0):
    """(nx+1)(ny+1)(nz+1) points at (0.5 i, 0.5 j, 0.5 k + dz), point index i + (nx+1)(j + (ny+1)k)."""
    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()  # Float32
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                pts.InsertNextPoint(0.5 * i, 0.5 * j, 0.5 * k + dz)
    grid.SetPoints(pts)

    def p(i, j, k):
        return i + (nx + 1) * (j + (ny + 1) * k)

    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                ids = [p(i, j, k), p(i + 1, j, k), p(i + 1, j + 1, k), p(i, j + 1, k),
                       p(i, j, k + 1), p(i + 1, j, k + 1), p(i + 1, j + 1, k + 1), p(i, j + 1, k + 1)]
                grid.InsertNextCell(vtk.VTK_HEXAHEDRON, 8, ids)
    add_point_arrays(grid)
    return grid


def mixed_mesh():
    """A tetra, a wedge, a pyramid, a triangle and a voxel; Float64 points."""
    grid = vtk.vtkUnstructuredGrid()
    pts = vtk.vtkPoints()
    pts.SetDataTypeToDouble()
    coords = [
        (0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1),                  # 0-3 tetra
        (2, 0, 0), (3, 0, 0), (2, 1, 0), (2, 0, 1), (3, 0, 1), (2, 1, 1),  # 4-9 wedge
        (4, 0, 0), (5, 0, 0), (5, 1, 0), (4, 1, 0), (4.5, 0.5, 1),   # 10-14 pyramid
        (6, 0, 0), (7, 0, 0), (6, 1, 0),                            # 15-17 triangle
        (8, 0, 0), (9, 0, 0), (8, 1, 0), (9, 1, 0),                  # 18-21 voxel bottom (pixel order)
        (8, 0, 1), (9, 0, 1), (8, 1, 1), (9, 1, 1),                  # 22-25 voxel top
    ]
    for c in coords:
        pts.InsertNextPoint(*c)
    grid.SetPoints(pts)
    grid.InsertNextCell(vtk.VTK_TETRA, 4, [0, 1, 2, 3])
    grid.InsertNextCell(vtk.VTK_WEDGE, 6, [4, 5, 6, 7, 8, 9])
    grid.InsertNextCell(vtk.VTK_PYRAMID, 5, [10, 11, 12, 13, 14])
    grid.InsertNextCell(vtk.VTK_TRIANGLE, 3, [15, 16, 17])
    grid.InsertNextCell(vtk.VTK_VOXEL, 8, list(range(18, 26)))
    material = vtk.vtkIntArray()
    material.SetName("material")
    for c in range(grid.GetNumberOfCells()):
        material.InsertNextValue(c + 1)
    grid.GetCellData().AddArray(material)
    add_point_arrays(grid)
    return grid


def write_vtu(grid, name, mode, compress=False, header64=False, big_endian=False, block_size=None):
    w = vtk.vtkXMLUnstructuredGridWriter()
    w.SetFileName(os.path.join(HERE, name))
    w.SetInputData(grid)
    if mode == "ascii":
        w.SetDataModeToAscii()
    elif mode == "binary":
        w.SetDataModeToBinary()
    else:
        w.SetDataModeToAppended()
        w.SetEncodeAppendedData(1 if mode == "appended_base64" else 0)
    if compress:
        w.SetCompressorTypeToZLib()
    else:
        w.SetCompressorTypeToNone()
    if header64:
        w.SetHeaderTypeToUInt64()
    else:
        w.SetHeaderTypeToUInt32()
    if big_endian:
        w.SetByteOrderToBigEndian()
    else:
        w.SetByteOrderToLittleEndian()
    if block_size:
        w.SetBlockSize(block_size)
    if not w.Write():
        raise RuntimeError("cannot write " + name)


def main():
    hexes = hex_grid(2, 2, 2)
    write_vtu(hexes, "hex_ascii.vtu", "ascii")
    for mode in ("binary", "appended_raw", "appended_base64"):
        for compress in (False, True):
            for header64 in (False, True):
                name = "hex_{}_{}_{}.vtu".format(mode, "zlib" if compress else "raw", "u64" if header64 else "u32")
                # Small zlib blocks: several blocks per array, the last one partial.
                write_vtu(hexes, name, mode, compress, header64, block_size=64 if compress else None)
    write_vtu(hexes, "hex_binary_zlib_u32_bigendian.vtu", "binary", True, False, big_endian=True, block_size=64)
    write_vtu(hexes, "hex_appended_raw_raw_u64_bigendian.vtu", "appended_raw", False, True, big_endian=True)

    mixed = mixed_mesh()
    write_vtu(mixed, "mixed_ascii.vtu", "ascii")
    write_vtu(mixed, "mixed_appended_raw_zlib_u64.vtu", "appended_raw", True, True)

    for name, binary, version in (("mixed_legacy_ascii.vtk", False, None),
                                  ("mixed_legacy_binary.vtk", True, None),
                                  ("mixed_legacy42_ascii.vtk", False, 42)):
        w = vtk.vtkUnstructuredGridWriter()
        w.SetFileName(os.path.join(HERE, name))
        w.SetInputData(mixed)
        if binary:
            w.SetFileTypeToBinary()
        else:
            w.SetFileTypeToASCII()
        if version:
            w.SetFileVersion(version)
        if not w.Write():
            raise RuntimeError("cannot write " + name)

    # A collection of 3 steps of a 1x1x2 hex grid: temperature + 10 s; step 2's points move
    # up by 0.25. Listed out of time order to check that readers sort by timestep.
    steps = []
    for s in range(3):
        g = hex_grid(1, 1, 2, dz=0.25 if s == 2 else 0.0)
        g.GetPointData().Initialize()
        add_point_arrays(g, step=s)
        name = "steps_{}.vtu".format(s)
        write_vtu(g, name, "appended_raw", compress=(s == 1))
        steps.append(name)
    with open(os.path.join(HERE, "steps.pvd"), "w") as f:
        f.write('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n')
        f.write("  <Collection>\n")
        for s, t in ((0, "0"), (2, "1.0"), (1, "0.5")):
            f.write('    <DataSet timestep="{}" group="" part="0" file="{}"/>\n'.format(t, steps[s]))
        f.write("  </Collection>\n</VTKFile>\n")


if __name__ == "__main__":
    main()
