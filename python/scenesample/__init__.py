"""scenesample: sample 3D triangle scenes with images, points and rays; rebuild geometry and
views from the samples; measure what each method costs and how accurate it is.

Conventions (shared by every function):

- Geometry and images are float32; ids are int32 with -1 for "nothing"; faces are uint32.
- Cameras follow OpenGL / pyrender / glTF: a 4x4 camera-to-world pose, looking along -Z with +Y
  up, ``yfov`` in radians, image row 0 at the top, pixel centres at +0.5.
- Depth is camera-space z (positive), ``+inf`` where no surface (pyrender uses 0).
- Ray hits: ``t`` in units of the direction's length, ``+inf`` and triangle -1 on a miss.
- Every result carries ``timings`` (seconds per stage).
"""

# `_env` first: on a headless machine it quiets Mesa's device-selection layer (see its notes).
from . import _env, errors, methods, plot, references, scenes  # noqa: F401
from ._api import device_info, discretize, reconstruct
from ._attributes import surface_attributes
from ._core import Camera
from ._core import __version__ as __version__
from ._evaluate import evaluate, intermediate_cameras
from ._plan import Effect, Frame, plan, render
from ._points import closest_points, occupancy, signed_distance, winding_number
from ._rays import all_hits, bvh_stats, cast_rays, count_hits, occluded, ray_kernel
from ._scene import Scene
from ._tradeoff import tradeoff
from .epr.omni import OmniShadowResult, omni_shadows
from .epr.points import Points, Reflector, SplatBuffers, cube_resolution, splat
from .epr.reflections import ReflectionResult, reflection_reference, reflections
from .errors import (
    ExrError,
    GpuError,
    GpuLimitError,
    GpuUnavailableError,
    InputError,
    MissingDependencyError,
    SceneError,
    SceneFileError,
    ScenesampleError,
    SceneWarning,
)
from .impostors.cells import Impostors, ImpostorView
from .nonredundant.shadows import AreaLight, ShadowResult, soft_shadows
from .results import AllHits, ClosestPoints, DepthImages, Mesh, RayHits, SurfaceSamples
from .visibility_field import FieldView, Slab, VisibilityField

__all__ = [
    "AllHits",
    "AreaLight",
    "Camera",
    "ClosestPoints",
    "DepthImages",
    "Effect",
    "ExrError",
    "FieldView",
    "Frame",
    "GpuError",
    "GpuLimitError",
    "GpuUnavailableError",
    "ImpostorView",
    "Impostors",
    "InputError",
    "Mesh",
    "MissingDependencyError",
    "OmniShadowResult",
    "Points",
    "RayHits",
    "ReflectionResult",
    "Reflector",
    "Scene",
    "SceneError",
    "SceneFileError",
    "SceneWarning",
    "Slab",
    "ShadowResult",
    "SplatBuffers",
    "SurfaceSamples",
    "VisibilityField",
    "ScenesampleError",
    "all_hits",
    "bvh_stats",
    "cast_rays",
    "closest_points",
    "count_hits",
    "cube_resolution",
    "device_info",
    "discretize",
    "errors",
    "evaluate",
    "intermediate_cameras",
    "methods",
    "occluded",
    "occupancy",
    "omni_shadows",
    "plan",
    "plot",
    "ray_kernel",
    "reconstruct",
    "references",
    "reflection_reference",
    "reflections",
    "render",
    "splat",
    "scenes",
    "signed_distance",
    "soft_shadows",
    "surface_attributes",
    "tradeoff",
    "winding_number",
]


def __dir__() -> list[str]:
    """The public API only: the private modules the façade imports from (``_core``, ``_api``,
    ...) become attributes of the package, but are not for users."""
    return sorted(__all__)
