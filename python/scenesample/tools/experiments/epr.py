"""Eye-based point rendering against MVR and iVIR (eye-based-point-rendering.txt §4.2): the
analogues of Tables 1-2 (time and its breakdown, points, shading operations, RMSE against MVR at
4x, for 1, 10, 20 and 50 mirror spheres), Fig. 6 (speed vs accuracy as rho_scale and the
reflectors' projected size vary) and Fig. 7 (the three methods' images beside the reference).

Scene: ``scenes.reflective_room`` (a procedural room with mirror spheres placed by a seed), eye
``scenes.reflective_room_eye`` turned ``--angle`` about the room. Writes ``epr.csv``,
``epr.md``, ``fig6.csv``, ``fig6.png`` and ``fig7.png`` to ``--out``, and for Table 3
(omnidirectional soft shadows, §5.2: a spherical light in the middle of the room with 1, 5, 10
and 20 samples; time, points and error against ray casting) ``table3.csv`` and ``fig10.png``
(EPR, MVR, iVIR and ray casting at the most samples).
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

METHODS = ("epr", "mvr", "ivir")
# Table 3's light: a sphere in the middle of the room, a little above the spheres.
SHADOW_LIGHT = ((0.0, 0.2, 1.0), 0.15)


def run(spheres: int, size: int, angle: float, distance: float, **kw: Any) -> dict[str, Any]:
    """One configuration: every method once (after an untimed warm-up of each) and the
    reference."""
    scene = ss.scenes.reflective_room(spheres=spheres, detail=3)
    eye = ss.scenes.reflective_room_eye(size, angle=angle, distance=distance)
    ref = ss.reflection_reference(scene, eye)
    out: dict[str, Any] = {"scene": scene, "eye": eye, "ref": ref}
    for m in METHODS:
        ss.reflections(scene, eye, method=m, **kw)
        r = ss.reflections(scene, eye, method=m, **kw)
        out[m] = {"result": r, "error": ss.evaluate(r, ref)}
    return out


def tables(args: Any, out: Path) -> tuple[list[dict[str, Any]], Optional[dict[str, Any]]]:
    rows = []
    fig7_run = None
    for n in steps(args.spheres, "epr: spheres", "runs"):
        t = time.perf_counter()
        r = run(n, args.resolution, args.angle, 3.2)
        for m in METHODS:
            res = r[m]["result"]
            e = r[m]["error"]
            rows.append(
                {
                    "spheres": n,
                    "triangles": r["scene"].triangle_count,
                    "method": m,
                    "mean_cube_resolution": float(np.mean(res.resolutions)),
                    **{f"{k}_s": v for k, v in res.timings.items()},
                    **{k: v for k, v in res.stats.items()},
                    "rmse": e["rmse"],
                    "rmse_reflective": e["rmse_reflective"],
                }
            )
        if n == args.figure_spheres:
            fig7_run = r
        print(f"epr tables: {n} spheres: {time.perf_counter() - t:.1f} s", flush=True)
    keys = sorted({k for r in rows for k in r})
    write_csv(out / "epr.csv", rows, keys)
    return rows, fig7_run


def fig6(args: Any, out: Path) -> list[dict[str, Any]]:
    """Time vs RMSE (mirrors) of EPR as rho_scale varies, one point per eye distance (nearer
    eyes see larger reflectors)."""
    plt = pyplot("the epr experiment's figures")

    rows = []
    for d in steps(args.distances, "epr: distances", "runs"):
        scene = ss.scenes.reflective_room(spheres=args.figure_spheres, detail=3)
        eye = ss.scenes.reflective_room_eye(args.resolution, angle=args.angle, distance=d)
        ref = ss.reflection_reference(scene, eye)
        for rho in args.rho:
            ss.reflections(scene, eye, method="epr", rho_scale=rho)
            r = ss.reflections(scene, eye, method="epr", rho_scale=rho)
            e = ss.evaluate(r, ref)
            rows.append(
                {
                    "distance": d,
                    "rho_scale": rho,
                    "mean_cube_resolution": float(np.mean(r.resolutions)),
                    "seconds": r.timings["total"],
                    "points": r.stats["points"],
                    "rmse_reflective": e["rmse_reflective"],
                }
            )
        print(f"epr fig6: distance {d}", flush=True)
    write_csv(out / "fig6.csv", rows)
    fig, ax = plt.subplots(figsize=(6, 4))
    for rho in args.rho:
        sel = [r for r in rows if r["rho_scale"] == rho]
        ax.plot(
            [r["seconds"] for r in sel],
            [r["rmse_reflective"] for r in sel],
            "-o",
            label=f"rho_scale {rho}",
        )
    ax.set_xlabel("EPR frame time, s")
    ax.set_ylabel("RMSE on mirrors vs 4x MVR (0-255)")
    ax.set_title(f"Fig. 6 analogue: {args.figure_spheres} spheres, eye distance varies")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "fig6.png", dpi=120)
    plt.close(fig)
    return rows


def markdown(rows: list[dict[str, Any]], fig6_rows: list[dict[str, Any]], args: Any) -> str:
    when = datetime.date.today().isoformat()
    cpu = platform.processor() or platform.machine()
    lines = [
        f"EPR vs MVR vs iVIR, reflective_room, {args.resolution}^2 eye; {when}, {cpu}, "
        f"{ss.device_info()['name']}. RMSE on the 0-255 sRGB scale against MVR at 4x "
        "(all pixels / mirrors); times in seconds.",
        "",
        "| spheres | triangles | method | cube res | total | points step | views | shade | "
        "deferred | points | shading ops | RMSE | EPR speedup | shading ops / EPR's |",
        "|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        e = next(x for x in rows if x["spheres"] == r["spheres"] and x["method"] == "epr")
        lines.append(
            f"| {r['spheres']} | {r['triangles']:,} | {r['method']} | "
            f"{r['mean_cube_resolution']:.0f} | {r['total_s']:.3f} | "
            f"{r.get('points_s', 0.0):.3f} | {r['views_s']:.3f} | {r.get('shade_s', 0.0):.3f} | "
            f"{r['deferred_s']:.3f} | {int(r['points']):,} | {int(r['shading_ops']):,} | "
            f"{r['rmse']:.2f} / {r['rmse_reflective']:.2f} | {r['total_s'] / e['total_s']:.2f} | "
            f"{r['shading_ops'] / max(e['shading_ops'], 1):.1f} |"
        )
    lines += [
        "",
        f"Fig. 6 analogue ({args.figure_spheres} spheres): EPR time and RMSE on the mirrors as "
        "rho_scale and the eye distance vary.",
        "",
        "| eye distance | cube res | rho_scale | seconds | points | RMSE (mirrors) |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in fig6_rows:
        lines.append(
            f"| {r['distance']} | {r['mean_cube_resolution']:.0f} | {r['rho_scale']} | "
            f"{r['seconds']:.3f} | {int(r['points']):,} | {r['rmse_reflective']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def table3(args: Any, out: Path) -> list[dict[str, Any]]:
    """Omnidirectional shadows: every method once per light-sample count (after an untimed
    warm-up), its error against ray casting of the same samples."""
    scene = ss.scenes.reflective_room(spheres=args.shadow_spheres, detail=3)
    eye = ss.scenes.reflective_room_eye(args.resolution, angle=args.angle)
    rows = []
    last = {}
    kw = dict(max_resolution=args.shadow_max_resolution)
    for n in steps(args.light_samples, "epr: light samples", "runs"):
        ref = ss.omni_shadows(scene, eye, *SHADOW_LIGHT, light_samples=n, method="raytraced")
        for m in METHODS:
            ss.omni_shadows(scene, eye, *SHADOW_LIGHT, light_samples=n, method=m, **kw)
            r = ss.omni_shadows(scene, eye, *SHADOW_LIGHT, light_samples=n, method=m, **kw)
            e = ss.evaluate(r, ref)
            last[m] = r
            rows.append(
                {
                    "light_samples": n,
                    "triangles": scene.triangle_count,
                    "method": m,
                    "resolution": r.resolution,
                    "points": int(r.stats.get("points", 0)),
                    **{f"{k}_s": v for k, v in r.timings.items()},
                    "intensity_error": e["intensity_error"],
                    "visibility_error": e["visibility_error"],
                    "raytraced_s": ref.timings["total"],
                }
            )
            print(f"  shadows {n} samples {m}: {r.timings['total']:.2f} s", flush=True)
        last["raytraced"] = ref
    write_csv(out / "table3.csv", rows)
    tiles = [last[m].visibility for m in (*METHODS, "raytraced")]
    gray = (np.concatenate(tiles, axis=1) * 255).astype(np.uint8)
    write_png(out / "fig10.png", np.repeat(gray[..., None], 3, axis=2))
    return rows


def table3_markdown(rows: list[dict[str, Any]], args: Any) -> str:
    lines = [
        "",
        f"Table 3 analogue: omnidirectional soft shadows, reflective_room with "
        f"{args.shadow_spheres} spheres ({rows[0]['triangles']:,} triangles) and a spherical "
        f"light of radius {SHADOW_LIGHT[1]} at {SHADOW_LIGHT[0]}, faces at most "
        f"{args.shadow_max_resolution}^2 (Eq. 6). Errors against ray casting on the 0-255 "
        "scale (intensity / visibility); times in seconds.",
        "",
        "| light samples | method | face res | points | points step | splat | test | "
        "raster+test | total | error | vs EPR |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        e = next(
            x for x in rows if x["light_samples"] == r["light_samples"] and x["method"] == "epr"
        )
        lines.append(
            f"| {r['light_samples']} | {r['method']} | {r['resolution']} | {r['points']:,} | "
            f"{r.get('points_s', 0.0):.3f} | {r.get('splat_s', 0.0):.3f} | "
            f"{r.get('test_s', 0.0):.3f} | {r.get('shadow_s', 0.0):.3f} | {r['total_s']:.3f} | "
            f"{r['intensity_error']:.2f} / {r['visibility_error']:.2f} | "
            f"{r['total_s'] / e['total_s']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def fig7(path: Path, run_: dict[str, Any]) -> None:
    tiles = [run_[m]["result"].to_srgb8() for m in METHODS] + [run_["ref"].to_srgb8()]
    write_png(path, np.concatenate(tiles, axis=1))


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(prog="python -m scenesample.experiments epr")
    p.add_argument("--spheres", type=int, nargs="+", default=[1, 10, 20, 50])
    p.add_argument("--resolution", type=int, default=256, help="eye side (paper: 1080p)")
    p.add_argument("--angle", type=float, default=0.0, help="eye position about the room")
    p.add_argument("--rho", type=float, nargs="+", default=[0.25, 0.5, 1.0])
    p.add_argument("--distances", type=float, nargs="+", default=[2.2, 3.2, 4.5])
    p.add_argument("--figure-spheres", type=int, default=10)
    p.add_argument("--light-samples", type=int, nargs="*", default=[1, 5, 10, 20])
    p.add_argument("--shadow-spheres", type=int, default=50)
    p.add_argument("--shadow-max-resolution", type=int, default=512)
    p.add_argument("--out", default="out/experiments/epr")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, fig7_run = tables(args, out)
    fig6_rows = fig6(args, out)
    if fig7_run is not None:
        fig7(out / "fig7.png", fig7_run)
    md = markdown(rows, fig6_rows, args)
    if args.light_samples:
        md += table3_markdown(table3(args, out), args)
    (out / "epr.md").write_text(md)
    print(md)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
