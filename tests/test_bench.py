"""The benchmark driver runs end to end (a smoke test at small sizes: the figures themselves
belong to `python -m scenesample.bench all`, not to a timed test)."""

from __future__ import annotations

import re

import pytest
import scenesample as ss


def test_bench_all_quick_writes_a_summary_and_every_methods_row(tmp_path, capsys, gpu):
    """`bench all --quick` writes the summary of every benchmark; its `bench methods` part
    measures every method against its brute force on small shared scenes, with the summary and
    one table per method (checked here rather than by a second run of the same benchmark)."""
    pytest.importorskip("embreex")
    pytest.importorskip("open3d")
    pytest.importorskip("pyrender")
    from scenesample.tools import bench

    out = tmp_path / "all.md"
    bench.main(["all", "--quick", "--repeats", "1", "--out", str(out)])
    md = out.read_text()
    for row in (
        "rays, primary, closest hit: one core vs Open3D",
        "rays, shadow, occluded: every core vs Open3D",
        "rays, BVH memory / Embree's",
        "depth images vs pyrender",
        "non-redundant / conventional time",
        "EPR speedup over MVR",
        "iVIR / EPR points",
        "field speedup over drawing everything, default (balanced) (turtles",
        "field speedup over drawing everything, paper, 1 slab, 1 id (turtles",
        "methods: field view / conventional, both on the GPU",
        "methods: non-redundant / conventional, GPU",
    ):
        assert row in md, row
    assert md.count("| met |") + md.count("| NOT met |") >= 14
    printed = capsys.readouterr().out
    assert "wrote" in printed
    # The methods report, as `bench methods` writes it, printed between the field's report
    # and the summary.
    methods = printed.split("# `python -m scenesample.bench methods`", 1)[1]
    check_methods_report(methods.split("`python -m scenesample.bench all`", 1)[0])


def test_bench_scenes_quick_poses_a_tiling_and_reports_every_target(tmp_path):
    """`bench scenes` tiles a shared scene into objects, poses it, and reports the pose against
    a build, posed incoherent and primary rays against flat ones and a frame against fcpw and
    Open3D, and a skinned frame against the same peers."""
    pytest.importorskip("fcpw")
    pytest.importorskip("open3d")
    from scenesample.tools import bench

    out = tmp_path / "scenes.md"
    bench.main(["scenes", "--quick", "--rounds", "1", "--scenes", "bunny", "--out", str(out)])
    md = out.read_text()
    assert "| stanford_bunny |" in md
    targets = (
        "a new pose <= 1% of a build",
        "posed incoherent rays >= 0.9x flat",
        "posed primary rays >= 0.9x flat",
        "frame >= 3x fcpw",
    )
    for target in targets:
        assert target in md
    skinned = md.split("Skinned frame (", 1)[1]
    assert re.match(r"10,240 triangles, 8 joints; (refit|built afresh)\)", skinned)
    assert skinned.count("x (") == 2


def test_bench_rays_quick_measures_scenes_and_tilings_on_one_core_and_every_core(tmp_path):
    """`bench rays` measures a shared scene and its tiling, each ray set on one core (a child
    process pinned to one) and on every core, against Open3D and embreex, with a verdict for
    every target, the build and the memory."""
    pytest.importorskip("embreex")
    pytest.importorskip("open3d")
    from scenesample.tools import _bench_rays, bench

    out = tmp_path / "rays.md"
    bench.main(["rays", "--quick", "--scenes", "bunny", "--out", str(out)])
    md = out.read_text()
    sections = ("## primary", "## incoherent", "## camera", "## shadow", "## segments", "## BVH")
    for section in sections:
        assert section in md
    for name in ("| stanford_bunny |", "| stanford_bunny x2 (tiled) |"):
        rows = [line for line in md.splitlines() if line.startswith(name)]
        assert len(rows) == 6, name  # one row per table
    rows = _bench_rays.summary_rows(_bench_rays.run(True, 1, ["cornell"]))
    # Two per ray set against Open3D, occluded against the closest hit on three sets on one and
    # every core, scaling and agreement per set, count (two) and list of hits, build, memory.
    assert len(rows) == 10 + 6 + 5 + 3 + 5 + 2 and all(r[2] > 0 for r in rows)
    # The cornell box (3,968 triangles) is only measured tiled.
    assert {r[3] for r in rows} == {"cornell_box x26 (tiled)"}
    assert "count_hits vs Open3D's count_intersections (one core)" in md
    assert "pinned with `os.sched_setaffinity`" in md
    assert f"kernel {ss.ray_kernel()}" in md


def test_bench_backends_quick_compares_gpu_cpu_and_auto(tmp_path, gpu):
    from scenesample.tools import bench

    out = tmp_path / "backends.md"
    bench.main(["backends", "--quick", "--repeats", "1", "--out", str(out)])
    md = out.read_text()
    assert "| scene | triangles | gpu | cpu | auto |" in md
    assert md.count("(gpu) |") + md.count("(cpu) |") >= 2  # conventional and peeling rows
    assert "Worst scene:" in md and ("met." in md)
    assert "Depth peeling, 4 layers" in md and "first difference not a tie |" in md
    assert "| 320x240 | orbit |" in md and "| 320x240 | sparse |" in md  # the crossover rows


def test_the_predicted_crossover_is_where_the_model_changes_its_mind(gpu):
    from scenesample.tools import _bench_backends as bb

    at = bb.predicted_crossover(640, 480)
    if at is None:
        pytest.skip("the model prefers one backend at every size on this machine")

    def picks(triangles: int) -> str:
        return ss.device_info(triangles=triangles, pixels=640 * 480, images=bb.VIEWS)["auto"][
            "backend"
        ]

    assert picks(at) == "cpu" and picks(int(at / 1.06)) == "gpu"


def check_methods_report(md: str) -> None:
    """The report of `bench methods --quick`: every row and section, a verdict on each."""
    for label in (
        "field view / conventional, both on the GPU (>= 1M triangles)",
        "field view / conventional, both on the CPU (>= 1M triangles)",
        "field: resampling share of the view's time",
        "field: cells drawn / cells visible",
        "field: hole pixels",
        "field: missed visible cells",
        "non-redundant / conventional, GPU",
        "impostors / triangles at 3x the size",
        "impostors / triangles at 8x the size",
        "EPR speedup over MVR",
    ):
        assert f"| {label} |" in md, label
    for section in (
        "## Visibility field",
        "## Non-redundant rendering",
        "## EPR against MVR",
        "## Impostors against their triangles",
        "## Soft shadows",
    ):
        assert section in md, section
    # The two field speed rows need a scene of >= 1M triangles; every other row has a verdict.
    assert md.count("| no scene fits |") == 2
    assert md.count("| met |") + md.count("| NOT met |") == 8
    assert md.count("| khr_simple_instancing |") >= 4  # field, NR, impostors, shadows
    assert md.count("| reflective_room |") >= 5  # and EPR


def test_bench_points_quick_splits_closed_and_open_scenes_and_reports_every_target(tmp_path):
    """`bench points` measures each query against every peer on closed and open scenes (here
    one of each, small) and reports a verdict for every target."""
    for peer in ("open3d", "fcpw", "igl", "point_cloud_utils", "trimesh"):
        pytest.importorskip(peer)
    import scenesample as ss
    from scenesample.tools import bench

    files = ss.scenes.shared_scene_files()
    if not {"khr_clearcoat_car_paint", "khr_cameras"} <= set(files):
        pytest.skip("shared scenes not present")
    out = tmp_path / "points.md"
    bench.main(["points", "--quick", "--scenes", "clearcoat,cameras", "--out", str(out)])
    md = out.read_text()
    assert "## Closed scenes: khr_clearcoat_car_paint" in md
    assert "## Open scenes: khr_cameras" in md
    for label in (
        "closest points, surface: fastest peer's time / ours",
        "closed scenes, box: occupancy, Open3D time / ours",
        "closed scenes, surface: signs agreeing with Open3D's",
        "open scenes, surface: signed distance, libigl fast winding number time / ours",
        "open scenes, box: signs agreeing with the float64 winding number's",
    ):
        assert f"| {label} |" in md, label
    # Every target has a verdict: three for closest points and three per group, per set.
    assert md.count("| met |") + md.count("| NOT met |") == 2 * (3 + 3 + 3)
    # Each peer's closest-point column is filled for both scenes.
    for name in ("khr_clearcoat_car_paint", "khr_cameras"):
        row = next(line for line in md.splitlines() if line.startswith(f"| {name} |"))
        assert "—" not in row.split("|")[4:8], row
