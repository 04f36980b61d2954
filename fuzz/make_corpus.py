#!/usr/bin/env python3
"""Writes the seed corpus of the fuzz targets (fuzz/corpus/<target>/). Run again after changing
the input layout described at the top of fuzz_world.cpp; the fuzzers grow their own copies."""
import math
import os
import struct

here = os.path.dirname(os.path.abspath(__file__))


def world_input(flags, verts, tris, particles=0, margin=64, ox=24, oy=0, exponent=0, speed=16, raw=False):
    out = bytes([flags | (1 if raw else 0), len(verts), particles, margin, ox & 0xFF, oy & 0xFF,
                 (exponent * 4) & 0xFF, speed])
    for v in verts:
        for c in v:
            out += struct.pack('<d', c) if raw else bytes([int(round(c * 8)) & 0xFF])
    for t in tris:
        out += bytes(t)
    return out


tetra_v = [(0, 0, 0), (2, 0, 0), (0, 2, 0), (0, 0, 2)]
tetra_t = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
octa_v = [(2, 0, 0), (-2, 0, 0), (0, 2, 0), (0, -2, 0), (0, 0, 2), (0, 0, -2)]
octa_t = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
grid_v = [(x, y, 0) for y in range(4) for x in range(4)]
grid_t = []
for y in range(3):
    for x in range(3):
        a = 4 * y + x
        grid_t += [(a, a + 1, a + 5), (a, a + 5, a + 4)]
ring = 12
cyl_v = [(2 * math.cos(2 * math.pi * k / ring), 2 * math.sin(2 * math.pi * k / ring), z) for z in (-2, 2)
         for k in range(ring)]
cyl_t = []
for k in range(ring):
    a, b = k, (k + 1) % ring
    cyl_t += [(a, b, b + ring), (a, b + ring, a + ring)]

world = {
    'tetra': world_input(0, tetra_v, tetra_t),
    'tetra_all_flags': world_input(4 | 16 | 32 | 64, tetra_v, tetra_t, particles=2),
    'octa_sensors_thesis': world_input(2 | 8, octa_v, octa_t, particles=3),
    'octa_walk_estimator': world_input(128 | 16, octa_v, octa_t, speed=200),
    'single_triangle': world_input(0, [(0, 0, 0), (2, 0, 0), (0, 2, 0)], [(0, 1, 2)], ox=4),
    'patch_4x4': world_input(4 | 64, grid_v, grid_t, particles=4, ox=0, oy=8),
    'open_cylinder': world_input(16, cyl_v, cyl_t, particles=5, ox=30),
    'two_pieces': world_input(0, tetra_v + [(v[0] + 6, v[1], v[2]) for v in tetra_v],
                              tetra_t + [tuple(i + 4 for i in t) for t in tetra_t], particles=3),
    'non_manifold_fin': world_input(0, [(0, 0, 0), (2, 0, 0), (1, 2, 0), (1, -2, 0), (1, 0, 2)],
                                    [(0, 1, 2), (1, 0, 3), (0, 1, 4)]),
    'bad_winding': world_input(0, tetra_v, [(0, 1, 2), (0, 1, 3), (0, 3, 2), (1, 2, 3)]),
    'degenerate_and_isolated': world_input(0, tetra_v + [(1, 1, 1), (0, 0, 0)],
                                           tetra_t + [(0, 0, 1), (0, 1, 5)]),
    'index_out_of_range': world_input(0, tetra_v, [(0, 1, 4)]),
    'no_triangles': world_input(0, tetra_v, []),
    'nan_coordinate': world_input(0, tetra_v[:3] + [(float('nan'), 0, 0)], tetra_t, raw=True),
    'huge_coordinates': world_input(0, [(1e300, 0, 0), (-1e300, 0, 0), (0, 1e300, 0), (0, 0, 1e-300)], tetra_t,
                                    raw=True),
    'far_and_small': world_input(16, [(1e5 + x * 1e-3, y * 1e-3, z * 1e-3) for (x, y, z) in octa_v], octa_t,
                                 raw=True),
    'scaled_up': world_input(0, octa_v, octa_t, exponent=20),
    'scaled_down': world_input(0, octa_v, octa_t, exponent=-30),
}

obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
off = b"OFF\n4 4 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
ply = (b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
       b"element face 4\nproperty list uchar int vertex_indices\nend_header\n"
       b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")
stl = (b"solid t\n facet normal 0 0 -1\n  outer loop\n   vertex 0 0 0\n   vertex 0 1 0\n   vertex 1 0 0\n"
       b"  endloop\n endfacet\n facet normal 0 -1 0\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n"
       b"   vertex 0 0 1\n  endloop\n endfacet\nendsolid t\n")
ply_binary = (b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
              b"property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
              + struct.pack('<12f', 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1)
              + b"".join(struct.pack('<B3i', 3, *f) for f in [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]))
coff = (b"COFF # colours\n4 4 6\n0 0 0 1 0 0 1\n1 0 0 0 1 0 1\n0 1 0 0 0 1 1\n0 0 1 1 1 1 1\n"
        b"3 0 2 1 255 0 0\n3 0 1 3\n4 0 3 2 2\n3 1 2 3\n")
binary_stl = b"\0" * 80 + struct.pack('<I', 1) + struct.pack('<12f', 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0) + b"\0\0"
# Extension byte: index into kExtensions of fuzz_mesh_file.cpp (obj off ply stl dae 3ds x bin).
mesh_file = {
    'tetra_obj': bytes([0]) + obj,
    'tetra_off': bytes([1]) + off,
    'tetra_ply': bytes([2]) + ply,
    'tetra_ply_binary': bytes([2]) + ply_binary,
    'coff_colours': bytes([1]) + coff,
    'two_facets_stl': bytes([3]) + stl,
    'one_facet_binary_stl': bytes([3]) + binary_stl,
    'obj_lines_only': bytes([0]) + b"v 0 0 0\nv 1 0 0\nl 1 2\n",
    'obj_bad_index': bytes([0]) + b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
    'obj_nan': bytes([0]) + b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    'off_truncated': bytes([1]) + off[:30],
    'ply_as_obj': bytes([0]) + ply,
    'garbage': bytes([4]) + bytes(range(256)),
}

for name, files in (('world', world), ('mesh_file', mesh_file)):
    d = os.path.join(here, 'corpus', name)
    os.makedirs(d, exist_ok=True)
    for key, data in files.items():
        with open(os.path.join(d, key), 'wb') as f:
            f.write(data)
