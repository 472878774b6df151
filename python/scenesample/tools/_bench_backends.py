"""``python -m scenesample.bench backends``: conventional depth images from the GPU raster path,
the CPU ray-cast path and ``backend="auto"``, side by side, on every shared real scene and one
large scene (four copies of the largest shared scene, over 4M triangles), at 640x480 and 1024²,
each from two sets of four views: the demo's orbit (the scene fills a third of the frame) and
the same views from three times as far ("sparse": a few percent of the pixels see the scene).
Then depth peeling (4 layers) the same way on the smallest real scene of at least 10K triangles,
the largest and the large one, from one view at 1024².

Every time is the best of ``repeats`` interleaved rounds after one warm-up call (so the scene
is on the GPU and its BVH built, as in a session that makes many images of one scene); ``auto``
then sees both prepared, which its cost model accounts for. The target: on every scene, size
and set of views the backend ``auto`` picks is within 10% of the faster one. That is judged on
the two backends' own times (best of the same rounds), since ``auto``'s call runs the backend
it picks; its own time is printed beside them, and differs from that backend's by lavapipe's
noise and the decision (a grid of at most 64x64 box tests per view). Also printed: ``auto``'s
prediction for both backends beside the measured times, and where the CPU's triangle ids
differ from the GPU's, and the crossover: the smallest scene on which the CPU was faster, per
size and kind of views, beside the size from which the cost model predicts it.
"""

from __future__ import annotations

import re
import time
import warnings
from typing import Any, Optional

import numpy as np

import scenesample as ss

from .demo import orbit

TARGET = 1.10
PEEL_LAYERS = 4
#: Peeling's smallest scene is the smallest with at least this many triangles.
PEEL_MIN_TRIANGLES = 10_000
SIZES = ((640, 480), (1024, 1024))
VIEWS = 4
#: How much farther the sparse views are than the orbit's.
SPARSE_DISTANCE = 3.0
BACKENDS = ("gpu", "cpu", "auto")


def _scenes(quick: bool) -> list[tuple[str, ss.Scene]]:
    out = []
    for name, path in ss.scenes.shared_scene_files().items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ss.SceneWarning)
            out.append((name, ss.Scene.load(path)))
    if not out:
        return [("procedural: shapes(detail=4)", ss.scenes.shapes(seed=0, detail=4))]
    if quick:
        out = [min(out, key=lambda x: abs(x[1].triangle_count - 20_000))]
    else:
        name, big = max(out, key=lambda x: x[1].triangle_count)
        out.append((f"{name} x4 (tiled)", _tiled(big, 2)))
    return out


def _tiled(scene: ss.Scene, k: int) -> ss.Scene:
    """``k x k`` copies of ``scene`` side by side on its x and y axes."""
    v, f = scene.vertices.astype(np.float64), scene.faces.astype(np.int64)
    lo, hi = v.min(0), v.max(0)
    step = (hi - lo) * 1.05
    verts, faces = [], []
    for i in range(k):
        for j in range(k):
            verts.append(v + np.array([i * step[0], j * step[1], 0.0]))
            faces.append(f + len(v) * (i * k + j))
    return ss.Scene.from_arrays(
        np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.uint32)
    )


def _camera(scene: ss.Scene, size: int) -> ss.Camera:
    lo, hi = scene.bounds.astype(np.float64)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    eye = c + r * np.array([0.9, -1.6, 0.8])
    up = (0.0, 0.0, 1.0)
    return ss.Camera.look_at(eye, c, up, yfov=0.8, width=size, height=size)


def views(scene: ss.Scene, kind: str, width: int, height: int) -> list[ss.Camera]:
    """The demo's orbit of ``VIEWS`` views (``kind="orbit"``), or the same views from
    ``SPARSE_DISTANCE`` times as far from the scene's centre (``"sparse"``)."""
    cams = orbit(scene, VIEWS, width, height)
    if kind == "orbit":
        return cams
    lo, hi = scene.bounds.astype(np.float64)
    c = (lo + hi) / 2
    return [
        ss.Camera.look_at(
            c + (np.asarray(cam.eye) - c) * SPARSE_DISTANCE, c, yfov=0.8, width=width, height=height
        )
        for cam in cams
    ]


def _predicted(reason: str) -> tuple[float, float]:
    """``auto``'s predictions (seconds) from its reason ("predicted gpu X ms vs cpu Y ms ...");
    NaN where it decided without predicting (no adapter, a size only one backend takes)."""
    m = re.search(r"predicted gpu ([0-9.]+) ms vs cpu ([0-9.]+) ms", reason)
    return (float(m[1]) / 1e3, float(m[2]) / 1e3) if m else (float("nan"), float("nan"))


def predicted_crossover(width: int, height: int, images: int = VIEWS) -> Optional[int]:
    """The smallest scene (triangles, to within 5%) for which this machine's cost model
    predicts the CPU faster than the GPU, for ``images`` images of ``width`` x ``height``
    (three quarters of their pixels on the scene's box, BVH built, scene uploaded): bisection
    on ``device_info``'s predictions. None when the CPU is predicted faster at every size from
    100 to 10^9 triangles or at none (no adapter: always)."""

    def cpu_faster(triangles: int) -> bool:
        a = ss.device_info(triangles=triangles, pixels=width * height, images=images)["auto"]
        return a["gpu_seconds"] is None or a["cpu_seconds"] < a["gpu_seconds"]

    lo, hi = 100, 10**9
    if cpu_faster(lo) or not cpu_faster(hi):
        return None
    while hi > lo * 1.05:
        mid = int(np.sqrt(lo * hi))
        lo, hi = (lo, mid) if cpu_faster(mid) else (mid, hi)
    return hi


def measured_crossover(rows: list[dict[str, Any]], size: list[int], kind: str) -> dict[str, Any]:
    """Of the rows of one image size and kind of views: the smallest scene (triangles) on
    which the CPU was faster, and how many larger scenes the GPU still won and smaller ones
    the CPU did (the scenes differ in more than size, so the line is not sharp)."""
    mine = sorted(
        (r for r in rows if r["size"] == size and r["views"] == kind), key=lambda r: r["triangles"]
    )
    cpu = [r["triangles"] for r in mine if r["cpu"] < r["gpu"]]
    first = cpu[0] if cpu else None
    return {
        "size": size,
        "views": kind,
        "first_cpu": first,
        "gpu_above": sum(r["cpu"] >= r["gpu"] for r in mine if first and r["triangles"] > first),
        "scenes": len(mine),
    }


def run(quick: bool = False, repeats: int = 5) -> dict[str, Any]:
    """Measure every scene, size and set of views; returns the rows and the device."""
    sizes = ((320, 240),) if quick else SIZES
    rows, peel_rows = [], []
    scenes = _scenes(quick)
    for name, scene in scenes:
        for width, height in sizes:
            for kind in ("orbit", "sparse"):
                cams = views(scene, kind, width, height)
                times, images = _timed(scene, cams, repeats)
                rows.append(
                    {
                        "scene": name,
                        "triangles": scene.triangle_count,
                        "size": [width, height],
                        "views": kind,
                        "covered": float(images["gpu"].mask.mean()),
                        **_compared(scene, times, images),
                    }
                )
                print(_row(rows[-1]), flush=True)
    # Peeling: the smallest and largest real scene (by triangles) and the tiling.
    by_size = sorted(scenes, key=lambda x: x[1].triangle_count)
    sizable = [x for x in by_size if x[1].triangle_count >= PEEL_MIN_TRIANGLES] or by_size
    chosen = by_size if quick else [sizable[0], *by_size[-2:]]
    size = 256 if quick else 1024
    for name, scene in chosen:
        cam = _camera(scene, size)
        times, images = _timed(scene, cam, repeats, "peeling", layers=PEEL_LAYERS)
        g, c = images["gpu"], images["cpu"]
        differ = g.triangle != c.triangle
        first = differ & (np.cumsum(differ, axis=0) - differ == 0)
        tie = np.isclose(g.depth, c.depth, rtol=1e-5)
        peel_rows.append(
            {
                "scene": name,
                "triangles": scene.triangle_count,
                **{b: times[b] for b in ("gpu", "cpu", "auto")},
                "auto_backend": images["auto"].backend,
                "same_pixels": float(1.0 - differ.any(axis=0).mean()),
                "first_differ_not_tie": float((first & ~tie).any(axis=0).mean()),
            }
        )
        print(_peel_row(peel_rows[-1]), flush=True)
    info = ss.device_info()
    crossover = [
        {
            **measured_crossover(rows, [w, h], kind),
            "predicted": predicted_crossover(w, h) if info["available"] else None,
        }
        for w, h in sizes
        for kind in ("orbit", "sparse")
    ]
    return {
        "rows": rows,
        "crossover": crossover,
        "peeling": peel_rows,
        "size": size,
        "sizes": [list(x) for x in sizes],
        "repeats": repeats,
        "device": info,
    }


def _compared(scene: ss.Scene, times: dict[str, float], images: dict[str, Any]) -> dict[str, Any]:
    """The times, auto's choice and predictions, and how the two backends' images agree."""
    g, c = images["gpu"], images["cpu"]
    either = (g.triangle >= 0) | (c.triangle >= 0)
    differ = g.triangle != c.triangle
    hit = (g.triangle >= 0) & (c.triangle >= 0)
    split = differ & hit
    rel = np.abs(g.depth[hit].astype(np.float64) - c.depth[hit]) / g.depth[hit]
    predicted_gpu, predicted_cpu = _predicted(images["auto"].backend_reason)
    return {
        "gpu": times["gpu"],
        "cpu": times["cpu"],
        "auto": times["auto"],
        "auto_backend": images["auto"].backend,
        "predicted_gpu": predicted_gpu,
        "predicted_cpu": predicted_cpu,
        "same_ids": float(1.0 - differ.mean()),
        "same_ids_covered": float(1.0 - differ[either].mean()) if either.any() else 1.0,
        "differ_adjacent": _adjacent(scene, g.triangle[split], c.triangle[split]),
        "depth_rel_median": float(np.median(rel)) if rel.size else 0.0,
        "depth_rel_p999": float(np.quantile(rel, 0.999)) if rel.size else 0.0,
    }


def _timed(
    scene: ss.Scene,
    cam: ss.Camera | list[ss.Camera],
    repeats: int,
    method: str = "conventional",
    **options: Any,
) -> tuple[dict[str, float], dict[str, Any]]:
    """Best of ``repeats`` interleaved rounds of ``discretize(scene, cam, method, **options,
    backend=b)`` per backend, after a warm-up call of each; the times and each last result."""

    def call(b: str) -> Any:
        return ss.discretize(scene, cam, method, backend=b, **options)

    results = {b: call(b) for b in BACKENDS}  # warm-up
    rounds: dict[str, list[float]] = {b: [] for b in BACKENDS}
    for _ in range(repeats):  # interleaved, so that a slow spell hits all three
        for b in BACKENDS:
            t = time.perf_counter()
            results[b] = call(b)
            rounds[b].append(time.perf_counter() - t)
    return {b: min(v) for b, v in rounds.items()}, results


def _adjacent(scene: ss.Scene, a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of the triangle pairs (a[i], b[i]) that share a vertex position (1 when none)."""
    if a.size == 0:
        return 1.0
    v, f = scene.vertices, scene.faces
    pa, pb = v[f[a]], v[f[b]]
    same = np.abs(pa[:, :, None, :] - pb[:, None, :, :]).max(-1) == 0
    return float(same.any((1, 2)).mean())


def choice_ratio(r: dict[str, Any]) -> float:
    """The time of the backend ``auto`` picked over the faster backend's."""
    return r[r["auto_backend"]] / min(r["gpu"], r["cpu"])


def _row(r: dict[str, Any]) -> str:
    ratio = choice_ratio(r)
    w, h = r["size"]
    return (
        f"| {r['scene']} | {r['triangles']:,} | {r['gpu'] * 1e3:.0f} | {r['cpu'] * 1e3:.0f} | "
        f"{r['auto'] * 1e3:.0f} ({r['auto_backend']}) | {ratio:.2f}x | {w}x{h} | "
        f"{r['views']} | {r['covered'] * 100:.0f}% | "
        f"{r['predicted_gpu'] * 1e3:.0f} / {r['predicted_cpu'] * 1e3:.0f} | "
        f"{r['same_ids'] * 100:.3f}% | {r['same_ids_covered'] * 100:.3f}% | "
        f"{r['differ_adjacent'] * 100:.1f}% | {r['depth_rel_p999']:.1e} |"
    )


def _peel_row(r: dict[str, Any]) -> str:
    ratio = r["auto"] / min(r["gpu"], r["cpu"])
    return (
        f"| {r['scene']} | {r['triangles']:,} | {r['gpu'] * 1e3:.0f} | {r['cpu'] * 1e3:.0f} | "
        f"{r['auto'] * 1e3:.0f} ({r['auto_backend']}) | {ratio:.2f}x | "
        f"{r['same_pixels'] * 100:.3f}% | {r['first_differ_not_tie'] * 100:.3f}% |"
    )


def report(r: dict[str, Any]) -> str:
    rows = r["rows"]
    ratios = [choice_ratio(x) for x in rows]
    worst = int(np.argmax(ratios))
    dev = r["device"]
    lines = [
        f"# `python -m scenesample.bench backends`, {time.strftime('%Y-%m-%d')}",
        "",
        f"{dev['name']} ({dev['device_type']}); {VIEWS} conventional images per call, from the "
        f"demo's orbit views or from {SPARSE_DISTANCE:g} times as far (sparse), best of "
        f"{r['repeats']} interleaved rounds after a warm-up (scene uploaded, BVH built). "
        "Covered: pixels that see a surface. Times in ms; auto: its own call's time and the "
        "backend it picked; auto / fastest: the picked backend's time over the faster one's "
        f"(target <= {TARGET:.2f}x on every row); predicted: the cost "
        "model's gpu / cpu estimate; same "
        "ids: pixels where both name the same triangle (or none), of all pixels and of those "
        "where either sees a surface; at an edge: of the pixels where both see a different "
        "triangle, those whose two triangles share a vertex; depth: 99.9th percentile of "
        "|gpu - cpu| / gpu where both see a surface.",
        "",
        "| scene | triangles | gpu | cpu | auto | auto / fastest | size | views | covered | "
        "predicted | same ids | same ids (covered) | at an edge | depth |",
        "|---|---:|---:|---:|---:|---:|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    lines += [_row(x) for x in rows]
    verdict = "met" if max(ratios) <= TARGET else "NOT met"
    lines += [
        "",
        f"Worst scene: {rows[worst]['scene']} at {rows[worst]['size'][0]}x"
        f"{rows[worst]['size'][1]} ({rows[worst]['views']} views), auto {ratios[worst]:.2f}x "
        f"the faster backend (target <= {TARGET:.2f}x on every row): {verdict}. Rows over the "
        f"target: {sum(x > TARGET for x in ratios)} of {len(ratios)}.",
    ]
    cross = r.get("crossover", [])
    if cross:
        lines += [
            "",
            "Crossover: the smallest scene on which the CPU backend was faster than the GPU "
            f"one, per image size and kind of views ({VIEWS} images per call), with the larger "
            "scenes the GPU still won; and the size from which this machine's cost model "
            "predicts the CPU faster (three quarters of the pixels on the scene's box, as "
            "`device_info(triangles=, pixels=, images=)` predicts).",
            "",
            "| size | views | CPU faster from (measured) | larger scenes the GPU won | "
            "CPU faster from (model) |",
            "|---|---|---:|---:|---:|",
            *[
                f"| {c['size'][0]}x{c['size'][1]} | {c['views']} | "
                + (f"{c['first_cpu']:,}" if c["first_cpu"] else "never")
                + f" | {c['gpu_above']} of {c['scenes']} | "
                + (f"{c['predicted']:,}" if c["predicted"] else "n/a")
                + " |"
                for c in cross
            ],
        ]
    peel = r.get("peeling", [])
    if peel:
        lines += [
            "",
            f"Depth peeling, {PEEL_LAYERS} layers at {r['size']}², timed the same way; same "
            "pixels: pixels whose layers all name the same triangles on both backends; first "
            "difference not a tie: pixels whose first differing layer shows the two at "
            "different depths (an edge; the deeper layers of such a pixel follow from it).",
            "",
            "| scene | triangles | gpu | cpu | auto | auto / fastest | same pixels | "
            "first difference not a tie |",
            "|---|---:|---:|---:|---:|---:|---:|---:|",
            *[_peel_row(x) for x in peel],
        ]
    return "\n".join(lines) + "\n"
