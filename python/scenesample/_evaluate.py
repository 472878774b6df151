"""The ``evaluate`` verb: accuracy and cost of a discretization."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Optional

import numpy as np

from . import _core
from ._scene import Scene
from .errors import InputError
from .results import DepthImages

__all__ = ["evaluate", "intermediate_cameras"]

METRICS = ("sampling",)


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
    images: DepthImages,
    scene: Scene,
    metric: str = "sampling",
    *,
    region: Optional[Sequence[Any]] = None,
    intermediate: int = 1000,
    redundancy: str = "pixel",
    seed: int = 0,
) -> dict[str, Any]:
    """Measure how well a set of depth images samples a scene (non-redundant-rendering.txt
    §6.1.2).

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
    if metric not in METRICS:
        raise InputError(f"metric must be one of {list(METRICS)}, got {metric!r}")
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
        list(images.cameras),
        str(images.method),
        reference,
        frames,
        redundancy,
        bool(images.cull_backfaces),
    )
    d["samples"] = d["samples"].astype(np.int64)
    return d
