"""Camera: construction, projection round trips, pixel rays, cube faces, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import scenesample as ss


def test_project_unproject_round_trip() -> None:
    cam = ss.Camera.look_at([3.0, 2.0, 5.0], [0.0, 0.5, 0.0], yfov=0.9, width=320, height=200)
    pts = np.random.default_rng(0).uniform(-1, 1, size=(500, 3))
    px, depth = cam.project(pts)
    assert px.shape == (500, 2) and depth.shape == (500,) and px.dtype == np.float64
    back = cam.unproject(px, depth)
    np.testing.assert_allclose(back, pts, atol=1e-12)


def test_conventions_row_zero_on_top_pixel_centres_at_half() -> None:
    cam = ss.Camera.look_at([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], yfov=np.pi / 2, width=4, height=4)
    (centre, above, right), depth = cam.project(np.array([[0.0, 0, 0], [0, 1, 0], [1, 0, 0]]))
    np.testing.assert_allclose(centre, [2.0, 2.0])
    assert above[1] < 2.0 and right[0] > 2.0
    assert depth[0] == pytest.approx(5.0)
    origins, dirs = cam.pixel_rays()
    assert origins.shape == (4, 4, 3) and dirs.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, rtol=1e-6)
    # Pixel (row 0, col 0) centre is at ndc (-0.75, +0.75): up and to the left.
    d = dirs[0, 0]
    assert d[0] < 0 and d[1] > 0 and d[2] < 0


def test_pixel_rays_unnormalised_give_t_equal_depth() -> None:
    cam = ss.Camera.look_at([1.0, 2.0, 3.0], [0.0, 0.0, 0.0], yfov=1.1, width=8, height=6)
    origins, dirs = cam.pixel_rays(normalize=False)
    pts = origins + 2.5 * dirs
    px, depth = cam.project(pts.reshape(-1, 3).astype(np.float64))
    np.testing.assert_allclose(depth, 2.5, rtol=1e-6)
    ys, xs = np.mgrid[0:6, 0:8] + 0.5
    np.testing.assert_allclose(px, np.stack([xs.ravel(), ys.ravel()], -1), atol=1e-4)


def test_pose_is_row_major_camera_to_world() -> None:
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 2.0, 3.0]
    cam = ss.Camera.from_pose(pose, yfov=1.0, width=10, height=10)
    np.testing.assert_array_equal(cam.pose, pose)
    assert cam.eye == [1.0, 2.0, 3.0] and cam.forward == [0.0, 0.0, -1.0]


def test_orthographic_projection() -> None:
    cam = ss.Camera.orthographic(
        np.eye(4), xmag=2.0, ymag=1.0, width=40, height=20, znear=0.1, zfar=10
    )
    px, depth = cam.project(np.array([[2.0, 1.0, -3.0]]))
    np.testing.assert_allclose(px, [[40.0, 0.0]])
    assert depth[0] == pytest.approx(3.0)
    origins, dirs = cam.pixel_rays()
    np.testing.assert_allclose(dirs.reshape(-1, 3), np.tile([0, 0, -1.0], (800, 1)))
    assert np.ptp(origins[..., 0]) > 3.5


def test_cube_faces_in_gl_order_cover_every_direction() -> None:
    faces = ss.Camera.cube([1.0, 2.0, 3.0], 16)
    assert len(faces) == 6
    np.testing.assert_allclose(
        [f.forward for f in faces],
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
        atol=1e-12,
    )
    dirs = np.random.default_rng(1).normal(size=(2000, 3))
    inside = np.zeros(len(dirs), dtype=int)
    for f in faces:
        px, depth = f.project(np.asarray(f.eye) + dirs)
        inside += (depth > 0) & np.all((px >= 0) & (px <= 16), axis=1)
    # Every direction lands in at least one face (exactly one except on the cube's edges).
    assert (inside >= 1).all() and (inside == 1).mean() > 0.99


def test_with_resolution_and_repr() -> None:
    cam = ss.Camera.look_at([0, 0, 1], [0, 0, 0], yfov=0.5, width=10, height=10)
    small = cam.with_resolution(3, 2)
    assert (small.width, small.height, small.yfov) == (3, 2, 0.5)
    assert "perspective" in repr(cam)
    assert cam == ss.Camera.look_at([0, 0, 1], [0, 0, 0], yfov=0.5, width=10, height=10)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: ss.Camera.look_at([0, 0, 1], [0, 0, 1], yfov=1, width=4, height=4), "same point"),
        (
            lambda: ss.Camera.look_at([0, 1, 0], [0, 0, 0], [0, 1, 0], yfov=1, width=4, height=4),
            "parallel",
        ),
        (lambda: ss.Camera.look_at([0, 0, 1], [0, 0, 0], yfov=4.0, width=4, height=4), "yfov"),
        (lambda: ss.Camera.look_at([0, 0, 1], [0, 0, 0], yfov=1, width=0, height=4), "resolution"),
        (lambda: ss.Camera.look_at([np.nan, 0, 1], [0, 0, 0], yfov=1, width=4, height=4), "finite"),
        (
            lambda: ss.Camera.look_at(
                [0, 0, 1], [0, 0, 0], yfov=1, width=4, height=4, znear=1, zfar=0.5
            ),
            "zfar",
        ),
        (
            lambda: ss.Camera.from_pose(np.diag([2.0, 2, 2, 1]), yfov=1, width=4, height=4),
            "orthonormal",
        ),
        (lambda: ss.Camera.from_pose(np.eye(3), yfov=1, width=4, height=4), r"\(4, 4\)|\(n, 4\)"),
        (lambda: ss.Camera.orthographic(np.eye(4), xmag=0, ymag=1, width=4, height=4), "xmag"),
        (lambda: ss.Camera.look_at("abc", [0, 0, 0], yfov=1, width=4, height=4), "eye"),
    ],
)
def test_bad_cameras_raise_input_error(make, match) -> None:
    with pytest.raises(ss.InputError, match=match):
        make()
