"""Work for the child processes of tests/test_process.py: a module of its own, so that the
"spawn" start method can import it by name in a fresh interpreter."""

from __future__ import annotations

import numpy as np
import scenesample as ss

KNOBS = {"depth": [0, 1], "resolution": [8], "subdivisions": [1]}


def camera() -> ss.Camera:
    return ss.Camera.look_at((3.0, 2.5, 2.0), (0, 0, 0), (0, 0, 1), yfov=0.8, width=64, height=48)


def use_everything() -> dict[str, np.ndarray]:
    """Ray casts on the CPU pool, a depth image and a splat on the GPU: what a child needs to
    remake after a fork (the thread pool, the device, the scene's buffers on it)."""
    scene = ss.scenes.icosphere(3)
    cam = camera()
    o, d = (a.reshape(-1, 3) for a in cam.pixel_rays())
    hits = ss.cast_rays(scene, o, d)
    images = ss.discretize(scene, [cam], backend="gpu")
    tris = np.arange(scene.triangle_count)
    centers = scene.vertices[scene.faces].mean(axis=1).astype(np.float32)
    lengths = np.full(len(tris), 0.05, dtype=np.float32)
    splat = ss.splat(ss.Points.from_arrays(scene, centers, lengths, tris, cameras=[cam]))
    return {
        "ray_triangle": hits.triangle,
        "image_triangle": images.triangle,
        "splat_depth": splat.depth,
    }


def unpickled_scene(data: bytes) -> tuple[int, bool]:
    """Unpickle a scene (``Scene.from_arrays`` underneath): its triangles, and whether it is
    closed (a parallel weld and edge sort)."""
    import pickle

    scene = pickle.loads(data)
    return scene.triangle_count, scene.closed
