"""The visibility field (visibility-field.txt): precomputed two-plane visibility of grid cells,
resampled per view to cull hidden geometry."""

from __future__ import annotations

import time
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Optional, Union

import numpy as np

from . import _core
from ._depth import conventional
from ._progress import Bar
from ._rays import cast_rays
from ._scene import Scene
from .errors import InputError
from .results import DepthImages

__all__ = ["Slab", "VisibilityField", "FieldView", "INTERPOLATIONS"]

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
        """The default slab: planes perpendicular to ``axis`` (default: the bounds' longest
        axis), uv ``margin`` of the scene's extent along it before the bounds' low side, st as
        far beyond the high side, both covering the bounds' cross-section widened on every side
        by ``widen`` times the bounds' longest extent. Cameras on the low side looking along
        +axis use it."""
        if not isinstance(scene, Scene):
            raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
        a = _core.default_slab(scene._core, axis, float(margin), float(widen))
        return cls.from_array(a)

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
    """The cell ids first hit along the lines of one slab (visibility-field.txt §3).

    Attributes
    ----------
    ids : (U, V, S, T, n) int32
        Per line sample, the ``n`` cells hit most often by its rays, most frequent first
        (ties: lower id first); -1 where fewer cells were hit.
    cells : (C,) structured array (``object``, ``x``, ``y``, ``z``; int32)
        Per non-empty cell: its group (object, or connected component) and grid coordinates.
    cell_bounds : (C, 2, 3) float32
        Each cell's grid box (low, high corner).
    cell_triangles : tuple of ((C + 1,) uint32 offsets, (F,) uint32 triangle ids)
        CSR: cell c holds triangles ``indices[offsets[c]:offsets[c + 1]]``.
    cell_of : (F,) uint32
        Each triangle's cell.
    slab : Slab
    stats : dict
        ``rays`` cast, ``memory_bytes`` (of ``ids``), ``compressed_bytes`` (``ids`` after
        zlib/deflate level 6; §7.1 expects high coherence), ``cells`` (non-empty), ``groups``,
        ``samples``.
    timings : dict of str to float
        Seconds: ``cells`` (grouping, grid, cell-sorted copy of the scene), ``rays``,
        ``rank``, ``compress``, ``total``.
    """

    ids: np.ndarray
    cells: np.ndarray
    cell_bounds: np.ndarray
    cell_triangles: tuple[np.ndarray, np.ndarray]
    cell_of: np.ndarray
    slab: Slab
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    _scene: Optional[Scene] = None
    _sorted: Any = None

    def __repr__(self) -> str:
        u, v, s, t, n = self.ids.shape
        return (
            f"VisibilityField({u}x{v} uv, {s}x{t} st, {n} ids per sample, "
            f"{len(self.cells):,} cells)"
        )

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}


@dataclass(eq=False, repr=False)
class FieldView:
    """A view rendered from the visibility field (visibility-field.txt §4).

    Attributes
    ----------
    marked : (C,) bool
        Cells the resampling marked.
    image : DepthImages
        One depth image rendered on the GPU from only the marked cells' triangles (triangle
        ids are the scene's).
    camera : Camera
    stats : dict
        ``cells_marked``, ``triangles_drawn``, ``pixels`` (resampled, after subsampling),
        ``pixels_outside`` (their lines miss the slab: they mark nothing).
    timings : dict of str to float
        Seconds: ``resample`` (the paper's K_rasterize+resample), ``render`` (the marked
        cells), ``total``.
    """

    marked: np.ndarray
    image: DepthImages
    camera: Any
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    _fields: list = field(default_factory=list)
    _interpolate: str = "none"
    _subsample: int = 1

    def __repr__(self) -> str:
        return (
            f"FieldView({self.stats.get('cells_marked', 0):,} of {len(self.marked):,} cells, "
            f"{self.stats.get('triangles_drawn', 0):,} triangles)"
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


def visibility_field(
    scene: Scene,
    *,
    slab: Union[None, Slab, Sequence[Slab]] = None,
    uv: Any = (16, 16),
    st: Any = (16, 16),
    grid: Any = (16, 16, 16),
    ids_per_sample: int = 1,
    supersample: int = 3,
    jitter: bool = False,
    seed: int = 0,
    progress: Optional[bool] = None,
) -> Union[VisibilityField, list[VisibilityField]]:
    """The visibility field (visibility-field.txt §3): for every sample (iu, iv, is, it) of the
    slab, ``supersample^4`` BVH rays from its uv cell to its st cell; the ``ids_per_sample``
    cells hit most often are kept (§3.3).

    Parameters
    ----------
    scene : Scene
    slab : Slab or list of Slab, optional
        The two-plane parameterization (default :meth:`Slab.around`: planes before and beyond
        the scene's bounds along their longest axis). Several slabs give one field each (a
        list), sharing the cells.
    uv, st : (int, int)
        Samples on each plane (default 16 x 16).
    grid : (int, int, int) or "scene"
        Cells along x, y, z of each object's bounding box (objects: the scene's meshes/nodes,
        or its connected components when it has one object); ``"scene"``: one 16^3 grid over
        the whole scene. A triangle belongs to the cell holding its centroid.
    ids_per_sample : int
        Cell ids kept per sample (the most frequent).
    supersample : int
        Rays per axis of each plane's sample cell (3: 3 x 3 on each plane, 81 rays per sample,
        §3.3), at sub-cell centres (the paper's regular grid).
    jitter : bool
        Jitter each ray within its sub-cell instead (off by default).
    seed : int
        Seeds the jitter (any non-negative integer, 0 included); unused without ``jitter``.
    progress : bool, optional
        A tqdm bar over the slab samples when tqdm is installed. None (default): only once the
        work has run for 2 s; True: at once; False: never. Ctrl-C stops it within half a
        second (``KeyboardInterrupt``).

    Returns
    -------
    VisibilityField or list of VisibilityField
        One per slab (a list when ``slab`` is a list).
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if scene.triangle_count == 0:
        raise InputError("the scene has no triangles")
    many = slab is not None and not isinstance(slab, Slab)
    slabs = [Slab.around(scene)] if slab is None else ([slab] if not many else list(slab))
    for k, s in enumerate(slabs):
        if not isinstance(s, Slab):
            raise InputError(f"slab[{k}] must be a Slab, got {type(s).__name__}")
    if not slabs:
        raise InputError("slab must be a Slab or a non-empty list of them")
    uv, st = _pair(uv, "uv"), _pair(st, "st")
    if isinstance(grid, str):
        if grid != "scene":
            raise InputError(f"grid must be three positive integers or 'scene', got {grid!r}")
        dims, grouping = (16, 16, 16), "scene"
    else:
        try:
            dims = tuple(int(g) for g in grid)
        except (TypeError, ValueError):
            raise InputError(
                f"grid must be three positive integers or 'scene', got {grid!r}"
            ) from None
        if len(dims) != 3 or min(dims) < 1:
            raise InputError(f"grid must be three positive integers or 'scene', got {grid!r}")
        grouping = "objects"
    for name, val in (("ids_per_sample", ids_per_sample), ("supersample", supersample)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
            raise InputError(f"{name} must be a positive integer, got {val!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    if not isinstance(jitter, (bool, np.bool_)):
        raise InputError(f"jitter must be True or False, got {jitter!r}")
    start = time.perf_counter()
    with Bar(progress, "visibility field", "samples") as bar:
        d = _core.visibility_field(
            scene._core,
            [s.as_array().reshape(-1, 3) for s in slabs],
            uv,
            st,
            dims,
            grouping,
            int(ids_per_sample),
            int(supersample),
            int(seed) if jitter else None,
            bar.callback,
        )
    cells = np.zeros(len(d["cells"]), dtype=CELL_DTYPE)
    for k, name in enumerate(CELL_DTYPE.names):
        cells[name] = d["cells"][:, k]
    out = []
    for f, s in zip(d["fields"], slabs):
        t = time.perf_counter()
        packed = len(zlib.compress(np.ascontiguousarray(f["ids"]).tobytes(), 6))
        timings = {"cells": d["cell_seconds"], **dict(f["timings"])}
        timings["compress"] = time.perf_counter() - t
        out.append(
            VisibilityField(
                ids=f["ids"],
                cells=cells,
                cell_bounds=d["cell_bounds"],
                cell_triangles=(d["offsets"], d["triangles"]),
                cell_of=d["cell_of"],
                slab=s,
                stats={
                    "rays": int(f["rays"]),
                    "memory_bytes": int(f["ids"].nbytes),
                    "compressed_bytes": packed,
                    "cells": len(cells),
                    "groups": int(d["groups"]),
                    "samples": int(np.prod(f["ids"].shape[:4])),
                },
                timings=timings,
                _scene=scene,
                _sorted=d["sorted_scene"],
            )
        )
    total = time.perf_counter() - start
    for f in out:
        f.timings["total"] = total
    return out if many else out[0]


def field_view(
    field_: Union[VisibilityField, Sequence[VisibilityField]],
    camera: Camera,
    *,
    interpolate: str = "none",
    subsample: int = 1,
) -> FieldView:
    """Render ``camera``'s view from a visibility field (visibility-field.txt §4, Fig. 4).

    One pixel in every ``subsample x subsample`` block (the block's middle pixel) gives a line;
    where it crosses the slab's uv and st rectangles gives (u, v, s, t); the cells stored at
    that sample are marked (``interpolate="uv"``: also the 2 x 2 samples around (u, v);
    ``"st"``: around (s, t); ``"uv+st"``: the 16 around both, §4.1). A pixel whose line misses
    either rectangle, runs parallel to a plane, or crosses st before uv marks nothing. Then only
    the marked cells' triangles are rasterized on the GPU (faces are kept sorted by cell: one
    draw per run of marked cells).

    Parameters
    ----------
    field_ : VisibilityField or list of VisibilityField
        One, or the list one ``discretize`` call made (one per slab, sharing the cells).
    camera : Camera
    interpolate : {"none", "uv", "st", "uv+st"}
    subsample : int
        Side of the pixel blocks that share one line (>= 1).

    Returns
    -------
    FieldView
        ``marked`` (C,) bool, ``image`` a :class:`DepthImages`, ``stats``, ``timings``
        (``resample``, ``render``, ``total``).
    """
    fs = [field_] if isinstance(field_, VisibilityField) else list(field_)
    if not fs or not all(isinstance(f, VisibilityField) for f in fs):
        raise InputError("reconstruct needs a VisibilityField or a list of them")
    if any(f.cells is not fs[0].cells for f in fs):
        raise InputError("the fields must come from one discretize call (shared cells)")
    if not isinstance(camera, Camera):
        raise InputError(f"camera must be a scenesample.Camera, got {type(camera).__name__}")
    if interpolate not in INTERPOLATIONS:
        raise InputError(f"interpolate must be one of {list(INTERPOLATIONS)}, got {interpolate!r}")
    if isinstance(subsample, bool) or not isinstance(subsample, (int, np.integer)) or subsample < 1:
        raise InputError(f"subsample must be a positive integer, got {subsample!r}")
    start = time.perf_counter()
    offsets, order = fs[0].cell_triangles
    d = _core.field_view(
        fs[0]._sorted,
        order,
        offsets,
        [f.slab.as_array().reshape(-1, 3) for f in fs],
        [f.ids for f in fs],
        camera,
        interpolate,
        int(subsample),
    )
    img = DepthImages._from_core(d["image"], [camera], False)
    marked = d["marked"]
    return FieldView(
        marked=marked,
        image=img,
        camera=camera,
        stats={
            "cells_marked": int(marked.sum()),
            "triangles_drawn": int(d["triangles_drawn"]),
            "pixels": int(d["pixels"]),
            "pixels_outside": int(d["outside"]),
        },
        timings={
            "resample": d["resample_seconds"],
            "render": d["render_seconds"],
            "total": time.perf_counter() - start,
        },
        _fields=fs,
        _interpolate=interpolate,
        _subsample=int(subsample),
    )


def cells_metric(view: FieldView, scene: Scene, camera: Optional[Camera] = None) -> dict[str, Any]:
    """``evaluate(view, scene, "cells")``: see :func:`scenesample.evaluate`."""

    if not isinstance(view, FieldView):
        raise InputError(f"metric='cells' measures a FieldView, got {type(view).__name__}")
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    f0 = view._fields[0]
    if scene is not f0._scene and scene.triangle_count != len(f0.cell_of):
        raise InputError("the scene is not the one the field was computed for")
    cam = view.camera if camera is None else camera
    if cam is not view.camera:
        view = field_view(
            view._fields, cam, interpolate=view._interpolate, subsample=view._subsample
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
        "extra_cells": int((marked & ~visible).sum()),
        "triangles_drawn": int(view.stats["triangles_drawn"]),
        "tracing_cells": int(traced.sum()),
        "tracing_missed_cells": int((visible & ~traced).sum()),
        "tracing_triangles": traced_tris,
        "hole_mask": hole,
        "time_zbuffer": t_all,
        "time_field": float(view.timings["resample"] + view.timings["render"]),
        "time_tracing": t_trace,
    }
