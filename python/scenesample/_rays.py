"""CPU ray queries on a scene's cached BVH: closest hit and the k nearest hits
(:func:`cast_rays`), any hit (:func:`occluded`), and what the BVH holds (:func:`bvh_stats`)."""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from . import _core
from ._progress import Bar, Progress
from ._scene import Scene, core_of
from .errors import check_integer
from .results import RayHits

__all__ = ["cast_rays", "occluded", "bvh_stats"]


def _rows(a: Any) -> np.ndarray:
    a = np.asarray(a)
    return a[None] if a.ndim == 1 and a.shape[:1] == (3,) else a


def _threads(threads: Optional[int]) -> Optional[int]:
    return None if threads is None else check_integer("threads", threads)


def cast_rays(
    scene: Scene,
    origins: Any,
    directions: Any,
    *,
    t_min: float = 0.0,
    t_max: float = float("inf"),
    max_hits: int = 1,
    threads: Optional[int] = None,
    progress: Progress = None,
) -> RayHits:
    """Closest hit of each ray, or its ``max_hits`` nearest hits, on the CPU.

    The scene's BVH (8-wide, built on first use and cached with the scene) is traversed ray by
    ray with AVX2 where the CPU has it; the GIL is released, and float32 C-contiguous inputs are
    read in place, without a copy. The triangle test is watertight (Woop, Benthin and Wald
    2013): a ray through a shared edge or vertex of a closed mesh never slips through. Both
    faces of a triangle count. Each reported hit's ``t`` and barycentrics are recomputed in
    float64 from the given direction.

    Parameters
    ----------
    scene : Scene
    origins : (N, 3) array_like of float
    directions : (N, 3) array_like of float
        Finite and non-zero; need not be unit length.
    t_min, t_max : float
        Accept hits with ``t_min <= t < t_max``, in units of each direction's length.
    max_hits : int
        With 1, the closest hit. With k > 1, the first k hits along each ray, nearest first:
        the ray-cast counterpart of k depth-peeling layers. Two hits whose ``t`` agree within
        a relative 1e-5 (coincident or duplicated triangles) count once, as the triangle with
        the smaller ``t``, then the smaller index.
    threads : int, optional
        None: every core. 1: the calling thread only. k: a pool of k threads (made once).
    progress : bool, callable or None
        A tqdm bar over the rays (see :func:`scenesample.methods.visibility_field`): None
        (default) once the call has run for 2 s, True at once, False never; a callable
        ``f(done, total)`` hears the counts instead. Ctrl-C stops the call within a fraction
        of a second.

    Returns
    -------
    RayHits
        For ``max_hits=1``: ``t`` (N,) float32 (+inf on a miss), ``triangle`` (N,) int32 (-1),
        ``barycentric`` (N, 2) float32. For k > 1: ``t`` (N, k) padded with +inf,
        ``triangle`` (N, k) padded with -1, ``barycentric`` (N, k, 2). ``timings``:
        ``bvh_build`` (0 when the BVH was cached) and ``trace`` seconds.

    Raises
    ------
    InputError
        Mismatched or non-finite rays, zero directions, a bad range, ``max_hits`` or
        ``threads`` below 1 or not an integer.
    """
    k = check_integer("max_hits", max_hits)
    with Bar(progress, "rays", "rays") as bar:
        r = _core.cast_rays(
            core_of(scene),
            _rows(origins),
            _rows(directions),
            float(t_min),
            float(t_max),
            k,
            _threads(threads),
            bar.callback,
        )
    return RayHits(**r)


def occluded(
    scene: Scene,
    origins: Any,
    directions: Any,
    *,
    t_min: float = 0.0,
    t_max: float = float("inf"),
    threads: Optional[int] = None,
    progress: Progress = None,
) -> np.ndarray:
    """Whether anything lies on each ray within ``t_min <= t < t_max`` (an any-hit query).

    The traversal stops at the first hit it meets, so this is faster than :func:`cast_rays` on
    the same rays; use it for shadow and visibility rays. Same BVH, watertight test, threads
    and input rules as :func:`cast_rays`.

    Parameters
    ----------
    scene : Scene
    origins, directions : (N, 3) array_like of float
    t_min, t_max : float
        In units of each direction's length: with ``directions = targets - origins`` and
        ``t_max = 1``, only what lies between each origin and its target counts.
    threads : int, optional
        None: every core; 1: the calling thread only; k: a pool of k threads.
    progress : bool, callable or None
        As for :func:`cast_rays`.

    Returns
    -------
    (N,) bool
        True where the ray hits a triangle in range.
    """
    with Bar(progress, "occlusion rays", "rays") as bar:
        r = _core.occluded(
            core_of(scene),
            _rows(origins),
            _rows(directions),
            float(t_min),
            float(t_max),
            _threads(threads),
            bar.callback,
        )
    return r["hit"]


def bvh_stats(scene: Scene) -> dict[str, Any]:
    """What the scene's ray-casting BVH holds (building it if needed).

    Returns
    -------
    dict
        ``triangles``, ``nodes`` (8-wide), ``blocks`` (leaf blocks of 4 triangles), ``bytes``
        (everything the queries read besides the rays: nodes, blocks and triangle ids),
        ``depth``, ``sah`` (surface area heuristic cost relative to the root, Embree's measure)
        and ``build_seconds``.
    """
    return dict(_core.bvh_stats(core_of(scene)))
