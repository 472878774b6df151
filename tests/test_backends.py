"""Conventional images from the CPU (ray-cast) backend equal the GPU (raster) backend's, `auto`
picks one and says why, and without any Vulkan driver the CPU paths still work while the
GPU-only methods say what to install."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import scenesample as ss
from conftest import SHARED, load_quiet

FIELDS = ("depth", "triangle", "normal", "position", "color")


def _agree(gpu_images: ss.DepthImages, cpu_images: ss.DepthImages, scene: ss.Scene) -> None:
    """The CPU images match the GPU's: same dtypes and shapes; ids equal at >= 99.9% of the
    pixels, and at every pixel where they differ the pixel centre lies within 1/50 pixel of an
    edge of one of the two triangles (the raster snaps vertices to 1/256 pixel, so a centre on
    an edge, or inside a sliver seen edge-on, can fall either side) or both see a surface at
    one depth (1e-4 relative); depths within 1e-5 relative where the ids agree."""
    for f in FIELDS:
        a, b = getattr(gpu_images, f), getattr(cpu_images, f)
        assert a.dtype == b.dtype and a.shape == b.shape, f
    g, c = gpu_images.triangle, cpu_images.triangle
    differ = g != c
    assert differ.mean() <= 1e-3, differ.mean()
    same = ~differ & (g >= 0)
    np.testing.assert_allclose(cpu_images.depth[same], gpu_images.depth[same], rtol=1e-5)
    np.testing.assert_array_equal(cpu_images.normal[same], gpu_images.normal[same])
    assert np.isinf(cpu_images.depth[c < 0]).all() and np.isnan(cpu_images.position[c < 0]).all()
    for i in range(len(gpu_images.cameras)):
        rows, cols = np.nonzero(differ[i])
        ok = _explained(gpu_images, cpu_images, scene, i, rows, cols)
        assert ok.all(), (i, rows[~ok], cols[~ok])


def _explained(
    gpu_images: ss.DepthImages,
    cpu_images: ss.DepthImages,
    scene: ss.Scene,
    i: int,
    rows: np.ndarray,
    cols: np.ndarray,
) -> np.ndarray:
    """Which of image i's pixels (rows, cols), where the two backends name different triangles,
    have a pixel centre within 1/50 pixel of an edge of one of the two triangles, or both see
    a surface at one depth (1e-4 relative: where surfaces cross or coincide, the depth
    buffer's float32 decides)."""
    g, c = gpu_images.triangle[i, rows, cols], cpu_images.triangle[i, rows, cols]
    cam = gpu_images.cameras[i]
    # The pixel centre, in the convention of `project`: where the surface point projects.
    seen = np.where((g >= 0)[:, None], gpu_images.position[i, rows, cols], 0)
    seen = np.where((g < 0)[:, None], cpu_images.position[i, rows, cols], seen)
    centre = cam.project(seen)[0]
    near_edge = np.zeros(rows.size, bool)
    for t in (g, c):
        ok = t >= 0
        corners = cam.project(scene.vertices[scene.faces[t[ok]]].reshape(-1, 3))[0]
        near_edge[ok] |= _edge_distance(centre[ok], corners.reshape(-1, 3, 2)) <= 0.02
    gd, cd = gpu_images.depth[i, rows, cols], cpu_images.depth[i, rows, cols]
    return near_edge | (np.abs(gd - cd) <= 1e-4 * np.minimum(gd, cd))


def _edge_distance(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Distance in pixels from points (N, 2) to the nearest edge of triangles (N, 3, 2)."""
    out = np.full(len(p), np.inf)
    for k in range(3):
        a, b = tri[:, k], tri[:, (k + 1) % 3]
        ab = b - a
        s = np.clip(((p - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-30), 0, 1)
        out = np.minimum(out, np.linalg.norm(p - (a + s[:, None] * ab), axis=1))
    return out


@pytest.mark.parametrize("cull", [False, True])
def test_cpu_images_equal_the_gpus_on_a_procedural_scene(gpu, cull):
    scene = ss.scenes.shapes(seed=3, detail=2)
    lo, hi = scene.bounds
    c = (lo + hi) / 2
    r = float(np.linalg.norm(hi - lo))
    cams = [
        ss.Camera.look_at(c + r * np.array([0.8, 0.5, 0.6]), c, yfov=0.8, width=160, height=120),
        ss.Camera.look_at(c + r * np.array([-0.7, 0.3, 0.9]), c, yfov=0.6, width=160, height=120),
        ss.Camera.orthographic(
            _pose(c + r * np.array([0.0, 0.2, 1.0]), c),
            xmag=r / 2,
            ymag=r * 0.375,
            width=160,
            height=120,
            znear=0.01 * r,
            zfar=3 * r,
        ),
    ]
    g = ss.discretize(scene, cams, cull_backfaces=cull, backend="gpu")
    c_ = ss.discretize(scene, cams, cull_backfaces=cull, backend="cpu")
    assert (g.backend, c_.backend) == ("gpu", "cpu")
    assert c_.backend_reason == "requested"
    assert {"bvh", "trace", "edges", "resolve", "total"} <= set(c_.timings)
    _agree(g, c_, scene)


@pytest.mark.parametrize("cull", [False, True])
def test_cpu_peeling_equals_the_gpus(gpu, cull):
    """Each pixel's layers agree until the first layer where the backends name different
    triangles, and that difference lies at an edge or a depth tie (the deeper layers of such a
    pixel follow from it); depths agree wherever the layers do."""
    scene = ss.scenes.shapes(seed=0, detail=2)
    cam = ss.Camera.look_at((3, 2, 3), (0, 0, 0), yfov=0.8, width=160, height=120)
    g = ss.discretize(scene, cam, "peeling", layers=4, cull_backfaces=cull, backend="gpu")
    c = ss.discretize(scene, cam, "peeling", layers=4, cull_backfaces=cull, backend="cpu")
    assert (g.backend, c.backend, c.method) == ("gpu", "cpu", "peeling")
    assert {"bvh", "trace", "edges", "resolve", "ties", "total"} <= set(c.timings)
    for f in FIELDS:
        assert (
            getattr(g, f).dtype == getattr(c, f).dtype
            and getattr(g, f).shape == getattr(c, f).shape
        )
    differ = g.triangle != c.triangle
    before = np.cumsum(differ, axis=0) - differ  # differences in earlier layers
    first = differ & (before == 0)
    for i in range(4):
        rows, cols = np.nonzero(first[i])
        assert _explained(g, c, scene, i, rows, cols).all(), i
        same = (before[i] == 0) & ~differ[i] & (g.triangle[i] >= 0)
        np.testing.assert_allclose(c.depth[i][same], g.depth[i][same], rtol=1e-5)
    # Most pixels agree on every layer; layers deepen along each pixel.
    assert (~differ.any(axis=0)).mean() > 0.98
    for i in range(1, 4):
        deeper = c.triangle[i] >= 0
        assert (c.triangle[i - 1][deeper] >= 0).all()
        assert (c.depth[i][deeper] > c.depth[i - 1][deeper]).all()
    if cull:
        assert c.triangle[2:].max() >= 0  # the culled layers still reach the far shapes
    else:
        assert (c.triangle[1] >= 0).sum() == (c.triangle[0] >= 0).sum()  # closed shapes


def test_culled_cpu_peeling_sees_a_front_face_under_its_back_twin():
    """A quad drawn with both windings (one copy each way, as exporters do for two-sided
    surfaces): culling keeps the copy that faces the camera, on both sides."""
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    f = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 2], [0, 2, 3]], np.uint32)  # back ones first
    scene = ss.Scene.from_arrays(v, f)
    for z, front in ((3.0, {2, 3}), (-3.0, {0, 1})):
        cam = ss.Camera.look_at((0.1, 0.2, z), (0, 0, 0), yfov=0.5, width=32, height=32)
        img = ss.discretize(scene, cam, "peeling", layers=2, cull_backfaces=True, backend="cpu")
        seen = set(np.unique(img.triangle[0])) - {-1}
        assert seen == front, (z, seen)
        assert (img.triangle[1] == -1).all()


def _pose(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    return ss.Camera.look_at(eye, target, yfov=0.5, width=8, height=8).pose


def test_a_near_plane_through_the_scene_cuts_both_backends_alike(gpu):
    scene = ss.scenes.shapes(seed=1, detail=2)
    lo, hi = scene.bounds
    c = (lo + hi) / 2
    r = float(np.linalg.norm(hi - lo))
    eye = c + r * np.array([0.6, 0.4, 0.5])
    dist = float(np.linalg.norm(eye - c))
    cam = ss.Camera.look_at(eye, c, yfov=0.8, width=128, height=128, znear=dist, zfar=dist * 1.3)
    g = ss.discretize(scene, cam, backend="gpu")
    cpu = ss.discretize(scene, cam, backend="cpu")
    covered = cpu.triangle >= 0
    assert covered.any() and (~covered).any()
    assert (cpu.depth[covered] >= dist * (1 - 1e-6)).all()
    assert (cpu.depth[covered] <= dist * 1.3 * (1 + 1e-6)).all()
    _agree(g, cpu, scene)


@pytest.mark.skipif("khr_toy_car" not in SHARED, reason="shared scenes not present")
def test_cpu_images_equal_the_gpus_on_a_real_scene(gpu):
    scene = load_quiet(SHARED["khr_toy_car"])
    lo, hi = scene.bounds
    c = (lo + hi) / 2
    r = float(np.linalg.norm(hi - lo))
    cam = ss.Camera.look_at(c + r * np.array([0.7, 0.5, 0.6]), c, yfov=0.8, width=320, height=240)
    g, c_ = (ss.discretize(scene, cam, backend=b) for b in ("gpu", "cpu"))
    _agree(g, c_, scene)


def test_auto_picks_a_backend_and_says_why(gpu):
    scene = ss.scenes.shapes(seed=0, detail=1)
    cam = ss.Camera.look_at((3, 2, 3), (0, 0, 0), yfov=0.8, width=64, height=64)
    images = ss.discretize(scene, cam)
    assert images.backend in ("gpu", "cpu")
    assert "predicted gpu" in images.backend_reason
    auto = ss.device_info(triangles=scene.triangle_count, pixels=64 * 64)["auto"]
    assert auto["backend"] in ("gpu", "cpu") and auto["cpu_seconds"] > 0
    assert auto["gpu_seconds"] is not None and auto["gpu_seconds"] > 0
    # The model grows with the work: more pixels never predict less time.
    more = ss.device_info(triangles=scene.triangle_count, pixels=1024 * 1024)["auto"]
    assert more["cpu_seconds"] >= auto["cpu_seconds"]
    assert more["gpu_seconds"] >= auto["gpu_seconds"]
    # A BVH still to build costs the CPU path time.
    cold = ss.device_info(triangles=4_000_000, pixels=1024 * 1024, bvh_built=False)["auto"]
    warm = ss.device_info(triangles=4_000_000, pixels=1024 * 1024, bvh_built=True)["auto"]
    assert cold["cpu_seconds"] > warm["cpu_seconds"]


def test_auto_sends_images_beyond_the_gpus_textures_to_the_cpu(gpu):
    """A request the GPU cannot hold (wider than its largest texture) runs on the CPU under
    auto, and equals what backend="cpu" makes; backend="gpu" raises GpuLimitError."""
    scene = ss.scenes.icosphere(1)
    wide = gpu["max_texture_dimension_2d"] + 1
    cam = ss.Camera.look_at([0, 0, 3], [0, 0, 0], yfov=0.01, width=wide, height=2)
    auto = ss.discretize(scene, cam)
    assert auto.backend == "cpu" and "largest texture" in auto.backend_reason
    assert auto.mask.any()
    cpu = ss.discretize(scene, cam, backend="cpu")
    assert np.array_equal(auto.triangle, cpu.triangle)
    with pytest.raises(ss.GpuLimitError, match="largest texture"):
        ss.discretize(scene, cam, backend="gpu")


def test_bad_backends_are_named():
    scene = ss.scenes.shapes(seed=0, detail=0)
    cam = ss.Camera.look_at((3, 2, 3), (0, 0, 0), yfov=0.8, width=16, height=16)
    with pytest.raises(ss.InputError, match="'auto', 'gpu', 'cpu'"):
        ss.discretize(scene, cam, backend="vulkan")
    with pytest.raises(ss.InputError, match="GPU only.*'conventional'"):
        ss.discretize(scene, method="impostors", backend="cpu")
    with pytest.raises(ss.InputError, match="triangles= and pixels="):
        ss.device_info(triangles=10)


# Run with every Vulkan driver hidden: the loader finds no ICD, so there is no adapter at all.
NO_VULKAN = textwrap.dedent(
    """
    import numpy as np, scenesample as ss
    scene = ss.scenes.shapes(seed=0, detail=1)
    cam = ss.Camera.look_at((3, 2, 3), (0, 0, 0), yfov=0.8, width=48, height=32)
    room, room_eye = ss.scenes.reflective_room(spheres=2, seed=0), ss.scenes.reflective_room_eye(16)
    points = ss.discretize(room, method="epr", eye=room_eye, resolution=16)  # CPU
    o, d = (a.reshape(-1, 3) for a in cam.pixel_rays())
    hits = ss.cast_rays(scene, o, d)
    assert (hits.triangle >= 0).any()
    assert ss.occluded(scene, o, d).any()
    images = ss.discretize(scene, cam)
    assert images.backend == "cpu" and "no GPU adapter" in images.backend_reason, images
    # Edge pixels follow the raster's fill rule, not the ray's.
    assert (images.triangle[0] == hits.triangle.reshape(32, 48)).mean() > 0.99
    layers = ss.discretize(scene, cam, "peeling", layers=2)
    assert layers.backend == "cpu" and (layers.triangle[1] >= 0).any(), layers
    for call in (
        lambda: ss.discretize(scene, cam, backend="gpu"),
        lambda: ss.discretize(scene, cam, "nonredundant"),
        lambda: ss.splat(points, resolution=16),
    ):
        try:
            call()
        except ss.GpuUnavailableError as e:
            assert "mesa-vulkan-drivers" in str(e), e
        else:
            raise AssertionError("no GpuUnavailableError")
    info = ss.device_info(triangles=5_000_000, pixels=1 << 20)
    assert not info["available"] and info["name"] is None, info
    assert "mesa-vulkan-drivers" in info["error"], info
    assert info["auto"]["backend"] == "cpu" and info["auto"]["gpu_seconds"] is None, info
    assert "no GPU adapter" in info["auto"]["reason"], info
    print("ok")
    """
)


def test_without_vulkan_the_cpu_paths_work(tmp_path):
    env = dict(os.environ, VK_ICD_FILENAMES=str(tmp_path / "none.json"))
    env["VK_DRIVER_FILES"] = env["VK_ICD_FILENAMES"]
    r = subprocess.run(
        [sys.executable, "-c", NO_VULKAN], capture_output=True, text=True, env=env, timeout=600
    )
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stdout + r.stderr


def test_plan_estimates_use_the_measured_rates(gpu):
    rates = ss._plan.rates(100_000)
    assert {"raster_triangles", "pixels", "rays"} <= set(rates["measured"])
    coefficients = ss.device_info(triangles=100_000, pixels=512 * 512)["auto"]["coefficients"]
    assert rates["raster_triangles"] == pytest.approx(1 / coefficients["gpu_per_triangle"])
    light = ss.AreaLight.above(ss.scenes.shapes(seed=0, detail=0), size=0.3, height=0.5)
    (effect,) = ss.plan(ss.scenes.shapes(seed=0, detail=0), area_lights=[light])
    # The cheaper way is run: ray tracing costs rays, Algorithm 5 rasterization.
    if effect.params["discretization"] == "raytraced":
        assert effect.estimate["measured_rates"] == ["rays"]
    else:
        assert "raster_triangles" in effect.estimate["measured_rates"]
        assert "shadow_triangles" not in effect.estimate["measured_rates"]


CALIBRATE = (
    "import json, scenesample as ss\n"
    "a = ss.device_info(triangles=100_000, pixels=512 * 512)['auto']\n"
    "print(json.dumps([a['calibration'], a['calibration_seconds'], a['coefficients']]))\n"
)


def calibrate(cache_dir: str, n: int = 1, **extra: str) -> list[list]:
    """`[source, probe seconds, coefficients]` of `n` fresh processes started at once."""
    env = dict(os.environ, SCENESAMPLE_CACHE_DIR=cache_dir, **extra)
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", CALIBRATE],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for _ in range(n)
    ]
    out = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=300)
        assert p.returncode == 0, stderr
        out.append(json.loads(stdout.strip().splitlines()[-1]))
    return out


def test_the_cost_model_is_measured_once_per_machine(tmp_path):
    """The first process runs the probes and writes the calibration file, then uses what the
    file holds; the next reads it (no probes, the same coefficients); a run with Vulkan hidden
    (another machine key) adds its own model beside it; a file that does not parse is measured
    anew."""
    path = tmp_path / "cost-model.json"
    [[source, seconds, first]] = calibrate(str(tmp_path))
    assert source == str(path) and seconds > 0
    assert all(k.startswith("scenesample ") for k in json.loads(path.read_text())["models"])
    [[source, seconds, again]] = calibrate(str(tmp_path))
    assert source == str(path) and seconds == 0 and again == first
    hidden = str(tmp_path / "none.json")
    [[source, _, cpu_only]] = calibrate(
        str(tmp_path), VK_ICD_FILENAMES=hidden, VK_DRIVER_FILES=hidden
    )
    assert source == str(path) and not any(k.startswith("gpu_") for k in cpu_only)
    assert len(json.loads(path.read_text())["models"]) == 2
    assert calibrate(str(tmp_path))[0][:2] == [str(path), 0]
    path.write_text("{not json")
    [[source, seconds, _]] = calibrate(str(tmp_path))
    assert source == str(path) and seconds > 0 and len(json.loads(path.read_text())["models"]) == 1


def test_processes_starting_together_share_one_model(tmp_path):
    """Three processes that need the model at once: one measures it under the file's lock, the
    others wait and read it, so all three decide alike."""
    runs = calibrate(str(tmp_path), n=3)
    assert {r[0] for r in runs} == {str(tmp_path / "cost-model.json")}
    assert sum(r[1] > 0 for r in runs) == 1, runs
    assert runs[0][2] == runs[1][2] == runs[2][2]


def test_without_a_calibration_file_auto_uses_the_builtin_model(tmp_path):
    """No file can be kept (switched off, or a cache directory that cannot be made): nothing is
    measured, and every process uses the same built-in coefficients."""
    off = calibrate("", n=2)
    assert all(r[0].startswith("built-in (SCENESAMPLE_CACHE_DIR is empty") for r in off), off
    assert off[0][1] == off[1][1] == 0 and off[0][2] == off[1][2]
    (tmp_path / "file").write_text("")
    [[source, seconds, coefficients]] = calibrate(str(tmp_path / "file" / "below"))
    assert source.startswith("built-in (no lock file") and seconds == 0, source
    assert coefficients == off[0][2]
