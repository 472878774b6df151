"""One labelled panel per paper, each on a shared real scene (procedural stand-ins where
``../shared/scenes`` is absent), one of what every sample carries (texture colour and shading
normals), and one accuracy-vs-time sweep: what the package's methods do, at a glance.

    python -m scenesample.gallery [--out DIR] [--quick]     # writes DIR/gallery.png

``make demo`` writes ``out/gallery.png``; the README's copy is ``docs/gallery.png``, made by
``python -m scenesample.gallery --out docs``. ``--quick`` uses small images (the test).
"""

from __future__ import annotations

import argparse
import textwrap
import time
import warnings
from pathlib import Path
from typing import Any, Optional

import numpy as np

import scenesample as ss

from .._optional import pyplot
from ..imageio import ids_to_rgb, linear_to_srgb

#: The scene of each panel: a shared scene when present, else a procedural one.
SCENES = {
    "nonredundant": ("stanford_bunny", lambda: ss.scenes.shapes(seed=1, detail=2)),
    "reflections": ("khr_transmission_test", lambda: ss.scenes.reflective_room(spheres=6)),
    "field": ("khr_simple_instancing", ss.scenes.turtles),
    "impostors": ("stanford_bunny", lambda: ss.scenes.shapes(seed=2, detail=2)),
    "samples": ("khr_toy_car", lambda: ss.scenes.shapes(seed=3, detail=2)),
}
NEW = np.array([1.0, 0.55, 0.1])  # the tint of samples a non-redundant image adds
SIZE, QUICK = 256, 96  # panel image sizes: the README's, and --quick's


def _scene(panel: str) -> tuple[ss.Scene, str]:
    name, fallback = SCENES[panel]
    shared = ss.scenes.shared_scene_files()
    if name in shared:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ss.SceneWarning)
            return ss.Scene.load(shared[name]), name
    scene = fallback()
    return scene, "procedural"


def _view(scene: ss.Scene, size: int, direction=(0.6, 0.45, 0.8), distance: float = 1.0):
    lo, hi = scene.bounds.astype(np.float64)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    d = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    return ss.Camera.look_at(
        c + d * r / np.sin(0.4) * distance, c, yfov=0.8, width=size, height=size
    )


def _grey(images: ss.DepthImages, i: int) -> np.ndarray:
    """Image i's surfaces in grey by their normal's facing of the camera (linear RGB)."""
    n = images.normal[i].astype(np.float64)
    forward = -np.asarray(images.cameras[i].pose, np.float64)[:3, 2]
    shade = 0.25 + 0.6 * np.abs(n @ forward)
    return np.where(images.mask[i][..., None], shade[..., None] * np.ones(3), 0.0)


def nonredundant_panel(size: int) -> dict[str, Any]:
    """Conventional image 1 of three reference views, and non-redundant image 1: where image 0
    already sampled the surface it samples the next surface behind (§3), tinted where its
    triangle is in none of the three conventional images."""
    scene, name = _scene("nonredundant")
    up = "z" if name == "procedural" else "y"
    cams = ss.scenes.reference_cameras(scene, size, up=up)
    conv = ss.discretize(scene, cams, backend="gpu")
    nr = ss.discretize(scene, cams, "nonredundant", backend="gpu")
    seen = np.unique(conv.triangle[conv.mask])
    new = nr.mask[1] & ~np.isin(nr.triangle[1], seen)
    tinted = np.where(new[..., None], NEW, _grey(nr, 1))
    n_conv, n_nr = len(seen), len(np.unique(nr.triangle[nr.mask]))
    return {
        "title": f"non-redundant rendering ({name}), view 1 of 3",
        "images": [linear_to_srgb(_grey(conv, 1)), linear_to_srgb(tinted)],
        "labels": [
            f"conventional: 3 views sample {n_conv:,} triangles",
            f"non-redundant: {n_nr:,} triangles; orange: samples of triangles no "
            "conventional view holds",
        ],
    }


def reflections_panel(size: int) -> dict[str, Any]:
    scene, name = _scene("reflections")
    eye = _view(scene, size, (0.3, 0.5, 1.0), 0.8)
    out = {}
    for method in ("epr", "mvr"):
        t = time.perf_counter()
        r = ss.reflections(scene, eye, method=method)
        out[method] = (r, time.perf_counter() - t)
    diff = ss.evaluate(out["epr"][0], out["mvr"][0], "image")
    labels = [
        f"{m.upper()}: {s:.2f} s, {int(r.stats.get('shading_ops', 0)):,} shading ops"
        for m, (r, s) in out.items()
    ]
    labels[0] += f"; vs MVR {diff['psnr']:.1f} dB"
    return {
        "title": f"eye-based point rendering: reflections ({name})",
        "images": [out[m][0].to_srgb8() for m in ("epr", "mvr")],
        "labels": labels,
    }


def field_panel(size: int) -> dict[str, Any]:
    """The view drawn with every triangle (grey), and the cells the field drew for it, each in
    its own colour over the grey (red: a visible cell it missed)."""
    scene, name = _scene("field")
    field = ss.discretize(scene, method="visibility_field", quality="fast", progress=False)
    cam = _view(scene, size, (-0.7, 0.6, 0.5), 0.9)
    view = ss.reconstruct(field, cam)
    cells = ss.evaluate(view, scene, "cells")
    full = ss.discretize(scene, cam, backend="gpu")
    # A triangle in no cell (degenerate: cell_of is 2^32 - 1) shows as background.
    cell_of = np.asarray(field.cell_of).astype(np.int64)
    cell_of[cell_of >= len(view.marked)] = -1
    ids = np.where(full.mask[0], cell_of[np.maximum(full.triangle[0], 0)], -1)
    drawn = (ids >= 0) & view.marked[np.maximum(ids, 0)]
    grey = linear_to_srgb(_grey(full, 0))
    over = np.where(drawn[..., None], ids_to_rgb(np.where(drawn, ids, -1)), grey)
    over[cells["hole_mask"]] = (255, 0, 0)
    return {
        "title": f"visibility field ({name}, quality='fast')",
        "images": [grey, over],
        "labels": [
            f"all triangles: {int(cells['cells_visible'])} cells visible",
            f"the field drew {int(cells['cells_rendered'])} of {len(view.marked)} cells; "
            f"missed {int(cells['missed_cells'])} (red)",
        ],
    }


def samples_panel(size: int) -> dict[str, Any]:
    """What every sample carries, as viewers draw it: the base-colour texture sampled per
    pixel (filtered for its footprint), and the file's normals interpolated (shading normals),
    against the faces' own normals."""
    scene, name = _scene("samples")
    cam = _view(scene, size, (0.5, 0.45, 0.9), 0.75)
    img = ss.discretize(scene, cam, backend="gpu")
    mask = img.mask[0]
    n = img.shading_normal[0]
    shown = np.where(mask[..., None], (n * 0.5 + 0.5) * 255, 0).round().astype(np.uint8)
    cos = np.clip((n[mask] * img.normal[0][mask]).sum(-1), -1, 1)
    textured = sum(m["base_color_textured"] for m in scene.materials)
    resolve = img.timings.get("resolve", 0.0) * 1e3
    return {
        "title": f"every sample's colour and normal ({name})",
        "images": [linear_to_srgb(img.color[0]), shown],
        "labels": [
            f"color: {textured} textured materials sampled per pixel (bilinear / trilinear by "
            f"footprint); resolve {resolve:.0f} ms",
            f"shading_normal: the file's normals interpolated; "
            f"{np.degrees(np.median(np.arccos(cos))):.1f}° from the faces' at the median",
        ],
    }


def impostors_panel(size: int) -> dict[str, Any]:
    scene, name = _scene("impostors")
    # --quick's 96-pixel panel shows each cell a few pixels wide: 32² impostor images are
    # enough there, and build in a quarter of the time of the README's 64² ones.
    resolution = 64 if size >= SIZE else 32
    t = time.perf_counter()
    imp = ss.discretize(
        scene, method="impostors", octree_depth=2, resolution=resolution, progress=False
    )
    build = time.perf_counter() - t
    cam = _view(scene, size, (0.5, 0.3, 0.8), 3.0)
    view = ss.reconstruct(imp, cam)
    truth = ss.ImpostorView.of_triangles(scene, cam)
    err = ss.evaluate(view, truth, "impostor")
    return {
        "title": f"impostors ({name}, 3x its size away; crop, 3x zoom)",
        "images": [_crop(view.color, truth.mask), _crop(truth.color, truth.mask)],
        "labels": [
            f"impostors ({len(imp.cells)} cells, built in {build:.1f} s): "
            f"{view.timings['total'] * 1e3:.0f} ms",
            f"triangles: {truth.timings['total'] * 1e3:.0f} ms; error "
            f"{err['error_per_foreground_pixel']:.1f}/px",
        ],
    }


def _crop(img: np.ndarray, mask: np.ndarray, zoom: int = 3) -> np.ndarray:
    """The square around the middle of ``img`` a ``zoom``-th of its side (and all of
    ``mask``'s pixels when they reach farther), scaled back up by pixel repetition."""
    h, w = mask.shape
    side = max(h // zoom, 1)
    ys, xs = np.nonzero(mask)
    cy, cx = (int(ys.mean()), int(xs.mean())) if len(ys) else (h // 2, w // 2)
    y0 = int(np.clip(cy - side // 2, 0, h - side))
    x0 = int(np.clip(cx - side // 2, 0, w - side))
    part = img[y0 : y0 + side, x0 : x0 + side]
    return np.repeat(np.repeat(part, zoom, axis=0), zoom, axis=1)


def tradeoff_panel() -> dict[str, Any]:
    scene, name = _scene("impostors")
    table = ss.tradeoff(
        scene,
        "impostors",
        knobs={"octree_depth": [0, 1, 2], "resolution": [16, 32]},
        camera=_view(scene, 128, (0.5, 0.3, 0.8), 3.0),
        progress=False,
        as_frame=False,
    )
    return {"title": f"accuracy vs time: impostors ({name})", "table": table}


def make(out: Path, size: int = SIZE) -> Path:
    """Compute every panel and write ``out/gallery.png``; returns its path. Needs matplotlib
    (:class:`~scenesample.errors.MissingDependencyError` without it, before any work)."""
    plt = pyplot("the gallery")
    panels = [
        nonredundant_panel(size),
        reflections_panel(size),
        field_panel(size),
        impostors_panel(size),
        samples_panel(size),
    ]
    sweep = tradeoff_panel()
    fig = plt.figure(figsize=(18, 8.5), dpi=100)
    grid = fig.add_gridspec(2, 3, hspace=0.3, wspace=0.22)
    spots = [grid[0, 0], grid[0, 1], grid[0, 2], grid[1, 0], grid[1, 1]]
    for spot, p in zip(spots, panels):
        sub = spot.subgridspec(1, 2, wspace=0.04)
        for k, (img, label) in enumerate(zip(p["images"], p["labels"])):
            ax = fig.add_subplot(sub[0, k])
            ax.imshow(img)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_xlabel(textwrap.fill(label, 34), fontsize=8)
            if k == 0:
                ax.set_title(p["title"], fontsize=10, loc="left")
    ax = fig.add_subplot(grid[1, 2])
    ss.plot.tradeoff(sweep["table"], ax=ax)
    ax.set_title(sweep["title"], fontsize=10, loc="left")
    ax.set_title("")  # the plot's own centred title: the panel's says it
    title = "scenesample: one panel per paper, and what every sample carries"
    fig.suptitle(title, fontsize=13, x=0.01, y=0.96, ha="left")
    out.mkdir(parents=True, exist_ok=True)
    path = out / "gallery.png"
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--quick", action="store_true", help="small images")
    a = p.parse_args(argv)
    t = time.perf_counter()
    path = make(Path(a.out), QUICK if a.quick else SIZE)
    print(f"wrote {path} in {time.perf_counter() - t:.1f} s")


if __name__ == "__main__":
    main()
