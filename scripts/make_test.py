"""`make test`: every check, from a fresh clone, as CI runs it.

The extension is compiled once, as the wheel users get: the sdist is built, the abi3
manylinux2014 wheel is built from that sdist (pip's PEP 517 path, as `pip install` of the sdist
does, linked by zig against glibc 2.17), and that very wheel is what pytest tests (in
target/test-venv, with the test extras) and what a clean venv outside the tree installs for the
smoke test and the quickstart. The cargo tests (debug assertions and overflow checks on) and
clippy share a target folder of their own and build while the wheel does: on two cores, the
long serial tail of the wheel's own crate leaves room for them.

Nothing is taken from the machine's Python or PATH beyond the interpreter that runs this
script: every tool (maturin, zig, ruff, pytest) comes from target/test-venv, whose `bin` is put
first on PATH for every stage, at the versions of scripts/pins.txt (the `pins` stage checks
them). `scripts/fresh_machine.sh` runs this as a machine where nothing was installed would.

Usage: python3 scripts/make_test.py [--only STAGE ...]
"""

from __future__ import annotations

import argparse
import os
import sys

import pins
from _stages import LOGS, ROOT, TARGET, Stage, run, sh

DIST = TARGET / "dist"
VENV = TARGET / "test-venv"
VPY = VENV / "bin" / "python"
PY = os.environ.get("PYTHON", sys.executable)
PINS = ROOT / "scripts" / "pins.txt"
#: `--no-compile`: the packages' bytecode is made when a module is first imported, for the
#: modules the tests import, not ahead of time for every file of every package (open3d, scipy,
#: matplotlib, ...), which cost CPU the wheel's build needed.
PIP = sh(
    VPY,
    "-m",
    "pip",
    "install",
    "--quiet",
    "--disable-pip-version-check",
    "--no-compile",
    "-c",
    PINS,
)
JUNIT = LOGS / "pytest.xml"
LINTED = ("python", "tests", "scripts")
#: Every stage finds the venv's tools (maturin looks for zig through `python3 -m ziglang`).
VENV_ENV = {"PATH": f"{VENV / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}"}
VENV_ENV["VIRTUAL_ENV"] = str(VENV)


STAGES = [
    Stage(
        "system",
        sh("bash", ROOT / "scripts/setup.sh", "--system"),
        what="Debian packages: Mesa's Vulkan driver, EGL, libusb",
    ),
    Stage("fmt", "cargo fmt --check", what="cargo fmt --check"),
    Stage(
        "venv",
        f"{sh(PY, '-m', 'venv', '--clear', VENV)} && {PIP} {sh(*pins.BUILD_TOOLS)}",
        what="target/test-venv with maturin and zig, which the wheel needs",
    ),
    Stage(
        "cargo",
        # Niced: the wheel is on the critical path (pytest waits for it), these are not; they
        # take what the wheel's build leaves of the two cores. Their own target folder lets them
        # build beside the wheel instead of waiting for its lock.
        "cargo test --profile checked --no-run"
        " && cargo clippy --profile checked --all-targets --features python -- -D warnings"
        " && cargo test --profile checked",
        env={"CARGO_TARGET_DIR": str(TARGET / "checks")},
        what="cargo tests (debug assertions, overflow checks), clippy -D warnings",
        nice=15,
    ),
    Stage(
        "deps",
        # numpy and the `test` extra of pyproject.toml (the tools the tests compare against).
        f"{PIP} {sh(*pins.requirements(['test']))}",
        after=("venv",),
        what="numpy and the test extras into target/test-venv",
        nice=10,
    ),
    Stage(
        "pins",
        sh(VPY, ROOT / "scripts/pins.py", "check", VPY),
        after=("deps",),
        what="every package in target/test-venv at its version in scripts/pins.txt",
    ),
    Stage(
        "ruff",
        f"{sh(VPY, '-m', 'ruff', 'check', *LINTED)}"
        f" && {sh(VPY, '-m', 'ruff', 'format', '--check', *LINTED)}",
        after=("deps",),
        what="ruff check, ruff format --check",
    ),
    Stage(
        "sdist",
        f"rm -rf {sh(DIST)} && {sh(VPY, '-m', 'maturin', 'sdist', '--out', DIST)}",
        after=("venv",),
        what="the sdist",
    ),
    Stage(
        "wheel",
        f"{sh(VPY, '-m', 'pip', 'wheel', '--no-deps', '--no-build-isolation', '-w', DIST)}"
        f" {sh(DIST)}/scenesample-*.tar.gz",
        after=("sdist",),
        env={
            "MATURIN_PEP517_ARGS": "--zig --compatibility manylinux2014",
            "CARGO_TARGET_DIR": str(TARGET / "manylinux"),
        },
        what="the abi3 manylinux2014 wheel, built from the sdist",
    ),
    Stage(
        "pytest",
        f"{PIP} --no-deps --force-reinstall {sh(DIST)}/scenesample-*.whl"
        f" && {sh(VPY, '-m', 'pytest', '-n', '2', '--dist', 'worksteal', '-rs')}"
        f" --junitxml={sh(JUNIT)}",
        after=("wheel", "deps", "pins", "system"),
        env={"PYOPENGL_PLATFORM": "egl"},
        what="pytest on both cores, against that wheel",
        junit=JUNIT,
    ),
    Stage(
        "wheel-venv",
        f"{sh('bash', ROOT / 'scripts/wheel_check.sh')} {sh(DIST)}/scenesample-*.whl",
        after=("wheel", "system"),
        what="that wheel alone in a clean venv: smoke test, quickstart, outside the tree",
        nice=10,
    ),
]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--only",
        nargs="+",
        choices=[s.name for s in STAGES],
        help="run only these stages (the stages they wait for count as passed)",
    )
    args = ap.parse_args()
    os.environ.update(VENV_ENV)
    return run([s for s in STAGES if not args.only or s.name in args.only])


if __name__ == "__main__":
    sys.exit(main())
