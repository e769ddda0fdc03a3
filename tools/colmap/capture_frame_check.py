"""Do a VDB and a mesh exported with `--to-capture` land on the capture? Reads them with
OpenVDB's own Python module (the one in the bpy wheel) and a plain PLY parser, and the COLMAP
model's points (text: `colmap model_converter --output_type TXT`), all in the capture's frame,
and prints: the share of sparse points in an active voxel's neighbourhood of the VDB (density
above zero within one voxel), and the points' median distance to the nearest mesh vertex against
the cameras' spread. Run with the validators' Python (../shared/validators/setup.sh):

    python capture_frame_check.py FILE.vdb FILE.ply POINTS3D.txt IMAGES.txt
"""

import os
import struct
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../../shared/validators"))
from _bootstrap import import_openvdb  # noqa: E402

import numpy as np  # noqa: E402

vdb_path, ply_path, points_path, images_path = sys.argv[1:5]
points = np.array(
    [[float(v) for v in line.split()[1:4]] for line in open(points_path) if line.strip() and not line.startswith("#")]
)


def camera_centres(path):
    lines = [l for l in open(path) if l.strip() and not l.startswith("#")]
    centres = []
    for line in lines[0::2]:
        v = line.split()
        qw, qx, qy, qz, tx, ty, tz = map(float, v[1:8])
        r = np.array([
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
            [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
            [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)],
        ])
        centres.append(-r.T @ np.array([tx, ty, tz]))
    return np.array(centres)


spread = np.linalg.norm(camera_centres(images_path) - camera_centres(images_path).mean(0), axis=1).mean()

vdb = import_openvdb()
grid = vdb.read(vdb_path, "density")
acc = grid.getConstAccessor()
inside = 0
for p in points:
    i, j, k = (int(round(c)) for c in grid.transform.worldToIndex(tuple(p)))
    near = any(
        acc.getValue((i + a, j + b, k + c)) > 0 for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)
    )
    inside += near
print(f"sparse points within a voxel of matter in the VDB: {inside} of {len(points)} ({100 * inside / len(points):.1f}%)")


def ply_vertices(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    count = next(int(l.split()[2]) for l in header if l.startswith("element vertex"))
    props = []
    for l in header[header.index(next(l for l in header if l.startswith("element vertex"))) + 1:]:
        if not l.startswith("property"):
            break
        props.append(l.split()[1])
    size = {"float": 4, "uchar": 1, "double": 8}
    stride = sum(size[t] for t in props)
    xyz = [struct.unpack_from("<fff", data, end + n * stride) for n in range(count)]
    return np.array(xyz)


verts = ply_vertices(ply_path)
d = np.array([np.min(np.linalg.norm(verts - p, axis=1)) for p in points])
print(f"mesh: {len(verts)} vertices; sparse points' distance to the nearest vertex: median {np.median(d):.4f}, "
      f"90th percentile {np.percentile(d, 90):.4f} ({100 * np.median(d) / spread:.2f}% / "
      f"{100 * np.percentile(d, 90) / spread:.2f}% of the cameras' mean distance from their centre, {spread:.3f})")
