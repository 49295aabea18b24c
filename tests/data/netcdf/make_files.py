#!/usr/bin/python3
"""Writes the small netCDF files the importer tests read (tests/preprocess/test_netcdf.cpp), with
netCDF4-python over netCDF-C, so that the tests read what real tools write.

Run with the system Python that has python3-netcdf4 (apt-get install python3-netcdf4):
    /usr/bin/python3 tests/data/netcdf/make_files.py
It writes into the directory holding this script, the same bytes every run on one machine (the
netCDF-4 files record the library versions in their _NCProperties attribute).

Values are written raw (packed), with automatic masking and scaling off. netCDF is C order: the
last dimension varies fastest, so a variable (z, y, x) is x fastest as brickyard stores it. The
formula the C++ test computes too, for a voxel (x, y, z):
    f(x, y, z) = (x*7 + y*13 + z*29) % 251

ocean.nc       netCDF-4 (HDF5, zlib, chunks 1x2x5x8). Dimensions time (unlimited, 2), depth 4,
               lat 10, lon 16, each with its coordinate variable: time 0, 31 (days since
               2000-01-01); depth 5, 15, 25, 35 (m, positive down); lat -5 + 0.25 j (degrees_north);
               lon 10 + 0.5 i (degrees_east).
               temp(time, depth, lat, lon) float, degC: 10 + (f % 31) / 4 + t over the ocean;
               _FillValue 1e20 over land: the columns lon >= 7 and lat <= 8 (a continent that
               fills one 8^3 brick) and the column lon 2, lat 3 (an island).
packed.nc      netCDF-3 classic, z 3, y 4, x 5, no coordinate variables. Two shorts:
               sst    raw f*10 - 1000, scale_factor 0.01 and add_offset 20 (float attributes),
                      _FillValue -32767 where (x + 2y + 3z) % 7 == 0;
               level  raw f*100, scale_factor 1 and add_offset -1000 (short attributes),
                      missing_value [32767, -32768]: 32767 where (x + y + z) % 5 == 0, -32768
                      where (x + y + z) % 5 == 1.
double3d.nc    netCDF-3 64-bit offset, z 5, y 6, x 7. density(z, y, x) double f/8 (exact in f32);
               coordinates x 100 + 2i (km), y -3 + 0.5j (km), z 0.25k (km); mask(y, x) byte, 2D.
types.nc       netCDF-4, z 2, y 3, x 4, one variable per element type: b byte f - 50,
               ub ubyte f + 100, us ushort f*800, i int f*40000 - 1000000, ui uint f*100000,
               wide int f*40000 with the first voxel 2^24 + 1 (f32 rounds it), i64 int64 f,
               names string.
layouts.nc     netCDF-3 classic, shapes brickyard refuses: surface(y, x), series(time, y, x),
               bands(band, z, y, x), five(band, c, z, y, x); time unlimited (3), band 2, c 2,
               z 2, y 3, x 4. All zeros.
nonuniform.nc  netCDF-3 classic, z 2, y 3: uneven(z, y, x) with x 0, 1, 2, 3.5, 5 (steps differ);
               flipped(z, lat, w) with lat 10, 5, 0 (descending; w has no coordinate variable);
               nearly(z, y, xx) with xx 0, 1.0005, 2, 3 (within 0.1% of uniform). All f.
"""
import os

import netCDF4
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def f(nz, ny, nx):
    """The formula over (z, y, x) index arrays, C order."""
    z, y, x = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    return (x * 7 + y * 13 + z * 29) % 251, x, y, z


def dataset(name, fmt):
    path = os.path.join(HERE, name)
    if os.path.exists(path):
        os.remove(path)
    return netCDF4.Dataset(path, "w", format=fmt)


def raw(var):
    """The variable, written as given: no packing by scale_factor/add_offset, no masking."""
    var.set_auto_maskandscale(False)
    return var


def coordinate(ds, name, dtype, values, **attrs):
    v = raw(ds.createVariable(name, dtype, (name,)))
    for k, a in attrs.items():
        v.setncattr(k, a)
    v[:] = np.asarray(values, dtype=dtype)


def ocean():
    ds = dataset("ocean.nc", "NETCDF4")
    ds.Conventions = "CF-1.8"
    ds.createDimension("time", None)
    for name, n in (("depth", 4), ("lat", 10), ("lon", 16)):
        ds.createDimension(name, n)
    coordinate(ds, "time", "f8", [0, 31], units="days since 2000-01-01 00:00:00", axis="T")
    coordinate(ds, "depth", "f4", [5, 15, 25, 35], units="m", positive="down", axis="Z")
    coordinate(ds, "lat", "f8", -5 + 0.25 * np.arange(10), units="degrees_north", axis="Y")
    coordinate(ds, "lon", "f8", 10 + 0.5 * np.arange(16), units="degrees_east", axis="X")
    temp = raw(ds.createVariable("temp", "f4", ("time", "depth", "lat", "lon"), zlib=True, chunksizes=(1, 2, 5, 8),
                                 fill_value=np.float32(1e20)))
    temp.units = "degC"
    temp.long_name = "sea water temperature"
    v, x, y, z = f(4, 10, 16)
    land = ((x >= 7) & (y <= 8)) | ((x == 2) & (y == 3))
    for t in range(2):
        step = (10 + (v % 31) / 4.0 + t).astype(np.float32)
        step[land] = np.float32(1e20)
        temp[t] = step
    ds.close()


def packed():
    ds = dataset("packed.nc", "NETCDF3_CLASSIC")
    for name, n in (("z", 3), ("y", 4), ("x", 5)):
        ds.createDimension(name, n)
    v, x, y, z = f(3, 4, 5)
    sst = raw(ds.createVariable("sst", "i2", ("z", "y", "x"), fill_value=np.int16(-32767)))
    sst.scale_factor = np.float32(0.01)
    sst.add_offset = np.float32(20)
    sst.units = "degC"
    packed = (v * 10 - 1000).astype(np.int16)
    packed[(x + 2 * y + 3 * z) % 7 == 0] = -32767
    sst[:] = packed
    level = raw(ds.createVariable("level", "i2", ("z", "y", "x")))
    level.scale_factor = np.int16(1)
    level.add_offset = np.int16(-1000)
    level.missing_value = np.array([32767, -32768], dtype=np.int16)
    packed = (v * 100).astype(np.int16)
    packed[(x + y + z) % 5 == 0] = 32767
    packed[(x + y + z) % 5 == 1] = -32768
    level[:] = packed
    ds.close()


def double3d():
    ds = dataset("double3d.nc", "NETCDF3_64BIT_OFFSET")
    for name, n in (("z", 5), ("y", 6), ("x", 7)):
        ds.createDimension(name, n)
    coordinate(ds, "x", "f4", 100 + 2 * np.arange(7), units="km")
    coordinate(ds, "y", "f4", -3 + 0.5 * np.arange(6), units="km")
    coordinate(ds, "z", "f4", 0.25 * np.arange(5), units="km")
    v, _, _, _ = f(5, 6, 7)
    density = raw(ds.createVariable("density", "f8", ("z", "y", "x")))
    density.units = "kg m-3"
    density[:] = v / 8.0
    mask = raw(ds.createVariable("mask", "i1", ("y", "x")))
    mask[:] = np.ones((6, 7), dtype=np.int8)
    ds.close()


def types():
    ds = dataset("types.nc", "NETCDF4")
    for name, n in (("z", 2), ("y", 3), ("x", 4)):
        ds.createDimension(name, n)
    v, _, _, _ = f(2, 3, 4)
    dims = ("z", "y", "x")
    for name, dtype, values in (("b", "i1", v - 50), ("ub", "u1", v + 100), ("us", "u2", v * 800),
                                ("i", "i4", v * 40000 - 1000000), ("ui", "u4", v * 100000), ("i64", "i8", v)):
        raw(ds.createVariable(name, dtype, dims))[:] = values.astype(dtype)
    wide = (v * 40000).astype(np.int32)
    wide[0, 0, 0] = 2**24 + 1
    raw(ds.createVariable("wide", "i4", dims))[:] = wide
    names = raw(ds.createVariable("names", str, dims))
    for idx in np.ndindex(2, 3, 4):
        names[idx] = "v%d" % v[idx]
    ds.close()


def layouts():
    ds = dataset("layouts.nc", "NETCDF3_CLASSIC")
    ds.createDimension("time", None)
    for name, n in (("band", 2), ("c", 2), ("z", 2), ("y", 3), ("x", 4)):
        ds.createDimension(name, n)
    for name, dims in (("surface", ("y", "x")), ("series", ("time", "y", "x")), ("bands", ("band", "z", "y", "x")),
                       ("five", ("band", "c", "z", "y", "x"))):
        var = raw(ds.createVariable(name, "f4", dims))
        shape = tuple(3 if d == "time" else len(ds.dimensions[d]) for d in dims)
        var[:] = np.zeros(shape, dtype=np.float32)
    ds.close()


def nonuniform():
    ds = dataset("nonuniform.nc", "NETCDF3_CLASSIC")
    for name, n in (("z", 2), ("y", 3), ("x", 5), ("lat", 3), ("w", 4), ("xx", 4)):
        ds.createDimension(name, n)
    coordinate(ds, "x", "f8", [0, 1, 2, 3.5, 5])
    coordinate(ds, "lat", "f8", [10, 5, 0], units="degrees_north")
    coordinate(ds, "xx", "f8", [0, 1.0005, 2, 3])
    for name, dims in (("uneven", ("z", "y", "x")), ("flipped", ("z", "lat", "w")), ("nearly", ("z", "y", "xx"))):
        shape = tuple(len(ds.dimensions[d]) for d in dims)
        raw(ds.createVariable(name, "f4", dims))[:] = f(*shape)[0].astype(np.float32)
    ds.close()


def main():
    ocean()
    packed()
    double3d()
    types()
    layouts()
    nonuniform()


if __name__ == "__main__":
    main()
