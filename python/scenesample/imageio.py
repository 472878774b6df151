"""Turning result arrays into viewable 8-bit images, and PNG output without extra dependencies."""

from __future__ import annotations

import os
import struct
import zlib
from typing import Optional

import numpy as np

from ._optional import require

__all__ = ["write_png", "depth_to_rgb", "normal_to_rgb", "linear_to_srgb", "ids_to_rgb"]


def write_png(path: str | os.PathLike[str], rgb: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 image as an 8-bit RGB PNG."""
    img = np.ascontiguousarray(rgb, dtype=np.uint8)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"write_png needs an (H, W, 3) image, got {img.shape}")
    h, w, _ = img.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), img.reshape(h, w * 3)], axis=1).tobytes()

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6))
    with open(path, "wb") as f:
        f.write(png + chunk(b"IEND", b""))


def _u8(x: np.ndarray) -> np.ndarray:
    return (np.clip(x, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


def linear_to_srgb(rgb: np.ndarray) -> np.ndarray:
    """(..., 3) linear colour -> (..., 3) uint8 sRGB: NaN as 0, clamped to [0, 1], the sRGB
    transfer curve, rounded half up. The package's one display encoder: every ``to_srgb8`` and
    every image metric goes through it."""
    c = np.clip(np.nan_to_num(rgb), 0.0, 1.0)
    return _u8(np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055))


#: Where :func:`auto_exposure` puts the log-average luminance (mid grey).
KEY = 0.18


def auto_exposure(rgb: np.ndarray, mask: Optional[np.ndarray] = None) -> float:
    """The scale that brings the log-average Rec. 709 luminance of the (H, W, 3) linear image's
    ``mask`` pixels (all by default) to :data:`KEY`, within 1/16..16; 1 where nothing is lit."""
    lum = np.nan_to_num(rgb.astype(np.float64)) @ np.array([0.2126, 0.7152, 0.0722])
    values = lum[mask] if mask is not None else lum.ravel()
    values = values[values > 0]
    if values.size == 0:
        return 1.0
    key = float(np.exp(np.mean(np.log(values + 1e-6))))
    return float(np.clip(KEY / key, 1 / 16, 16.0))


def depth_to_rgb(depth: np.ndarray) -> np.ndarray:
    """(H, W) depth -> (H, W, 3) uint8: near bright, far dark, empty black."""
    finite = np.isfinite(depth)
    out = np.zeros(depth.shape + (3,), np.uint8)
    if finite.any():
        lo, hi = np.quantile(depth[finite], [0.01, 0.99])
        t = 1.0 - (np.clip(depth, lo, hi) - lo) / max(hi - lo, 1e-12)
        ramp = np.stack([0.15 + 0.85 * t, 0.1 + 0.8 * t**1.5, 0.35 + 0.3 * t**3], -1)
        out[finite] = _u8(ramp[finite])
    return out


def normal_to_rgb(normal: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit normals -> (H, W, 3) uint8 (n * 0.5 + 0.5; empty black)."""
    zero = ~np.any(normal != 0, axis=-1)
    out = _u8(normal * 0.5 + 0.5)
    out[zero] = 0
    return out


def ids_to_rgb(ids: np.ndarray) -> np.ndarray:
    """(H, W) int ids -> (H, W, 3) uint8, a stable pseudo-random colour per id; -1 black."""
    h = (ids.astype(np.uint64) * np.uint64(2654435761)) & np.uint64(0xFFFFFF)
    rgb = np.stack([(h >> np.uint64(s)) & np.uint64(255) for s in (16, 8, 0)], -1).astype(np.uint8)
    rgb[ids < 0] = 0
    return rgb


def plain_sheet(rows: list[list[np.ndarray]]) -> np.ndarray:
    """(H, W, 3) uint8: the tiles of ``rows`` (each (h, w, 3) uint8, all of one size) in a grid,
    without labels (numpy only: what the demo writes when Pillow is missing)."""
    if not rows or any(len(r) != len(rows[0]) for r in rows):
        raise ValueError("plain_sheet: rows of equal length")
    return np.concatenate([np.concatenate(r, axis=1) for r in rows], axis=0).astype(np.uint8)


def labelled_sheet(
    rows: list[list[np.ndarray]], columns: list[str], row_labels: list[str]
) -> np.ndarray:
    """(H, W, 3) uint8: the tiles of ``rows`` (each (h, w, 3) uint8, all of one size) in a grid,
    each column's name above it and each row's at its left, in white on a dark margin.

    The labels are drawn with Pillow (the ``demo`` extra); without it,
    :class:`~scenesample.errors.MissingDependencyError` says so (:func:`plain_sheet` needs
    nothing)."""
    require("PIL", "the contact sheet's labels")
    from PIL import Image, ImageDraw, ImageFont

    if not rows or any(len(r) != len(columns) for r in rows) or len(row_labels) != len(rows):
        raise ValueError("labelled_sheet: one label per row and per column, rows of equal length")
    h, w = rows[0][0].shape[:2]
    size = max(12, min(24, w // 14))
    font = ImageFont.load_default(size=size)
    probe = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    left = 12 + max(int(probe.textlength(s, font=font)) for s in row_labels)
    top = size * 2
    sheet = Image.new("RGB", (left + w * len(columns), top + h * len(rows)), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    for j, name in enumerate(columns):
        x = left + j * w + (w - probe.textlength(name, font=font)) / 2
        draw.text((x, size // 2), name, fill=(235, 235, 235), font=font)
    for i, (label, tiles) in enumerate(zip(row_labels, rows)):
        y = top + i * h
        draw.text((6, y + (h - size) / 2), label, fill=(235, 235, 235), font=font)
        for j, tile in enumerate(tiles):
            sheet.paste(
                Image.fromarray(np.ascontiguousarray(tile, dtype=np.uint8)), (left + j * w, y)
            )
    return np.asarray(sheet)
