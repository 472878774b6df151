"""Shared fixtures: the GPU (tests that need it skip without one), reference tools, shared
scenes, and camera rigs."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import scenesample as ss

SHARED = ss.scenes.shared_scene_files()


@pytest.fixture(scope="session")
def gpu() -> dict:
    info = ss.device_info()
    if not info["available"]:
        pytest.skip(f"no GPU adapter: {info['error']}")
    return info


def load_quiet(path: Path) -> ss.Scene:
    """Load a shared scene; its expected warnings (missing images, unsimulated extensions) are
    checked in test_scene_gltf.py, not here."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ss.SceneWarning)
        return ss.Scene.load(path)


def orbit_cameras(
    scene: ss.Scene,
    n: int,
    width: int,
    height: int,
    yfov: float = 0.9,
    seed: int = 0,
    fill: float = 0.8,
) -> list[ss.Camera]:
    """n cameras on a sphere around the scene's bounds, each framing the whole bounding sphere."""
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds.astype(np.float64)
    centre = (lo + hi) / 2
    radius = max(np.linalg.norm(hi - lo) / 2, 1e-6)
    dist = radius / np.sin(yfov / 2) / fill
    cams = []
    for _ in range(n):
        d = rng.normal(size=3)
        d[1] = abs(d[1]) * 0.7 + 0.2
        d /= np.linalg.norm(d)
        cams.append(
            ss.Camera.look_at(
                centre + d * dist, centre, (0, 1, 0), yfov=yfov, width=width, height=height
            )
        )
    return cams


def silhouette(mask: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood holds both covered and empty pixels (per image)."""
    pad = np.pad(mask, ((0, 0), (1, 1), (1, 1)), mode="edge")
    h, w = mask.shape[1:]
    shifts = [
        pad[:, 1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)
    ]
    stack = np.stack(shifts)
    return stack.any(0) & ~stack.all(0)
