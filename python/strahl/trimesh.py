"""A drop-in ray intersector for trimesh: ``mesh.ray = strahl.trimesh.RayMeshIntersector(mesh)``.

It answers the methods of trimesh's ``RayMeshIntersector`` (``intersects_id``,
``intersects_location``, ``intersects_first``, ``intersects_any``, ``contains_points``) with
strahl's BVH on every core. All hits along a ray come from one walk, not from re-querying beyond
each hit, so no hit is skipped or found twice; a ray through an edge or vertex shared by several
faces reports that crossing once (the face with the lowest index among them). Hits are grouped
by ray, nearest first (trimesh's own order is by round of re-querying). trimesh itself is not
imported: any object with ``vertices`` and ``faces`` arrays will do.
"""

from __future__ import annotations

from typing import Any, Tuple

import numpy as np

from . import INVALID_ID, RaycastingScene

__all__ = ["RayMeshIntersector"]


class RayMeshIntersector:
    """Ray queries on one mesh (trimesh's ``RayMeshIntersector`` interface).

    The BVH is built on the first query and again whenever the mesh's vertices or faces change
    (trimesh's content hash).
    """

    def __init__(self, mesh: Any, threads: int = 0, watertight: bool = True) -> None:
        self.mesh = mesh
        self._threads = threads
        self._watertight = watertight
        self._scene: RaycastingScene | None = None
        self._key: Any = None

    def _current(self) -> RaycastingScene:
        key = self._mesh_key()
        if self._scene is None or key != self._key:
            s = RaycastingScene(threads=self._threads, watertight=self._watertight)
            s.add_triangles(np.asarray(self.mesh.vertices), np.asarray(self.mesh.faces))
            self._scene, self._key = s, key
        return self._scene

    def _mesh_key(self) -> Any:
        h = getattr(self.mesh, "__hash__", None)
        try:
            return h() if h is not None else id(self.mesh)
        except TypeError:
            return id(self.mesh)

    @staticmethod
    def _rays(ray_origins: Any, ray_directions: Any) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        o = np.asarray(ray_origins, dtype=np.float64)
        d = np.asarray(ray_directions, dtype=np.float64)
        if o.ndim != 2 or o.shape[1] != 3 or d.shape != o.shape:
            raise ValueError(f"ray_origins and ray_directions must both have shape (n, 3), got {o.shape} and {d.shape}")
        return o, d, np.hstack([o, d])

    def intersects_id(
        self,
        ray_origins: Any,
        ray_directions: Any,
        multiple_hits: bool = True,
        max_hits: int | None = None,
        return_locations: bool = False,
        **kwargs: Any,
    ):
        """Faces hit by each ray: ``(index_tri, index_ray[, locations])``. With
        ``multiple_hits`` every crossing of each ray (at most ``max_hits`` per ray), else only
        the first."""
        o, d, rays = self._rays(ray_origins, ray_directions)
        s = self._current()
        if multiple_hits:
            ans = s.list_intersections(rays)
            tri = ans["primitive_ids"].astype(np.int64)
            ray = ans["ray_ids"].astype(np.int64)
            t = ans["t_hit"].astype(np.float64)
            if max_hits is not None:
                rank = np.arange(len(ray)) - ans["ray_splits"][:-1][ray]
                keep = rank < max_hits
                tri, ray, t = tri[keep], ray[keep], t[keep]
        else:
            ans = s.cast_rays(rays)
            ray = np.nonzero(ans["primitive_ids"] != INVALID_ID)[0]
            tri = ans["primitive_ids"][ray].astype(np.int64)
            t = ans["t_hit"][ray].astype(np.float64)
        if return_locations:
            return tri, ray, o[ray] + d[ray] * t[:, None]
        return tri, ray

    def intersects_location(self, ray_origins: Any, ray_directions: Any, **kwargs: Any):
        """Where rays hit the mesh: ``(locations, index_ray, index_tri)``."""
        tri, ray, loc = self.intersects_id(ray_origins, ray_directions, return_locations=True, **kwargs)
        return loc, ray, tri

    def intersects_first(self, ray_origins: Any, ray_directions: Any, **kwargs: Any) -> np.ndarray:
        """The first face each ray hits, or -1."""
        _, _, rays = self._rays(ray_origins, ray_directions)
        p = self._current().cast_rays(rays)["primitive_ids"]
        return np.where(p == INVALID_ID, -1, p.astype(np.int64))

    def intersects_any(self, ray_origins: Any, ray_directions: Any, **kwargs: Any) -> np.ndarray:
        """Whether each ray hits the mesh."""
        _, _, rays = self._rays(ray_origins, ray_directions)
        return self._current().test_occlusions(rays)

    def contains_points(self, points: Any) -> np.ndarray:
        """Whether each point lies inside the (closed) mesh: crossings' parity along three rays,
        by majority."""
        return self._current().compute_occupancy(points) > 0
