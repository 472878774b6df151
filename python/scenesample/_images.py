"""Comparing image-like results, whatever made them: depth images (their base colour), impostor
views, reflections, frames, shadow visibility, or plain arrays. Every comparison works on the
8-bit sRGB display of both images (one encoder: :func:`scenesample.imageio.linear_to_srgb`), as
eye-based-point-rendering.txt §4.2 measures, so results of different methods compare directly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import InputError
from .imageio import linear_to_srgb

__all__ = ["display", "image_metrics", "reflection_metrics", "impostor_metrics"]


def _linear(x: Any) -> tuple[np.ndarray, np.ndarray]:
    """(k, H, W, 3) linear RGB and (k, H, W) coverage of an image-like object."""
    if hasattr(x, "triangle") and hasattr(x, "color") and np.ndim(x.color) == 4:  # DepthImages
        return np.asarray(x.color), np.asarray(x.triangle) >= 0
    if hasattr(x, "color") and hasattr(x, "depth"):  # ImpostorView
        return np.asarray(x.color)[None], np.isfinite(np.asarray(x.depth))[None]
    if hasattr(x, "visibility") and hasattr(x, "mask"):  # ShadowResult, OmniShadowResult
        v = np.where(x.mask, np.asarray(x.visibility, dtype=np.float64), 0.0)
        return np.repeat(v[None, ..., None], 3, axis=-1), np.asarray(x.mask)[None]
    if hasattr(x, "image"):  # ReflectionResult, Frame
        img = np.asarray(x.image)
        mask = getattr(x, "mask", None)
        cover = np.ones(img.shape[:2], bool) if mask is None else np.asarray(mask, bool)
        return img[None], cover[None]
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=-1)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InputError(
            f"expected an image-like result or an (H, W, 3) / (H, W) array, got "
            f"{type(x).__name__} of shape {arr.shape}"
        )
    return arr[None], np.ones(arr.shape[:2], bool)[None]


def display(x: Any) -> tuple[np.ndarray, np.ndarray]:
    """((k, H, W, 3) uint8 sRGB, (k, H, W) bool coverage) of an image-like result."""
    rgb, cover = _linear(x)
    return linear_to_srgb(rgb), cover


def _pair(result: Any, reference: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    a, ma = display(result)
    b, mb = display(reference)
    if a.shape != b.shape:
        raise InputError(
            f"the images differ in shape: {type(result).__name__} {a.shape[:3]} vs "
            f"{type(reference).__name__} {b.shape[:3]} (same cameras needed)"
        )
    return a, ma, b, mb


def _stats(diff: np.ndarray) -> tuple[float, float, float]:
    if diff.size == 0:
        return float("nan"), float("nan"), float("nan")
    mse = float(np.mean(diff**2))
    psnr = float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))
    return mse**0.5, psnr, float(np.abs(diff).max())


def image_metrics(result: Any, reference: Any) -> dict[str, Any]:
    """The metrics every pair of image-like results of one size gets (``metric="image"``)."""
    a, ma, b, mb = _pair(result, reference)
    diff = a.astype(np.float64) - b.astype(np.float64)
    rmse, psnr, mx = _stats(diff)
    return {
        "rmse": rmse,
        "psnr": psnr,
        "max_abs": mx,
        "pixel_error": int(np.abs(diff).sum()),
        "coverage_difference": float((ma != mb).mean()),
    }


def reflection_metrics(result: Any, reference: Any) -> dict[str, Any]:
    """``metric="reflection"``: the image metrics, and the same over the reference's
    reflective pixels (``reference.reflective``, all pixels for an array), with that mask."""
    out = image_metrics(result, reference)
    a, _, b, _ = _pair(result, reference)
    mask = getattr(reference, "reflective", None)
    mask = np.ones(a.shape[1:3], bool) if mask is None else np.asarray(mask, dtype=bool)
    diff = a[0].astype(np.float64) - b[0].astype(np.float64)
    rr, rp, rm = _stats(diff[mask])
    out.update(rmse_reflective=rr, psnr_reflective=rp, max_abs_reflective=rm, mask=mask)
    return out


def impostor_metrics(view: Any, reference: Any) -> dict[str, Any]:
    """``metric="impostor"``: the paper's figures (multi-cell-orthographic-impostors.txt §5) on
    the 8-bit colours the views store (linear colour x 255, as the paper's framebuffer holds
    them, not the sRGB display)."""
    for name, v in (("view", view), ("reference", reference)):
        if not (hasattr(v, "color") and hasattr(v, "depth") and hasattr(v, "used")):
            raise InputError(
                f"metric='impostor' compares two ImpostorViews; {name} is {type(v).__name__}"
            )
    if view.color.shape != reference.color.shape:
        raise InputError(f"images differ in shape: {view.color.shape} vs {reference.color.shape}")
    a = np.round(np.clip(view.color, 0, 1) * 255).astype(np.int64)
    b = np.round(np.clip(reference.color, 0, 1) * 255).astype(np.int64)
    diff = np.abs(a - b)
    p_diff = int(diff.sum())
    fg = reference.mask
    if fg.any():
        ys, xs = np.nonzero(fg)
        rect = (ys.max() - ys.min() + 1) * (xs.max() - xs.min() + 1)
    else:
        rect = 0
    # Inside the silhouette: foreground pixels whose four neighbours are foreground too (a
    # one-pixel misfit of the outline is resampling, not the inter-cell "black line").
    inner = fg.copy()
    inner[1:] &= fg[:-1]
    inner[:-1] &= fg[1:]
    inner[:, 1:] &= fg[:, :-1]
    inner[:, :-1] &= fg[:, 1:]
    inner[[0, -1], :] = False
    inner[:, [0, -1]] = False
    gaps = inner & ~view.mask
    return {
        "pixel_error": p_diff,
        "error_per_foreground_pixel": float(p_diff / rect) if rect else float("nan"),
        "gap_pixels": int(gaps.sum()),
        "gap_mask": gaps,
        "rmse": float(np.sqrt(np.mean(diff.astype(np.float64) ** 2))),
        "foreground_rect": int(rect),
    }
