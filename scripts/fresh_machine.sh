#!/usr/bin/env bash
# Run make targets as a machine where nothing was installed before would, to catch a step the
# README's commands rely on but do not perform themselves. Our own machines, and CI's, keep what
# earlier runs installed into the system Python and PATH, which hides such steps.
#
#   scripts/fresh_machine.sh [TARGET ...]     (default: test; e.g. `demo test wheel`)
#
# What it does:
# - clones the committed HEAD (not the work tree) into a new folder, with ../shared beside it,
#   as CI does;
# - makes a bare venv from the interpreter behind `python3` and puts its `bin` first on PATH,
#   so `python3` has only pip: nothing installed in the system Python can be imported;
# - runs each target under `env -i` with a PATH of that venv, cargo's bin and the system folders
#   only (no pyenv shims, no tools another run installed on the user's PATH).
# Caches stay (pip's and cargo's downloads): they hold no installed tool, only speed up fetches.
# System packages (apt) cannot be un-installed here: the targets install what is missing.
# FRESH_DIR=folder keeps the clone there (default: a new folder under /tmp, removed on success).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
SHARED=$(realpath "$ROOT/../shared")
TARGETS=("${@:-test}")
WORK=${FRESH_DIR:-$(mktemp -d /tmp/scenesample-fresh.XXXXXX)}
mkdir -p "$WORK"

git clone --quiet "$ROOT" "$WORK/scenesample"
ln -sfn "$SHARED" "$WORK/shared"
# The interpreter itself, not a shim or a venv: `python3 -m venv` works on it everywhere.
BASE_PY=$(python3 -c 'import sys; print(sys.base_prefix + "/bin/python3")')
"$BASE_PY" -m venv "$WORK/bare"

CARGO_BIN=$(dirname "$(command -v cargo)")
FRESH_PATH="$WORK/bare/bin:$CARGO_BIN:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
echo "fresh clone: $WORK/scenesample; python3: $WORK/bare/bin/python3 (bare venv)"
for target in "${TARGETS[@]}"; do
    echo "== make $target (as a fresh machine)"
    env -i HOME="$HOME" PATH="$FRESH_PATH" TERM="${TERM:-dumb}" LANG=C.UTF-8 \
        ${CARGO_HOME:+CARGO_HOME="$CARGO_HOME"} ${RUSTUP_HOME:+RUSTUP_HOME="$RUSTUP_HOME"} \
        make -C "$WORK/scenesample" "$target"
done
if [ -z "${FRESH_DIR:-}" ]; then rm -rf "$WORK"; fi
echo "fresh machine: make ${TARGETS[*]} passed"
