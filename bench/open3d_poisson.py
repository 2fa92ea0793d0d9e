#!/usr/bin/python3
"""Open3D's Poisson surface reconstruction, the peer of bench_integration (Debian's python3-open3d).

    open3d_poisson.py POINTS.ply DEPTH OUT.ply

POINTS.ply holds oriented points (x y z nx ny nz); the mesh goes to OUT.ply, and one line of
JSON to stdout: the seconds the reconstruction took and the threads it may use. Exit code 3 when
Open3D is not installed, 1 on bad input.
"""
import json
import os
import sys
import time

try:
    import open3d as o3d
except ImportError:
    sys.exit(3)


def main():
    if len(sys.argv) != 4:
        print(__doc__, file=sys.stderr)
        sys.exit(1)
    points, depth, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    pcd = o3d.io.read_point_cloud(points)
    if not pcd.has_points() or not pcd.has_normals():
        print(f"open3d_poisson: {points} has no oriented points", file=sys.stderr)
        sys.exit(1)
    t0 = time.perf_counter()
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=depth)
    seconds = time.perf_counter() - t0
    if not o3d.io.write_triangle_mesh(out, mesh, write_ascii=False):
        print(f"open3d_poisson: cannot write {out}", file=sys.stderr)
        sys.exit(1)
    print(json.dumps({"seconds": seconds, "threads": os.cpu_count(), "version": o3d.__version__}))


if __name__ == "__main__":
    main()
