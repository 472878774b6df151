"""The main job: load a scene, discretize it from a few views on the GPU, cross-check the
triangle ids with CPU ray casts, write EXR and PNG images, and print what each stage cost.

    python -m scenesample.demo [--scene PATH] [--out DIR] [--views N] [--size W H] [--quick]

Without --scene it uses a real scene from ../shared/scenes when that folder is present (the toy
car, else the bunny), otherwise a procedural one. With scenesample alone (numpy its only
dependency) it does everything but the gallery (matplotlib) and the contact sheet's labels
(Pillow), and says in one line how to get them: ``pip install 'scenesample[demo]'``.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path
from typing import Optional

import numpy as np

import scenesample as ss
from scenesample.errors import MissingDependencyError
from scenesample.imageio import (
    depth_to_rgb,
    ids_to_rgb,
    labelled_sheet,
    linear_to_srgb,
    normal_to_rgb,
    plain_sheet,
    write_png,
)
from scenesample.tools import gallery

PREFERRED = ("khr_toy_car", "stanford_bunny", "cornell_box")


def pick_scene(path: Optional[str], procedural: bool) -> tuple[ss.Scene, str, float]:
    start = time.perf_counter()
    if path:
        return ss.Scene.load(path), path, time.perf_counter() - start
    shared = {} if procedural else ss.scenes.shared_scene_files()
    for name in PREFERRED:
        if name in shared:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", ss.SceneWarning)
                scene = ss.Scene.load(shared[name])
            for w in caught:
                print(f"  note: {str(w.message).split(': ', 1)[-1]}")
            return scene, f"{name} ({shared[name]})", time.perf_counter() - start
    scene = ss.scenes.shapes(seed=0, detail=3)
    return scene, "procedural shapes(seed=0, detail=3)", time.perf_counter() - start


def orbit(scene: ss.Scene, n: int, width: int, height: int) -> list[ss.Camera]:
    lo, hi = scene.bounds.astype(np.float64)
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    yfov = 0.8
    dist = radius / np.sin(yfov / 2) * 0.8  # the bounding sphere overstates most scenes
    cams = []
    for i in range(n):
        a = 2 * np.pi * (i + 0.125) / n
        d = np.array([np.cos(a), 0.6, np.sin(a)])
        eye = centre + d / np.linalg.norm(d) * dist
        cams.append(ss.Camera.look_at(eye, centre, yfov=yfov, width=width, height=height))
    return cams


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--scene", help="a glTF/GLB (or any trimesh-readable) file")
    p.add_argument("--procedural", action="store_true", help="use the procedural scene")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--views", type=int, default=4)
    p.add_argument("--size", type=int, nargs=2, default=(640, 480), metavar=("W", "H"))
    p.add_argument(
        "--quick", action="store_true", help="two small views and a small gallery (the test)"
    )
    a = p.parse_args(argv)
    if a.quick:
        a.views, a.size = 2, (160, 120)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    info = ss.device_info()
    print(f"scenesample {ss.__version__} on {info['name']} ({info['backend']})")
    scene, label, load_s = pick_scene(a.scene, a.procedural)
    print(f"scene: {label}\n  {scene.triangle_count:,} triangles, {len(scene.materials)} materials")

    cams = orbit(scene, a.views, *a.size)
    ss.discretize(scene, cams[:1], backend="gpu")  # first use: device, pipeline, upload
    images = ss.discretize(scene, cams, backend="gpu")

    origins, dirs = cams[0].pixel_rays()
    hits = ss.cast_rays(scene, origins.reshape(-1, 3), dirs.reshape(-1, 3))
    gpu_ids = images.triangle[0].ravel()
    covered = (gpu_ids >= 0) | hits.hit
    agree = float((gpu_ids == hits.triangle)[covered].mean())
    # The same images from the CPU backend (the BVH is built now), and what `auto` picks.
    cpu_images = ss.discretize(scene, cams, backend="cpu")
    auto = ss.discretize(scene, cams)

    # Lit frames, shaded by the package's one shading model (src/shading.rs), no effects.
    start = time.perf_counter()
    frames = [ss.render(scene, c, effects=[]) for c in cams]
    render_s = time.perf_counter() - start

    start = time.perf_counter()
    images.save_exr(out / "views.exr")
    rows = []
    columns = ["lit (auto exposure)", "base colour", "normal", "depth", "triangle id"]
    for i in range(images.n):
        tiles = {
            "lit": frames[i].to_srgb8("auto"),
            "color": linear_to_srgb(images.color[i]),
            "normal": normal_to_rgb(images.normal[i]),
            "depth": depth_to_rgb(images.depth[i]),
            "triangle": ids_to_rgb(images.triangle[i]),
        }
        for name, tile in tiles.items():
            write_png(out / f"view{i}_{name}.png", tile)
        rows.append(list(tiles.values()))
    labels = [f"view {i}" for i in range(images.n)]
    missing: list[MissingDependencyError] = []
    try:
        sheet = labelled_sheet(rows, columns, labels)
    except MissingDependencyError as e:
        sheet = plain_sheet(rows)
        missing.append(e)
    write_png(out / "contact_sheet.png", sheet)
    write_s = time.perf_counter() - start

    # One panel per paper, on one shared scene each (python -m scenesample.gallery).
    start = time.perf_counter()
    try:
        gallery_path: Optional[Path] = gallery.make(out, gallery.QUICK if a.quick else gallery.SIZE)
    except MissingDependencyError as e:
        gallery_path = None
        missing.append(e)
    gallery_s = time.perf_counter() - start

    w, h = a.size
    print(f"\n{images.n} views at {w}x{h}: {images.mask.mean():.1%} of pixels see a surface")
    print(f"GPU triangle ids vs CPU ray casts (view 0): {agree:.3%} of covered pixels agree")
    print(f"backend='auto' chose {auto.backend}: {auto.backend_reason}")
    print("\n| stage | seconds |\n|---|---:|")
    print(f"| load scene | {load_s:.4f} |")
    for stage, secs in images.timings.items():
        print(f"| discretize: {stage} | {secs:.4f} |")
    print(f"| cast_rays: BVH build | {hits.timings['bvh_build']:.4f} |")
    print(f"| discretize, backend='cpu': total | {cpu_images.timings['total']:.4f} |")
    print(f"| discretize, backend='auto' ({auto.backend}): total | {auto.timings['total']:.4f} |")
    print(f"| cast_rays: trace {len(hits):,} rays | {hits.timings['trace']:.4f} |")
    print(f"| render {len(frames)} lit frames | {render_s:.4f} |")
    print(f"| write EXR + PNG | {write_s:.4f} |")
    gallery_cell = "skipped" if gallery_path is None else f"{gallery_s:.4f}"
    print(f"| gallery: one panel per paper | {gallery_cell} |")
    lit = "the scene's lights" if not frames[0].stats["default_light"] else "the default light"
    print(f"\nlit frames: {lit}, shown with auto exposure (Frame.to_srgb8('auto'))")
    wrote = [str(out / "views.exr"), f"{out / 'contact_sheet.png'} (+ one PNG per view and field)"]
    print("wrote " + " and ".join(wrote + ([str(gallery_path)] if gallery_path else [])))
    if missing:
        print(skipped_line(missing))


def skipped_line(missing: list[MissingDependencyError]) -> str:
    """One line: what was skipped for want of which packages, and the command that brings them
    (one extra for all of them)."""
    parts = ", ".join(f"{e.purpose} ({e.package})" for e in missing)
    extras = sorted({e.extra for e in missing})
    return f"skipped {parts}: pip install 'scenesample[{','.join(extras)}]'"


if __name__ == "__main__":
    main()
