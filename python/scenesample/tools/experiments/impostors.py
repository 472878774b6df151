"""Multi-cell orthographic impostors against rendering the triangles
(multi-cell-orthographic-impostors.txt §5): analogues of Fig. 2 (error per foreground pixel vs
relative camera distance), Fig. 8 (single cell vs multi-cell), Fig. 14 (orthographic vs
perspective 40/60/90-degree impostors), Figs. 4-7 (gap pixels with and without cell growing),
Fig. 15 (a triangle budget for the nearest cells) and the storage and deflate ratio vs octree
depth (the paper: ~18%).

Scenes: ``stanford_bunny`` and a large real scene (``khr_toy_car``) from ``../shared/scenes``
when present, and the procedural ``urban``. Cameras look at the scene's centre from a fixed
direction at ``--distances`` bounding-box diagonals, their field of view narrowed so the scene
keeps its size on screen (so the error measured is the impostors', not the sampling of a
shrinking object). Writes ``impostors.csv``, ``storage.csv``, ``impostors.md``,
``fig2_<scene>.png`` (error vs distance, every variant), ``fig15_<scene>.png`` (error vs
distance with triangle budgets) and ``fig8_<scene>.png`` (triangles, single cell, multi-cell,
multi-cell error) to ``--out``.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import time
from pathlib import Path
from typing import Any, Optional

import numpy as np

import scenesample as ss

from ..._optional import pyplot
from ..._progress import steps
from ...imageio import write_png
from ._tables import write_csv

DIRECTION = np.array([0.3, 0.4, 1.0]) / np.linalg.norm([0.3, 0.4, 1.0])


def load(name: str) -> tuple[ss.Scene, tuple[float, float, float]]:
    """The scene and its up vector."""
    if name in ss.scenes.PAPER_SCENES:
        return ss.scenes.PAPER_SCENES[name](), (0.0, 0.0, 1.0)
    files = ss.scenes.shared_scene_files()
    if name not in files:
        raise SystemExit(
            f"unknown scene {name!r}: one of {list(ss.scenes.PAPER_SCENES)} or, with "
            f"../shared/scenes present, {list(files)}"
        )
    return ss.Scene.load(files[name]), (0.0, 1.0, 0.0)


def camera(scene: ss.Scene, up: Any, distance: float, size: int) -> Any:
    lo, hi = scene.bounds.astype(np.float64)
    c, diag = (lo + hi) / 2, np.linalg.norm(hi - lo)
    d = DIRECTION if abs(np.dot(DIRECTION, up)) < 0.9 else np.array([1.0, 0.2, 0.1])
    eye = c + d / np.linalg.norm(d) * distance * diag
    yfov = 2 * np.arctan(0.6 / distance)
    return ss.Camera.look_at(tuple(eye), tuple(c), tuple(up), yfov=yfov, width=size, height=size)


def variants(args: Any) -> dict[str, dict[str, Any]]:
    kw = dict(subdivisions=args.subdivisions, resolution=args.resolution)
    out = {
        "single cell": dict(octree_depth=0, **kw),
        f"multi-cell (depth {args.octree_depth})": dict(octree_depth=args.octree_depth, **kw),
        "multi-cell, no growing": dict(octree_depth=args.octree_depth, grow=False, **kw),
    }
    for deg in (40, 60, 90):
        out[f"perspective {deg}"] = dict(
            octree_depth=args.octree_depth,
            projection="perspective",
            fov=float(np.radians(deg)),
            **kw,
        )
    return out


def run_scene(name: str, args: Any, out: Path) -> tuple[list[dict], list[dict]]:
    scene, up = load(name)
    rows, storage = [], []
    built = {}
    for label, kw in variants(args).items():
        t = time.perf_counter()
        imp = ss.discretize(scene, method="impostors", **kw)
        built[label] = imp
        print(f"  {name}: {label}: {len(imp.cells)} cells, {time.perf_counter() - t:.1f} s")
        for d in args.distances:
            cam = camera(scene, up, d, args.size)
            ref = ss.ImpostorView.of_triangles(scene, cam)
            view = ss.reconstruct(imp, cam)
            e = ss.evaluate(view, ref)
            rows.append(_row(name, scene, label, imp, d, 0, view, ref, e))
    multi_label = f"multi-cell (depth {args.octree_depth})"
    multi = built[multi_label]
    for frac in args.budgets:
        if frac == 0:
            continue
        budget = int(frac * scene.triangle_count)
        for d in args.distances:
            cam = camera(scene, up, d, args.size)
            ref = ss.ImpostorView.of_triangles(scene, cam)
            view = ss.reconstruct(multi, cam, triangle_budget=budget, scene=scene)
            rows.append(
                _row(name, scene, multi_label, multi, d, frac, view, ref, ss.evaluate(view, ref))
            )
    for depth in args.storage_octree_depths:
        t = time.perf_counter()
        imp = ss.discretize(
            scene,
            method="impostors",
            octree_depth=depth,
            subdivisions=args.subdivisions,
            resolution=args.resolution,
        )
        storage.append(
            {
                "scene": name,
                "depth": depth,
                "cells": len(imp.cells),
                "views": len(imp.directions),
                "resolution": args.resolution,
                "seconds": time.perf_counter() - t,
                "bytes_raw": imp.stats["bytes_raw"],
                "bytes_compressed": imp.stats["bytes_compressed"],
                "ratio": imp.stats["bytes_compressed"] / max(imp.stats["bytes_raw"], 1),
            }
        )
    figures(name, scene, up, rows, built, multi_label, args, out)
    return rows, storage


def _row(name, scene, label, imp, d, frac, view, ref, e) -> dict[str, Any]:
    return {
        "scene": name,
        "triangles": scene.triangle_count,
        "variant": label,
        "cells": len(imp.cells),
        "distance": d,
        "budget_fraction": frac,
        "error_per_foreground_pixel": e["error_per_foreground_pixel"],
        "pixel_error": e["pixel_error"],
        "gap_pixels": e["gap_pixels"],
        "rmse": e["rmse"],
        "triangles_drawn": view.stats["triangles_drawn"],
        "cells_impostors": view.stats["cells_impostors"],
        "time_view": view.timings["total"],
        "time_triangles": ref.timings["total"],
    }


def figures(name, scene, up, rows, built, multi_label, args, out: Path) -> None:
    plt = pyplot("the impostors experiment's figures")

    def error_vs_distance(series, xlabel: str, ylabel: str, title: str, path: Path) -> None:
        """One line per (label, rows) of error per foreground pixel against distance."""
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        for label, sel in series:
            ax.plot(
                [r["distance"] for r in sel],
                [r["error_per_foreground_pixel"] for r in sel],
                "o-",
                label=label,
            )
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    error_vs_distance(
        [
            (label, [r for r in rows if r["variant"] == label and r["budget_fraction"] == 0])
            for label in built
        ],
        "relative camera distance (bounding-box diagonals)",
        "error per foreground pixel (sum |dRGB|, 0-765)",
        f"{name}: impostors vs triangles",
        out / f"fig2_{name}.png",
    )
    error_vs_distance(
        [
            (
                f"budget {frac:.0%} of the triangles",
                [r for r in rows if r["variant"] == multi_label and r["budget_fraction"] == frac],
            )
            for frac in sorted({r["budget_fraction"] for r in rows})
        ],
        "relative camera distance",
        "error per foreground pixel",
        f"{name}: nearest cells as triangles ({multi_label})",
        out / f"fig15_{name}.png",
    )

    cam = camera(scene, up, 1.0, args.size)
    ref = ss.ImpostorView.of_triangles(scene, cam)
    single = ss.reconstruct(built["single cell"], cam)
    multi = ss.reconstruct(built[multi_label], cam)
    diff = np.abs(multi.color - ref.color).sum(-1, keepdims=True)
    tiles = [ref.to_srgb8(), single.to_srgb8(), multi.to_srgb8()]
    tiles.append((np.clip(np.repeat(diff, 3, axis=2), 0, 1) * 255).astype(np.uint8))
    write_png(out / f"fig8_{name}.png", np.concatenate(tiles, axis=1))


def markdown(rows: list[dict], storage: list[dict], args: Any) -> str:
    when = datetime.date.today().isoformat()
    cpu = platform.processor() or platform.machine()
    dists = sorted({r["distance"] for r in rows})
    lines = [
        f"Impostors vs triangles; {when}, {cpu}, {ss.device_info()['name']}. Octree depth "
        f"{args.octree_depth}, {20 * 4**args.subdivisions} views per cell, "
        f"{args.resolution}^2 images; "
        f"{args.size}^2 views at a constant on-screen size. Error per foreground pixel (the "
        "paper's p_diff over the reference's foreground rectangle, 0-765) / interior gap "
        "pixels, by relative camera distance.",
        "",
        "| scene | variant | budget | cells | " + " | ".join(f"d = {d}" for d in dists) + " |",
        "|---|---|---:|---:|" + "---:|" * len(dists),
    ]
    keys = []
    for r in rows:
        k = (r["scene"], r["variant"], r["budget_fraction"])
        if k not in keys:
            keys.append(k)
    for k in keys:
        sel = {
            r["distance"]: r for r in rows if (r["scene"], r["variant"], r["budget_fraction"]) == k
        }
        cells = next(iter(sel.values()))["cells"]
        vals = " | ".join(
            f"{sel[d]['error_per_foreground_pixel']:.1f} / {sel[d]['gap_pixels']}" for d in dists
        )
        lines.append(f"| {k[0]} | {k[1]} | {k[2]:.0%} | {cells} | {vals} |")
    lines += [
        "",
        "Storage of the cropped images (4 bytes of colour + 4 of depth per texel) and deflate "
        "(zlib level 6, one stream per cell).",
        "",
        "| scene | octree depth | cells | views | build s | raw bytes | deflated | ratio |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for s in storage:
        lines.append(
            f"| {s['scene']} | {s['depth']} | {s['cells']} | {s['views']} | {s['seconds']:.1f} | "
            f"{s['bytes_raw']:,} | {s['bytes_compressed']:,} | {s['ratio']:.1%} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(prog="python -m scenesample.experiments impostors")
    p.add_argument("--scenes", nargs="+", default=["stanford_bunny", "khr_toy_car", "urban"])
    p.add_argument("--distances", type=float, nargs="+", default=[0.5, 0.75, 1, 1.5, 2, 4])
    p.add_argument("--octree-depth", type=int, default=2)
    p.add_argument("--subdivisions", type=int, default=2)
    p.add_argument("--resolution", type=int, default=32)
    p.add_argument("--budgets", type=float, nargs="+", default=[0, 0.1, 0.3])
    p.add_argument("--storage-octree-depths", type=int, nargs="*", default=[0, 1, 2, 3])
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--out", default="out/experiments/impostors")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, storage = [], []
    files = ss.scenes.shared_scene_files()
    for name in steps(args.scenes, "impostors", "scenes"):
        if name not in ss.scenes.PAPER_SCENES and name not in files:
            print(f"  skipping {name}: ../shared/scenes/{name} is not present")
            continue
        r, s = run_scene(name, args, out)
        rows += r
        storage += s
    write_csv(out / "impostors.csv", rows)
    if storage:
        write_csv(out / "storage.csv", storage)
    md = markdown(rows, storage, args)
    (out / "impostors.md").write_text(md)
    print(md)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
