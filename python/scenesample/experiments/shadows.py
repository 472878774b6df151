"""Soft shadows from discretized scenes (non-redundant-rendering.txt §6.2): Table 3 (error vs
depth-image resolution), Table 4 (error vs light size), Table 5 (time per step of Algorithm 5)
and Fig. 8 (shadow images and error images), measured against both references — shadow maps of
the original triangles (``geometry``, the paper's) and exact ray casts (``raytraced``).

Writes ``shadows.csv``, ``shadows.md`` and ``fig8_<scene>.png`` to ``--out``. Fig. 9 (frame time
vs scene complexity) is not produced yet.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import platform
import time
from pathlib import Path
from typing import Any, Optional

import numpy as np

import scenesample as ss

from ..imageio import write_png

METHODS = ("nonredundant", "conventional", "peeling")
REFERENCES = ("geometry", "raytraced")


def run(
    scene: ss.Scene,
    camera: Any,
    size: float,
    resolution: int,
    samples: int,
    shadow_resolution: int,
    refs: dict[str, Any],
) -> dict[str, Any]:
    light = ss.AreaLight.above(scene, size=size, height=0.5)
    out: dict[str, Any] = {}
    for ref in REFERENCES:
        if ref not in refs:
            refs[ref] = ss.soft_shadows(
                scene,
                camera,
                light,
                samples=(samples, samples),
                discretization=ref,
                resolution=resolution,
                shadow_resolution=shadow_resolution,
            )
    for m in METHODS:
        r = ss.soft_shadows(
            scene,
            camera,
            light,
            samples=(samples, samples),
            discretization=m,
            resolution=resolution,
            shadow_resolution=shadow_resolution,
        )
        out[m] = {"result": r, **{ref: ss.evaluate(r, refs[ref]) for ref in REFERENCES}}
    return out


def fig8(path: Path, refs: dict[str, Any], results: dict[str, Any]) -> None:
    """Row 1: visibility of geometry, raytraced and the three discretizations; row 2: absolute
    error against ray casting (x4, red)."""
    tiles = [refs["geometry"], refs["raytraced"]] + [results[m]["result"] for m in METHODS]
    ref = refs["raytraced"].visibility
    top = [np.repeat((255 * t.visibility)[..., None], 3, axis=2) for t in tiles]
    bottom = []
    for t in tiles:
        e = np.clip(4 * 255 * np.abs(t.visibility - ref), 0, 255)
        bottom.append(np.stack([e, np.zeros_like(e), np.zeros_like(e)], axis=2))
    img = np.concatenate([np.concatenate(top, axis=1), np.concatenate(bottom, axis=1)], axis=0)
    write_png(path, img.astype(np.uint8))


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(prog="python -m scenesample.experiments shadows")
    p.add_argument("--scenes", nargs="+", default=["grass", "urban"])
    p.add_argument("--resolutions", type=int, nargs="+", default=[256, 512, 768])
    p.add_argument("--sizes", type=float, nargs="+", default=[0.25, 0.5, 1.0, 2.0, 4.0])
    p.add_argument("--resolution", type=int, default=512, help="for the light-size sweep")
    p.add_argument("--samples", type=int, default=8, help="light samples per side (paper: 16)")
    p.add_argument("--output", type=int, default=256, help="output image side (paper: 512)")
    p.add_argument("--shadow-resolution", type=int, default=512)
    p.add_argument("--out", default="out/experiments/shadows")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.scenes:
        scene = getattr(ss.scenes, name)()
        camera = ss.scenes.reference_cameras(scene, args.output)[0]
        sweeps = [("resolution", r, 1.0, r) for r in args.resolutions]
        sweeps += [("light_size", s, s, args.resolution) for s in args.sizes]
        refs_by_size: dict[float, dict[str, Any]] = {}
        for table, value, size, res in sweeps:
            refs = refs_by_size.setdefault(size, {})
            t = time.perf_counter()
            r = run(scene, camera, size, res, args.samples, args.shadow_resolution, refs)
            for m in METHODS:
                res_m = r[m]["result"]
                rows.append(
                    {
                        "scene": name,
                        "table": table,
                        "value": value,
                        "method": m,
                        **{
                            f"{k}_vs_{ref}": r[m][ref][k]
                            for ref in REFERENCES
                            for k in ("intensity_error", "visibility_error")
                        },
                        **{
                            f"{k}_s": res_m.timings.get(k, 0.0)
                            for k in ("discretize", "reconstruct", "shadow")
                        },
                        "occluder_triangles": res_m.occluder_triangles,
                    }
                )
            if table == "resolution" and value == args.resolutions[len(args.resolutions) // 2]:
                fig8(out / f"fig8_{name}.png", refs, r)
            print(f"{name} {table}={value}: {time.perf_counter() - t:.1f} s", flush=True)
    with open(out / "shadows.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    md = markdown(rows, args)
    (out / "shadows.md").write_text(md)
    print(md)
    print(f"wrote {out}")


def markdown(rows: list[dict[str, Any]], args: Any) -> str:
    when = datetime.date.today().isoformat()
    cpu = platform.processor() or platform.machine()
    lines = [
        f"Soft shadows, {args.output}^2 output, {args.samples}x{args.samples} light samples, "
        f"{args.shadow_resolution}^2 shadow maps; {when}, {cpu}, {ss.device_info()['name']}.",
        "",
        "Errors (0-255) as i / v: intensity / visibility error, against geometry shadow maps "
        "(the paper's reference) and against ray casting.",
        "",
        "| scene | sweep | value | "
        + " | ".join(f"{m} vs geometry | vs raytraced" for m in METHODS)
        + " |",
        "|---|---|---:|" + "---:|---:|" * len(METHODS),
    ]
    keys = sorted(
        {(r["scene"], r["table"], r["value"]) for r in rows}, key=lambda k: (k[0], k[1], k[2])
    )
    for key in keys:
        cells = []
        for m in METHODS:
            r = next(
                x for x in rows if (x["scene"], x["table"], x["value"]) == key and x["method"] == m
            )
            for ref in REFERENCES:
                cells.append(
                    f"{r[f'intensity_error_vs_{ref}']:.2f} / {r[f'visibility_error_vs_{ref}']:.2f}"
                )
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Table 5 analogue: seconds per step (resolution sweep, middle resolution).",
        "",
        "| scene | method | discretize | reconstruct | shadow | occluder triangles |",
        "|---|---|---:|---:|---:|---:|",
    ]
    mid = args.resolutions[len(args.resolutions) // 2]
    for r in rows:
        if r["table"] == "resolution" and r["value"] == mid:
            lines.append(
                f"| {r['scene']} | {r['method']} | {r['discretize_s']:.3f} | "
                f"{r['reconstruct_s']:.3f} | {r['shadow_s']:.3f} | {r['occluder_triangles']:,} |"
            )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
