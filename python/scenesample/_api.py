"""The verbs ``discretize`` and ``reconstruct``: each dispatches on ``method=`` to a function of
:mod:`scenesample.methods` and checks the options against its signature (``evaluate`` lives in
``_evaluate``, ``splat`` in ``_epr``, ray queries in ``_rays``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal, Optional, Union, overload

from . import _core
from ._conventional import camera_list
from ._scene import Scene
from .epr.points import Points
from .errors import GpuUnavailableError, InputError
from .impostors.cells import Impostors, ImpostorView
from .methods import DISCRETIZE, RECONSTRUCT, check_options, field_view, impostor_view
from .nonredundant.images import offset_images
from .results import DepthImages, Mesh
from .visibility_field import FieldView, VisibilityField

__all__ = ["discretize", "reconstruct", "device_info", "offset_images"]

Camera = _core.Camera
DISCRETIZE_METHODS = tuple(DISCRETIZE)
RECONSTRUCT_METHODS = tuple(RECONSTRUCT)
ImageMethod = Literal["conventional", "nonredundant", "peeling"]
PointMethod = Literal["epr", "ivir"]
Cameras = Union[None, Camera, Sequence[Camera]]


@overload
def discretize(
    scene: Scene, cameras: Cameras = ..., method: ImageMethod = ..., **options: Any
) -> DepthImages: ...
@overload
def discretize(
    scene: Scene, cameras: None = ..., *, method: PointMethod, **options: Any
) -> Points: ...
@overload
def discretize(
    scene: Scene, cameras: None = ..., *, method: Literal["visibility_field"], **options: Any
) -> VisibilityField: ...
@overload
def discretize(
    scene: Scene, cameras: None = ..., *, method: Literal["impostors"], **options: Any
) -> Impostors: ...
def discretize(
    scene: Scene,
    cameras: Cameras = None,
    method: str = "conventional",
    **options: Any,
) -> Union[DepthImages, Points, VisibilityField, Impostors]:
    """Sample a scene: with depth images (non-redundant-rendering.txt §3, §6.1), with points
    for many off-screen views (eye-based-point-rendering.txt §3), with a visibility field
    (visibility-field.txt §3) or with impostors (multi-cell-orthographic-impostors.txt §3.1).

    Each method is a function of :mod:`scenesample.methods` whose docstring gives its options,
    defaults and result; ``discretize(scene, cameras, method, **options)`` calls it.

    Parameters
    ----------
    scene : Scene
    cameras : Camera or sequence of Camera
        The views of the depth-image methods (resolutions must match); the other methods make
        their own views and take none.
    method : str
        ``"conventional"`` (:func:`~scenesample.methods.conventional`: ``cull_backfaces``),
        ``"nonredundant"`` (:func:`~scenesample.methods.nonredundant`: ``redundancy``,
        ``cull_backfaces``), ``"peeling"`` (:func:`~scenesample.methods.peeling`:
        ``layers`` (required), ``camera``, ``cull_backfaces``), ``"epr"`` / ``"ivir"``
        (:func:`~scenesample.methods.epr`: ``eye`` (required), ``reflectors``, ``light``,
        ``light_samples``, ``rho_scale`` (epr only), ``seed``, ``resolution``, ``progress``),
        ``"visibility_field"`` (:func:`~scenesample.methods.visibility_field`: ``slab``,
        ``quality``, ``uv``, ``st``, ``grid``, ``ids_per_sample``, ``supersample``,
        ``jitter``, ``seed``, ``memory_limit``, ``progress``), ``"impostors"``
        (:func:`~scenesample.methods.impostors`: ``octree_depth``, ``subdivisions``,
        ``resolution``, ``projection``, ``fov``, ``grow``, ``progress``).
    **options
        The method's keyword options.

    Returns
    -------
    DepthImages, Points, VisibilityField (all its slabs in one) or Impostors

    Raises
    ------
    InputError
        Unknown method, an option the method does not take (the message lists those it
        takes), a missing required option, cameras for a method that makes its own views, or
        an invalid value.
    GpuUnavailableError, GpuLimitError
        For the GPU methods: no adapter, or images beyond the device's limits.
    """
    if method not in DISCRETIZE:
        raise InputError(f"method must be one of {list(DISCRETIZE)}, got {method!r}")
    fn, takes_cameras = DISCRETIZE[method]
    check_options(method, fn, options, DISCRETIZE)
    if not takes_cameras:
        if cameras is not None:
            raise InputError(
                f"method={method!r} makes its own views: pass no cameras (the eye of "
                "'epr'/'ivir' is eye=)"
            )
        return fn(scene, **options)
    if cameras is None:
        raise InputError(f"method={method!r} needs cameras")
    return fn(scene, camera_list(cameras), **options)


@overload
def reconstruct(
    source: DepthImages, method: Literal["mesh", "hybrid", "points"] = ..., **options: Any
) -> Mesh: ...
@overload
def reconstruct(source: VisibilityField, method: Camera, **options: Any) -> FieldView: ...
@overload
def reconstruct(source: Impostors, method: Camera, **options: Any) -> ImpostorView: ...
def reconstruct(
    source: Union[DepthImages, VisibilityField, Impostors],
    method: Union[str, Camera] = "hybrid",
    **options: Any,
) -> Union[Mesh, FieldView, ImpostorView]:
    """Rebuild surfaces from depth-image samples (non-redundant-rendering.txt §4), or render a
    view from a visibility field (visibility-field.txt §4) or from impostors
    (multi-cell-orthographic-impostors.txt §3.2).

    - ``reconstruct(images, "mesh" | "hybrid" | "points", **options)``: see
      :func:`~scenesample.methods.mesh`, :func:`~scenesample.methods.hybrid` (``scene``,
      ``offset``) and :func:`~scenesample.methods.points`. Returns a :class:`Mesh`.
    - ``reconstruct(field, camera, **options)`` with a :class:`VisibilityField`: see
      :func:`~scenesample.methods.field_view` (``interpolate``, ``subsample``, ``fallback``,
      ``trust``, ``backend``). Returns a :class:`FieldView`.
    - ``reconstruct(impostors, camera, **options)``: see
      :func:`~scenesample.methods.impostor_view` (``triangle_budget``, ``scene``,
      ``screen_threshold``). Returns an :class:`ImpostorView`.

    Raises
    ------
    InputError
        Unknown method, a source of the wrong type, or an option the method does not take.
    """
    if isinstance(source, Impostors):
        if not isinstance(method, Camera):
            raise InputError("reconstruct(impostors, camera): the second argument must be a Camera")
        check_options("impostor_view", impostor_view, options, _VIEWS)
        return impostor_view(source, method, **options)
    fields = source if isinstance(source, (list, tuple)) else [source]
    if fields and all(isinstance(f, VisibilityField) for f in fields):
        if not isinstance(method, Camera):
            raise InputError("reconstruct(field, camera): the second argument must be a Camera")
        check_options("field_view", field_view, options, _VIEWS)
        return field_view(source, method, **options)
    if not isinstance(source, DepthImages):
        raise InputError(
            f"images must be a DepthImages or a VisibilityField, got {type(source).__name__}"
        )
    if not isinstance(method, str) or method not in RECONSTRUCT:
        raise InputError(f"method must be one of {list(RECONSTRUCT)}, got {method!r}")
    check_options(method, RECONSTRUCT[method], options, {**RECONSTRUCT, **_VIEWS})
    return RECONSTRUCT[method](source, **options)


_VIEWS = {"field_view": field_view, "impostor_view": impostor_view}


def device_info(
    *,
    triangles: Optional[int] = None,
    pixels: Optional[int] = None,
    images: int = 1,
    bvh_built: bool = True,
    uploaded: bool = True,
) -> dict[str, Any]:
    """The GPU adapter scenesample uses: ``available`` (True), ``name``, ``backend``,
    ``device_type``, ``driver``, ``timestamps`` (whether GPU timings are available) and the
    limits that bound requests (``max_texture_dimension_2d``,
    ``max_storage_buffer_binding_size``).

    Without an adapter (no Vulkan driver) it does not raise: ``available`` is False, ``error``
    says why and how to install one, ``name``/``backend``/``device_type``/``driver`` are None,
    ``timestamps`` False and the limits 0. The CPU paths (``cast_rays``, ``occluded``,
    conventional and peeling ``discretize``) then still work; the GPU-only methods raise
    :class:`GpuUnavailableError`.

    With ``triangles`` and ``pixels`` (per image), also ``auto``: what conventional
    ``discretize(..., backend="auto")`` would choose for ``images`` images of a scene of that
    size: ``backend`` ("gpu" or "cpu"; always "cpu" without an adapter), ``reason``, the
    predicted ``gpu_seconds`` (None without an adapter) and ``cpu_seconds``,
    ``calibration_seconds`` (the cost model's probes, run in this process; 0 when another
    process had run them), ``calibration`` (the calibration file's path, or ``"built-in (...)"``
    where no file can be kept) and ``coefficients`` (seconds per call, triangle, pixel and ray;
    see ``src/discretize/backend/``), for views where three quarters of the pixels see the
    scene's bounding box (``discretize`` counts them for its cameras). ``discretize`` weighs
    every request as one whose BVH
    is built and whose GPU copy is made, whatever ran before, so that its choice depends only
    on the call; ``bvh_built=False`` or ``uploaded=False`` predict a first call instead."""
    try:
        info: dict[str, Any] = {"available": True, **_core.device_info()}
    except GpuUnavailableError as e:
        info = {
            "available": False,
            "error": str(e),
            "name": None,
            "backend": None,
            "device_type": None,
            "driver": None,
            "timestamps": False,
            "max_texture_dimension_2d": 0,
            "max_storage_buffer_binding_size": 0,
        }
    if (triangles is None) != (pixels is None):
        raise InputError("device_info needs both triangles= and pixels= (or neither)")
    if triangles is not None and pixels is not None:
        if triangles < 0 or pixels < 1 or images < 1:
            raise InputError(
                f"triangles must be >= 0 and pixels, images >= 1; got {triangles}, {pixels}, "
                f"{images}"
            )
        info["auto"] = _core.choose_backend(
            int(triangles), int(pixels), int(images), bool(bvh_built), bool(uploaded)
        )
    return info
