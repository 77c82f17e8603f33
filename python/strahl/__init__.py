"""strahl: high-throughput ray queries on CPUs, from numpy.

An Open3D-shaped :class:`RaycastingScene` (closest hits, occlusion, all hits, hit counts,
closest points, signed distance, occupancy) over strahl's SIMD BVH, with instancing, over
triangle meshes, analytic spheres and CSG solids (``add_spheres``, ``add_solid``). Code
written for ``open3d.t.geometry.RaycastingScene`` ports by changing the import; results are
numpy arrays instead of Open3D tensors (``ans["t_hit"]`` rather than ``ans["t_hit"].numpy()``).

Every query releases the GIL and runs on the scene's own thread pool; a scene is built on its
first query (and again after geometry is added), and may then be queried from many Python
threads at once. strahl traces in float32: float64 input is converted once, on the way in.
"""

from __future__ import annotations

import json
import math
import re
import threading
from typing import Any, Dict, List, NamedTuple, Optional, Tuple

import numpy as np

from . import _strahl

__all__ = ["RaycastingScene", "INVALID_ID", "create_rays_pinhole", "load_obj", "render", "Rendered", "ray_tree"]

#: The id of "no geometry / primitive / instance" in query results (Embree's and Open3D's).
INVALID_ID: int = int(_strahl.INVALID_ID)


def _float_rows(a: Any, width: int, what: str) -> Tuple[np.ndarray, Tuple[int, ...]]:
    """``a`` as a C-contiguous float32 ``(n, width)`` array (no copy if it already is one), and
    the leading shape of the input."""
    if not isinstance(a, np.ndarray) and hasattr(a, "numpy"):
        a = a.numpy()  # an Open3D or torch tensor
    arr = np.asarray(a)
    if arr.dtype.kind not in "fiu":
        raise TypeError(f"{what} must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim < 1 or arr.shape[-1] != width:
        raise ValueError(f"{what} must have shape (..., {width}), got {arr.shape}")
    lead = arr.shape[:-1]
    flat = np.ascontiguousarray(arr.reshape(-1, width), dtype=np.float32)
    return flat, lead


class RaycastingScene:
    """A scene of triangle meshes and analytic spheres for ray and point queries (Open3D's
    ``RaycastingScene``, plus :meth:`add_spheres`).

    Args:
        threads: threads of the scene's pool; 0 (the default) uses one per core. Open3D's
            per-call ``nthreads`` is accepted by every query and ignored: the pool is the scene's.
        watertight: the watertight triangle test (Woop et al. 2013) with a conservative box
            test, so no ray slips between the triangles of a closed mesh (the default, like
            Open3D's robust Embree scene); ``False`` picks Möller–Trumbore with the fast box
            test.
        quality: the BVH build preset, by Embree's names: ``"fast"`` (fewer bins),
            ``"medium"`` (binned SAH, the default) or ``"high"`` (spatial splits: slower to
            build, faster to trace).
    """

    INVALID_ID: int = INVALID_ID

    def __init__(self, threads: int = 0, watertight: bool = True, quality: str = "medium") -> None:
        if not isinstance(threads, (int, np.integer)) or isinstance(threads, bool) or threads < 0:
            raise ValueError(f"threads must be a non-negative integer, got {threads!r}")
        if quality not in ("fast", "medium", "high"):
            raise ValueError(f'quality must be "fast", "medium" or "high", got {quality!r}')
        self._quality = quality
        self._threads = int(threads)
        self._watertight = bool(watertight)
        # Per geometry: (vertices, triangles) for a mesh, ("spheres", centres, radii) for spheres.
        self._geometries: List[Tuple[Any, ...]] = []
        # Per geometry: its instances as (instance id, 4×4 float32 transform), or None while it
        # has none.
        self._instances: List[Optional[List[Tuple[int, np.ndarray]]]] = []
        self._instance_count = 0
        self._core: Optional[_strahl.Core] = None
        self._lock = threading.Lock()
        # The scene file this scene was read from, if any: then it takes no more geometry.
        self._scene_file: Optional[str] = None

    @classmethod
    def from_scene_file(
        cls, path: Any, threads: int = 0, watertight: bool = True, quality: str = "medium"
    ) -> "RaycastingScene":
        """The scene of a strahl scene file (TOML, see ``data/README.md``): its triangle meshes,
        analytic spheres and solids (CSG trees of spheres, boxes, cylinders, cones, tori,
        quadrics, superquadrics, blobs and closed meshes), placed by its ``[[instance]]``\ s.

        A hit's ``geometry_ids`` is the index of its instance's ``[mesh.*]`` table (tables in
        name order), ``instance_ids`` the index of the ``[[instance]]``, ``primitive_ids`` the
        triangle, sphere, or the solid's primitive (depth first). Such a scene takes no further
        ``add_triangles``/``add_instances``. A file that cannot be read raises ``OSError``; a
        malformed one, or one describing bad geometry, ``ValueError`` naming the entry.
        """
        scene = cls(threads, watertight, quality)
        scene._core = _strahl.Core.from_scene_file(str(path), scene._threads, scene._watertight, scene._quality)
        scene._scene_file = str(path)
        return scene

    def _check_open(self) -> None:
        if self._scene_file is not None:
            raise ValueError(f"this scene was read from the scene file {self._scene_file!r}; it takes no more geometry")

    # -- building -----------------------------------------------------------------------------

    def add_triangles(self, vertex_positions: Any, triangle_indices: Any = None) -> int:
        """Adds a triangle mesh and returns its geometry id.

        ``vertex_positions``: ``(n, 3)`` float32 or float64; ``triangle_indices``: ``(m, 3)`` of
        any integer type, each in ``[0, n)``. A mesh object with ``vertices`` and ``faces``
        (trimesh) or ``vertex.positions`` and ``triangle.indices`` (Open3D's tensor mesh) may be
        passed alone. NaN vertices and zero-area triangles are kept in the mesh but can never
        be hit.
        """
        self._check_open()
        if triangle_indices is None:
            vertex_positions, triangle_indices = _mesh_arrays(vertex_positions)
        v, _ = _float_rows(vertex_positions, 3, "vertex_positions")
        if np.asarray(vertex_positions).ndim != 2:
            raise ValueError(f"vertex_positions must have shape (n, 3), got {np.shape(vertex_positions)}")
        f = np.asarray(triangle_indices)
        if f.dtype.kind not in "iu":
            raise TypeError(f"triangle_indices must be an integer array, got dtype {f.dtype}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"triangle_indices must have shape (m, 3), got {f.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(
                f"triangle_indices must lie in [0, {len(v)}) for {len(v)} vertices, got [{f.min()}, {f.max()}]"
            )
        return self._add_geometry((v.copy(), np.ascontiguousarray(f, dtype=np.uint32)))

    def add_spheres(self, centers: Any, radii: Any) -> int:
        """Adds a set of analytic spheres and returns its geometry id (one id for the set, in
        the same numbering as :meth:`add_triangles`).

        ``centers``: ``(n, 3)`` float32 or float64; ``radii``: ``(n,)``, or one number for all.
        A sphere costs no triangles: it is intersected exactly (the numerically robust test of
        Ray Tracing Gems ch. 7), in its own BVH beside the triangles'. Hits report the sphere's
        index in ``primitive_ids``, its outward unit normal in ``primitive_normals`` and
        ``(0, 0)`` in ``primitive_uvs``; every query sees spheres (crossings count entry and
        exit, closest points lie on the sphere). Instances of a sphere set must be similarities
        (rotation or mirror, uniform scale, translation): a transform that shears or scales
        unevenly raises ``ValueError`` when the scene is built. Centres that are not finite and
        radii that are not positive and finite raise ``ValueError`` naming the sphere.
        """
        self._check_open()
        c, _ = _float_rows(centers, 3, "centers")
        if np.asarray(centers).ndim != 2:
            raise ValueError(f"centers must have shape (n, 3), got {np.shape(centers)}")
        r = np.asarray(radii)
        if r.dtype.kind not in "iuf":
            raise TypeError(f"radii must be numbers, got dtype {r.dtype}")
        if r.ndim == 0:
            r = np.full(len(c), r, dtype=np.float32)
        if r.shape != (len(c),):
            raise ValueError(f"radii must have shape ({len(c)},) for {len(c)} centers, got {r.shape}")
        r = np.ascontiguousarray(r, dtype=np.float32)
        bad = ~(np.isfinite(r) & (r > 0))
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"radius {i} is {r[i]}: radii must be positive and finite")
        bad = ~np.isfinite(c).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"center {i} is {c[i].tolist()}: centers must be finite")
        return self._add_geometry(("spheres", c.copy(), r.copy()))

    def add_solid(self, solid: Any) -> int:
        """Adds a solid and returns its geometry id: primitives (``sphere``, ``box``,
        ``cylinder``, ``cone``, ``torus``, ``quadric``, ``superellipsoid``, ``supertoroid``,
        ``superhyperboloid``, ``ratioquadric``, ``blob``, a closed mesh from an ``obj`` file)
        placed by ``translate``/``rotate``/``scale``/``matrix`` and combined by ``union``,
        ``intersection`` and ``difference``, intersected exactly (CSG over ray intervals,
        float64) in their own BVH beside the triangles'.

        ``solid``: a dict in the notation of a scene file's ``solid = { … }`` (``data/README.md``;
        nested dicts and lists, numbers, numpy arrays), or that notation as a TOML string::

            die = scene.add_solid({"difference": [
                {"box": {}},
                {"sphere": {"center": [0, 0, 1], "radius": 0.3}},
            ], "rotate": [0, 45, 0]})

        Hits report the primitive hit in ``primitive_ids`` (the tree's leaves, depth first,
        operands in order) and the outward unit normal; the ray queries and
        :meth:`compute_occupancy` see solids, and instances may place them by any invertible
        affine map. Closest points are not found on solids: :meth:`compute_closest_points`,
        :meth:`compute_distance` and :meth:`compute_signed_distance` raise
        ``NotImplementedError`` on a scene that has any. ``material`` keys are ignored. A malformed
        or bad solid (a negative radius, ``minor >= major``, NaN, a singular ``scale``, an
        empty operation, an unbounded plane on its own, a missing OBJ file) raises ``ValueError``
        naming the node; a value of another type ``TypeError``.
        """
        self._check_open()
        try:
            text = solid if isinstance(solid, str) else _toml_value(solid, "solid")
        except RecursionError:
            raise ValueError("the solid is nested too deeply to write down") from None
        _strahl.check_solid(text)
        return self._add_geometry(("solid", None, text))

    def _add_geometry(self, entry: Tuple[Any, ...]) -> int:
        """Appends a checked geometry entry (see ``_geometries``) and returns its id."""
        with self._lock:
            self._geometries.append(entry)
            self._instances.append(None)
            self._core = None
            return len(self._geometries) - 1

    def add_instances(self, geometry_id: int, transforms: Any) -> np.ndarray:
        """Places geometry ``geometry_id`` by each of ``transforms`` (``(K, 4, 4)`` or ``(4, 4)``,
        object to world, last row ``0 0 0 1``, invertible) and returns the new instances' ids.

        A geometry is shown where it was added until its first instance is added; from then on
        only at its instances. Hits on instances report the geometry id and, in
        ``instance_ids``, the instance id (counted over all ``add_instances`` calls, from 0);
        hits on geometry shown as added report ``INVALID_ID`` there. Rays are moved into the
        object's space without renormalizing, so ``t_hit`` is the world-space distance in
        units of the ray's direction.
        """
        self._check_open()
        t = np.asarray(transforms, dtype=np.float64)
        if t.shape == (4, 4):
            t = t[None]
        if t.ndim != 3 or t.shape[1:] != (4, 4):
            raise ValueError(f"transforms must have shape (K, 4, 4), got {np.shape(transforms)}")
        if not np.all(np.isfinite(t)):
            raise ValueError("transforms must be finite")
        if not np.allclose(t[:, 3], [0.0, 0.0, 0.0, 1.0], atol=0.0):
            raise ValueError("the last row of every transform must be 0 0 0 1")
        det = np.linalg.det(t[:, :3, :3])
        if np.any(det == 0.0):
            raise ValueError(f"transform {int(np.argmax(det == 0.0))} is not invertible")
        with self._lock:
            if not (0 <= int(geometry_id) < len(self._geometries)):
                raise ValueError(f"no geometry {geometry_id} (the scene has {len(self._geometries)})")
            g = int(geometry_id)
            start = self._instance_count
            ids = np.arange(start, start + len(t), dtype=np.uint32)
            prev = self._instances[g]
            block = [(int(ids[i]), np.ascontiguousarray(t[i], dtype=np.float32)) for i in range(len(t))]
            self._instances[g] = block if prev is None else prev + block
            self._instance_count += len(t)
            self._core = None
            return ids

    def _built(self) -> "_strahl.Core":
        with self._lock:
            if self._core is None:
                placements = []
                if any(i is not None for i in self._instances):
                    for g, inst in enumerate(self._instances):
                        if inst is None:
                            placements.append((g, np.eye(4, dtype=np.float32), INVALID_ID))
                        else:
                            placements.extend((g, m, i) for i, m in inst)
                geometries = [g if len(g) == 3 else ("triangles",) + tuple(g) for g in self._geometries]
                self._core = _strahl.Core(geometries, placements, self._threads, self._watertight, self._quality)
            return self._core

    # -- ray queries --------------------------------------------------------------------------

    def cast_rays(self, rays: Any, tnear: float = 0.0, tfar: float = float("inf"), nthreads: int = 0) -> Dict[str, np.ndarray]:
        """Closest hits of ``rays`` (``(..., 6)``: origin, direction) in ``(tnear, tfar]``.

        Returns Open3D's keys: ``t_hit`` (inf on a miss), ``geometry_ids``, ``primitive_ids``
        (``INVALID_ID`` on a miss), ``primitive_uvs`` (barycentrics of vertices 1 and 2),
        ``primitive_normals`` (unit geometric normals; 0 on a miss), and ``instance_ids``.
        Rays with a NaN or zero direction miss.
        """
        r, lead = _float_rows(rays, 6, "rays")
        t, g, p, uv, n, i = self._built().cast_rays(r, float(tnear), float(tfar), _width(lead))
        return {
            "t_hit": t.reshape(lead),
            "geometry_ids": g.reshape(lead),
            "primitive_ids": p.reshape(lead),
            "primitive_uvs": uv.reshape(lead + (2,)),
            "primitive_normals": n.reshape(lead + (3,)),
            "instance_ids": i.reshape(lead),
        }

    def test_occlusions(self, rays: Any, tnear: float = 0.0, tfar: float = float("inf"), nthreads: int = 0) -> np.ndarray:
        """Whether anything lies on each ray in ``(tnear, tfar]`` (bool, shape ``(...)``)."""
        r, lead = _float_rows(rays, 6, "rays")
        return self._built().test_occlusions(r, float(tnear), float(tfar), _width(lead)).reshape(lead)

    def count_intersections(self, rays: Any, tnear: float = 0.0, tfar: float = float("inf"), nthreads: int = 0) -> np.ndarray:
        """How many times each ray crosses the surface (int32, shape ``(...)``), in one walk.

        A ray through an edge or vertex shared by several triangles crosses there once (hits
        at the same point facing the same way are merged); a ray grazing a silhouette counts
        twice (in and out), so the parity says inside or outside."""
        r, lead = _float_rows(rays, 6, "rays")
        return self._built().count_intersections(r, float(tnear), float(tfar)).astype(np.int32).reshape(lead)

    def list_intersections(self, rays: Any, tnear: float = 0.0, tfar: float = float("inf"), nthreads: int = 0) -> Dict[str, np.ndarray]:
        """Every crossing of every ray, nearest first, in one walk per ray (the crossings
        ``count_intersections`` counts). Ray ``i``'s crossings are entries
        ``ray_splits[i]:ray_splits[i + 1]`` of ``ray_ids``, ``t_hit``, ``geometry_ids``,
        ``primitive_ids``, ``primitive_uvs`` and ``instance_ids``."""
        r, _ = _float_rows(rays, 6, "rays")
        splits, ray_ids, t, g, p, uv, i = self._built().list_intersections(r, float(tnear), float(tfar))
        return {
            "ray_splits": splits.astype(np.int64),
            "ray_ids": ray_ids,
            "t_hit": t,
            "geometry_ids": g,
            "primitive_ids": p,
            "primitive_uvs": uv,
            "instance_ids": i,
        }

    # -- point queries ------------------------------------------------------------------------

    def compute_closest_points(self, query_points: Any, nthreads: int = 0) -> Dict[str, np.ndarray]:
        """The surface point nearest to each query point (``(..., 3)``): ``points``,
        ``geometry_ids``, ``primitive_ids``, ``primitive_uvs``, ``primitive_normals`` (unit),
        ``instance_ids``, and ``distance``. Points that are not finite, and every point of an
        empty scene, get NaN points and ``INVALID_ID``. Triangles and spheres only: a scene with
        solids (:meth:`add_solid`, scene files) raises ``NotImplementedError``."""
        q, lead = _float_rows(query_points, 3, "query_points")
        pts, (d, g, p, uv, n, i) = self._built().compute_closest_points(q)
        return {
            "points": pts.reshape(lead + (3,)),
            "geometry_ids": g.reshape(lead),
            "primitive_ids": p.reshape(lead),
            "primitive_uvs": uv.reshape(lead + (2,)),
            "primitive_normals": n.reshape(lead + (3,)),
            "instance_ids": i.reshape(lead),
            "distance": d.reshape(lead),
        }

    def compute_distance(self, query_points: Any, nthreads: int = 0) -> np.ndarray:
        """Distance from each query point to the surface (float32; inf in an empty scene, NaN
        for a point that is not finite)."""
        return self.compute_closest_points(query_points)["distance"]

    def compute_signed_distance(self, query_points: Any, nthreads: int = 0, nsamples: int = 3) -> np.ndarray:
        """Distance to the surface, negative inside (float32). Inside is decided by the parity
        of the crossings along ``nsamples`` rays (1 to 7; a tie counts as outside), by
        majority. strahl's default is 3; Open3D's is 1, which is right on a closed mesh and
        wrong wherever its ray meets a hole."""
        q, lead = _float_rows(query_points, 3, "query_points")
        return self._built().compute_signed_distance(q, _votes(nsamples)).reshape(lead)

    def compute_occupancy(self, query_points: Any, nthreads: int = 0, nsamples: int = 3) -> np.ndarray:
        """1.0 inside the closed surface, 0.0 outside (float32, as Open3D's); ``nsamples`` as
        for :meth:`compute_signed_distance`."""
        q, lead = _float_rows(query_points, 3, "query_points")
        return self._built().compute_occupancy(q, _votes(nsamples)).astype(np.float32).reshape(lead)

    # -- helpers ------------------------------------------------------------------------------

    @staticmethod
    def create_rays_pinhole(*args: Any, **kwargs: Any) -> np.ndarray:
        """See :func:`create_rays_pinhole`."""
        return create_rays_pinhole(*args, **kwargs)

    @property
    def threads(self) -> int:
        """Threads of the scene's pool."""
        return self._built().threads

    def __getstate__(self) -> Dict[str, Any]:
        """The geometry, and the built BVH if the scene has been built (so that unpickling does
        not build it again: a two-level scene rebuilds only its top level)."""
        with self._lock:
            state = {
                "threads": self._threads,
                "watertight": self._watertight,
                "quality": self._quality,
                "geometries": list(self._geometries),
                "instances": list(self._instances),
                "instance_count": self._instance_count,
                "scene_file": self._scene_file,
            }
            if self._core is not None:
                state["built"] = self._core.serialize()
            return state

    def __setstate__(self, state: Dict[str, Any]) -> None:
        self.__init__(state["threads"], state["watertight"], state.get("quality", "medium"))
        self._geometries = list(state["geometries"])
        self._instances = list(state["instances"])
        self._instance_count = state["instance_count"]
        self._scene_file = state.get("scene_file")
        if "built" in state:
            instanced, data, ids = state["built"]
            self._core = _strahl.Core.deserialize(instanced, data, ids, self._threads)


class Rendered(NamedTuple):
    """What :func:`render` returns."""

    #: Linear RGB radiance, ``(height, width, 3)`` float32, rows from the top.
    image: np.ndarray
    #: The same as 8-bit sRGB, ``(height, width, 3)`` uint8: the pixels ``strahl render`` writes
    #: to a PNG.
    srgb: np.ndarray
    #: ``rays`` (per kind: primary, shadow, reflected, refracted), ``seconds`` (the render),
    #: ``build_seconds`` (loading and BVH), ``query_share`` (of the threads' time), ``threads``,
    #: ``width``, ``height``, ``spp``, ``max_depth``, ``cut_by_weight``, ``cut_by_depth``.
    stats: Dict[str, Any]


def render(
    path: Any,
    width: Optional[int] = None,
    height: Optional[int] = None,
    spp: Optional[int] = None,
    max_depth: Optional[int] = None,
    bailout: Optional[float] = None,
    threads: int = 0,
) -> Rendered:
    """Renders a strahl scene file (``data/README.md``) with strahl's ray tracer (Whitted
    recursion with shadows, reflection, refraction, Fresnel and Beer–Lambert; area lights,
    textures, the cameras of the scene file), as ``strahl render`` does: the same image for any
    thread count. ``width``, ``height``, ``spp`` (samples per pixel), ``max_depth`` and
    ``bailout`` override the file's ``[render]`` table; ``threads`` 0 uses one per core.

    A missing or unreadable file raises ``OSError``; a malformed one, one without a
    ``[camera]``, or a setting out of range (a side of 0 or above 32768 pixels, ``spp`` outside
    1–4096, ``max_depth`` above 64, ``bailout`` outside [0, 1]) ``ValueError``."""
    if not isinstance(threads, (int, np.integer)) or isinstance(threads, bool) or threads < 0:
        raise ValueError(f"threads must be a non-negative integer, got {threads!r}")

    b = None if bailout is None else float(bailout)
    image, srgb, stats = _strahl.render(
        str(path), _count("width", width), _count("height", height), _count("spp", spp),
        _count("max_depth", max_depth), b, int(threads)
    )
    return Rendered(image, srgb, stats)


def ray_tree(
    path: Any,
    x: int,
    y: int,
    width: Optional[int] = None,
    height: Optional[int] = None,
    max_depth: Optional[int] = None,
    bailout: Optional[float] = None,
) -> Tuple[List[Dict[str, Any]], np.ndarray]:
    """The lecture's ray tree of pixel ``(x, y)`` (column, row from the top) of a scene file's
    image: its first sample traced depth first with the renderer's optics, as ``strahl render
    --ray-tree`` writes it. Returns one dict per ray, parents before children (``parent``: the
    index of the ray that spawned it, ``None`` for the primary ray; ``kind``: ``"primary"``,
    ``"shadow"``, ``"reflected"`` or ``"refracted"``; ``depth``; ``origin``; ``dir``; ``t``:
    where it hit or was blocked, ``None`` if it went free; ``tfar``: a shadow feeler's end;
    ``weight``), and the sample's colour (linear RGB). Errors as for :func:`render`, and
    ``ValueError`` for a pixel outside the image."""
    b = None if bailout is None else float(bailout)
    nodes, colour = _strahl.ray_tree(
        str(path), _count("x", x), _count("y", y), _count("width", width), _count("height", height),
        _count("max_depth", max_depth), b
    )
    return nodes, np.array(colour, dtype=np.float32)


def _count(name: str, v: Any) -> Optional[int]:
    """``v`` as an unsigned 32-bit count (``None`` stays ``None``); ``ValueError`` otherwise."""
    if v is None:
        return None
    if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or not 0 <= v < 2**32:
        raise ValueError(f"{name} must be an integer in [0, 2^32), got {v!r}")
    return int(v)


def load_obj(path: Any, merge: bool = True) -> Any:
    """Triangle meshes of a Wavefront OBJ file, with strahl's loader (polygons fanned into
    triangles, materials ignored). With ``merge`` (the default) one ``(vertices (n, 3) float32,
    triangles (m, 3) uint32)`` pair for the whole file, else one pair per object or group.
    A missing or unreadable file raises ``OSError``; a malformed one ``ValueError`` naming the
    line."""
    meshes = _strahl.load_obj(str(path))
    if not merge:
        return meshes
    if not meshes:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32)
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes[:-1]])
    v = np.concatenate([v for v, _ in meshes])
    f = np.concatenate([f + np.uint32(o) for (_, f), o in zip(meshes, offsets)])
    return v, f


def _toml_value(x: Any, at: str) -> str:
    """``x`` (dicts, lists, tuples, numpy arrays, numbers, bools, strings) in TOML's inline
    notation; ``TypeError`` naming the entry ``at`` for anything else."""
    if isinstance(x, dict):
        items = []
        for k, v in x.items():
            if not isinstance(k, str):
                raise TypeError(f"{at}: keys must be strings, got {k!r}")
            key = k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)
            items.append(f"{key} = {_toml_value(v, f'{at}.{k}')}")
        return "{ " + ", ".join(items) + " }"
    if isinstance(x, np.ndarray):
        x = x.tolist()
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_toml_value(v, f"{at}[{i}]") for i, v in enumerate(x)) + "]"
    if isinstance(x, (bool, np.bool_)):
        return "true" if x else "false"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        f = float(x)
        return "nan" if f != f else ("inf" if f == math.inf else "-inf" if f == -math.inf else repr(f))
    if isinstance(x, str):
        return json.dumps(x)
    raise TypeError(f"{at}: {type(x).__name__} is not a number, string, list or dict")


def _votes(nsamples: Any) -> int:
    if isinstance(nsamples, bool) or not isinstance(nsamples, (int, np.integer)) or not 1 <= nsamples <= 7:
        raise ValueError(f"nsamples must be an integer from 1 to 7, got {nsamples!r}")
    return int(nsamples)


def _width(lead: Tuple[int, ...]) -> int:
    """The image width of rays shaped ``(..., height, width, 6)`` (0 for a flat list): camera
    rays of an image are traced in 4×4 tiles."""
    return int(lead[-1]) if len(lead) >= 2 else 0


def _mesh_arrays(mesh: Any) -> Tuple[Any, Any]:
    """Vertices and triangles of a trimesh or Open3D (legacy or tensor) mesh."""
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        return np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if hasattr(mesh, "vertex") and hasattr(mesh, "triangle"):
        return mesh.vertex.positions.numpy(), mesh.triangle.indices.numpy()
    if hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):
        return np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    raise TypeError(f"add_triangles needs (vertex_positions, triangle_indices) or a mesh, got {type(mesh).__name__}")


def create_rays_pinhole(*args: Any, **kwargs: Any) -> np.ndarray:
    """Camera rays, ``(height_px, width_px, 6)`` float32, as Open3D's ``create_rays_pinhole``.

    Either ``(fov_deg, center, eye, up, width_px, height_px)``: a camera at ``eye`` looking at
    ``center`` with a horizontal field of view of ``fov_deg``; or ``(intrinsic_matrix (3, 3),
    extrinsic_matrix (4, 4, world to camera), width_px, height_px)``. Rays start at the camera
    centre and pass through pixel centres; directions are not normalized (their z in camera
    space is 1).
    """
    names_a = ["fov_deg", "center", "eye", "up", "width_px", "height_px"]
    names_b = ["intrinsic_matrix", "extrinsic_matrix", "width_px", "height_px"]
    if "fov_deg" in kwargs or (args and np.ndim(args[0]) == 0):
        a = dict(zip(names_a, args), **kwargs)
        missing = [n for n in names_a if n not in a]
        if missing:
            raise TypeError(f"create_rays_pinhole is missing {missing}")
        w, h = _size(a["width_px"], a["height_px"])
        fov = float(a["fov_deg"])
        if not (0.0 < fov < 180.0):
            raise ValueError(f"fov_deg must lie in (0, 180), got {fov}")
        center, eye, up = (np.asarray(a[k], dtype=np.float64).reshape(3) for k in ("center", "eye", "up"))
        f = 0.5 * w / np.tan(0.5 * np.radians(fov))
        k = np.array([[f, 0.0, 0.5 * w], [0.0, f, 0.5 * h], [0.0, 0.0, 1.0]])
        z = center - eye
        if not np.all(np.isfinite(z)) or np.linalg.norm(z) == 0.0:
            raise ValueError("center and eye must be distinct finite points")
        z /= np.linalg.norm(z)
        x = np.cross(up / np.linalg.norm(up), z)
        if not np.all(np.isfinite(x)) or np.linalg.norm(x) == 0.0:
            raise ValueError("up must not be parallel to the viewing direction")
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        r = np.stack([x, y, z])
        extrinsic = np.eye(4)
        extrinsic[:3, :3] = r
        extrinsic[:3, 3] = -r @ eye
    else:
        a = dict(zip(names_b, args), **kwargs)
        missing = [n for n in names_b if n not in a]
        if missing:
            raise TypeError(f"create_rays_pinhole is missing {missing}")
        w, h = _size(a["width_px"], a["height_px"])
        k = np.asarray(a["intrinsic_matrix"], dtype=np.float64)
        extrinsic = np.asarray(a["extrinsic_matrix"], dtype=np.float64)
        if k.shape != (3, 3) or extrinsic.shape != (4, 4):
            raise ValueError("intrinsic_matrix must be 3×3 and extrinsic_matrix 4×4")
    r, t = extrinsic[:3, :3], extrinsic[:3, 3]
    try:
        to_world = r.T @ np.linalg.inv(k)
    except np.linalg.LinAlgError as e:
        raise ValueError(f"the intrinsic matrix is singular: {e}") from None
    origin = -r.T @ t
    px = np.stack(np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5), axis=-1)
    px = np.concatenate([px, np.ones((h, w, 1))], axis=-1)
    rays = np.empty((h, w, 6), dtype=np.float32)
    rays[..., :3] = origin
    rays[..., 3:] = px @ to_world.T
    return rays


def _size(w: Any, h: Any) -> Tuple[int, int]:
    w, h = int(w), int(h)
    if w <= 0 or h <= 0:
        raise ValueError(f"width_px and height_px must be positive, got {w}×{h}")
    return w, h
