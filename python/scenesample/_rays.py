"""CPU ray queries on a scene's cached BVH: closest hit and the k nearest hits
(:func:`cast_rays`), any hit (:func:`occluded`), and what the BVH holds (:func:`bvh_stats`)."""

from __future__ import annotations

import math
import re
from typing import Any, Callable, Optional

import numpy as np

from . import _core
from ._progress import Bar, Progress
from ._scene import Scene, core_of
from .errors import InputError, check_integer
from .results import AllHits, RayHits

__all__ = ["cast_rays", "occluded", "all_hits", "count_hits", "bvh_stats", "ray_kernel"]


def _rays(origins: Any, directions: Any) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """Origins and directions of shape (..., 3), broadcast against each other (numpy's rules),
    as (N, 3) rows in C order, and the batch shape ``...``. Rows already of the full shape and
    C-contiguous stay views (float32 ones are then read in place)."""
    o, d = np.asarray(origins), np.asarray(directions)
    for name, a in (("origins", o), ("directions", d)):
        if a.ndim == 0 or a.shape[-1] != 3:
            raise InputError(f"{name} must have shape (..., 3), got {a.shape}")
    try:
        shape = np.broadcast_shapes(o.shape[:-1], d.shape[:-1])
    except ValueError:
        raise InputError(
            f"origins of shape {o.shape} and directions of shape {d.shape} do not broadcast"
        ) from None
    n = math.prod(shape)
    return (*(np.broadcast_to(a, (*shape, 3)).reshape(n, 3) for a in (o, d)), shape)


def _indexed(
    shape: tuple[int, ...],
    call: Callable[[], Any],
    names: tuple[str, ...] = ("origins", "directions"),
) -> Any:
    """``call()``, with a bad row's flat number in an InputError about one of ``names`` turned
    into its index in the batch (``origins[2, 17]`` for a (H, W, 3) array)."""
    try:
        return call()
    except InputError as e:
        if len(shape) == 1:
            raise

        def where(m: re.Match) -> str:
            at = np.unravel_index(int(m.group(2)), shape) if shape else ()
            return f"{m.group(1)}[{', '.join(str(int(i)) for i in at)}]"

        pattern = rf"({'|'.join(map(re.escape, names))})\[(\d+)\]"
        raise InputError(re.sub(pattern, where, str(e))) from None


def _threads(threads: Optional[int]) -> Optional[int]:
    return None if threads is None else check_integer("threads", threads)


def _query(
    name: str,
    label: str,
    scene: Scene,
    origins: Any,
    directions: Any,
    t_min: float,
    t_max: float,
    threads: Optional[int],
    progress: Progress,
    *own: Any,
) -> tuple[dict[str, Any], tuple[int, ...]]:
    """The boundary every ray query shares, written once: the rays broadcast to rows, the
    core's query ``name`` (``_core.<name>(scene, origins, directions, t_min, t_max, *own,
    threads, progress)``) under a progress bar of ``label``, a bad row named by its index in
    the batch; the core's dict and the batch shape."""
    o, d, shape = _rays(origins, directions)
    call = getattr(_core, name)
    with Bar(progress, label, "rays") as bar:
        r = _indexed(
            shape,
            lambda: call(
                core_of(scene), o, d, float(t_min), float(t_max), *own, _threads(threads),
                bar.callback,
            ),
        )  # fmt: skip
    return r, shape


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

    The scene's BVH (8-wide, built on first use and cached with the scene) is traversed with
    AVX-512 or AVX2 where the CPU has it (:func:`ray_kernel`), eight neighbouring rays at a time
    where they share an octant and nearly a direction (camera rays in pixel order do), else ray
    by ray; the answers are the same either way, bit for bit. The GIL is released, and float32
    C-contiguous inputs are read in place, without a copy. The triangle test is watertight
    (Woop, Benthin and Wald 2013): a ray through a shared edge or vertex of a closed mesh never
    slips through.
    Both faces of a triangle count. Each reported hit's ``t`` and barycentrics are recomputed in
    float64 from the given direction.

    Parameters
    ----------
    scene : Scene
    origins : (..., 3) array_like of float
    directions : (..., 3) array_like of float
        Finite and non-zero; need not be unit length. The two broadcast against each other
        (one origin for many directions, say), and ``...`` is the batch shape they make:
        ``Camera.pixel_rays()``'s (H, W, 3) arrays go straight in.
    t_min, t_max : float
        Accept hits with ``t_min <= t < t_max``, in units of each direction's length.
    max_hits : int
        With 1, the closest hit. With k > 1, the first k hits along each ray, nearest first:
        the ray-cast counterpart of k depth-peeling layers. Hits whose ``t`` agree within a
        relative 1e-5 (coincident or duplicated triangles) count once: in order of ``t``, then
        index, a hit within 1e-5 of the hit that began the current surface joins it, and the
        surface is reported as that first hit (so the answer does not depend on the order the
        tree is searched in).
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
        For ``max_hits=1``: ``t`` (...) float32 (+inf on a miss), ``triangle`` (...) int32
        (-1), ``barycentric`` (..., 2) float32. For k > 1: ``t`` (..., k) padded with +inf,
        ``triangle`` (..., k) padded with -1, ``barycentric`` (..., k, 2); the rays x k hits
        must fit in the memory limit (``SCENESAMPLE_MEMORY_LIMIT``, else half the machine's
        memory), checked before anything is allocated. ``timings``: ``bvh_build`` (0 when
        the BVH was cached) and ``trace`` seconds.

    Raises
    ------
    InputError
        Shapes that are not (..., 3) or do not broadcast, non-finite rays (named by their
        index in the batch), zero directions, a bad range, ``max_hits`` or ``threads`` below
        1 or not an integer, rays x ``max_hits`` over the memory limit.
    """
    k = check_integer("max_hits", max_hits)
    r, shape = _query(
        "cast_rays", "rays", scene, origins, directions, t_min, t_max, threads, progress, k
    )
    hits = () if k == 1 else (k,)
    return RayHits(
        t=r["t"].reshape((*shape, *hits)),
        triangle=r["triangle"].reshape((*shape, *hits)),
        barycentric=r["barycentric"].reshape((*shape, *hits, 2)),
        timings=r["timings"],
        max_hits=k,
    )


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
    origins, directions : (..., 3) array_like of float
        Broadcast against each other, as for :func:`cast_rays`.
    t_min, t_max : float
        In units of each direction's length: with ``directions = targets - origins`` and
        ``t_max = 1``, only what lies between each origin and its target counts.
    threads : int, optional
        None: every core; 1: the calling thread only; k: a pool of k threads.
    progress : bool, callable or None
        As for :func:`cast_rays`.

    Returns
    -------
    (...) bool
        True where the ray hits a triangle in range.
    """
    r, shape = _query(
        "occluded", "occlusion rays", scene, origins, directions, t_min, t_max, threads, progress
    )
    return r["hit"].reshape(shape)


def all_hits(
    scene: Scene,
    origins: Any,
    directions: Any,
    *,
    t_min: float = 0.0,
    t_max: float = float("inf"),
    threads: Optional[int] = None,
    progress: Progress = None,
) -> AllHits:
    """Every hit along each ray, nearest first, with no ``max_hits`` to guess: a ragged list in
    Open3D's layout (``RaycastingScene.list_intersections``), whose memory is that of the hits
    found.

    Same BVH, watertight test, ``t`` units, barycentrics and input rules as
    :func:`cast_rays`. Hits whose ``t`` agree within a relative 1e-5 (coincident or
    duplicated triangles) count once, as with ``max_hits``, so ray ``i``'s hits are exactly
    ``cast_rays(..., max_hits=k)``'s for any ``k`` at least its count.

    Parameters
    ----------
    scene : Scene
    origins, directions : (..., 3) array_like of float
        Broadcast against each other; rays are numbered in C order over the batch.
    t_min, t_max : float
    threads : int, optional
    progress : bool, callable or None

    Returns
    -------
    AllHits
        ``ray_splits`` (N + 1,) int64, ``t`` (H,) float32, ``triangle`` (H,) int32,
        ``barycentric`` (H, 2) float32, ``ray_ids`` and ``count`` (per ray, batch shape).
    """
    r, shape = _query(
        "all_hits", "rays", scene, origins, directions, t_min, t_max, threads, progress
    )
    return AllHits(
        ray_splits=r["ray_splits"],
        t=r["t"],
        triangle=r["triangle"],
        barycentric=r["barycentric"],
        shape=tuple(shape),
        timings=r["timings"],
    )


def count_hits(
    scene: Scene,
    origins: Any,
    directions: Any,
    *,
    t_min: float = 0.0,
    t_max: float = float("inf"),
    threads: Optional[int] = None,
    progress: Progress = None,
) -> np.ndarray:
    """How many distinct surfaces each ray crosses in ``t_min <= t < t_max``
    (``RaycastingScene.count_intersections``; coincident hits count once, as in
    :func:`all_hits`).

    The same traversal and rule as :func:`all_hits` (so ``count_hits(...)`` equals
    ``all_hits(...).count``), keeping only the count: no memory for the hits.

    Returns
    -------
    (...) int64
        In the rays' batch shape.
    """
    r, shape = _query(
        "count_hits", "rays", scene, origins, directions, t_min, t_max, threads, progress
    )
    return r["count"].reshape(shape)


def bvh_stats(scene: Scene) -> dict[str, Any]:
    """What the scene's ray-casting BVH holds (building it if needed).

    Returns
    -------
    dict
        ``triangles``, ``nodes`` (8-wide), ``blocks`` (leaf blocks of 4 triangles), ``bytes``
        (everything the queries read besides the rays: nodes, blocks and triangle ids),
        ``depth``, ``instances``, ``sah`` (surface area heuristic cost relative to the root,
        Embree's measure), ``build_seconds`` and ``winding_bytes`` (the per-node records of
        :func:`scenesample.winding_number`, 0 until it first runs on the scene).

        A rigidly posed scene of two or more objects (:meth:`Scene.posed`, a clip's rigid
        nodes) is traced on a two-level tree: each object's own tree, built once with the
        scene as loaded and shared by its poses, under a top tree over the objects'
        ``instances`` built for the pose (``build_seconds`` is then that top tree's, ``sah``
        its cost, and ``bytes`` counts the objects' trees too). Other scenes have a flat tree
        and ``instances`` 0.
    """
    return dict(_core.bvh_stats(core_of(scene)))


def ray_kernel(use: Optional[str] = None) -> str:
    """The instruction set that CPU ray queries run on: ``"avx512"``, ``"avx2"`` or
    ``"portable"`` (point queries use AVX2 at most).

    Every query gives bit-identical answers on every kernel (the same ``t``, triangle ids and
    barycentrics), so the kernel changes only speed. The widest kernel the CPU has is chosen at
    run time; ``use="avx2"`` or ``use="portable"`` allows none wider for the whole process (so
    that one machine can check each narrower kernel against the code it would otherwise run),
    and ``use="best"`` goes back to the widest. A kernel the CPU lacks is never used: asking
    for ``"avx512"`` on a CPU without it gives the next one down. Queries already running keep
    their kernel.

    Parameters
    ----------
    use : {"best", "avx512", "avx2", "portable"}, optional
        The widest kernel allowed from now on; ``None`` (the default) only reports the kernel.

    Returns
    -------
    str
        The kernel the next query runs on.

    Raises
    ------
    InputError
        ``use`` is not one of the names above.
    """
    return str(_core.ray_kernel(use))
