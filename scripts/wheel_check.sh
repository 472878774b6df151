#!/usr/bin/env bash
# Prove that `pip install scenesample-*.whl` is all a user needs: install the given wheel into a
# fresh virtual environment (only numpy may come with it) and, from outside the source tree, run
# a smoke test and the quick demo without its extras (it must finish and name the extra), then
# the quickstart notebook. Versions come from scripts/pins.txt. `make test` passes the wheel it
# built from the sdist.
# Usage: scripts/wheel_check.sh path/to/scenesample-*.whl
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PY="${PYTHON:-python3}"
WHEEL=$(realpath "$1")
case "$(basename "$WHEEL")" in
    scenesample-*-cp39-abi3-manylinux2014_x86_64*.whl) ;;
    *) echo "not the abi3 manylinux2014 wheel: $WHEEL" >&2; exit 1 ;;
esac
echo "wheel: $(basename "$WHEEL") ($(du -h "$WHEEL" | cut -f1))"
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
pipq() { "$1" -m pip install --quiet --disable-pip-version-check --no-compile -c "$ROOT/scripts/pins.txt" "${@:2}"; }

"$PY" -m venv "$WORK/venv"
V="$WORK/venv/bin/python"
pipq "$V" "$WHEEL"
deps=$("$V" -m pip list --format=freeze --disable-pip-version-check | cut -d= -f1 | sort | tr '\n' ' ')
echo "installed: $deps"
case "$deps" in
    "numpy pip scenesample "|"numpy pip scenesample setuptools ") ;;
    *) echo "the wheel pulled in more than numpy: $deps" >&2; exit 1 ;;
esac
cd "$WORK"
"$V" "$ROOT/scripts/smoke.py" "$ROOT" "$ROOT/../shared/scenes/stanford_bunny/stanford-bunny.obj"

# The demo with the wheel alone: everything but what needs the `demo` extra, one line naming it.
"$V" -m scenesample.demo --quick --procedural --out "$WORK/demo" >"$WORK/demo.log" 2>&1 \
    || { cat "$WORK/demo.log"; echo "the demo failed without its extras" >&2; exit 1; }
if grep -q Traceback "$WORK/demo.log" || ! grep -q "pip install 'scenesample\[demo\]'" "$WORK/demo.log"; then
    cat "$WORK/demo.log"; echo "the demo without its extras must name scenesample[demo], with no traceback" >&2; exit 1
fi
grep "scenesample\[demo\]" "$WORK/demo.log"

pipq "$V" matplotlib nbclient nbformat ipykernel
"$V" - "$ROOT/notebooks/quickstart.ipynb" <<'PYEOF'
import sys
import nbclient, nbformat
nb = nbformat.read(sys.argv[1], as_version=4)
nbclient.NotebookClient(nb, timeout=600, kernel_name="python3").execute()
errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
          if o.get("output_type") == "error"]
assert not errors, errors
print("quickstart notebook ok (from the wheel)")
PYEOF
"$V" "$ROOT/scripts/pins.py" check "$V" --no-build-tools
