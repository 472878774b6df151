"""Same call, same result: every method's arrays on two shared scenes (tests/_determinism.py) are
bit-identical in this process, in fresh interpreters, in forked and spawned workers, when run
again in another order, and when run from two threads at once. Timings are the only fields
left out: they measure the run, not its answer."""

from __future__ import annotations

import json
import multiprocessing
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import _determinism
import pytest
from conftest import SHARED

pytestmark = pytest.mark.skipif(
    not all(s in SHARED for s in _determinism.SCENES), reason="shared scenes not present"
)


def assert_same(expected: dict[str, str], got: dict[str, str], where: str) -> None:
    assert got.keys() == expected.keys(), f"{where}: {sorted(got.keys() ^ expected.keys())[:10]}"
    differ = [k for k in expected if got[k] != expected[k]]
    assert not differ, f"{where}: {len(differ)} of {len(expected)} differ, e.g. {differ[:12]}"


@pytest.fixture(scope="module")
def reference(gpu) -> dict[str, str]:
    return _determinism.digests()


def test_fresh_interpreters_agree_with_this_process(reference):
    procs = [
        subprocess.Popen(
            [sys.executable, str(Path(_determinism.__file__)), order],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for order in ("forward", "reverse", "forward")
    ]
    for i, p in enumerate(procs):
        out, err = p.communicate(timeout=600)
        assert p.returncode == 0, err[-3000:]
        assert_same(reference, json.loads(out.strip().splitlines()[-1]), f"interpreter {i}")


@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_workers_agree_with_their_parent(reference, method):
    ex = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context(method))
    try:
        futures = [ex.submit(_determinism.digests, order) for order in ("forward", "reverse")]
        for i, f in enumerate(futures):
            assert_same(reference, f.result(timeout=600), f"{method}ed worker {i}")
    finally:
        for p in list(getattr(ex, "_processes", {}).values()):
            p.kill()
        ex.shutdown(wait=False, cancel_futures=True)


def test_repeats_and_threads_agree(reference):
    assert_same(reference, _determinism.digests("reverse"), "a repeat in reverse order")
    with ThreadPoolExecutor(2) as pool:
        for i, got in enumerate(pool.map(_determinism.digests, ("forward", "reverse"))):
            assert_same(reference, got, f"thread {i}")
