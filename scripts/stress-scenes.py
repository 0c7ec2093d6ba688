#!/usr/bin/env python3
"""Writes the scenes built to break a BVH traversal or a watertight triangle
test, as OBJ files (and a binary PLY of one too large for OBJ), into a folder
(default: $DPP_SCENES/stress, else ~/.cache/dpp-scenes/stress).
docs/benchmarks.md measures dpp against Embree on them:

    python3 scripts/stress-scenes.py
    T=~/.cache/dpp-scenes/stress
    dpp bench $(ls $T/*.obj $T/*.ply | grep -v slivers) --engine dpp,embree \\
        --workloads 1 --views front --threads 2 --rounds 2 --markdown stress.md
    # (exits with status 1: on sphere-1e15 Embree's own hits are off)
    # slivers: Embree takes minutes per 1080p frame there
    dpp bench $T/slivers.obj --engine dpp,embree --workloads 1 --views front \\
        --size 480x270 --warmup 0 --rounds 1 --threads 2

Plain Python 3, no packages; deterministic (fixed seeds), so every run writes
the same files. OBJ coordinates are written with 9 significant digits, which
the loader rounds to f32; PLY ones as f32.
"""

import math
import os
import random
import sys


def write_obj(path, positions, triangles):
    with open(path, "w") as out:
        out.write("# %s: written by scripts/stress-scenes.py\n" % os.path.basename(path))
        out.writelines("v %.9g %.9g %.9g\n" % p for p in positions)
        out.writelines("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in triangles)


def grid(columns, rows, point):
    """A (columns+1) x (rows+1) grid of vertices `point(i, j)`, two triangles per cell."""
    positions = [point(i, j) for j in range(rows + 1) for i in range(columns + 1)]
    triangles = []
    for j in range(rows):
        for i in range(columns):
            a = j * (columns + 1) + i
            b, c, d = a + 1, a + columns + 2, a + columns + 1
            triangles += [(a, b, c), (a, c, d)]
    return positions, triangles


def sphere(center, radius, segments=300):
    """A latitude-longitude sphere of 2 * segments^2 triangles (the rows at the
    poles are degenerate, as in such meshes)."""

    def point(i, j):
        theta, phi = math.pi * j / segments, 2 * math.pi * i / segments
        return (
            center[0] + radius * math.sin(theta) * math.cos(phi),
            center[1] + radius * math.cos(theta),
            center[2] + radius * math.sin(theta) * math.sin(phi),
        )

    return grid(segments, segments, point)


def write_large_sphere_ply(path, segments):
    """`sphere((0, 0, 0), 1, segments)` as a binary PLY, streamed row by row:
    at millions of triangles, lists of tuples would take gigabytes."""
    import struct

    vertex, face = struct.Struct("<3f"), struct.Struct("<B3i")
    with open(path, "wb") as out:
        out.write(
            (
                "ply\nformat binary_little_endian 1.0\n"
                "comment written by scripts/stress-scenes.py\n"
                "element vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
                "element face %d\nproperty list uchar int vertex_indices\nend_header\n"
                % ((segments + 1) ** 2, 2 * segments**2)
            ).encode()
        )
        for j in range(segments + 1):
            theta = math.pi * j / segments
            row = bytearray()
            for i in range(segments + 1):
                phi = 2 * math.pi * i / segments
                row += vertex.pack(
                    math.sin(theta) * math.cos(phi),
                    math.cos(theta),
                    math.sin(theta) * math.sin(phi),
                )
            out.write(row)
        for j in range(segments):
            row = bytearray()
            for i in range(segments):
                a = j * (segments + 1) + i
                b, c, d = a + 1, a + segments + 2, a + segments + 1
                row += face.pack(3, a, b, c) + face.pack(3, a, c, d)
            out.write(row)
    return 2 * segments**2


def merged(*meshes):
    positions, triangles = [], []
    for mesh_positions, mesh_triangles in meshes:
        base = len(positions)
        positions += mesh_positions
        triangles += [(a + base, b + base, c + base) for a, b, c in mesh_triangles]
    return positions, triangles


FAR = (1e5, -2e5, 3e5)


def flat():
    """A plane seen face on: every ray's box tests tie at one depth."""
    return grid(200, 200, lambda i, j: (-1 + i / 100, -1 + j / 100, 0.0))


def soup():
    """100,000 random overlapping triangles, 1% degenerate (two equal corners)."""
    rng = random.Random(1)
    positions, triangles = [], []
    for index in range(100_000):
        center = [rng.uniform(-1, 1) for _ in range(3)]
        size = rng.uniform(0.005, 0.05)
        corners = [tuple(c + rng.uniform(-size, size) for c in center) for _ in range(3)]
        if index % 100 == 0:
            corners[2] = corners[1]
        base = len(positions)
        positions += corners
        triangles.append((base, base + 1, base + 2))
    return positions, triangles


def needles(count=50_000):
    """50,000 random needles, each about a thousandth as wide as it is long:
    a band of a ten-thousandth of a needle's width is narrower than one f32
    rounding step, which is what made `dpp bench` count rays 2-3 steps off a
    long edge as a disagreement before the border band had a rounding term."""
    rng = random.Random(2)
    positions, triangles = [], []
    for _ in range(count):
        start = [rng.uniform(-1, 1) for _ in range(3)]
        along = [rng.uniform(-1, 1) for _ in range(3)]
        end = [s + a for s, a in zip(start, along)]
        base = len(positions)
        positions += [tuple(start), tuple(end), tuple(e + 1e-4 * a + 1e-3 for e, a in zip(end, along))]
        triangles.append((base, base + 1, base + 2))
    return positions, triangles


def one_triangle():
    """A lone right triangle: its hypotenuse is an open border through the view's centre."""
    return [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)], [(0, 1, 2)]


def cube_every_face_twice(cells=122):
    """A closed cube of 6 * cells^2 quads, each triangle listed twice: every hit ties."""
    faces = []
    for axis in range(3):
        for side in (-1.0, 1.0):

            def point(i, j, axis=axis, side=side):
                u, v = -1 + 2 * i / cells, -1 + 2 * j / cells
                p = [0.0, 0.0, 0.0]
                p[axis], p[(axis + 1) % 3], p[(axis + 2) % 3] = side, u, v
                return tuple(p)

            positions, triangles = grid(cells, cells, point)
            if side < 0:
                triangles = [(a, c, b) for a, b, c in triangles]
            faces.append((positions, triangles + triangles))
    return merged(*faces)


def layers(count=60, cells=60):
    """60 stacked bumpy sheets 0.05 apart: many surfaces behind each pixel."""
    sheets = []
    for layer in range(count):
        depth = -0.05 * layer

        def point(i, j, depth=depth, layer=layer):
            x, y = -1 + 2 * i / cells, -1 + 2 * j / cells
            return (x, y, depth + 0.01 * math.sin(7 * x + layer) * math.cos(5 * y))

        sheets.append(grid(cells, cells, point))
    return merged(*sheets)


def stadium():
    """A small dense sphere on a 2000 x 2000 plate of two triangles."""
    plate = (
        [(-1000.0, -1.0, -1000.0), (1000.0, -1.0, -1000.0), (1000.0, -1.0, 1000.0), (-1000.0, -1.0, 1000.0)],
        [(0, 2, 1), (0, 3, 2)],
    )
    return merged(sphere((0.0, 0.0, 0.0), 1.0), plate)


def slivers(count=60_000):
    """A tilted cylinder of 2 * count full-length slivers (each one's box is
    nearly the cylinder's) and beside it a wavy disk fanned into count slivers
    around one vertex."""
    ca, sa, cb, sb = math.cos(0.7), math.sin(0.7), math.cos(0.5), math.sin(0.5)

    def tilted(x, y, z):
        y, z = ca * y - sa * z, sa * y + ca * z
        return cb * x + sb * z, y, -sb * x + cb * z

    positions, triangles = [], []
    for i in range(count):
        angle = 2 * math.pi * i / count
        positions += [tilted(math.cos(angle), math.sin(angle), z) for z in (-5.0, 5.0)]
    for i in range(count):
        j = (i + 1) % count
        a, b, c, d = 2 * i, 2 * i + 1, 2 * j, 2 * j + 1
        triangles += [(a, c, b), (b, c, d)]
    centre = len(positions)
    positions.append((4.0, 0.0, 0.0))
    for i in range(count):
        angle = 2 * math.pi * i / count
        positions.append((4 + 3 * math.cos(angle), 3 * math.sin(angle), 0.5 * math.sin(7 * angle)))
    triangles += [(centre, centre + 1 + i, centre + 1 + (i + 1) % count) for i in range(count)]
    return positions, triangles


SCENES = {
    "flat": flat,
    "sphere-near": lambda: sphere((0.0, 0.0, 0.0), 1.0),
    "sphere-far": lambda: sphere(FAR, 1.0),
    "sphere-far-large": lambda: sphere(FAR, 100.0),
    "sphere-tiny": lambda: sphere((0.0, 0.0, 0.0), 1e-4),
    # Beyond f32's comfortable range: cubes of coordinates overflow or underflow.
    "sphere-1e15": lambda: sphere((0.0, 0.0, 0.0), 1e15),
    "sphere-1e-14": lambda: sphere((0.0, 0.0, 0.0), 1e-14),
    "soup": soup,
    "needles": needles,
    "one-triangle": one_triangle,
    "cube-every-face-twice": cube_every_face_twice,
    "layers": layers,
    "stadium": stadium,
    "slivers": slivers,
}

# Written as binary PLY: (name, segments).
LARGE_SPHERES = [
    # 10 million triangles; PLOC's tree of its pole fans is deeper than the
    # traversal stacks allow, so that part is rebuilt by median split.
    ("sphere-10m", 2236),
]


def main():
    default = os.path.join(
        os.environ.get("DPP_SCENES", os.path.expanduser("~/.cache/dpp-scenes")), "stress"
    )
    folder = sys.argv[1] if len(sys.argv) > 1 else default
    os.makedirs(folder, exist_ok=True)
    for name, make in SCENES.items():
        positions, triangles = make()
        path = os.path.join(folder, name + ".obj")
        write_obj(path, positions, triangles)
        print("%-24s %9d triangles  %s" % (name, len(triangles), path))
    for name, segments in LARGE_SPHERES:
        path = os.path.join(folder, name + ".ply")
        count = write_large_sphere_ply(path, segments)
        print("%-24s %9d triangles  %s" % (name, count, path))


if __name__ == "__main__":
    main()
