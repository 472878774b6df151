"""What accuracy costs in time: sweeps give one row per setting with its error, time and
memory, mark the Pareto front, run on any concurrent.futures executor (a dask cluster of
separate processes included) with the same errors, and plot."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import scenesample as ss


@pytest.fixture(scope="module")
def ball():
    return ss.scenes.icosphere(3)


CAM = ss.Camera.look_at((2.5, 2.0, 1.5), (0, 0, 0), (0, 0, 1), yfov=0.8, width=48, height=48)
KNOBS = {"octree_depth": [0, 1], "resolution": [8, 24], "subdivisions": [1]}


def test_a_sweep_tabulates_error_time_memory_and_the_front(ball):
    table = ss.tradeoff(ball, "impostors", knobs=KNOBS, camera=CAM, progress=False, as_frame=False)
    assert table.dtype.names[:3] == ("octree_depth", "resolution", "subdivisions")
    assert len(table) == 4
    assert np.isfinite(table["error"]).all() and (table["seconds"] >= 0).all()
    assert (table["memory"] > 0).all() and table["pareto"].any()
    # Finer images cost more memory; the front is not dominated by any row.
    for d in (0, 1):
        rows = table[table["octree_depth"] == d]
        assert rows["memory"][rows["resolution"] == 24] > rows["memory"][rows["resolution"] == 8]
    front = table[table["pareto"]]
    for f in front:
        beaten = (table["error"] < f["error"]) & (table["seconds"] < f["seconds"])
        assert not beaten.any()


def test_the_pareto_front_on_a_known_case():
    from scenesample._tradeoff import pareto

    err = np.array([1.0, 2.0, 0.5, 3.0, 0.5])
    sec = np.array([1.0, 0.5, 2.0, 3.0, 2.5])
    assert pareto(err, sec).tolist() == [True, True, True, False, False]


def test_an_executor_gives_the_same_errors(ball):
    serial = ss.tradeoff(ball, "impostors", knobs=KNOBS, camera=CAM, progress=False, as_frame=False)
    with ThreadPoolExecutor(2) as ex:
        threaded = ss.tradeoff(
            ball, "impostors", knobs=KNOBS, camera=CAM, executor=ex, progress=False, as_frame=False
        )
    np.testing.assert_array_equal(serial["error"], threaded["error"])
    np.testing.assert_array_equal(serial["memory"], threaded["memory"])


def test_a_dask_cluster_of_separate_processes_runs_a_sweep(ball):
    distributed = pytest.importorskip("dask.distributed")
    knobs = {"ids_per_sample": [1, 3], "interpolate": ["none", "uv+st"], "resolution": [6]}
    cam = ss.Camera.look_at((-4.0, 0.3, 0.2), (0, 0, 0), (0, 0, 1), yfov=0.7, width=48, height=48)
    serial = ss.tradeoff(
        ball, "visibility_field", knobs=knobs, camera=cam, progress=False, as_frame=False
    )
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        pids = set(client.run(lambda: __import__("os").getpid()).values())
        assert len(pids) == 2 and __import__("os").getpid() not in pids
        table = ss.tradeoff(
            ball,
            "visibility_field",
            knobs=knobs,
            camera=cam,
            executor=client.get_executor(),
            progress=False,
            as_frame=False,
        )
    np.testing.assert_array_equal(table["error"], serial["error"])
    # More ids and interpolation never miss more.
    e = {(r["ids_per_sample"], r["interpolate"]): r["error"] for r in table}
    assert e[3, "uv+st"] <= e[3, "none"] <= e[1, "none"]


def test_pandas_frames_and_the_plot(ball):
    pd = pytest.importorskip("pandas")
    table = ss.tradeoff(ball, "impostors", knobs=KNOBS, camera=CAM, progress=False)
    assert isinstance(table, pd.DataFrame) and len(table) == 4
    assert "error per foreground pixel" in table.attrs["error"]
    import matplotlib

    matplotlib.use("Agg")
    ax = ss.plot.tradeoff(table)
    assert ax.get_xlabel() == "seconds" and "foreground" in ax.get_ylabel()
    assert len(ax.lines) == 1 and len(ax.texts) == int(table["pareto"].sum())


def test_a_shadow_sweep_against_ray_casting(ball):
    floor = ss.Scene.from_arrays(
        np.concatenate(
            [ball.vertices * 0.3 + [0, 0, 0.6], [[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]]]
        ),
        np.concatenate([ball.faces, np.array([[0, 1, 2], [0, 2, 3]]) + len(ball.vertices)]),
        lights=[{"type": "point", "position": [0.3, 0.2, 2.0]}],
    )
    cam = ss.Camera.look_at((2.5, -2.5, 2.5), (0, 0, 0.3), (0, 0, 1), yfov=0.8, width=48, height=48)
    knobs = {"method": ["mvr", "epr"], "light_samples": [1, 4]}
    t = ss.tradeoff(floor, "omni_shadows", knobs=knobs, camera=cam, progress=False, as_frame=False)
    assert len(t) == 4 and np.isfinite(t["error"]).all() and (t["error"] < 40).all()
    # More light samples approach the 4-sample ray-cast reference.
    for m in ("mvr", "epr"):
        rows = t[t["method"] == m]
        assert rows["error"][rows["light_samples"] == 4] < rows["error"][rows["light_samples"] == 1]


def test_bad_input_is_refused(ball):
    with pytest.raises(ss.InputError, match="effect_or_method"):
        ss.tradeoff(ball, "caustics")
    with pytest.raises(ss.InputError, match="knob"):
        ss.tradeoff(ball, "impostors", knobs={"octree_depth": []})
    with pytest.raises(ss.InputError, match="executor"):
        ss.tradeoff(ball, "impostors", knobs=KNOBS, camera=CAM, executor=object(), progress=False)


def test_the_visibility_field_sweeps_quality_with_missed_cells_as_the_error():
    """The default sweep is the quality knob; each row carries its missed cells (the error),
    holes, coverage and build time, and the paper's resampling (fallback off, one slab) misses
    at least as much as the conservative default."""
    ball = ss.scenes.icosphere(3)
    cam = ss.Camera.look_at((-4.0, 0.3, 0.2), (0, 0, 0), (0, 0, 1), yfov=0.7, width=48, height=48)
    assert list(ss._tradeoff.KNOBS["visibility_field"]) == ["quality"]
    knobs = {"quality": ["fast", "exact"], "resolution": [6]}
    t = ss.tradeoff(
        ball, "visibility_field", knobs=knobs, camera=cam, progress=False, as_frame=False
    )
    assert list(t["quality"]) == ["fast", "exact"]
    assert ((t["error"] >= 0) & (t["error"] <= 1)).all()
    assert (t["covered"] > 0).all() and t["hole_fraction"][1] <= 0.01
    assert t["error"][1] <= t["error"][0]  # exact traces every mixed sample's lines
    assert (t["build_seconds"] >= 0).all()
    paper = {"resolution": [6], "fallback": [False], "single_slab": [True], "ids_per_sample": [1]}
    p = ss.tradeoff(
        ball, "visibility_field", knobs=paper, camera=cam, progress=False, as_frame=False
    )
    assert p["error"][0] >= t["error"].max()
