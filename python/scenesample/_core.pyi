# Hand-written stubs for the native module (src/py/); checked against it by tests/test_api.py
# with mypy.stubtest.
from collections.abc import Sequence
from os import PathLike
from typing import Any, Callable, Optional, Union, final

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "Camera",
    "Impostors",
    "Scene",
    "bvh_stats",
    "cast_rays",
    "default_slab",
    "device_info",
    "discretize_conventional",
    "discretize_nonredundant",
    "discretize_peeling",
    "epr_points",
    "epr_shadow_points",
    "field_view",
    "impostor_directions",
    "impostor_view",
    "impostors",
    "occluded",
    "omni_shadows",
    "read_exr",
    "reflections",
    "reconstruct",
    "render_cells",
    "render_lit",
    "sampling_metrics",
    "shade_frame",
    "soft_shadows",
    "splat",
    "visibility_field",
    "write_exr",
    "__version__",
]
__version__: str

_Path = Union[str, PathLike[str]]

@final
class Scene:
    @staticmethod
    def load_gltf(path: _Path) -> Scene: ...
    @staticmethod
    def load_obj(path: _Path) -> Scene: ...
    @staticmethod
    def from_arrays(
        vertices: ArrayLike,
        faces: ArrayLike,
        normals: Optional[ArrayLike] = None,
        colors: Optional[ArrayLike] = None,
        material_ids: Optional[ArrayLike] = None,
        materials: Optional[Sequence[dict[str, Any]]] = None,
        object_ids: Optional[ArrayLike] = None,
        objects: Optional[Sequence[str]] = None,
        lights: Optional[Sequence[dict[str, Any]]] = None,
    ) -> Scene: ...
    @property
    def vertices(self) -> np.ndarray: ...
    @property
    def faces(self) -> np.ndarray: ...
    @property
    def normals(self) -> Optional[np.ndarray]: ...
    @property
    def colors(self) -> np.ndarray: ...
    @property
    def material_ids(self) -> np.ndarray: ...
    @property
    def object_ids(self) -> np.ndarray: ...
    @property
    def objects(self) -> list[str]: ...
    @property
    def triangle_count(self) -> int: ...
    @property
    def degenerate_count(self) -> int: ...
    @property
    def bounds(self) -> np.ndarray: ...
    @property
    def warnings(self) -> list[str]: ...
    @property
    def materials(self) -> list[dict[str, Any]]: ...
    @property
    def lights(self) -> list[dict[str, Any]]: ...
    @property
    def cameras(self) -> list[Camera]: ...

@final
class Camera:
    @staticmethod
    def look_at(
        eye: ArrayLike,
        target: ArrayLike,
        up: Optional[ArrayLike] = None,
        *,
        yfov: float,
        width: int,
        height: int,
        znear: Optional[float] = None,
        zfar: Optional[float] = None,
    ) -> Camera: ...
    @staticmethod
    def from_pose(
        pose: ArrayLike,
        *,
        yfov: float,
        width: int,
        height: int,
        znear: Optional[float] = None,
        zfar: Optional[float] = None,
    ) -> Camera: ...
    @staticmethod
    def orthographic(
        pose: ArrayLike,
        *,
        xmag: float,
        ymag: float,
        width: int,
        height: int,
        znear: Optional[float] = None,
        zfar: Optional[float] = None,
    ) -> Camera: ...
    @staticmethod
    def cube(
        center: ArrayLike,
        resolution: int,
        *,
        znear: Optional[float] = None,
        zfar: Optional[float] = None,
    ) -> list[Camera]: ...
    @staticmethod
    def blend(cameras: list[Camera], weights: Optional[list[float]] = None) -> Camera: ...
    def __reduce__(
        self,
    ) -> tuple[
        Any,
        tuple[
            list[float],
            str,
            tuple[float, float],
            int,
            int,
            Optional[float],
            Optional[float],
            Optional[str],
        ],
    ]: ...
    @staticmethod
    def _restore(
        pose: list[float],
        kind: str,
        params: tuple[float, float],
        width: int,
        height: int,
        znear: Optional[float],
        zfar: Optional[float],
        name: Optional[str],
    ) -> Camera: ...
    def with_resolution(self, width: int, height: int) -> Camera: ...
    @property
    def pose(self) -> np.ndarray: ...
    @property
    def projection(self) -> str: ...
    @property
    def yfov(self) -> Optional[float]: ...
    @property
    def xmag(self) -> Optional[float]: ...
    @property
    def ymag(self) -> Optional[float]: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def znear(self) -> Optional[float]: ...
    @property
    def zfar(self) -> Optional[float]: ...
    @property
    def name(self) -> Optional[str]: ...
    @property
    def eye(self) -> list[float]: ...
    @property
    def forward(self) -> list[float]: ...
    def project(self, points: ArrayLike) -> tuple[np.ndarray, np.ndarray]: ...
    def unproject(self, pixels: ArrayLike, depth: ArrayLike) -> np.ndarray: ...
    def pixel_rays(self, *, normalize: bool = True) -> tuple[np.ndarray, np.ndarray]: ...
    def corner_camera(self) -> Camera: ...
    def pixel_footprint(self, depth: float) -> float: ...
    def __eq__(self, value: object, /) -> bool: ...
    def __ne__(self, value: object, /) -> bool: ...

def discretize_conventional(
    scene: Scene, cameras: list[Camera], cull_backfaces: bool = False
) -> dict[str, Any]: ...
def discretize_nonredundant(
    scene: Scene,
    cameras: list[Camera],
    redundancy: str = "pixel",
    cull_backfaces: bool = False,
) -> dict[str, Any]: ...
def discretize_peeling(
    scene: Scene, camera: Camera, layers: int, cull_backfaces: bool = False
) -> dict[str, Any]: ...
def sampling_metrics(
    scene: Scene,
    triangle: ArrayLike,
    position: ArrayLike,
    depth: ArrayLike,
    cameras: list[Camera],
    method: str,
    reference: list[Camera],
    frames: list[Camera],
    redundancy: str,
    cull_backfaces: bool,
) -> dict[str, Any]: ...
def reconstruct(images: Any, method: str, offset: Optional[Any] = None) -> dict[str, Any]: ...
def soft_shadows(
    scene: Scene,
    camera: Camera,
    center: ArrayLike,
    u: ArrayLike,
    v: ArrayLike,
    samples: tuple[int, int],
    discretization: str,
    resolution: int,
    corners: bool,
    reconstruction: str,
    shadow_resolution: int,
    layers: int,
) -> dict[str, Any]: ...
def epr_points(
    scene: Scene,
    eye: Camera,
    centers: ArrayLike,
    radii: Sequence[float],
    triangles: Sequence[ArrayLike],
    resolutions: Sequence[int],
    density: str,
    rho_scale: float,
    seed: int,
    progress: Optional[Callable[[int, int], object]] = None,
) -> dict[str, Any]: ...
def epr_shadow_points(
    scene: Scene,
    eye: Camera,
    center: ArrayLike,
    radius: float,
    samples: int,
    resolution: int,
    max_resolution: int,
    density: str,
    rho_scale: float,
    seed: int,
) -> dict[str, Any]: ...
def omni_shadows(
    scene: Scene,
    eye: Camera,
    center: ArrayLike,
    radius: float,
    samples: int,
    method: str,
    rho_scale: float,
    resolution: int,
    max_resolution: int,
    seed: int,
) -> dict[str, Any]: ...
def splat(
    scene: Scene,
    center: ArrayLike,
    length: ArrayLike,
    triangle: ArrayLike,
    views: ArrayLike,
    cameras: Sequence[Camera],
    clip_to_triangle: bool,
) -> dict[str, Any]: ...
def reflections(
    scene: Scene,
    eye: Camera,
    centers: ArrayLike,
    radii: Sequence[float],
    triangles: Sequence[ArrayLike],
    resolutions: Sequence[int],
    method: str,
    bounces: int,
    supersample: int,
    rho_scale: float,
    seed: int,
) -> dict[str, Any]: ...
def default_slab(scene: Scene, axis: Optional[int], margin: float, widen: float) -> np.ndarray: ...
def visibility_field(
    scene: Scene,
    slabs: Sequence[ArrayLike],
    uv: tuple[int, int],
    st: tuple[int, int],
    grid: tuple[int, int, int],
    grouping: str,
    ids_per_sample: int,
    supersample: int,
    jitter: Optional[int],
    progress: Optional[Callable[[int, int], object]] = None,
) -> dict[str, Any]: ...
def field_view(
    sorted_scene: Scene,
    triangles: np.ndarray,
    offsets: np.ndarray,
    slabs: Sequence[ArrayLike],
    ids: Sequence[np.ndarray],
    camera: Camera,
    interpolate: str,
    subsample: int,
) -> dict[str, Any]: ...
def render_cells(
    sorted_scene: Scene,
    triangles: np.ndarray,
    offsets: np.ndarray,
    marked: np.ndarray,
    camera: Camera,
) -> tuple[dict[str, Any], int]: ...

@final
class Impostors: ...

def impostors(
    scene: Scene,
    depth: int,
    subdivisions: int,
    resolution: int,
    projection_name: str,
    fov: Optional[float],
    grow: bool,
    progress: Optional[Callable[[int, int], object]] = None,
) -> tuple[Impostors, dict[str, Any]]: ...
def impostor_view(
    handle: Impostors,
    camera: Camera,
    triangle_budget: Optional[int],
    use_scene: bool,
    screen_threshold: float,
) -> dict[str, Any]: ...
def render_lit(scene: Scene, camera: Camera) -> dict[str, Any]: ...
def shade_frame(
    scene: Scene,
    camera: Camera,
    triangle: ArrayLike,
    position: ArrayLike,
    light_visibility: Sequence[Optional[ArrayLike]],
    areas: Sequence[tuple[ArrayLike, Optional[ArrayLike]]],
) -> np.ndarray: ...
def impostor_directions(handle: Impostors, camera: Camera) -> list[int]: ...
def cast_rays(
    scene: Scene,
    origins: ArrayLike,
    directions: ArrayLike,
    t_min: float = 0.0,
    t_max: float = ...,
    max_hits: int = 1,
    threads: Optional[int] = None,
) -> dict[str, Any]: ...
def occluded(
    scene: Scene,
    origins: ArrayLike,
    directions: ArrayLike,
    t_min: float = 0.0,
    t_max: float = ...,
    threads: Optional[int] = None,
) -> dict[str, Any]: ...
def bvh_stats(scene: Scene) -> dict[str, Any]: ...
def device_info() -> dict[str, Any]: ...
def write_exr(
    path: _Path,
    width: int,
    height: int,
    depth: ArrayLike,
    triangle: ArrayLike,
    normal: ArrayLike,
    position: ArrayLike,
    color: ArrayLike,
    cameras: list[Camera],
    method: str,
) -> None: ...
def read_exr(path: _Path) -> dict[str, Any]: ...
