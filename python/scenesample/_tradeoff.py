"""What accuracy costs in time: sweep a method's accuracy knobs, measure each setting's error
against a reference, its time and its memory, and mark the Pareto front."""

from __future__ import annotations

import itertools
import math
import time
from concurrent.futures import Executor
from typing import Any, Optional

import numpy as np

from . import _core
from ._api import discretize, reconstruct
from ._evaluate import evaluate
from ._plan import emissive_lights
from ._progress import Bar, Progress
from ._scene import Scene
from .epr.omni import omni_shadows
from .epr.reflections import reflection_reference, reflections
from .errors import InputError
from .impostors.cells import ImpostorView
from .nonredundant.shadows import AreaLight, soft_shadows
from .visibility_field import Slab

__all__ = ["tradeoff", "KNOBS", "default_camera"]

Camera = _core.Camera
# Memory a setting of a sweep holds before and after it runs (its knobs, its row), in bytes.
_ROW_BYTES = 4096

# The accuracy knobs of each effect or method, and the values swept by default.
KNOBS: dict[str, dict[str, list]] = {
    "soft_shadows": {
        "discretization": ["nonredundant", "conventional", "peeling"],
        "resolution": [128, 256, 512],
        "samples": [4, 8],
    },
    "omni_shadows": {
        "method": ["mvr", "epr", "ivir"],
        "light_samples": [1, 5, 10],
        "rho_scale": [0.5],
    },
    "reflections": {
        "method": ["epr", "mvr", "ivir"],
        "rho_scale": [0.25, 0.5, 1.0],
        "bounces": [1, 2],
    },
    "visibility_field": {
        "quality": ["fast", "balanced", "exact"],
    },
    "impostors": {
        "octree_depth": [0, 1, 2],
        "resolution": [16, 32, 64],
    },
}

ERRORS = {
    "soft_shadows": "mean |visible fraction - reference| x 255 (reference: ray casting, 16x16 "
    "samples)",
    "omni_shadows": "mean |visible fraction - reference| x 255 (reference: ray casting, as many "
    "light samples as the sweep's largest)",
    "reflections": "RMSE on the 0-255 sRGB scale against MVR at 4x the eye's resolution",
    "visibility_field": "fraction of the visible cells the field missed",
    "impostors": "error per foreground pixel (0-765) against the triangles",
}


def default_camera(scene: Scene, size: int = 256) -> Camera:
    """The scene's first camera at ``size``², else one looking at its centre from 1.2
    diagonals along (1, 0.8, 0.6) (y or z up, whichever is the scene's shorter axis)."""
    if scene.cameras:
        c = scene.cameras[0]
        return c.with_resolution(size, size)
    lo, hi = scene.bounds.astype(np.float64)
    c, ext = (lo + hi) / 2, hi - lo
    up = np.array([0.0, 0.0, 1.0]) if ext[2] <= ext[1] else np.array([0.0, 1.0, 0.0])
    d = np.array([1.0, 0.8, 0.6]) if up[2] else np.array([1.0, 0.6, 0.8])
    eye = c + d / np.linalg.norm(d) * 1.2 * np.linalg.norm(ext)
    return Camera.look_at(tuple(eye), tuple(c), tuple(up), yfov=0.8, width=size, height=size)


def _camera_state(cam: Camera) -> tuple:
    return (
        np.asarray(cam.pose),
        cam.projection,
        cam.yfov,
        cam.xmag,
        cam.ymag,
        cam.width,
        cam.height,
        cam.znear,
        cam.zfar,
    )


def _camera(state: tuple) -> Camera:
    pose, proj, yfov, xmag, ymag, w, h, zn, zf = state
    if proj == "perspective":
        return Camera.from_pose(pose, yfov=yfov, width=w, height=h, znear=zn, zfar=zf)
    return Camera.orthographic(pose, xmag=xmag, ymag=ymag, width=w, height=h, znear=zn, zfar=zf)


def _light(scene: Scene, kind: str) -> Any:
    if kind == "soft_shadows":
        found = emissive_lights(scene)
        if found:
            return found[0][1]
        return AreaLight.above(scene, size=0.5, height=0.5, up=_up(scene))
    lo, hi = scene.bounds.astype(np.float64)
    for light in scene.lights:
        if light["type"] in ("point", "spot"):
            return (tuple(light["position"]), 0.02 * float(np.linalg.norm(hi - lo)))
    c = (lo + hi) / 2
    axis = "xyz".index(_up(scene))
    c[axis] = lo[axis] + 0.75 * (hi[axis] - lo[axis])
    return (tuple(c), 0.03 * float(np.linalg.norm(hi - lo)))


def _up(scene: Scene) -> str:
    lo, hi = scene.bounds.astype(np.float64)
    ext = hi - lo
    return "z" if ext[2] <= ext[1] else "y"


def _reference(kind: str, scene: Scene, cam: Camera, light: Any, knobs: dict) -> Any:
    if kind == "soft_shadows":
        r = soft_shadows(scene, cam, light, samples=(16, 16), discretization="raytraced")
        return (r.visibility, r.mask)
    if kind == "omni_shadows":
        n = max(knobs.get("light_samples", [20]))
        r = omni_shadows(scene, cam, *light, light_samples=n, method="raytraced")
        return (r.visibility, r.mask)
    if kind == "reflections":
        return reflection_reference(scene, cam)
    if kind == "visibility_field":
        return None
    return ImpostorView.of_triangles(scene, cam)


def _visibility_error(r: Any, ref: Any) -> float:
    """Mean |visible fraction - reference| x 255 over the pixels both see a surface at."""
    vis, mask = ref
    both = mask & r.mask
    return float(255 * np.abs(r.visibility[both] - vis[both]).mean())


def _run_soft_shadows(scene: Scene, cam: Camera, light: Any, ref: Any, settings: dict) -> dict:
    s = int(settings.get("samples", 8))
    start = time.perf_counter()
    r = soft_shadows(
        scene,
        cam,
        light,
        samples=(s, s),
        discretization=settings.get("discretization", "nonredundant"),
        resolution=int(settings.get("resolution", 512)),
    )
    seconds = time.perf_counter() - start
    memory = r.visibility.nbytes + r.visible.nbytes + r.mask.nbytes
    return {"error": _visibility_error(r, ref), "seconds": seconds, "memory": memory}


def _run_omni_shadows(scene: Scene, cam: Camera, light: Any, ref: Any, settings: dict) -> dict:
    start = time.perf_counter()
    r = omni_shadows(
        scene,
        cam,
        *light,
        light_samples=int(settings.get("light_samples", 20)),
        method=settings.get("method", "epr"),
        rho_scale=float(settings.get("rho_scale", 0.5)),
        max_resolution=int(settings.get("max_resolution", 512)),
    )
    seconds = time.perf_counter() - start
    return {
        "error": _visibility_error(r, ref),
        "seconds": seconds,
        "memory": int(r.stats.get("buffer_bytes", 0)) + r.visible.nbytes,
        "points": float(r.stats.get("points", 0)),
    }


def _run_reflections(scene: Scene, cam: Camera, light: Any, ref: Any, settings: dict) -> dict:
    start = time.perf_counter()
    r = reflections(
        scene,
        cam,
        method=settings.get("method", "epr"),
        rho_scale=float(settings.get("rho_scale", 0.5)),
        bounces=int(settings.get("bounces", 1)),
    )
    seconds = time.perf_counter() - start
    return {
        "error": float(evaluate(r, ref)["rmse"]),
        "seconds": seconds,
        "memory": int(r.stats.get("buffer_bytes", 0)),
        "shading_ops": float(r.stats.get("shading_ops", 0)),
    }


def _run_visibility_field(scene: Scene, cam: Camera, light: Any, ref: Any, settings: dict) -> dict:
    opts: dict[str, Any] = {"quality": settings.get("quality", "balanced")}
    if "resolution" in settings:
        res = int(settings["resolution"])
        opts["uv"] = opts["st"] = (res, res)
    if "ids_per_sample" in settings:
        opts["ids_per_sample"] = int(settings["ids_per_sample"])
    if settings.get("single_slab"):
        opts["slab"] = Slab.around(scene)
    start = time.perf_counter()
    field = discretize(scene, method="visibility_field", **opts)
    build = time.perf_counter() - start
    view = reconstruct(
        field,
        cam,
        interpolate=settings.get("interpolate"),
        fallback=bool(settings.get("fallback", True)),
    )
    m = evaluate(view, scene, "cells")
    return {
        "error": float(m["missed_fraction"]),
        "seconds": float(m["time_field"]),
        "memory": int(field.stats["memory_bytes"]),
        "build_seconds": build,
        "time_zbuffer": float(m["time_zbuffer"]),
        "hole_fraction": float(m["hole_fraction"]),
        "covered": float(view.covered),
        "cells_fraction": float(m["cells_fraction"]),
    }


def _run_impostors(scene: Scene, cam: Camera, light: Any, ref: Any, settings: dict) -> dict:
    start = time.perf_counter()
    imp = discretize(
        scene,
        method="impostors",
        octree_depth=int(settings.get("octree_depth", 2)),
        resolution=int(settings.get("resolution", 32)),
        subdivisions=int(settings.get("subdivisions", 2)),
    )
    build = time.perf_counter() - start
    view = reconstruct(imp, cam)
    return {
        "error": float(evaluate(view, ref)["error_per_foreground_pixel"]),
        "seconds": view.timings["total"],
        "memory": int(imp.stats["bytes_raw"]),
        "build_seconds": build,
    }


_RUNS = {
    "soft_shadows": _run_soft_shadows,
    "omni_shadows": _run_omni_shadows,
    "reflections": _run_reflections,
    "visibility_field": _run_visibility_field,
    "impostors": _run_impostors,
}


def _run(kind: str, scene: Scene, cam_state: tuple, light: Any, ref: Any, settings: dict) -> dict:
    """One row: run ``kind`` with ``settings``, time it, measure its error and memory."""
    row = _RUNS[kind](scene, _camera(cam_state), light, ref, settings)
    row["seconds"], row["memory"] = float(row["seconds"]), int(row["memory"])
    return row


def pareto(error: np.ndarray, seconds: np.ndarray) -> np.ndarray:
    """(n,) bool: rows no other row beats in both error and time (ties kept)."""
    e, s = np.asarray(error, dtype=np.float64), np.asarray(seconds, dtype=np.float64)
    front = np.ones(len(e), dtype=bool)
    for i in range(len(e)):
        dominated = (e <= e[i]) & (s <= s[i]) & ((e < e[i]) | (s < s[i]))
        front[i] = not dominated.any()
    return front


def tradeoff(
    scene: Scene,
    effect_or_method: str,
    *,
    knobs: Optional[dict[str, list]] = None,
    reference: Any = None,
    camera: Optional[Camera] = None,
    executor: Optional[Executor] = None,
    progress: Progress = None,
    as_frame: Optional[bool] = None,
) -> Any:
    """Sweep the accuracy knobs of an effect or method and tabulate what each setting costs.

    Parameters
    ----------
    scene : Scene
    effect_or_method : {"soft_shadows", "omni_shadows", "reflections", "visibility_field",
        "impostors"}
    knobs : dict of str to list, optional
        The values to sweep per knob (every combination runs); by default :data:`KNOBS`.
        Knobs not named keep their defaults. The visibility field's: ``quality`` (the
        default sweep: fast, balanced, exact), ``resolution`` (samples per plane axis),
        ``ids_per_sample``, ``interpolate``, ``fallback`` (False: the paper's resampling) and
        ``single_slab`` (True: the paper's one slab instead of six); its rows add
        ``hole_fraction``, ``covered`` and ``cells_fraction``.
    reference : optional
        What the error is measured against (see :data:`ERRORS`); computed by default: shadows
        by ray casting, reflections by MVR at 4x, impostors by the triangles. The visibility
        field always compares with a full rasterization.
    camera : Camera, optional
        The view (default :func:`default_camera`).
    executor : concurrent.futures.Executor, optional
        Runs the settings (one task each), e.g. a process pool or a dask cluster's
        ``client.get_executor()``; the scene and camera are pickled to the workers. Default:
        one after another in this process.
    progress : bool, callable or None
        A tqdm bar over the settings when tqdm is installed: None (default) once the sweep has
        run for 2 s, True at once, False never; a callable ``f(done, total)`` hears the count
        of settings done instead.
    as_frame : bool, optional
        Return a pandas DataFrame (default: when pandas is installed) or a numpy structured
        array.

    Returns
    -------
    DataFrame or structured array
        One row per setting: the knobs, ``error`` (see :data:`ERRORS`), ``seconds`` (the
        method's own time, measured where it ran), ``memory`` (bytes its results hold),
        extras per method (``points``, ``shading_ops``, ``build_seconds``, ...) and ``pareto``
        (on the error-time front).
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if effect_or_method not in KNOBS:
        raise InputError(f"effect_or_method must be one of {list(KNOBS)}, got {effect_or_method!r}")
    grid = dict(KNOBS[effect_or_method]) if knobs is None else dict(knobs)
    for k, v in grid.items():
        if not isinstance(v, (list, tuple)) or not v:
            raise InputError(f"knob {k!r} needs a non-empty list of values, got {v!r}")
    cam = default_camera(scene) if camera is None else camera
    if not isinstance(cam, Camera):
        raise InputError(f"camera must be a scenesample.Camera, got {type(cam).__name__}")
    if executor is not None and not hasattr(executor, "submit"):
        raise InputError("executor must be a concurrent.futures.Executor (with submit)")
    light = _light(scene, effect_or_method) if "shadows" in effect_or_method else None
    ref = _reference(effect_or_method, scene, cam, light, grid) if reference is None else reference
    names = list(grid)
    count = math.prod(len(v) for v in grid.values())
    # A setting's knobs and its row of results, before the grid is made.
    _core.check_memory(
        f"a tradeoff grid of {count} settings ({' x '.join(str(len(v)) for v in grid.values())})",
        min(count, 2**127),
        _ROW_BYTES,
    )
    settings = [dict(zip(names, combo)) for combo in itertools.product(*grid.values())]
    state = _camera_state(cam)
    bar = Bar(progress, f"tradeoff {effect_or_method}", "settings", total=len(settings))
    rows: list[Optional[dict]] = [None] * len(settings)
    if executor is None:
        for i, s in enumerate(settings):
            rows[i] = _run(effect_or_method, scene, state, light, ref, s)
            bar.update(1)
    else:
        from concurrent.futures import as_completed

        futures = {
            executor.submit(_run, effect_or_method, scene, state, light, ref, s): i
            for i, s in enumerate(settings)
        }
        for f in as_completed(futures):
            rows[futures[f]] = f.result()
            bar.update(1)
    bar.close()
    results = [r for r in rows if r is not None]
    front = pareto([r["error"] for r in results], [r["seconds"] for r in results])
    extras = sorted({k for r in results for k in r} - {"error", "seconds", "memory"})
    columns = {n: [s[n] for s in settings] for n in names}
    columns["error"] = [r["error"] for r in results]
    columns["seconds"] = [r["seconds"] for r in results]
    columns["memory"] = [r["memory"] for r in results]
    for k in extras:
        columns[k] = [r.get(k, np.nan) for r in results]
    columns["pareto"] = list(front)
    use_pandas = as_frame
    if use_pandas is None:
        try:
            import pandas  # noqa: F401

            use_pandas = True
        except ImportError:
            use_pandas = False
    if use_pandas:
        import pandas as pd

        frame = pd.DataFrame(columns)
        frame.attrs["error"] = ERRORS[effect_or_method]
        frame.attrs["effect"] = effect_or_method
        return frame
    return _structured(columns)


def _structured(columns: dict[str, list]) -> np.ndarray:
    dtypes = []
    for k, v in columns.items():
        a = np.asarray(v)
        if a.dtype.kind in "US" or a.dtype == object:
            dtypes.append((k, f"U{max(len(str(x)) for x in v)}"))
        else:
            dtypes.append((k, a.dtype))
    out = np.zeros(len(next(iter(columns.values()))), dtype=dtypes)
    for k, v in columns.items():
        out[k] = [str(x) if out.dtype[k].kind == "U" else x for x in v]
    return out
