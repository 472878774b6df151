"""Soft shadows from discretized scenes (non-redundant-rendering.txt §6.2): Table 3 (error vs
depth-image resolution), Table 4 (error vs light size), Table 5 (time per step of Algorithm 5)
and Fig. 8 (shadow images and error images), measured against both references — shadow maps of
the original triangles (``geometry``, the paper's) and exact ray casts (``raytraced``).

Scenes: the procedural analogues (``grass``, ``urban``, ...; z up) and, when ``../shared/scenes``
is present, real ones (``cornell_box``, ``pine_tree``, ``stanford_bunny``, ...; y up). The
procedural and most real scenes are lit by a square light above them, its diagonal the swept
multiple of the scene's bounding-box diagonal (Table 4). The Cornell box is lit by its own ceiling
light (the ``light`` object of cornell_box.obj, 1 cm below it) and seen through its open front; it
has no light-size sweep.

Fig. 9 (frame time vs scene complexity): the grass scene grown by its blade count to 8.4M
triangles, soft shadows from shadow maps of the original triangles against shadow maps of the
hybrid reconstruction of non-redundant (and conventional) depth images; each step timed, the
crossover interpolated in log(triangles), and the frame time at 16 x 16 light samples modelled
from the measured per-sample shadow time.

Writes ``shadows.csv``, ``shadows.md``, ``fig8_<scene>.png``, ``fig9.csv`` and ``fig9.png`` to
``--out``.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Optional

import numpy as np

import scenesample as ss

from ..._optional import pyplot
from ..._progress import steps
from ...imageio import write_png
from ._tables import write_csv

METHODS = ("nonredundant", "conventional", "peeling")
REFERENCES = ("geometry", "raytraced")


# The Cornell box's ceiling light: the corners of the `light` object in cornell_box.obj (y = 1.98),
# 1 cm below it so that the light's own quad does not shadow the samples.
CORNELL_LIGHT = ((-0.005, 1.97, -0.03), (0.47, 0.0, 0.0), (0.0, 0.0, 0.38))


def shadow_scene(
    name: str, output: int
) -> tuple[ss.Scene, Any, Callable[[float], ss.AreaLight], bool]:
    """(scene, eye camera, light of a given size, whether the light size can be swept)."""
    if name in ss.scenes.PAPER_SCENES:
        scene = ss.scenes.PAPER_SCENES[name]()
        camera = ss.scenes.reference_cameras(scene, output)[0]
        return scene, camera, lambda size: ss.AreaLight.above(scene, size=size, height=0.5), True
    files = ss.scenes.shared_scene_files()
    if name not in files:
        raise SystemExit(
            f"unknown scene {name!r}: one of {list(ss.scenes.PAPER_SCENES)} or, with "
            f"../shared/scenes present, {list(files)}"
        )
    scene = ss.Scene.load(files[name])
    if name == "cornell_box":
        camera = ss.Camera.look_at(
            (0, 1, 3.4), (0, 1, 0), (0, 1, 0), yfov=0.75, width=output, height=output
        )
        return scene, camera, lambda size: ss.AreaLight(*CORNELL_LIGHT), False
    camera = ss.scenes.reference_cameras(scene, output, up="y")[0]
    return (
        scene,
        camera,
        lambda size: ss.AreaLight.above(scene, size=size, height=0.5, up="y"),
        True,
    )


def run(
    scene: ss.Scene,
    camera: Any,
    light: ss.AreaLight,
    resolution: int,
    samples: int,
    shadow_resolution: int,
    refs: dict[str, Any],
) -> dict[str, Any]:
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
    p.add_argument(
        "--scenes",
        nargs="*",
        default=["grass", "urban", "cornell_box", "pine_tree"],
        help="procedural names or names of ../shared/scenes folders; none: Fig. 9 only",
    )
    p.add_argument("--resolutions", type=int, nargs="+", default=[256, 512, 768])
    p.add_argument("--sizes", type=float, nargs="+", default=[0.25, 0.5, 1.0, 2.0, 4.0])
    p.add_argument("--resolution", type=int, default=512, help="for the light-size sweep")
    p.add_argument("--samples", type=int, default=8, help="light samples per side (paper: 16)")
    p.add_argument("--output", type=int, default=256, help="output image side (paper: 512)")
    p.add_argument("--shadow-resolution", type=int, default=512)
    p.add_argument(
        "--fig9-blades",
        type=int,
        nargs="*",
        default=[4000, 16000, 64000, 200000, 600000],
        help="grass blade counts for Fig. 9 (600000 blades: 8.4M triangles); none skips it",
    )
    p.add_argument("--fig9-samples", type=int, default=8, help="light samples per side in Fig. 9")
    p.add_argument("--out", default="out/experiments/shadows")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in steps(args.scenes, "shadows", "scenes"):
        scene, camera, light_of, sizes = shadow_scene(name, args.output)
        sweeps = [("resolution", r, 1.0, r) for r in args.resolutions]
        sweeps += [("light_size", s, s, args.resolution) for s in args.sizes if sizes]
        refs_by_size: dict[float, dict[str, Any]] = {}
        for table, value, size, res in sweeps:
            refs = refs_by_size.setdefault(size, {})
            t = time.perf_counter()
            light = light_of(size)
            r = run(scene, camera, light, res, args.samples, args.shadow_resolution, refs)
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
    md = ""
    if rows:
        write_csv(out / "shadows.csv", rows)
        md = markdown(rows, args)
    if args.fig9_blades:
        md += fig9(out, args.fig9_blades, args)
    if not md:
        raise SystemExit("nothing to do: give --scenes, --fig9-blades or both")
    (out / "shadows.md" if rows else out / "fig9.md").write_text(md)
    print(md)
    print(f"wrote {out}")


FIG9_METHODS = ("geometry", "nonredundant", "conventional")
# The paper's light sampling (16 x 16), for the modelled frame times of Fig. 9.
PAPER_SAMPLES = 16


def crossover(tris: list[int], ours: list[float], theirs: list[float]) -> Optional[float]:
    """The triangle count where ``ours`` first drops below ``theirs``, interpolated linearly in
    log(triangles) between the two measured counts around it; None when it never does, the
    smallest count when it already does there."""
    diff = np.array(ours) - np.array(theirs)
    below = np.flatnonzero(diff < 0)
    if len(below) == 0:
        return None
    k = int(below[0])
    if k == 0:
        return float(tris[0])
    a, b = np.log(tris[k - 1]), np.log(tris[k])
    f = diff[k - 1] / (diff[k - 1] - diff[k])
    return float(np.exp(a + f * (b - a)))


def fig9(out: Path, blades: list[int], args: Any) -> str:
    """Frame time (all steps of Algorithm 5, eye image included) vs triangle count for the grass
    scene grown by blade count; writes fig9.csv and fig9.png and returns a markdown section."""
    plt = pyplot("the shadows experiment's figures")

    n = args.fig9_samples
    rows = []
    for b in sorted(blades):
        scene = ss.scenes.grass(blades=b)
        camera = ss.scenes.reference_cameras(scene, args.output)[0]
        light = ss.AreaLight.above(scene, size=1.0, height=0.5)
        for m in FIG9_METHODS:
            kw = dict(
                samples=(n, n),
                discretization=m,
                resolution=args.resolution,
                shadow_resolution=args.shadow_resolution,
            )
            if not rows and m == FIG9_METHODS[0]:
                ss.soft_shadows(scene, camera, light, **kw)  # device and pipelines, untimed
            r = ss.soft_shadows(scene, camera, light, **kw)
            t = r.timings
            per_sample = t.get("shadow", 0.0) / (n * n)
            rows.append(
                {
                    "blades": b,
                    "triangles": scene.triangle_count,
                    "method": m,
                    "samples": n * n,
                    **{f"{k}_s": t.get(k, 0.0) for k in ("eye", "discretize", "reconstruct")},
                    "shadow_s": t.get("shadow", 0.0),
                    "total_s": t["total"],
                    "shadow_per_sample_s": per_sample,
                    "occluder_triangles": r.occluder_triangles,
                    f"modelled_total_{PAPER_SAMPLES}x{PAPER_SAMPLES}_s": t["total"]
                    + per_sample * (PAPER_SAMPLES**2 - n * n),
                }
            )
            print(f"fig9 {scene.triangle_count:,} triangles {m}: {t['total']:.2f} s", flush=True)
    write_csv(out / "fig9.csv", rows)

    modelled = f"modelled_total_{PAPER_SAMPLES}x{PAPER_SAMPLES}_s"
    series = {m: [r for r in rows if r["method"] == m] for m in FIG9_METHODS}
    tris = [r["triangles"] for r in series["geometry"]]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for m, color in zip(FIG9_METHODS, ("k", "C2", "C0")):
        ax.loglog(tris, [r["total_s"] for r in series[m]], "-o", color=color, label=f"{m}, {n}x{n}")
        ax.loglog(
            tris,
            [r[modelled] for r in series[m]],
            "--",
            color=color,
            alpha=0.6,
            label=f"{m}, {PAPER_SAMPLES}x{PAPER_SAMPLES} (modelled)",
        )
    ax.set_xlabel("scene triangles (grass, growing blade count)")
    ax.set_ylabel("frame time, s")
    ax.set_title(f"Fig. 9 analogue on {ss.device_info()['name'].split(' (')[0]}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig9.png", dpi=120)
    plt.close(fig)

    lines = [
        "",
        f"Fig. 9 analogue: frame time vs scene complexity (grass grown by blade count), "
        f"{n}x{n} light samples measured, {PAPER_SAMPLES}x{PAPER_SAMPLES} modelled as measured "
        f"total + (per-sample shadow time) x the extra samples; depth images "
        f"{args.resolution}^2, shadow maps {args.shadow_resolution}^2.",
        "",
        "| triangles | method | eye | discretize | reconstruct | shadow | total | "
        f"total at {PAPER_SAMPLES}x{PAPER_SAMPLES} (modelled) | occluder triangles |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['triangles']:,} | {r['method']} | {r['eye_s']:.2f} | {r['discretize_s']:.2f} | "
            f"{r['reconstruct_s']:.2f} | {r['shadow_s']:.2f} | {r['total_s']:.2f} | "
            f"{r[modelled]:.2f} | {r['occluder_triangles']:,} |"
        )
    lines.append("")
    for m in FIG9_METHODS[1:]:
        for key, label in (("total_s", f"{n}x{n}"), (modelled, f"{PAPER_SAMPLES}x{PAPER_SAMPLES}")):
            c = crossover(tris, [r[key] for r in series[m]], [r[key] for r in series["geometry"]])
            if c is None:
                where = "never, up to the largest scene"
            elif c == tris[0]:
                where = f"already at the smallest scene ({tris[0]:,} triangles)"
            else:
                where = f"from about {c:,.0f} triangles"
            lines.append(f"- {m} beats geometry shadow maps at {label} light samples: {where}.")
    return "\n".join(lines) + "\n"


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
