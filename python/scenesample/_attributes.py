"""What the surface looks like where rays, points or samples meet it: texture coordinates,
colour (the material's texture sampled there) and shading normal, in one call for any
:func:`~scenesample.cast_rays`, :func:`~scenesample.all_hits` or
:func:`~scenesample.closest_points` result."""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from . import _core
from ._scene import Scene, core_of
from .errors import InputError
from .results import SurfaceSamples

__all__ = ["surface_attributes"]


def surface_attributes(
    scene: Scene,
    hits: Any = None,
    *,
    triangle: Any = None,
    barycentric: Any = None,
    points: Any = None,
    footprint: Any = None,
) -> SurfaceSamples:
    """The surface's attributes where samples meet it, as images and viewers have them.

    Give either a result with ``triangle`` and ``barycentric`` fields (:class:`RayHits` from
    :func:`~scenesample.cast_rays`, any ``max_hits``; :class:`AllHits`;
    :class:`ClosestPoints`), or the arrays themselves: ``triangle`` with ``barycentric`` or
    with world ``points`` on those triangles.

    Parameters
    ----------
    scene : Scene
        The scene the samples were taken of.
    hits : RayHits, AllHits or ClosestPoints, optional
    triangle : (...) array_like of int, optional
        Triangle ids (-1: nothing there).
    barycentric : (..., 2) array_like of float, optional
        (u, v) on each triangle, point = (1-u-v)*v0 + u*v1 + v*v2 (the hits' convention);
        clamped into the triangle.
    points : (..., 3) array_like of float, optional
        World points, projected onto their triangle's plane (instead of ``barycentric``).
    footprint : float or (...) array_like of float, optional
        The side, in world units, of the square each sample stands for: the texture is
        filtered over it (trilinearly between mip levels, as for a pixel of an image). Default:
        none, the finest level filtered bilinearly, as a single ray sees it.

    Returns
    -------
    SurfaceSamples
        ``texcoord`` (..., 2), ``color`` (..., 3), ``shading_normal`` (..., 3) and ``normal``
        (..., 3), in the samples' shape; zero (texcoord NaN) where a sample sees nothing.
    """
    if hits is not None:
        if triangle is not None or barycentric is not None or points is not None:
            raise InputError("give hits, or triangle with barycentric or points, not both")
        try:
            triangle, barycentric = hits.triangle, hits.barycentric
        except AttributeError:
            raise InputError(
                "hits must have triangle and barycentric fields (RayHits, AllHits, "
                f"ClosestPoints), got {type(hits).__name__}"
            ) from None
    if triangle is None or (barycentric is None) == (points is None):
        raise InputError("give the triangle ids with their barycentric coordinates or points")
    tri = np.asarray(triangle)
    shape = tri.shape
    where, width = (barycentric, 2) if barycentric is not None else (points, 3)
    at = np.asarray(where, dtype=np.float32)
    if at.shape != (*shape, width):
        name = "barycentric" if width == 2 else "points"
        raise InputError(f"{name} must have shape {(*shape, width)}, got {at.shape}")
    size: Optional[np.ndarray] = None
    if footprint is not None:
        try:
            size = np.broadcast_to(np.asarray(footprint, dtype=np.float32), shape)
        except ValueError:
            raise InputError(
                f"footprint of shape {np.shape(footprint)} does not broadcast to {shape}"
            ) from None
        size = np.ascontiguousarray(size).reshape(-1)
    rows = np.ascontiguousarray(at).reshape(-1, width)
    d = _core.surface_attributes(
        core_of(scene),
        np.ascontiguousarray(tri).reshape(-1),
        rows if width == 2 else None,
        rows if width == 3 else None,
        size,
    )
    return SurfaceSamples(
        texcoord=d["texcoord"].reshape(*shape, 2),
        color=d["color"].reshape(*shape, 3),
        shading_normal=d["shading_normal"].reshape(*shape, 3),
        normal=d["normal"].reshape(*shape, 3),
    )
