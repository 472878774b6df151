"""The depth-image methods of non-redundant-rendering.txt: sampling a scene with conventional,
non-redundant (§3, Algorithms 1-3) and depth-peeled (§6.1.3) images, and rebuilding surfaces
from them (§4, Algorithm 4). Public through :mod:`scenesample.methods` and the verbs."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal, Optional, Union

import numpy as np

from .. import _core
from .._conventional import _images, camera_list, conventional
from .._scene import Scene, core_of
from ..errors import InputError
from ..results import DepthImages, Mesh

Camera = _core.Camera


def nonredundant(
    scene: Scene,
    cameras: Union[Camera, Sequence[Camera]],
    *,
    redundancy: Literal["pixel", "visibility"] = "pixel",
    cull_backfaces: bool = False,
    backend: Literal["auto", "gpu", "cpu"] = "auto",
) -> DepthImages:
    """Non-redundant images (non-redundant-rendering.txt §3, Algorithm 1): one image per
    camera, rendered in order; image i keeps at each pixel the nearest sample that is not
    redundant with images 0..i-1, so a redundant sample never hides a new one behind it.
    Image 0 is conventional: bit for bit the image 0 of :func:`conventional` with the same
    cameras and ``backend``.

    Parameters
    ----------
    scene : Scene
    cameras : Camera or sequence of Camera
        In rendering order; resolutions must match.
    redundancy : {"pixel", "visibility"}
        ``"pixel"`` (Algorithm 3, on the GPU in the same pass): a sample is redundant when an
        earlier image holds its triangle at the pixel it reprojects to. ``"visibility"``
        (Algorithm 2, exact, on the CPU): a sample is redundant when an earlier image's
        viewpoint sees it (inside that image's view volume, unoccluded). Each pixel ray of
        image i is walked front to back through the surfaces it crosses with BVH ray casts,
        each candidate tested with one visibility ray per earlier viewpoint; the first
        candidate no earlier viewpoint sees is kept. Surfaces within ``1e-5`` of the scene
        diagonal (plus ``1e-5`` of the distance) count as the same point.
    cull_backfaces : bool
        Drop triangles whose counter-clockwise front faces away (off by default).
    backend : {"auto", "gpu", "cpu"}
        Where image 0 is made, as for :func:`conventional` (``"auto"``: the backend
        ``conventional(scene, cameras)`` picks). The later images are rendered on the GPU
        (pixel redundancy, testing against an image 0 traced on the CPU as against their own)
        or traced on the CPU (visibility redundancy).

    Returns
    -------
    DepthImages
        As :func:`conventional`, ``method="nonredundant"``; ``backend`` is image 0's, and
        ``backend_reason`` says where each image was made.
    """
    if redundancy not in ("pixel", "visibility"):
        raise InputError(f"redundancy must be 'pixel' or 'visibility', got {redundancy!r}")
    cams, cull = camera_list(cameras), bool(cull_backfaces)
    d = _core.discretize_nonredundant(core_of(scene), cams, redundancy, cull, backend)
    return _images(d, scene, cams, cull, "nonredundant", redundancy)


def peeling(
    scene: Scene,
    cameras: Union[Camera, Sequence[Camera]],
    *,
    layers: int,
    camera: Optional[Camera] = None,
    cull_backfaces: bool = False,
    backend: Literal["auto", "gpu", "cpu"] = "auto",
) -> DepthImages:
    """Depth peeling (non-redundant-rendering.txt §6.1.3): ``layers`` layers from one
    viewpoint; layer i keeps the nearest sample strictly beyond layer i-1's depth at each pixel.

    Ties: a surface whose depth at the pixel centre is within a relative 1e-5 of layer i-1's (a
    duplicated or coplanar face) is that layer met again, not a new one, so depths strictly
    increase along each pixel, as the distinct hits of ``cast_rays(max_hits=k)`` do; the freed
    last layers of such a pixel are empty.

    Parameters
    ----------
    scene : Scene
    cameras : Camera or sequence of Camera
        The reference views; the viewpoint defaults to their centroid with their mean
        orientation, as in §6.1.3.
    layers : int
        Number of layers, >= 1 (required).
    camera : Camera, optional
        The viewpoint (its resolution must match ``cameras``).
    cull_backfaces : bool
        Drop triangles whose counter-clockwise front faces away (off by default).
    backend : {"auto", "gpu", "cpu"}
        ``"gpu"``: one raster pass per layer. ``"cpu"``: each pixel-centre ray gathers its
        ``layers`` nearest distinct surfaces in one BVH traversal (the query of
        ``cast_rays(max_hits=layers)``, with back faces passed through when culling), resolved
        and tie-merged by the same float64 code; layers differ from the GPU's only where a
        pixel centre lies on an edge (and behind such a pixel). ``"auto"`` (default): the one
        the cost model of :func:`conventional` predicts is faster for ``layers`` images.

    Returns
    -------
    DepthImages
        As :func:`conventional`, with n = ``layers``, ``method="peeling"``; ``reference`` is
        ``cameras``; ``backend`` and ``backend_reason`` say which backend ran and why.
    """
    cams, cull = camera_list(cameras), bool(cull_backfaces)
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
    d = _core.discretize_peeling(core_of(scene), camera, int(layers), cull, backend)
    return _images(d, scene, cams, cull, "peeling", "pixel")


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
    if method == "nonredundant":
        return nonredundant(scene, corners, redundancy=redundancy, cull_backfaces=cull)
    # The backend the images came from: the two sets must meet at the same edges.
    backend = images.backend if images.backend in ("gpu", "cpu") else "auto"
    if method == "peeling":
        return peeling(
            scene,
            corners[:1],
            layers=images.n,
            camera=corners[0],
            cull_backfaces=cull,
            backend=backend,
        )
    return conventional(scene, corners, cull_backfaces=cull, backend=backend)


def _check_images(images: Any) -> None:
    if not isinstance(images, DepthImages):
        raise InputError(
            f"images must be a DepthImages or a VisibilityField, got {type(images).__name__}"
        )


def _rebuild(
    images: DepthImages, method: str, offset: Optional[DepthImages], timings: dict[str, float]
) -> Mesh:
    d = _core.reconstruct(images, method, offset)
    timings.update(d.pop("timings"))
    return Mesh(**d, timings=timings, method=method)


def mesh(images: DepthImages) -> Mesh:
    """The conventional depth-image mesh (non-redundant-rendering.txt §4). Neighbouring samples
    are connected when they hold the same triangle or each lies within one pixel footprint (the
    pixel's size at the sample's depth, ``Camera.pixel_footprint``) of the other's tangent
    plane; a 2x2 block gives two triangles when its four samples connect around it, one when
    three do; isolated samples are dropped.

    Returns
    -------
    Mesh
        ``vertices`` (V, 3) float32, ``faces`` (F, 3) uint32 (counter-clockwise as seen from
        the sample's camera), ``sample`` (F,) int64 flat index (image * H * W + row * W +
        column) of the sample each face came from, ``timings``.
    """
    _check_images(images)
    return _rebuild(images, "mesh", None, {})


def points(images: DepthImages) -> Mesh:
    """One square per sample in its tangent plane with the area of the pixel's footprint on
    that plane (side at most 8 footprints). Returns a :class:`Mesh` as :func:`mesh` does."""
    _check_images(images)
    return _rebuild(images, "points", None, {})


def hybrid(
    images: DepthImages, *, scene: Optional[Scene] = None, offset: Optional[DepthImages] = None
) -> Mesh:
    """Hybrid reconstruction (non-redundant-rendering.txt §4, Algorithm 4): every sample becomes
    a quad over its pixel. Each corner is the offset image's sample at that corner when it
    belongs to the same surface (the test of :func:`mesh`), shared by all quads that take it,
    so a continuous surface is tiled without cracks or overlap; otherwise the corner ray's
    intersection with the sample's tangent plane. No corner lies farther than 8 footprints from
    its sample: beyond that (grazing planes), or without a normal, the corner is taken on the
    plane facing the camera at the sample's depth. Every vertex is finite.

    Parameters
    ----------
    images : DepthImages
        Any discretization (conventional, non-redundant, peeling, or loaded from EXR).
    scene : Scene, optional
        The scene to render the offset images from; by default the scene the images were
        discretized from (required for images loaded from EXR).
    offset : DepthImages, optional
        Precomputed offset images, made by the same method from
        ``[c.corner_camera() for c in images.cameras]``.

    Returns
    -------
    Mesh
        As :func:`mesh`; ``timings`` has ``offset`` (rendering the offset images) first.
    """
    _check_images(images)
    timings: dict[str, float] = {}
    if offset is None:
        offset = offset_images(images, scene)
        timings["offset"] = offset.timings.get("total", 0.0)
    if not isinstance(offset, DepthImages):
        raise InputError(f"offset must be a DepthImages, got {type(offset).__name__}")
    return _rebuild(images, "hybrid", offset, timings)
