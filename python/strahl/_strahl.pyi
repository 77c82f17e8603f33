"""Type stubs of the extension module (python/src/lib.rs). Use the wrappers in ``strahl``."""

from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

INVALID_ID: int

F32 = npt.NDArray[np.float32]
U32 = npt.NDArray[np.uint32]
HitArrays = Tuple[F32, U32, U32, F32, F32, U32]

class Core:
    def __init__(
        self,
        geometries: List[Tuple[str, Optional[F32], Union[U32, F32, str]]],
        placements: List[Tuple[int, F32, int]],
        threads: int,
        watertight: bool,
        quality: str,
    ) -> None: ...
    @property
    def threads(self) -> int: ...
    @property
    def triangles(self) -> int: ...
    @property
    def spheres(self) -> int: ...
    def cast_rays(self, rays: F32, tnear: float, tfar: float, width: int) -> HitArrays: ...
    def test_occlusions(self, rays: F32, tnear: float, tfar: float, width: int) -> npt.NDArray[np.bool_]: ...
    def count_intersections(self, rays: F32, tnear: float, tfar: float) -> U32: ...
    def list_intersections(
        self, rays: F32, tnear: float, tfar: float
    ) -> Tuple[npt.NDArray[np.uint64], U32, F32, U32, U32, F32, U32]: ...
    def compute_closest_points(self, points: F32) -> Tuple[F32, HitArrays]: ...
    def compute_signed_distance(self, points: F32, votes: int) -> F32: ...
    def compute_occupancy(self, points: F32, votes: int) -> npt.NDArray[np.bool_]: ...
    def serialize(self) -> Tuple[bool, bytes, List[Tuple[int, int]]]: ...
    @staticmethod
    def deserialize(instanced: bool, data: bytes, ids: List[Tuple[int, int]], threads: int) -> "Core": ...
    @staticmethod
    def from_scene_file(path: str, threads: int, watertight: bool, quality: str) -> "Core": ...

def load_obj(path: str) -> List[Tuple[F32, U32]]: ...
def check_solid(text: str) -> None: ...
def render(
    path: str,
    width: Optional[int],
    height: Optional[int],
    spp: Optional[int],
    max_depth: Optional[int],
    bailout: Optional[float],
    threads: int,
) -> Tuple[F32, npt.NDArray[np.uint8], Dict[str, Any]]: ...
def ray_tree(
    path: str,
    x: Optional[int],
    y: Optional[int],
    width: Optional[int],
    height: Optional[int],
    max_depth: Optional[int],
    bailout: Optional[float],
) -> Tuple[List[Dict[str, Any]], Tuple[float, float, float]]: ...
