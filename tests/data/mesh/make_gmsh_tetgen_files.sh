#!/bin/sh
# Regenerates the gmsh and TetGen meshes the mesh-format tests read (tests/preprocess/
# test_mesh_formats.cpp), from box.geo, prism.geo and cube.poly in this folder.
# Needs: apt-get install -y --no-install-recommends gmsh tetgen (Debian 12: gmsh 4.8.4,
# tetgen 1.5.0). The outputs are committed; rerun only when the inputs change, then update the
# counts the tests expect.
set -eu
cd "$(dirname "$0")"

# The unit cube in tetrahedra, as every MSH flavour the reader knows.
gmsh -3 box.geo -format msh22 -o box_msh22.msh
gmsh -3 box.geo -format msh22 -bin -o box_msh22_bin.msh
gmsh -3 box.geo -format msh41 -o box_msh41.msh
gmsh -3 box.geo -format msh41 -bin -o box_msh41_bin.msh
# A slab of prisms (extruded in layers).
gmsh -3 prism.geo -format msh41 -o prism_msh41.msh
gmsh -3 prism.geo -format msh2 -bin -o prism_msh2_bin.msh

# TetGen: quality tetrahedralization of the cube, tets of volume <= 0.05 (cube.1.node, cube.1.ele; faces and edges
# are not read, so they are removed).
tetgen -qa0.05 cube.poly
rm -f cube.1.face cube.1.edge cube.1.smesh cube.1.vtk
