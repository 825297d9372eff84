"""Point-preview build speed in Blender (bpy as a module): prints seconds per preview size.

    python scripts/bench_preview.py [COUNT ...]        (default: 100000 1000000)

Times ``artgs_addon.pointcloud.point_cloud_object`` (mesh + colour + radius attributes via
foreach_set, geometry-nodes display modifier) on random points, best of three runs.
"""

from __future__ import annotations

import sys
import time

import bpy
import numpy as np

from artgs.artgs_addon.pointcloud import point_cloud_object


def main(argv: list[str]) -> int:
    counts = [int(a) for a in argv] or [100_000, 1_000_000]
    rng = np.random.default_rng(0)
    collection = bpy.context.scene.collection
    for n in counts:
        points, colors, radius = rng.normal(size=(n, 3)), rng.random((n, 3)), np.full(n, 0.01)
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            obj = point_cloud_object("bench", points, colors, radius, collection)
            best = min(best, time.perf_counter() - t0)
            mesh = obj.data
            bpy.data.objects.remove(obj)
            bpy.data.meshes.remove(mesh)
        print(f"{n:>9d} points: {best:.3f} s ({n / best / 1e6:.1f} M points/s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
