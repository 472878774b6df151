"""How close the reconstructions of non-redundant-rendering.txt §4 come to the true surface:
conventional and non-redundant images from the three reference viewpoints, each rebuilt as the
depth-image ``mesh``, the ``hybrid`` reconstruction (Algorithm 4) and oriented ``points``, and
measured with ``evaluate(..., "surface")``: accuracy and completeness (mean, median and max:
the two halves of the Hausdorff distance), Chamfer distance, and precision, recall and F-score
at a threshold (Tanks and Temples' definitions), every step timed.

Writes ``reconstruction.csv`` and ``reconstruction.md`` to ``--out``.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path
from typing import Any, Optional

import scenesample as ss

from ..._progress import steps
from ._tables import write_csv

DISCRETIZATIONS = ("conventional", "nonredundant")
RECONSTRUCTIONS = ("mesh", "hybrid", "points")


def load(name: str) -> ss.Scene:
    if name in ss.scenes.PAPER_SCENES:
        return ss.scenes.PAPER_SCENES[name]()
    shared = ss.scenes.shared_scene_files()
    if name not in shared:
        known = [*ss.scenes.PAPER_SCENES, *shared]
        raise SystemExit(f"unknown scene {name!r}: one of {known}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ss.SceneWarning)
        return ss.Scene.load(shared[name])


def run_scene(scene: ss.Scene, resolution: int, samples: int, seed: int) -> list[dict[str, Any]]:
    cams = ss.scenes.reference_cameras(scene, resolution)
    rows = []
    for d in DISCRETIZATIONS:
        t = time.perf_counter()
        # On the GPU both, so that the table does not depend on the backend `auto` picks.
        images = ss.discretize(scene, cams, d, backend="gpu")
        t_disc = time.perf_counter() - t
        for r in RECONSTRUCTIONS:
            t = time.perf_counter()
            mesh = ss.reconstruct(images, r)
            t_rec = time.perf_counter() - t
            m = ss.evaluate(mesh, scene, "surface", samples=samples, seed=seed)
            rows.append(
                {
                    "discretization": d,
                    "reconstruction": r,
                    "triangles": len(mesh.faces),
                    **{
                        k: m[k]
                        for k in (
                            "accuracy_mean",
                            "accuracy_median",
                            "accuracy_max",
                            "completeness_mean",
                            "completeness_median",
                            "completeness_max",
                            "chamfer",
                            "precision",
                            "recall",
                            "fscore",
                            "threshold",
                        )
                    },
                    "discretize_seconds": t_disc,
                    "reconstruct_seconds": t_rec,
                    "evaluate_seconds": m["timings"]["total"],
                }
            )
    return rows


def markdown(rows: list[dict[str, Any]], args: Any) -> str:
    lines = [
        "# Surface accuracy of the reconstructions (non-redundant-rendering.txt §4)",
        "",
        f"`python -m scenesample.experiments reconstruction --resolution {args.resolution} "
        f"--samples {args.samples}`: three reference views per scene "
        "(`scenes.reference_cameras`), images on the GPU, "
        f"{args.samples:,} area samples on each side, distances in units of the scene's "
        "bounding-box diagonal; precision, recall and F-score at 0.5% of that diagonal.",
        "",
        "| scene | images | reconstruction | triangles | accuracy mean / median / max | "
        "completeness mean / median / max | Chamfer | precision | recall | F-score | "
        "reconstruct s |",
        "|---|---|---|---:|---|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        diag = r["threshold"] / 0.005

        def f(k: str, r: dict = r, diag: float = diag) -> str:
            return f"{r[k] / diag:.2e}"

        lines.append(
            f"| {r['scene']} | {r['discretization']} | {r['reconstruction']} | "
            f"{r['triangles']:,} | {f('accuracy_mean')} / {f('accuracy_median')} / "
            f"{f('accuracy_max')} | {f('completeness_mean')} / {f('completeness_median')} / "
            f"{f('completeness_max')} | {f('chamfer')} | {r['precision']:.3f} | "
            f"{r['recall']:.3f} | {r['fscore']:.3f} | {r['reconstruct_seconds']:.3f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(prog="python -m scenesample.experiments reconstruction")
    p.add_argument(
        "--scenes",
        nargs="+",
        default=[*ss.scenes.PAPER_SCENES, "stanford_bunny", "khr_toy_car"],
        help="procedural names or shared scene names",
    )
    p.add_argument("--resolution", type=int, default=512)
    p.add_argument("--samples", type=int, default=100_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="out/experiments/reconstruction")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    shared = ss.scenes.shared_scene_files()
    names = [n for n in args.scenes if n in ss.scenes.PAPER_SCENES or n in shared]
    rows = []
    for name in steps(names, "reconstruction", "scenes"):
        scene = load(name)
        for r in run_scene(scene, args.resolution, args.samples, args.seed):
            rows.append({"scene": name, "scene_triangles": scene.triangle_count, **r})
    write_csv(out / "reconstruction.csv", rows)
    md = markdown(rows, args)
    (out / "reconstruction.md").write_text(md)
    print(md)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
