#!/usr/bin/python3
"""Writes VTK's own vtkRTAnalyticSource output for the wavelet field's test (tests/fields/).

Each case is written as NAME.f32: the RTData point scalars, float32 little-endian, x fastest,
no header (the dimensions are in the table below and in the C++ test). The cases cover VTK's
untouched default source, odd and even extents, non-cube grids (so a swapped axis shows),
each way of spelling the centre, an axis of one sample, and non-default parameters.

Run from the repository root with Debian's python3-vtk9:
    /usr/bin/python3 tests/data/wavelet/make_wavelet_reference.py
"""

import os
import struct
import sys

import vtk

HERE = os.path.dirname(os.path.abspath(__file__))

# name: (WholeExtent, Center or None for VTK's default, parameters other than VTK's defaults)
CASES = {
    # vtkRTAnalyticSource() exactly as constructed: extent -10..10, centre 0 (21^3).
    "default_21x21x21": (None, None, {}),
    # Odd sizes, centred extent, default centre.
    "odd_11x7x5": ((-5, 5, -3, 3, -2, 2), None, {}),
    # Even sizes: extent from 0 with the centre in the middle.
    "even_8x6x4": ((0, 7, 0, 5, 0, 3), (3.5, 2.5, 1.5), {}),
    # The same centring spelled three ways, one per axis, and an axis of one sample.
    "mixed_9x1x6": ((-4, 4, 7, 7, -3, 2), (0.0, 7.0, -0.5), {}),
    # Every parameter away from its default.
    "params_7x9x8": ((0, 6, -4, 4, -4, 3), (3.0, 0.0, -0.5),
                     {"Maximum": 100.0, "StandardDeviation": 0.3, "XFreq": 25.0, "YFreq": 45.0,
                      "ZFreq": 11.0, "XMag": 4.0, "YMag": 7.5, "ZMag": 12.0}),
}


def run(extent, center, params):
    source = vtk.vtkRTAnalyticSource()
    if extent is not None:
        source.SetWholeExtent(*extent)
    if center is not None:
        source.SetCenter(*center)
    for name, value in params.items():
        getattr(source, "Set" + name)(value)
    source.Update()
    image = source.GetOutput()
    scalars = image.GetPointData().GetScalars()
    assert scalars.GetDataType() == vtk.VTK_FLOAT, scalars.GetDataTypeAsString()
    values = [scalars.GetValue(i) for i in range(scalars.GetNumberOfTuples())]
    return image.GetDimensions(), values


def main():
    print("VTK", vtk.vtkVersion.GetVTKVersion())
    for name, (extent, center, params) in CASES.items():
        dims, values = run(extent, center, params)
        expected = tuple(int(d) for d in name.rsplit("_", 1)[1].split("x"))
        if tuple(dims) != expected:
            sys.exit(f"{name}: VTK produced {dims}, the name says {expected}")
        with open(os.path.join(HERE, name + ".f32"), "wb") as f:
            f.write(struct.pack("<%df" % len(values), *values))
        print(f"{name}.f32: {dims[0]}x{dims[1]}x{dims[2]}, values in [{min(values):.6g}, {max(values):.6g}]")


if __name__ == "__main__":
    main()
