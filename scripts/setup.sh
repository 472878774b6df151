#!/usr/bin/env bash
# Set up a fresh Debian/Ubuntu machine: system packages (Mesa's software Vulkan driver for the GPU
# path, EGL for pyrender, libusb for Open3D), then scenesample built in release mode with the test
# extras, as an editable install into the current Python (what `make demo` and `make check` use).
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
# Editable install: maturin builds the extension in release mode into python/scenesample/.
"$PY" -m pip install --quiet --disable-pip-version-check -e ".[test]"
