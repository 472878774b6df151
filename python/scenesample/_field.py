"""The visibility field (visibility-field.txt): precomputed two-plane visibility of grid cells,
resampled per view to cull hidden geometry."""

from __future__ import annotations

import time
import warnings
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Optional, Union

import numpy as np

from . import _core
from ._depth import conventional
from ._progress import Bar, Progress
from ._rays import cast_rays
from ._scene import Scene
from .errors import InputError, SceneWarning
from .results import DepthImages

__all__ = [
    "Slab",
    "VisibilityField",
    "FieldView",
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
    _sorted: Any = None

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
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}


@dataclass(eq=False, repr=False)
class FieldView:
    """A view rendered from the visibility field (visibility-field.txt §4).

    Attributes
    ----------
    marked : (C,) bool
        Cells drawn: those the resampling marked, those the fallback's rays hit, and those
        found across the edges at the cells' borders (``stats["border_cells"]``).
    image : DepthImages
        One depth image drawn from only the marked cells' triangles, on the GPU or the CPU
        (``image.backend``; triangle ids are the scene's).
    camera : Camera
    covered : float
        The fraction of resampled pixels the field answered; the others were traced
        (``fallback``) or, with ``fallback=False``, marked nothing. With the fallback a line
        that sees nothing (misses the scene's bounds) counts as answered; without it, only
        lines some slab crosses the right way do.
    fallback_pixels : int
        Resampled pixels traced because no slab holds their line (outside every slab, or the
        camera inside the scene's bounds) or every sample holding it overflowed.
    fallback_cells : int
        Cells only the fallback marked.
    stats : dict
        ``cells_marked``, ``triangles_drawn``, ``pixels`` (resampled, after subsampling),
        ``pixels_outside`` (no slab holds their line), ``pixels_overflowed`` (only overflowed
        samples do), ``covered``, ``fallback_pixels``, ``fallback_cells``, ``border_cells``
        (cells found by looking across the edges at the borders between cells of the drawn
        view, then drawn too: a pixel the field answered may go, under the raster's snapping,
        to a triangle across an edge passing within a 32nd of a pixel of its centre).
    timings : dict of str to float
        Seconds: ``resample`` (the paper's K_rasterize+resample), ``fallback`` (tracing),
        ``render`` (the marked cells, the look along their borders, and the second draw when
        that found cells; ``image.timings["borders"]`` is the look), ``total``.
    """

    marked: np.ndarray
    image: DepthImages
    camera: Any
    covered: float = 1.0
    fallback_pixels: int = 0
    fallback_cells: int = 0
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    _field: Any = None
    _interpolate: str = "none"
    _subsample: int = 1
    _fallback: bool = True
    _trust: int = 1
    _backend: str = "gpu"

    def __repr__(self) -> str:
        return (
            f"FieldView({self.stats.get('cells_marked', 0):,} of {len(self.marked):,} cells, "
            f"{self.stats.get('triangles_drawn', 0):,} triangles, {100 * self.covered:.1f}% "
            "covered)"
        )

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}


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
        d = _core.visibility_field(
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
    cells = np.zeros(len(d["cells"]), dtype=CELL_DTYPE)
    for k, name in enumerate(CELL_DTYPE.names):
        cells[name] = d["cells"][:, k]
    t = time.perf_counter()
    ids, hits = d["ids"], d["cells_hit"]
    packed = len(zlib.compress(np.ascontiguousarray(ids).tobytes(), 6))
    timings = {"cells": d["cell_seconds"], **dict(d["timings"]), "bvh": d["bvh_seconds"]}
    timings.pop("total", None)
    timings["compress"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - start
    return VisibilityField(
        ids=ids,
        cells_hit=hits,
        slabs=tuple(slabs),
        cells=cells,
        cell_bounds=d["cell_bounds"],
        cell_triangles=(d["offsets"], d["triangles"]),
        cell_of=d["cell_of"],
        settings=settings,
        stats={
            "rays": int(d["rays"]),
            "memory_bytes": int(ids.nbytes + hits.nbytes),
            "compressed_bytes": packed,
            "cells": len(cells),
            "groups": int(d["groups"]),
            "samples": int(np.prod(ids.shape[:5])),
            "overflowed": int((hits > ids.shape[-1]).sum()),
        },
        timings=timings,
        _scene=scene,
        _sorted=d["sorted_scene"],
    )


def field_view(
    field_: VisibilityField,
    camera: Camera,
    *,
    interpolate: Optional[str] = None,
    subsample: int = 1,
    fallback: bool = True,
    trust: Optional[int] = None,
    backend: str = "gpu",
    resampler: str = "blocks",
) -> FieldView:
    """Render ``camera``'s view from a visibility field (visibility-field.txt §4, Fig. 4).

    One pixel in every ``subsample x subsample`` block (the block's middle pixel) gives a line.
    Each slab that holds the line answers it: the line crosses its uv rectangle, then its st
    rectangle, and everything the pixel can see (between the near and far planes, within the
    scene's bounds) lies between the two with nothing on the line between the uv plane and
    the near end. The cells stored at the sample holding (u, v, s, t) are marked
    (``interpolate="uv"``: also the 2 x 2 samples around (u, v); ``"st"``: around (s, t);
    ``"uv+st"``: the 16 around both, §4.1); several slabs' answers are merged (with
    ``fallback``, a pixel that earlier slabs answered is not read again). A slab answers only
    when every sample it reads for the line hit at most ``trust`` cells, and only its answers
    mark cells (with ``fallback``; without it every read marks). A pixel no slab
    answers is traced instead (``fallback``): its ray is cast through the scene and the cell
    it hits is marked (and, when it lies on a triangle's edge, the cells of four rays a 32nd
    of a pixel around it, as the raster may pick the neighbour). Then only the marked cells'
    triangles are drawn: rasterized on the GPU (faces are kept sorted by cell: one draw per
    run of marked cells), or traced on the CPU. With ``fallback``, the drawn view's pixels at
    the borders between cells that lie within a 32nd of a pixel of their triangle's edge then
    trace the same four rays, and the cells those find are drawn too (``border_cells``): the
    field answered those pixels without a ray, and the raster may give them to the triangle
    across the edge.

    The guarantee, with ``fallback`` and ``subsample=1``: every pixel's visible triangle is
    drawn unless its cell is smaller than a sample's beam and none of the sample's rays (nor,
    with interpolation, its neighbours') hit it. With ``subsample > 1`` only the block's
    middle pixel is answered.

    Parameters
    ----------
    field_ : VisibilityField
    camera : Camera
    interpolate : {"none", "uv", "st", "uv+st"}, optional
        Default: the field's ``settings["interpolate"]``.
    subsample : int
        Side of the pixel blocks that share one line (>= 1).
    fallback : bool
        Trace the pixels the field cannot answer (default). False: the paper's own behaviour,
        every slab the line crosses the right way answers it, overflowed samples included,
        and a line no slab crosses marks nothing (holes may appear).
    trust : int, optional
        A slab answers a line only when every sample it reads (the one holding the line and
        its interpolation neighbours) hit at most this many cells (with ``fallback``).
        Default: the field's ``settings["trust"]``, else its ids per sample (no sample read
        overflowed). 1 (``quality="balanced"`` and ``"exact"``): only where every sample read
        saw a single cell; lines near a cell border are traced.
    backend : {"gpu", "cpu"}
        How the marked cells are drawn. ``"gpu"`` (default): rasterized, as
        ``discretize(scene, camera, backend="gpu")`` draws the whole scene. ``"cpu"``: traced
        as ``backend="cpu"`` traces the whole scene (pixel-centre rays through the scene's BVH
        on all cores, centres on an edge decided by the raster's rule), each ray meeting only
        the marked cells' triangles; the pixels the fallback traced keep what it found. The two
        backends mark the same cells, and their images agree as the two backends of
        conventional images do (up to edge pixels where the GPU's float32 transform rounds a
        vertex differently). Resampling and the fallback run on the CPU either way.
    resampler : {"blocks", "pixels"}
        ``"blocks"`` (default): pixels whose lines read the same samples are taken a block at a
        time. ``"pixels"``: the plain reference, each pixel's line read on its own, slower. The
        two mark the same cells and leave the same pixels to the fallback (tested).

    Returns
    -------
    FieldView
        ``marked`` (C,) bool, ``image`` a :class:`DepthImages`, ``covered``,
        ``fallback_pixels``, ``fallback_cells``, ``stats``, ``timings``.
    """
    if isinstance(field_, (list, tuple)) and len(field_) == 1:
        field_ = field_[0]
    if not isinstance(field_, VisibilityField):
        raise InputError(
            f"reconstruct needs a VisibilityField (all slabs are in one), got "
            f"{type(field_).__name__}"
        )
    if not isinstance(camera, Camera):
        raise InputError(f"camera must be a scenesample.Camera, got {type(camera).__name__}")
    if interpolate is None:
        interpolate = field_.settings.get("interpolate", "none")
    if interpolate not in INTERPOLATIONS:
        raise InputError(f"interpolate must be one of {list(INTERPOLATIONS)}, got {interpolate!r}")
    if isinstance(subsample, bool) or not isinstance(subsample, (int, np.integer)) or subsample < 1:
        raise InputError(f"subsample must be a positive integer, got {subsample!r}")
    if not isinstance(fallback, (bool, np.bool_)):
        raise InputError(f"fallback must be True or False, got {fallback!r}")
    if backend not in ("gpu", "cpu"):
        raise InputError(f"backend must be 'gpu' or 'cpu', got {backend!r}")
    if resampler not in ("blocks", "pixels"):
        raise InputError(f"resampler must be 'blocks' or 'pixels', got {resampler!r}")
    if trust is None:
        trust = field_.settings.get("trust") or field_.ids.shape[-1]
    if isinstance(trust, bool) or not isinstance(trust, (int, np.integer)) or trust < 1:
        raise InputError(f"trust must be a positive integer, got {trust!r}")
    lo, hi = field_._scene.bounds.astype(np.float64)
    eye = np.asarray(camera.pose, dtype=np.float64)[:3, 3]
    if (eye > lo).all() and (eye < hi).all():
        warnings.warn(
            f"the camera at {np.round(eye, 4).tolist()} is inside the scene's bounds: the field "
            + (
                "answers none of the lines that start among the geometry; they are traced"
                if fallback
                else "may miss what lies between the camera and a slab's uv plane (fallback=False)"
            ),
            SceneWarning,
            stacklevel=3,
        )
    start = time.perf_counter()
    offsets, order = field_.cell_triangles
    d = _core.field_view(
        field_._sorted,
        order,
        offsets,
        [s.as_array().reshape(-1, 3) for s in field_.slabs],
        np.ascontiguousarray(field_.ids),
        np.ascontiguousarray(field_.cells_hit),
        camera,
        interpolate,
        int(subsample),
        bool(fallback),
        int(min(trust, 65535)),
        backend,
        resampler == "pixels",
    )
    img = DepthImages._from_core(d["image"], [camera], False)
    img.backend, img.backend_reason = backend, "requested"
    marked = d["marked"]
    pixels = int(d["pixels"])
    missed = int(d["outside"]) + int(d["overflowed"])
    covered = 1.0 - missed / max(pixels, 1)
    fallback_pixels = missed if fallback else 0
    return FieldView(
        marked=marked,
        image=img,
        camera=camera,
        covered=covered,
        fallback_pixels=fallback_pixels,
        fallback_cells=int(d["fallback_cells"]),
        stats={
            "cells_marked": int(marked.sum()),
            "triangles_drawn": int(d["triangles_drawn"]),
            "pixels": pixels,
            "pixels_outside": int(d["outside"]),
            "pixels_overflowed": int(d["overflowed"]),
            "covered": covered,
            "fallback_pixels": fallback_pixels,
            "fallback_cells": int(d["fallback_cells"]),
            "border_cells": int(d["border_cells"]),
        },
        timings={
            "resample": d["resample_seconds"],
            "fallback": d["fallback_seconds"],
            "render": d["render_seconds"],
            "total": time.perf_counter() - start,
        },
        _field=field_,
        _interpolate=interpolate,
        _subsample=int(subsample),
        _fallback=bool(fallback),
        _trust=int(trust),
        _backend=backend,
    )


def cells_metric(view: FieldView, scene: Scene, camera: Optional[Camera] = None) -> dict[str, Any]:
    """``evaluate(view, scene, "cells")``: see :func:`scenesample.evaluate`."""

    if not isinstance(view, FieldView):
        raise InputError(f"metric='cells' measures a FieldView, got {type(view).__name__}")
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    f0 = view._field
    if scene is not f0._scene and scene.triangle_count != len(f0.cell_of):
        raise InputError("the scene is not the one the field was computed for")
    cam = view.camera if camera is None else camera
    if cam is not view.camera:
        view = field_view(
            f0,
            cam,
            interpolate=view._interpolate,
            subsample=view._subsample,
            fallback=view._fallback,
            trust=view._trust,
            backend=view._backend,
        )
    cell_of = f0.cell_of.astype(np.int64)
    c = len(view.marked)

    # 1. Z-buffer of all geometry.
    t = time.perf_counter()
    # On the GPU, as the field view is drawn: the two meet at the same pixel edges.
    truth = conventional(scene, cam, backend="gpu")
    t_all = time.perf_counter() - t
    tri = truth.triangle[0]
    seen = tri >= 0
    visible = np.zeros(c, dtype=bool)
    visible[cell_of[tri[seen]]] = True
    marked = view.marked
    hole = np.zeros(tri.shape, dtype=bool)
    hole[seen] = ~marked[cell_of[tri[seen]]]

    # 3. Visibility tracing: rays from the camera through the same pixels the field view
    # resamples, then render the cells they hit.
    t = time.perf_counter()
    k = view._subsample
    ys = np.minimum(np.arange(0, cam.height, k) + k // 2, cam.height - 1)
    xs = np.minimum(np.arange(0, cam.width, k) + k // 2, cam.width - 1)
    o, d = cam.pixel_rays()
    o, d = o[ys][:, xs].reshape(-1, 3), d[ys][:, xs].reshape(-1, 3)
    hits = cast_rays(scene, o, d)
    traced = np.zeros(c, dtype=bool)
    traced[cell_of[hits.triangle[hits.triangle >= 0]]] = True
    offsets, order = f0.cell_triangles
    _core.render_cells(f0._sorted, order, offsets, traced, cam)
    t_trace = time.perf_counter() - t
    traced_tris = int(np.diff(offsets.astype(np.int64))[traced].sum())

    non_empty = c
    return {
        "cells_rendered": int(marked.sum()),
        "cells_fraction": float(marked.sum() / max(non_empty, 1)),
        "cells_visible": int(visible.sum()),
        "missed_cells": int((visible & ~marked).sum()),
        "missed_fraction": float((visible & ~marked).sum() / max(int(visible.sum()), 1)),
        "hole_pixels": int(hole.sum()),
        "hole_fraction": float(hole.sum() / max(int(seen.sum()), 1)),
        "covered": float(view.covered),
        "fallback_pixels": int(view.fallback_pixels),
        "extra_cells": int((marked & ~visible).sum()),
        "triangles_drawn": int(view.stats["triangles_drawn"]),
        "tracing_cells": int(traced.sum()),
        "tracing_missed_cells": int((visible & ~traced).sum()),
        "tracing_triangles": traced_tris,
        "hole_mask": hole,
        "time_zbuffer": t_all,
        "time_field": float(
            view.timings["resample"] + view.timings["fallback"] + view.timings["render"]
        ),
        "time_tracing": t_trace,
    }
