# Hand-written stubs for the native module (src/py/); checked against it by tests/test_api.py
# with mypy.stubtest.
from collections.abc import Sequence
from os import PathLike
from typing import (
    Any,
    Callable,
    Literal,
    Optional,
    Protocol,
    TypedDict,
    TypeVar,
    Union,
    final,
)

import numpy as np
from numpy.typing import ArrayLike

_R = TypeVar("_R", covariant=True)

__all__ = [
    "Camera",
    "Field",
    "Impostors",
    "Scene",
    "__version__",
    "all_hits",
    "bvh_stats",
    "ray_kernel",
    "cast_rays",
    "check_memory",
    "choose_backend",
    "closest_points",
    "count_hits",
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
    "reconstruct",
    "reflections",
    "render_cells",
    "render_lit",
    "sampling_metrics",
    "shade_frame",
    "six_slabs",
    "soft_shadows",
    "splat",
    "surface_attributes",
    "visibility_field",
    "winding_numbers",
    "write_exr",
]
__version__: str

_Path = Union[str, PathLike[str]]
_Redundancy = Literal["pixel", "visibility"]
_ImageMethod = Literal["conventional", "nonredundant", "peeling"]
_MeshMethod = Literal["mesh", "hybrid", "points"]
_Discretization = Literal["nonredundant", "conventional", "peeling", "geometry", "raytraced"]
_Density = Literal["eye", "offscreen"]
_OmniMethod = Literal["epr", "mvr", "ivir", "raytraced"]
_ReflectionMethod = Literal["epr", "mvr", "ivir"]
_Grouping = Literal["objects", "scene"]
_Interpolation = Literal["none", "uv", "st", "uv+st"]
_Projection = Literal["orthographic", "perspective"]

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
        texcoords: Optional[ArrayLike] = None,
        textures: Optional[Sequence[np.ndarray]] = None,
        cameras: Optional[Sequence[Camera]] = None,
        animations: Optional[str] = None,
    ) -> Scene: ...
    def posed(
        self,
        transforms: ArrayLike,
        rewinds: bool = False,
        lights: Optional[list[dict[str, Any]]] = None,
        vertices: Optional[ArrayLike] = None,
        normals: Optional[ArrayLike] = None,
    ) -> Scene: ...
    @property
    def base(self) -> Optional[Scene]: ...
    @property
    def rewinds(self) -> bool: ...
    @property
    def deforms(self) -> bool: ...
    @property
    def animations(self) -> list[tuple[str, float]]: ...
    @property
    def animations_state(self) -> Optional[str]: ...
    @property
    def texcoords(self) -> Optional[np.ndarray]: ...
    @property
    def textures(self) -> list[np.ndarray]: ...
    def at(self, t: float, clips: list[int | str]) -> Scene: ...
    def key_times(self, clip: int | str) -> np.ndarray: ...
    def deformed(self, vertices: ArrayLike, normals: Optional[ArrayLike] = None) -> Scene: ...
    @property
    def transforms(self) -> Optional[np.ndarray]: ...
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
    def vertex_count(self) -> int: ...
    @property
    def degenerate_count(self) -> int: ...
    @property
    def closed(self) -> bool: ...
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

# The dicts the native functions return, key by key; tests/test_stub_keys.py checks them against
# real calls (private names, which stubtest skips). Timings and stats map names to seconds or
# counts, so they stay dict[str, float].

class _Ops(TypedDict):
    cube_maps: int
    splat_passes: int
    shadow_views: int
    rays_cast: int

class _ImagesDict(TypedDict):
    depth: np.ndarray
    triangle: np.ndarray
    normal: np.ndarray
    shading_normal: np.ndarray
    position: np.ndarray
    color: np.ndarray
    cameras: list[Camera]
    method: str
    timings: dict[str, float]

class _BackendImagesDict(_ImagesDict):
    backend: Literal["gpu", "cpu"]
    backend_reason: str

class _SamplingDict(TypedDict):
    samples: np.ndarray
    redundant: np.ndarray
    disoccluded: np.ndarray
    useful: np.ndarray
    available_avg: np.ndarray
    available_min: np.ndarray
    frames: int
    disoccluded_mask: np.ndarray
    useful_mask: np.ndarray
    timings: dict[str, float]

class _MeshDict(TypedDict):
    vertices: np.ndarray
    faces: np.ndarray
    sample: np.ndarray
    timings: dict[str, float]

class _ShadowDict(TypedDict):
    visibility: np.ndarray
    visible: np.ndarray
    mask: np.ndarray
    occluder_triangles: int
    timings: dict[str, float]
    ops: _Ops

class _PointsDict(TypedDict):
    center: np.ndarray
    length: np.ndarray
    triangle: np.ndarray
    normal: np.ndarray
    shading_normal: np.ndarray
    color: np.ndarray
    material: np.ndarray
    views: np.ndarray
    cameras: list[Camera]
    timings: dict[str, float]
    stats: dict[str, float]

class _OmniDict(TypedDict):
    visibility: np.ndarray
    visible: np.ndarray
    mask: np.ndarray
    light_samples: np.ndarray
    resolution: int
    stats: dict[str, float]
    timings: dict[str, float]
    ops: _Ops

class _SplatDict(TypedDict):
    depth: np.ndarray
    index: np.ndarray
    packed: np.ndarray
    timings: dict[str, float]
    ops: _Ops

class _ReflectionsDict(TypedDict):
    image: np.ndarray
    reflective: np.ndarray
    stats: dict[str, float]
    timings: dict[str, float]
    ops: _Ops

class _FieldDict(TypedDict):
    groups: int
    cell_seconds: float
    bvh_seconds: float
    rays: int
    timings: dict[str, float]

class _FieldViewDict(TypedDict):
    marked: np.ndarray
    pixels: int
    outside: int
    overflowed: int
    fallback_cells: int
    border_cells: int
    triangles_drawn: int
    resample_seconds: float
    fallback_seconds: float
    render_seconds: float
    image: _ImagesDict

class _ImpostorsDict(TypedDict):
    lo: np.ndarray
    size: np.ndarray
    index: np.ndarray
    directions: np.ndarray
    color: np.ndarray
    depth: np.ndarray
    crops: np.ndarray
    triangle_counts: np.ndarray
    offsets: np.ndarray
    triangles: np.ndarray
    rays: int
    timings: dict[str, float]

class _ImpostorViewDict(TypedDict):
    color: np.ndarray
    depth: np.ndarray
    used: np.ndarray
    stats: dict[str, float]
    timings: dict[str, float]

class _LitDict(TypedDict):
    color: np.ndarray
    depth: np.ndarray
    seconds: float

class _HitsDict(TypedDict):
    t: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    timings: dict[str, float]

class _OcclusionDict(TypedDict):
    hit: np.ndarray
    timings: dict[str, float]

class _AllHitsDict(TypedDict):
    ray_splits: np.ndarray
    t: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    timings: dict[str, float]

class _CountDict(TypedDict):
    count: np.ndarray
    timings: dict[str, float]

class _ClosestDict(TypedDict):
    point: np.ndarray
    distance: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    timings: dict[str, float]

class _BvhStatsDict(TypedDict):
    triangles: int
    nodes: int
    blocks: int
    bytes: int
    depth: int
    instances: int
    sah: float
    build_seconds: float
    winding_bytes: int

class _DeviceInfo(TypedDict):
    name: str
    backend: str
    device_type: str
    driver: str
    timestamps: bool
    max_texture_dimension_2d: int
    max_storage_buffer_binding_size: int

def discretize_conventional(
    scene: Scene,
    cameras: list[Camera],
    cull_backfaces: bool = False,
    backend: Literal["auto", "gpu", "cpu"] = "auto",
) -> _BackendImagesDict: ...
def discretize_nonredundant(
    scene: Scene,
    cameras: list[Camera],
    redundancy: _Redundancy = "pixel",
    cull_backfaces: bool = False,
    backend: Literal["auto", "gpu", "cpu"] = "auto",
) -> _BackendImagesDict: ...
def discretize_peeling(
    scene: Scene,
    camera: Camera,
    layers: int,
    cull_backfaces: bool = False,
    backend: Literal["auto", "gpu", "cpu"] = "auto",
) -> _BackendImagesDict: ...
def sampling_metrics(
    scene: Scene,
    triangle: ArrayLike,
    position: ArrayLike,
    depth: ArrayLike,
    cameras: list[Camera],
    method: _ImageMethod,
    reference: list[Camera],
    frames: list[Camera],
    redundancy: _Redundancy,
    cull_backfaces: bool,
) -> _SamplingDict: ...
def reconstruct(images: Any, method: _MeshMethod, offset: Optional[Any] = None) -> _MeshDict: ...
def soft_shadows(
    scene: Scene,
    camera: Camera,
    center: ArrayLike,
    u: ArrayLike,
    v: ArrayLike,
    samples: tuple[int, int],
    discretization: _Discretization,
    resolution: int,
    corners: bool,
    reconstruction: _MeshMethod,
    shadow_resolution: int,
    layers: int,
) -> _ShadowDict: ...
def epr_points(
    scene: Scene,
    eye: Camera,
    centers: ArrayLike,
    radii: Sequence[float],
    triangles: Sequence[ArrayLike],
    resolutions: Sequence[int],
    density: _Density,
    rho_scale: float,
    seed: int,
    progress: Optional[Callable[[int, int], object]] = None,
) -> _PointsDict: ...
def epr_shadow_points(
    scene: Scene,
    eye: Camera,
    center: ArrayLike,
    radius: float,
    samples: int,
    resolution: int,
    max_resolution: int,
    density: _Density,
    rho_scale: float,
    seed: int,
) -> _PointsDict: ...
def omni_shadows(
    scene: Scene,
    eye: Camera,
    center: ArrayLike,
    radius: float,
    samples: int,
    method: _OmniMethod,
    rho_scale: float,
    resolution: int,
    max_resolution: int,
    seed: int,
) -> _OmniDict: ...
def splat(
    scene: Scene,
    center: ArrayLike,
    length: ArrayLike,
    triangle: ArrayLike,
    views: ArrayLike,
    cameras: Sequence[Camera],
    clip_to_triangle: bool,
) -> _SplatDict: ...
def reflections(
    scene: Scene,
    eye: Camera,
    centers: ArrayLike,
    radii: Sequence[float],
    triangles: Sequence[ArrayLike],
    resolutions: Sequence[int],
    method: _ReflectionMethod,
    bounces: int,
    supersample: int,
    rho_scale: float,
    seed: int,
) -> _ReflectionsDict: ...
def default_slab(scene: Scene, axis: Optional[int], margin: float, widen: float) -> np.ndarray: ...
def six_slabs(scene: Scene, margin: float) -> np.ndarray: ...

@final
class Field:
    @staticmethod
    def restore(
        scene: Scene,
        slabs: Sequence[ArrayLike],
        ids: np.ndarray,
        cells_hit: np.ndarray,
        triangles: np.ndarray,
        offsets: np.ndarray,
        cells: np.ndarray,
        cell_bounds: np.ndarray,
        cell_of: np.ndarray,
    ) -> Field: ...
    @property
    def ids(self) -> np.ndarray: ...
    @property
    def cells_hit(self) -> np.ndarray: ...
    @property
    def triangles(self) -> np.ndarray: ...
    @property
    def offsets(self) -> np.ndarray: ...
    @property
    def cells(self) -> np.ndarray: ...
    @property
    def cell_bounds(self) -> np.ndarray: ...
    @property
    def cell_of(self) -> np.ndarray: ...
    @property
    def slabs(self) -> np.ndarray: ...

def visibility_field(
    scene: Scene,
    slabs: Sequence[ArrayLike],
    uv: tuple[int, int],
    st: tuple[int, int],
    grid: tuple[int, int, int],
    cell_size: Optional[float],
    grouping: _Grouping,
    ids_per_sample: int,
    supersample: int,
    jitter: Optional[int],
    progress: Optional[Callable[[int, int], object]] = None,
) -> tuple[Field, _FieldDict]: ...
def field_view(
    field: Field,
    camera: Camera,
    interpolate: _Interpolation,
    subsample: int,
    fallback: bool,
    trust: int,
    backend: Literal["gpu", "cpu"],
    reference: bool = False,
) -> _FieldViewDict: ...
def render_cells(
    field: Field,
    marked: np.ndarray,
    camera: Camera,
) -> tuple[_ImagesDict, int]: ...

@final
class Impostors: ...

def impostors(
    scene: Scene,
    depth: int,
    subdivisions: int,
    resolution: int,
    projection_name: _Projection,
    fov: Optional[float],
    grow: bool,
    progress: Optional[Callable[[int, int], object]] = None,
) -> tuple[Impostors, _ImpostorsDict]: ...
def impostor_view(
    handle: Impostors,
    camera: Camera,
    triangle_budget: Optional[int],
    use_scene: bool,
    screen_threshold: float,
) -> _ImpostorViewDict: ...
def render_lit(scene: Scene, camera: Camera) -> _LitDict: ...
def shade_frame(
    scene: Scene,
    camera: Camera,
    gbuffer: tuple[ArrayLike, ArrayLike, ArrayLike],
    light_visibility: Sequence[Optional[ArrayLike]],
    areas: Sequence[tuple[ArrayLike, Optional[ArrayLike]]],
) -> tuple[np.ndarray, bool]: ...
def impostor_directions(handle: Impostors, camera: Camera) -> list[int]: ...

class _RayQuery(Protocol[_R]):
    """Every ray query's signature (src/py/rays.rs's `ray_query!`), declared once."""

    def __call__(
        self,
        scene: Scene,
        origins: ArrayLike,
        directions: ArrayLike,
        t_min: float = 0.0,
        t_max: float = ...,
        threads: Optional[int] = None,
        progress: Optional[Callable[[int, int], object]] = None,
    ) -> _R: ...

def cast_rays(
    scene: Scene,
    origins: ArrayLike,
    directions: ArrayLike,
    t_min: float = 0.0,
    t_max: float = ...,
    max_hits: int = 1,
    threads: Optional[int] = None,
    progress: Optional[Callable[[int, int], object]] = None,
) -> _HitsDict: ...

occluded: _RayQuery[_OcclusionDict]
all_hits: _RayQuery[_AllHitsDict]
count_hits: _RayQuery[_CountDict]

def closest_points(
    scene: Scene,
    points: ArrayLike,
    max_distance: float = ...,
    threads: Optional[int] = None,
    progress: Optional[Callable[[int, int], object]] = None,
) -> _ClosestDict: ...
def winding_numbers(
    scene: Scene,
    points: ArrayLike,
    threads: Optional[int] = None,
    progress: Optional[Callable[[int, int], object]] = None,
) -> np.ndarray: ...
def bvh_stats(scene: Scene) -> _BvhStatsDict: ...
def ray_kernel(widest: Optional[str] = None) -> str: ...
def device_info() -> _DeviceInfo: ...
def check_memory(what: str, count: int, each: int) -> int: ...

class _BackendChoiceDict(TypedDict):
    backend: Literal["gpu", "cpu"]
    reason: str
    gpu_seconds: Optional[float]
    cpu_seconds: float
    calibration_seconds: float
    calibration: str
    coefficients: dict[str, float]

def choose_backend(
    triangles: int,
    pixels: int,
    images: int = 1,
    bvh_built: bool = True,
    uploaded: bool = True,
    box_fraction: float = 0.75,
) -> _BackendChoiceDict: ...

class _AttributesDict(TypedDict):
    texcoord: np.ndarray
    color: np.ndarray
    shading_normal: np.ndarray
    normal: np.ndarray

def surface_attributes(
    scene: Scene,
    triangle: ArrayLike,
    barycentric: Optional[ArrayLike] = None,
    points: Optional[ArrayLike] = None,
    footprint: Optional[ArrayLike] = None,
) -> _AttributesDict: ...
def write_exr(
    path: _Path,
    width: int,
    height: int,
    depth: ArrayLike,
    triangle: ArrayLike,
    normal: ArrayLike,
    shading_normal: ArrayLike,
    position: ArrayLike,
    color: ArrayLike,
    cameras: list[Camera],
    method: str,
) -> None: ...
def read_exr(path: _Path) -> _ImagesDict: ...
