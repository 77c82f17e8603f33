"""strahl's Python package side by side with Open3D's RaycastingScene, trimesh + embreex and embreex.

Every engine gets the same float32 numpy rays and points, in its own input type, converted
before the clock starts (Open3D tensors for Open3D); every scene is built and committed before
timing (a first query warms each engine up). Each measurement is the median of ``--passes``
passes, the engines interleaved pass by pass; ratios are strahl's throughput over the other's.

    python python/benchmarks/vs_open3d.py --out compare/results/python

needs ``pip install ./python open3d==0.20.0 "numpy<2" trimesh embreex rtree`` (Open3D 0.20 wheels
are built against numpy 1). Scenes: the shared scenes when ``../shared/scenes`` exists.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import strahl
from strahl.trimesh import RayMeshIntersector

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "scenes"
SCENES = {
    "cornell": "cornell_box/cornell_box.obj",
    "teapot": "teapot/teapot.obj",
    "bunny": "bunny/bunny.obj",
    "sibenik": "sibenik/sibenik.obj",
    "sponza": "sponza_dabrovic/sponza.obj",
    "igea": "igea/igea.obj",
    "conference": "conference/conference.obj",
}
# Interiors are seen from inside, the others from outside.
INTERIORS = {"sibenik", "sponza", "conference", "cornell"}


def cpu_name() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def camera_rays(v: np.ndarray, name: str, w: int, h: int) -> np.ndarray:
    lo, hi = v.min(0), v.max(0)
    c, ext = (lo + hi) / 2, hi - lo
    if name in INTERIORS:
        eye = c - ext * [0.3, 0.1, 0.0] if name != "cornell" else c + ext * [0.0, 0.0, 1.4]
        at = c + ext * [0.3, -0.05, 0.05] if name != "cornell" else c
        fov = 75 if name != "cornell" else 45
    else:
        eye = c + np.linalg.norm(ext) * np.array([0.35, 0.25, 0.9])
        at, fov = c, 45
    # (h, w, 6), as Open3D's users hold camera rays: both engines get the image's shape.
    return strahl.create_rays_pinhole(fov, at, eye, [0, 1, 0], w, h)


def incoherent_rays(v: np.ndarray, n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lo, hi = v.min(0), v.max(0)
    o = rng.uniform(lo, hi, (n, 3))
    d = rng.normal(size=(n, 3))
    return np.hstack([o, d / np.linalg.norm(d, axis=1, keepdims=True)]).astype(np.float32)


def query_points(v: np.ndarray, f: np.ndarray, n: int, seed: int = 2) -> np.ndarray:
    """Half near the surface (surface samples moved off it by up to 1% of the extent), half
    uniform in the box around the mesh."""
    rng = np.random.default_rng(seed)
    lo, hi = v.min(0), v.max(0)
    ext = np.linalg.norm(hi - lo)
    tri = v[f[rng.integers(0, len(f), n // 2)]].astype(np.float64)
    r = rng.uniform(size=(n // 2, 2))
    flip = r.sum(1) > 1
    r[flip] = 1 - r[flip]
    p = tri[:, 0] + (tri[:, 1] - tri[:, 0]) * r[:, :1] + (tri[:, 2] - tri[:, 0]) * r[:, 1:]
    p += rng.normal(size=p.shape) * 0.01 * ext
    u = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), (n - n // 2, 3))
    return np.vstack([p, u]).astype(np.float32)


def winding_numbers(v: np.ndarray, f: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Generalized winding numbers (Jacobson et al. 2013) in float64: the sum of the signed
    solid angles of the triangles seen from each point, over 4π (Van Oosterom–Strackee)."""
    a0, b0, c0 = (v[f[:, k]].astype(np.float64) for k in range(3))
    out = np.empty(len(pts))
    for i, p in enumerate(pts.astype(np.float64)):
        a, b, c = a0 - p, b0 - p, c0 - p
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la + np.einsum("ij,ij->i", c, a) * lb
        out[i] = np.arctan2(det, den).sum() / (2 * np.pi)
    return out


def distinct_points(t: np.ndarray, scale: float) -> int:
    """Hits along one ray (unit direction) at distinct points: sorted distances grouped where
    they differ by less than 1e-5 of the larger of the distance and the scene's largest
    coordinate `scale` (a float32 hit point is only that exact: far from the origin, two faces
    at one point get distances some ulps of the coordinates apart)."""
    x = np.sort(t)
    return 0 if len(x) == 0 else 1 + int((np.diff(x) > 1e-5 * np.maximum(x[1:], scale)).sum())


def brute_t(v: np.ndarray, f: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """t of every ray against every triangle (Möller–Trumbore in float64; inf where missed)."""
    v = v.astype(np.float64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    e1, e2 = b - a, c - a
    out = np.empty((len(rays), len(f)))
    for i, r in enumerate(rays.astype(np.float64)):
        o, d = r[:3], r[3:]
        p = np.cross(d, e2)
        det = np.einsum("tk,tk->t", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - a
            u = np.einsum("tk,tk->t", s, p) * inv
            q = np.cross(s, e1)
            w = (q @ d) * inv
            t = np.einsum("tk,tk->t", e2, q) * inv
            ok = (det != 0) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
        out[i] = np.where(ok, t, np.inf)
    return out


def timed(fn, passes: int, results: dict, key: str) -> None:
    t0 = time.perf_counter()
    fn()
    results.setdefault(key, []).append(time.perf_counter() - t0)


def median(xs):
    return statistics.median(xs)


def spread(a, b):
    """Quartiles of the per-pass ratios b[i] / a[i] (a: strahl's times)."""
    r = sorted(y / x for x, y in zip(a, b))
    q = statistics.quantiles(r, n=4) if len(r) >= 2 else [r[0]] * 3
    return q[0], q[2]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--passes", type=int, default=5)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--width", type=int, default=1024)
    ap.add_argument("--height", type=int, default=768)
    ap.add_argument("--incoherent", type=int, default=500_000)
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--all-hits-rays", type=int, default=100_000)
    ap.add_argument("--contains-points", type=int, default=20_000, help="points for trimesh's contains_points")
    ap.add_argument("--sign-points", type=int, default=2000, help="points checked against winding numbers (closed meshes)")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()

    import open3d as o3d
    import trimesh

    has_embree = trimesh.ray.has_embree
    if has_embree:
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh as EmbreexMesh

    threads = [int(t) for t in args.threads.split(",")]
    rows, accuracy = [], []
    header = {
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "python": sys.version.split()[0],
        "open3d": o3d.__version__,
        "trimesh": trimesh.__version__,
        "embreex": has_embree,
        "numpy": np.__version__,
        "passes": args.passes,
    }
    print(json.dumps(header), flush=True)
    for name in args.scenes.split(","):
        path = SHARED / SCENES[name]
        if not path.exists():
            print(f"{name}: {path} not found, skipped", flush=True)
            continue
        v, f = strahl.load_obj(path)
        sets = {
            "camera": camera_rays(v, name, args.width, args.height),
            "incoherent": incoherent_rays(v, args.incoherent),
        }
        pts = query_points(v, f, args.points)
        for nt in threads:
            ours = strahl.RaycastingScene(threads=nt)
            ours.add_triangles(v, f)
            theirs = o3d.t.geometry.RaycastingScene()
            theirs.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(f))
            pts_t = o3d.core.Tensor(pts)
            ops = []
            for kind, rays in sets.items():
                rt = o3d.core.Tensor(rays)
                ops += [
                    (f"cast_rays {kind}", rays.size // 6, lambda r=rays: ours.cast_rays(r), lambda r=rt: theirs.cast_rays(r, nthreads=nt)),
                    (f"test_occlusions {kind}", rays.size // 6, lambda r=rays: ours.test_occlusions(r),
                     lambda r=rt: theirs.test_occlusions(r, nthreads=nt)),
                ]
            ah = sets["incoherent"][: args.all_hits_rays]
            ah_t = o3d.core.Tensor(ah)
            ops += [
                ("count_intersections incoherent", len(ah), lambda: ours.count_intersections(ah),
                 lambda: theirs.count_intersections(ah_t, nthreads=nt)),
                ("compute_closest_points", len(pts), lambda: ours.compute_closest_points(pts),
                 lambda: theirs.compute_closest_points(pts_t, nthreads=nt)),
                ("compute_signed_distance", len(pts), lambda: ours.compute_signed_distance(pts),
                 lambda: theirs.compute_signed_distance(pts_t, nthreads=nt)),
                ("compute_signed_distance nsamples=1", len(pts), lambda: ours.compute_signed_distance(pts, nsamples=1),
                 lambda: theirs.compute_signed_distance(pts_t, nthreads=nt, nsamples=1)),
            ]
            for op, n, a, b in ops:
                a(), b()  # build, commit, warm up
                times: dict = {}
                for _ in range(args.passes):
                    timed(a, args.passes, times, "strahl")
                    timed(b, args.passes, times, "open3d")
                lo, hi = spread(times["strahl"], times["open3d"])
                row = {
                    "scene": name, "threads": nt, "op": op, "other": "Open3D", "n": n,
                    "strahl_mqps": n / median(times["strahl"]) / 1e6, "other_mqps": n / median(times["open3d"]) / 1e6,
                    "ratio": median(times["open3d"]) / median(times["strahl"]), "q1": lo, "q3": hi,
                }
                rows.append(row)
                print(json.dumps(row), flush=True)
        # Agreement with Open3D (2 threads' answers; they do not depend on threads).
        ours = strahl.RaycastingScene()
        ours.add_triangles(v, f)
        theirs = o3d.t.geometry.RaycastingScene()
        theirs.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(f))
        for kind, rays in sets.items():
            a = ours.cast_rays(rays)["t_hit"]
            b = theirs.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
            both = np.isfinite(a) & np.isfinite(b)
            same = (np.isfinite(a) == np.isfinite(b)) & (~both | (np.abs(a - b) <= 1e-4 * np.maximum(np.abs(b), 1e-6)))
            accuracy.append({"scene": name, "what": f"cast_rays {kind} agreement with Open3D", "value": float(same.mean())})
        ca = ours.count_intersections(ah)
        cb = theirs.count_intersections(ah_t).numpy()
        accuracy.append({"scene": name, "what": "count_intersections rays with the same count as Open3D", "value": float((ca == cb).mean())})
        # trimesh + embreex (single-threaded) against strahl.trimesh (2 threads).
        if has_embree:
            mesh = trimesh.Trimesh(v, f, process=False)
            ref = trimesh.ray.ray_pyembree.RayMeshIntersector(mesh)
            mine = RayMeshIntersector(mesh)
            o, d = ah[:, :3], ah[:, 3:]
            tm_ops = [
                ("intersects_first", lambda: mine.intersects_first(o, d), lambda: ref.intersects_first(o, d)),
                ("intersects_location (all hits)", lambda: mine.intersects_location(o, d), lambda: ref.intersects_location(o, d, multiple_hits=True)),
                ("intersects_any", lambda: mine.intersects_any(o, d), lambda: ref.intersects_any(o, d)),
            ]
            es = rtcs.EmbreeScene()
            EmbreexMesh(es, v[f])
            o32, d32 = np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32)
            tm_ops.append(("embreex run (closest hit)", lambda: mine.intersects_first(o, d), lambda: es.run(o32, d32)))
            cp = pts[: args.contains_points].astype(np.float64)
            tm_ops.append(("contains_points", lambda: mine.contains_points(cp), lambda: ref.contains_points(cp)))
            for op, a, b in tm_ops:
                n_op = len(cp) if op == "contains_points" else len(o)
                a(), b()
                times = {}
                for _ in range(args.passes):
                    timed(a, args.passes, times, "strahl")
                    timed(b, args.passes, times, "other")
                lo, hi = spread(times["strahl"], times["other"])
                row = {
                    "scene": name, "threads": 2, "op": op, "other": "trimesh+embreex" if "embreex run" not in op else "embreex",
                    "n": n_op, "strahl_mqps": n_op / median(times["strahl"]) / 1e6,
                    "other_mqps": n_op / median(times["other"]) / 1e6,
                    "ratio": median(times["other"]) / median(times["strahl"]), "q1": lo, "q3": hi,
                }
                rows.append(row)
                print(json.dumps(row), flush=True)
            # trimesh reports unique hit locations; strahl every crossing (two back-to-back faces
            # at one point are two). Compared by distinct points per ray, and the rays where
            # they differ decided by brute force (every triangle, float64).
            loc_a, ray_a, _ = mine.intersects_location(o, d)
            _, ray_b, _ = ref.intersects_location(o, d, multiple_hits=True)
            t_a = np.einsum("ij,ij->i", loc_a - o[ray_a], d[ray_a]) / np.einsum("ij,ij->i", d[ray_a], d[ray_a])
            order = np.argsort(ray_a, kind="stable")
            cut = np.searchsorted(ray_a[order], np.arange(len(o) + 1))
            scale = float(np.abs(v).max())
            na = np.array([distinct_points(t_a[order[cut[i]:cut[i + 1]]], scale) for i in range(len(o))])
            nb = np.bincount(ray_b, minlength=len(o))
            diff = np.nonzero(na != nb)[0]
            sub = diff[:300]
            bf = np.array([distinct_points(row[np.isfinite(row)], scale) for row in brute_t(v, f, ah[sub])]) if len(sub) else np.zeros(0)
            accuracy += [
                {"scene": name, "what": "all hits: distinct points, strahl", "value": int(na.sum())},
                {"scene": name, "what": "all hits: distinct points, trimesh+embreex", "value": int(nb.sum())},
                {"scene": name, "what": "all hits: rays where they differ", "value": int(len(diff))},
                {"scene": name, "what": f"all hits: of {len(sub)} differing rays, brute force agrees with strahl", "value": int((na[sub] == bf).sum())},
                {"scene": name, "what": f"all hits: of {len(sub)} differing rays, brute force agrees with trimesh+embreex", "value": int((nb[sub] == bf).sum())},
            ]
        # Signs against winding numbers, on closed meshes only.
        closed = trimesh.Trimesh(v, f, process=True).is_watertight
        if closed and args.sign_points:
            sp = pts[np.random.default_rng(3).choice(len(pts), args.sign_points, replace=False)]
            wn = winding_numbers(v, f, sp)
            inside = wn > 0.5
            sa = ours.compute_signed_distance(sp) < 0
            sa1 = ours.compute_signed_distance(sp, nsamples=1) < 0
            accuracy.append({"scene": name, "what": f"signed distance sign errors, strahl with one ray (of {len(sp)})", "value": int((sa1 != inside).sum())})
            sb = theirs.compute_signed_distance(o3d.core.Tensor(sp)).numpy() < 0
            accuracy.append({"scene": name, "what": f"signed distance sign errors, strahl (of {len(sp)})", "value": int((sa != inside).sum())})
            accuracy.append({"scene": name, "what": f"signed distance sign errors, Open3D (of {len(sp)})", "value": int((sb != inside).sum())})
            if has_embree:
                sc = ref.contains_points(sp.astype(np.float64))
                accuracy.append({"scene": name, "what": f"contains_points errors, trimesh+embreex (of {len(sp)})", "value": int((sc != inside).sum())})
                accuracy.append({"scene": name, "what": f"contains_points errors, strahl (of {len(sp)})", "value": int((mine.contains_points(sp) != inside).sum())})
        for a in accuracy:
            if a["scene"] == name:
                print(json.dumps(a), flush=True)

    md = ["| scene | query | vs | threads | strahl M/s | other M/s | ratio [q1–q3] |", "|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        md.append(
            f"| {r['scene']} | {r['op']} | {r['other']} | {r['threads']} | {r['strahl_mqps']:.2f} | {r['other_mqps']:.2f} "
            f"| {r['ratio']:.2f}× [{r['q1']:.2f}–{r['q3']:.2f}] |"
        )
    md += ["", "| scene | accuracy | value |", "|---|---|---:|"]
    md += [f"| {a['scene']} | {a['what']} | {a['value']:.4f} |" if isinstance(a["value"], float) else f"| {a['scene']} | {a['what']} | {a['value']} |" for a in accuracy]
    report = "\n".join(md)
    print(report)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "results.json").write_text(json.dumps({"machine": header, "rows": rows, "accuracy": accuracy}, indent=1))
        (args.out / "report.md").write_text(f"Machine: {header['cpu']}, {header['cores']} cores; Open3D {header['open3d']}, trimesh {header['trimesh']}.\n\n" + report + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
