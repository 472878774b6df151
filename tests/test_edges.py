"""Numbers at the edges of what users do: a camera inside a closed mesh, a near plane through
the geometry, triangles a million times smaller than the scene next to ones ten thousand times
larger, and more than 2^24 triangles (where float32 ids and counts would break). Each case
checks finite outputs against an exact answer, never just "no exception"."""

from __future__ import annotations

import numpy as np
import pytest
import scenesample as ss


def pixel_hits(scene, cam, **kw):
    """cast_rays at the pixel centres along camera-z directions: t is depth."""
    o, d = cam.pixel_rays(normalize=False)
    return ss.cast_rays(scene, o.reshape(-1, 3), d.reshape(-1, 3), **kw)


def test_a_camera_inside_a_closed_mesh_sees_its_inside_everywhere(gpu):
    """From the centre of a closed icosphere every pixel sees the sphere from inside: one
    layer (peeling finds nothing behind it), depth equal to the ray cast's, and a non-redundant
    second view from the same point adds nothing."""
    ball = ss.scenes.icosphere(4, radius=2.0)
    cam = ss.Camera.look_at((0.1, 0.05, 0.0), (1, 0.3, 0.2), (0, 0, 1), yfov=1.4, width=64,
                            height=48)  # fmt: skip
    img = ss.discretize(ball, cam)
    assert img.mask.all() and np.isfinite(img.depth).all() and (img.depth > 0).all()
    hits = pixel_hits(ball, cam)
    same = hits.triangle == img.triangle.ravel()
    assert same.mean() >= 0.99
    np.testing.assert_allclose(img.depth.ravel()[same], hits.t[same], rtol=1e-5)
    # The normals point outwards (winding), away from the eye inside.
    assert (np.einsum("hwk,hwk->hw", img.normal[0], img.position[0] - cam.eye) > 0).all()
    peel = ss.discretize(ball, [cam], "peeling", layers=2, camera=cam)
    assert peel.mask[0].all() and not peel.mask[1].any()
    twice = ss.discretize(ball, [cam, cam], "nonredundant")
    assert not twice.mask[1].any()


def test_a_near_plane_through_the_geometry_shows_what_lies_beyond_it(gpu):
    """A znear that cuts the scene: the image holds, at each pixel, the nearest surface at or
    beyond the near plane, exactly what cast_rays gives with t_min = znear along camera-z
    directions. Nothing nearer than znear appears, and nothing is NaN."""
    scene = ss.scenes.shapes(seed=3, detail=2)
    lo, hi = scene.bounds
    centre = (lo + hi) / 2
    eye = centre + np.array([0.0, -1.2, 0.3]) * np.linalg.norm(hi - lo)
    dist = np.linalg.norm(centre - eye)
    cam = ss.Camera.look_at(eye, centre, (0, 0, 1), yfov=0.8, width=96, height=72,
                            znear=dist * 0.95, zfar=dist * 3)  # fmt: skip
    img = ss.discretize(scene, cam)
    assert not np.isnan(img.depth).any()
    assert (img.depth[img.mask] >= cam.znear * (1 - 1e-6)).all()
    hits = pixel_hits(scene, cam, t_min=cam.znear)
    full = pixel_hits(scene, cam)
    # The cut is real: some pixels see past a nearer surface.
    assert ((full.t < cam.znear) & (hits.t > cam.znear)).sum() > 50
    covered = img.mask.ravel() | hits.hit
    agree = (img.triangle.ravel() == hits.triangle) & covered
    assert agree.sum() >= 0.99 * covered.sum()
    np.testing.assert_allclose(img.depth.ravel()[agree], hits.t[agree], rtol=1e-5)


def test_tiny_triangles_beside_huge_ones_are_hit_exactly():
    """Triangles 1e-6 of the scene's diagonal beside ones 1e4 times larger: rays aimed at the
    tiny ones' centroids hit them (watertight; never through the fan they form), with t within
    1e-6 relative of the exact float64 distance. In images such triangles are far below a
    pixel's footprint and show only where they cover a pixel centre."""
    rng = np.random.default_rng(0)
    diag_scale = 1000.0
    big = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) * diag_scale * 0.01
    # Fans of 6 tiny triangles around points spread over a 1000-unit box, at height 1.
    s = diag_scale * 1e-6 * np.sqrt(3)
    centres = rng.uniform(-diag_scale / 2, diag_scale / 2, (200, 3)) * [1, 1, 0] + [0, 0, 1]
    verts = [big]
    faces = [np.array([[0, 1, 2], [0, 2, 3]])]
    n = 4
    ring = np.array([[np.cos(a), np.sin(a), 0] for a in np.arange(6) * np.pi / 3]) * s
    for c in centres:
        verts.append(np.vstack([c, c + ring]))
        faces.append(np.array([[0, 1 + k, 1 + (k + 1) % 6] for k in range(6)]) + n)
        n += 7
    verts.append(np.array([[-500, -500, -10], [500, -500, -10], [0, 500, -10]]))
    faces.append(np.array([[0, 1, 2]]) + n)
    v = np.concatenate(verts).astype(np.float32)
    scene = ss.Scene.from_arrays(v, np.concatenate(faces))
    tiny = np.concatenate(faces)[2:-1]
    corners = v.astype(np.float64)[tiny]
    target = corners.mean(axis=1)
    origin = target + [0.3, -0.2, 50.0]
    d = (target - origin).astype(np.float32)
    hits = ss.cast_rays(scene, origin.astype(np.float32), d)
    assert (hits.triangle == np.arange(2, 2 + len(tiny))).all()
    # The fans lie in the plane z = 1: the exact parameter of the float32 ray there.
    exact = (1.0 - origin.astype(np.float32)[:, 2].astype(np.float64)) / d[:, 2]
    np.testing.assert_allclose(hits.t, exact, rtol=1e-6)
    # The fans' centres: every ray hits one of the six triangles meeting there.
    at_centre = np.array([c for c in v[4:-3:7]], dtype=np.float64)
    o2 = (at_centre + [0.01, 0.02, 30.0]).astype(np.float32)
    h2 = ss.cast_rays(scene, o2, (at_centre - o2).astype(np.float32))
    assert h2.hit.all() and (h2.triangle >= 2).all() and (h2.triangle < 2 + len(tiny)).all()


@pytest.mark.slow
def test_more_than_2_to_the_24_triangles_keep_exact_ids(gpu):
    """2^24 + 1 triangles: ids and counts past float32's exact integers stay exact. A
    4096 x 2048 grid of quads (2^24 triangles) lies behind one more triangle, id 2^24, which
    the image and the ray cast both report at the image centre, and the ray aimed at the
    grid's last triangle reports 2^24 - 1."""
    nx, ny = 4096, 2048
    xs = np.linspace(-1, 1, nx + 1, dtype=np.float32)
    ys = np.linspace(-1, 1, ny + 1, dtype=np.float32)
    gx, gy = np.meshgrid(xs, ys)
    grid = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size, np.float32)], -1)
    idx = np.arange((nx + 1) * (ny + 1), dtype=np.uint32).reshape(ny + 1, nx + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.empty((2 * nx * ny + 1, 3), dtype=np.uint32)
    faces[0:-1:2] = np.stack([a, b, c], -1)
    faces[1:-1:2] = np.stack([a, c, d], -1)
    del a, b, c, d
    n = len(grid)
    front = np.array([[-0.1, -0.1, 0.5], [0.1, -0.1, 0.5], [0.0, 0.1, 0.5]], dtype=np.float32)
    faces[-1] = [n, n + 1, n + 2]
    scene = ss.Scene.from_arrays(np.concatenate([grid, front]), faces)
    assert scene.triangle_count == 2**24 + 1
    cam = ss.Camera.look_at((0, 0, 3), (0, 0, 0), (0, 1, 0), yfov=0.5, width=33, height=33)
    img = ss.discretize(scene, cam)
    assert img.triangle[0, 16, 16] == 2**24
    hits = pixel_hits(scene, cam)
    assert hits.triangle[16 * 33 + 16] == 2**24
    # Inside the grid's last triangle (a, c, d of the last quad), off its diagonal.
    c = grid[idx[-1, -1]].astype(np.float64)
    last = c + 0.2 * (grid[idx[-1, -2]] - c) + 0.05 * (grid[idx[-2, -1]] - c)
    ray = ss.cast_rays(scene, (last + [0, 0, 1]).astype(np.float32)[None],
                       np.array([[0, 0, -1]], np.float32))  # fmt: skip
    assert ray.triangle[0] == 2**24 - 1
    assert ss.bvh_stats(scene)["triangles"] == 2**24 + 1
