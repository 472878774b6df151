"""Sampling quality of conventional images, non-redundant rendering and depth peeling
(non-redundant-rendering.txt §6.1): Table 1 (redundant, disoccluded and useful samples per
image), Table 2 (available samples of intermediate frames), Fig. 6 (disoccluded and useful
samples) and Fig. 7 (pixel vs visibility redundancy as resolution grows).

Writes ``sampling.csv``, ``sampling.md``, ``fig6_<scene>.png`` and ``fig7.png`` (+ ``fig7.csv``)
to ``--out``.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import time
import warnings
from pathlib import Path
from typing import Any, Optional

import numpy as np

import scenesample as ss

from ..._optional import pyplot
from ..._progress import steps
from ...imageio import linear_to_srgb, write_png
from ._tables import write_csv

METHODS = ("conventional", "nonredundant", "peeling")
#: Closed objects are sampled with back faces culled, as in the paper; thin sheets (blades,
#: leaves) have no inside and keep both faces.
CULL = {"grass": False, "urban": True, "bird_nest": True, "tree": False}
#: The paper's methods are rasterisations: conventional and peeled images come from the GPU path
#: (non-redundant images have no other), so the tables do not depend on which backend
#: ``backend="auto"`` picks on the machine that runs them (the CPU path agrees on ~99.99% of
#: pixels, not all).
BACKEND = {"conventional": "gpu", "peeling": "gpu"}


def scene_list(names: list[str]) -> dict[str, tuple[ss.Scene, str, bool]]:
    """name -> (scene, up axis, cull back faces), procedural and (when present) shared."""
    out: dict[str, tuple[ss.Scene, str, bool]] = {}
    shared = ss.scenes.shared_scene_files()
    for name in names:
        if name in ss.scenes.PAPER_SCENES:
            out[name] = (ss.scenes.PAPER_SCENES[name](), "z", CULL[name])
        elif name == "shared":
            for sname, path in shared.items():
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", ss.SceneWarning)
                    out[sname] = (ss.Scene.load(path), "y", False)
        elif name in shared:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ss.SceneWarning)
                out[name] = (ss.Scene.load(shared[name]), "y", False)
        else:
            raise SystemExit(
                f"unknown scene {name!r}: procedural {list(ss.scenes.PAPER_SCENES)}, "
                f"'shared', or one of {list(shared)}"
            )
    return out


def run_scene(
    scene: ss.Scene, up: str, cull: bool, resolution: int, frames: int, redundancy: str
) -> dict[str, Any]:
    cams = ss.scenes.reference_cameras(scene, resolution, up=up)
    out = {}
    for m in METHODS:
        kw: dict[str, Any] = {"layers": 3} if m == "peeling" else {}
        if m in BACKEND:
            kw["backend"] = BACKEND[m]
        if m == "nonredundant":
            kw["redundancy"] = redundancy
        t = time.perf_counter()
        images = ss.discretize(scene, cams, m, cull_backfaces=cull, **kw)
        t_disc = time.perf_counter() - t
        metrics = ss.evaluate(images, scene, intermediate=frames, redundancy=redundancy)
        out[m] = {"images": images, "metrics": metrics, "seconds": t_disc}
    return out


def fig6(images: ss.DepthImages, metrics: dict[str, Any]) -> np.ndarray:
    """Images side by side: shaded grey samples, disoccluded green, useful yellow."""
    shade = 0.35 + 0.5 * np.abs(np.nan_to_num(images.normal[..., 2:3]))
    rgb = np.where(images.mask[..., None], shade * np.array([0.6, 0.6, 0.6]), 0.0)
    rgb = np.where(metrics["disoccluded_mask"][..., None], [0.05, 0.6, 0.05], rgb)
    rgb = np.where(metrics["useful_mask"][..., None], [0.9, 0.8, 0.05], rgb)
    return linear_to_srgb(np.concatenate(list(rgb), axis=1))


def pct(x: float) -> str:
    return f"{100 * x:.0f}"


def markdown(results: dict[str, dict[str, Any]], args: argparse.Namespace) -> str:
    names = list(results)
    lines = [
        f"Sampling metrics, {args.resolution}x{args.resolution}, {args.frames} intermediate "
        f"frames, {args.redundancy} redundancy; {datetime.date.today()}, "
        f"{platform.machine()} ({os.cpu_count()} cores), {ss.device_info()['name']}.",
        "",
        "Table 1 (view-independent): % of each image's samples",
        "",
        "| model | image 0 | image 1 | image 2 |",
        "|---|---:|---:|---:|",
        "| *redundant, conventional* | | | |",
    ]
    for n in names:
        r = results[n]["conventional"]["metrics"]["redundant"]
        lines.append(f"| {n} | " + " | ".join(pct(x) for x in r) + " |")
    for m, title in (("nonredundant", "non-redundant"), ("peeling", "depth peeling")):
        lines.append(f"| *disoccluded (useful), {title}* | | | |")
        for n in names:
            mm = results[n][m]["metrics"]
            cells = [f"{pct(d)} ({pct(u)})" for d, u in zip(mm["disoccluded"], mm["useful"])]
            lines.append(f"| {n} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Table 2 (view-dependent): % of an intermediate frame's samples available in the images",
        "",
        "| model | conventional avg | min | non-redundant avg | min | peeling avg | min | "
        "time conv / nr / peel (s) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for n in names:
        cells = []
        for m in METHODS:
            mm = results[n][m]["metrics"]
            cells += [pct(mm["available_avg"][-1]), pct(mm["available_min"][-1])]
        times = " / ".join(f"{results[n][m]['seconds']:.3f}" for m in METHODS)
        lines.append(f"| {n} | " + " | ".join(cells) + f" | {times} |")
    return "\n".join(lines) + "\n"


def fig7(out: Path, scene_name: str, resolutions: list[int], frames: int) -> None:
    """Redundant / disoccluded / useful (image 1 and 2 averaged) under pixel and visibility
    redundancy as resolution grows."""
    plt = pyplot("the sampling experiment's figures")

    scene, up, cull = scene_list([scene_name])[scene_name]
    rows = []
    for res in resolutions:
        for mode in ("pixel", "visibility"):
            t = time.perf_counter()
            r = run_scene(scene, up, cull, res, frames, mode)
            conv = r["conventional"]["metrics"]
            nr = r["nonredundant"]["metrics"]
            rows.append(
                {
                    "resolution": res,
                    "redundancy": mode,
                    "redundant": float(np.mean(conv["redundant"][1:])),
                    "disoccluded": float(np.mean(nr["disoccluded"][1:])),
                    "useful": float(np.mean(nr["useful"][1:])),
                    "seconds": time.perf_counter() - t,
                }
            )
            print(f"fig7 {scene_name} {res} {mode}: {rows[-1]}", flush=True)
    write_csv(out / "fig7.csv", rows)
    fig, ax = plt.subplots(figsize=(6, 4))
    for key, color in (("redundant", "C0"), ("disoccluded", "C1"), ("useful", "C2")):
        for mode, style in (("pixel", "-o"), ("visibility", "--s")):
            sel = [r for r in rows if r["redundancy"] == mode]
            ax.plot(
                [r["resolution"] for r in sel],
                [100 * r[key] for r in sel],
                style,
                color=color,
                label=f"{key} ({mode})",
            )
    ax.set_xlabel("resolution (pixels per side)")
    ax.set_ylabel("% of samples (images 1-2)")
    ax.set_title(f"Fig. 7 analogue: {scene_name}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig7.png", dpi=120)
    plt.close(fig)


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(prog="python -m scenesample.experiments sampling")
    p.add_argument(
        "--scenes",
        nargs="+",
        default=[*ss.scenes.PAPER_SCENES, "shared"],
        help="procedural names, 'shared' (all of ../shared/scenes) or shared names",
    )
    p.add_argument("--resolution", type=int, default=512)
    p.add_argument("--frames", type=int, default=200, help="intermediate frames (paper: 1000)")
    p.add_argument("--redundancy", choices=["pixel", "visibility"], default="pixel")
    p.add_argument("--fig7-scene", default="bird_nest")
    p.add_argument(
        "--fig7-resolutions",
        type=int,
        nargs="*",
        default=[256, 512, 1024],
        help="empty to skip Fig. 7",
    )
    p.add_argument("--out", default="out/experiments/sampling")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    rows = []
    for name, (scene, up, cull) in steps(scene_list(args.scenes).items(), "sampling", "scenes"):
        t = time.perf_counter()
        r = run_scene(scene, up, cull, args.resolution, args.frames, args.redundancy)
        results[name] = r
        for m in METHODS:
            mm = r[m]["metrics"]
            for i in range(len(mm["samples"])):
                rows.append(
                    {
                        "scene": name,
                        "triangles": scene.triangle_count,
                        "method": m,
                        "image": i,
                        "resolution": args.resolution,
                        "redundancy": args.redundancy,
                        "cull_backfaces": cull,
                        **{
                            k: float(mm[k][i])
                            for k in (
                                "samples",
                                "redundant",
                                "disoccluded",
                                "useful",
                                "available_avg",
                                "available_min",
                            )
                        },
                        "discretize_seconds": r[m]["seconds"],
                        "evaluate_seconds": mm["timings"]["total"],
                    }
                )
            if m != "conventional":
                write_png(out / f"fig6_{name}_{m}.png", fig6(r[m]["images"], mm))
        print(f"{name}: {time.perf_counter() - t:.1f} s", flush=True)
    write_csv(out / "sampling.csv", rows)
    md = markdown(results, args)
    (out / "sampling.md").write_text(md)
    print(md)
    if args.fig7_resolutions:
        fig7(out, args.fig7_scene, args.fig7_resolutions, min(args.frames, 100))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
