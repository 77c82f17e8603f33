"""strahl.trimesh.RayMeshIntersector against trimesh's own intersector (where trimesh is installed)."""

import numpy as np
import pytest

from strahl.trimesh import RayMeshIntersector

trimesh = pytest.importorskip("trimesh")


def rays_at(mesh, n, seed):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-2, 2, (n, 3))
    target = mesh.sample(n, seed=seed) if hasattr(mesh, "sample") else rng.uniform(-1, 1, (n, 3))
    return o, target - o


def test_agrees_with_trimesh_on_a_closed_mesh():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    mesh.apply_transform(np.diag([1.0, 0.6, 0.8, 1.0]))
    o, d = rays_at(mesh, 2000, 1)
    ours = RayMeshIntersector(mesh)
    ref = trimesh.ray.ray_triangle.RayMeshIntersector(mesh)
    first = ours.intersects_first(o, d)
    want = ref.intersects_first(o, d)
    # Aimed at sampled surface points: every ray hits. The first face agrees, or ties at an edge.
    assert np.all(first >= 0) and np.all(want >= 0)
    same = first == want
    assert same.mean() > 0.99
    loc, ray, tri = ours.intersects_location(o, d)
    counts = np.bincount(ray, minlength=len(o))
    # A closed surface, rays from outside (or inside) cross it an even (odd) number of times.
    inside = ours.contains_points(o)
    assert np.all(counts % 2 == inside.astype(int))
    np.testing.assert_array_equal(inside, mesh.contains(o))
    # Hits lie on the faces they name.
    c = mesh.triangles_center[tri]
    n = mesh.face_normals[tri]
    np.testing.assert_allclose(np.einsum("ij,ij->i", loc - c, n), 0, atol=1e-5)
    assert np.all(ours.intersects_any(o, d))
    mesh.ray = ours  # trimesh's own methods now use strahl
    np.testing.assert_array_equal(mesh.ray.intersects_first(o, d), first)


def test_max_hits_and_single_hits():
    mesh = trimesh.creation.box()
    o = np.array([[0.1, 0.2, -3.0], [5.0, 5.0, 5.0]])
    d = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    ours = RayMeshIntersector(mesh)
    tri, ray = ours.intersects_id(o, d)
    assert ray.tolist() == [0, 0]
    tri, ray = ours.intersects_id(o, d, max_hits=1)
    assert ray.tolist() == [0]
    tri, ray, loc = ours.intersects_id(o, d, multiple_hits=False, return_locations=True)
    np.testing.assert_allclose(loc, [[0.1, 0.2, -0.5]], atol=1e-6)
    with pytest.raises(ValueError):
        ours.intersects_first(o, d[:1])
