"""``python -m scenesample.bench rays``: CPU ray queries against Embree (embreex, one thread) and
Open3D's ``RaycastingScene`` (Embree on every core), on every shared real scene of at least 10K
triangles plus one procedural scene, for four ray sets, with build time and memory.

Each (scene, ray set) is timed in interleaved rounds (ours, then the peer, then ours on every
core, then Open3D), so that a slow moment of a shared machine hits both sides of a ratio; a ratio
is the median over rounds of peer time / our time (> 1: we are faster), and Mrays/s are the best
round's. Inputs are the same arrays for every tool; times are wall times of the Python call, as a
user sees them.
"""

from __future__ import annotations

import datetime
import os
import platform
import time
from collections.abc import Callable
from typing import Any, Optional

import numpy as np

import scenesample as ss

# Issue targets, checked on every scene (not on average).
TARGET_PRIMARY_1T = 1.5
TARGET_INCOHERENT_1T = 1.2
TARGET_OTHER_1T = 1.0
TARGET_INCOHERENT_ALL = 1.2
TARGET_ALL_CORES = 1.0
TARGET_MEMORY = 1.25
TARGET_BUILD = 1.5
TARGET_ANY_OVER_CLOSEST = 1.0  # occluded is never slower than the closest hit
TARGET_HITS = 1.2  # count_hits and all_hits against Open3D's count and list of intersections
MIN_TRIANGLES = 10_000
RAY_SETS = ("primary", "shuffled", "incoherent", "occlusion")
# Occlusion rays start this fraction of their segment off the surface and stop as short of the
# light, so that no tool needs a t_min (embreex has none).
SEGMENT_MARGIN = 1e-4


def bench_scenes(quick: bool) -> list[tuple[str, ss.Scene]]:
    """Every shared scene of at least 10K triangles (all of them, the instanced 1M-triangle
    spheres included; quick skips scenes over 500K triangles), then `scenes.shapes`."""
    import warnings

    out = []
    for name, path in ss.scenes.shared_scene_files().items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ss.SceneWarning)
            scene = ss.Scene.load(path)
        if scene.triangle_count < MIN_TRIANGLES or (quick and scene.triangle_count > 500_000):
            continue
        out.append((name, scene))
    out.append(("procedural: shapes(detail=4)", ss.scenes.shapes(seed=0, detail=2 if quick else 4)))
    return out


def ray_sets(
    scene: ss.Scene, width: int, height: int, seed: int = 7
) -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """The four ray sets: (origins, directions, t_max), float32 C-contiguous.

    - primary: a camera framing the scene's bounding sphere, pixel centres in image order;
    - shuffled: the same rays in a random order;
    - incoherent: from uniform points in the scene's box towards other uniform points in it;
    - occlusion: from the surface points the primary rays hit (in image order, repeated to as
      many rays) towards uniform points of a square light above the scene (a quarter of its
      width on a side), as segments (``t_max = 1``).
    """
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds.astype(np.float64)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    fov = 0.8
    toward = np.array([0.55, 0.45, 0.7]) / np.linalg.norm([0.55, 0.45, 0.7])
    cam = ss.Camera.look_at(
        c + toward * r / np.sin(fov / 2) * 0.85, c, yfov=fov, width=width, height=height
    )
    o, d = (a.reshape(-1, 3) for a in cam.pixel_rays())
    out = {"primary": (o, d, np.inf)}
    p = rng.permutation(len(o))
    out["shuffled"] = (np.ascontiguousarray(o[p]), np.ascontiguousarray(d[p]), np.inf)
    n = width * height
    a = rng.uniform(lo, hi, (n, 3))
    b = rng.uniform(lo, hi, (n, 3))
    out["incoherent"] = (a.astype(np.float32), (b - a).astype(np.float32), np.inf)
    hits = ss.cast_rays(scene, o, d)
    visible = np.flatnonzero(hits.hit)
    if len(visible) == 0:
        raise RuntimeError("the benchmark camera sees nothing of the scene")
    visible = np.repeat(visible, -(-n // len(visible)))[:n]
    points = o[visible].astype(np.float64) + d[visible] * hits.t[visible, None].astype(np.float64)
    ext = hi - lo
    light = np.array([c[0], hi[1] + 0.1 * ext[1], c[2]])
    light = light + rng.uniform(-0.125, 0.125, (n, 1)) * [ext[0], 0, 0]
    light = light + rng.uniform(-0.125, 0.125, (n, 1)) * [0, 0, ext[2]]
    seg = light - points
    out["occlusion"] = (
        (points + SEGMENT_MARGIN * seg).astype(np.float32),
        (seg * (1 - 2 * SEGMENT_MARGIN)).astype(np.float32),
        1.0,
    )
    return out


def cpu_model() -> str:
    """The processor's model name (``/proc/cpuinfo`` on Linux), else the architecture: ratios
    against Embree depend on it, since Embree picks its kernels by instruction set."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _seconds(fn: Callable[[], Any]) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def bench_build(scene: ss.Scene, rounds: int) -> dict[str, float]:
    """Best wall time of a fresh BVH plus one ray, for each tool, in interleaved rounds."""
    one = (np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
    best = {"ours": np.inf, "embreex": np.inf, "open3d": np.inf}
    for _ in range(rounds):
        # A new Scene has no cached BVH: its first query builds one.
        best["ours"] = min(
            best["ours"],
            _seconds(lambda: ss.cast_rays(ss.Scene.from_arrays(scene.vertices, scene.faces), *one)),
        )
        best["embreex"] = min(
            best["embreex"], _seconds(lambda: ss.references.EmbreeReference(scene).commit())
        )
        best["open3d"] = min(
            best["open3d"], _seconds(lambda: ss.references.Open3DReference(scene).commit())
        )
    return best


def bench_scene_rays(
    scene: ss.Scene, sets: dict[str, tuple[np.ndarray, np.ndarray, float]], rounds: int
) -> dict[str, dict[str, Any]]:
    """Per ray set: best Mrays/s of each tool, median ratios, and how often the hits agree."""
    embree = ss.references.EmbreeReference(scene)
    open3d = ss.references.Open3DReference(scene)
    embree.commit()
    open3d.commit()
    ss.cast_rays(scene, *(a[:1] for a in sets["primary"][:2]))  # our BVH, cached
    out = {}
    for kind, (o, d, t_max) in sets.items():
        tools = _tools(scene, embree, open3d, kind, o, d, t_max)
        times: dict[str, list[float]] = {k: [] for k in tools}
        for _ in range(rounds):
            for k, fn in tools.items():
                times[k].append(_seconds(fn))
        t = {k: np.array(v) for k, v in times.items()}
        n = len(o)
        out[kind] = {
            "rays": n,
            "mrays": {k: n / v.min() / 1e6 for k, v in t.items()},
            "one_thread": float(np.median(t["embreex"] / t["ours_1t"])),
            "all_cores": float(np.median(t["open3d"] / t["ours_all"])),
            # From one thread to every core: each tool's own speedup.
            "scaling": float(np.median(t["ours_1t"] / t["ours_all"])),
            "open3d_scaling": float(np.median(t["open3d_1t"] / t["open3d"])),
            "agree": _agreement(scene, embree, kind, o, d, t_max),
        }
        if "closest_1t" in t:
            # What stopping at the first hit buys over the closest hit, on the same rays.
            out[kind]["any_over_closest"] = float(np.median(t["closest_1t"] / t["ours_1t"]))
        if "count" in t:
            out[kind]["count"] = float(np.median(t["open3d_count"] / t["count"]))
            out[kind]["list"] = float(np.median(t["open3d_list"] / t["list"]))
    return out


def _tools(
    scene: ss.Scene,
    embree: Any,
    open3d: Any,
    kind: str,
    o: np.ndarray,
    d: np.ndarray,
    t_max: float,
) -> dict[str, Callable[[], Any]]:
    """The four timed calls on one ray set: any-hit queries for occlusion rays, closest hits
    otherwise."""
    if kind == "occlusion":
        return {
            "ours_1t": lambda: ss.occluded(scene, o, d, t_max=t_max, threads=1),
            "closest_1t": lambda: ss.cast_rays(scene, o, d, t_max=t_max, threads=1),
            "embreex": lambda: embree.occluded(o, d, t_max),
            "ours_all": lambda: ss.occluded(scene, o, d, t_max=t_max),
            "open3d": lambda: open3d.occluded(o, d, t_max),
            "open3d_1t": lambda: open3d.occluded(o, d, t_max, threads=1),
        }
    tools = {
        "ours_1t": lambda: ss.cast_rays(scene, o, d, threads=1),
        "embreex": lambda: embree.cast(o, d),
        "ours_all": lambda: ss.cast_rays(scene, o, d),
        "open3d": lambda: open3d.cast(o, d),
        "open3d_1t": lambda: open3d.cast(o, d, threads=1),
    }
    if kind == "incoherent":
        # Every hit along the rays, counted and listed (whole rays, on every core).
        tools |= {
            "count": lambda: ss.count_hits(scene, o, d),
            "open3d_count": lambda: open3d.count_hits(o, d),
            "list": lambda: ss.all_hits(scene, o, d),
            "open3d_list": lambda: open3d.all_hits(o, d),
        }
    return tools


def _agreement(
    scene: ss.Scene, embree: Any, kind: str, o: np.ndarray, d: np.ndarray, t_max: float
) -> float:
    """Fraction of rays where we and Embree report the same triangle (or the same verdict)."""
    if kind == "occlusion":
        return float(np.mean(ss.occluded(scene, o, d, t_max=t_max) == embree.occluded(o, d, t_max)))
    return float(np.mean(ss.cast_rays(scene, o, d).triangle == embree.cast(o, d)["triangle"]))


def run(
    quick: bool = False, rounds: Optional[int] = None, only: Optional[list[str]] = None
) -> dict[str, Any]:
    """Measure every scene; returns the raw figures (see :func:`report`)."""
    width, height = (320, 240) if quick else (1024, 768)
    rounds = rounds or (1 if quick else 5)
    results: dict[str, Any] = {
        "rays": width * height,
        "rounds": rounds,
        "cores": os.cpu_count(),
        "cpu": cpu_model(),
        "scenes": {},
    }
    for name, scene in bench_scenes(quick):
        if only and not any(o in name for o in only):
            continue
        build = bench_build(scene, max(rounds, 3))
        stats = ss.bvh_stats(scene)
        embree_bytes = ss.references.embree_memory(scene)
        sets = ray_sets(scene, width, height)
        results["scenes"][name] = {
            "triangles": scene.triangle_count,
            "build": build,
            "bytes_per_triangle": {
                "ours": stats["bytes"] / scene.triangle_count,
                "embree": embree_bytes / scene.triangle_count,
            },
            "sets": bench_scene_rays(scene, sets, rounds),
        }
        print(f"  {name}: done", flush=True)
    return results


def _targets(kind: str) -> tuple[float, float]:
    """(1 thread against embreex, every core against Open3D) for a ray set."""
    one = {"primary": TARGET_PRIMARY_1T, "incoherent": TARGET_INCOHERENT_1T}
    every = {"incoherent": TARGET_INCOHERENT_ALL}
    return one.get(kind, TARGET_OTHER_1T), every.get(kind, TARGET_ALL_CORES)


def summary_rows(r: dict[str, Any]) -> list[tuple[str, float, float, str, float, bool]]:
    """(comparison, geometric mean, worst ratio, worst scene, target, met) for each target;
    build and memory ratios are ours / Embree's (lower is better), the others peer / ours."""
    scenes = r["scenes"]
    rows = []

    def add(label: str, values: dict[str, float], target: float, higher_better: bool) -> None:
        names = list(values)
        v = np.array([values[k] for k in names])
        worst = int(np.argmin(v) if higher_better else np.argmax(v))
        ok = v[worst] >= target if higher_better else v[worst] <= target
        gmean = float(np.exp(np.mean(np.log(v))))
        rows.append((label, gmean, float(v[worst]), names[worst], target, bool(ok)))

    for kind in RAY_SETS:
        one, every = _targets(kind)
        add(
            f"{kind}: 1 thread vs embreex",
            {n: s["sets"][kind]["one_thread"] for n, s in scenes.items()},
            one,
            True,
        )
        add(
            f"{kind}: all cores vs Open3D",
            {n: s["sets"][kind]["all_cores"] for n, s in scenes.items()},
            every,
            True,
        )
    add(
        "occlusion: occluded / cast_rays speed (1 thread, same rays)",
        {n: s["sets"]["occlusion"]["any_over_closest"] for n, s in scenes.items()},
        TARGET_ANY_OVER_CLOSEST,
        True,
    )
    for key, label in (("count", "count_hits"), ("list", "all_hits")):
        add(
            f"incoherent: {label} vs Open3D's {'count' if key == 'count' else 'list'}"
            "_intersections (all cores)",
            {n: s["sets"]["incoherent"][key] for n, s in scenes.items()},
            TARGET_HITS,
            True,
        )
    add(
        "BVH build time / Embree's (the faster of embreex and Open3D)",
        {
            n: s["build"]["ours"] / min(s["build"]["embreex"], s["build"]["open3d"])
            for n, s in scenes.items()
        },
        TARGET_BUILD,
        False,
    )
    add(
        "BVH memory / Embree's",
        {
            n: s["bytes_per_triangle"]["ours"] / s["bytes_per_triangle"]["embree"]
            for n, s in scenes.items()
        },
        TARGET_MEMORY,
        False,
    )
    return rows


def report(r: dict[str, Any]) -> str:
    """The markdown page: per-set throughput tables, build and memory, and the summary."""
    lines = [
        f"# `python -m scenesample.bench rays`, {datetime.date.today().isoformat()}",
        "",
        f"{r.get('cpu') or cpu_model()}, {r['cores']} cores; {r['rays']:,} rays "
        f"per set; ratios are medians of {r['rounds']} interleaved rounds (peer time / ours: "
        "> 1 means we are faster), Mrays/s the best round. embreex runs Embree 4 on one "
        "thread (`rtcIntersect1`/`rtcOccluded1` per ray, robust mode); Open3D's "
        "`RaycastingScene` runs Embree on every core. Occlusion rays use each tool's any-hit "
        "query (`occluded`, `OCCLUDED`, `test_occlusions`).",
        "",
        "## Summary (every scene must meet each target; the worst scene decides)",
        "",
        "| comparison | geometric mean | worst | worst scene | target | verdict |",
        "|---|---:|---:|---|---:|---|",
    ]
    for label, gmean, worst, where, target, ok in summary_rows(r):
        sign = "<=" if "/ Embree's" in label else ">="
        verdict = "met" if ok else "NOT met"
        lines.append(
            f"| {label} | {gmean:.2f}x | {worst:.2f}x | {where} | {sign} {target}x | {verdict} |"
        )
    for kind in RAY_SETS:
        extra = {
            "occlusion": " occluded / cast_rays speed |",
            "incoherent": " count_hits / Open3D | all_hits / Open3D |",
        }.get(kind, "")
        lines += [
            "",
            f"## {kind}",
            "",
            "| scene | triangles | ours 1 thread | embreex | ratio | ours all cores | Open3D | "
            "ratio | 1 thread to all cores: ours | Open3D | same hits as Embree |" + extra,
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
            + "---:|" * extra.count("|"),
        ]  # fmt: skip
        for name, s in r["scenes"].items():
            x = s["sets"][kind]
            m = x["mrays"]
            tail = {
                "occlusion": lambda x=x: f" {x['any_over_closest']:.2f}x |",
                "incoherent": lambda x=x: f" {x['count']:.2f}x | {x['list']:.2f}x |",
            }.get(kind, lambda: "")()
            lines.append(
                f"| {name} | {s['triangles']:,} | {m['ours_1t']:.2f} | {m['embreex']:.2f} | "
                f"{x['one_thread']:.2f}x | {m['ours_all']:.2f} | {m['open3d']:.2f} | "
                f"{x['all_cores']:.2f}x | {x['scaling']:.2f}x | {x['open3d_scaling']:.2f}x | "
                f"{x['agree']:.4%} |" + tail
            )
    lines += [
        "",
        "## BVH build (fresh scene, plus one ray) and memory",
        "",
        "| scene | triangles | ours ms | embreex ms | Open3D ms | ours / Embree | ours B/tri | "
        "Embree B/tri | ours / Embree |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, s in r["scenes"].items():
        b, m = s["build"], s["bytes_per_triangle"]
        lines.append(
            f"| {name} | {s['triangles']:,} | {1e3 * b['ours']:.1f} | {1e3 * b['embreex']:.1f} | "
            f"{1e3 * b['open3d']:.1f} | {b['ours'] / min(b['embreex'], b['open3d']):.2f}x | "
            f"{m['ours']:.1f} | {m['embree']:.1f} | {m['ours'] / m['embree']:.2f}x |"
        )
    return "\n".join(lines) + "\n"
