"""Ordinary Python process handling: a child forked (or spawned) after the parent used the
package just works, and Ctrl-C stops a long call before its work is done, leaving the
process, its caches and the GPU device usable."""

from __future__ import annotations

import json
import multiprocessing
import os
import pickle
import subprocess
import sys
import textwrap
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout

import _workers
import numpy as np
import pytest
import scenesample as ss

CHILD_TIMEOUT = 300


def run_in_children(method: str, fn, *args, n: int = 2):
    """`fn(*args)` in `n` children of a `method` pool; the children are killed, and the test
    fails, if they do not answer in time (a hang would otherwise outlive the test run)."""
    ex = ProcessPoolExecutor(n, mp_context=multiprocessing.get_context(method))
    try:
        futures = [ex.submit(fn, *args) for _ in range(n)]
        try:
            return [f.result(timeout=CHILD_TIMEOUT) for f in futures]
        except FutureTimeout:
            for p in list(getattr(ex, "_processes", {}).values()):
                p.kill()
            pytest.fail(f"a {method}ed child hung on its first call after the parent's")
    finally:
        ex.shutdown(wait=False, cancel_futures=True)


@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_children_work_after_the_parent_used_rays_images_and_splats(gpu, method):
    here = _workers.use_everything()
    for there in run_in_children(method, _workers.use_everything):
        assert there.keys() == here.keys()
        for k in here:
            np.testing.assert_array_equal(there[k], here[k], err_msg=k)


def test_a_child_forked_after_the_parent_made_scenes_makes_them_too():
    """Scene.from_arrays (and so unpickling) and Scene.closed run on the package's pool, never
    on rayon's global one, whose threads a fork does not copy: a large scene made, or asked
    whether it is closed, in the parent and then in a forked child hung the child once its
    faces took several parallel chunks."""
    big = ss.scenes.icosphere(6)  # 81,920 faces: more than one chunk of the bounds pass
    data = pickle.dumps(big)
    here = _workers.unpickled_scene(data)
    assert here == (big.triangle_count, True)
    assert run_in_children("fork", _workers.unpickled_scene, data) == [here] * 2


def test_a_tradeoff_on_a_fork_pool_after_use(gpu):
    ball = ss.scenes.icosphere(3)
    _workers.use_everything()
    serial = ss.tradeoff(
        ball,
        "impostors",
        knobs=_workers.KNOBS,
        camera=_workers.camera(),
        progress=False,
        as_frame=False,
    )
    ex = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("fork"))
    try:
        forked = ss.tradeoff(
            ball,
            "impostors",
            knobs=_workers.KNOBS,
            camera=_workers.camera(),
            executor=ex,
            progress=False,
            as_frame=False,
        )
    finally:
        for p in list(getattr(ex, "_processes", {}).values()):
            p.kill()
        ex.shutdown(wait=False, cancel_futures=True)
    np.testing.assert_array_equal(forked["error"], serial["error"])
    np.testing.assert_array_equal(forked["memory"], serial["memory"])


# The script a subprocess runs: start a long call whose progress callback sends SIGINT as soon as
# the work has counted itself (so the call is under way, however fast the machine), and report
# whether the KeyboardInterrupt came, where the work stood when it stopped, and whether
# everything still works afterwards.
INTERRUPT = textwrap.dedent(
    """
    import json, os, signal, sys, time
    import numpy as np
    import scenesample as ss

    # Python's own Ctrl-C handler, whatever started the test (a shell's background job starts
    # its children with SIGINT ignored, and Python then installs none).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    scene = ss.scenes.icosphere(4)
    cam = ss.Camera.look_at((3, 2, 1.5), (0, 0, 0), (0, 0, 1), yfov=0.8, width=32, height=24)
    before = ss.discretize(scene, [cam]).triangle
    rng = np.random.default_rng(0)
    if sys.argv[1].startswith("cast_rays"):
        n = 20_000_000
        o = rng.uniform(-2, 2, (n, 3)).astype(np.float32)
        d = rng.normal(size=(n, 3)).astype(np.float32)
    seen, sent = [], []
    def progress(done, total):
        seen.append((done, total))
        if total and not sent:
            sent.append(time.perf_counter())
            os.kill(os.getpid(), signal.SIGINT)
    calls = {
        "cast_rays": lambda: ss.cast_rays(scene, o, d, threads=1, progress=progress),
        "cast_rays_all_cores": lambda: ss.cast_rays(scene, o, d, progress=progress),
        "visibility_field": lambda: ss.discretize(
            scene, method="visibility_field", uv=(40, 40), st=(40, 40), progress=progress),
        "impostors": lambda: ss.discretize(
            scene, method="impostors", octree_depth=2, resolution=64, progress=progress),
    }
    out = {"interrupted": False}
    try:
        calls[sys.argv[1]]()
    except KeyboardInterrupt:
        out["interrupted"] = True
        out["seconds"] = time.perf_counter() - sent[0]
    out["seen"] = seen
    small = ss.cast_rays(scene, np.zeros((4, 3), np.float32), np.eye(4, 3, dtype=np.float32) + 1)
    out["rays_after"] = small.triangle.tolist()
    out["rays_fresh"] = ss.cast_rays(
        ss.scenes.icosphere(4), np.zeros((4, 3), np.float32),
        np.eye(4, 3, dtype=np.float32) + 1).triangle.tolist()
    out["image_same"] = bool((ss.discretize(scene, [cam]).triangle == before).all())
    print(json.dumps(out))
    """
)


@pytest.mark.parametrize(
    "call", ["cast_rays", "cast_rays_all_cores", "visibility_field", "impostors"]
)
def test_ctrl_c_stops_a_long_call_before_its_work_is_done(gpu, call):
    """The interruption is raised from the call, the work's last count (reported once more
    where it stopped) falls short of its total, and the process, its caches and the GPU work
    as before. No clock decides the outcome: the signal follows the work's own first report."""
    env = dict(os.environ, PYTHONFAULTHANDLER="1")
    r = subprocess.run(
        [sys.executable, "-c", INTERRUPT, call],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["interrupted"], out
    done, total = out["seen"][-1]
    assert 0 <= done < total, out["seen"]
    assert out["rays_after"] == out["rays_fresh"]
    assert out["image_same"]


def test_calls_from_other_threads_finish_while_the_main_thread_is_interrupted(gpu):
    """The interruption stops only the call it was meant for: another thread's ray cast, under
    way when it comes (its first progress report says so) and perhaps stopped by the shared
    flag and run again, returns the same hits."""
    script = textwrap.dedent(
        """
        import json, os, signal, threading
        import numpy as np
        import scenesample as ss

        signal.signal(signal.SIGINT, signal.default_int_handler)  # as in INTERRUPT
        scene = ss.scenes.icosphere(4)
        rng = np.random.default_rng(1)
        o = rng.uniform(-2, 2, (3_000_000, 3)).astype(np.float32)
        d = rng.normal(size=(3_000_000, 3)).astype(np.float32)
        expect = ss.cast_rays(scene, o, d, threads=1).triangle
        got, started = {}, threading.Event()
        def other():
            got["hits"] = ss.cast_rays(
                scene, o, d, threads=1, progress=lambda done, total: started.set()).triangle
        worker = threading.Thread(target=other)
        worker.start()
        started.wait()
        sent = []
        def interrupt(done, total):
            if total and not sent:
                sent.append(done)
                os.kill(os.getpid(), signal.SIGINT)
        interrupted = False
        try:
            ss.cast_rays(scene, o, d, progress=interrupt)
        except KeyboardInterrupt:
            interrupted = True
        worker.join()
        print(json.dumps({"interrupted": interrupted,
                          "same": bool((got["hits"] == expect).all())}))
        """
    )
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out == {"interrupted": True, "same": True}


def test_cameras_pickle_bit_for_bit():
    import pickle

    cams = [
        ss.Camera.look_at((1.0, 2.0, 3.0), (0.1, 0.2, 0.3), yfov=0.7, width=33, height=17),
        ss.Camera.orthographic(np.eye(4), xmag=1.5, ymag=0.5, width=8, height=9, znear=0.1),
        *ss.Camera.cube((0.3, 0.2, 0.1), 16, zfar=50.0),
    ]
    for c in cams:
        back = pickle.loads(pickle.dumps(c))
        assert back == c
        assert back.name == c.name and back.projection == c.projection
        np.testing.assert_array_equal(back.pose, c.pose)
    with pytest.raises(ss.InputError, match="16"):
        ss.Camera._restore([1.0] * 3, "perspective", (0.5, 0.0), 4, 4, None, None, None)
