"""strahl.RaycastingScene against brute-force numpy references on small meshes."""

import pickle
import threading

import numpy as np
import pytest

import strahl

INVALID = strahl.INVALID_ID


# -- meshes and references -------------------------------------------------------------------


def soup(seed, n=300, size=0.3):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-1, 1, (n, 1, 3))
    v = (c + rng.uniform(-size, size, (n, 3, 3))).reshape(-1, 3)
    return v, np.arange(3 * n).reshape(n, 3)


def box(lo=(0, 0, 0), hi=(1, 1, 1)):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[(hi if i & (1 << a) else lo)[a] for a in range(3)] for i in range(8)])
    quads = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]]
    f = np.array([t for a, b, c, d in quads for t in ([a, b, c], [a, c, d])])
    return v, f


def icosphere(subdiv=3, radius=1.0, center=(0, 0, 0)):
    t = (1 + 5**0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
         [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(subdiv):
        mid, nf = {}, []

        def m(a, b):
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
    return np.array(v) * radius + np.asarray(center, float), np.array(f)


def random_rays(seed, n):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-2, 2, (n, 3))
    d = rng.uniform(-1, 1, (n, 3)) - o
    return np.hstack([o, d]).astype(np.float32)


def brute_hits(v, f, rays):
    """t of every ray against every triangle (Möller–Trumbore, float64), inf where missed."""
    v = v.astype(np.float64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    o, d = rays[:, None, :3].astype(np.float64), rays[:, None, 3:].astype(np.float64)
    e1, e2 = b - a, c - a
    p = np.cross(d, e2)
    det = np.einsum("rtk,tk->rt", p, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - a
        u = np.einsum("rtk,rtk->rt", s, p) * inv
        q = np.cross(s, e1)
        w = np.einsum("rtk,rtk->rt", d, q) * inv
        t = np.einsum("tk,rtk->rt", e2, q) * inv
    ok = (det != 0) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
    return np.where(ok, t, np.inf)


def brute_distance(v, f, pts):
    """Distance from each point to the mesh, by sampling-free projection + edge segments."""
    v = v.astype(np.float64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    out = np.empty(len(pts))
    for i, p in enumerate(pts.astype(np.float64)):
        q = p - n * np.einsum("tk,tk->t", p - a, n)[:, None]
        inside = np.ones(len(f), bool)
        for x, y in ((a, b), (b, c), (c, a)):
            inside &= np.einsum("tk,tk->t", np.cross(y - x, q - x), n) >= 0
        d_plane = np.linalg.norm(p - q, axis=1)

        def seg(x, y):
            xy = y - x
            s = np.clip(np.einsum("tk,tk->t", p - x, xy) / np.einsum("tk,tk->t", xy, xy), 0, 1)
            return np.linalg.norm(x + xy * s[:, None] - p, axis=1)

        d_edge = np.minimum(np.minimum(seg(a, b), seg(b, c)), seg(c, a))
        out[i] = np.min(np.where(inside, d_plane, d_edge))
    return out


def scene_of(*meshes, **kw):
    s = strahl.RaycastingScene(**kw)
    for v, f in meshes:
        s.add_triangles(v, f)
    return s


# -- ray queries -------------------------------------------------------------------------------


@pytest.mark.parametrize("watertight", [True, False])
def test_cast_rays_matches_brute_force(watertight):
    v, f = soup(1)
    rays = random_rays(2, 2000)
    ans = scene_of((v, f), watertight=watertight).cast_rays(rays)
    t = brute_hits(v, f, rays)
    want = t.min(axis=1)
    hit = np.isfinite(want)
    assert hit.sum() > 500
    assert np.array_equal(np.isfinite(ans["t_hit"]), hit)
    np.testing.assert_allclose(ans["t_hit"][hit], want[hit], rtol=1e-4)
    # The triangle named is one at the nearest distance.
    prim = ans["primitive_ids"][hit]
    np.testing.assert_allclose(t[hit][np.arange(hit.sum()), prim], want[hit], rtol=1e-4)
    assert np.all(ans["geometry_ids"][hit] == 0) and np.all(ans["geometry_ids"][~hit] == INVALID)
    # Unit normals of the named triangles; the hit point from the barycentrics.
    n = ans["primitive_normals"][hit]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, rtol=1e-5)
    a, b, c = (v[f[prim, k]] for k in range(3))
    uv = ans["primitive_uvs"][hit]
    p = a * (1 - uv.sum(1, keepdims=True)) + b * uv[:, :1] + c * uv[:, 1:]
    np.testing.assert_allclose(p, rays[hit, :3] + rays[hit, 3:] * want[hit, None], atol=1e-4)


def test_occlusion_and_interval():
    v, f = soup(3)
    rays = random_rays(4, 2000)
    s = scene_of((v, f))
    t = brute_hits(v, f, rays)
    np.testing.assert_array_equal(s.test_occlusions(rays), np.isfinite(t).any(axis=1))
    occ = s.test_occlusions(rays, tnear=0.5, tfar=1.0)
    np.testing.assert_array_equal(occ, ((t > 0.5) & (t <= 1.0)).any(axis=1))
    ans = s.cast_rays(rays, tnear=0.5)
    want = np.where(t > 0.5, t, np.inf).min(axis=1)
    np.testing.assert_allclose(ans["t_hit"], want, rtol=1e-4)


def test_all_hits_in_one_walk_match_brute_force():
    v, f = soup(5, n=400)
    rays = random_rays(6, 1500)
    s = scene_of((v, f))
    t = brute_hits(v, f, rays)
    lists = s.list_intersections(rays)
    counts = s.count_intersections(rays)
    assert counts.dtype == np.int32
    splits = lists["ray_splits"]
    assert len(splits) == len(rays) + 1 and splits[-1] == len(lists["t_hit"])
    np.testing.assert_array_equal(np.diff(splits), counts)
    for i in range(len(rays)):
        want = np.sort(t[i][np.isfinite(t[i])])
        got = lists["t_hit"][splits[i]:splits[i + 1]]
        assert np.all(lists["ray_ids"][splits[i]:splits[i + 1]] == i)
        assert len(got) == len(want), i
        np.testing.assert_allclose(got, want, rtol=1e-4)
    assert (counts >= 3).sum() > 100


def test_crossings_through_shared_edges_count_once():
    s = scene_of(box())
    # Through face diagonals (shared edges), corners' neighbourhoods and face centres.
    pts = np.array([[0.5, 0.5], [0.25, 0.25], [0.75, 0.75], [0.3, 0.7], [0.5, 0.2]])
    rays = []
    for axis in range(3):
        for a, b in pts:
            o = np.zeros(3)
            o[(axis + 1) % 3], o[(axis + 2) % 3], o[axis] = a, b, -1
            d = np.zeros(3)
            d[axis] = 1
            rays.append(np.concatenate([o, d]))
    np.testing.assert_array_equal(s.count_intersections(np.array(rays)), 2)


# -- point queries -----------------------------------------------------------------------------


def test_closest_points_match_brute_force():
    v, f = soup(7, n=200)
    s = scene_of((v, f))
    pts = np.random.default_rng(8).uniform(-2, 2, (300, 3)).astype(np.float32)
    ans = s.compute_closest_points(pts)
    want = brute_distance(v, f, pts)
    np.testing.assert_allclose(ans["distance"], want, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(s.compute_distance(pts), want, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(ans["points"] - pts, axis=1), want, rtol=1e-4, atol=1e-6)
    prim = ans["primitive_ids"]
    a, b, c = (v[f[prim, k]] for k in range(3))
    uv = ans["primitive_uvs"]
    p = a * (1 - uv.sum(1, keepdims=True)) + b * uv[:, :1] + c * uv[:, 1:]
    np.testing.assert_allclose(p, ans["points"], atol=1e-5)


def test_signed_distance_and_occupancy_of_closed_meshes():
    sv, sf = icosphere(3, 0.8, (2, 0, 0))
    s = scene_of(box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)), (sv, sf))
    rng = np.random.default_rng(9)
    pts = rng.uniform(-1, 1, (3000, 3)) * [2, 1, 1] + [1, 0, 0]
    in_box = np.all(np.abs(pts) < 0.5, axis=1)
    r = np.linalg.norm(pts - [2, 0, 0], axis=1)
    keep = np.abs(r - 0.8) > 0.02  # the tessellated sphere lies inside the true one
    in_ball = r < 0.8
    sd = s.compute_signed_distance(pts)
    occ = s.compute_occupancy(pts)
    assert occ.dtype == np.float32
    np.testing.assert_array_equal(occ[keep], (in_box | in_ball)[keep].astype(np.float32))
    np.testing.assert_array_equal(sd < 0, occ == 1)
    np.testing.assert_allclose(np.abs(sd), s.compute_distance(pts), rtol=1e-6)
    assert (occ == 1).sum() > 200
    # One ray, as Open3D casts, or seven: the same answers on closed meshes.
    for n in (1, 7):
        np.testing.assert_array_equal(s.compute_occupancy(pts, nsamples=n)[keep], occ[keep])
        np.testing.assert_array_equal(s.compute_signed_distance(pts, nsamples=n)[keep], sd[keep])
    for bad in (0, 8, 2.5, True):
        with pytest.raises(ValueError, match="nsamples"):
            s.compute_occupancy(pts[:3], nsamples=bad)


# -- instancing --------------------------------------------------------------------------------


def transform(scale, angle, shift):
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:3, :3] = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ np.diag(scale)
    m[:3, 3] = shift
    return m


def test_instances_match_the_transformed_geometry():
    v, f = icosphere(2, 0.5)
    ts = np.stack([transform([1, 1, 1], 0, [0, 0, 0]), transform([0.5, 1.5, 0.8], 0.7, [1.5, 0.3, -0.2]),
                   transform([-1, 0.7, 1.2], -0.4, [-1.2, -0.5, 0.4])])
    s = strahl.RaycastingScene()
    g = s.add_triangles(v, f)
    ids = s.add_instances(g, ts)
    np.testing.assert_array_equal(ids, [0, 1, 2])
    flat = strahl.RaycastingScene()
    for m in ts:
        flat.add_triangles(v @ m[:3, :3].T + m[:3, 3], f)
    rays = random_rays(10, 3000)
    a, b = s.cast_rays(rays), flat.cast_rays(rays)
    hit = np.isfinite(b["t_hit"])
    assert hit.sum() > 300
    np.testing.assert_array_equal(np.isfinite(a["t_hit"]), hit)
    np.testing.assert_allclose(a["t_hit"][hit], b["t_hit"][hit], rtol=1e-4)
    np.testing.assert_array_equal(a["instance_ids"][hit], b["geometry_ids"][hit])
    assert np.all(a["geometry_ids"][hit] == g)
    np.testing.assert_allclose(np.sum(a["primitive_normals"][hit] * b["primitive_normals"][hit], 1), 1, atol=1e-3)
    np.testing.assert_array_equal(s.count_intersections(rays), flat.count_intersections(rays))
    pts = np.random.default_rng(11).uniform(-2.5, 2.5, (500, 3))
    np.testing.assert_allclose(s.compute_distance(pts), flat.compute_distance(pts), rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(s.compute_occupancy(pts), flat.compute_occupancy(pts))


# -- input handling ----------------------------------------------------------------------------


def test_dtypes_layouts_and_shapes():
    v, f = soup(12, n=100)
    s = scene_of((v, f))
    rays = random_rays(13, 256)
    base = s.cast_rays(rays)["t_hit"]
    # float64, non-contiguous, and batched shapes give the same answers.
    np.testing.assert_array_equal(s.cast_rays(rays.astype(np.float64))["t_hit"], base)
    wide = np.zeros((256, 12), np.float32)
    wide[:, ::2] = rays
    np.testing.assert_array_equal(s.cast_rays(wide[:, ::2])["t_hit"], base)
    np.testing.assert_array_equal(s.cast_rays(np.asfortranarray(rays))["t_hit"], base)
    ans = s.cast_rays(rays.reshape(16, 16, 6))
    assert ans["t_hit"].shape == (16, 16) and ans["primitive_normals"].shape == (16, 16, 3)
    np.testing.assert_array_equal(ans["t_hit"].ravel(), base)
    # Any integer index type; float64 vertices.
    s2 = scene_of((v.astype(np.float64), f.astype(np.int16)))
    np.testing.assert_array_equal(s2.cast_rays(rays)["t_hit"], base)
    # Empty input, empty scene.
    assert s.cast_rays(np.zeros((0, 6)))["t_hit"].shape == (0,)
    assert s.list_intersections(np.zeros((0, 6)))["ray_splits"].tolist() == [0]
    empty = strahl.RaycastingScene()
    assert np.all(np.isinf(empty.cast_rays(rays)["t_hit"]))
    assert np.all(np.isinf(empty.compute_distance(np.zeros((3, 3)))))
    assert not empty.compute_occupancy(np.zeros((3, 3))).any()


def test_bad_input_raises_clear_errors():
    v, f = soup(14, n=10)
    s = scene_of((v, f))
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        s.cast_rays(np.zeros((4, 5)))
    with pytest.raises(ValueError):
        s.compute_distance(np.zeros(4))
    with pytest.raises(TypeError):
        s.cast_rays(np.array([["a"] * 6]))
    with pytest.raises(TypeError):
        s.cast_rays(np.ones((2, 6), dtype=bool))
    with pytest.raises(ValueError, match="must lie in"):
        s.add_triangles(v, f + 100)
    with pytest.raises(ValueError, match="must lie in"):
        s.add_triangles(v, f - 1)
    with pytest.raises(TypeError):
        s.add_triangles(v, f.astype(np.float32))
    with pytest.raises(ValueError):
        s.add_triangles(v[:, :2], f)
    with pytest.raises(ValueError, match="not invertible"):
        s.add_instances(0, np.diag([1.0, 0.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="last row"):
        s.add_instances(0, np.ones((4, 4)))
    with pytest.raises(ValueError, match="no geometry"):
        s.add_instances(7, np.eye(4))
    with pytest.raises(ValueError):
        strahl.RaycastingScene(threads=-1)
    with pytest.raises(ValueError):
        strahl.RaycastingScene(threads=1.5)
    with pytest.raises(ValueError, match="quality"):
        strahl.RaycastingScene(quality="ultra")
    with pytest.raises(ValueError):
        strahl.create_rays_pinhole(90, [0, 0, 0], [0, 0, 0], [0, 1, 0], 4, 4)
    # NaN and zero-direction rays miss; NaN vertices and points have defined answers.
    bad = np.array([[0, 0, 0, 0, 0, 0], [np.nan, 0, 0, 0, 0, 1], [0, 0, 0, np.nan, 0, 1]], np.float32)
    assert np.all(np.isinf(s.cast_rays(bad)["t_hit"]))
    assert not s.test_occlusions(bad).any() and not s.count_intersections(bad).any()
    vn = v.copy()
    vn[0] = np.nan
    assert len(scene_of((vn, f)).cast_rays(random_rays(1, 10))["t_hit"]) == 10
    d = s.compute_signed_distance(np.array([[np.nan, 0, 0], [np.inf, 0, 0]]))
    assert np.all(np.isnan(d))


# -- pickling, threads, cameras ----------------------------------------------------------------


def test_pickle_round_trip():
    v, f = soup(15, n=100)
    s = scene_of((v, f))
    s.add_instances(0, np.stack([np.eye(4), transform([1, 2, 1], 0.3, [3, 0, 0])]))
    rays = random_rays(16, 500)
    before = s.cast_rays(rays)
    s2 = pickle.loads(pickle.dumps(s))
    assert s2._core is not None, "the built BVH travels with the pickle"
    after = s2.cast_rays(rays)
    for k in before:
        np.testing.assert_array_equal(before[k], after[k])
    flat = scene_of((v, f), watertight=False)
    flat.cast_rays(rays[:1])
    flat2 = pickle.loads(pickle.dumps(flat))
    np.testing.assert_array_equal(flat2.cast_rays(rays)["t_hit"], flat.cast_rays(rays)["t_hit"])
    # An unbuilt scene pickles its geometry only.
    fresh = pickle.loads(pickle.dumps(scene_of((v, f))))
    assert fresh._core is None
    np.testing.assert_array_equal(fresh.cast_rays(rays)["t_hit"], scene_of((v, f)).cast_rays(rays)["t_hit"])
    # Bytes that are not a scene are refused, whatever they hold.
    instanced, data, ids = s._core.serialize()
    for bad in (b"", b"garbage", data[: len(data) // 2], data + b"\0"):
        with pytest.raises(ValueError):
            strahl._strahl.Core.deserialize(instanced, bad, ids, 1)
    with pytest.raises(ValueError):
        strahl._strahl.Core.deserialize(instanced, data, ids[:-1], 1)


def test_threads_agree_and_python_threads_may_share_a_scene():
    v, f = soup(17, n=500)
    rays = random_rays(18, 20000)
    one = scene_of((v, f), threads=1)
    two = scene_of((v, f), threads=2)
    assert one.threads == 1 and two.threads == 2
    want = one.cast_rays(rays)
    got = two.cast_rays(rays)
    for k in want:
        np.testing.assert_array_equal(want[k], got[k])
    results, errors = [None] * 6, []

    def work(i):
        try:
            results[i] = two.cast_rays(rays)["t_hit"]
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    ts = [threading.Thread(target=work, args=(i,)) for i in range(6)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    assert not errors
    for r in results:
        np.testing.assert_array_equal(r, want["t_hit"])


def test_pinhole_rays():
    rays = strahl.create_rays_pinhole(fov_deg=90, center=[0, 0, 0], eye=[0, 0, 5], up=[0, 1, 0], width_px=64, height_px=48)
    assert rays.shape == (48, 64, 6) and rays.dtype == np.float32
    np.testing.assert_allclose(rays[..., :3], np.broadcast_to([0, 0, 5], (48, 64, 3)))
    d = rays[..., 3:] / np.linalg.norm(rays[..., 3:], axis=-1, keepdims=True)
    # The middle looks at the centre; the horizontal field of view is 90° between outer edges.
    mid = (rays[23, 31, 3:] + rays[24, 32, 3:]) / 2
    np.testing.assert_allclose(mid / np.linalg.norm(mid), [0, 0, -1], atol=1e-6)
    left, right = rays[24, 0, 3:], rays[24, 63, 3:]
    assert left[0] * right[0] < 0
    half = np.degrees(np.arctan(abs(left[0] / left[2])))
    assert abs(half - 45 * (63 / 64)) < 0.5
    # Row 0 is the top of the image: up is +y in the world, image y grows downwards.
    assert d[0, 32, 1] < 0 < d[47, 32, 1] or d[0, 32, 1] > 0 > d[47, 32, 1]
    # The intrinsic/extrinsic form gives the same rays.
    f = 32 / np.tan(np.radians(45))
    k = np.array([[f, 0, 32], [0, f, 24], [0, 0, 1]])
    x = np.cross([0, 1, 0], [0, 0, -1])
    r = np.stack([x, np.cross([0, 0, -1], x), [0, 0, -1]])
    e = np.eye(4)
    e[:3, :3] = r
    e[:3, 3] = -r @ [0, 0, 5]
    np.testing.assert_allclose(strahl.create_rays_pinhole(k, e, 64, 48), rays, atol=1e-5)
    s = scene_of(box((-1, -1, -1), (1, 1, 1)))
    t = s.cast_rays(rays)["t_hit"]
    # The front face (z = 1, 4 from the eye) spans x in [-1, 1]: a quarter of the half-width.
    assert np.isfinite(t).sum() == 16 * 16


def test_load_obj(tmp_path):
    p = tmp_path / "quad.obj"
    p.write_text("o a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\no b\nv 0 0 1\nv 1 0 1\nv 0 1 1\nf -3 -2 -1\n")
    v, f = strahl.load_obj(p)
    assert v.shape == (7, 3) and f.shape == (3, 3) and v.dtype == np.float32 and f.dtype == np.uint32
    parts = strahl.load_obj(p, merge=False)
    assert [len(x[1]) for x in parts] == [2, 1]
    s = scene_of((v, f))
    t = s.cast_rays(np.array([[0.2, 0.3, 2, 0, 0, -1]], np.float32))["t_hit"]
    np.testing.assert_allclose(t, [1.0])
    with pytest.raises(OSError):
        strahl.load_obj(tmp_path / "missing.obj")
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match="line"):
        strahl.load_obj(bad)


# -- scene files: solids --------------------------------------------------------------------


SOLIDS_TOML = """
[mesh.ball]
solid = { difference = [ { sphere = { radius = 1.0 } }, { box = { min = [0.0, 0.0, 0.0], max = [2.0, 2.0, 2.0] } } ] }

[mesh.ring]
solid = { supertoroid = { major = 1.0, minor = 0.25, e = 0.5, n = 0.5 } }

[[instance]]
mesh = "ball"

[[instance]]
mesh = "ring"
translate = [5.0, 0.0, 0.0]
"""


def test_scene_file_solids(tmp_path):
    path = tmp_path / "solids.toml"
    path.write_text(SOLIDS_TOML)
    scene = strahl.RaycastingScene.from_scene_file(path, threads=2)
    # Straight down onto the ball: outside the cut-away octant the top of the sphere (t = 4),
    # inside it the cut face z = 0 (t = 5) where the sphere's cap was removed.
    rays = np.array([[-0.3, -0.2, 5, 0, 0, -1], [0.3, 0.2, 5, 0, 0, -1], [5.0, 5.0, 5, 0, 0, -1]], np.float32)
    hits = scene.cast_rays(rays)
    expected = 5 - np.sqrt(1 - 0.13)
    assert abs(hits["t_hit"][0] - expected) < 1e-5
    assert abs(hits["t_hit"][1] - 5.0) < 1e-5
    assert np.isinf(hits["t_hit"][2])
    # Geometry ids are the mesh tables in name order ("ball", "ring"); instance ids the
    # [[instance]]s.
    assert list(hits["geometry_ids"][:2]) == [0, 0] and list(hits["instance_ids"][:2]) == [0, 0]
    # Along x through the squared ring (centre x = 5): crossings at 5 ± 1 ± 0.25.
    ring = np.array([[2.0, 0.0, 0.0, 1, 0, 0]], np.float32)
    h = scene.cast_rays(ring)
    assert abs(h["t_hit"][0] - 1.75) < 1e-5 and h["geometry_ids"][0] == 1 and h["instance_ids"][0] == 1
    assert scene.count_intersections(ring)[0] == 4
    clone = pickle.loads(pickle.dumps(scene))
    assert np.array_equal(clone.cast_rays(rays)["t_hit"], hits["t_hit"])
    with pytest.raises(ValueError, match="scene file"):
        scene.add_triangles(*box())


def test_scene_file_errors(tmp_path):
    with pytest.raises(OSError):
        strahl.RaycastingScene.from_scene_file(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[mesh.r]\nsolid = { supertoroid = { major = 1.0, minor = 2.0 } }\n[[instance]]\nmesh = \"r\"\n")
    with pytest.raises(ValueError, match="supertoroid"):
        strahl.RaycastingScene.from_scene_file(bad)
