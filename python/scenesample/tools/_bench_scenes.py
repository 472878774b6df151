"""``python -m scenesample.bench scenes``: moving scenes. Each shared scene of at least 5,000
triangles is tiled (one object per tile, at least 100 tiles and 1M triangles; at least 4 tiles
and 50K triangles with ``--quick``), and every tile is moved every frame.

Per scene, medians of interleaved rounds:

- a new pose (``Scene.posed`` and its BVH, a two-level tree: what the next ray cast needs;
  after the first pose) against building the same geometry from scratch
  (``Scene.from_arrays`` and its BVH): target <= 1%;
- rays on the posed scene against the same geometry built flat, 262,144 incoherent rays and
  the 512x512 camera's primary rays: target >= 0.9x for both;
- a frame (pose, 262,144 incoherent rays and a 512x512 conventional image on the CPU) against
  fcpw (``update_object_vertices``, ``refit`` and the same rays plus the image's primary rays)
  and Open3D (a new ``RaycastingScene`` and the same rays): target >= 3x both;
- a deformation (``Scene.deformed``: every vertex of the tiling moved by a travelling wave, a
  twentieth of the scene's size high, and its BVH refit) against the same fresh build: target
  <= 10%; and rays on it against the same vertices built flat: target >= 0.8x.

Once per run, a skinned frame: a tube of 102,400 triangles on a chain of 8 joints, written as
glTF by ``scenes.bending_tube`` (no shared scene is skinned), posed by ``Scene.at`` (linear
blend skinning and the BVH's refit), with the same rays and image, against the same peers fed
the same skinned vertices (their skinning not charged to them): target >= 3x both; and against
a fresh build.
"""

from __future__ import annotations

import statistics
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

import scenesample as ss

from .._scene import Scene
from ..scenes import bending_tube, shared_scene_files

MIN_TRIANGLES = 5_000
# 100 tiles of a scene over this many triangles would not fit a 24 GiB machine's rebuilds.
MAX_TILED = 12_000_000


def _tiling(scene: Scene, quick: bool) -> tuple[Scene, int]:
    n = len(scene.faces)
    target, least = (50_000, 4) if quick else (1_000_000, 100)
    tiles = max(least, -(-target // n))
    side = int(np.ceil(np.sqrt(tiles)))
    lo, hi = scene.bounds
    step = (hi - lo) * 1.1
    places = np.array([np.eye(4) for _ in range(tiles)])
    for k in range(tiles):
        places[k, 0, 3] = step[0] * (k % side)
        places[k, 1, 3] = step[1] * (k // side)
    mesh = (scene.vertices, scene.faces)
    return Scene.from_meshes([mesh] * tiles, places), tiles


def _centres(base: Scene) -> np.ndarray:
    """Each tile's centre, as the mean of the vertices of its first 64 faces."""
    ids = base.object_ids
    out = np.zeros((len(base.objects), 3))
    for k in range(len(out)):
        v = base.vertices[np.unique(base.faces[ids == k][:64])]
        out[k] = v.mean(axis=0)
    return out


def _poses(base: Scene, frame: int, centres: np.ndarray) -> np.ndarray:
    """Each tile turned about its own centre (`centres`, [`_centres`]) and lifted a little,
    differently every frame."""
    lo, hi = base.bounds
    rng = np.random.default_rng(frame)
    n = len(base.objects)
    out = np.array([np.eye(4) for _ in range(n)])
    angles = rng.uniform(-0.3, 0.3, n)
    c, s = np.cos(angles), np.sin(angles)
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -s, s, c
    shift = centres - np.einsum("kij,kj->ki", out[:, :3, :3], centres)
    out[:, :3, 3] = shift + rng.uniform(0, 0.02, (n, 1)) * (hi - lo)
    return out


def _wave(base: Scene, frame: int) -> np.ndarray:
    """Every vertex of ``base`` lifted by a wave across the scene (a twentieth of its size
    high), travelling with ``frame``."""
    v = base.vertices.astype(np.float64)
    lo, hi = (np.asarray(x, np.float64) for x in base.bounds)
    size = float(np.linalg.norm(hi - lo))
    u = (v - lo) / np.maximum(hi - lo, 1e-12)
    lift = 0.05 * size * np.sin(2 * np.pi * (2 * u[:, 0] + 0.1 * frame)) * np.cos(3 * u[:, 1])
    v[:, 2] += lift
    return v.astype(np.float32)


def _deformed(base: Scene, o: np.ndarray, d: np.ndarray, rounds: int) -> dict[str, Any]:
    """A deformation of ``base`` and its refit, and rays on it against a fresh build."""
    waves = [_wave(base, k) for k in range(rounds + 1)]
    shape = base.deformed(waves[0])
    ss.bvh_stats(shape)
    fresh = Scene.from_arrays(
        shape.vertices, shape.faces, object_ids=shape.object_ids, objects=shape.objects
    )
    for scene in (shape, fresh):  # built, and each first call's set-up done, before timing
        ss.cast_rays(scene, o[:64], d[:64])
    frames = iter(range(1, 10**9))

    def deform() -> None:
        ss.bvh_stats(base.deformed(waves[next(frames) % len(waves)]))

    return {
        "deform_s": _median(deform, rounds),
        "rays_deformed_s": _median(lambda: ss.cast_rays(shape, o, d), rounds),
        "rays_fresh_s": _median(lambda: ss.cast_rays(fresh, o, d), rounds),
        "deform_refit": ss.bvh_stats(shape)["sah"] != ss.bvh_stats(fresh)["sah"],
    }


def _rays(scene: Scene, n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    lo, hi = scene.bounds
    o = rng.uniform(lo, hi, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    return o, d


def _median(f: Callable[[], Any], rounds: int) -> float:
    return statistics.median(_seconds(lambda _: f(), None) for _ in range(rounds))


def _seconds(f: Callable[[Any], Any], arg: Any) -> float:
    t = time.perf_counter()
    f(arg)
    return time.perf_counter() - t


def _peers(flat: Scene, o: np.ndarray, d: np.ndarray, cam: Any) -> dict[str, Callable]:
    """Each peer's frame on `flat`'s geometry: its update, the rays and the camera's rays."""
    po, pd = (np.asarray(a, np.float32).reshape(-1, 3) for a in cam.pixel_rays())
    out: dict[str, Callable] = {}
    v = np.ascontiguousarray(flat.vertices, np.float32)
    f = np.ascontiguousarray(flat.faces, np.int32)
    origins, dirs = np.concatenate([o, po]), np.concatenate([d, pd])
    try:
        import fcpw

        fs = fcpw.scene_3D()
        fs.set_object_count(1)
        fs.set_object_vertices(v, 0)
        fs.set_object_triangles(f, 0)
        fs.build(fcpw.aggregate_type.bvh_surface_area, True)
        of, df = np.asfortranarray(origins), np.asfortranarray(dirs)
        bounds = np.full(len(origins), np.inf, np.float32)

        def fcpw_frame(vertices: np.ndarray) -> None:
            fs.update_object_vertices(vertices, 0)
            fs.refit()
            fs.intersect(of, df, bounds, fcpw.interaction_3D_list())

        out["fcpw"] = fcpw_frame
    except ImportError:
        pass
    try:
        import open3d as o3d

        rays = o3d.core.Tensor(np.concatenate([origins, dirs], axis=1))

        def open3d_frame(vertices: np.ndarray) -> None:
            rs = o3d.t.geometry.RaycastingScene()
            rs.add_triangles(o3d.core.Tensor(vertices), o3d.core.Tensor(f.astype(np.uint32)))
            rs.cast_rays(rays)

        out["open3d"] = open3d_frame
    except ImportError:
        pass
    return out


def _one(name: str, scene: Scene, quick: bool, rounds: int) -> dict[str, Any]:
    base, tiles = _tiling(scene, quick)
    n_rays = 16_384 if quick else 262_144
    size = 128 if quick else 512
    o, d = _rays(base, n_rays)
    lo, hi = base.bounds
    mid = (lo + hi) / 2
    cam = ss.Camera.look_at(
        mid + np.array([0.0, -1.2, 0.9]) * np.linalg.norm(hi - lo),
        mid,
        (0.0, 0.0, 1.0),
        yfov=0.8,
        width=size,
        height=size,
    )
    centres = _centres(base)
    poses = [_poses(base, k, centres) for k in range(rounds + 1)]
    t = time.perf_counter()
    first = base.posed(poses[0])
    ss.bvh_stats(first)
    first_pose = time.perf_counter() - t
    flat = Scene.from_arrays(
        first.vertices, first.faces, object_ids=first.object_ids, objects=first.objects
    )
    frames = iter(range(1, 10**9))

    def pose() -> Scene:
        s = base.posed(poses[next(frames) % len(poses)])
        ss.bvh_stats(s)
        return s

    def build() -> None:
        s = Scene.from_arrays(
            first.vertices, first.faces, object_ids=first.object_ids, objects=first.objects
        )
        ss.bvh_stats(s)

    ss.bvh_stats(flat)
    pose_s = _median(pose, rounds)
    build_s = _median(build, rounds)
    rays_posed = _median(lambda: ss.cast_rays(first, o, d), rounds)
    rays_flat = _median(lambda: ss.cast_rays(flat, o, d), rounds)
    po, pd = cam.pixel_rays()
    po = np.ascontiguousarray(np.broadcast_to(po, pd.shape).reshape(-1, 3), np.float32)
    pd = np.ascontiguousarray(pd.reshape(-1, 3), np.float32)
    primary_posed = _median(lambda: ss.cast_rays(first, po, pd), rounds)
    primary_flat = _median(lambda: ss.cast_rays(flat, po, pd), rounds)

    def frame() -> None:
        s = pose()
        ss.cast_rays(s, o, d)
        ss.discretize(s, cameras=[cam], backend="cpu")

    frame_s = _median(frame, rounds)
    peers = {}
    verts = [np.ascontiguousarray(base.posed(p).vertices) for p in poses[:2]]
    for peer, frame_of in _peers(flat, o, d, cam).items():
        peers[peer] = statistics.median(_seconds(frame_of, verts[k % 2]) for k in range(rounds))
    return {
        "scene": name,
        "triangles": len(base.faces),
        "objects": tiles,
        "first_pose_s": first_pose,
        "pose_s": pose_s,
        "build_s": build_s,
        "rays_posed_s": rays_posed,
        "rays_flat_s": rays_flat,
        "primary_posed_s": primary_posed,
        "primary_flat_s": primary_flat,
        "instances": ss.bvh_stats(first)["instances"],
        "frame_s": frame_s,
        "peers_s": peers,
        **_deformed(base, o, d, rounds),
        "rays": n_rays,
        "image": size,
    }


def _skinned(quick: bool, rounds: int) -> dict[str, Any]:
    """The skinned frame: ``Scene.at`` with its refit, rays and an image, against a fresh
    build, and a frame against the peers."""
    with tempfile.TemporaryDirectory() as folder:
        scene = Scene.load(bending_tube(Path(folder), rows=20 if quick else 200))
    n_rays = 16_384 if quick else 262_144
    size = 128 if quick else 512
    times = [0.25 * k for k in range(rounds + 1)]
    first = scene.at(times[0])
    ss.bvh_stats(first)
    o, d = _rays(first, n_rays)
    lo, hi = first.bounds
    mid = (lo + hi) / 2
    cam = ss.Camera.look_at(
        mid + np.array([0.0, 0.0, 1.5]) * np.linalg.norm(hi - lo),
        mid,
        (0.0, 1.0, 0.0),
        yfov=0.8,
        width=size,
        height=size,
    )
    frames = iter(range(1, 10**9))

    def pose() -> Scene:
        s = scene.at(times[next(frames) % len(times)])
        ss.bvh_stats(s)
        return s

    def build() -> None:
        ss.bvh_stats(Scene.from_arrays(first.vertices, first.faces))

    def frame() -> None:
        s = pose()
        ss.cast_rays(s, o, d)
        ss.discretize(s, cameras=[cam], backend="cpu")

    fresh = Scene.from_arrays(first.vertices, first.faces)
    ss.bvh_stats(fresh)
    out = {
        "triangles": len(first.faces),
        "pose_s": _median(pose, rounds),
        "build_s": _median(build, rounds),
        "rays_posed_s": _median(lambda: ss.cast_rays(first, o, d), rounds),
        "rays_flat_s": _median(lambda: ss.cast_rays(fresh, o, d), rounds),
        "frame_s": _median(frame, rounds),
        "refit": ss.bvh_stats(first)["sah"] != ss.bvh_stats(fresh)["sah"],
    }
    verts = [np.ascontiguousarray(scene.at(t).vertices) for t in times[:2]]
    out["peers_s"] = {
        peer: statistics.median(_seconds(frame_of, verts[k % 2]) for k in range(rounds))
        for peer, frame_of in _peers(fresh, o, d, cam).items()
    }
    return out


def run(quick: bool, rounds: Optional[int], only: Optional[list[str]]) -> dict[str, Any]:
    rounds = rounds or (2 if quick else 5)
    out, skipped = [], []
    for name, path in shared_scene_files().items():
        if only and not any(s in name for s in only):
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = Scene.load(path)
        n = len(scene.faces)
        if n < MIN_TRIANGLES or (not quick and 100 * n > MAX_TILED):
            skipped.append(name)
            continue
        out.append(_one(name, scene, quick, rounds))
        print(f"  {name}: done", flush=True)
    skinned = _skinned(quick, rounds)
    return {
        "scenes": out,
        "skinned": skinned,
        "rounds": rounds,
        "quick": quick,
        "skipped": skipped,
    }


def report(r: dict[str, Any]) -> str:
    rows = r["scenes"]
    lines = [
        "# `python -m scenesample.bench scenes`",
        "",
        __doc__.split("\n\n", 1)[1].strip(),
        "",
        f"Medians of {r['rounds']} rounds. Not measured: shared scenes below {MIN_TRIANGLES} "
        f"triangles, or whose 100 tiles would exceed {MAX_TILED:,} "
        f"({', '.join(r.get('skipped', [])) or 'none'}).",
        "",
        "| scene | triangles | objects | first pose s | pose s | build s | pose / build "
        "| posed rays / flat | posed primary / flat | frame s | frame vs fcpw | frame vs Open3D "
        "| deform s | deform / build | deformed rays / fresh |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for s in rows:
        p = s["peers_s"]
        vs = {k: f"{p[k] / s['frame_s']:.2f}x" if k in p else "-" for k in ("fcpw", "open3d")}
        lines.append(
            f"| {s['scene']} | {s['triangles']:,} | {s['objects']} | {s['first_pose_s']:.3f} "
            f"| {s['pose_s']:.4f} | {s['build_s']:.3f} | {s['pose_s'] / s['build_s']:.1%} "
            f"| {s['rays_flat_s'] / s['rays_posed_s']:.2f}x "
            f"| {s['primary_flat_s'] / s['primary_posed_s']:.2f}x | {s['frame_s']:.3f} "
            f"| {vs['fcpw']} | {vs['open3d']} | {s['deform_s']:.4f} "
            f"| {s['deform_s'] / s['build_s']:.1%}{'' if s['deform_refit'] else ' (rebuilt)'} "
            f"| {s['rays_fresh_s'] / s['rays_deformed_s']:.2f}x |"
        )
    if rows:
        worst = lambda f: max(rows, key=f)  # noqa: E731
        w1 = worst(lambda s: s["pose_s"] / s["build_s"])
        lines += [
            "",
            "| target | worst | scene | verdict |",
            "|---|---:|---|---|",
            f"| a new pose <= 1% of a build | {w1['pose_s'] / w1['build_s']:.2%} "
            f"| {w1['scene']} | {'met' if w1['pose_s'] <= 0.01 * w1['build_s'] else 'NOT met'} |",
        ]
        for kind, key in (("incoherent", "rays"), ("primary", "primary")):
            w2 = worst(lambda s: s[f"{key}_posed_s"] / s[f"{key}_flat_s"])  # noqa: B023
            r2 = w2[f"{key}_flat_s"] / w2[f"{key}_posed_s"]
            lines.append(
                f"| posed {kind} rays >= 0.9x flat | {r2:.2f}x | {w2['scene']} "
                f"| {'met' if r2 >= 0.9 else 'NOT met'} |"
            )
        w3 = worst(lambda s: s["deform_s"] / s["build_s"])
        w4 = worst(lambda s: s["rays_deformed_s"] / s["rays_fresh_s"])
        r3, r4 = w3["deform_s"] / w3["build_s"], w4["rays_fresh_s"] / w4["rays_deformed_s"]
        lines += [
            f"| a deformation <= 10% of a build | {r3:.1%} | {w3['scene']} "
            f"| {'met' if r3 <= 0.10 else 'NOT met'} |",
            f"| deformed rays >= 0.8x a fresh build | {r4:.2f}x | {w4['scene']} "
            f"| {'met' if r4 >= 0.8 else 'NOT met'} |",
        ]
        for peer in ("fcpw", "open3d"):
            have = [s for s in rows if peer in s["peers_s"]]
            if have:
                w = min(have, key=lambda s: s["peers_s"][peer] / s["frame_s"])
                ratio = w["peers_s"][peer] / w["frame_s"]
                lines.append(
                    f"| frame >= 3x {peer} | {ratio:.2f}x | {w['scene']} "
                    f"| {'met' if ratio >= 3 else 'NOT met'} |"
                )
    k = r.get("skinned")
    if k:
        vs = {p: k["peers_s"][p] / k["frame_s"] for p in k["peers_s"]}
        lines += [
            "",
            f"Skinned frame ({k['triangles']:,} triangles, 8 joints; "
            f"{'refit' if k['refit'] else 'built afresh'}):",
            "",
            "| at(t) and BVH s | fresh build s | at / build | rays / fresh | frame s "
            "| frame vs fcpw | frame vs Open3D |",
            "|---:|---:|---:|---:|---:|---:|---:|",
            f"| {k['pose_s']:.4f} | {k['build_s']:.4f} | {k['pose_s'] / k['build_s']:.1%} "
            f"| {k['rays_flat_s'] / k['rays_posed_s']:.2f}x | {k['frame_s']:.3f} | "
            + " | ".join(
                f"{vs[p]:.2f}x ({'met' if vs[p] >= 3 else 'NOT met'})" if p in vs else "-"
                for p in ("fcpw", "open3d")
            )
            + " |",
        ]
    return "\n".join(lines) + "\n"
