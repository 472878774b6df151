"""The loaders under mutation (tests/fuzz_loaders.py): a few hundred mutated glTF, GLB, OBJ and
MTL files load or raise the package's typed errors, and the harness itself reports a crash, a
hang and an untyped error as findings without losing the cases after them. `make fuzz` runs a
longer campaign."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import fuzz_loaders
import pytest

HARNESS = str(Path(fuzz_loaders.__file__))

pytestmark = pytest.mark.skipif(not fuzz_loaders.seeds_present(), reason="no shared scenes")


def fuzz(*args: str) -> dict:
    r = subprocess.run(
        [sys.executable, HARNESS, *args], capture_output=True, text=True, timeout=600
    )
    return json.loads(r.stdout)


def test_mutated_scene_files_load_or_raise_typed_errors():
    report = fuzz("--cases", "400", "--seed", "7")
    assert report["findings"] == [], report
    assert sum(report["outcomes"].values()) == 400
    # The mutations reach both ends: files that still load, and each kind of typed error.
    assert {"ok", "error: SceneFileError", "error: SceneError"} <= set(report["outcomes"])


@pytest.mark.parametrize("kind", ["crash", "hang", "raise"])
def test_the_harness_reports_what_is_not_a_typed_error(kind):
    report = fuzz("--cases", "6", "--seed", "0", "--inject", kind, "--inject-at", "2",
                  "--timeout", "5")  # fmt: skip
    (finding,) = report["findings"]
    assert finding["case"] == 2, report
    assert {"crash": "exit -6", "hang": "hang", "raise": "RuntimeError"}[kind] in finding["what"]
    assert sum(report["outcomes"].values()) == 5, "the cases after it still ran"
