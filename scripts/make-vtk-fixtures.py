#!/usr/bin/env python3
"""Writes the VTK test fixtures in tests/vtk/ with VTK's own writers (PyPI
`vtk`) and NIfTI with nibabel, so that dpp's readers are checked against an
independent writer, not against themselves.

    pip install vtk nibabel numpy
    python3 scripts/make-vtk-fixtures.py        # rewrites tests/vtk/

- ball_*.vti, ball.pvti (+ ball/ pieces), ball_legacy*.vtk, ball.nii.gz: one
  9x8x7 volume, spacing (0.5, 0.25, 1), origin (-2, -1, -3), whose active
  scalars `distance` are each sample's distance from (0, 0, 0); also
  `position` (3 components, f64), `id` (int32) and cell data `cellid`. The
  .vti files are ASCII, inline base64, appended base64, appended raw (which
  vtkio cannot read: an error test), zlib (64-bit headers), lz4 and
  big-endian.
- shape.obj, shape.vtp, shape_legacy*.vtk (5.1 ASCII and binary, 4.2): one mesh of quads, triangles,
  a pentagon and a triangle strip, with a point field `height`; the OBJ
  lists the same faces (the strip as VTK triangulates it), in the same order.
- cells.vtu, cells_legacy.vtk (5.1), cells_legacy42.vtk (4.2), cells.pvtu (+ cells/ pieces): an
  unstructured grid of hexahedra, a wedge, a pyramid and tetrahedra with a
  cell field `pressure` and a point field `temperature`.
- expected.json: the triangle counts of the grids' external surfaces as VTK
  computes them (vtkDataSetSurfaceFilter, then vtkTriangleFilter), whole and
  per piece.
"""

import json
import os
import sys

import nibabel
import numpy as np
import vtk
from vtk.util import numpy_support

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "vtk")


def path(name):
    return os.path.join(OUT, name)


def ball():
    dims = (9, 8, 7)
    spacing = (0.5, 0.25, 1.0)
    origin = (-2.0, -1.0, -3.0)
    image = vtk.vtkImageData()
    image.SetDimensions(*dims)
    image.SetSpacing(*spacing)
    image.SetOrigin(*origin)
    k, j, i = np.meshgrid(*(np.arange(n) for n in dims[::-1]), indexing="ij")
    position = np.stack(
        [origin[a] + spacing[a] * idx for a, idx in enumerate((i, j, k))], axis=-1
    ).reshape(-1, 3)
    distance = np.linalg.norm(position, axis=1).astype(np.float32)

    def add(data, array, name):
        vtk_array = numpy_support.numpy_to_vtk(np.ascontiguousarray(array), deep=1)
        vtk_array.SetName(name)
        data.AddArray(vtk_array)
        return vtk_array

    # `id` first: the active scalars, not the first array, are the default.
    add(image.GetPointData(), np.arange(len(distance), dtype=np.int32), "id")
    image.GetPointData().SetScalars(add(image.GetPointData(), distance, "distance"))
    add(image.GetPointData(), position.astype(np.float64), "position")
    cells = (dims[0] - 1) * (dims[1] - 1) * (dims[2] - 1)
    add(image.GetCellData(), np.arange(cells, dtype=np.float32), "cellid")

    def xml(name, mode, compressor="none", encode=True, big=False, header64=False):
        writer = vtk.vtkXMLImageDataWriter()
        writer.SetFileName(path(name))
        writer.SetInputData(image)
        {"ascii": writer.SetDataModeToAscii, "binary": writer.SetDataModeToBinary,
         "appended": writer.SetDataModeToAppended}[mode]()
        writer.SetEncodeAppendedData(encode)
        {"none": writer.SetCompressorTypeToNone, "zlib": writer.SetCompressorTypeToZLib,
         "lz4": writer.SetCompressorTypeToLZ4}[compressor]()
        if big:
            writer.SetByteOrderToBigEndian()
        if header64:
            writer.SetHeaderTypeToUInt64()
        assert writer.Write() == 1, name

    xml("ball_ascii.vti", "ascii")
    xml("ball_binary.vti", "binary")
    xml("ball_appended.vti", "appended")
    xml("ball_raw.vti", "appended", encode=False)
    xml("ball_zlib.vti", "appended", "zlib", header64=True)
    xml("ball_lz4.vti", "binary", "lz4")
    xml("ball_be.vti", "binary", big=True)

    # Three pieces along z sharing their boundary layers (as VTK's own
    # splits do), written one by one; the .pvti names them.
    os.makedirs(path("ball"), exist_ok=True)
    slabs = [(0, 2), (2, 4), (4, 6)]
    for n, (z0, z1) in enumerate(slabs):
        voi = vtk.vtkExtractVOI()
        voi.SetInputData(image)
        voi.SetVOI(0, dims[0] - 1, 0, dims[1] - 1, z0, z1)
        voi.Update()
        writer = vtk.vtkXMLImageDataWriter()
        writer.SetFileName(path("ball/ball_%d.vti" % n))
        writer.SetInputData(voi.GetOutput())
        writer.SetCompressorTypeToZLib()
        assert writer.Write() == 1
    whole = "0 %d 0 %d 0 %d" % (dims[0] - 1, dims[1] - 1, dims[2] - 1)
    with open(path("ball.pvti"), "w") as pvti:
        pvti.write(
            '<?xml version="1.0"?>\n'
            '<VTKFile type="PImageData" version="1.0" byte_order="LittleEndian" header_type="UInt32">\n'
            '  <PImageData WholeExtent="%s" GhostLevel="0" Origin="%r %r %r" Spacing="%r %r %r">\n'
            % ((whole,) + origin + spacing)
            + '    <PPointData Scalars="distance">\n'
            '      <PDataArray type="Int32" Name="id"/>\n'
            '      <PDataArray type="Float32" Name="distance"/>\n'
            '      <PDataArray type="Float64" Name="position" NumberOfComponents="3"/>\n'
            '    </PPointData>\n'
            + "".join(
                '    <Piece Extent="0 %d 0 %d %d %d" Source="ball/ball_%d.vti"/>\n'
                % (dims[0] - 1, dims[1] - 1, z0, z1, n)
                for n, (z0, z1) in enumerate(slabs)
            )
            + '  </PImageData>\n</VTKFile>\n'
        )

    for name, binary in (("ball_legacy.vtk", False), ("ball_legacy_binary.vtk", True)):
        writer = vtk.vtkStructuredPointsWriter()
        writer.SetFileName(path(name))
        writer.SetInputData(image)
        writer.SetFileType(vtk.VTK_BINARY if binary else vtk.VTK_ASCII)
        assert writer.Write() == 1, name

    # NIfTI: x fastest on disk; voxel (i, j, k) at origin + spacing * (i, j, k).
    volume = distance.reshape(dims[::-1]).transpose(2, 1, 0)
    affine = np.diag([*spacing, 1.0])
    affine[:3, 3] = origin
    nibabel.save(nibabel.Nifti1Image(volume, affine), path("ball.nii.gz"))


def shape():
    points = [
        (0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),  # a quad
        (2, 0, 0), (3, 0.5, 0.2), (2.5, 1.5, 0.1),  # a triangle
        (0, 0, 1), (1, 0, 1.2), (1.5, 0.8, 1.1), (0.5, 1.5, 1.0), (-0.5, 0.8, 1.1),  # a pentagon
        (0, 2, 0), (0, 3, 0.3), (1, 2, 0.1), (1, 3, 0.4), (2, 2, 0.2), (2, 3, 0.5),  # a strip
    ]
    polys = [[0, 1, 2, 3], [4, 5, 6], [7, 8, 9, 10, 11], [1, 4, 6, 2]]
    strip = [12, 13, 14, 15, 16, 17]
    data = vtk.vtkPolyData()
    vtk_points = vtk.vtkPoints()
    for p in points:
        vtk_points.InsertNextPoint(*p)
    data.SetPoints(vtk_points)
    cells = vtk.vtkCellArray()
    for poly in polys:
        cells.InsertNextCell(len(poly), poly)
    data.SetPolys(cells)
    strips = vtk.vtkCellArray()
    strips.InsertNextCell(len(strip), strip)
    data.SetStrips(strips)
    height = numpy_support.numpy_to_vtk(np.array([p[2] + p[1] for p in points], dtype=np.float64))
    height.SetName("height")
    data.GetPointData().SetScalars(height)

    # shape_zlib.vtp is VTK's default output (zlib, with empty Verts and
    # Lines arrays), on which vtkio 0.7.0-rc2 fails: dpp must say so cleanly.
    for name, compressed in (("shape.vtp", False), ("shape_zlib.vtp", True)):
        writer = vtk.vtkXMLPolyDataWriter()
        writer.SetFileName(path(name))
        writer.SetInputData(data)
        if not compressed:
            writer.SetCompressorTypeToNone()
        assert writer.Write() == 1, name
    # Legacy 5.1 (offsets and connectivity) and 4.2 (counts before ids).
    for name, binary, version in (
        ("shape_legacy.vtk", False, 51),
        ("shape_legacy_binary.vtk", True, 51),
        ("shape_legacy42.vtk", True, 42),
    ):
        legacy = vtk.vtkPolyDataWriter()
        legacy.SetFileName(path(name))
        legacy.SetInputData(data)
        legacy.SetFileType(vtk.VTK_BINARY if binary else vtk.VTK_ASCII)
        legacy.SetFileVersion(version)
        assert legacy.Write() == 1, name

    # The OBJ: the polygons, then the strip as VTK triangulates it (odd
    # triangles with their first two corners swapped).
    faces = list(polys)
    for t in range(len(strip) - 2):
        a, b, c = strip[t], strip[t + 1], strip[t + 2]
        faces.append([a, b, c] if t % 2 == 0 else [b, a, c])
    with open(path("shape.obj"), "w") as obj:
        obj.write("# written by scripts/make-vtk-fixtures.py\n")
        for p in points:
            obj.write("v %r %r %r\n" % tuple(float(x) for x in p))
        for face in faces:
            obj.write("f " + " ".join(str(v + 1) for v in face) + "\n")


def surface_triangles(grid):
    surface = vtk.vtkDataSetSurfaceFilter()
    surface.SetInputData(grid)
    triangles = vtk.vtkTriangleFilter()
    triangles.SetInputConnection(surface.GetOutputPort())
    triangles.Update()
    return triangles.GetOutput().GetNumberOfPolys()


def cells():
    grid = vtk.vtkUnstructuredGrid()
    points = vtk.vtkPoints()
    # A 4x3x3 lattice of points: a 3x2x2 block of hexahedra.
    index = {}
    for k in range(3):
        for j in range(3):
            for i in range(4):
                index[(i, j, k)] = points.InsertNextPoint(i, j, k * 0.8)
    apex = points.InsertNextPoint(1.5, 1.5, 2.6)  # a pyramid on the top
    ridge = [points.InsertNextPoint(4.7, j, 0.4) for j in (0, 1)]  # a wedge on the side
    tip = points.InsertNextPoint(2, -0.9, 0.5)  # a tetrahedron on the front
    grid.SetPoints(points)
    pressure = []
    for k in range(2):
        for j in range(2):
            for i in range(3):
                p = lambda a, b, c: index[(i + a, j + b, k + c)]
                hexa = [p(0, 0, 0), p(1, 0, 0), p(1, 1, 0), p(0, 1, 0),
                        p(0, 0, 1), p(1, 0, 1), p(1, 1, 1), p(0, 1, 1)]
                grid.InsertNextCell(vtk.VTK_HEXAHEDRON, 8, hexa)
                pressure.append(10.0 * i + 3.0 * j + k)
    top = [index[(1, 1, 2)], index[(2, 1, 2)], index[(2, 2, 2)], index[(1, 2, 2)]]
    grid.InsertNextCell(vtk.VTK_PYRAMID, 5, top + [apex])
    pressure.append(-5.0)
    # Wedge: triangle (3,0,0)-(3,0,1)... on the x = 3 side, j in 0..1, k 0..1.
    side0 = [index[(3, 0, 0)], index[(3, 0, 1)], ridge[0]]
    side1 = [index[(3, 1, 0)], index[(3, 1, 1)], ridge[1]]
    grid.InsertNextCell(vtk.VTK_WEDGE, 6, side0 + side1)
    pressure.append(40.0)
    front = [index[(1, 0, 0)], index[(2, 0, 0)], index[(2, 0, 1)]]
    grid.InsertNextCell(vtk.VTK_TETRA, 4, front + [tip])
    pressure.append(7.5)
    grid.InsertNextCell(vtk.VTK_TETRA, 4, [index[(1, 0, 0)], index[(2, 0, 1)], index[(1, 0, 1)], tip])
    pressure.append(8.5)
    array = numpy_support.numpy_to_vtk(np.array(pressure, dtype=np.float32), deep=1)
    array.SetName("pressure")
    grid.GetCellData().SetScalars(array)
    xyz = numpy_support.vtk_to_numpy(points.GetData())
    temperature = numpy_support.numpy_to_vtk(xyz[:, 0] * 2 + xyz[:, 2], deep=1)
    temperature.SetName("temperature")
    grid.GetPointData().AddArray(temperature)

    writer = vtk.vtkXMLUnstructuredGridWriter()
    writer.SetFileName(path("cells.vtu"))
    writer.SetInputData(grid)
    assert writer.Write() == 1
    for name, version in (("cells_legacy.vtk", 51), ("cells_legacy42.vtk", 42)):
        legacy = vtk.vtkUnstructuredGridWriter()
        legacy.SetFileName(path(name))
        legacy.SetInputData(grid)
        legacy.SetFileType(vtk.VTK_BINARY)
        legacy.SetFileVersion(version)
        assert legacy.Write() == 1, name

    # Two pieces: the front half of the block (hexahedra j = 0) with the
    # wedge and the tetrahedra, and the back half with the pyramid.
    os.makedirs(path("cells"), exist_ok=True)
    pieces = [[0, 1, 2, 6, 7, 8, 13, 14, 15], [3, 4, 5, 9, 10, 11, 12]]
    assert sorted(sum(pieces, [])) == list(range(grid.GetNumberOfCells()))
    counts = []
    for n, ids in enumerate(pieces):
        extract = vtk.vtkExtractCells()
        extract.SetInputData(grid)
        chosen = vtk.vtkIdList()
        for i in ids:
            chosen.InsertNextId(i)
        extract.SetCellList(chosen)
        extract.Update()
        piece = extract.GetOutput()
        for name in ("vtkOriginalCellIds", "vtkOriginalPointIds"):
            piece.GetCellData().RemoveArray(name)
            piece.GetPointData().RemoveArray(name)
        writer = vtk.vtkXMLUnstructuredGridWriter()
        writer.SetFileName(path("cells/cells_%d.vtu" % n))
        writer.SetInputData(piece)
        writer.SetCompressorTypeToLZ4()
        assert writer.Write() == 1
        counts.append(surface_triangles(piece))
    with open(path("cells.pvtu"), "w") as pvtu:
        pvtu.write(
            '<?xml version="1.0"?>\n'
            '<VTKFile type="PUnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n'
            '  <PUnstructuredGrid GhostLevel="0">\n'
            '    <PPointData>\n'
            '      <PDataArray type="Float64" Name="temperature"/>\n'
            '    </PPointData>\n'
            '    <PCellData Scalars="pressure">\n'
            '      <PDataArray type="Float32" Name="pressure"/>\n'
            '    </PCellData>\n'
            '    <PPoints>\n'
            '      <PDataArray type="Float32" NumberOfComponents="3"/>\n'
            '    </PPoints>\n'
            + "".join('    <Piece Source="cells/cells_%d.vtu"/>\n' % n for n in range(len(pieces)))
            + '  </PUnstructuredGrid>\n</VTKFile>\n'
        )
    return {
        "cells": grid.GetNumberOfCells(),
        "pressure": pressure,
        "surface_triangles": surface_triangles(grid),
        "piece_surface_triangles": counts,
        "piece_cells": pieces,
    }


def main():
    os.makedirs(OUT, exist_ok=True)
    ball()
    shape()
    expected = {"vtk": vtk.vtkVersion.GetVTKVersion(), "cells": cells()}
    with open(path("expected.json"), "w") as out:
        json.dump(expected, out, indent=1)
        out.write("\n")
    print("wrote", os.path.normpath(OUT), file=sys.stderr)


if __name__ == "__main__":
    main()
