"""Point queries on a scene's BVH (the ray-casting tree, shared): the closest surface point,
the generalized winding number, and from them the signed distance and occupancy
(:func:`closest_points`, :func:`winding_number`, :func:`signed_distance`, :func:`occupancy`)."""

from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np

from . import _core
from ._progress import Bar, Progress
from ._rays import _indexed, _threads
from ._scene import Scene, core_of
from .errors import InputError
from .results import ClosestPoints

__all__ = ["closest_points", "winding_number", "signed_distance", "occupancy"]


def _points(points: Any) -> tuple[np.ndarray, tuple[int, ...]]:
    """Points of shape (..., 3) as (N, 3) rows in C order (a view where they already are), and
    the batch shape ``...``."""
    p = np.asarray(points)
    if p.ndim == 0 or p.shape[-1] != 3:
        raise InputError(f"points must have shape (..., 3), got {p.shape}")
    shape = p.shape[:-1]
    return p.reshape(math.prod(shape), 3), shape


def closest_points(
    scene: Scene,
    points: Any,
    *,
    max_distance: float = float("inf"),
    threads: Optional[int] = None,
    progress: Progress = None,
) -> ClosestPoints:
    """The closest point of the scene's surface to each point, on the CPU.

    The scene's ray-casting BVH (built once, cached with the scene) is descended best-first,
    the eight child boxes of a node measured at once; the triangles of the leaves it reaches
    are measured exactly, in float64 (closest point by Voronoi region), so distances agree
    with a float64 brute force. Where several triangles are equally close (a point nearest a
    shared edge or vertex), the one with the smaller index is reported.

    Parameters
    ----------
    scene : Scene
    points : (..., 3) array_like of float
        Finite; float32 C-contiguous arrays are read in place.
    max_distance : float
        Farther surfaces are not reported (``triangle`` -1, ``distance`` +inf); a finite bound
        makes far points cheap.
    threads : int, optional
        None: every core. 1: the calling thread only. k: a pool of k threads.
    progress : bool, callable or None
        As for :func:`scenesample.cast_rays`, counting points.

    Returns
    -------
    ClosestPoints
        ``point`` (..., 3) float32, ``distance`` (...) float32, ``triangle`` (...) int32,
        ``barycentric`` (..., 2) float32, ``timings``.

    Raises
    ------
    InputError
        Points not of shape (..., 3) or not finite (named by their index), a negative or NaN
        ``max_distance``, bad ``threads``.
    """
    p, shape = _points(points)
    with Bar(progress, "closest points", "points") as bar:
        r = _indexed(
            shape,
            lambda: _core.closest_points(
                core_of(scene), p, float(max_distance), _threads(threads), bar.callback
            ),
            ("points",),
        )
    return ClosestPoints(
        point=r["point"].reshape((*shape, 3)),
        distance=r["distance"].reshape(shape),
        triangle=r["triangle"].reshape(shape),
        barycentric=r["barycentric"].reshape((*shape, 2)),
        timings=r["timings"],
    )


def winding_number(
    scene: Scene,
    points: Any,
    *,
    threads: Optional[int] = None,
    progress: Progress = None,
) -> np.ndarray:
    """The generalized winding number of the scene's surface at each point (Jacobson et al.
    2013): the signed solid angle of every triangle seen from the point, over 4 pi.

    Inside a closed mesh whose faces wind counter-clockwise seen from outside it is 1 (2 where
    two such meshes overlap, -1 inside one wound the other way), outside 0; near the holes of
    an open mesh, or inside a soup of triangles, it varies smoothly between, which is what
    makes it a robust inside test where ray parity is not.

    Two ways, chosen per scene (the answer depends on the scene and the point alone):

    - A closed surface (vertices welded by position, every edge walked as often one way as the
      other: checked once and cached with the scene; an STL triangle soup counts) has an integer
      winding number off the surface, found exactly by one ray per point: the signed count of
      the triangles it crosses, from the point out of the scene's bounds the short way (0 for a
      point outside the bounds). A ray that meets an edge exactly, or whose point lies within
      2^-16 of the scene's largest coordinate from the plane of a triangle it meets (a point
      on or next to the surface), leaves that point to the sum below.
    - Otherwise, summed over the BVH: a node whose bounding sphere is more than 2 radii away
      adds its dipole term (the area-weighted normals of its triangles; a small record per node,
      made on first use and cached with the scene), nearer ones are opened, and triangles add
      their exact solid angle. The result is within a few hundredths of the exact sum.

    Returns
    -------
    (...) float64
    """
    p, shape = _points(points)
    with Bar(progress, "winding numbers", "points") as bar:
        w = _indexed(
            shape,
            lambda: _core.winding_numbers(core_of(scene), p, _threads(threads), bar.callback),
            ("points",),
        )
    return w.reshape(shape)


def occupancy(
    scene: Scene,
    points: Any,
    *,
    threads: Optional[int] = None,
    progress: Progress = None,
) -> np.ndarray:
    """1 where a point is inside the scene, 0 outside (``RaycastingScene.compute_occupancy``'s
    output): inside is a generalized winding number of at least 0.5 (:func:`winding_number`).

    On a closed mesh this is the inside of the surface, as ray parity decides it (by one ray
    per point: see :func:`winding_number`); on an open mesh (missing faces, cracks) a point
    counts as inside where more than half of the directions around it see the mesh's back
    faces: a hole narrower than the surface around it does not turn the inside out, as it does
    for ray parity. Faces must wind counter-clockwise seen from outside; a mesh wound the other
    way is inside out (its winding number is -1).

    Returns
    -------
    (...) float32
        1.0 or 0.0.
    """
    w = winding_number(scene, points, threads=threads, progress=progress)
    return (w >= 0.5).astype(np.float32)


def signed_distance(
    scene: Scene,
    points: Any,
    *,
    threads: Optional[int] = None,
    progress: Progress = None,
) -> np.ndarray:
    """The distance of each point to the scene's surface, negative inside
    (``RaycastingScene.compute_signed_distance``'s convention): :func:`closest_points`'
    distance, signed by :func:`occupancy` (generalized winding number >= 0.5 is inside, so the
    sign holds on open meshes as described there).

    Returns
    -------
    (...) float32
    """
    d = closest_points(scene, points, threads=threads, progress=progress).distance
    inside = winding_number(scene, points, threads=threads) >= 0.5
    return np.where(inside, -d, d).astype(np.float32)
