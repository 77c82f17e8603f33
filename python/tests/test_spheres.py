"""Analytic spheres in strahl.RaycastingScene (add_spheres) against float64 numpy references."""

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
