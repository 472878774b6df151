#!/usr/bin/env bash
# Set up a fresh Debian/Ubuntu machine: system packages (Mesa's software Vulkan driver for the GPU
# path, EGL for pyrender, libusb for Open3D), then scenesample built in release mode with the test
# and demo extras, as an editable install into the current Python (`python3`, or $PYTHON): what
# `make demo` and `make check` use. Python packages at the versions of scripts/pins.txt.
# `--system`: the system packages only (`make test` builds and tests in target/test-venv).
# Idempotent: installs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
PACKAGES="mesa-vulkan-drivers libvulkan1 libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri libglx-mesa0 libusb-1.0-0"
missing=""
for p in $PACKAGES; do
    dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
if [ -n "$missing" ]; then
    echo "installing system packages:$missing"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
fi

if ! command -v cargo >/dev/null; then
    echo "scenesample needs a Rust toolchain (cargo); install it with rustup first" >&2
    exit 1
fi
if [ "${1:-}" = "--system" ]; then exit 0; fi

PY="${PYTHON:-python3}"
# Every version from scripts/pins.txt. maturin is installed first and the build is not isolated,
# so the pinned maturin builds it; its PEP 517 hook runs `maturin` from PATH, so the scripts
# folder of PY's environment goes first (PY may be a venv's python whose bin is not on PATH).
PIPI=("$PY" -m pip install --quiet --disable-pip-version-check -c scripts/pins.txt)
PATH="$("$PY" -c 'import sysconfig; print(sysconfig.get_path("scripts"))'):$PATH"
export PATH
"${PIPI[@]}" maturin
# numpy and the extras first, each built in its own isolated environment: some have no wheel
# (pyrender's PyOpenGL 3.1.0 is an sdist whose setup.py needs `wheel`, which a fresh Python
# lacks), and pip's cache of wheels it once built hides that on a machine that ran this before.
mapfile -t DEPS < <("$PY" scripts/pins.py requirements test demo)
"${PIPI[@]}" "${DEPS[@]}"
# Editable install: maturin builds the extension in release mode into python/scenesample/.
"${PIPI[@]}" --no-build-isolation --no-deps -e .
