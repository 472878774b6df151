"""Seeded mutation fuzzing of the scene loaders: glTF, GLB, OBJ and MTL files of the shared
scenes, with bytes flipped, cut out, inserted or numbers swapped for hostile ones, go to
`Scene.load` and one ray cast. Every case must end in a scene, or in one of the package's typed
errors (`ScenesampleError`); any other exception, a crash or a hang is a finding.

The cases run in a child process that says which case it starts, so a crash or a hang (the child
is killed after `--timeout` seconds on one case) is pinned to its case, and the run goes on
from the next.

    python tests/fuzz_loaders.py --cases 300 --seed 0      # what tests/test_fuzz.py runs
    make fuzz                                               # a longer run
    python tests/fuzz_loaders.py --case 1234 --seed 0       # replay one case, in-process
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import traceback
import warnings
from pathlib import Path

import numpy as np

SCENES = Path(
    os.environ.get("SCENESAMPLE_SCENES", Path(__file__).resolve().parents[2] / "shared" / "scenes")
)
# (folder, main file, files a case may mutate besides the main one)
SEEDS = [
    ("cornell_box", "cornell_box.obj", ["cornell_box.mtl"]),
    ("khr_cameras", "Cameras.gltf", ["simpleSquare.bin"]),
    ("khr_simple_instancing", "SimpleInstancing.glb", []),
    ("khr_clearcoat_car_paint", "ClearCoatCarPaint.glb", []),
    ("pine_tree", "scene.gltf", ["scene.bin"]),
    ("khr_lights_punctual_lamp", "LightsPunctualLamp.gltf", ["LightsPunctualLamp.data.bin"]),
]
# Numbers a loader must not trust: negative, zero, past u32 / i32, huge, not finite.
HOSTILE = [b"-1", b"0", b"4294967295", b"4294967296", b"2147483648", b"1e308", b"-1e308",
           b"65535", b"nan", b"1e-320", b"99999999999999999999"]  # fmt: skip
NUMBER = re.compile(rb"-?\d+(\.\d+)?([eE][-+]?\d+)?")


def seeds_present() -> list[tuple[str, str, list[str]]]:
    return [s for s in SEEDS if (SCENES / s[0] / s[1]).exists()]


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """One to four mutations of `data`."""
    b = bytearray(data)
    for _ in range(int(rng.integers(1, 5))):
        op = int(rng.integers(0, 6))
        n = len(b)
        if n == 0:
            b += bytes(rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8))
            continue
        at = int(rng.integers(0, n))
        if op == 0:  # flip bits
            for _ in range(int(rng.integers(1, 9))):
                i = int(rng.integers(0, n))
                b[i] ^= 1 << int(rng.integers(0, 8))
        elif op == 1:  # cut the tail
            del b[at:]
        elif op == 2:  # cut a span
            del b[at : at + int(rng.integers(1, 4096))]
        elif op == 3:  # insert random bytes
            b[at:at] = bytes(rng.integers(0, 256, int(rng.integers(1, 256)), dtype=np.uint8))
        elif op == 4:  # repeat a span
            end = min(n, at + int(rng.integers(1, 4096)))
            b[at:at] = b[at:end] * int(rng.integers(1, 4))
        else:  # a number swapped for a hostile one (text files; binary ones get bytes)
            spans = [m.span() for m in NUMBER.finditer(b, at, min(n, at + 65536))]
            if spans:
                s, e = spans[int(rng.integers(0, len(spans)))]
                b[s:e] = HOSTILE[int(rng.integers(0, len(HOSTILE)))]
            else:
                b[at : at + 4] = bytes([0xFF, 0xFF, 0xFF, 0x7F])
    return bytes(b)


def posing_internal_errors(data: bytes, seed: int, cases: int, folder: Path) -> list[tuple]:
    """`cases` seeded mutations of the animated glTF `data`, each loaded and posed by every
    clip at 0.5 s and past its end: the (case, message) of those that reported the reader's
    "internal error" (a panic caught) rather than a scene or a typed error."""
    import scenesample as ss

    case, found = folder / "case.gltf", []
    for i in range(cases):
        case.write_bytes(mutate(data, np.random.default_rng([seed, i])))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ss.SceneWarning)
                scene = ss.Scene.load(case)
                for k in range(len(scene.animations)):
                    scene.at(0.5, k)
                    scene.at(1e9, k)
        except ss.ScenesampleError as e:
            if "internal error" in str(e):
                found.append((i, str(e)))
    return found


def run_case(seed: int, i: int, work: Path) -> str:
    """Case `i` of run `seed`: "ok", "error: <typed error>", or raises what was not typed."""
    import scenesample as ss

    rng = np.random.default_rng([seed, i])
    seeds = seeds_present()
    folder, main, sidecars = seeds[int(rng.integers(0, len(seeds)))]
    src = SCENES / folder
    case = work / f"case{i}"
    shutil.rmtree(case, ignore_errors=True)
    case.mkdir(parents=True)
    for entry in src.iterdir():  # the scene's other files, unchanged, by link
        (case / entry.name).symlink_to(entry)
    victims = [main, *sidecars]
    victim = victims[int(rng.integers(0, len(victims)))]
    (case / victim).unlink()
    (case / victim).write_bytes(mutate((src / victim).read_bytes(), rng))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ss.SceneWarning)
            scene = ss.Scene.load(case / main)
        lo, hi = (np.asarray(x, np.float64) for x in scene.bounds)
        centre = np.where(np.isfinite(lo + hi), (lo + hi) / 2, 0.0)
        o = (centre + [0.0, 0.0, 1.0]).astype(np.float32)
        d = np.array([[0, 0, -1], [0.3, -0.2, -1], [0, 1, 0]], np.float32)
        ss.cast_rays(scene, o, d)
        return "ok"
    except ss.ScenesampleError as e:
        return f"error: {type(e).__name__}"
    finally:
        shutil.rmtree(case, ignore_errors=True)


def child(seed: int, start: int, stop: int, inject: str = "", at: int = -1) -> None:
    """Run cases start..stop, saying each one's start and outcome on stdout. `inject` makes
    case `at` crash, hang or raise an untyped error instead (the harness's own test)."""
    work = Path(tempfile.mkdtemp(prefix="scenesample-fuzz-"))
    try:
        for i in range(start, stop):
            say(f"start {i}")
            try:
                if i == at and inject == "crash":
                    os.abort()
                if i == at and inject == "hang":
                    time.sleep(3600)
                if i == at and inject == "raise":
                    raise RuntimeError("untyped")
                outcome = run_case(seed, i, work)
            except Exception:
                last = traceback.format_exc().strip().splitlines()[-1]
                say(f"bad {i} {json.dumps(last)}")
                continue
            say(f"done {i} {outcome}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


def say(line: str) -> None:
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def run(seed: int, cases: int, timeout: float, inject: tuple[str, int] = ("", -1)) -> dict:
    """Cases 0..cases in child processes; a crash or hang is recorded and the run goes on."""
    findings: list[dict] = []
    outcomes: dict[str, int] = {}
    i = 0
    while i < cases:
        cmd = [
            sys.executable,
            __file__,
            "--child",
            "--seed",
            str(seed),
            "--start",
            str(i),
            "--stop",
            str(cases),
            "--inject",
            inject[0],
            "--inject-at",
            str(inject[1]),
        ]
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=_pump, args=(p.stdout, lines), daemon=True).start()
        current, started, ended = i, time.monotonic(), False
        while not ended:
            try:
                line = lines.get(timeout=0.2)
            except queue.Empty:
                if time.monotonic() - started > timeout:
                    p.kill()
                    findings.append({"case": current, "what": f"hang: over {timeout} s"})
                    break
                continue
            if line is None:
                ended = True
                continue
            kind, n, *rest = line.rstrip("\n").split(" ", 2)
            if kind == "start":
                current, started = int(n), time.monotonic()
            elif kind == "done":
                outcomes[rest[0]] = outcomes.get(rest[0], 0) + 1
            elif kind == "bad":
                findings.append({"case": int(n), "what": json.loads(rest[0])})
        p.wait()
        if p.returncode == 0:
            break
        if not any(f["case"] == current for f in findings):
            err = (p.stderr.read() if p.stderr else "").strip().splitlines()[-3:]
            findings.append({"case": current, "what": f"exit {p.returncode}: {err}"})
        i = current + 1
    return {"seed": seed, "cases": cases, "outcomes": outcomes, "findings": findings}


def _pump(stream, lines: queue.Queue) -> None:
    for line in stream:
        lines.put(line)
    lines.put(None)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cases", type=int, default=300)
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds one case may take")
    ap.add_argument("--case", type=int, help="replay this case in this process")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--start", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--stop", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--inject", choices=["", "crash", "hang", "raise"], default="",
                    help="make case --inject-at fail this way (to test the harness)")  # fmt: skip
    ap.add_argument("--inject-at", type=int, default=-1, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if not seeds_present():
        sys.exit(f"no seed scenes under {SCENES}")
    if args.child:
        child(args.seed, args.start, args.stop, args.inject, args.inject_at)
        return 0
    if args.case is not None:
        with tempfile.TemporaryDirectory() as work:
            sys.stdout.write(run_case(args.seed, args.case, Path(work)) + "\n")
        return 0
    report = run(args.seed, args.cases, args.timeout, (args.inject, args.inject_at))
    sys.stdout.write(json.dumps(report, indent=1) + "\n")
    return 1 if report["findings"] else 0


if __name__ == "__main__":
    sys.exit(main())
