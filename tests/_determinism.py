"""Every method's arrays on two shared scenes, reduced to digests, for tests/test_determinism.py:
a module of its own so that spawned workers and fresh interpreters import it by name.

Run as a script it prints the digests as JSON: `python tests/_determinism.py [order]`."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import pickle
import sys
import threading
import warnings
from typing import Any, Callable

import numpy as np
import scenesample as ss

# A scene with area and point lights (soft and omnidirectional shadows), and one with metallic
# materials (reflections): together they call for every effect `render` simulates.
SCENES = ("khr_lights_punctual_lamp", "khr_transmission_test")
SIZE = 64


_LOADING = threading.Lock()


def _scene(name: str) -> ss.Scene:
    # catch_warnings is not thread-safe: threads running digests() load one at a time.
    with _LOADING, warnings.catch_warnings():
        warnings.simplefilter("ignore", ss.SceneWarning)
        return ss.Scene.load(ss.scenes.shared_scene_files()[name])


def _cameras(scene: ss.Scene, n: int = 3) -> list[ss.Camera]:
    lo, hi = (np.asarray(b, np.float64) for b in scene.bounds)
    c, r = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    dirs = [(0.6, 0.4, 0.9), (-0.8, 0.5, 0.5), (0.2, 0.9, -0.7)]
    return [
        ss.Camera.look_at(
            c + r * np.asarray(d) / np.linalg.norm(d), c, yfov=0.8, width=SIZE, height=SIZE
        )
        for d in dirs[:n]
    ]


def _moved(scene: ss.Scene) -> tuple[np.ndarray, np.ndarray]:
    """Per object a small turn and lift (a rigid pose: a two-level tree), and every vertex
    lifted by a wave (a deformation: a refit tree)."""
    lo, hi = (np.asarray(b, np.float64) for b in scene.bounds)
    n = len(scene.objects)
    a = np.linspace(-0.2, 0.2, n)
    m = np.array([np.eye(4) for _ in range(n)])
    m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
    m[:, 2, 3] = np.linspace(0, 0.05, n) * (hi - lo)[2]
    v = scene.vertices.astype(np.float64)
    v[:, 1] += 0.03 * (hi - lo)[1] * np.sin(6.0 * (v[:, 0] - lo[0]) / max(hi[0] - lo[0], 1e-9))
    return m, v.astype(np.float32)


def _skip(key: str) -> bool:
    """Fields that measure the run rather than its answer."""
    k = key.lower()
    return k in ("timings", "stats_seconds") or "seconds" in k or k in ("memory_peak",)


def digest(obj: Any, at: str, out: dict[str, str]) -> None:
    """Add a sha256 (of dtype, shape and bytes) of every array reachable from `obj` to `out`,
    keyed by its path; plain numbers and strings are kept as they are."""
    if isinstance(obj, np.ndarray):
        h = hashlib.sha256(f"{obj.dtype}{obj.shape}".encode())
        h.update(np.ascontiguousarray(obj).tobytes())
        out[at] = h.hexdigest()[:16]
    elif isinstance(obj, dict):
        for k, v in obj.items():
            if not _skip(str(k)):
                digest(v, f"{at}.{k}", out)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            digest(v, f"{at}[{i}]", out)
    elif isinstance(obj, (bool, int, float, str, type(None))):
        out[at] = repr(obj)
    elif hasattr(obj, "as_dict"):
        digest(obj.as_dict(), at, out)
    elif dataclasses.is_dataclass(obj):
        digest({f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}, at, out)
    elif isinstance(obj, ss.Camera):
        out[at] = repr(obj)
    else:
        out[at] = type(obj).__name__


def calls(name: str) -> list[tuple[str, Callable[[], Any]]]:
    """Every method on scene `name`, each a (label, call) pair."""
    scene = _scene(name)
    cams = _cameras(scene)
    eye = cams[0]
    lo, hi = (np.asarray(b, np.float64) for b in scene.bounds)
    o, d = (a.reshape(-1, 3) for a in eye.pixel_rays())
    light = ss.AreaLight.above(scene, size=float(np.linalg.norm(hi - lo)) * 0.2)
    centre, radius = (lo + hi) / 2 + [0, 0.4 * (hi - lo)[1], 0], 0.05 * np.linalg.norm(hi - lo)

    def nr():
        return ss.discretize(scene, cams, "nonredundant")

    def field_view():
        field = ss.discretize(scene, method="visibility_field", uv=(8, 8), st=(8, 8))
        return field.as_dict() | {
            "view": ss.reconstruct(field, eye),
            "cpu view": ss.reconstruct(field, eye, backend="cpu"),
            # The field restored from its pickle (its sorted scene and BVH rebuilt).
            "unpickled view": ss.reconstruct(pickle.loads(pickle.dumps(field)), eye),
        }

    def impostor_view():
        imp = ss.discretize(scene, method="impostors", octree_depth=1, resolution=16)
        return {"impostors": imp, "view": ss.reconstruct(imp, eye, triangle_budget=1000,
                                                          scene=scene)}  # fmt: skip

    def epr():
        pts = ss.discretize(scene, method="epr", eye=eye, resolution=32)
        return {"points": pts, "splat": ss.splat(pts, resolution=32)}

    poses, wave = _moved(scene)
    out = [
        ("cast_rays", lambda: ss.cast_rays(scene, o, d)),
        ("posed_rays", lambda: ss.cast_rays(scene.posed(poses), o, d)),
        ("deformed_rays", lambda: ss.cast_rays(scene.deformed(wave), o, d)),
        ("cast_rays_k3", lambda: ss.cast_rays(scene, o, d, max_hits=3)),
        ("occluded", lambda: ss.occluded(scene, o, d, t_max=0.5)),
        ("conventional", lambda: ss.discretize(scene, cams)),
        ("conventional_gpu", lambda: ss.discretize(scene, cams, backend="gpu")),
        ("conventional_cpu", lambda: ss.discretize(scene, cams, backend="cpu")),
        ("peeling", lambda: ss.discretize(scene, eye, "peeling", layers=3)),
        ("nonredundant", nr),
        ("nonredundant_visibility",
         lambda: ss.discretize(scene, cams, "nonredundant", redundancy="visibility")),
        ("reconstruct_hybrid", lambda: ss.reconstruct(nr(), "hybrid")),
        ("reconstruct_points", lambda: ss.reconstruct(nr(), "points")),
        ("field", field_view),
        ("impostors", impostor_view),
        ("epr", epr),
        ("reflections_epr", lambda: ss.reflections(scene, eye, method="epr")),
        ("reflections_mvr", lambda: ss.reflections(scene, eye, method="mvr")),
        ("omni_shadows", lambda: ss.omni_shadows(scene, eye, centre, radius, light_samples=4)),
        ("soft_shadows", lambda: ss.soft_shadows(scene, eye, light, samples=(4, 4),
                                                 resolution=SIZE)),  # fmt: skip
    ]  # fmt: skip
    if name == SCENES[0]:  # the second scene's nine emissive objects take seconds to render
        out.append(("render", lambda: ss.render(scene, eye, quality="fast")))
    return out


def digests(order: str = "forward") -> dict[str, str]:
    """Digests of every call on both scenes, run in `order` ("forward" or "reverse")."""
    todo = [(f"{name}/{label}", f) for name in SCENES for label, f in calls(name)]
    if order == "reverse":
        todo.reverse()
    out: dict[str, str] = {}
    for label, f in todo:
        try:
            result = f()
        except ss.ScenesampleError as e:  # a method the scene cannot take: the error is its answer
            result = f"{type(e).__name__}: {e}"
        digest(result, label, out)
    return dict(sorted(out.items()))


if __name__ == "__main__":
    sys.stdout.write(json.dumps(digests(sys.argv[1] if len(sys.argv) > 1 else "forward")) + "\n")
