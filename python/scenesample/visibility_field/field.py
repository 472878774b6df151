"""The visibility field (visibility-field.txt §3): slabs, the precomputed two-plane visibility of
grid cells, and the Rust handle that holds it."""

from __future__ import annotations

import time
import warnings
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Optional, Union

import numpy as np

from .. import _core
from .._progress import Bar, Progress
from .._scene import Scene
from ..errors import InputError, SceneWarning

__all__ = [
    "Slab",
    "VisibilityField",
    "INTERPOLATIONS",
    "QUALITIES",
    "default_settings",
]

Camera = _core.Camera
INTERPOLATIONS = ("none", "uv", "st", "uv+st")
CELL_DTYPE = np.dtype([("object", "<i4"), ("x", "<i4"), ("y", "<i4"), ("z", "<i4")])


def _vec(x: Any, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise InputError(f"{name} must be 3 finite numbers, got {x!r}")
    return a


@dataclass(frozen=True, eq=False)
class Slab:
    """Two rectangles parameterizing lines (§3): a line crosses ``uv`` at rectangle
    coordinates (u, v) and ``st`` at (s, t), all in [0, 1). Each rectangle is ``(origin, u,
    v)``: the points ``origin + a u + b v`` for a, b in [0, 1]. The field stores lines running
    from the uv plane toward the st plane; a camera uses it where its pixel rays cross uv first
    (typically: on the uv side of the slab, looking toward st)."""

    uv: tuple[np.ndarray, np.ndarray, np.ndarray]
    st: tuple[np.ndarray, np.ndarray, np.ndarray]

    def __post_init__(self) -> None:
        for name in ("uv", "st"):
            rect = getattr(self, name)
            try:
                o, u, v = rect
            except (TypeError, ValueError):
                raise InputError(f"Slab.{name} must be (origin, u, v), got {rect!r}") from None
            vs = tuple(_vec(x, f"Slab.{name}[{k}]") for k, x in enumerate((o, u, v)))
            if np.linalg.norm(np.cross(vs[1], vs[2])) <= 1e-12 * np.linalg.norm(vs[1]) * (
                np.linalg.norm(vs[2])
            ) or not np.linalg.norm(vs[1]):
                raise InputError(f"Slab.{name}'s edges must be non-zero and not parallel")
            object.__setattr__(self, name, vs)

    @classmethod
    def around(
        cls, scene: Scene, axis: Optional[int] = None, margin: float = 0.05, widen: float = 0.25
    ) -> Slab:
        """The paper's single slab: planes perpendicular to ``axis`` (default: the bounds' longest
        axis), uv ``margin`` of the scene's extent along it before the bounds' low side, st as
        far beyond the high side, both covering the bounds' cross-section widened on every side
        by ``widen`` times the bounds' longest extent. Cameras on the low side looking along
        +axis use it."""
        if not isinstance(scene, Scene):
            raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
        a = _core.default_slab(scene._core, axis, float(margin), float(widen))
        return cls.from_array(a)

    @classmethod
    def six(cls, scene: Scene, margin: float = 0.05) -> list[Slab]:
        """The six slabs that answer every camera outside the scene's bounds (§6: several
        slabs cover viewpoints all around a scene): for each axis, one slab per direction,
        planes ``margin`` of the extent along it beyond the bounds on either side. A line
        makes at most 45 degrees with the axis nearest its direction, so the rectangles are
        widened on every side by the axis's extent plus both gaps: every line through the
        bounds is held by the slab of its dominant axis and direction."""
        if not isinstance(scene, Scene):
            raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
        return [cls.from_array(a) for a in _core.six_slabs(scene._core, float(margin))]

    @classmethod
    def from_array(cls, a: Any) -> Slab:
        """From a (2, 3, 3) array: uv then st, each (origin, u, v)."""
        a = np.asarray(a, dtype=np.float64)
        if a.shape != (2, 3, 3):
            raise InputError(f"a slab array must be (2, 3, 3), got {a.shape}")
        return cls(tuple(a[0]), tuple(a[1]))

    def as_array(self) -> np.ndarray:
        """(2, 3, 3) float64: uv then st, each (origin, u, v)."""
        return np.array([self.uv, self.st], dtype=np.float64)

    def __repr__(self) -> str:
        o = self.uv[0] + (self.uv[1] + self.uv[2]) / 2
        p = self.st[0] + (self.st[1] + self.st[2]) / 2
        return f"Slab(uv centre {np.round(o, 4).tolist()}, st centre {np.round(p, 4).tolist()})"


@dataclass(eq=False, repr=False)
class VisibilityField:
    """The cell ids first hit along the lines of one or more slabs (visibility-field.txt §3).

    The field is held on the Rust side (``_core.Field``); the arrays below are read-only numpy
    views of it, and a view (:func:`field_view`) sends it only the camera and the options. A
    pickle carries the scene, the slabs and the arrays byte for byte and rebuilds the
    cell-sorted scene where it is loaded, so the views there are the same bytes.

    Attributes
    ----------
    ids : (K, U, V, S, T, n) int32
        Per slab and line sample, the ``n`` cells hit most often by its rays, most frequent
        first (ties: lower id first); -1 where fewer cells were hit.
    cells_hit : (K, U, V, S, T) uint16
        How many distinct cells each sample's rays hit (at most 65535). More than ``n``: the
        sample overflowed, a line in its beam may see a cell it does not list, so a view
        traces it instead (``fallback``); see also ``overflow``.
    slabs : tuple of Slab
        The K slabs (default: :meth:`Slab.six`, both directions along each axis).
    cells : (C,) structured array (``object``, ``x``, ``y``, ``z``; int32)
        Per non-empty cell: its group (object, or connected component) and grid coordinates.
    cell_bounds : (C, 2, 3) float32
        Each cell's grid box (low, high corner).
    cell_triangles : tuple of ((C + 1,) uint32 offsets, (F,) uint32 triangle ids)
        CSR: cell c holds triangles ``indices[offsets[c]:offsets[c + 1]]``.
    cell_of : (F,) uint32
        Each triangle's cell.
    settings : dict
        What was used and why: ``quality``, ``uv``, ``st``, ``grid`` (cells per axis, or the
        cap when cells are sized), ``cell_size`` (None when ``grid`` was given), ``ids_per_
        sample``, ``supersample``, ``interpolate`` and ``trust`` (what :func:`field_view` uses
        by default), ``rule`` (a sentence: how the defaults were derived from the scene).
    stats : dict
        ``rays`` cast, ``memory_bytes`` (``ids`` and ``cells_hit``), ``compressed_bytes``
        (``ids`` after zlib/deflate level 6; §7.1 expects high coherence), ``cells`` (non-empty),
        ``groups``, ``samples`` (all slabs), ``overflowed`` (samples).
    timings : dict of str to float
        Seconds: ``cells`` (grouping, grid, cell-sorted copy of the scene), ``rays``, ``rank``,
        ``bvh`` (of the cell-sorted scene, for the fallback), ``compress``, ``total``.
    """

    ids: np.ndarray
    cells_hit: np.ndarray
    slabs: tuple
    cells: np.ndarray
    cell_bounds: np.ndarray
    cell_triangles: tuple[np.ndarray, np.ndarray]
    cell_of: np.ndarray
    settings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    _scene: Optional[Scene] = None
    _handle: Any = None

    @property
    def overflow(self) -> np.ndarray:
        """(K, U, V, S, T) bool: the samples whose rays hit more cells than they list."""
        return self.cells_hit > self.ids.shape[-1]

    def __repr__(self) -> str:
        k, u, v, s, t, n = self.ids.shape
        return (
            f"VisibilityField({k} slab{'s' if k > 1 else ''}, {u}x{v} uv, {s}x{t} st, {n} ids "
            f"per sample, {len(self.cells):,} cells)"
        )

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}

    def __reduce__(self) -> tuple[Any, tuple[dict[str, Any]]]:
        """Pickling (e.g. to the workers of a sweep): the scene, the slabs and the arrays travel
        byte for byte; the cell-sorted scene that views draw is rebuilt where the field lands,
        so a view there gives the same bytes as here."""
        h = self._handle
        state = {
            "scene": self._scene,
            "slabs": [s.as_array() for s in self.slabs],
            "arrays": tuple(getattr(h, name) for name, _ in _STATE_ARRAYS),
            "settings": self.settings,
            "stats": self.stats,
            "timings": self.timings,
        }
        return (_field_from_state, (state,))


#: What a pickled field's arrays hold, in the order ``__reduce__`` writes them.
_STATE_ARRAYS = (
    ("ids", np.int32),
    ("cells_hit", np.uint16),
    ("triangles", np.uint32),
    ("offsets", np.uint32),
    ("cells", np.int32),
    ("cell_bounds", np.float32),
    ("cell_of", np.uint32),
)


def _field_from_state(state: dict[str, Any]) -> VisibilityField:
    """A pickled field (:meth:`VisibilityField.__reduce__`): dtypes checked here, shapes and
    the face order by ``_core.Field.restore``."""
    if not isinstance(state.get("scene"), Scene):
        raise InputError("a pickled field must hold the scenesample.Scene it was built for")
    scene, slabs = state["scene"], [Slab.from_array(a) for a in state["slabs"]]
    arrays = state["arrays"]
    if not isinstance(arrays, tuple) or len(arrays) != len(_STATE_ARRAYS):
        raise InputError(f"a pickled field holds {len(_STATE_ARRAYS)} arrays")
    for a, (name, dtype) in zip(arrays, _STATE_ARRAYS):
        if not isinstance(a, np.ndarray) or a.dtype != dtype:
            got = a.dtype if isinstance(a, np.ndarray) else type(a).__name__
            raise InputError(f"a pickled field's {name} must be {np.dtype(dtype)}, got {got}")
    handle = _core.Field.restore(scene._core, [s.as_array().reshape(-1, 3) for s in slabs], *arrays)
    return _field_of(handle, scene, slabs, state["settings"], state["stats"], state["timings"])


def _field_of(
    handle: Any, scene: Scene, slabs: Sequence[Slab], settings: dict, stats: dict, timings: dict
) -> VisibilityField:
    """The field's Python face: read-only views of the handle's arrays."""
    # (C, 4) int32 read as (C,) records of four int32 fields: still a view of the handle's.
    cells = handle.cells.view(CELL_DTYPE)[:, 0]
    return VisibilityField(
        ids=handle.ids,
        cells_hit=handle.cells_hit,
        slabs=tuple(slabs),
        cells=cells,
        cell_bounds=handle.cell_bounds,
        cell_triangles=(handle.offsets, handle.triangles),
        cell_of=handle.cell_of,
        settings=settings,
        stats=stats,
        timings=timings,
        _scene=scene,
        _handle=handle,
    )


def _pair(x: Any, name: str) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in x)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be two positive integers, got {x!r}") from None
    if a < 1 or b < 1:
        raise InputError(f"{name} must be two positive integers, got {x!r}")
    return a, b


QUALITIES = ("fast", "balanced", "exact")

#: quality -> (samples per axis of each plane, rays per axis of a sample's plane cell, ids per
#: sample, interpolation, trust: the most cells a sample's rays may hit for it to answer a
#: line, None for its ids per sample); see :func:`default_settings`.
_QUALITY: dict[str, tuple] = {
    "fast": (16, 2, 8, "uv+st", None),
    "balanced": (20, 3, 12, "uv+st", 1),
    "exact": (24, 3, 16, "uv+st", 1),
}
#: Cells are about this many beam widths wide (see :func:`default_settings`).
_CELL_BEAMS = 0.33
#: At most this many cells along each axis of a group.
_MAX_CELLS = 16


def default_settings(scene: Scene, slabs: Sequence[Slab], quality: str = "balanced") -> dict:
    """The field's settings derived from the scene and its slabs.

    The rule. ``quality`` sets the samples per axis of each plane N, the rays per axis of a
    sample's plane cell r, the ids kept per sample n and the trust t (the most cells a
    sample's rays may hit for it to answer a line; the other lines are traced):

    ============  ====  ===  ====  ======================
    quality        N     r    n     t
    ============  ====  ===  ====  ======================
    ``fast``       16    2    8    n (no sample read overflowed)
    ``balanced``   20    3    12   1 (every sample read saw one cell)
    ``exact``      24    3    16   1
    ============  ====  ===  ====  ======================

    A sample's beam is then about ``w = L / N`` wide, L the mean side of the slabs'
    rectangles (about three times the scene's extent for :meth:`Slab.six`). Cells are made
    about ``w / 3`` wide along each axis of each group (at most 16 per axis): a beam crosses a
    few cells, so a sample rarely overflows its ids, and most samples inside an object see
    one cell. Views interpolate ``uv+st`` (§4.1: the 16 samples around a line).

    Costs: K N^4 r^4 rays (six slabs at ``balanced``: 78M rays, 8-17 s on 2 cores for
    2K-1M-triangle scenes) and K N^4 (4 n + 2) bytes (6 slabs at ``balanced``: 48 MB).
    """
    if quality not in _QUALITY:
        raise InputError(f"quality must be one of {list(QUALITIES)}, got {quality!r}")
    n, ss, ids, interp, trust = _QUALITY[quality]
    sides = [np.linalg.norm(r[k]) for s in slabs for r in (s.uv, s.st) for k in (1, 2)]
    beam = float(np.mean(sides)) / n
    return {
        "quality": quality,
        "uv": (n, n),
        "st": (n, n),
        "grid": (_MAX_CELLS,) * 3,
        "cell_size": _CELL_BEAMS * beam,
        "ids_per_sample": ids,
        "supersample": ss,
        "interpolate": interp,
        "trust": trust,
        "rule": (
            f"{quality}: {n}x{n} samples per plane, {ss}^4 rays and {ids} ids per sample; "
            f"cells ~{_CELL_BEAMS:g} beam wide ({_CELL_BEAMS * beam:.4g}, at most {_MAX_CELLS} "
            "per axis of each group); views interpolate uv+st"
        ),
    }


def _memory_limit() -> int:
    """scenesample's memory limit: ``SCENESAMPLE_MEMORY_LIMIT`` bytes, else half of this
    machine's physical memory (``src/limits.rs``)."""
    return _core.check_memory("nothing", 0, 0)


def _encloses(slab: Slab, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Whether every corner of the box [lo, hi] lies strictly between the slab's planes and,
    dropped perpendicularly onto each plane, inside its rectangle."""
    corners = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(3, -1).T
    side = []
    for o, u, v in (slab.uv, slab.st):
        n = np.cross(u, v)
        n /= np.linalg.norm(n)
        side.append((corners - o) @ n)
        p = corners - o - np.outer((corners - o) @ n, n)
        g = np.array([[u @ u, u @ v], [u @ v, v @ v]])
        ab = np.linalg.solve(g, np.stack([p @ u, p @ v]))
        if (ab < 0).any() or (ab > 1).any():
            return False
    a, b = side
    return bool(((a > 0) & (b < 0)).all() or ((a < 0) & (b > 0)).all())


def visibility_field(
    scene: Scene,
    *,
    slab: Union[None, Slab, Sequence[Slab]] = None,
    quality: str = "balanced",
    uv: Any = None,
    st: Any = None,
    grid: Any = None,
    ids_per_sample: Optional[int] = None,
    supersample: Optional[int] = None,
    jitter: bool = False,
    seed: int = 0,
    memory_limit: Optional[int] = None,
    progress: Progress = None,
) -> VisibilityField:
    """The visibility field (visibility-field.txt §3): for every sample (iu, iv, is, it) of
    each slab, ``supersample^4`` BVH rays from its uv cell to its st cell; the
    ``ids_per_sample`` cells hit most often are kept (§3.3), and whether more were hit.

    By default the field covers every camera outside the scene's bounds: six slabs
    (:meth:`Slab.six`, both directions along each axis, the paper's §6 remedy for viewpoints
    all around a scene), with resolutions derived from the scene (:func:`default_settings`).
    A view (:func:`field_view`) traces the pixels no slab answers, so nothing goes missing
    but cells smaller than a sample's beam.

    Parameters
    ----------
    scene : Scene
    slab : Slab or list of Slab, optional
        The two-plane parameterizations (default: :meth:`Slab.six`). One slab, e.g.
        :meth:`Slab.around`, covers a walkthrough on its uv side (the paper's single slab);
        views fall back to tracing elsewhere. A slab that does not enclose the scene's bounds
        warns (:class:`SceneWarning`).
    quality : {"fast", "balanced", "exact"}
        Where the derived defaults sit between precomputation (time, memory) and what views
        miss; see :func:`default_settings`. Explicit options below override it.
    uv, st : (int, int), optional
        Samples on each plane of every slab.
    grid : (int, int, int) or "scene", optional
        Cells along x, y, z of each object's bounding box (objects: the scene's meshes/nodes,
        or its connected components when it has one object); ``"scene"``: one 16^3 grid over
        the whole scene. A triangle belongs to the cell holding its centroid. Default: cells
        about a sample's beam wide (:func:`default_settings`).
    ids_per_sample : int, optional
        Cell ids kept per sample (the most frequent).
    supersample : int, optional
        Rays per axis of each plane's sample cell (3: 3 x 3 on each plane, 81 rays per sample,
        §3.3), at sub-cell centres (the paper's regular grid).
    jitter : bool
        Jitter each ray within its sub-cell instead (off by default).
    seed : int
        Seeds the jitter (any non-negative integer, 0 included); unused without ``jitter``.
    memory_limit : int, optional
        Bytes the field may take (ids, overflow flags, one uv sample's rays); default
        scenesample's memory limit (``SCENESAMPLE_MEMORY_LIMIT``, else half the machine's
        memory). A larger field raises :class:`InputError` before anything is
        allocated.
    progress : bool, callable or None
        A tqdm bar over the slab samples when tqdm is installed. None (default): only once the
        work has run for 2 s; True: at once; False: never; a callable ``f(done, total)``
        hears the counts instead, from the calling thread (a last time where the work ended
        or was interrupted). Ctrl-C stops the work within a fraction of a second
        (``KeyboardInterrupt``).

    Returns
    -------
    VisibilityField
        All slabs in one field (``ids`` is (K, U, V, S, T, n)).
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if scene.triangle_count == 0:
        raise InputError("the scene has no triangles")
    if slab is None:
        slabs = Slab.six(scene)
    elif isinstance(slab, Slab):
        slabs = [slab]
    elif isinstance(slab, (str, bytes)) or not isinstance(slab, Sequence):
        raise InputError(f"slab must be a Slab or a list of them, got {type(slab).__name__}")
    else:
        slabs = list(slab)
    for k, s in enumerate(slabs):
        if not isinstance(s, Slab):
            raise InputError(f"slab[{k}] must be a Slab, got {type(s).__name__}")
    if not slabs:
        raise InputError("slab must be a Slab or a non-empty list of them")
    settings = default_settings(scene, slabs, quality)
    if uv is not None:
        settings["uv"] = _pair(uv, "uv")
    if st is not None:
        settings["st"] = _pair(st, "st")
    if grid is not None:
        settings["cell_size"] = None
        if isinstance(grid, str):
            if grid != "scene":
                raise InputError(f"grid must be three positive integers or 'scene', got {grid!r}")
            settings["grid"] = "scene"
        else:
            try:
                dims = tuple(int(g) for g in grid)
            except (TypeError, ValueError):
                raise InputError(
                    f"grid must be three positive integers or 'scene', got {grid!r}"
                ) from None
            if len(dims) != 3 or min(dims) < 1:
                raise InputError(f"grid must be three positive integers or 'scene', got {grid!r}")
            settings["grid"] = dims
    for name, val in (("ids_per_sample", ids_per_sample), ("supersample", supersample)):
        if val is None:
            continue
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
            raise InputError(f"{name} must be a positive integer, got {val!r}")
        settings[name] = int(val)
    options = dict(uv=uv, st=st, grid=grid, ids_per_sample=ids_per_sample, supersample=supersample)
    given = [name for name, value in options.items() if value is not None]
    if given:
        settings["rule"] += f" (overridden: {', '.join(given)})"
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    if not isinstance(jitter, (bool, np.bool_)):
        raise InputError(f"jitter must be True or False, got {jitter!r}")
    _check_memory(settings, len(slabs), memory_limit)
    lo, hi = scene.bounds.astype(np.float64)
    for k, s in enumerate(slabs):
        if slab is not None and not _encloses(s, lo, hi):
            warnings.warn(
                f"slab {k} does not enclose the scene's bounds (between its planes and inside "
                "its rectangles): views trace the lines it cannot answer",
                SceneWarning,
                stacklevel=3,
            )
    return _sample(scene, slabs, settings, int(seed) if jitter else None, progress)


def _check_memory(settings: dict, k: int, limit: Optional[int]) -> None:
    """InputError before any allocation when the field needs more than ``limit`` bytes."""
    if limit is None:
        limit = _memory_limit()
    elif isinstance(limit, bool) or not isinstance(limit, (int, np.integer)) or limit < 1:
        raise InputError(f"memory_limit must be a positive number of bytes, got {limit!r}")
    u, v = settings["uv"]
    s, t = settings["st"]
    samples = k * u * v * s * t
    rays_per_uv = s * t * settings["supersample"] ** 4
    need = samples * (4 * settings["ids_per_sample"] + 2) + rays_per_uv * 40
    if need > limit:
        raise InputError(
            f"a field of {k} slab(s) x {u}x{v}x{s}x{t} samples x {settings['ids_per_sample']} "
            f"ids would take {need / 2**30:.2f} GiB, over the memory limit of "
            f"{limit / 2**30:.2f} GiB (memory_limit=; by default SCENESAMPLE_MEMORY_LIMIT, in "
            "bytes, or half this machine's memory): lower uv/st/ids_per_sample"
        )


def _sample(
    scene: Scene, slabs: list, settings: dict, seed: Optional[int], progress: Progress
) -> VisibilityField:
    start = time.perf_counter()
    grid = settings["grid"]
    grouping = "scene" if grid == "scene" else "objects"
    dims = (16, 16, 16) if grid == "scene" else grid
    with Bar(progress, "visibility field", "samples") as bar:
        handle, d = _core.visibility_field(
            scene._core,
            [s.as_array().reshape(-1, 3) for s in slabs],
            settings["uv"],
            settings["st"],
            dims,
            settings["cell_size"],
            grouping,
            settings["ids_per_sample"],
            settings["supersample"],
            seed,
            bar.callback,
        )
    t = time.perf_counter()
    ids, hits = handle.ids, handle.cells_hit
    packed = len(zlib.compress(np.ascontiguousarray(ids).tobytes(), 6))
    timings = {"cells": d["cell_seconds"], **dict(d["timings"]), "bvh": d["bvh_seconds"]}
    timings.pop("total", None)
    timings["compress"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - start
    stats = {
        "rays": int(d["rays"]),
        "memory_bytes": int(ids.nbytes + hits.nbytes),
        "compressed_bytes": packed,
        "cells": len(handle.cells),
        "groups": int(d["groups"]),
        "samples": int(np.prod(ids.shape[:5])),
        "overflowed": int((hits > ids.shape[-1]).sum()),
    }
    return _field_of(handle, scene, slabs, settings, stats, timings)
