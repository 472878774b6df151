"""`make check`: the fast inner loop for a developer on a warm tree (after `make setup`, or a
`make test`). It runs the lints, and for the files changed since REF (default: the uncommitted
changes, new files included) rebuilds what they feed and runs the tests they touch:

- Rust or shader changes: the cargo tests and clippy (in target/checks, as `make test` does) and
  the editable extension rebuilt in release mode;
- then pytest on both cores over the test files that the changed files' rooms map to
  (`ROOMS`), plus any changed test file. A changed file that no room names runs every test.

It is not a substitute for `make test`, which builds the wheel and runs everything.

Usage: python3 scripts/make_check.py [--since REF] [--dry-run]
"""

from __future__ import annotations

import argparse
import subprocess
import sys

from _stages import ROOT, TARGET, Stage, run, sh

PY = sys.executable
LINTED = ("python", "tests", "scripts")

# Which test files cover which parts of the tree: a path containing a key's text maps to them.
ROOMS: dict[str, tuple[str, ...]] = {
    "src/trace/": ("test_rays.py", "test_edges.py", "test_stability.py"),
    "_rays.py": ("test_rays.py",),
    "src/trace/points.rs": ("test_points.py",),
    "src/trace/instances.rs": ("test_posed.py",),
    "src/trace/refit.rs": ("test_posed.py",),
    "src/scene/pose.rs": ("test_posed.py", "test_animation.py"),
    "src/py/points.rs": ("test_points.py",),
    "_points.py": ("test_points.py",),
    "_surface.py": ("test_points.py",),
    "_bench": ("test_bench.py",),
    "bench.py": ("test_bench.py",),
    "src/image/": ("test_depth_images.py", "test_backends.py"),
    "_conventional.py": ("test_depth_images.py", "test_backends.py"),
    "src/calibration/": ("test_backends.py", "test_plan.py"),
    "src/random.rs": ("test_visibility_field.py", "test_reflections.py", "test_splat.py"),
    "src/gpu/": ("test_depth_images.py", "test_backends.py", "test_nonredundant.py"),
    "nonredundant/images.py": (
        "test_depth_images.py",
        "test_nonredundant.py",
        "test_reconstruct.py",
    ),
    "src/nonredundant/": ("test_nonredundant.py", "test_reconstruct.py"),
    "src/nonredundant/sampling.rs": ("test_nonredundant.py", "test_evaluate_images.py"),
    "_evaluate.py": ("test_nonredundant.py", "test_evaluate_images.py", "test_reconstruct.py"),
    "_images.py": ("test_evaluate_images.py", "test_impostors.py"),
    "visibility_field": ("test_visibility_field.py",),
    "field": ("test_visibility_field.py",),
    "impostors": ("test_impostors.py",),
    "epr": ("test_splat.py", "test_reflections.py"),
    "splat": ("test_splat.py",),
    "reflections": ("test_reflections.py",),
    "shading.rs": ("test_reflections.py", "test_plan.py", "test_first_minutes.py"),
    "omni": ("test_omni_shadows.py",),
    "shadow": ("test_reconstruct.py", "test_omni_shadows.py"),
    "src/scene/": ("test_scene.py", "test_scene_gltf.py", "test_obj.py"),
    "_scene.py": ("test_scene.py", "test_scene_gltf.py", "test_obj.py"),
    "scenes.py": ("test_scene.py",),
    "_paper_scenes.py": ("test_scene.py",),
    "camera": ("test_camera.py",),
    "src/io/": ("test_depth_images.py",),
    "imageio.py": ("test_depth_images.py", "test_first_minutes.py"),
    "_plan.py": ("test_plan.py",),
    "src/epr/mod.rs": ("test_plan.py",),
    "_tradeoff.py": ("test_tradeoff.py",),
    "plot.py": ("test_tradeoff.py",),
    "src/process.rs": ("test_process.py", "test_progress.py"),
    "_progress.py": ("test_progress.py",),
    "src/counters.rs": ("test_plan.py",),
    "src/limits.rs": ("test_limits.py",),
    "src/error.rs": ("test_api.py",),
    "src/py/": ("test_api.py", "test_stub_keys.py"),
    "_core.pyi": ("test_api.py", "test_stub_keys.py"),
    "__init__.py": ("test_api.py", "test_layering.py"),
    "errors.py": ("test_api.py",),
    "methods.py": ("test_methods.py",),
    "_api.py": ("test_methods.py",),
    "results.py": ("test_methods.py", "test_api.py"),
    "references.py": ("test_depth_images.py",),
    "demo.py": ("test_api.py", "test_first_minutes.py"),
    "gallery.py": ("test_first_minutes.py",),
    "_env.py": ("test_first_minutes.py",),
    "tools/experiments/": ("test_nonredundant.py", "test_impostors.py", "test_reflections.py"),
    "notebooks/": ("test_notebooks.py",),
    "shaders/": ("test_depth_images.py", "test_nonredundant.py", "test_splat.py"),
}
# Files that feed no test directly.
QUIET = ("docs/", "README.md", "Makefile", ".ci/", "scripts/", ".gitignore", "LICENSE")
RUST = ("src/", "shaders/", "Cargo.toml", "Cargo.lock", "build.rs")


def changed(since: str) -> list[str]:
    """Paths changed since `since` (committed or not), and untracked files not ignored."""

    def git(*args: str) -> list[str]:
        out = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True)
        return [line for line in out.stdout.splitlines() if line]

    return sorted(
        {*git("diff", "--name-only", since), *git("ls-files", "--others", "--exclude-standard")}
    )


def tests_for(paths: list[str]) -> tuple[list[str], list[str]]:
    """The test files the changed `paths` touch, and the changed paths that no room names
    (any such path means: run every test)."""
    tests: set[str] = set()
    unmapped = []
    for p in paths:
        if p.startswith("tests/"):
            name = p.removeprefix("tests/")
            if name.startswith("test_") and name.endswith(".py"):
                tests.add(name)
            elif name == "conftest.py":  # every test may use it
                unmapped.append(p)
            elif name.endswith(".py"):  # a helper: the tests that import it
                users = [t.name for t in (ROOT / "tests").glob("test_*.py")
                         if f"import {name[:-3]}" in t.read_text()]  # fmt: skip
                if users:
                    tests.update(users)
                else:
                    unmapped.append(p)
            continue
        if p.startswith(QUIET) or p.endswith(".md"):
            continue
        hits = [t for key, ts in ROOMS.items() if key in p for t in ts]
        if hits:
            tests.update(hits)
        else:
            unmapped.append(p)
    return sorted(t for t in tests if (ROOT / "tests" / t).exists()), unmapped


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--since", default="HEAD", help="compare with this git ref (default HEAD)")
    ap.add_argument("--dry-run", action="store_true", help="say what would run, run nothing")
    args = ap.parse_args()
    paths = changed(args.since)
    tests, unmapped = tests_for(paths)
    rust = any(p.startswith(RUST) for p in paths)
    selection = ["tests"] if unmapped else [f"tests/{t}" for t in tests]
    print(f"changed since {args.since}: {len(paths)} files; Rust: {'yes' if rust else 'no'}")
    if unmapped:
        print(f"no room names {', '.join(unmapped[:5])}: running every test")
    elif tests:
        print(f"tests: {' '.join(tests)}")
    cargo_env = {"CARGO_TARGET_DIR": str(TARGET / "checks")}
    stages = [
        Stage("fmt", "cargo fmt --check", what="cargo fmt --check"),
        Stage(
            "ruff",
            f"{sh(PY, '-m', 'ruff', 'check', *LINTED)}"
            f" && {sh(PY, '-m', 'ruff', 'format', '--check', *LINTED)}",
            what="ruff",
        ),
    ]
    if rust:
        stages += [
            Stage(
                "cargo",
                "cargo clippy --profile checked --all-targets --features python -- -D warnings"
                " && cargo test --profile checked",
                env=cargo_env,
                what="clippy and the cargo tests",
            ),
            Stage(
                "build",
                sh(PY, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation")
                + " -e .",
                what="the editable extension, release mode",
            ),
        ]
    if unmapped or tests:
        stages.append(
            Stage(
                "pytest",
                sh(PY, "-m", "pytest", "-n", "2", "--dist", "worksteal", "-q", *selection),
                after=("build",),
                env={"PYOPENGL_PLATFORM": "egl"},
                what=f"pytest {' '.join(selection)}",
            )
        )
    if args.dry_run:
        for s in stages:
            print(f"{s.name}: {s.command}")
        return 0
    return run(stages)


if __name__ == "__main__":
    sys.exit(main())
