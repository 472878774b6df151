"""Views from the visibility field (visibility-field.txt §4): resample the field for a camera,
trace what it cannot answer, draw the marked cells; and ``evaluate(view, scene, "cells")``."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, fields
from typing import Any, Optional

import numpy as np

from .. import _core
from .._conventional import conventional
from .._rays import cast_rays
from .._scene import Scene
from ..errors import InputError, SceneWarning
from ..results import DepthImages
from .field import INTERPOLATIONS, VisibilityField

__all__ = ["FieldView", "field_view", "cells_metric"]

Camera = _core.Camera


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
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}


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
    d = _core.field_view(
        field_._handle,
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
    _core.render_cells(f0._handle, traced, cam)
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
