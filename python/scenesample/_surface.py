"""``evaluate(result, scene, "surface")``: how far a reconstruction lies from the true surface
and how much of it it covers, from seeded area samples and closest-point queries on the
scene's BVH (the definitions of Tanks and Temples: Knapitsch et al., SIGGRAPH 2017)."""

from __future__ import annotations

import time
from typing import Any, Optional

import numpy as np

from ._points import closest_points
from ._scene import Scene
from .errors import InputError

__all__ = ["surface_metrics", "sample_surface"]

#: The default distance threshold of precision and recall, as a fraction of the scene's
#: bounding-box diagonal (about twice the pixel footprint of a 512-pixel view of the whole
#: scene).
DEFAULT_THRESHOLD = 0.005


def sample_surface(
    vertices: np.ndarray, faces: np.ndarray, n: int, rng: np.random.Generator
) -> np.ndarray:
    """``n`` points spread uniformly by area over the triangles (float64 (n, 3))."""
    v = np.asarray(vertices, np.float64)
    tri = v[np.asarray(faces, np.int64)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = area.sum()
    if not (total > 0 and np.isfinite(total)):
        raise InputError("the surface to sample has no area")
    pick = np.searchsorted(np.cumsum(area) / total, rng.random(n), side="right")
    pick = np.minimum(pick, len(area) - 1)
    r1, r2 = rng.random(n), rng.random(n)
    flip = r1 + r2 > 1
    r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
    t = tri[pick]
    return t[:, 0] + (t[:, 1] - t[:, 0]) * r1[:, None] + (t[:, 2] - t[:, 0]) * r2[:, None]


def _result_surface(result: Any) -> tuple[Optional[np.ndarray], np.ndarray]:
    """(faces or None, vertices or points) of what ``evaluate`` measures: a ``Mesh`` (or a
    ``Scene``, or anything with ``vertices`` and ``faces``, such as a trimesh mesh), a
    ``Points`` result (its centres) or an (N, 3) array of points."""
    if hasattr(result, "vertices") and hasattr(result, "faces"):
        return np.asarray(result.faces), np.asarray(result.vertices)
    if hasattr(result, "center"):
        return None, np.asarray(result.center)
    arr = np.asarray(result)
    if arr.ndim != 2 or arr.shape[1] != 3 or not np.issubdtype(arr.dtype, np.number):
        raise InputError(
            "metric='surface' measures a Mesh, a Points result, a trimesh mesh or an (N, 3) "
            f"array of points, got {type(result).__name__}"
            + (f" of shape {arr.shape}" if arr.ndim else "")
        )
    return None, arr


def _stats(d: np.ndarray, prefix: str) -> dict[str, float]:
    return {
        f"{prefix}_mean": float(d.mean()),
        f"{prefix}_median": float(np.median(d)),
        f"{prefix}_max": float(d.max()),
    }


def surface_metrics(
    result: Any, scene: Scene, samples: int, threshold: Optional[float], seed: int
) -> dict[str, Any]:
    """See :func:`scenesample.evaluate` (``metric="surface"``)."""
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise InputError(f"samples must be a positive integer, got {samples!r}")
    lo, hi = scene.bounds.astype(np.float64)
    diagonal = float(np.linalg.norm(hi - lo))
    tau = DEFAULT_THRESHOLD * diagonal if threshold is None else float(threshold)
    if not (np.isfinite(tau) and tau > 0):
        raise InputError(f"threshold must be a positive distance, got {threshold!r}")
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    faces, verts = _result_surface(result)
    if faces is None:
        if len(verts) == 0:
            raise InputError("the point set to measure is empty")
        if not np.isfinite(verts).all():
            raise InputError("the point set to measure holds non-finite coordinates")
        ours = verts.astype(np.float32)
        # Each point a degenerate triangle: the BVH's closest points are then nearest points.
        index = np.arange(len(ours), dtype=np.uint32)
        rebuilt = Scene.from_arrays(ours, np.stack([index] * 3, axis=1))
    else:
        if len(faces) == 0:
            raise InputError("the mesh to measure has no faces")
        ours = sample_surface(verts, faces, samples, rng).astype(np.float32)
        rebuilt = Scene.from_arrays(np.asarray(verts, np.float32), np.asarray(faces))
    truth = sample_surface(scene.vertices, scene.faces, samples, rng).astype(np.float32)
    t_sample = time.perf_counter() - start
    t = time.perf_counter()
    acc = closest_points(scene, ours).distance.astype(np.float64)
    t_acc = time.perf_counter() - t
    t = time.perf_counter()
    comp = closest_points(rebuilt, truth).distance.astype(np.float64)
    t_comp = time.perf_counter() - t
    precision = float((acc < tau).mean())
    recall = float((comp < tau).mean())
    fscore = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return {
        **_stats(acc, "accuracy"),
        **_stats(comp, "completeness"),
        "chamfer": float((acc.mean() + comp.mean()) / 2),
        "hausdorff": float(max(acc.max(), comp.max())),
        "precision": precision,
        "recall": recall,
        "fscore": float(fscore),
        "threshold": tau,
        "accuracy_distances": acc.astype(np.float32),
        "completeness_distances": comp.astype(np.float32),
        "timings": {
            "sample": t_sample,
            "accuracy": t_acc,
            "completeness": t_comp,
            "total": time.perf_counter() - start,
        },
    }
