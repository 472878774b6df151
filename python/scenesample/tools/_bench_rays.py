"""``python -m scenesample.bench rays``: CPU ray queries against Embree 4 as Open3D drives it
(``RaycastingScene``), on one core and on every core, with embreex (Embree 4 ray by ray from
Cython, one thread) as a second reference.

Scenes: every shared real scene of at least 10K triangles, and a tiling of every shared scene of
at least 1,000 triangles into 1-4M triangles (a 3D grid of copies; the instanced 1M-triangle
spheres are already in that range and are tiled twice). ``--quick`` (a smoke test): the three
smallest of those scenes, small ray sets, and one tiling, of 100K triangles.

Ray sets, the same arrays for every tool:

- primary: a camera framing the scene's bounding sphere, pixel centres in image order
  (1024x768);
- incoherent: 400K rays from uniform points of the scene's box towards other uniform points,
  closest hits along the whole ray (and every hit: ``count_hits``, ``all_hits``);
- camera: any hit (``occluded``) on the primary rays, which are also timed with ``cast_rays``
  for the any-hit / closest-hit ratio of the same rays;
- shadow: any hit on segments from the surface points the primary rays meet (image order)
  to uniform points of a square light above the scene, a quarter of its width on a side;
- segments: any hit on the segments between the incoherent rays' two points.

One core: a child process pinned to one core (``os.sched_setaffinity``, before Open3D is
imported: TBB, which runs Open3D's queries, follows the affinity) times ours with
``threads=1``, Open3D and embreex. Every core: a second child, not pinned, times ours on every
core and with ``threads=1`` (our scaling, in interleaved rounds) and Open3D (its scaling is its
pinned time over this one, from the two processes). Each (scene, set) is timed in interleaved
rounds, so that a slow moment of a shared machine hits both sides of a ratio; a ratio is the
median over rounds of the peer's time over ours (> 1: we are faster); Mrays/s are the best
round's; times are wall times of the Python call, as a user sees them. Targets hold on every
scene: the worst scene decides.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from typing import Any, Optional

import numpy as np

import scenesample as ss

# Issue targets (peer time / ours, on every scene), both on one core and on every core.
TARGET_PRIMARY = 2.0
TARGET_INCOHERENT = 1.5
TARGET_OCCLUDED = 1.5  # camera, shadow and incoherent segments
TARGET_ANY_OVER_CLOSEST = 1.2  # occluded's speed over the closest hit's, same rays
TARGET_SCALING = 1.9  # two cores over one, ours
TARGET_COUNT = 1.2  # count_hits against Open3D's count_intersections
TARGET_LIST = 1.2  # all_hits against Open3D's list_intersections
TARGET_MEMORY = 1.0  # BVH bytes per triangle / Embree's
TARGET_BUILD = 1.5  # BVH build time / Embree's
TARGET_AGREE = 0.99997  # rays whose hit triangle (or verdict) is Embree's
MIN_TRIANGLES = 10_000
MIN_TILED = 1_000
TILED = 2_000_000  # triangles a tiling aims at (1-4M)
TILED_QUICK = 100_000
#: How many shared scenes ``--quick`` measures: the smallest of at least MIN_TRIANGLES.
QUICK_SCENES = 3
BIG = 500_000
CLOSEST = ("primary", "incoherent")
ANY = ("camera", "shadow", "segments")
SETS = CLOSEST + ANY
SEGMENT_MARGIN = 1e-4  # shadow rays start and stop this fraction of their segment off the ends


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


def tiled(scene: ss.Scene, triangles: int) -> ss.Scene:
    """``scene`` copied on a 3D grid (twice as many columns and rows as layers, a tenth of the
    box apart) into at least ``triangles`` triangles, one object per copy."""
    n = scene.triangle_count
    copies = max(2, -(-triangles // n))
    layers = max(1, round((copies / 4) ** (1 / 3)))
    side = int(np.ceil(np.sqrt(copies / layers)))
    lo, hi = scene.bounds.astype(np.float64)
    step = (hi - lo) * 1.1
    grid = [(x, y, z) for z in range(layers) for y in range(side) for x in range(side)]
    places = np.array([np.eye(4) for _ in range(copies)])
    for k, (x, y, z) in enumerate(grid[:copies]):
        places[k, :3, 3] = step * (x, z, y)
    mesh = (scene.vertices, scene.faces)
    return ss.Scene.from_meshes([mesh] * copies, places)


def bench_scenes(
    quick: bool, only: Optional[list[str]] = None
) -> list[tuple[str, Callable[[], ss.Scene]]]:
    """(name, loader) of every scene measured, in order: the shared scenes of at least 10K
    triangles, then the tilings (see the module's notes). Loaders, so that a child process
    loads one scene at a time."""
    loaded: dict[str, ss.Scene] = {}

    def load(name: str, path: Any) -> ss.Scene:
        if name not in loaded:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ss.SceneWarning)
                loaded.clear()
                loaded[name] = ss.Scene.load(path)
        return loaded[name]

    files = ss.scenes.shared_scene_files()
    if only:
        files = {k: v for k, v in files.items() if any(o in k for o in only)}
    sizes = {name: load(name, path).triangle_count for name, path in files.items()}
    out: list[tuple[str, Callable[[], ss.Scene]]] = []
    measured = [n for n in files if sizes[n] >= MIN_TRIANGLES and not (quick and sizes[n] > BIG)]
    if quick:
        smallest = set(sorted(measured, key=lambda n: (sizes[n], n))[:QUICK_SCENES])
        measured = [n for n in measured if n in smallest]
    for name in measured:
        path = files[name]
        out.append((name, lambda name=name, path=path: load(name, path)))
    goal = TILED_QUICK if quick else TILED
    tilings = [n for n in files if sizes[n] >= MIN_TILED and not (quick and sizes[n] > BIG)]
    for name in tilings[:1] if quick else tilings:
        copies = max(2, -(-goal // sizes[name]))
        label = f"{name} x{copies} (tiled)"
        path = files[name]
        out.append((label, lambda name=name, path=path: tiled(load(name, path), goal)))
    return out


def ray_sets(
    scene: ss.Scene, quick: bool, seed: int = 7
) -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """The five ray sets (see the module's notes): (origins, directions, t_max), float32
    C-contiguous, the same in every process for the same scene."""
    width, height, n = (320, 240, 50_000) if quick else (1024, 768, 400_000)
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds.astype(np.float64)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    fov = 0.8
    toward = np.array([0.55, 0.45, 0.7]) / np.linalg.norm([0.55, 0.45, 0.7])
    cam = ss.Camera.look_at(
        c + toward * r / np.sin(fov / 2) * 0.85, c, yfov=fov, width=width, height=height
    )
    o, d = (a.reshape(-1, 3) for a in cam.pixel_rays())
    out = {"primary": (o, d, np.inf), "camera": (o, d, np.inf)}
    a = rng.uniform(lo, hi, (n, 3))
    b = rng.uniform(lo, hi, (n, 3))
    out["incoherent"] = (a.astype(np.float32), (b - a).astype(np.float32), np.inf)
    hits = ss.cast_rays(scene, o, d)
    visible = np.flatnonzero(hits.hit)
    if len(visible) == 0:
        raise RuntimeError("the benchmark camera sees nothing of the scene")
    points = o[visible].astype(np.float64) + d[visible] * hits.t[visible, None].astype(np.float64)
    ext = hi - lo
    light = np.array([c[0], hi[1] + 0.1 * ext[1], c[2]])
    light = light + rng.uniform(-0.125, 0.125, (len(points), 1)) * [ext[0], 0, 0]
    light = light + rng.uniform(-0.125, 0.125, (len(points), 1)) * [0, 0, ext[2]]
    seg = light - points
    out["shadow"] = (
        (points + SEGMENT_MARGIN * seg).astype(np.float32),
        (seg * (1 - 2 * SEGMENT_MARGIN)).astype(np.float32),
        1.0,
    )
    out["segments"] = (out["incoherent"][0], out["incoherent"][1], 1.0)
    return out


def _seconds(fn: Callable[[], Any]) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


#: Seconds of rest before each timed call: the thread pools of the call before (TBB's, rayon's)
#: keep their threads spinning for a while after their work, which would steal the cores from
#: the next call (on two cores, 0.6x on the call after Open3D's without it).
REST = 0.05


def _timed(tools: dict[str, Callable[[], Any]], rounds: int) -> dict[str, list[float]]:
    """Each tool's wall time in ``rounds`` interleaved rounds, after one untimed call each."""
    for fn in tools.values():
        fn()
    times: dict[str, list[float]] = {k: [] for k in tools}
    for _ in range(rounds):
        for k, fn in tools.items():
            time.sleep(REST)
            times[k].append(_seconds(fn))
    return times


def _tools(
    mode: str, scene: ss.Scene, refs: dict[str, Any], kind: str, rays: tuple
) -> dict[str, Callable[[], Any]]:
    """The timed calls of one ray set in one mode (``one``: pinned to a core; ``all``). The
    peers' calls are their own, on rays converted to their formats beforehand
    (``references.*.raw``): their time is their query's, without our conversions around it."""
    o, d, t_max = rays
    open3d = refs["open3d"].raw(o, d, t_max)
    threads = 1 if mode == "one" else None
    if kind in ANY:
        tools = {
            "ours": lambda: ss.occluded(scene, o, d, t_max=t_max, threads=threads),
            "ours_closest": lambda: ss.cast_rays(scene, o, d, t_max=t_max, threads=threads),
            "open3d": open3d["occluded"],
        }
    else:
        tools = {
            "ours": lambda: ss.cast_rays(scene, o, d, threads=threads),
            "open3d": open3d["cast"],
        }
    if mode == "one":
        tools["embreex"] = refs["embreex"].raw(o, d, t_max)["occluded" if kind in ANY else "cast"]
        if kind == "incoherent":
            tools["count"] = lambda: ss.count_hits(scene, o, d, threads=1)
            tools["open3d_count"] = open3d["count"]
    else:
        one = (
            (lambda: ss.occluded(scene, o, d, t_max=t_max, threads=1))
            if kind in ANY
            else (lambda: ss.cast_rays(scene, o, d, threads=1))
        )
        tools["ours_1t"] = one
        if kind == "incoherent":
            tools |= {
                "count": lambda: ss.count_hits(scene, o, d),
                "open3d_count": open3d["count"],
                "list": lambda: ss.all_hits(scene, o, d),
                "open3d_list": open3d["list"],
            }
    return tools


def _agreement(scene: ss.Scene, open3d: Any, kind: str, rays: tuple) -> float:
    """Fraction of rays where we and Embree (through Open3D) report the same triangle, or the
    same occlusion verdict."""
    o, d, t_max = rays
    if kind in ANY:
        return float(np.mean(ss.occluded(scene, o, d, t_max=t_max) == open3d.occluded(o, d, t_max)))
    return float(np.mean(ss.cast_rays(scene, o, d).triangle == open3d.cast(o, d)["triangle"]))


def _build(scene: ss.Scene, rounds: int) -> dict[str, float]:
    """Best wall time of a fresh BVH plus one ray, for each tool, in interleaved rounds."""
    one = (np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
    best = {"ours": np.inf, "embreex": np.inf, "open3d": np.inf}
    for _ in range(rounds):
        # A new Scene has no cached BVH: its first query builds one. The peers' scenes are
        # made and committed in the timed call (embreex builds as the mesh is added).
        fresh = ss.Scene.from_arrays(scene.vertices, scene.faces)
        time.sleep(REST)
        best["ours"] = min(best["ours"], _seconds(lambda f=fresh: ss.cast_rays(f, *one)))
        time.sleep(REST)
        embree = _seconds(lambda: ss.references.EmbreeReference(scene).commit())
        best["embreex"] = min(best["embreex"], embree)
        time.sleep(REST)
        open3d = _seconds(lambda: ss.references.Open3DReference(scene).commit())
        best["open3d"] = min(best["open3d"], open3d)
    return best


def measure(mode: str, quick: bool, rounds: int, only: Optional[list[str]]) -> dict[str, Any]:
    """One child's figures: every scene's ray sets timed in ``mode`` (``one`` or ``all``); in
    ``all``, also the build, the memory and the agreement with Embree."""
    out: dict[str, Any] = {}
    for name, load in bench_scenes(quick, only):
        scene = load()
        scene = ss.Scene.from_arrays(scene.vertices, scene.faces)
        sets = ray_sets(scene, quick)
        refs = {"open3d": ss.references.Open3DReference(scene)}
        refs["open3d"].commit()
        if mode == "one":
            refs["embreex"] = ss.references.EmbreeReference(scene)
            refs["embreex"].commit()
        entry: dict[str, Any] = {"triangles": scene.triangle_count, "sets": {}}
        for kind, rays in sets.items():
            times = _timed(_tools(mode, scene, refs, kind, rays), rounds)
            entry["sets"][kind] = {"rays": len(rays[0]), "times": times}
            if mode == "all":
                entry["sets"][kind]["agree"] = _agreement(scene, refs["open3d"], kind, rays)
        if mode == "all":
            stats = ss.bvh_stats(scene)
            entry["build"] = _build(scene, max(rounds, 3) if scene.triangle_count < BIG else 1)
            entry["bytes_per_triangle"] = {
                "ours": stats["bytes"] / scene.triangle_count,
                "embree": ss.references.embree_memory(scene) / scene.triangle_count,
            }
            entry["sah"] = stats["sah"]
        out[name] = entry
        print(f"  {mode}: {name}: done", flush=True)
    return out


def _child(mode: str, quick: bool, rounds: int, only: Optional[list[str]]) -> dict[str, Any]:
    """``measure`` in a child process of its own (pinned to one core for ``one``)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, f"{mode}.json")
        cmd = [sys.executable, "-m", "scenesample.tools._bench_rays", mode, path, str(rounds)]
        cmd += ["--quick"] * quick + (["--scenes", ",".join(only)] if only else [])
        subprocess.run(cmd, check=True)
        with open(path) as f:
            return json.load(f)


def run(
    quick: bool = False, rounds: Optional[int] = None, only: Optional[list[str]] = None
) -> dict[str, Any]:
    """Measure every scene on one core and on every core; the raw figures (see
    :func:`report`)."""
    rounds = rounds or (1 if quick else 5)
    one = _child("one", quick, rounds, only)
    every = _child("all", quick, rounds, only)
    return {
        "rounds": rounds,
        "cores": os.cpu_count(),
        "cpu": cpu_model(),
        "kernel": ss.ray_kernel(),
        "scenes": {name: {"one": one[name], "all": every[name]} for name in every},
    }


def _median(num: list[float], den: list[float]) -> float:
    return float(np.median(np.array(num) / np.array(den)))


def figures(s: dict[str, Any], kind: str) -> dict[str, float]:
    """The ratios of one scene's ray set (peer time / ours, > 1: we are faster) and Mrays/s."""
    one, every = s["one"]["sets"][kind], s["all"]["sets"][kind]
    t1, ta = one["times"], every["times"]
    n = one["rays"]
    f = {
        "one": _median(t1["open3d"], t1["ours"]),
        "embreex": _median(t1["embreex"], t1["ours"]),
        "all": _median(ta["open3d"], ta["ours"]),
        "scaling": _median(ta["ours_1t"], ta["ours"]),
        "open3d_scaling": float(min(t1["open3d"]) / min(ta["open3d"])),
        "mrays_one": n / min(t1["ours"]) / 1e6,
        "mrays_open3d_one": n / min(t1["open3d"]) / 1e6,
        "mrays_all": n / min(ta["ours"]) / 1e6,
        "mrays_open3d_all": n / min(ta["open3d"]) / 1e6,
        "agree": every["agree"],
    }
    if kind in ANY:
        f["any_over_closest_one"] = _median(t1["ours_closest"], t1["ours"])
        f["any_over_closest_all"] = _median(ta["ours_closest"], ta["ours"])
    if kind == "incoherent":
        f["count_one"] = _median(t1["open3d_count"], t1["count"])
        f["count_all"] = _median(ta["open3d_count"], ta["count"])
        f["list_all"] = _median(ta["open3d_list"], ta["list"])
    return f


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

    fig = {n: {k: figures(s, k) for k in SETS} for n, s in scenes.items()}
    targets = {"primary": TARGET_PRIMARY, "incoherent": TARGET_INCOHERENT}
    for kind in SETS:
        target = targets.get(kind, TARGET_OCCLUDED)
        query = "closest hit" if kind in CLOSEST else "occluded"
        for where, key in (("one core", "one"), ("every core", "all")):
            add(
                f"{kind}, {query}: {where} vs Open3D",
                {n: f[kind][key] for n, f in fig.items()},
                target,
                True,
            )
    for kind in ANY:
        for where, key in (("one core", "one"), ("every core", "all")):
            add(
                f"{kind}: occluded / cast_rays speed ({where}, same rays)",
                {n: f[kind][f"any_over_closest_{key}"] for n, f in fig.items()},
                TARGET_ANY_OVER_CLOSEST,
                True,
            )
    for kind in SETS:
        add(
            f"{kind}: two cores / one, ours",
            {n: f[kind]["scaling"] for n, f in fig.items()},
            TARGET_SCALING,
            True,
        )
    for key, label, target in (
        ("count_one", "count_hits vs Open3D's count_intersections (one core)", TARGET_COUNT),
        ("count_all", "count_hits vs Open3D's count_intersections (every core)", TARGET_COUNT),
        ("list_all", "all_hits vs Open3D's list_intersections (every core)", TARGET_LIST),
    ):
        add(f"incoherent: {label}", {n: f["incoherent"][key] for n, f in fig.items()}, target, True)
    for kind in SETS:
        add(
            f"{kind}: rays with Embree's hit",
            {n: f[kind]["agree"] for n, f in fig.items()},
            TARGET_AGREE,
            True,
        )
    build = {n: s["all"]["build"] for n, s in scenes.items()}
    add(
        "BVH build time / Embree's (the faster of embreex and Open3D)",
        {n: b["ours"] / min(b["embreex"], b["open3d"]) for n, b in build.items()},
        TARGET_BUILD,
        False,
    )
    add(
        "BVH memory / Embree's",
        {
            n: s["all"]["bytes_per_triangle"]["ours"] / s["all"]["bytes_per_triangle"]["embree"]
            for n, s in scenes.items()
        },
        TARGET_MEMORY,
        False,
    )
    return rows


def _set_table(r: dict[str, Any], kind: str) -> list[str]:
    query = "cast_rays" if kind in CLOSEST else "occluded"
    head = (
        f"| scene | triangles | {query} Mrays/s, one core: ours | Open3D | ratio | embreex "
        "ratio | every core: ours | Open3D | ratio | two cores / one: ours | Open3D | "
        "same hits as Embree |"
    )
    extra = {
        "camera": " occluded / cast_rays: one core | every core |",
        "shadow": " occluded / cast_rays: one core | every core |",
        "segments": " occluded / cast_rays: one core | every core |",
        "incoherent": " count_hits / Open3D: one core | every core | all_hits / Open3D |",
    }.get(kind, "")
    lines = ["", f"## {kind}", "", head + extra, "|---|" + "---:|" * (11 + extra.count("|"))]
    for name, s in r["scenes"].items():
        f = figures(s, kind)
        tail = ""
        if kind in ANY:
            tail = f" {f['any_over_closest_one']:.2f}x | {f['any_over_closest_all']:.2f}x |"
        elif kind == "incoherent":
            tail = f" {f['count_one']:.2f}x | {f['count_all']:.2f}x | {f['list_all']:.2f}x |"
        lines.append(
            f"| {name} | {s['all']['triangles']:,} | {f['mrays_one']:.2f} | "
            f"{f['mrays_open3d_one']:.2f} | {f['one']:.2f}x | {f['embreex']:.2f}x | "
            f"{f['mrays_all']:.2f} | {f['mrays_open3d_all']:.2f} | {f['all']:.2f}x | "
            f"{f['scaling']:.2f}x | {f['open3d_scaling']:.2f}x | {f['agree']:.4%} |" + tail
        )
    return lines


def report(r: dict[str, Any]) -> str:
    """The markdown page: the summary, a table per ray set, build and memory."""
    lines = [
        f"# `python -m scenesample.bench rays`, {datetime.date.today().isoformat()}",
        "",
        f"{r.get('cpu') or cpu_model()}, {r['cores']} cores, "
        f"kernel {r.get('kernel', 'not recorded')} (`ss.ray_kernel()`). Peer: Embree 4 as Open3D's "
        "`RaycastingScene` drives it (robust mode), on one core (its process pinned with "
        "`os.sched_setaffinity`, against ours with `threads=1`) and on every core; embreex "
        "(Embree 4 ray by ray, one thread) is the second reference. Ratios are medians of "
        f"{r['rounds']} interleaved rounds of peer time / ours (> 1: we are faster); Mrays/s "
        "the best round's. Two cores / one: ours from interleaved rounds in one process, "
        "Open3D's from its pinned and unpinned processes.",
        "",
        "## Summary (every scene must meet each target; the worst scene decides)",
        "",
        "| comparison | geometric mean | worst | worst scene | target | verdict |",
        "|---|---:|---:|---|---:|---|",
    ]
    for label, gmean, worst, where, target, ok in summary_rows(r):
        sign = "<=" if "/ Embree's" in label else ">="
        value = f"{worst:.4%}" if "Embree's hit" in label else f"{worst:.2f}x"
        mean = f"{gmean:.4%}" if "Embree's hit" in label else f"{gmean:.2f}x"
        verdict = "met" if ok else "NOT met"
        lines.append(f"| {label} | {mean} | {value} | {where} | {sign} {target} | {verdict} |")
    for kind in SETS:
        lines += _set_table(r, kind)
    lines += [
        "",
        "## BVH build (fresh scene, plus one ray) and memory",
        "",
        "| scene | triangles | ours ms | embreex ms | Open3D ms | ours / Embree | ours B/tri | "
        "Embree B/tri | ours / Embree | SAH cost |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, s in r["scenes"].items():
        a = s["all"]
        b, m = a["build"], a["bytes_per_triangle"]
        lines.append(
            f"| {name} | {a['triangles']:,} | {1e3 * b['ours']:.1f} | {1e3 * b['embreex']:.1f} | "
            f"{1e3 * b['open3d']:.1f} | {b['ours'] / min(b['embreex'], b['open3d']):.2f}x | "
            f"{m['ours']:.1f} | {m['embree']:.1f} | {m['ours'] / m['embree']:.2f}x | "
            f"{a['sah']:.1f} |"
        )
    return "\n".join(lines + NOTES) + "\n"


#: What the report says besides its figures: how the work is spread, and what that implies
#: beyond the two cores measured here.
NOTES = [
    "",
    "## Two cores, and what the design implies for 16 or 64",
    "",
    "- **How the work is split.** A call's rays are cut into chunks of 1,024 (`trace::schedule`) "
    "that rayon's pool steals, each with its own stacks; the tree is read-only and shared. A "
    "786K-ray call has 768 chunks: 48 for each of 16 threads, 12 for each of 64, enough to "
    "even out; a call of under 64K rays has fewer chunks than a 64-core pool has threads, and "
    "leaves cores idle.",
    "- **Writes to shared result arrays.** Each chunk writes only its own slices; neighbouring "
    "chunks share at most a cache line at their border. The arrays are allocated zeroed (lazily, "
    'by the system) and each chunk marks its own entries "no hit" on its thread: filled up '
    "front by the calling thread, 786K rays' 12.6 MB took 4-5 ms of page faults on one core, "
    "15% of `intel_sponza_ivy`'s primary rays on two; on 64 cores it would have been most of "
    "the call.",
    "- **The float64 refinement** of each hit runs in the chunk that found it, in batches of 256 "
    "hits after their traversal; it adds no serial step.",
    "- **What stays serial per call:** the check of the rays (itself parallel, a pass over the "
    "inputs), the lookup of the cached tree, the any-hit probe (256 rays traced both ways, "
    "about 0.1-0.2 ms), and the Python wrapper (no copies: numpy takes the result vectors). "
    "These are fixed costs, so small calls scale worst: `shadow` on `intel_sponza_ivy` (34K "
    "rays) is the weakest case here.",
    "- **Measured on two cores:** where the gap to 2x is, the chunks' busy time summed over "
    "threads tells. On `intel_sponza_ivy`'s primary rays it is the same on one thread and on two "
    "(46 ms). On `balloon`'s it rose from 43-45 ms on one thread to 54-59 ms on two in five "
    "rounds of six (43 ms in the sixth, which then took 24 ms): each chunk ran 25-30% slower "
    "while the other core worked, with no shared write between them, so the two cores of this "
    "virtual machine contend for something below the code (one core's two hyperthreads, or "
    "memory). On many cores the trees of large scenes, read by every core, compete for the "
    "shared last-level cache as they do here.",
    "- **The first call builds the tree**, in parallel above 8,192 triangles a range; its top "
    "levels split one range at a time, so the build scales less than the trace.",
    "- **Rests between calls cost the second core.** Each timed call here follows a 50 ms rest "
    "(`REST`), after which rayon's workers sleep and this virtual machine's idle core takes "
    "milliseconds to wake. `intel_sponza_ivy`'s 786K primary rays, two threads over one: 1.87x "
    "in 200 calls back to back (24.9 -> 13.3 ms, 1.8 cores busy under `perf stat`), 1.25-1.8x "
    "with 50 ms rests in between, from run to run; two processes tracing on one thread each "
    "run as fast as one alone, so the cores themselves do not contend.",
]


def _main(argv: list[str]) -> None:
    """A child's entry: ``MODE OUT.json ROUNDS [--quick] [--scenes a,b]``."""
    p = argparse.ArgumentParser()
    p.add_argument("mode", choices=("one", "all"))
    p.add_argument("out")
    p.add_argument("rounds", type=int)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--scenes")
    a = p.parse_args(argv)
    if a.mode == "one" and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    only = a.scenes.split(",") if a.scenes else None
    with open(a.out, "w") as f:
        json.dump(measure(a.mode, a.quick, a.rounds, only), f)


if __name__ == "__main__":
    _main(sys.argv[1:])
