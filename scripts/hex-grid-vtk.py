#!/usr/bin/env python3
"""A legacy binary VTK unstructured grid of N^3 unit hexahedra, for timing how
dpp reads large unstructured grids (their external faces): docs/benchmarks.md,
"External faces by a sort". Standard library only.

Usage: python3 scripts/hex-grid-vtk.py N OUT.vtk
"""
import array
import sys


def main():
    n, out = int(sys.argv[1]), sys.argv[2]
    m = n + 1

    def big_endian(values):
        values.byteswap()
        return values.tobytes()

    def index(i, j, k):
        return i + m * (j + m * k)

    points = array.array("f")
    for k in range(m):
        for j in range(m):
            for i in range(m):
                points.extend((i, j, k))
    cells = array.array("i")
    for k in range(n):
        for j in range(n):
            for i in range(n):
                cells.extend((8, index(i, j, k), index(i + 1, j, k), index(i + 1, j + 1, k),
                              index(i, j + 1, k), index(i, j, k + 1), index(i + 1, j, k + 1),
                              index(i + 1, j + 1, k + 1), index(i, j + 1, k + 1)))
    with open(out, "wb") as f:
        f.write(b"# vtk DataFile Version 3.0\nhexahedra\nBINARY\nDATASET UNSTRUCTURED_GRID\n")
        f.write(b"POINTS %d float\n" % m**3 + big_endian(points) + b"\n")
        f.write(b"CELLS %d %d\n" % (n**3, 9 * n**3) + big_endian(cells) + b"\n")
        # VTK_HEXAHEDRON is cell type 12.
        f.write(b"CELL_TYPES %d\n" % n**3 + big_endian(array.array("i", [12] * n**3)) + b"\n")


if __name__ == "__main__":
    main()
