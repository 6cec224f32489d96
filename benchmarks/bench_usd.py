"""Export speed: a room of about 1 000 000 triangles written as .usda, .usdc and .usdz.

    python3 benchmarks/bench_usd.py [--triangles 1000000] [--repeats 3]

The room is the built-in living room's box, tessellated finely (every wall, the floor and the
ceiling), with per-vertex colours, two labelled surfaces and three 10 s sources. Each format is
timed with and without OpenUSD's validators (``write_scene(check=...)``). The baseline, in the
same run, is open3d writing the same mesh as binary PLY: speed is reported as a ratio to it.
Prints a table; the median of ``--repeats`` runs.
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

import usd_export
import vrecho
from localization import PlacedSource


def grid_room(n_triangles: int, room) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed box around the room's footprint bounds, about ``n_triangles`` triangles."""
    lo, hi = room.footprint.min(axis=0), room.footprint.max(axis=0)
    box_lo, box_hi = np.r_[lo, 0.0], np.r_[hi, room.height_m]
    size = box_hi - box_lo
    area = 2 * (size[0] * size[1] + size[0] * size[2] + size[1] * size[2])
    step = np.sqrt(2 * area / n_triangles)
    verts, faces = [], []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        na, nb = int(np.ceil(size[a] / step)), int(np.ceil(size[b] / step))
        ua, ub = np.meshgrid(np.linspace(box_lo[a], box_hi[a], na + 1), np.linspace(box_lo[b], box_hi[b], nb + 1),
                             indexing="ij")
        for side in (box_lo[axis], box_hi[axis]):
            p = np.zeros((ua.size, 3))
            p[:, a], p[:, b], p[:, axis] = ua.ravel(), ub.ravel(), side
            idx = np.arange(ua.size).reshape(ua.shape) + sum(len(v) for v in verts)
            q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
            faces += [q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
            verts.append(p)
    v = np.vstack(verts)
    rng = np.random.default_rng(0)
    return v, np.vstack(faces), rng.uniform(0.3, 0.9, (len(v), 3))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    import open3d as o3d

    scene = vrecho.builtin_scene()
    v, f, c = grid_room(args.triangles, scene.room)
    surfaces = [usd_export.LabeledSurface(f"{d.kind}_{k}", scene.discontinuity_corners(k),
                                          "open" if d.is_open else "closed", None if d.is_open else d.kind, 1.5, 0.9)
                for k, d in enumerate(scene.discontinuities)]
    rng = np.random.default_rng(1)
    sources = [PlacedSource(s.position, rng.normal(0, 0.1, 441_000), 44_100, 0.8, s.sound)
               for s in scene.sources]
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f.astype(np.int32)))
    mesh.vertex_colors = o3d.utility.Vector3dVector(c)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        def timed(fn):
            ts = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                fn()
                ts.append(time.perf_counter() - t)
            return float(np.median(ts))

        base = timed(lambda: o3d.io.write_triangle_mesh(str(Path(tmp) / "room.ply"), mesh, write_ascii=False))
        rows.append(("open3d binary PLY (baseline)", base, Path(tmp, "room.ply").stat().st_size))
        for suffix in (".usda", ".usdc", ".usdz"):
            for check in (False, True):
                out = Path(tmp) / f"scene{suffix}"
                t = timed(lambda: usd_export.write_scene(out, (v, f, c), surfaces, sources, check=check))
                rows.append((f"usd_export {suffix}{' + validation' if check else ''}", t, out.stat().st_size))
    print(f"\n{len(f):,} triangles, {len(v):,} vertices, {len(surfaces)} surfaces, {len(sources)} sources of 10 s; "
          f"median of {args.repeats}; {platform.node()} {time.strftime('%Y-%m-%d')}")
    print("| writer | seconds | x baseline | file MB |\n|---|---|---|---|")
    for name, t, size in rows:
        print(f"| {name} | {t:.2f} | {t / base:.1f} | {size / 1e6:.1f} |")


if __name__ == "__main__":
    main()
