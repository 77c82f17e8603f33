"""Analytic spheres (``add_spheres``) against the same spheres tessellated, from Python.

10,000 random spheres in a 20-unit cube, once as a sphere set and once as icospheres of 1,280
triangles each (12.8 million triangles). Each scene is built and warmed up by one query before
the clock; each figure is the best of ``--passes`` ``cast_rays`` calls on the same float32 rays:
1024² camera rays and 2^20 scattered rays (uniform origins in the cube, normal directions).

    python python/benchmarks/spheres_vs_mesh.py --threads 2
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

import strahl


def icosphere(subdiv: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere: 20 · 4^subdiv triangles."""
    t = (1 + 5**0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
         [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdiv):
        mid: dict = {}
        nf = []

        def m(a: int, b: int) -> int:
            k = (min(a, b), max(a, b))
            if k not in mid:
                p = v[a] + v[b]
                v.append(p / np.linalg.norm(p))
                mid[k] = len(v) - 1
            return mid[k]

        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = nf
    return np.array(v), np.array(f)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--passes", type=int, default=5)
    ap.add_argument("--spheres", type=int, default=10_000)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    n = args.spheres
    c = rng.uniform(-10, 10, (n, 3))
    r = rng.uniform(0.1, 0.4, n)
    v0, f0 = icosphere(3)
    scenes = {}
    t0 = time.perf_counter()
    s = strahl.RaycastingScene(threads=args.threads)
    s.add_spheres(c, r)
    s.cast_rays(np.zeros((1, 6), np.float32))
    scenes["spheres"] = (s, time.perf_counter() - t0)
    verts = (v0[None] * r[:, None, None] + c[:, None]).reshape(-1, 3)
    tris = (f0[None] + (np.arange(n) * len(v0))[:, None, None]).reshape(-1, 3)
    t0 = time.perf_counter()
    m = strahl.RaycastingScene(threads=args.threads)
    m.add_triangles(verts, tris)
    m.cast_rays(np.zeros((1, 6), np.float32))
    scenes[f"icospheres ({len(f0)} triangles each)"] = (m, time.perf_counter() - t0)
    camera = strahl.create_rays_pinhole(fov_deg=60, center=[0, 0, 0], eye=[0, 0, -30], up=[0, 1, 0],
                                        width_px=1024, height_px=1024)
    scattered = np.hstack([rng.uniform(-10, 10, (1 << 20, 3)), rng.normal(size=(1 << 20, 3))]).astype(np.float32)
    print(f"{platform.processor() or platform.machine()}, {args.threads} threads, {n} spheres")
    print("| model | build s | camera Mrays/s | scattered Mrays/s | camera rays hit |")
    print("|---|---:|---:|---:|---:|")
    for name, (scene, build) in scenes.items():
        speeds = []
        for rays in (camera, scattered):
            best = float("inf")
            for _ in range(args.passes):
                t0 = time.perf_counter()
                ans = scene.cast_rays(rays)
                best = min(best, time.perf_counter() - t0)
            speeds.append(rays.size // 6 / best / 1e6)
        hit = np.isfinite(scene.cast_rays(camera)["t_hit"]).mean()
        print(f"| {name} | {build:.3f} | {speeds[0]:.1f} | {speeds[1]:.1f} | {hit:.3f} |")


if __name__ == "__main__":
    main()
