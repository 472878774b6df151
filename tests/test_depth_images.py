"""GPU depth images cross-validated against pyrender (raster) and embreex (ray casts), plus the
fields' internal consistency, precision far from the origin, limits and EXR round trips.

Reference settings: pyrender with back-face culling off (both windings) and single-sample
buffers, so it samples pixel centres like we do (see scenesample.references)."""

from __future__ import annotations

import numpy as np
import pytest
import scenesample as ss
from conftest import SHARED, load_quiet, orbit_cameras, silhouette
from scenesample.references import pyrender_depth

RTOL = 1e-3  # relative depth agreement required on >= 99.5% of pixels covered by both


def assert_matches_pyrender(scene: ss.Scene, cams: list, label: str) -> dict:
    pytest.importorskip("pyrender")
    ours = ss.discretize(scene, cams)
    ref = pyrender_depth(scene, cams)
    mine, theirs = np.isfinite(ours.depth), np.isfinite(ref)
    both = mine & theirs
    assert both.sum() > 0.01 * both.size, f"{label}: the cameras see almost nothing"
    rel = np.abs(ours.depth[both] - ref[both]) / ref[both]
    agree = float((rel <= RTOL).mean())
    assert agree >= 0.995, f"{label}: only {agree:.4%} of covered pixels agree to {RTOL}"
    differ = mine != theirs
    # Coverage may differ only on silhouettes (of either image: thin features can vanish in one).
    outside = differ & ~(silhouette(mine) | silhouette(theirs))
    assert outside.sum() == 0, (
        f"{label}: {outside.sum()} coverage differences away from silhouettes"
    )
    return {"agree": agree, "coverage_diff": int(differ.sum())}


def test_procedural_scene_matches_pyrender(gpu) -> None:
    s = ss.scenes.shapes(seed=1)
    assert_matches_pyrender(s, orbit_cameras(s, 3, 320, 240, seed=1), "shapes")


def test_translated_scene_matches_pyrender_and_itself(gpu) -> None:
    offset = np.array([1e5, -3e4, 1e5])
    near = ss.scenes.shapes(seed=1)
    far = ss.scenes.shapes(seed=1, offset=offset)
    cams = orbit_cameras(far, 3, 320, 240, seed=1)
    assert_matches_pyrender(far, cams, "shapes + 1e5")
    # Translation invariance: the same views of the untranslated scene give the same depths up to
    # the rounding of float32 vertices at 1e5 (ulp 0.008; scene depths ~15).
    moved = []
    for c in cams:
        pose = np.array(c.pose)
        pose[:3, 3] -= offset
        moved.append(ss.Camera.from_pose(pose, yfov=c.yfov, width=c.width, height=c.height))
    a, b = ss.discretize(far, cams), ss.discretize(near, moved)
    both = a.mask & b.mask
    # Vertex rounding moves edges by up to ~10% of a pixel footprint here: ids differ only there.
    assert (a.triangle[both] == b.triangle[both]).mean() > 0.98
    rel = np.abs(a.depth[both] - b.depth[both]) / b.depth[both]
    assert np.median(rel) < 1e-5 and np.quantile(rel, 0.995) < 1e-3


@pytest.mark.slow
@pytest.mark.skipif(not SHARED, reason="../shared/scenes is absent")
@pytest.mark.parametrize("name", sorted(SHARED))
def test_shared_scene_matches_pyrender(gpu, name) -> None:
    s = load_quiet(SHARED[name])
    assert_matches_pyrender(s, orbit_cameras(s, 2, 256, 192, seed=3), name)


def test_triangle_ids_match_embree_through_trimesh(gpu) -> None:
    trimesh = pytest.importorskip("trimesh")
    pytest.importorskip("embreex")
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    s = ss.scenes.shapes(seed=2)
    cams = orbit_cameras(s, 2, 256, 192, seed=2)
    img = ss.discretize(s, cams)
    mesh = trimesh.Trimesh(s.vertices, s.faces, process=False)
    embree = RayMeshIntersector(mesh)
    for i, cam in enumerate(cams):
        origins, dirs = cam.pixel_rays()
        ref = embree.intersects_first(origins.reshape(-1, 3), dirs.reshape(-1, 3)).reshape(
            img.height, img.width
        )
        covered = img.triangle[i] >= 0
        same = img.triangle[i] == ref
        assert same[covered].mean() >= 0.995
        # Every disagreement is at a pixel centre within a pixel's footprint of a triangle edge.
        bad = np.argwhere(covered & ~same)
        hits = ss.cast_rays(s, origins[bad[:, 0], bad[:, 1]], dirs[bad[:, 0], bad[:, 1]])
        footprint = img.depth[i][bad[:, 0], bad[:, 1]] * 2 * np.tan(cam.yfov / 2) / cam.height
        assert (edge_distance(s, hits) <= footprint).all()


def edge_distance(s: ss.Scene, hits: ss.RayHits) -> np.ndarray:
    """World distance from each hit point to the nearest edge of its triangle."""
    v = s.vertices.astype(np.float64)[s.faces[hits.triangle].astype(int)]
    u, w = hits.barycentric[:, 0].astype(np.float64), hits.barycentric[:, 1].astype(np.float64)
    bary = np.stack([1 - u - w, u, w], -1)
    area2 = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=-1)
    # Barycentric i times the height over the edge opposite vertex i.
    opposite = [np.linalg.norm(v[:, (k + 2) % 3] - v[:, (k + 1) % 3], axis=-1) for k in range(3)]
    return np.min([bary[:, k] * area2 / opposite[k] for k in range(3)], axis=0)


def test_fields_are_consistent_with_the_bvh_and_the_camera(gpu) -> None:
    s = ss.scenes.shapes(seed=4)
    cam = orbit_cameras(s, 1, 200, 150, seed=4)[0]
    img = ss.discretize(s, cam)
    assert img.depth.shape == (1, 150, 200) and img.depth.dtype == np.float32
    assert img.triangle.dtype == np.int32 and img.normal.shape == (1, 150, 200, 3)
    m = img.mask[0]
    assert np.isposinf(img.depth[0][~m]).all() and (img.triangle[0][~m] == -1).all()
    assert np.isnan(img.position[0][~m]).all() and (img.normal[0][~m] == 0).all()
    # Depth is the t of an unnormalised pixel ray (camera-space z of the direction is -1).
    origins, dirs = cam.pixel_rays(normalize=False)
    hits = ss.cast_rays(s, origins.reshape(-1, 3), dirs.reshape(-1, 3))
    t = hits.t.reshape(150, 200)
    same = m & (hits.triangle.reshape(150, 200) == img.triangle[0])
    assert same.sum() > 0.99 * m.sum()
    np.testing.assert_allclose(img.depth[0][same], t[same], rtol=1e-5)
    # Position is the unprojected depth; normal is the unit face normal; colour the vertex colour.
    ys, xs = np.nonzero(m)
    world = cam.unproject(
        np.stack([xs + 0.5, ys + 0.5], -1), img.depth[0][ys, xs].astype(np.float64)
    )
    np.testing.assert_allclose(img.position[0][ys, xs], world, atol=1e-4)
    tri = img.triangle[0][ys, xs]
    v = s.vertices[s.faces[tri].astype(int)].astype(np.float64)
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(img.normal[0][ys, xs], n, atol=1e-6)
    np.testing.assert_allclose(img.color[0][ys, xs], s.colors[s.faces[tri, 0]], atol=1e-6)


def test_far_from_origin_with_near_far_ratio_1e6(gpu) -> None:
    """Depth and position stay precise 1e5 from the origin with znear/zfar = 1e-6."""
    offset = np.array([1e5, 1e5, -1e5])
    s = ss.scenes.shapes(seed=5, offset=offset)
    base = orbit_cameras(s, 1, 160, 120, seed=5)[0]
    cam = ss.Camera.from_pose(
        base.pose, yfov=base.yfov, width=160, height=120, znear=1e-3, zfar=1e3
    )
    img = ss.discretize(s, cam)
    origins, dirs = cam.pixel_rays(normalize=False)
    hits = ss.cast_rays(s, origins.reshape(-1, 3), dirs.reshape(-1, 3))
    same = img.mask[0].ravel() & (hits.triangle == img.triangle[0].ravel())
    assert same.sum() > 0.99 * img.mask.sum() > 0
    # Ray origins are float32 at 1e5 (ulp 0.008), so the BVH is the less precise side here.
    rel = np.abs(img.depth[0].ravel()[same] - hits.t[same]) / hits.t[same]
    assert np.quantile(rel, 0.99) < 1e-3


def test_many_cameras_are_split_into_chunks_and_agree(gpu) -> None:
    s = ss.scenes.shapes(seed=6, detail=1)
    # Chunks hold about a million pixels (4 views of 512^2): 44 views make 11 chunks.
    cams = orbit_cameras(s, 44, 512, 512, seed=6)
    all_at_once = ss.discretize(s, cams)
    one = ss.discretize(s, cams[40])
    np.testing.assert_array_equal(all_at_once.depth[40], one.depth[0])
    np.testing.assert_array_equal(all_at_once.triangle[40], one.triangle[0])
    assert len(all_at_once.cameras) == 44 and all_at_once.cameras[40] == cams[40]


def test_backface_culling_is_off_by_default(gpu) -> None:
    s = ss.scenes.icosphere(2)
    inside = ss.Camera.look_at([0, 0, 0], [0, 0, -1], yfov=1.0, width=32, height=32)
    assert ss.discretize(s, inside).mask.all()
    assert not ss.discretize(s, inside, cull_backfaces=True).mask.any()
    outside = ss.Camera.look_at([0, 0, 4], [0, 0, 0], yfov=1.0, width=32, height=32)
    a, b = ss.discretize(s, outside), ss.discretize(s, outside, cull_backfaces=True)
    np.testing.assert_array_equal(a.triangle, b.triangle)


def test_degenerate_triangles_never_produce_nan(gpu) -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=np.float32)
    s = ss.Scene.from_arrays(v, [[0, 1, 2], [0, 1, 3], [1, 4, 3], [3, 3, 3]])
    img = ss.discretize(
        s, ss.Camera.look_at([0.5, 0.5, 2], [0.5, 0.5, 0], yfov=1.0, width=64, height=64)
    )
    m = img.mask
    assert m.any() and np.isfinite(img.depth[m]).all() and np.isfinite(img.normal[m]).all()
    assert np.isfinite(img.position[m]).all() and not np.isin(img.triangle[m], [0, 3]).any()


def test_orthographic_camera(gpu) -> None:
    s = ss.Scene.from_arrays(
        [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]]
    )
    pose = np.eye(4)
    pose[2, 3] = 5
    cam = ss.Camera.orthographic(pose, xmag=2, ymag=2, width=40, height=40, znear=0.1, zfar=10)
    img = ss.discretize(s, cam)
    assert img.mask.sum() == 20 * 20
    np.testing.assert_allclose(img.depth[img.mask], 5.0)


def test_timings_are_reported(gpu) -> None:
    s = ss.scenes.shapes(seed=7, detail=1)
    img = ss.discretize(s, orbit_cameras(s, 2, 64, 48), backend="gpu")
    for key in ("device", "upload", "prepare", "raster", "readback", "resolve", "total"):
        assert img.timings[key] >= 0
    cpu = ss.discretize(s, orbit_cameras(s, 2, 64, 48), backend="cpu")
    assert set(cpu.timings) == {"bvh", "trace", "edges", "resolve", "total"}
    # Durations are only checked to be there: how long they are is the machine's business.
    if gpu["timestamps"]:
        assert img.timings["raster_gpu"] >= 0
    assert set(img.as_dict()) == {
        "depth",
        "triangle",
        "normal",
        "shading_normal",
        "position",
        "color",
        "cameras",
        "timings",
        "method",
        "reference",
        "cull_backfaces",
        "backend",
        "backend_reason",
    }


def test_exr_round_trip_is_bit_exact(gpu, tmp_path) -> None:
    s = ss.scenes.shapes(seed=8, detail=1, offset=(1e5, 0, 0))
    img = ss.discretize(s, orbit_cameras(s, 3, 64, 48, seed=8))
    img.save_exr(tmp_path / "views.exr")
    back = ss.DepthImages.load_exr(tmp_path / "views.exr")
    for name in ("depth", "triangle", "normal", "shading_normal", "position", "color"):
        a, b = getattr(img, name), getattr(back, name)
        assert a.dtype == b.dtype and a.shape == b.shape
        np.testing.assert_array_equal(a.view(np.uint32), b.view(np.uint32), err_msg=name)
    assert back.cameras == img.cameras


def test_bad_requests_raise_typed_errors(gpu, tmp_path) -> None:
    s = ss.scenes.icosphere(1)
    a = ss.Camera.look_at([0, 0, 3], [0, 0, 0], yfov=1, width=8, height=8)
    b = a.with_resolution(9, 8)
    with pytest.raises(ss.InputError, match="camera 1 is 9x8"):
        ss.discretize(s, [a, b])
    with pytest.raises(ss.InputError, match="at least one camera"):
        ss.discretize(s, [])
    with pytest.raises(ss.InputError, match="method must be one of"):
        ss.discretize(s, a, method="magic")
    with pytest.raises(ss.InputError, match="scenesample.Scene"):
        ss.discretize("scene", a)  # type: ignore[arg-type]
    huge = a.with_resolution(gpu["max_texture_dimension_2d"] + 1, 8)
    with pytest.raises(ss.GpuLimitError, match="exceed this device's largest texture"):
        ss.discretize(s, huge, backend="gpu")
    with pytest.raises(ss.ExrError):
        ss.DepthImages.load_exr(tmp_path / "absent.exr")
    (tmp_path / "junk.exr").write_bytes(b"not an exr at all")
    with pytest.raises(ss.ExrError):
        ss.DepthImages.load_exr(tmp_path / "junk.exr")
    # The device survives all of the above.
    assert ss.discretize(s, a).mask.any()


def test_the_pyrender_shim_restores_numpy_infty() -> None:
    """pyrender reads ``np.infty`` (removed in numpy 2), e.g. for the bounds of a mesh without
    primitives; importing it through the references module puts the alias back."""
    pytest.importorskip("pyrender")
    from scenesample import references

    references._import_pyrender()
    assert getattr(np, "infty") == np.inf  # noqa: B009
