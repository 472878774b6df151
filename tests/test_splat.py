"""EPR points and splatting (eye-based-point-rendering.txt §3): the splat pass against a numpy
model of the same definition, order independence, and the point generator's determinism,
coverage and bounds in hard cases."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scenesample as ss


def _square_corners(points: ss.Points, scene: ss.Scene, i: int) -> np.ndarray:
    """The four world corners of point i's square (along its triangle's longest edge)."""
    p = np.asarray(scene.vertices, dtype=np.float64)[np.asarray(scene.faces)[points.triangle[i]]]
    edges = [p[1] - p[0], p[2] - p[1], p[0] - p[2]]
    along = max(edges, key=lambda e: float(e @ e))
    n = np.cross(edges[0], -edges[2])
    u = along / np.linalg.norm(along)
    v = np.cross(n / np.linalg.norm(n), u)
    h = points.length[i] / 2
    c = points.center[i].astype(np.float64)
    return np.array([c + su * u + sv * v for su in (-h, h) for sv in (-h, h)])


def _expected_pixels(points, scene, cam, i, clip):
    """Pixels (row, col) the splat of point i must fill: those whose unit square overlaps the
    bounding box of the projected square and, with clip, the projected triangle."""
    xy, _ = cam.project(_square_corners(points, scene, i))
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    x0, y0 = max(int(np.floor(lo[0])), 0), max(int(np.floor(lo[1])), 0)
    x1 = min(int(np.ceil(hi[0])), cam.width) - 1
    y1 = min(int(np.ceil(hi[1])), cam.height) - 1
    tri, _ = cam.project(
        np.asarray(scene.vertices, dtype=np.float64)[np.asarray(scene.faces)[points.triangle[i]]]
    )
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    if e1[0] * e2[1] - e1[1] * e2[0] < 0:
        tri = tri[[0, 2, 1]]
    out = set()
    for y in range(y0, y1 + 1):
        for x in range(x0, x1 + 1):
            if clip:
                ok = True
                for k in range(3):
                    a, b = tri[k], tri[(k + 1) % 3]
                    inward = np.array([a[1] - b[1], b[0] - a[0]])
                    corner = np.array([x + (inward[0] > 0), y + (inward[1] > 0)], dtype=float)
                    if (b[0] - a[0]) * (corner[1] - a[1]) - (b[1] - a[1]) * (corner[0] - a[0]) < 0:
                        ok = False
                if not ok:
                    continue
            out.add((y, x))
    return out


@pytest.fixture
def tilted():
    """One large tilted triangle and a camera looking at it obliquely."""
    scene = ss.Scene.from_arrays([[-1, -1, 0], [1.2, -0.8, 0.3], [-0.2, 1, -0.2]], [[0, 1, 2]])
    cam = ss.Camera.look_at((0.3, -0.4, 2.5), (0, 0, 0), (0, 1, 0), yfov=0.9, width=40, height=30)
    return scene, cam


@pytest.mark.parametrize("clip", [True, False])
def test_one_point_fills_exactly_its_box_inside_its_triangle(gpu, tilted, clip):
    scene, cam = tilted
    # Near a corner of the triangle, so that the clip matters.
    centers = [[-0.85, -0.85, 0.0], [0.1, 0.0, 0.0]]
    for c in centers:
        pts = ss.Points.from_arrays(scene, [c], [0.35], [0], cameras=[cam])
        b = ss.splat(pts, clip_to_triangle=clip)
        got = {tuple(p) for p in np.argwhere(b.index[0] == 0)}
        want = _expected_pixels(pts, scene, cam, 0, clip)
        # Pixel-boundary ties (f32 on the GPU, f64 here) may differ by a pixel or two.
        assert len(got ^ want) <= 2, (c, sorted(got ^ want))
        assert len(want) > 4
        depth = float(np.dot(np.asarray(c) - np.asarray(cam.eye), cam.forward))
        assert np.allclose(b.depth[0][b.index[0] == 0], depth, rtol=1e-5)
        assert (b.packed[0][b.index[0] < 0] == np.iinfo(np.uint64).max).all()


def test_overlapping_points_resolve_to_the_nearer_in_any_order(gpu):
    scene = ss.Scene.from_arrays(
        [[-1, -1, 0], [1, -1, 0], [0, 1, 0], [-1, -1, 0.5], [1, -1, 0.5], [0, 1, 0.5]],
        [[0, 1, 2], [3, 4, 5]],
    )
    cam = ss.Camera.look_at((0, 0, 3), (0, 0, 0), (0, 1, 0), yfov=0.8, width=32, height=32)
    centers = np.array([[0, 0, 0], [0.05, 0, 0.5], [0, 0.05, 0]], dtype=np.float32)
    tris = np.array([0, 1, 0])
    lengths = np.array([0.6, 0.4, 0.6], dtype=np.float32)
    a = ss.splat(ss.Points.from_arrays(scene, centers, lengths, tris, cameras=[cam]))
    # The nearer point (index 1, z = 0.5) wins wherever it lands.
    near = a.index[0] == 1
    assert near.sum() > 4
    assert np.allclose(a.depth[0][near], 2.5)
    # Reordered points give the same buffers up to the renumbering.
    order = np.array([2, 1, 0])
    b = ss.splat(
        ss.Points.from_arrays(scene, centers[order], lengths[order], tris[order], cameras=[cam])
    )
    renumber = np.array([-1, 2, 1, 0])  # index in b -> index in a (-1 stays -1)
    assert np.array_equal(b.depth, a.depth)
    mapped = renumber[b.index + 1]
    # Points 0 and 2 lie at the same depth: ties go to the lower index, which reordering swaps.
    same = (a.index == 1) | (a.index == -1)
    assert np.array_equal(mapped[same], a.index[same])


def test_splat_is_independent_of_run_and_fills_many_views(gpu):
    scene = ss.scenes.turtles()
    eye = ss.Camera.look_at((0, -4, 2), (0, 0, 0), (0, 0, 1), yfov=0.8, width=96, height=96)
    pts = ss.discretize(
        scene, method="epr", eye=eye, reflectors=[((0, 0, 0.3), 0.3)], resolution=32
    )
    a = ss.splat(pts)
    b = ss.splat(pts)
    assert a.index.shape == (6, 32, 32)
    # The cube around the turtles sees them and the ground on a good share of its texels.
    assert (a.index >= 0).mean() > 0.3
    assert np.array_equal(a.packed, b.packed)


def test_epr_points_are_deterministic_and_seed_dependent(gpu):
    scene = ss.scenes.grass(blades=300)
    eye = ss.scenes.reference_cameras(scene, 128)[0]
    refl = [((0.0, 0.0, 0.3), 0.15)]
    a = ss.discretize(scene, method="epr", eye=eye, reflectors=refl, seed=3)
    b = ss.discretize(scene, method="epr", eye=eye, reflectors=refl, seed=3)
    for k in ("center", "length", "triangle", "normal", "material", "views"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert a.stats == b.stats
    c = ss.discretize(scene, method="epr", eye=eye, reflectors=refl, seed=4, rho_scale=0.05)
    d = ss.discretize(scene, method="epr", eye=eye, reflectors=refl, seed=3, rho_scale=0.05)
    # At a low density many blades are sub-1/10-cell and culled stochastically: seeds differ.
    assert c.stats["triangles_culled"] > 0
    assert not np.array_equal(c.triangle, d.triangle)


def test_epr_needs_far_fewer_points_than_ivir(gpu):
    """EPR samples at the eye's resolution via the reflector, iVIR at the cube map's."""
    scene = ss.scenes.urban()
    eye = ss.scenes.reference_cameras(scene, 256)[0]
    refl = [((0.0, 0.0, 0.5), 0.1)]
    epr = ss.discretize(scene, method="epr", eye=eye, reflectors=refl, resolution=128)
    ivir = ss.discretize(scene, method="ivir", eye=eye, reflectors=refl, resolution=128)
    assert len(ivir) > 3 * len(epr) > 0


def test_epr_splat_covers_the_cube_map_like_rasterization(gpu):
    """Splatting EPR points fills every texel a conventional render of the same cube faces
    covers, with a surface at the rasterized depth up to the splat's size: each point covers
    several texels at one depth (its centre's), and near silhouettes a nearer splat overhangs."""
    scene = ss.scenes.urban()
    eye = ss.scenes.reference_cameras(scene, 256)[0]
    refl = [((0.0, 0.0, 0.6), 0.1)]
    pts = ss.discretize(scene, method="epr", eye=eye, reflectors=refl, resolution=256)
    b = ss.splat(pts)
    ref = ss.discretize(scene, pts.cameras)
    covered = np.isfinite(ref.depth)
    holes = covered & (b.index < 0)
    assert holes.sum() <= 0.001 * covered.sum(), holes.sum() / covered.sum()
    both = covered & (b.index >= 0)
    size = pts.length[b.index[both]] + pts.cameras[0].pixel_footprint(1.0) * ref.depth[both]
    close = np.abs(b.depth[both] - ref.depth[both]) <= 2 * size
    assert close.mean() >= 0.9, close.mean()


def test_hard_cases_stay_finite_and_bounded(gpu):
    """The eye inside a reflector's sphere, and a reflector touching the geometry: finite
    lengths, bounded point counts."""
    scene = ss.scenes.grass(blades=200)
    eye = ss.Camera.look_at((0, 0, 0.3), (0, 1, 0.3), (0, 0, 1), yfov=0.9, width=64, height=64)
    for refl in ([((0, 0, 0.3), 0.5)], [((0, 0, 0.0), 0.2)]):
        pts = ss.discretize(scene, method="epr", eye=eye, reflectors=refl, resolution=32)
        assert np.isfinite(pts.center).all() and np.isfinite(pts.length).all()
        assert (pts.length > 0).all()
        # The documented per-triangle cap (MAX_PER_TRIANGLE cells, plus the cells the
        # triangle's edges cross) holds even where the density formula runs away.
        assert np.bincount(pts.triangle).max() <= 2 * 65536
        assert pts.stats["points"] == len(pts)


def test_bad_input_raises_typed_errors(gpu, tilted):
    scene, cam = tilted
    pts = ss.Points.from_arrays(scene, [[0, 0, 0]], [0.3], [0], cameras=[cam])
    other = cam.with_resolution(20, 20)
    with pytest.raises(ss.InputError, match="one resolution"):
        ss.splat(pts, [cam, other])
    with pytest.raises(ss.InputError, match="visibility words"):
        ss.splat(pts, [cam] * 65)
    with pytest.raises(ss.InputError, match=r"triangle\[0\] is 5: the scene has 1 triangles"):
        ss.Points.from_arrays(scene, [[0, 0, 0]], [0.3], [5], cameras=[cam])
    bad = dataclasses.replace(pts, triangle=np.array([5], np.int32))
    with pytest.raises(ss.InputError, match="triangle 5"):
        ss.splat(bad)
    nan = ss.Points.from_arrays(scene, [[np.nan, 0, 0]], [0.3], [0], cameras=[cam])
    with pytest.raises(ss.InputError, match="non-finite"):
        ss.splat(nan)
    with pytest.raises(ss.InputError, match="eye="):
        ss.discretize(scene, method="epr")
    with pytest.raises(ss.InputError, match="reflective object"):
        ss.discretize(scene, method="epr", eye=cam)
    with pytest.raises(ss.InputError, match="rho_scale"):
        ss.discretize(scene, method="epr", eye=cam, reflectors=[((0, 0, 0), 0.5)], rho_scale=0)


def test_points_beyond_one_texture_chunk_splat_like_their_halves(gpu):
    """2.3M points: more than one chunk of the point geometry on lavapipe (2M points per 128 MiB
    binding). The buffers equal the nearest of splatting each half alone, the second half's
    indices shifted: chunking changes nothing."""
    scene = ss.Scene.from_arrays(
        [[-1, -1, 0], [1, -1, 0], [0, 1, 0], [-1, -1, 0.5], [1, -1, 0.5], [0, 1, 0.5]],
        [[0, 1, 2], [3, 4, 5]],
    )
    # Oblique, so that depths differ from point to point (no ties broken by index alone).
    cam = ss.Camera.look_at((1.2, -0.9, 2.6), (0, 0, 0.2), (0, 1, 0), yfov=0.8, width=96, height=96)
    rng = np.random.default_rng(7)
    n = 2_300_000
    tris = rng.integers(0, 2, n)
    # Uniform points in the triangle (barycentric), on its plane.
    r1, r2 = rng.random(n), rng.random(n)
    flip = r1 + r2 > 1
    r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
    v = scene.vertices[scene.faces[tris]].astype(np.float64)
    centers = v[:, 0] + r1[:, None] * (v[:, 1] - v[:, 0]) + r2[:, None] * (v[:, 2] - v[:, 0])
    lengths = rng.uniform(0.005, 0.03, n).astype(np.float32)

    def splat(sl):
        return ss.splat(
            ss.Points.from_arrays(scene, centers[sl], lengths[sl], tris[sl], cameras=[cam])
        ).packed

    whole = splat(slice(None))
    half = n // 2
    a, b = splat(slice(0, half)), splat(slice(half, None))
    empty = np.iinfo(np.uint64).max
    b = np.where(b == empty, b, b + np.uint64(half))
    # The last points (the second chunk's) win pixels, so losing them would show.
    late = (whole != empty) & ((whole & np.uint64(0xFFFFFFFF)) >= 2_100_000)
    assert late.sum() > 10, late.sum()
    assert np.array_equal(whole, np.minimum(a, b))
    assert (whole != empty).mean() > 0.3
