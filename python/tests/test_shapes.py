"""Analytic spheres and CSG solids in strahl.RaycastingScene (add_spheres, add_solid) against
float64 numpy references and point membership."""

import pickle

import numpy as np
import pytest

import strahl

from test_raycasting import brute_hits, random_rays, soup, transform

INVALID = strahl.INVALID_ID


def random_spheres(seed, n=40):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.5, 1.5, (n, 3)), rng.uniform(0.05, 0.3, n)


def sphere_roots(c, r, rays):
    """Both roots of every ray against every sphere (float64), NaN where the line misses."""
    c = c.astype(np.float64)
    o, d = rays[:, None, :3].astype(np.float64), rays[:, None, 3:].astype(np.float64)
    oc = o - c[None]
    a = (d * d).sum(-1)
    b = (d * oc).sum(-1)
    disc = b * b - a * ((oc * oc).sum(-1) - r[None].astype(np.float64) ** 2)
    with np.errstate(invalid="ignore"):
        s = np.sqrt(disc)
    return (-b - s) / a, (-b + s) / a


def brute_sphere_hits(c, r, rays):
    """t of every ray against every sphere: the nearest root above 0, inf where there is none."""
    near, far = sphere_roots(c, r, rays)
    t = np.where(near > 0, near, np.where(far > 0, far, np.inf))
    return np.where(np.isnan(t), np.inf, t)


def test_mixed_scene_matches_brute_force_and_keeps_the_users_ids():
    # Triangles, spheres, triangles: strahl numbers meshes before spheres inside; the user's ids
    # are the order of the add_* calls.
    (v1, f1), (v2, f2) = soup(1, n=60), soup(2, n=60)
    c, r = random_spheres(3)
    s = strahl.RaycastingScene()
    assert s.add_triangles(v1, f1) == 0
    assert s.add_spheres(c, r) == 1
    assert s.add_triangles(v2, f2) == 2
    rays = random_rays(4, 4000)
    got = s.cast_rays(rays)
    per = [brute_hits(v1, f1, rays), brute_sphere_hits(c, r, rays), brute_hits(v2, f2, rays)]
    best = np.stack([p.min(axis=1) for p in per])
    t = best.min(axis=0)
    geom = best.argmin(axis=0)
    hit = np.isfinite(t)
    assert (geom[hit] == 1).sum() > 300, "enough rays hit the spheres first"
    np.testing.assert_array_equal(np.isfinite(got["t_hit"]), hit)
    np.testing.assert_allclose(got["t_hit"][hit], t[hit], rtol=1e-4, atol=1e-6)
    # Ties between geometries within float rounding are not decided here.
    with np.errstate(invalid="ignore"):
        gap = np.sort(best, axis=0)[1] - t
    clear = hit & (gap > 1e-3 * np.maximum(t, 1))
    np.testing.assert_array_equal(got["geometry_ids"][clear], geom[clear])
    on_sphere = clear & (geom == 1)
    prim = per[1].argmin(axis=1)
    np.testing.assert_array_equal(got["primitive_ids"][on_sphere], prim[on_sphere])
    p = rays[on_sphere, :3] + rays[on_sphere, 3:] * got["t_hit"][on_sphere, None]
    outward = (p - c[prim[on_sphere]]) / r[prim[on_sphere], None]
    np.testing.assert_allclose(got["primitive_normals"][on_sphere], outward, atol=2e-3)
    np.testing.assert_array_equal(got["primitive_uvs"][on_sphere], 0)
    assert np.all(got["instance_ids"] == INVALID)
    np.testing.assert_array_equal(s.test_occlusions(rays), hit)
    np.testing.assert_array_equal(s.test_occlusions(rays, tfar=0.5), t <= 0.5)


def test_crossings_closest_points_and_inside_of_spheres():
    # Spheres on a grid, apart, so inside one means inside the union.
    g = np.stack(np.meshgrid([-1, 0, 1], [-1, 0, 1], [0], indexing="ij"), -1).reshape(-1, 3).astype(float)
    r = np.linspace(0.2, 0.45, len(g))
    s = strahl.RaycastingScene()
    s.add_spheres(g, r)
    rays = random_rays(5, 2000)
    near, far = sphere_roots(g, r, rays)
    want = (np.nan_to_num(near, nan=-1) > 0).sum(1) + (np.nan_to_num(far, nan=-1) > 0).sum(1)
    assert want.max() >= 2
    np.testing.assert_array_equal(s.count_intersections(rays), want)
    lists = s.list_intersections(rays)
    np.testing.assert_array_equal(np.diff(lists["ray_splits"]), want)
    assert np.all(lists["geometry_ids"] == 0)
    pts = np.random.default_rng(6).uniform(-2, 2, (3000, 3))
    dc = np.linalg.norm(pts[:, None] - g[None], axis=2) - r[None]
    want_d = np.abs(dc).min(axis=1)
    got = s.compute_closest_points(pts)
    np.testing.assert_allclose(got["distance"], want_d, rtol=1e-4, atol=1e-5)
    np.testing.assert_array_equal(got["primitive_ids"], np.abs(dc).argmin(axis=1))
    k = np.abs(dc).argmin(axis=1)
    on = np.linalg.norm(got["points"] - g[k], axis=1)
    np.testing.assert_allclose(on, r[k], rtol=1e-4)
    inside = (dc < 0).any(axis=1)
    clear = np.abs(dc).min(axis=1) > 1e-4
    np.testing.assert_array_equal(s.compute_occupancy(pts)[clear], inside[clear])
    sd = s.compute_signed_distance(pts)
    np.testing.assert_allclose(sd[clear], np.where(inside, -want_d, want_d)[clear], rtol=1e-4, atol=1e-5)


def test_instanced_spheres_match_the_placed_spheres():
    c, r = random_spheres(7, n=25)
    ts = np.stack([transform([1, 1, 1], 0, [0, 0, 0]), transform([0.6, 0.6, 0.6], 0.8, [1.0, -0.4, 0.3]),
                   transform([-1.3, 1.3, 1.3], -0.3, [-0.8, 0.5, -0.6])])
    s = strahl.RaycastingScene()
    g = s.add_spheres(c, r)
    s.add_instances(g, ts)
    flat = strahl.RaycastingScene()
    for m in ts:
        flat.add_spheres(c @ m[:3, :3].T + m[:3, 3], r * abs(np.linalg.det(m[:3, :3])) ** (1 / 3))
    rays = random_rays(8, 3000)
    a, b = s.cast_rays(rays), flat.cast_rays(rays)
    hit = np.isfinite(b["t_hit"])
    assert hit.sum() > 300
    np.testing.assert_array_equal(np.isfinite(a["t_hit"]), hit)
    np.testing.assert_allclose(a["t_hit"][hit], b["t_hit"][hit], rtol=1e-4)
    np.testing.assert_array_equal(a["instance_ids"][hit], b["geometry_ids"][hit])
    np.testing.assert_array_equal(a["primitive_ids"][hit], b["primitive_ids"][hit])
    assert np.all(a["geometry_ids"][hit] == g)
    np.testing.assert_allclose(a["primitive_normals"][hit], b["primitive_normals"][hit], atol=2e-3)
    # Spheres stay spheres only under similarities.
    sheared = strahl.RaycastingScene()
    sheared.add_instances(sheared.add_spheres(c, r), transform([1, 2, 1], 0, [0, 0, 0]))
    with pytest.raises(ValueError, match="similar|uniform|sphere"):
        sheared.cast_rays(rays[:1])


def test_bad_spheres_raise_clear_errors():
    s = strahl.RaycastingScene()
    c = np.zeros((3, 3))
    for radii, match in [([1, 0, 1], "radius 1"), ([1, 1, -2], "radius 2"), ([np.nan, 1, 1], "radius 0"),
                         ([1, np.inf, 1], "radius 1")]:
        with pytest.raises(ValueError, match=match):
            s.add_spheres(c, radii)
    with pytest.raises(ValueError, match="center 1"):
        s.add_spheres([[0, 0, 0], [np.nan, 0, 0]], 1.0)
    with pytest.raises(ValueError, match="center 0"), np.errstate(over="ignore"):
        s.add_spheres([[1e39, 0, 0]], 1.0)
    with pytest.raises(ValueError, match="shape"):
        s.add_spheres(c, [1, 1])
    with pytest.raises(ValueError, match="shape"):
        s.add_spheres(np.zeros((3, 2)), 1.0)
    with pytest.raises(ValueError, match="shape"):
        s.add_spheres(np.zeros(3), 1.0)
    with pytest.raises(TypeError):
        s.add_spheres(c, ["a", "b", "c"])
    # Nothing was added by the failed calls; an empty set is a geometry every ray misses.
    assert s.add_spheres(np.zeros((0, 3)), np.zeros(0)) == 0
    assert not np.isfinite(s.cast_rays(random_rays(9, 10))["t_hit"]).any()
    # The core refuses bad spheres too (a scene built from unchecked arrays).
    with pytest.raises(ValueError, match="radius"):
        strahl._strahl.Core([("spheres", np.zeros((1, 3), np.float32), np.array([-1], np.float32))], [], 1, True,
                            "medium")
    with pytest.raises(ValueError, match="kind"):
        strahl._strahl.Core([("cones", np.zeros((1, 3), np.float32), np.zeros(1, np.float32))], [], 1, True, "medium")
    # NaN and zero-direction rays miss spheres as they miss triangles.
    s2 = strahl.RaycastingScene()
    s2.add_spheres([[0, 0, 0]], 1.0)
    rays = np.array([[0, 0, -5, 0, 0, 0], [0, 0, -5, np.nan, 0, 1], [np.nan, 0, -5, 0, 0, 1], [0, 0, -5, 0, 0, 1]],
                    np.float32)
    t = s2.cast_rays(rays)["t_hit"]
    assert np.all(np.isinf(t[:3])) and abs(t[3] - 4) < 1e-5


def test_pickle_keeps_spheres_and_ids():
    (v, f), (c, r) = soup(10, n=50), random_spheres(11)
    rays = random_rays(12, 1000)
    for instanced in (False, True):
        s = strahl.RaycastingScene()
        s.add_spheres(c, r)
        s.add_triangles(v, f)
        if instanced:
            s.add_instances(0, transform([0.5, 0.5, 0.5], 0.2, [0.5, 0, 0]))
        before = s.cast_rays(rays)
        assert (before["geometry_ids"] == 0).sum() > 50 and (before["geometry_ids"] == 1).sum() > 50
        after = pickle.loads(pickle.dumps(s)).cast_rays(rays)
        for k in before:
            np.testing.assert_array_equal(before[k], after[k])
    instanced, data, ids = s._core.serialize()
    flat = strahl.RaycastingScene()
    flat.add_spheres(c, r)
    flat.add_triangles(v, f)
    flat.cast_rays(rays[:1])
    instanced, data, ids = flat._core.serialize()
    assert not instanced and [g for g, _ in ids] == [1, 0]
    with pytest.raises(ValueError, match="geometry ids"):
        strahl._strahl.Core.deserialize(False, data, ids + [(2, INVALID)], 1)
    assert strahl._strahl.Core.deserialize(False, data, ids, 1).spheres == len(c)


# -- solids (add_solid) -------------------------------------------------------------------------

DIE = {"difference": [{"box": {}}, {"sphere": {"center": [0, 0, 1], "radius": 0.5}}]}


def die_crossings(rays):
    """Every boundary crossing (t > 0) of each ray with the box [-1, 1]³ minus the ball of radius
    0.5 at (0, 0, 1), in float64, by intervals: the box's slab interval minus the ball's."""
    o, d = rays[:, :3].astype(np.float64), rays[:, 3:].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        a, b = (-1 - o) / d, (1 - o) / d
    t0 = np.nanmax(np.minimum(a, b), axis=1)
    t1 = np.nanmin(np.maximum(a, b), axis=1)
    s0, s1 = sphere_roots(np.array([[0.0, 0.0, 1.0]]), np.array([0.5]), rays)
    s0, s1 = s0[:, 0], s1[:, 0]
    out = []
    for i in range(len(rays)):
        if not t0[i] <= t1[i]:
            out.append([])
            continue
        pieces = [(t0[i], t1[i])]
        if np.isfinite(s0[i]):
            pieces = [(x, y) for x, y in ((t0[i], min(t1[i], s0[i])), (max(t0[i], s1[i]), t1[i])) if x < y]
        out.append(sorted(t for p in pieces for t in p if t > 0))
    return out


def test_solid_matches_intervals_and_membership():
    s = strahl.RaycastingScene()
    assert s.add_solid(DIE) == 0
    rays = random_rays(20, 3000) * np.float32([1.5, 1.5, 1.5, 1, 1, 1])
    want = die_crossings(rays)
    first = np.array([w[0] if w else np.inf for w in want])
    got = s.cast_rays(rays)
    hit = np.isfinite(first)
    assert hit.sum() > 500
    np.testing.assert_array_equal(np.isfinite(got["t_hit"]), hit)
    np.testing.assert_allclose(got["t_hit"][hit], first[hit], rtol=1e-4, atol=1e-6)
    # Leaves depth first: the box is primitive 0, the ball 1.
    p = rays[hit, :3] + rays[hit, 3:] * first[hit, None]
    on_ball = np.abs(np.linalg.norm(p - [0, 0, 1], axis=1) - 0.5) < 1e-4
    np.testing.assert_array_equal(got["primitive_ids"][hit], on_ball.astype(np.uint32))
    normal = np.where(on_ball[:, None], -(p - [0, 0, 1]) / 0.5, 0)
    np.testing.assert_allclose(got["primitive_normals"][hit][on_ball], normal[on_ball], atol=2e-3)
    np.testing.assert_array_equal(s.count_intersections(rays), [len(w) for w in want])
    pts = np.random.default_rng(21).uniform(-1.5, 1.5, (4000, 3))
    inside = (np.abs(pts) <= 1).all(axis=1) & (np.linalg.norm(pts - [0, 0, 1], axis=1) > 0.5)
    np.testing.assert_array_equal(s.compute_occupancy(pts), inside)
    # Closest points are not searched on solids: a clear error, not an "infinitely far" answer.
    for query in (s.compute_closest_points, s.compute_distance, s.compute_signed_distance):
        with pytest.raises(NotImplementedError, match="solids"):
            query(pts[:3])


def test_solid_notation_string_placement_and_mixed_ids():
    v, f = soup(22, n=40)
    c, r = random_spheres(23, n=10)
    m = transform([0.7, 1.3, 0.9], 0.6, [0.2, -0.1, 0.3])
    m[0, 1] = 0.4  # a shear: solids take any invertible affine map
    s = strahl.RaycastingScene()
    assert s.add_triangles(v, f) == 0
    placed = dict(DIE, matrix=m[:3].tolist())
    assert s.add_solid(placed) == 1
    assert s.add_spheres(c, r) == 2
    # The same solid as a TOML string, placed as an instance instead.
    t = strahl.RaycastingScene()
    g = t.add_solid("{ difference = [{ box = {} }, { sphere = { center = [0, 0, 1], radius = 0.5 } }] }")
    t.add_instances(g, m)
    rays = random_rays(24, 3000)
    a, b = s.cast_rays(rays), t.cast_rays(rays)
    solid_hits = a["geometry_ids"] == 1
    assert solid_hits.sum() > 100
    assert (a["geometry_ids"] == 0).sum() > 100 and (a["geometry_ids"] == 2).sum() > 20
    # Where the mixed scene hits the solid first, the instanced solid alone hits there too.
    np.testing.assert_allclose(a["t_hit"][solid_hits], b["t_hit"][solid_hits], rtol=1e-4, atol=1e-6)
    np.testing.assert_array_equal(a["primitive_ids"][solid_hits], b["primitive_ids"][solid_hits])
    np.testing.assert_allclose(a["primitive_normals"][solid_hits], b["primitive_normals"][solid_hits], atol=2e-3)
    assert np.all(b["geometry_ids"][np.isfinite(b["t_hit"])] == g)
    after = pickle.loads(pickle.dumps(s)).cast_rays(rays)
    for k in a:
        np.testing.assert_array_equal(a[k], after[k])
    unbuilt = strahl.RaycastingScene()
    unbuilt.add_solid(DIE)
    restored = pickle.loads(pickle.dumps(unbuilt))
    assert restored._core is None
    np.testing.assert_array_equal(restored.cast_rays(rays)["t_hit"], unbuilt.cast_rays(rays)["t_hit"])


def test_bad_solids_raise_clear_errors():
    s = strahl.RaycastingScene()
    for bad, match in [
        ({"torus": {"major": 1.0, "minor": 2.0}}, "minor"),
        ({"box": {}, "sphere": {}}, "exactly one"),
        ({"union": []}, "no operands"),
        ({"sphere": {"radius": float("nan")}}, "radius"),
        ({"sphere": {"radius": -1}}, "radius"),
        ({"box": {}, "scale": [1, 0, 1]}, "invertible"),
        ({"plane": {"normal": [0, 1, 0]}}, "unbounded"),
        ({"obj": "/nonexistent/die.obj"}, "die.obj"),
        ({"sphere": {"radius": 1}, "colour": 3}, "colour"),
        ("{ box = ", "unclosed"),
        ("{ box = {} }\n[mesh.x]\nobj = 'a.obj'", "mesh"),
    ]:
        with pytest.raises(ValueError, match=match):
            s.add_solid(bad)
    with pytest.raises(TypeError, match=r"solid\.sphere\.radius"):
        s.add_solid({"sphere": {"radius": object()}})
    with pytest.raises(TypeError, match="keys"):
        s.add_solid({1: {}})
    # Keys that need quoting reach the parser as keys (and are refused there by name).
    with pytest.raises(ValueError, match="a b"):
        s.add_solid({"a b": {}})
    # Trees too deep for the notation: a clear error from either side of the parser.
    deep = {"box": {}}
    for _ in range(2000):
        deep = {"union": [deep]}
    with pytest.raises(ValueError, match="deep"):
        s.add_solid(deep)
    with pytest.raises(ValueError, match="TOML"):
        s.add_solid("{ union = [" * 10000 + "{ box = {} }" + "] }" * 10000)
    assert s.add_solid({"sphere": {"radius": np.float32(0.5), "center": np.zeros(3)}}) == 0
