"""Progress bars on long work: tqdm when installed, counting real units (slab samples, cells,
triangles, settings), shown at once with progress=True, never with False, and by default only
once the work has run for a couple of seconds."""

from __future__ import annotations

import numpy as np
import pytest
import scenesample as ss
import scenesample._progress as progress_module


class Recorder:
    """Stands in for tqdm: records what the bar was told."""

    made: list = []

    def __init__(self, total=None, desc="", unit="", delay=0.0, leave=True):
        self.total, self.desc, self.unit, self.delay, self.n = total, desc, unit, delay, 0
        self.updates = 0
        Recorder.made.append(self)

    def update(self, n):
        self.n += n
        self.updates += 1

    def refresh(self):
        pass

    def close(self):
        self.closed = True


@pytest.fixture
def bars(monkeypatch):
    tqdm_auto = pytest.importorskip("tqdm.auto")
    Recorder.made = []
    monkeypatch.setattr(tqdm_auto, "tqdm", Recorder)
    return Recorder.made


def test_the_field_counts_slab_samples(bars):
    ball = ss.scenes.icosphere(2)
    ss.discretize(ball, method="visibility_field", uv=(4, 3), st=(5, 2), progress=True)
    (bar,) = bars
    assert (bar.unit, bar.delay, bar.closed) == ("samples", 0.0, True)
    # Six slabs by default, counted from the start (the total does not grow slab by slab).
    assert bar.total == bar.n == 6 * 4 * 3 * 5 * 2


def test_impostors_count_cells_and_points_count_triangles(bars, gpu):
    ball = ss.scenes.icosphere(2)
    imp = ss.discretize(ball, method="impostors", octree_depth=1, resolution=8, progress=True)
    assert bars[-1].unit == "cells" and bars[-1].total == bars[-1].n == len(imp.cells)
    eye = ss.Camera.look_at((3, 0, 1), (0, 0, 0), (0, 0, 1), yfov=0.8, width=32, height=32)
    mirror = ss.scenes.icosphere(1, radius=0.3, center=(0.0, 1.2, 0.0))
    scene = ss.Scene.from_arrays(
        np.concatenate([ball.vertices, mirror.vertices]),
        np.concatenate([ball.faces, mirror.faces + len(ball.vertices)]),
    )
    ss.discretize(scene, method="epr", eye=eye, reflectors=[((0.0, 1.2, 0.0), 0.3)],
                  resolution=16, progress=True)  # fmt: skip
    assert bars[-1].unit == "triangles"
    assert bars[-1].total == bars[-1].n and bars[-1].n % scene.triangle_count == 0


def test_default_bars_wait_and_false_shows_none(bars):
    ball = ss.scenes.icosphere(2)
    ss.discretize(ball, method="visibility_field", uv=(2, 2), st=(2, 2))
    assert bars[-1].delay == progress_module.DELAY
    before = len(bars)
    ss.discretize(ball, method="visibility_field", uv=(2, 2), st=(2, 2), progress=False)
    assert len(bars) == before
    with pytest.raises(ss.InputError, match="progress"):
        ss.discretize(ball, method="visibility_field", progress="yes")


def test_tradeoff_counts_settings(bars):
    ball = ss.scenes.icosphere(2)
    cam = ss.Camera.look_at((2.5, 2.0, 1.5), (0, 0, 0), (0, 0, 1), yfov=0.8, width=24, height=24)
    knobs = {"depth": [0, 1], "resolution": [8], "subdivisions": [1]}
    ss.tradeoff(ball, "impostors", knobs=knobs, camera=cam, progress=True, as_frame=False)
    sweep = [b for b in bars if b.unit == "settings"]
    assert len(sweep) == 1 and sweep[0].total == sweep[0].n == 2


def test_an_experiment_counts_its_scenes(bars, tmp_path, gpu):
    from scenesample.tools.experiments import impostors

    impostors.main(
        ["--scenes", "urban", "--distances", "1", "--octree-depth", "1", "--subdivisions", "0"]
        + ["--resolution", "8", "--budgets", "0", "--storage-octree-depths", "0"]
        + ["--size", "24", "--out", str(tmp_path)]
    )
    outer = [b for b in bars if b.unit == "scenes"]
    assert len(outer) == 1 and outer[0].total == outer[0].n == 1


def recorder():
    """A progress callable and the list of ``(done, total)`` it was told."""
    seen: list = []
    return seen, lambda *a: seen.append(a)


def test_ray_queries_count_rays_and_a_callable_hears_the_counts():
    ball = ss.scenes.icosphere(2)
    rng = np.random.default_rng(0)
    o = rng.uniform(-2, 2, (5000, 3)).astype(np.float32)
    d = rng.normal(size=(5000, 3)).astype(np.float32)
    for threads in (None, 1):
        seen, hear = recorder()
        ss.cast_rays(ball, o, d, threads=threads, progress=hear)
        assert seen[-1] == (5000, 5000), (threads, seen)
        assert all(done <= total for done, total in seen)
    seen, hear = recorder()
    ss.occluded(ball, o, d, progress=hear)
    assert seen[-1] == (5000, 5000)
    # Inner ray casts of other methods do not count as theirs: the field counts samples.
    seen, hear = recorder()
    ss.discretize(ball, method="visibility_field", uv=(2, 2), st=(2, 2), progress=hear)
    assert seen[-1] == (6 * 16, 6 * 16)


def test_a_sweep_tells_a_callable_each_setting():
    ball = ss.scenes.icosphere(2)
    cam = ss.Camera.look_at((2.5, 2.0, 1.5), (0, 0, 0), (0, 0, 1), yfov=0.8, width=24, height=24)
    knobs = {"depth": [0, 1], "resolution": [8], "subdivisions": [1]}
    seen, hear = recorder()
    ss.tradeoff(ball, "impostors", knobs=knobs, camera=cam, progress=hear, as_frame=False)
    assert seen == [(1, 2), (2, 2)]
