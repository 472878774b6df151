"""``python -m scenesample.bench points``: the point queries against every peer a user would try,
on every shared real scene and a tiling of the toy car past 4M triangles, for two point sets:

- surface: area-uniform points of the scene's surface, each moved by a normal variate of 1% of
  the bounding-box diagonal;
- box: uniform points of the scene's bounding box.

Closest points against Open3D's ``RaycastingScene`` (Embree), fcpw, libigl's AABB tree and
point-cloud-utils; signed distance and occupancy against Open3D on closed scenes (where its ray
parity is right) and against libigl's fast winding number on open ones (where only a winding
number is); trimesh once, on a subset. Scenes are split by :attr:`Scene.closed`.

Every tool runs on every core (trimesh: numpy). Each is timed in interleaved rounds after its
tree is built; tools that build a tree per call (libigl's fast winding number and signed
distance, point-cloud-utils) are timed as a call on the points less a call on one point, i.e.
without that build. A ratio is the median over rounds of the peer's time over ours (> 1: we
are faster). Slow peers on scenes of more than 500K triangles are timed on a subset and
compared per point. Accuracy: our distances against a float64 brute force (a subset); signs
against Open3D's away from the surface (closed scenes) or against the float64 winding number
(open scenes, a subset).
"""

from __future__ import annotations

import datetime
import os
import time
import warnings
from typing import Any, Callable, Optional

import numpy as np

import scenesample as ss

from .._surface import sample_surface
from ._bench_rays import cpu_model

TARGET_CLOSEST = 2.0  # closest points: the fastest peer's time over ours
TARGET_RELATIVE_ERROR = 1e-6
TARGET_TRIMESH = 50.0
TARGET_CLOSED = 1.5  # closed scenes: Open3D's signed distance and occupancy time over ours
TARGET_CLOSED_SIGNS = 0.9999  # ... with Open3D's signs away from the surface
TARGET_OPEN = 10.0  # open scenes: libigl's fast winding number time over ours
TARGET_OPEN_SIGNS = 0.999  # ... with the float64 winding number's signs, away from 1/2
TILING_TRIANGLES = 4_000_000
SETS = ("surface", "box")
BIG = 500_000
CLOSEST_PEERS = ("open3d", "fcpw", "libigl", "pcu")


def bench_scenes(quick: bool, only: Optional[list[str]] = None) -> list[tuple[str, ss.Scene]]:
    """Every shared scene (quick: those under 500K triangles; `only`: those whose names contain
    one of these), then the tiling."""
    out = []
    for name, path in ss.scenes.shared_scene_files().items():
        if only and not any(o in name for o in only):
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ss.SceneWarning)
            scene = ss.Scene.load(path)
        if quick and scene.triangle_count > BIG:
            continue
        out.append((name, scene))
    base = dict(out).get("khr_toy_car")
    if base is not None and not quick and (not only or any(o in "tiled" for o in only)):
        out.append(("khr_toy_car tiled", tiling(base, TILING_TRIANGLES)))
    return out


def tiling(scene: ss.Scene, triangles: int) -> ss.Scene:
    """Copies of `scene` side by side on a square grid, at least `triangles` in all."""
    copies = -(-triangles // scene.triangle_count)
    side = int(np.ceil(np.sqrt(copies)))
    lo, hi = scene.bounds.astype(np.float64)
    step = (hi - lo) * 1.1
    v, f = scene.vertices.astype(np.float64), scene.faces.astype(np.int64)
    verts, faces = [], []
    for i in range(copies):
        offset = np.array([(i % side) * step[0], 0.0, (i // side) * step[2]])
        faces.append(f + len(v) * i)
        verts.append(v + offset)
    return ss.Scene.from_arrays(np.concatenate(verts).astype(np.float32), np.concatenate(faces))


def point_sets(scene: ss.Scene, n: int, seed: int = 3) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds.astype(np.float64)
    diag = float(np.linalg.norm(hi - lo))
    surface = sample_surface(scene.vertices, scene.faces, n, rng)
    surface += rng.normal(size=surface.shape) * 0.01 * diag
    return {
        "surface": np.ascontiguousarray(surface, dtype=np.float32),
        "box": np.ascontiguousarray(rng.uniform(lo, hi, (n, 3)), dtype=np.float32),
    }


def _seconds(fn: Callable[[], Any]) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def brute_distances(scene: ss.Scene, pts: np.ndarray) -> np.ndarray:
    """Float64 distances from each point to every triangle, the least kept (numpy, blockwise)."""
    tri = scene.vertices.astype(np.float64)[scene.faces.astype(np.int64)]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    out = np.full(len(pts), np.inf)

    def seg(p: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        e = y - x
        l2 = (e * e).sum(1)
        t = np.clip(((p - x) * e).sum(1) / np.where(l2 > 0, l2, 1), 0, 1)
        return (((x + e * t[:, None]) - p) ** 2).sum(1)

    for i, p in enumerate(pts.astype(np.float64)):
        d2 = np.minimum(np.minimum(seg(p, a, b), seg(p, b, c)), seg(p, c, a))
        n = np.cross(b - a, c - a)
        nl = np.linalg.norm(n, axis=1)
        ok = nl > 0
        n = n / np.where(ok, nl, 1)[:, None]
        h = ((p - a) * n).sum(1)
        r = p - n * h[:, None]
        inside = ok.copy()
        for x, y in ((a, b), (b, c), (c, a)):
            inside &= (np.cross(y - x, r - x) * n).sum(1) >= 0
        out[i] = np.sqrt(np.where(inside, np.minimum(h * h, d2), d2).min())
    return out


def exact_winding(scene: ss.Scene, pts: np.ndarray) -> np.ndarray:
    """The generalized winding number in float64: every triangle's solid angle (Van Oosterom and
    Strackee) summed, point by point."""
    tri = scene.vertices.astype(np.float64)[scene.faces.astype(np.int64)]
    out = np.zeros(len(pts))
    for i, p in enumerate(np.asarray(pts, np.float64)):
        a, b, c = (tri[:, k] - p for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        div = (
            la * lb * lc
            + np.einsum("ij,ij->i", a, b) * lc
            + np.einsum("ij,ij->i", b, c) * la
            + np.einsum("ij,ij->i", c, a) * lb
        )
        out[i] = 2 * np.arctan2(det, div).sum() / (4 * np.pi)
    return out


class Peers:
    """The peers that are installed, each with its tree built for one scene: callables that take
    (N, 3) float32 points. ``per_call`` names the tools whose call builds its own tree."""

    def __init__(self, scene: ss.Scene) -> None:
        self.closest: dict[str, Callable[[np.ndarray], Any]] = {}
        self.signed: dict[str, Callable[[np.ndarray], Any]] = {}
        self.occupancy: dict[str, Callable[[np.ndarray], Any]] = {}
        self.per_call: set[str] = set()
        o3d = ss.references.Open3DReference(scene)
        o3d.closest_points(scene.vertices[:1])  # Open3D builds its tree on the first query
        self.open3d = o3d
        self.closest["open3d"] = o3d.closest_points
        self.signed["open3d"] = o3d.signed_distance
        self.occupancy["open3d"] = o3d.occupancy
        v64, f64 = scene.vertices.astype(np.float64), scene.faces.astype(np.int64)
        try:
            import fcpw

            fs = fcpw.scene_3D()
            fs.set_object_count(1)
            fs.set_object_vertices(np.ascontiguousarray(scene.vertices, np.float32), 0)
            fs.set_object_triangles(np.ascontiguousarray(scene.faces, np.int32), 0)
            fs.build(fcpw.aggregate_type.bvh_surface_area, True)

            def fcpw_closest(p: np.ndarray) -> Any:
                found = fcpw.interaction_3D_list()
                return fs.find_closest_points(p, np.full(len(p), np.inf, np.float32), found)

            self.closest["fcpw"] = fcpw_closest
        except ImportError:
            pass
        try:
            import igl

            tree = igl.AABB()
            tree.init(v64, f64)
            self.closest["libigl"] = lambda p: tree.squared_distance(v64, f64, p.astype(np.float64))
            fwn = igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER
            self.signed["libigl"] = lambda p: igl.signed_distance(
                p.astype(np.float64), v64, f64, sign_type=fwn
            )
            self.occupancy["libigl"] = lambda p: (
                igl.fast_winding_number(v64, f64, p.astype(np.float64)) >= 0.5
            )
            self.per_call |= {"libigl_signed", "libigl_occupancy"}
        except ImportError:
            pass
        try:
            import point_cloud_utils as pcu

            v32, f32 = scene.vertices, scene.faces
            self.closest["pcu"] = lambda p: pcu.closest_points_on_mesh(p, v32, f32)
            self.per_call.add("pcu_closest")
        except ImportError:
            pass


def _timed_rounds(
    calls: dict[str, Callable[[], Any]], one: dict[str, Callable[[], Any]], rounds: int
) -> dict[str, np.ndarray]:
    """Each call's seconds in `rounds` interleaved rounds; a call in `one` (the same tool on one
    point) is subtracted from it (the tree it builds per call), measured in the same round.
    Where the build takes more than 90% of the call, what is left is within the noise of the
    two timings: that tool's times are NaN (not measured) rather than a ratio made of noise."""
    times: dict[str, list[float]] = {k: [] for k in calls}
    for _ in range(rounds):
        for k, fn in calls.items():
            t = _seconds(fn)
            if k in one:
                build = _seconds(one[k])
                t = t - build if t - build > 0.1 * t else float("nan")
            times[k].append(t)
    return {k: np.array(v) for k, v in times.items()}


def _query(
    name: str,
    ours: Callable[[np.ndarray], Any],
    peers: dict[str, Callable[[np.ndarray], Any]],
    per_call: set[str],
    pts: np.ndarray,
    big: bool,
    rounds: int,
) -> dict[str, Any]:
    """One query on one point set against its peers: Mpoints/s of each (best round) and each
    peer's time over ours per point (median of rounds)."""
    few = pts[: min(len(pts), 20_000)] if big else pts
    calls = {"ours": lambda: ours(pts)}
    one = {}
    for k, fn in peers.items():
        calls[k] = lambda fn=fn: fn(few)
        if f"{k}_{name}" in per_call:
            one[k] = lambda fn=fn: fn(pts[:1])
    t = _timed_rounds(calls, one, rounds)
    per_point = {
        k: v / (len(pts) if k == "ours" else len(few))
        for k, v in t.items()
        if not np.isnan(v).any()
    }
    return {
        "mpoints": {k: 1e-6 / v.min() for k, v in per_point.items()},
        "ratio": {k: float(np.median(v / per_point["ours"])) for k, v in per_point.items()},
    }


def _accuracy(scene: ss.Scene, peers: Peers, pts: np.ndarray, brute_n: int) -> dict[str, Any]:
    """Our distances against the float64 brute force (a subset) and Open3D's; our signs
    against Open3D's away from the surface (closed scenes) or the float64 winding number's
    away from 1/2 (open scenes, a subset)."""
    lo, hi = scene.bounds.astype(np.float64)
    diag = float(np.linalg.norm(hi - lo))
    ours = ss.closest_points(scene, pts).distance.astype(np.float64)
    theirs = peers.open3d.closest_points(pts)["distance"].astype(np.float64)
    exact = brute_distances(scene, pts[:brute_n])
    rel = np.abs(ours[:brute_n] - exact) / np.maximum(exact, 1e-30)
    out = {
        "relative_error": float(rel.max()),
        "open3d_difference": float(np.quantile(np.abs(ours - theirs), 0.999)),
    }
    occ = ss.occupancy(scene, pts)
    if scene.closed:
        clear = ours > 1e-5 * diag
        out["signs"] = float((occ == peers.open3d.occupancy(pts))[clear].mean())
        out["signs_points"] = int(clear.sum())
    else:
        w = exact_winding(scene, pts[:brute_n])
        clear = np.abs(w - 0.5) >= 1e-3
        out["signs"] = float((occ[:brute_n] == (w >= 0.5))[clear].mean())
        out["signs_points"] = int(clear.sum())
    return out


def bench_scene(
    scene: ss.Scene, n: int, rounds: int, brute_n: int, trimesh_n: int
) -> dict[str, Any]:
    peers = Peers(scene)
    sets = point_sets(scene, n)
    closed = scene.closed
    # Our trees (and winding data) built before anything is timed.
    ss.signed_distance(scene, sets["box"][:8])
    ss.winding_number(scene, sets["box"][:8])
    big = scene.triangle_count > BIG
    sign_peer = "open3d" if closed else "libigl"
    out: dict[str, Any] = {"triangles": scene.triangle_count, "closed": closed, "sets": {}}
    for kind, pts in sets.items():

        def only(d: dict[str, Callable], key: str = sign_peer) -> dict[str, Callable]:
            return {key: d[key]} if key in d else {}

        row: dict[str, Any] = {
            "closest": _query(
                "closest", lambda p: ss.closest_points(scene, p), peers.closest,
                peers.per_call, pts, big, rounds,
            ),
            "signed": _query(
                "signed", lambda p: ss.signed_distance(scene, p), only(peers.signed),
                peers.per_call, pts, big, rounds,
            ),
            "occupancy": _query(
                "occupancy", lambda p: ss.occupancy(scene, p), only(peers.occupancy),
                peers.per_call, pts, big, rounds,
            ),
        }  # fmt: skip
        row.update(_accuracy(scene, peers, pts, brute_n))
        if trimesh_n:
            row["trimesh"] = _trimesh_ratio(scene, pts, trimesh_n, row["closest"])
        out["sets"][kind] = row
    stats = ss.bvh_stats(scene)
    out["bvh_bytes"] = stats["bytes"]
    out["winding_bytes"] = stats.get("winding_bytes", 0)
    return out


def _trimesh_ratio(scene: ss.Scene, pts: np.ndarray, n: int, ours: dict[str, Any]) -> float:
    """trimesh's closest points per point (best of two on a subset) over ours (best round)."""
    import trimesh

    tm = trimesh.Trimesh(scene.vertices, scene.faces, process=False)
    few = pts[:n]
    t = min(_seconds(lambda: trimesh.proximity.closest_point(tm, few)) for _ in range(2))
    return float((t / len(few)) / (1e-6 / ours["mpoints"]["ours"]))


def run(
    quick: bool = False, rounds: Optional[int] = None, only: Optional[list[str]] = None
) -> dict[str, Any]:
    n = 20_000 if quick else 100_000
    rounds = rounds or (1 if quick else 3)
    results: dict[str, Any] = {
        "points": n,
        "rounds": rounds,
        "cores": os.cpu_count(),
        "cpu": cpu_model(),
        "scenes": {},
    }
    for name, scene in bench_scenes(quick, only):
        results["scenes"][name] = bench_scene(
            scene,
            n,
            rounds,
            # The numpy brute forces cost points x triangles: fewer points on large scenes.
            brute_n=int(np.clip(2e7 // scene.triangle_count, 20, 50 if quick else 300)),
            trimesh_n=0 if scene.triangle_count > BIG else (100 if quick else 500),
        )
        print(f"  {name}: done", flush=True)
    return results


def _fastest_peer(x: dict[str, Any]) -> tuple[float, str]:
    """The fastest closest-point peer's time over ours, and its name."""
    ratios = {k: v for k, v in x["closest"]["ratio"].items() if k != "ours"}
    name = min(ratios, key=ratios.get)
    return ratios[name], name


def summary_rows(r: dict[str, Any]) -> list[tuple[str, float, str, str, bool]]:
    """(comparison, worst value, worst scene, target, met): every target on every scene it
    applies to, the worst scene reported."""
    rows = []

    def add(label: str, values: dict[str, float], target: float, higher: bool) -> None:
        if not values:
            return
        names = list(values)
        v = np.array([values[k] for k in names])
        i = int(np.argmin(v) if higher else np.argmax(v))
        ok = v[i] >= target if higher else v[i] <= target
        rows.append((label, float(v[i]), names[i], f"{'>=' if higher else '<='} {target:g}", ok))

    scenes = r["scenes"]
    groups = {
        "closed": {n: s for n, s in scenes.items() if s["closed"]},
        "open": {n: s for n, s in scenes.items() if not s["closed"]},
    }
    for kind in SETS:
        sets = {n: s["sets"][kind] for n, s in scenes.items()}
        add(
            f"closest points, {kind}: fastest peer's time / ours",
            {n: _fastest_peer(x)[0] for n, x in sets.items()},
            TARGET_CLOSEST,
            True,
        )
        add(
            f"closest points, {kind}: trimesh time / ours (per point)",
            {n: x["trimesh"] for n, x in sets.items() if "trimesh" in x},
            TARGET_TRIMESH,
            True,
        )
        add(
            f"closest points, {kind}: relative error vs float64 brute force",
            {n: x["relative_error"] for n, x in sets.items()},
            TARGET_RELATIVE_ERROR,
            False,
        )
        for group, peer, target, signs in (
            ("closed", "open3d", TARGET_CLOSED, TARGET_CLOSED_SIGNS),
            ("open", "libigl", TARGET_OPEN, TARGET_OPEN_SIGNS),
        ):
            g = {n: s["sets"][kind] for n, s in groups[group].items()}
            label = "Open3D" if peer == "open3d" else "libigl fast winding number"
            for query in ("signed", "occupancy"):
                add(
                    f"{group} scenes, {kind}: {query.replace('signed', 'signed distance')}, "
                    f"{label} time / ours",
                    {n: x[query]["ratio"][peer] for n, x in g.items() if peer in x[query]["ratio"]},
                    target,
                    True,
                )
            ref = "Open3D's" if group == "closed" else "the float64 winding number's"
            add(
                f"{group} scenes, {kind}: signs agreeing with {ref}",
                {n: x["signs"] for n, x in g.items()},
                signs,
                True,
            )
    return rows  # fmt: skip


def _fmt(label: str, value: float) -> str:
    if "error" in label:
        return f"{value:.2e}"
    if "signs" in label:
        return f"{value:.4%}"
    return f"{value:.2f}x"


def report(r: dict[str, Any]) -> str:
    lines = [
        f"# `python -m scenesample.bench points`, {datetime.date.today().isoformat()}",
        "",
        f"{r['cpu']}, {r['cores']} cores; {r['points']:,} points per set; ratios are medians of "
        f"{r['rounds']} interleaved rounds (peer time / ours: > 1 means we are faster), "
        "Mpoints/s the best round. Every tool on every core but trimesh (numpy); trees built "
        "before timing (libigl's fast winding number and signed distance, and point-cloud-utils, "
        "build theirs in each call: a call on one point is subtracted). Open3D's signed distance "
        "and occupancy are by ray parity, right on closed scenes only; libigl's by its fast "
        "winding number; ours by the winding number (one ray per point on closed scenes).",
        "",
        "## Summary (every scene must meet each target; the worst scene decides)",
        "",
        "| comparison | worst | worst scene | target | verdict |",
        "|---|---:|---|---:|---|",
    ]
    for label, worst, where, target, ok in summary_rows(r):
        lines.append(
            f"| {label} | {_fmt(label, worst)} | {where} | {target} | "
            f"{'met' if ok else 'NOT met'} |"
        )
    for group, closed in (("Closed scenes", True), ("Open scenes", False)):
        names = [n for n, s in r["scenes"].items() if s["closed"] == closed]
        lines += ["", f"## {group}: {', '.join(names) or 'none'}"]
        for kind in SETS:
            lines += _set_table(r, names, kind, closed)
    lines += _memory_table(r)
    return "\n".join(lines) + "\n"


def _set_table(r: dict[str, Any], names: list[str], kind: str, closed: bool) -> list[str]:
    peer = "Open3D" if closed else "libigl FWN"
    key = "open3d" if closed else "libigl"
    lines = [
        "",
        f"### {kind} points",
        "",
        "| scene | triangles | closest: ours Mpts/s | Open3D | fcpw | libigl | pcu | fastest "
        f"peer / ours | trimesh | signed distance: ours | {peer} | ratio | occupancy: ours | "
        f"{peer} | ratio | signs agree | max rel. error |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]

    def m(q: dict[str, Any], k: str) -> str:
        return f"{q['mpoints'][k]:.2f}" if k in q["mpoints"] else "—"

    def ratio(q: dict[str, Any], k: str) -> str:
        return f"{q['ratio'][k]:.2f}x" if k in q["ratio"] else "—"

    for name in names:
        s = r["scenes"][name]
        x = s["sets"][kind]
        c, sd, oc = x["closest"], x["signed"], x["occupancy"]
        best, who = _fastest_peer(x)
        tm = f"{x['trimesh']:.0f}x" if "trimesh" in x else "—"
        lines.append(
            f"| {name} | {s['triangles']:,} | {m(c, 'ours')} | "
            + " | ".join(m(c, k) for k in CLOSEST_PEERS)
            + f" | {best:.2f}x ({who}) | {tm} | {m(sd, 'ours')} | {m(sd, key)} | "
            f"{ratio(sd, key)} | {m(oc, 'ours')} | {m(oc, key)} | {ratio(oc, key)} | "
            f"{x['signs']:.4%} of {x['signs_points']:,} | {x['relative_error']:.1e} |"
        )
    return lines


def _memory_table(r: dict[str, Any]) -> list[str]:
    lines = [
        "",
        "## Memory",
        "",
        "The point queries read the ray-casting BVH; the winding numbers of open scenes add one "
        "28-byte record per node, made on first use.",
        "",
        "| scene | BVH bytes | winding data bytes | extra |",
        "|---|---:|---:|---:|",
    ]
    for name, s in r["scenes"].items():
        lines.append(
            f"| {name} | {s['bvh_bytes']:,} | {s['winding_bytes']:,} | "
            f"{s['winding_bytes'] / max(s['bvh_bytes'], 1):.1%} |"
        )
    return lines
