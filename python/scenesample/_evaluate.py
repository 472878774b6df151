"""The ``evaluate`` verb: accuracy and cost of a discretization."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any, Literal, Optional

import numpy as np

from . import _core
from ._conventional import conventional
from ._images import display, image_metrics, impostor_metrics, reflection_metrics
from ._scene import Scene
from ._surface import surface_metrics
from .epr.omni import OmniShadowResult
from .epr.reflections import ReflectionResult
from .errors import InputError
from .impostors.cells import ImpostorView
from .nonredundant.shadows import ShadowResult
from .results import DepthImages, Mesh
from .visibility_field import FieldView, cells_metric

__all__ = ["evaluate", "intermediate_cameras"]

METRICS = (
    "sampling", "shadow", "geometry", "surface", "image", "reflection", "impostor", "cells"
)  # fmt: skip
Metric = Literal[
    "sampling", "shadow", "geometry", "surface", "image", "reflection", "impostor", "cells"
]


def default_metric(result: Any, reference: Any) -> str:
    """The metric ``evaluate`` uses when none is given: against a :class:`Scene`, the one the
    result's type calls for (``DepthImages`` -> ``"sampling"``, ``Mesh`` -> ``"geometry"``,
    ``FieldView`` -> ``"cells"``); between two shadow results ``"shadow"``; between two impostor
    views ``"impostor"``; a reflection result against one with reflective pixels
    ``"reflection"``; any other pair of images ``"image"``."""
    if isinstance(reference, Scene) or reference is None:
        return {Mesh: "geometry", FieldView: "cells"}.get(type(result), "sampling")
    shadows = (ShadowResult, OmniShadowResult)
    if isinstance(result, shadows) and isinstance(reference, shadows):
        return "shadow"
    if isinstance(result, ImpostorView) and isinstance(reference, ImpostorView):
        return "impostor"
    if isinstance(result, ReflectionResult) and hasattr(reference, "reflective"):
        return "reflection"
    return "image"


def intermediate_cameras(region: Sequence[Any], count: int, seed: int = 0) -> list[Any]:
    """``count`` cameras inside the region spanned by ``region``'s viewpoints.

    One camera: ``count`` copies of it. Two: viewpoints on the segment between them, at
    seeded uniform positions. Three or more: seeded uniform points of the triangle (simplex)
    they span, i.e. Dirichlet(1, ..., 1) weights. Each camera's viewpoint is the weighted mean
    of the region's viewpoints and its orientation their weighted quaternion mean
    (``Camera.blend``); projection and resolution are those of ``region[0]``.
    """
    cams = list(region)
    if not cams:
        raise InputError("region needs at least one camera")
    for i, c in enumerate(cams):
        if not isinstance(c, _core.Camera):
            raise InputError(f"region[{i}] must be a scenesample.Camera, got {type(c).__name__}")
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 0:
        raise InputError(f"intermediate must be a non-negative integer, got {count!r}")
    # Each camera's Python object and weights, before any is made.
    _core.check_memory(f"{count} intermediate cameras", int(count), 1024)
    rng = np.random.default_rng(seed)
    k = len(cams)
    if k == 1:
        weights = np.ones((count, 1))
    elif k == 2:
        t = rng.uniform(size=count)
        weights = np.stack([1.0 - t, t], axis=1)
    else:
        weights = rng.dirichlet(np.ones(k), size=count)
    return [_core.Camera.blend(cams, [float(x) for x in w]) for w in weights]


def evaluate(
    images: Any,
    scene: Any,
    metric: Optional[Metric] = None,
    *,
    region: Optional[Sequence[Any]] = None,
    intermediate: int = 1000,
    redundancy: Literal["pixel", "visibility"] = "pixel",
    seed: int = 0,
    cameras: Optional[Sequence[Any]] = None,
    tolerance: float = 0.01,
    camera: Optional[Any] = None,
    samples: int = 100_000,
    threshold: Optional[float] = None,
) -> dict[str, Any]:
    """Measure a result's accuracy against a reference or the scene. Without ``metric``, it
    follows from the two arguments (see :func:`default_metric`): ``DepthImages`` + Scene ->
    ``"sampling"``, ``Mesh`` + Scene -> ``"geometry"``, ``FieldView`` + Scene -> ``"cells"``,
    two shadow results -> ``"shadow"``, two ``ImpostorView`` -> ``"impostor"``, a
    ``ReflectionResult`` against one -> ``"reflection"``, any other two images -> ``"image"``.
    Two lists (frames of an animation and their references) give each pair's metrics and the
    sequence's temporal flicker (see :func:`evaluate_sequence`).

    ``evaluate(result, reference, "image")``: any image-like result (``DepthImages`` (their
    base colour), ``ImpostorView``, ``ReflectionResult``, ``Frame``, ``ShadowResult`` and
    ``OmniShadowResult`` (their visible fraction as grey), or an (H, W, 3) / (H, W) array of
    linear values) against any other of the same size, on the 0-255 scale of their 8-bit sRGB
    display (eye-based-point-rendering.txt §4.2). Always the same keys: ``rmse``, ``psnr``,
    ``max_abs`` (over all pixels), ``pixel_error`` (the sum over pixels of |dR| + |dG| + |dB|,
    the p_diff of multi-cell-orthographic-impostors.txt §5) and ``coverage_difference`` (the
    fraction of pixels where one has a surface and the other none; arrays cover every pixel).

    ``evaluate(result, reference, "reflection")``: the image metrics, and ``rmse_reflective``,
    ``psnr_reflective``, ``max_abs_reflective`` over the reference's reflective pixels, with
    that ``mask``. The reflections' reference is :func:`scenesample.reflection_reference` (MVR
    at 4x, downsampled).

    ``evaluate(view, reference, "impostor")`` with two :class:`ImpostorView` (the reference
    typically ``ImpostorView.of_triangles(scene, camera)``): the paper's figures
    (multi-cell-orthographic-impostors.txt §5) on the 8-bit colours the views store (linear x
    255, no display encoding): ``pixel_error`` (p_diff), ``error_per_foreground_pixel``
    (divided by the area of the reference's foreground bounding rectangle, Fig. 2),
    ``gap_pixels`` and ``gap_mask`` (background showing through inside the reference's
    silhouette, i.e. at foreground pixels whose four neighbours are foreground too: the "black
    line" artifact, not a one-pixel misfit of the outline), ``rmse`` and ``foreground_rect``.

    ``evaluate(shadows, reference, "shadow")`` compares two :class:`ShadowResult` (or two
    :class:`OmniShadowResult`) of one view and one set of light samples
    (non-redundant-rendering.txt §6.2) over the pixels both see a surface at, on a 0-255 scale:
    ``intensity_error`` (mean absolute difference of the visible fraction: opposite errors at
    a pixel cancel), ``visibility_error`` (mean share of light samples resolved differently),
    ``max_intensity_error``, ``rmse`` (of the visible fraction), ``pixels`` and that ``mask``.
    Intensity error never exceeds visibility error.

    ``evaluate(mesh, scene, "geometry", cameras=...)`` renders the scene and the mesh from each
    camera and compares, over all cameras' pixels: ``coverage`` (fraction of the true surface's
    pixels where the mesh lies within the depth tolerance), ``over_coverage`` (pixels where the
    mesh lies in front of the true surface by more than the tolerance or where there is none,
    as a fraction of the true surface's pixels), ``mean_depth_error`` and ``max_depth_error``
    (world units, where both have a surface), and ``timings``. The tolerance at depth d is
    ``tolerance * d`` plus one pixel footprint.

    ``evaluate(result, scene, "surface", samples=100_000, threshold=None, seed=0)`` measures
    how far a reconstruction lies from the scene's surface and how much of it it covers, in
    world units (the definitions of Tanks and Temples). ``result`` is a ``Mesh``, a trimesh mesh
    (anything with ``vertices`` and ``faces``), a :class:`Points` result (its centres) or an
    (N, 3) array of points. Meshes and the scene are sampled by area (``samples`` points each,
    seeded by ``seed``); a point set is taken whole. ``accuracy_mean``, ``accuracy_median``,
    ``accuracy_max``: distances from the result's samples to the scene's surface (their max is
    one half of the Hausdorff distance); ``completeness_mean``, ``_median``, ``_max``: from the
    scene's samples to the result (to its nearest point, for a point set); ``chamfer`` (the
    mean of the two means), ``hausdorff`` (the larger max); ``precision`` and ``recall``: the
    fractions of those distances below ``threshold`` (default 0.5% of the scene's bounding-box
    diagonal), and ``fscore`` their harmonic mean; ``threshold``, the two distance arrays
    (``accuracy_distances``, ``completeness_distances``) and ``timings``. Distances come from
    :func:`scenesample.closest_points` (float64 exact).

    ``evaluate(view, scene, "cells", camera=None)`` measures a :class:`FieldView`
    (visibility-field.txt §6) against a full rasterization of ``scene`` from its camera (or
    ``camera``, for which the view is re-rendered): ``cells_rendered`` (marked),
    ``cells_fraction`` (of the non-empty cells), ``cells_visible`` (holding a triangle some
    pixel of the full rasterization sees), ``missed_cells`` (visible, not marked) and
    ``missed_fraction`` (of the visible), ``hole_pixels`` (pixels whose true triangle is in an
    unmarked cell) and ``hole_mask`` (H, W), ``extra_cells`` (marked, not visible),
    ``triangles_drawn``; and the seconds of the three strategies: ``time_zbuffer`` (all
    geometry), ``time_field`` (resample + render the marked cells), ``time_tracing``
    (visibility tracing: BVH rays from the camera through the same subsampled pixels, then
    render the cells they hit), with ``tracing_cells``, ``tracing_missed_cells`` and
    ``tracing_triangles``.

    The rest of this docstring describes ``"sampling"``: how well a set of depth images
    samples a scene (non-redundant-rendering.txt §6.1.2).

    Parameters
    ----------
    images : DepthImages
        From ``discretize`` (its ``method`` and ``reference`` cameras say how to read it).
    scene : Scene
        The scene the images sample.
    metric : {"sampling"}
    region : sequence of Camera, optional
        The viewpoints spanning the region of intermediate views (segment for two, triangle
        for three); default ``images.reference``.
    intermediate : int
        Number of intermediate output frames (default 1000, as in the paper).
    redundancy : {"pixel", "visibility"}
        The redundancy definition used by every metric (§3.1).
    seed : int
        Seeds the placement of the intermediate frames.

    Returns
    -------
    dict
        One (n,) array per metric, entry i for image i:

        - ``samples`` (int64): covered pixels of image i;
        - ``redundant`` (float64): fraction of image i's samples redundant with an image j < i;
        - ``disoccluded``: fraction not captured by the conventional reference images (for a
          non-redundant image, the conventional image from its own camera; for a peeling
          layer, any conventional reference image; 0 for conventional images);
        - ``useful``: fraction of the disoccluded samples needed (redundant with) at least one
          intermediate frame; 0 where nothing is disoccluded;
        - ``available_avg``, ``available_min``: over the intermediate frames, the fraction of a
          frame's samples available in (redundant with) at least one of images 0..i — the
          last entry is the paper's Table 2 figure for the whole set.

        Also ``disoccluded_mask`` and ``useful_mask``, (n, H, W) bool: which pixels hold
        disoccluded and useful samples (the paper's Fig. 6), ``frames`` (int) and ``timings``
        (seconds: ``conventional`` reference images, ``view_independent`` metrics 1-2,
        ``frames`` rendering and testing the intermediate frames, ``total``).

    Raises
    ------
    InputError
        Unknown metric or redundancy, images without reference cameras, bad ``intermediate``.
    """
    if isinstance(images, (list, tuple)):
        return evaluate_sequence(images, scene, metric)
    if metric is None:
        metric = default_metric(images, scene)
    if metric not in METRICS:
        raise InputError(f"metric must be one of {list(METRICS)}, got {metric!r}")
    if metric in ("image", "reflection", "impostor"):
        # Anything else that is not image-like is refused by the metric itself.
        for name, v in (("result", images), ("reference", scene)):
            if isinstance(v, Scene):
                raise InputError(
                    f"metric={metric!r} compares two image-like results; the {name} is "
                    f"{type(v).__name__}"
                )
        return {
            "image": image_metrics,
            "reflection": reflection_metrics,
            "impostor": impostor_metrics,
        }[metric](images, scene)
    if metric == "shadow":
        return _shadow_error(images, scene)
    if metric == "cells":
        return cells_metric(images, scene, camera)
    if metric == "geometry":
        return _geometry_error(images, scene, cameras, tolerance)
    if metric == "surface":
        return surface_metrics(images, scene, samples, threshold, seed)
    return _sampling(images, scene, region, intermediate, redundancy, seed)


def _sampling(
    images: Any,
    scene: Any,
    region: Optional[Sequence[Any]],
    intermediate: int,
    redundancy: str,
    seed: int,
) -> dict[str, Any]:
    """``evaluate``'s ``"sampling"`` metric (non-redundant-rendering.txt §6.1.2)."""
    if not isinstance(images, DepthImages):
        raise InputError(f"images must be a DepthImages, got {type(images).__name__}")
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if redundancy not in ("pixel", "visibility"):
        raise InputError(f"redundancy must be 'pixel' or 'visibility', got {redundancy!r}")
    reference = list(images.reference)
    if not reference:
        raise InputError(
            "images.reference is empty: set it to the cameras the images were made for"
        )
    frames = intermediate_cameras(reference if region is None else region, intermediate, seed)
    n, h, w = images.triangle.shape
    d = _core.sampling_metrics(
        scene._core,
        np.ascontiguousarray(images.triangle, dtype=np.int32).reshape(-1),
        np.ascontiguousarray(images.position, dtype=np.float32).reshape(-1, 3),
        np.ascontiguousarray(images.depth, dtype=np.float32).reshape(-1, 1),
        list(images.cameras),
        str(images.method),
        reference,
        frames,
        redundancy,
        bool(images.cull_backfaces),
    )
    d["samples"] = d["samples"].astype(np.int64)
    return d


def _shadow_error(result: Any, reference: Any) -> dict[str, Any]:
    kinds = (ShadowResult, OmniShadowResult)
    for name, r in (("result", result), ("reference", reference)):
        if not isinstance(r, kinds):
            raise InputError(
                f"metric='shadow' compares ShadowResults or OmniShadowResults; {name} is "
                f"{type(r).__name__}"
            )
    if result.visible.shape != reference.visible.shape:
        raise InputError(
            f"the results differ in shape: {result.visible.shape} vs {reference.visible.shape} "
            "(same camera and light samples needed)"
        )
    both = result.mask & reference.mask
    if not both.any():
        raise InputError("the two results share no pixel with a surface")
    diff = np.abs(result.visibility.astype(np.float64) - reference.visibility)[both]
    wrong = (result.visible != reference.visible)[both].mean(axis=-1)
    return {
        "intensity_error": float(255 * diff.mean()),
        "visibility_error": float(255 * wrong.mean()),
        "max_intensity_error": float(255 * diff.max()),
        "rmse": float(255 * np.sqrt(np.mean(diff**2))),
        "pixels": int(both.sum()),
        "mask": both,
    }


def _geometry_error(
    mesh: Any, scene: Any, cameras: Optional[Sequence[Any]], tolerance: float
) -> dict[str, Any]:
    if not isinstance(mesh, Mesh):
        raise InputError(f"metric='geometry' measures a Mesh, got {type(mesh).__name__}")
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if not cameras:
        raise InputError("metric='geometry' needs cameras=[...] to compare from")
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise InputError(f"tolerance must be a non-negative number, got {tolerance!r}")
    start = time.perf_counter()
    cams = list(cameras)
    truth = conventional(scene, cams)
    if len(mesh.faces):
        rebuilt = conventional(mesh.to_scene(), cams, backend=truth.backend)
        dm = rebuilt.depth.astype(np.float64)
    else:
        dm = np.full(truth.depth.shape, np.inf)
    dt = truth.depth.astype(np.float64)
    tol = np.empty_like(dt)
    for i, c in enumerate(cams):
        f0, f1 = c.pixel_footprint(0.0), c.pixel_footprint(1.0)
        tol[i] = tolerance * dt[i] + f0 + (f1 - f0) * dt[i]
    t_in, m_in = np.isfinite(dt), np.isfinite(dm)
    both = t_in & m_in
    diff = np.where(both, dm, 0.0) - np.where(both, dt, 0.0)
    err = np.abs(diff)[both]
    close = both & (np.abs(diff) <= np.where(both, tol, 0.0))
    over = (m_in & ~t_in) | (both & (diff < -np.where(both, tol, 0.0)))
    surface = max(int(t_in.sum()), 1)
    return {
        "coverage": float(close.sum() / surface),
        "over_coverage": float(over.sum() / surface),
        "mean_depth_error": float(err.mean()) if err.size else float("nan"),
        "max_depth_error": float(err.max()) if err.size else float("nan"),
        "timings": {"total": time.perf_counter() - start},
    }


def evaluate_sequence(
    frames: Sequence[Any], references: Sequence[Any], metric: Optional[Metric] = None
) -> dict[str, Any]:
    """Accuracy and temporal stability of an animation: ``frames[k]`` against
    ``references[k]`` (the same metric as :func:`evaluate` of one pair).

    Returns ``per_frame`` (each pair's metrics), ``overall`` (each scalar metric's mean over
    the frames), and for image-like frames the temporal figures, on the 0-255 scale of the
    8-bit sRGB display: ``flicker`` (per frame from the second on, the mean over pixels of the
    absolute change of the error image |frame - reference|, channels averaged, from the frame
    before) and ``reference_change`` (the same for the reference images themselves: how much
    the scene's motion changes the picture), with their means and ``flicker_ratio`` (mean
    flicker over mean reference change) in ``overall``. A method as stable as its reference
    flickers near 0; flicker comparable to the reference's change means its errors jump
    around as much as the picture moves. When each pair's metrics carry a ``mask`` (the
    reflection metric's mirror pixels), the same figures over the pixels masked in both frames
    come as ``flicker_reflective`` and ``reference_change_reflective``.
    """
    frames, references = list(frames), list(references)
    if not frames or not isinstance(references, list) or len(references) != len(frames):
        raise InputError(
            f"a sequence needs as many reference frames as frames, got {len(frames)} and "
            f"{len(references) if isinstance(references, list) else type(references).__name__}"
        )
    per_frame = [evaluate(a, b, metric) for a, b in zip(frames, references)]
    overall: dict[str, Any] = {}
    for key, v in per_frame[0].items():
        if isinstance(v, (int, float, np.floating, np.integer)) and not isinstance(v, bool):
            overall[key] = float(np.mean([f[key] for f in per_frame]))
    out: dict[str, Any] = {"per_frame": per_frame, "overall": overall}
    try:
        shown = [
            (display(a)[0].astype(np.float64), display(b)[0].astype(np.float64))
            for a, b in zip(frames, references)
        ]
    except InputError:
        return out  # not images: no temporal figures
    err = [np.abs(a - b).mean(axis=-1) for a, b in shown]
    flicker = np.array([np.nan] + [float(np.abs(e1 - e0).mean()) for e0, e1 in zip(err, err[1:])])
    change = np.array(
        [np.nan] + [float(np.abs(b1 - b0).mean()) for (_, b0), (_, b1) in zip(shown, shown[1:])]
    )
    out["flicker"], out["reference_change"] = flicker, change
    _temporal_means(overall, "", flicker, change)
    masks = [f.get("mask") for f in per_frame]
    if all(isinstance(m, np.ndarray) for m in masks):
        # Over the pixels the metric singles out (the mirrors) in both frames.
        both = [m0 & m1 for m0, m1 in zip(masks, masks[1:])]

        def mean(x: np.ndarray, m: np.ndarray) -> float:
            m = np.broadcast_to(m, x.shape)
            return float(x[m].mean()) if m.any() else float("nan")

        flicker_m = np.array(
            [np.nan] + [mean(np.abs(e1 - e0), m) for e0, e1, m in zip(err, err[1:], both)]
        )
        change_m = np.array(
            [np.nan]
            + [
                mean(np.abs(b1 - b0).mean(axis=-1), m)
                for (_, b0), (_, b1), m in zip(shown, shown[1:], both)
            ]
        )
        out["flicker_reflective"], out["reference_change_reflective"] = flicker_m, change_m
        _temporal_means(overall, "_reflective", flicker_m, change_m)
    return out


def _temporal_means(
    overall: dict[str, Any], suffix: str, flicker: np.ndarray, change: np.ndarray
) -> None:
    if len(flicker) < 2 or np.isnan(flicker[1:]).all():
        return
    f, c = float(np.nanmean(flicker)), float(np.nanmean(change))
    overall["flicker" + suffix], overall["reference_change" + suffix] = f, c
    overall["flicker_ratio" + suffix] = f / c if c > 0 else float("nan")
