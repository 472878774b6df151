"""The visibility field against rendering everything and against visibility tracing
(visibility-field.txt §6): analogues of Figs. 8-11 (cells rendered and time per frame along a
camera path, for none / uv / st / uv+st interpolation, 1 vs 5 ids per sample, several slab
resolutions and pixel subsamplings) and Figs. 13-15 (the images, holes marked), plus the
field's memory and how well it compresses (§7.1).

Scenes: ``turtles`` (``scenes.turtles()``, 16 turtles on a ground), ``sphere`` (one closed
convex icosphere), and real scenes from ``../shared/scenes`` (by folder name, e.g.
``stanford_bunny``).

Two parts per scene:

- **The paper's setup** (marked "paper, 1 slab"): one slab (planes before and beyond the bounds
  along the longest axis), the paper's 16^3 cells per object and 81 rays per sample, views
  without the fallback, along a path of cameras on the uv side of the slab looking across it
  at a shallow angle (the paper keeps its cameras "within the region where the geometry is not
  clipped by the parameterization"). Swept over resolutions, ids, interpolations, subsampling.
- **The defaults** (``discretize(scene, method="visibility_field", quality=q)``: six slabs,
  scene-derived settings, conservative fallback), from six cameras outside the bounds all
  around the scene; per quality the worst view's missed cells and holes, the cells drawn
  beside the truly visible ones, how much the field answered (covered) and the time.

Writes ``visibility_field.csv`` (one row per scene, setting and frame of the paper's part),
``visibility_field_defaults.csv`` (one row per scene, quality and view),
``visibility_field.md`` (both tables, memory and compression), ``fig8_<scene>.png`` (cells
rendered along the path), ``fig9_<scene>.png`` (time per frame: z-buffer, field, tracing) and
``fig13_<scene>.png`` (full rendering; paper field with 1 id; paper field with the most ids and
uv+st; the default field with its fallback; holes in red) to ``--out``.
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

INTERPOLATIONS = ("none", "uv", "st", "uv+st")


def load(name: str) -> ss.Scene:
    if name == "turtles":
        return ss.scenes.turtles()
    if name == "sphere":
        return ss.scenes.icosphere(4)
    files = ss.scenes.shared_scene_files()
    if name not in files:
        raise SystemExit(
            f"unknown scene {name!r}: 'turtles', 'sphere' or, with ../shared/scenes present, "
            f"one of {list(files)}"
        )
    return ss.Scene.load(files[name])


def path(scene: ss.Scene, frames: int, size: int) -> list[Any]:
    """Cameras on the uv side of the default slab: one scene length back along its axis, a
    fifth of it above the centre (along the shortest other axis), sweeping sideways across
    half the scene's width, all looking at the centre."""
    lo, hi = scene.bounds.astype(np.float64)
    c, ext = (lo + hi) / 2, hi - lo
    axis = int(np.argmax(ext))
    others = [k for k in range(3) if k != axis]
    up_axis = min(others, key=lambda k: ext[k])
    side = next(k for k in others if k != up_axis)
    up = np.eye(3)[up_axis]
    cams = []
    for i in range(frames):
        f = i / max(frames - 1, 1) - 0.5
        eye = c.copy()
        eye[axis] = lo[axis] - ext[axis]
        eye[up_axis] = c[up_axis] + 0.2 * ext[axis]
        eye[side] = c[side] + f * 0.5 * ext[side]
        dist = np.linalg.norm(c - eye)
        radius = 0.5 * np.linalg.norm(ext)
        yfov = float(min(2 * np.arctan(radius / dist), 1.2))
        cams.append(
            ss.Camera.look_at(tuple(eye), tuple(c), tuple(up), yfov=yfov, width=size, height=size)
        )
    return cams


def paper_field(scene: ss.Scene, res: int, ids: int, **options: Any) -> ss.VisibilityField:
    """The paper's setup: one slab along the longest axis, 16^3 cells per object, 81 rays per
    sample, ``res``^4 samples and ``ids`` ids per sample (``options``: e.g. ``progress``)."""
    return ss.discretize(
        scene,
        method="visibility_field",
        slab=ss.Slab.around(scene),
        uv=(res, res),
        st=(res, res),
        grid=(16, 16, 16),
        supersample=3,
        ids_per_sample=ids,
        **options,
    )


def six_directions(scene: ss.Scene, size: int) -> list[Any]:
    """Six cameras one bounds diagonal from the centre, around all six sides (slightly off
    the axes), looking at the centre."""
    lo, hi = scene.bounds.astype(np.float64)
    c, diag = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    dirs = [(1, 0.25, 0.15), (-1, -0.2, 0.1), (0.2, 1, 0.3), (-0.15, -1, 0.2)]
    dirs += [(0.1, 0.3, 1), (0.3, -0.2, -1)]
    cams = []
    for d in dirs:
        d = np.array(d, dtype=np.float64) / np.linalg.norm(d)
        up = (0, 0, 1) if abs(d[2]) < 0.9 else (0, 1, 0)
        eye = tuple(c + d * diag)
        cams.append(ss.Camera.look_at(eye, tuple(c), up, yfov=0.8, width=size, height=size))
    return cams


def run_defaults(name: str, scene: ss.Scene, args: Any) -> tuple[list[dict], Any]:
    """The default field per quality, from six directions: one row per quality and view."""
    rows, kept = [], None
    for q in args.qualities:
        t = time.perf_counter()
        f = ss.discretize(scene, method="visibility_field", quality=q)
        build = time.perf_counter() - t
        if q == "balanced" or kept is None:
            kept = f
        print(f"  {name}: default field, quality={q}, {build:.1f} s", flush=True)
        for i, cam in enumerate(six_directions(scene, args.size)):
            view = ss.reconstruct(f, cam)
            m = ss.evaluate(view, scene, "cells")
            rows.append(
                {
                    "scene": name,
                    "quality": q,
                    "view": i,
                    "slabs": len(f.slabs),
                    "res": f.settings["uv"][0],
                    "ids": f.settings["ids_per_sample"],
                    "cells": len(f.cells),
                    "build_seconds": build,
                    "memory_bytes": f.stats["memory_bytes"],
                    "rays": f.stats["rays"],
                    "cells_fraction": m["cells_fraction"],
                    "visible_fraction": m["cells_visible"] / max(len(f.cells), 1),
                    "missed_fraction": m["missed_fraction"],
                    "hole_fraction": m["hole_fraction"],
                    "covered": view.covered,
                    "fallback_pixels": view.fallback_pixels,
                    "fallback_cells": view.fallback_cells,
                    "time_zbuffer": m["time_zbuffer"],
                    "time_field": m["time_field"],
                    "time_tracing": m["time_tracing"],
                }
            )
    return rows, kept


def settings(args: Any) -> list[dict[str, Any]]:
    """Every (resolution, ids, interpolation, subsample) the experiment runs."""
    out = []
    for res in args.resolutions:
        for n in args.ids:
            for interp in INTERPOLATIONS:
                out.append({"res": res, "ids": n, "interpolate": interp, "subsample": 1})
    # Subsampling with the middle resolution and the fewest ids (the paper's 1 of 4 and 1 of 9
    # pixels).
    mid = sorted(args.resolutions)[len(args.resolutions) // 2]
    for k in args.subsamples:
        if k != 1:
            out.append({"res": mid, "ids": min(args.ids), "interpolate": "none", "subsample": k})
    return out


def run_scene(name: str, args: Any, out: Path) -> tuple[list[dict], list[dict], list[dict]]:
    scene = load(name)
    defaults, default_field = run_defaults(name, scene, args)
    cams = path(scene, args.frames, args.size)
    rows, fields_rows = [], []
    fields: dict[tuple[int, int], Any] = {}
    for s in settings(args):
        key = (s["res"], s["ids"])
        if key not in fields:
            t = time.perf_counter()
            f = paper_field(scene, s["res"], s["ids"])
            fields[key] = f
            fields_rows.append(
                {
                    "scene": name,
                    "triangles": scene.triangle_count,
                    "res": s["res"],
                    "ids": s["ids"],
                    "cells": f.stats["cells"],
                    "rays": f.stats["rays"],
                    "seconds": time.perf_counter() - t,
                    "memory_bytes": f.stats["memory_bytes"],
                    "compressed_bytes": f.stats["compressed_bytes"],
                    "ratio": f.stats["compressed_bytes"] / f.stats["memory_bytes"],
                }
            )
            print(f"  {name}: field {s['res']}^4 x {s['ids']} ids", flush=True)
        f = fields[key]
        for i, cam in enumerate(cams):
            view = ss.reconstruct(
                f, cam, interpolate=s["interpolate"], subsample=s["subsample"], fallback=False
            )
            m = ss.evaluate(view, scene, "cells")
            rows.append(
                {
                    "scene": name,
                    **s,
                    "frame": i,
                    "cells": len(f.cells),
                    "cells_rendered": m["cells_rendered"],
                    "cells_visible": m["cells_visible"],
                    "missed_cells": m["missed_cells"],
                    "missed_fraction": m["missed_fraction"],
                    "hole_pixels": m["hole_pixels"],
                    "extra_cells": m["extra_cells"],
                    "triangles_drawn": m["triangles_drawn"],
                    "tracing_missed_cells": m["tracing_missed_cells"],
                    "time_zbuffer": m["time_zbuffer"],
                    "time_field": m["time_field"],
                    "time_resample": view.timings["resample"],
                    "time_tracing": m["time_tracing"],
                }
            )
    figures(name, scene, cams, rows, fields, default_field, out)
    return rows, fields_rows, defaults


def figures(
    name: str,
    scene: Any,
    cams: list,
    rows: list[dict],
    fields: dict,
    default_field: Any,
    out: Path,
) -> None:
    plt = pyplot("the visibility_field experiment's figures")

    def series(res: int, ids: int, interp: str, key: str) -> list[float]:
        return [
            r[key]
            for r in rows
            if (r["res"], r["ids"], r["interpolate"], r["subsample"]) == (res, ids, interp, 1)
        ]

    res = 16 if any(r["res"] == 16 for r in rows) else rows[0]["res"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for ax, ids in zip(axes, sorted({r["ids"] for r in rows})[:2]):
        for interp in INTERPOLATIONS:
            ax.plot(series(res, ids, interp, "cells_rendered"), label=interp)
        ax.plot(series(res, ids, "none", "cells_visible"), "k--", label="visible (truth)")
        ax.set_title(f"{name}: {res}^4 field, {ids} id(s) per sample")
        ax.set_xlabel("frame")
    axes[0].set_ylabel("cells rendered")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / f"fig8_{name}.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 3.8))
    ax.plot(series(res, 1, "none", "time_zbuffer"), label="z-buffer, all geometry")
    ax.plot(series(res, 1, "none", "time_field"), label="field (resample + render)")
    ax.plot(series(res, 1, "none", "time_tracing"), label="visibility tracing")
    ax.set_xlabel("frame")
    ax.set_ylabel("seconds")
    ax.set_title(f"{name}: time per frame ({res}^4 field, 1 id, no interpolation)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / f"fig9_{name}.png", dpi=110)
    plt.close(fig)

    cam = cams[len(cams) // 2]
    full = ss.discretize(scene, cam, backend="gpu")  # rasterised, as the field's views are
    tiles = [_shade(full.normal[0], full.triangle[0] >= 0, None)]
    for key, interp in (((res, 1), "none"), ((res, max(k[1] for k in fields)), "uv+st")):
        if key not in fields:
            continue
        view = ss.reconstruct(fields[key], cam, interpolate=interp, fallback=False)
        m = ss.evaluate(view, scene, "cells")
        img = view.image
        tiles.append(_shade(img.normal[0], img.triangle[0] >= 0, m["hole_mask"]))
    if default_field is not None:
        view = ss.reconstruct(default_field, cam)
        m = ss.evaluate(view, scene, "cells")
        img = view.image
        tiles.append(_shade(img.normal[0], img.triangle[0] >= 0, m["hole_mask"]))
    write_png(out / f"fig13_{name}.png", np.concatenate(tiles, axis=1))


def _shade(normal: np.ndarray, mask: np.ndarray, holes: Optional[np.ndarray]) -> np.ndarray:
    """Normals as grey levels; holes (pixels whose true cell was not marked) in red."""
    g = np.where(mask, 0.35 + 0.6 * np.abs(normal).max(axis=-1), 0.08)
    img = np.repeat(g[..., None], 3, axis=2)
    if holes is not None:
        img[holes] = (0.9, 0.1, 0.1)
    return (np.clip(img, 0, 1) * 255).astype(np.uint8)


def defaults_markdown(rows: list[dict]) -> list[str]:
    """The default field per scene and quality: worst view and mean."""
    lines = [
        "The defaults: six slabs, scene-derived settings, conservative fallback; six views "
        "outside the bounds per scene. Worst view (max) of missed cells (fraction of the "
        "visible ones) and hole pixels (fraction of the pixels that see the scene); cells "
        "drawn beside the cells truly visible (the floor any culling meets), mean over views; "
        "covered: the fraction of pixels the field answered (the rest were traced), worst "
        "view; times per view in milliseconds (means).",
        "",
        "| scene | quality | samples | ids | cells | build s | MB | missed (max) | holes (max) | "
        "drawn / visible cells | covered (min) | z-buffer | field | tracing |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    keys = list(dict.fromkeys((r["scene"], r["quality"]) for r in rows))
    for k in keys:
        sel = [r for r in rows if (r["scene"], r["quality"]) == k]
        r0 = sel[0]

        def col(key: str, f: Any = np.mean, sel: list = sel) -> float:
            return float(f([r[key] for r in sel]))

        lines.append(
            f"| {k[0]} | {k[1]} | {r0['slabs']} x {r0['res']}^4 | {r0['ids']} | {r0['cells']:,} | "
            f"{r0['build_seconds']:.1f} | {r0['memory_bytes'] / 1e6:.0f} | "
            f"{col('missed_fraction', np.max):.2%} | {col('hole_fraction', np.max):.2%} | "
            f"{col('cells_fraction'):.0%} / {col('visible_fraction'):.0%} | "
            f"{col('covered', np.min):.0%} | {1e3 * col('time_zbuffer'):.1f} | "
            f"{1e3 * col('time_field'):.1f} | {1e3 * col('time_tracing'):.1f} |"
        )
    return lines + [""]


def markdown(rows: list[dict], fields_rows: list[dict], defaults: list[dict], args: Any) -> str:
    when = datetime.date.today().isoformat()
    cpu = platform.processor() or platform.machine()
    lines = defaults_markdown(defaults) if defaults else []
    lines += [
        "The paper's setup (paper, 1 slab, no fallback): "
        f"{args.frames} frames of {args.size}^2 along each scene's path; "
        f"{when}, {cpu}, {ss.device_info()['name']}. Means over the path; missed = visible "
        "cells the field did not mark (fraction of the visible cells); holes = pixels whose "
        "true triangle lies in an unmarked cell; times in milliseconds.",
        "",
        "| scene | field | ids | interpolation | subsample | cells rendered | of all | "
        "missed | hole px | z-buffer | field | of which resample | tracing |",
        "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    keys = []
    for r in rows:
        k = (r["scene"], r["res"], r["ids"], r["interpolate"], r["subsample"])
        if k not in keys:
            keys.append(k)
    for k in keys:
        sel = [
            r
            for r in rows
            if (r["scene"], r["res"], r["ids"], r["interpolate"], r["subsample"]) == k
        ]

        def mean(key: str, sel: list = sel) -> float:
            return float(np.mean([r[key] for r in sel]))

        lines.append(
            f"| {k[0]} (paper, 1 slab) | {k[1]}^4 | {k[2]} | {k[3]} | {k[4]} | "
            f"{mean('cells_rendered'):.0f} | "
            f"{mean('cells_rendered') / sel[0]['cells']:.1%} | {mean('missed_fraction'):.1%} | "
            f"{mean('hole_pixels'):.0f} | {1e3 * mean('time_zbuffer'):.1f} | "
            f"{1e3 * mean('time_field'):.1f} | {1e3 * mean('time_resample'):.1f} | "
            f"{1e3 * mean('time_tracing'):.1f} |"
        )
    lines += [
        "",
        "Memory of the id arrays and their zlib (deflate, level 6) size.",
        "",
        "| scene | triangles | field | ids | cells | rays | build s | bytes | compressed | ratio |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for f in fields_rows:
        lines.append(
            f"| {f['scene']} (paper, 1 slab) | {f['triangles']:,} | {f['res']}^4 | {f['ids']} | "
            f"{f['cells']:,} | "
            f"{f['rays']:,} | {f['seconds']:.1f} | {f['memory_bytes']:,} | "
            f"{f['compressed_bytes']:,} | {f['ratio']:.1%} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(prog="python -m scenesample.experiments visibility_field")
    p.add_argument("--scenes", nargs="+", default=["turtles", "sphere", "stanford_bunny"])
    p.add_argument("--resolutions", type=int, nargs="+", default=[8, 16, 24])
    p.add_argument("--ids", type=int, nargs="+", default=[1, 5])
    p.add_argument("--subsamples", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--size", type=int, default=128)
    p.add_argument(
        "--qualities",
        nargs="*",
        default=["fast", "balanced", "exact"],
        choices=ss.visibility_field.QUALITIES,
    )
    p.add_argument("--out", default="out/experiments/visibility_field")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, fields_rows, defaults = [], [], []
    for name in steps(args.scenes, "visibility_field", "scenes"):
        r, f, d = run_scene(name, args, out)
        rows += r
        fields_rows += f
        defaults += d
    write_csv(out / "visibility_field.csv", rows)
    if defaults:
        write_csv(out / "visibility_field_defaults.csv", defaults)
    md = markdown(rows, fields_rows, defaults, args)
    (out / "visibility_field.md").write_text(md)
    print(md)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
