"""The verbs ``discretize`` and ``reconstruct`` (``evaluate`` lives in ``_evaluate``, ``splat`` in
``_epr``, ray queries in ``_rays``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Optional, Union

import numpy as np

from . import _core
from ._epr import Points, epr_points
from ._field import FieldView, Slab, VisibilityField, field_view, visibility_field
from ._impostors import Impostors, ImpostorView, impostor_view, impostors
from ._omni import shadow_points
from ._scene import Scene
from .errors import InputError
from .results import DepthImages, Mesh

__all__ = ["discretize", "reconstruct", "device_info"]

Camera = _core.Camera
DISCRETIZE_METHODS = (
    "conventional",
    "nonredundant",
    "peeling",
    "epr",
    "ivir",
    "visibility_field",
    "impostors",
)


def _scene_core(scene: Any) -> _core.Scene:
    if isinstance(scene, Scene):
        return scene._core
    raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")


def _camera_list(cameras: Union[Camera, Sequence[Camera]]) -> list[Camera]:
    cams = [cameras] if isinstance(cameras, Camera) else list(cameras)
    for i, c in enumerate(cams):
        if not isinstance(c, Camera):
            raise InputError(f"cameras[{i}] must be a scenesample.Camera, got {type(c).__name__}")
    if not cams:
        raise InputError("discretize needs at least one camera")
    return cams


def discretize(
    scene: Scene,
    cameras: Union[None, Camera, Sequence[Camera]] = None,
    method: str = "conventional",
    *,
    redundancy: str = "pixel",
    layers: Optional[int] = None,
    camera: Optional[Camera] = None,
    cull_backfaces: bool = False,
    eye: Optional[Camera] = None,
    reflectors: Any = None,
    rho_scale: float = 0.5,
    seed: int = 0,
    resolution: Union[None, int, Sequence[int]] = None,
    light: Any = None,
    light_samples: int = 20,
    slab: Union[None, Slab, Sequence[Slab]] = None,
    uv: Any = (16, 16),
    st: Any = (16, 16),
    grid: Any = (16, 16, 16),
    ids_per_sample: int = 1,
    supersample: int = 3,
    depth: int = 4,
    subdivisions: int = 2,
    projection: str = "orthographic",
    fov: Optional[float] = None,
    grow: bool = True,
    progress: Optional[bool] = None,
) -> Union[DepthImages, Points, VisibilityField, list[VisibilityField], Impostors]:
    """Sample a scene with depth images (non-redundant-rendering.txt §3, §6.1) or with points
    for many off-screen views (eye-based-point-rendering.txt §3).

    Parameters
    ----------
    scene : Scene
    cameras : Camera or sequence of Camera
        The reference views of the depth-image methods; poses and projections may differ,
        resolutions must match. Not used by ``epr`` / ``ivir``.
    method : {"conventional", "nonredundant", "peeling", "epr", "ivir"}
        ``"conventional"``: one image per camera, each sampling every surface it sees (one GPU
        raster pass per image, nearest surface at each pixel centre, no multisampling).

        ``"nonredundant"``: one image per camera, rendered in order; image i keeps at each
        pixel the nearest sample that is not redundant with images 0..i-1 (Algorithm 1), so a
        redundant sample never hides a new one behind it. Image 0 is conventional.

        ``"peeling"``: ``layers`` depth-peeling layers from one viewpoint (``camera``, by
        default the centroid of ``cameras`` with their mean orientation, as in §6.1.3); layer
        i keeps the nearest sample strictly beyond layer i-1's depth at each pixel. Ties: a
        surface whose depth at the pixel centre is within a relative 1e-5 of layer i-1's (a
        duplicated or coplanar face) is that layer met again, not a new one, so depths
        strictly increase along each pixel, as the distinct hits of
        ``cast_rays(max_hits=k)`` do; the freed last layers of such a pixel are empty.
    redundancy : {"pixel", "visibility"}
        For ``nonredundant``. ``"pixel"`` (Algorithm 3, on the GPU in the same pass): a sample
        is redundant when an earlier image holds its triangle at the pixel it reprojects to.
        ``"visibility"`` (Algorithm 2, exact, on the CPU): a sample is redundant when an
        earlier image's viewpoint sees it (inside that image's view volume, unoccluded). Each
        pixel ray of image i is walked front to back through the surfaces it crosses with BVH
        ray casts, each candidate tested with one visibility ray per earlier viewpoint; the
        first candidate no earlier viewpoint sees is kept. Surfaces within ``1e-5`` of the
        scene diagonal (plus ``1e-5`` of the distance) count as the same point.
    layers : int
        For ``peeling`` (required there): number of layers, >= 1.
    camera : Camera, optional
        For ``peeling``: the viewpoint (its resolution must match ``cameras``).
    cull_backfaces : bool
        Drop triangles whose counter-clockwise front faces away (off by default).
    eye : Camera
        For ``epr`` / ``ivir`` (required there): the eye whose pixels the points must fill.
    reflectors : list, optional
        For ``epr`` / ``ivir``: object names, :class:`Reflector` objects or ``(center,
        radius)`` bounding spheres; by default every object whose material has metallic >= 0.9
        and roughness <= 0.1. Each gets a cube map of six views.
    rho_scale : float
        For ``epr``: points per eye pixel along each axis (§3.2; 0.5 is the paper's choice).
    seed : int
        For ``epr`` / ``ivir``: seeds the stochastic culling of sub-1/10-pixel triangles.
    resolution : int or sequence of int, optional
        For ``epr`` / ``ivir``: cube-map face resolution (one, or one per reflector); by
        default the adaptive size of §4.1.1 (see :func:`scenesample.cube_resolution`), or for
        shadow points Eq. 6 (see :func:`scenesample.omni_shadows`).
    light : (center, radius), optional
        For ``epr`` / ``ivir``: points for the shadow cube maps of this spherical light
        (eye-based-point-rendering.txt §5.1) instead of reflections: six views per light
        sample, in ``Camera.cube`` order, sample after sample. EPR spacing: the eye's pixel
        footprint at the nearest of the triangle's shadow volumes over ``rho_scale`` (Eq. 5),
        never finer than the iVIR spacing, the cube-map texel at the triangle's distance from
        the nearest light sample (so an eye inside a shadow volume gets a finite density).
    light_samples : int
        With ``light``: samples on the light (its centre for 1, else a Fibonacci lattice on its
        sphere).
    slab : Slab or list of Slab, optional
        For ``visibility_field``: the two-plane parameterization (default
        :meth:`Slab.around`: planes before and beyond the scene's bounds along their longest
        axis). Several slabs give one field each (a list), sharing the cells.
    uv, st : (int, int)
        For ``visibility_field``: samples on each plane (default 16 x 16).
    grid : (int, int, int) or "scene"
        For ``visibility_field``: cells along x, y, z of each object's bounding box (objects:
        the scene's meshes/nodes, or its connected components when it has one object);
        ``"scene"``: one 16^3 grid over the whole scene. A triangle belongs to the cell holding
        its centroid.
    ids_per_sample : int
        For ``visibility_field``: cell ids kept per sample (the most frequent).
    supersample : int
        For ``visibility_field``: rays per axis of each plane's sample cell (3: 3 x 3 on each
        plane, 81 rays per sample, §3.3). ``seed`` 0 puts them at sub-cell centres (the
        paper's regular grid); any other seed jitters each within its sub-cell.
    depth, subdivisions, projection, fov, grow
        For ``impostors``: octree depth (leaves 2**depth per axis of the cubic bounds; empty
        ones skipped), icosahedron subdivisions (20 * 4**s views per cell: 320 for 2),
        ``"orthographic"`` (the paper's) or ``"perspective"`` images (camera at radius /
        sin(fov / 2), ``fov`` in radians), and cell growing (§4.3: each cell's images show
        every triangle that intersects its bounding sphere; without it only the geometry
        inside the cell, rays clipped to its box). ``resolution`` is the image side (default
        128).
    progress : bool, optional
        For the precomputations (``visibility_field``: slab samples; ``impostors``: cells;
        ``epr``/``ivir`` reflector points: triangles): a tqdm bar when tqdm is installed. None
        (default): only once the work has run for 2 s; True: at once; False: never. Ctrl-C
        stops any of them within half a second (``KeyboardInterrupt``).

    ``"epr"`` (§3.1-3.4, Eq. 2-4): per triangle, one visibility bit per cube-map view
    (conservative: dropped only when all vertices lie outside one plane of the 20%-enlarged
    frustum; a reflector's own triangles are left out of its own cube, and so is a triangle
    whose material is single-sided (``double_sided`` false) and turns its back to the
    reflector's centre, as §3.2 samples a triangle only for the views it faces; triangles
    without a material count as double-sided); point spacing = the
    eye's pixel footprint at the distance light travels from the triangle via the nearest
    reflector's bounding sphere to the eye, divided by ``rho_scale``, never finer than the finest
    cube map that sees the triangle; triangles under 1/10 point-cell dropped with probability
    1 - 10 A; every lattice cell overlapping the triangle gives a point (exact conservative
    rasterization, on the CPU, since wgpu here has none). ``"ivir"``: the same, spaced by the
    cube-map texel at the triangle's distance from the reflector.

    ``"impostors"`` (multi-cell-orthographic-impostors.txt §3.1): per non-empty octree cell and
    icosahedron direction, a ``resolution``² image of the cell ray-cast on the CPU through a
    BVH of the cell's triangles, lit view-independently (base colour x (0.3 + 0.7 |n . L|), L
    fixed), cropped to its content. See :class:`Impostors`.

    ``"visibility_field"`` (visibility-field.txt §3): for every sample (iu, iv, is, it) of the
    slab, ``supersample^4`` BVH rays from its uv cell to its st cell; the ``ids_per_sample``
    cells hit most often are kept (§3.3). See :class:`VisibilityField`.

    Returns
    -------
    DepthImages, Points or VisibilityField
        For ``visibility_field``: :class:`VisibilityField` (a list for several slabs). For
        ``epr`` / ``ivir``: :class:`Points`. Otherwise :class:`DepthImages`:
        ``depth`` (n, H, W) float32 camera-space z (+inf empty), ``triangle`` (n, H, W) int32
        (-1 empty), ``normal``/``position``/``color`` (n, H, W, 3) float32, ``cameras``,
        ``method``, ``reference`` (= ``cameras``), ``timings``. n is ``len(cameras)``, or
        ``layers`` for peeling.

        At the edges: a camera inside a closed mesh sees its inside on every pixel; with an
        explicit ``znear`` that cuts through the scene each pixel holds the nearest surface at
        or beyond the near plane (``cast_rays(t_min=znear)`` along camera-z directions gives
        the same); a triangle far smaller than a pixel's footprint appears only where it covers
        a pixel centre; triangle ids stay exact past 2^24 (int32 up to 2^31 - 1).

    Raises
    ------
    GpuUnavailableError
        No GPU adapter (install ``mesa-vulkan-drivers`` for a software one).
    GpuLimitError
        The images exceed the device's texture or buffer limits.
    InputError
        Unknown method or redundancy, cameras of different resolutions, no camera, or missing
        or invalid ``layers``.
    """
    if method not in DISCRETIZE_METHODS:
        raise InputError(f"method must be one of {list(DISCRETIZE_METHODS)}, got {method!r}")
    if method == "impostors":
        if cameras is not None or eye is not None:
            raise InputError("method='impostors' makes its own views: no cameras")
        return impostors(
            scene,
            depth=depth,
            subdivisions=subdivisions,
            resolution=128 if resolution is None else resolution,
            projection=projection,
            fov=fov,
            grow=grow,
            progress=progress,
        )
    if method == "visibility_field":
        if cameras is not None or eye is not None:
            raise InputError("method='visibility_field' samples lines through a slab: no cameras")
        return visibility_field(
            scene,
            slab=slab,
            uv=uv,
            st=st,
            grid=grid,
            ids_per_sample=ids_per_sample,
            supersample=supersample,
            seed=seed if seed else None,
            progress=progress,
        )
    if method in ("epr", "ivir"):
        if eye is None:
            raise InputError(f"method={method!r} needs eye=, the camera the points serve")
        if cameras is not None:
            raise InputError(f"method={method!r} makes its own cube-map views; pass no cameras")
        if light is not None:
            if reflectors is not None:
                raise InputError("pass reflectors= (reflections) or light= (shadows), not both")
            if resolution is not None and not isinstance(resolution, (int, np.integer)):
                raise InputError(f"shadow cube maps share one resolution; got {resolution!r}")
            return shadow_points(
                scene,
                eye,
                light,
                light_samples=light_samples,
                rho_scale=rho_scale,
                seed=seed,
                resolution=resolution,
                density="eye" if method == "epr" else "offscreen",
            )
        return epr_points(
            scene,
            eye,
            reflectors=reflectors,
            rho_scale=rho_scale,
            seed=seed,
            resolution=resolution,
            density="eye" if method == "epr" else "offscreen",
            progress=progress,
        )
    if eye is not None or reflectors is not None or resolution is not None or light is not None:
        raise InputError(
            f"eye, reflectors, light and resolution apply to method='epr', not {method!r}"
        )
    if cameras is None:
        raise InputError(f"method={method!r} needs cameras")
    cams = _camera_list(cameras)
    core = _scene_core(scene)
    cull = bool(cull_backfaces)
    if method != "peeling" and (layers is not None or camera is not None):
        raise InputError(f"layers and camera apply to method='peeling', not {method!r}")
    if method != "nonredundant" and redundancy != "pixel":
        raise InputError(f"redundancy applies to method='nonredundant', not {method!r}")
    if method == "conventional":
        d = _core.discretize_conventional(core, cams, cull)
    elif method == "nonredundant":
        if redundancy not in ("pixel", "visibility"):
            raise InputError(f"redundancy must be 'pixel' or 'visibility', got {redundancy!r}")
        d = _core.discretize_nonredundant(core, cams, redundancy, cull)
    else:
        if layers is None:
            raise InputError("method='peeling' needs layers=k (the number of layers)")
        if isinstance(layers, bool) or not isinstance(layers, (int, np.integer)) or layers < 1:
            raise InputError(f"layers must be a positive integer, got {layers!r}")
        if camera is None:
            camera = Camera.blend(cams)
        elif not isinstance(camera, Camera):
            raise InputError(f"camera must be a scenesample.Camera, got {type(camera).__name__}")
        if (camera.width, camera.height) != (cams[0].width, cams[0].height):
            raise InputError(
                f"the peeling camera is {camera.width}x{camera.height}, the cameras are "
                f"{cams[0].width}x{cams[0].height}; they must match"
            )
        d = _core.discretize_peeling(core, camera, int(layers), cull)
    images = DepthImages._from_core(d, cams, cull)
    # Provenance, so that ``reconstruct(images, "hybrid")`` can render the offset images.
    images._source = (scene, method, redundancy)
    return images


RECONSTRUCT_METHODS = ("mesh", "hybrid", "points")


def reconstruct(
    images: Union[DepthImages, VisibilityField, Sequence[VisibilityField], Impostors],
    method: Union[str, Camera] = "hybrid",
    *,
    scene: Optional[Scene] = None,
    offset: Optional[DepthImages] = None,
    interpolate: str = "none",
    subsample: int = 1,
    triangle_budget: Optional[int] = 0,
    screen_threshold: float = 0.0,
) -> Union[Mesh, FieldView, ImpostorView]:
    """Rebuild surfaces from depth-image samples (non-redundant-rendering.txt §4), or a view
    from the visibility field (visibility-field.txt §4).

    ``reconstruct(field, camera, interpolate="none", subsample=1)`` with a
    :class:`VisibilityField` (or a list of them, one per slab, from one ``discretize`` call)
    renders ``camera``'s view from the field (Fig. 4): one pixel in every ``subsample x
    subsample`` block (the block's middle pixel) gives a line; where it crosses the slab's uv
    and st rectangles gives (u, v, s, t); the cells stored at that sample are marked
    (``interpolate="uv"``: also the 2 x 2 samples around (u, v); ``"st"``: around (s, t);
    ``"uv+st"``: the 16 around both, §4.1). A pixel whose line misses either rectangle, runs
    parallel to a plane, or crosses st before uv marks nothing. Then only the marked cells'
    triangles are rasterized on the GPU (faces are kept sorted by cell: one draw per run of
    marked cells). Returns a :class:`FieldView` (``marked`` (C,) bool, ``image`` a
    :class:`DepthImages`, ``stats``, ``timings`` ``resample`` and ``render``).

    ``reconstruct(impostors, camera, triangle_budget=0, scene=None, screen_threshold=0)`` with
    :class:`Impostors` draws ``camera``'s view (multi-cell-orthographic-impostors.txt §3.2):
    cells whose sphere (and triangles) lie outside the view are culled; the rest, nearest
    first, are drawn as triangles (GPU, lit like the impostors) while their triangles fit in
    ``triangle_budget`` (``None``: no limit; needs ``scene``) and their sphere spans at least
    ``screen_threshold`` pixels; every other cell as the impostor whose direction makes the
    smallest angle with the direction from the cell to the eye, a billboard through the cell's
    centre, depth-tested, with no per-pixel correction. Returns an :class:`ImpostorView`.

    Parameters
    ----------
    images : DepthImages
        Any discretization (conventional, non-redundant, peeling, or loaded from EXR).
    method : {"hybrid", "mesh", "points"}
        ``"mesh"``: the conventional depth-image mesh. Neighbouring samples are connected when
        they hold the same triangle or each lies within one pixel footprint (the pixel's size at
        the sample's depth, ``Camera.pixel_footprint``) of the other's tangent plane; a 2x2
        block gives two triangles when its four samples connect around it, one when three do;
        isolated samples are dropped.

        ``"hybrid"`` (Algorithm 4): every sample becomes a quad over its pixel. Each corner is
        the offset image's sample at that corner when it belongs to the same surface (same test
        as above), shared by all quads that take it, so a continuous surface is tiled without
        cracks or overlap; otherwise the corner ray's intersection with the sample's tangent
        plane. No corner lies farther than 8 footprints from its sample: beyond that (grazing
        planes), or without a normal, the corner is taken on the plane facing the camera at the
        sample's depth. Every vertex is finite.

        ``"points"``: one square per sample in its tangent plane with the area of the pixel's
        footprint on that plane (side at most 8 footprints).
    scene : Scene, optional
        For ``hybrid``: the scene to render the offset images from; by default the scene the
        images were discretized from (required for images loaded from EXR).
    offset : DepthImages, optional
        For ``hybrid``: precomputed offset images, made by the same method from
        ``[c.corner_camera() for c in images.cameras]``.

    Returns
    -------
    Mesh
        ``vertices`` (V, 3) float32, ``faces`` (F, 3) uint32 (counter-clockwise as seen from
        the sample's camera), ``sample`` (F,) int64 flat index (image * H * W + row * W +
        column) of the sample each face came from, ``timings`` (``offset`` for rendering H,
        then the method's own step).
    """
    if isinstance(images, Impostors):
        if not isinstance(method, Camera):
            raise InputError("reconstruct(impostors, camera): the second argument must be a Camera")
        return impostor_view(
            images,
            method,
            triangle_budget=triangle_budget,
            scene=scene,
            screen_threshold=screen_threshold,
        )
    fields = images if isinstance(images, (list, tuple)) else [images]
    if fields and all(isinstance(f, VisibilityField) for f in fields):
        if not isinstance(method, Camera):
            raise InputError("reconstruct(field, camera): the second argument must be a Camera")
        if scene is not None or offset is not None:
            raise InputError("scene and offset apply to depth images, not a visibility field")
        return field_view(fields, method, interpolate=interpolate, subsample=subsample)
    if not isinstance(images, DepthImages):
        raise InputError(
            f"images must be a DepthImages or a VisibilityField, got {type(images).__name__}"
        )
    if interpolate != "none" or subsample != 1:
        raise InputError("interpolate and subsample apply to a visibility field")
    if method not in RECONSTRUCT_METHODS:
        raise InputError(f"method must be one of {list(RECONSTRUCT_METHODS)}, got {method!r}")
    timings: dict[str, float] = {}
    if method == "hybrid" and offset is None:
        offset = offset_images(images, scene)
        timings["offset"] = offset.timings.get("total", 0.0)
    elif method != "hybrid" and (offset is not None or scene is not None):
        raise InputError(f"scene and offset apply to method='hybrid', not {method!r}")
    if offset is not None and not isinstance(offset, DepthImages):
        raise InputError(f"offset must be a DepthImages, got {type(offset).__name__}")
    d = _core.reconstruct(images, method, offset)
    timings.update(d.pop("timings"))
    return Mesh(**d, timings=timings, method=method)


def offset_images(images: DepthImages, scene: Optional[Scene] = None) -> DepthImages:
    """The offset images H of hybrid reconstruction: the same discretization as ``images``
    from each camera's ``corner_camera()`` (half a pixel off in both directions, one pixel
    larger), rendered from ``scene`` (by default the scene ``images`` came from)."""
    source = getattr(images, "_source", None)
    method, redundancy = images.method, "pixel"
    if source is not None:
        scene = source[0] if scene is None else scene
        redundancy = source[2]
    if scene is None:
        raise InputError(
            "hybrid reconstruction renders offset images from the scene: pass scene= (images "
            "loaded from a file do not remember theirs) or offset="
        )
    corners = [c.corner_camera() for c in images.cameras]
    cull = images.cull_backfaces
    if method == "peeling":
        return discretize(
            scene, corners[:1], "peeling", layers=images.n, camera=corners[0], cull_backfaces=cull
        )
    if method == "nonredundant":
        return discretize(scene, corners, method, redundancy=redundancy, cull_backfaces=cull)
    return discretize(scene, corners, "conventional", cull_backfaces=cull)


def device_info() -> dict[str, Any]:
    """The GPU adapter scenesample uses: ``name``, ``backend``, ``device_type``, ``driver``,
    ``timestamps`` (whether GPU timings are available) and the limits that bound requests.

    Raises :class:`GpuUnavailableError` when there is none."""
    return _core.device_info()
