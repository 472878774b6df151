"""Point queries (closest points, winding numbers, signed distance, occupancy) and every-hit ray
queries, against a float64 brute force in numpy (`_bench_points.brute_distances`), against Open3D's
RaycastingScene, and on Open3D's own documented example."""

from __future__ import annotations

import numpy as np
import pytest
import scenesample as ss
from conftest import SHARED, load_quiet
from scenesample.tools._bench_points import brute_distances, exact_winding


def brute(scene: ss.Scene, pts: np.ndarray) -> np.ndarray:
    """The float64 brute force `bench points` reports its error against: projection onto the
    plane when inside, onto the three edges otherwise (unlike the package's Voronoi-region
    closest point)."""
    return brute_distances(scene, pts)


def soup(scene: ss.Scene) -> ss.Scene:
    """`scene` with every triangle's corners its own vertices, as an STL file has them."""
    v = scene.vertices[scene.faces.reshape(-1)]
    return ss.Scene.from_arrays(v, np.arange(len(v), dtype=np.uint32).reshape(-1, 3))


def near_surface_points(scene: ss.Scene, rng: np.random.Generator) -> np.ndarray:
    """Points on triangles (inside them, on their edges and at corners) and 1e-7 off them along
    their normals, on either side."""
    v, f = scene.vertices.astype(np.float64), scene.faces.astype(np.int64)
    t = rng.choice(len(f), 200)
    a, b, c = (v[f[t, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    uv = rng.uniform(0, 1, (200, 2))
    uv[uv.sum(1) > 1] = 1 - uv[uv.sum(1) > 1]
    uv[:50, 1] = 0  # on an edge
    uv[50:60] = 0  # at a corner
    on = a + (b - a) * uv[:, :1] + (c - a) * uv[:, 1:]
    return np.concatenate([on, on + 1e-7 * n, on - 1e-7 * n]).astype(np.float32)


@pytest.mark.parametrize("form", ["welded", "soup", "inside_out"])
def test_closed_meshes_give_the_exact_winding_number(form):
    """On a closed mesh each point's winding number comes from one ray's signed crossings: the
    integer the float64 sum rounds to. Where the ray cannot tell (the point within 2^-16 of the
    largest coordinate from a triangle's plane it meets, or an edge met exactly) the
    hierarchical sum answers, within a few hundredths of the float64 sum; inside and outside
    agree with it either way, on or within 1e-7 of the surface too, on any thread count. A
    triangle soup is closed by its welded edges; a mesh wound inside out is -1 inside."""
    rng = np.random.default_rng(11)
    scene = ss.scenes.icosphere(2)
    if form == "soup":
        scene = soup(scene)
    if form == "inside_out":
        scene = ss.Scene.from_arrays(scene.vertices, scene.faces[:, ::-1])
    pts = np.concatenate(
        [
            rng.uniform(-1.3, 1.3, (1500, 3)).astype(np.float32),
            near_surface_points(scene, rng),
        ]
    )
    exact = exact_winding(scene, pts)
    w = ss.winding_number(scene, pts)
    distance = ss.closest_points(scene, pts).distance
    # Exactly on the surface (the float32 point on a triangle) the winding number is no integer:
    # 1/2 on a face or an edge, a corner's solid angle; the sum's rounding decides its side.
    settled = (np.abs(exact - np.round(exact)) < 0.25) & (distance > 0)
    assert (~settled).sum() >= 5 and (distance < 1e-6).sum() >= 500
    np.testing.assert_allclose(w[settled], exact[settled], atol=0.03)
    by_ray = w == np.round(exact)
    far = distance > 1e-3
    assert by_ray[far].all(), np.flatnonzero(~by_ray & far)
    inside = -1 if form == "inside_out" else 1
    occ = ss.occupancy(scene, pts)
    np.testing.assert_array_equal(occ[settled], (np.round(exact[settled]) >= 1).astype(np.float32))
    sd = ss.signed_distance(scene, pts)
    np.testing.assert_array_equal(np.signbit(sd[settled]), (w[settled] >= 0.5))
    assert (w[settled] == inside).sum() > 200 and (w[settled] == 0).sum() > 200
    for threads in (1, 3):
        one = ss.winding_number(scene, pts, threads=threads)
        np.testing.assert_array_equal(one.view(np.uint64), w.view(np.uint64))


def unit_box() -> ss.Scene:
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box(extents=(1, 1, 1))
    box.apply_translation((0.5, 0.5, 0.5))
    return ss.Scene.from_trimesh(box)


def test_open3d_s_documented_example():
    """Open3D's RaycastingScene tutorial: a unit box queried at its centre, outside a corner and
    on a corner."""
    box = unit_box()
    q = np.array([[0.5, 0.5, 0.5], [-0.5, -0.5, -0.5], [0, 0, 0]], np.float32)
    np.testing.assert_allclose(ss.closest_points(box, q).distance, [0.5, np.sqrt(0.75), 0], 1e-6)
    np.testing.assert_allclose(ss.signed_distance(box, q), [-0.5, np.sqrt(0.75), 0], 1e-6)
    np.testing.assert_array_equal(ss.occupancy(box, q), [1, 0, 0])
    # The winding number at a corner of a cube is 1/8: on the surface, not inside.
    np.testing.assert_allclose(ss.winding_number(box, q), [1, 0, 0.125], atol=1e-6)


def test_hard_points_match_a_float64_brute_force():
    """Points on vertices, on edges, exactly on faces (vertex means), far away and inside a
    closed mesh: distances within 1e-6 relative of the brute force (or 1e-7 of the scene's
    size for points on the surface), and the reported point lies that far away on the face
    reported."""
    scene = ss.scenes.icosphere(2)
    v = scene.vertices.astype(np.float64)
    f = scene.faces.astype(np.int64)
    rng = np.random.default_rng(3)
    pts = np.concatenate(
        [
            v[:40],  # on vertices
            (v[f[:40, 0]] + v[f[:40, 1]]) / 2,  # on edges
            v[f[:40]].mean(1),  # on faces
            rng.normal(size=(40, 3)) * 50,  # far
            rng.normal(size=(40, 3)) * 0.3,  # inside
            rng.uniform(-1.2, 1.2, (200, 3)),  # anywhere near
        ]
    ).astype(np.float32)
    got = ss.closest_points(scene, pts)
    want = brute(scene, pts.astype(np.float64))
    np.testing.assert_allclose(got.distance, want, rtol=1e-6, atol=1e-7)
    reached = np.linalg.norm(got.point.astype(np.float64) - pts, axis=1)
    np.testing.assert_allclose(reached, want, rtol=1e-5, atol=1e-6)
    # The point is on the face reported, at the barycentrics reported.
    corners = v[f[got.triangle]]
    u, w = got.barycentric[:, :1].astype(np.float64), got.barycentric[:, 1:].astype(np.float64)
    at = corners[:, 0] * (1 - u - w) + corners[:, 1] * u + corners[:, 2] * w
    np.testing.assert_allclose(at, got.point, atol=1e-5)
    # max_distance cuts off the far points only.
    capped = ss.closest_points(scene, pts, max_distance=2.0)
    far = want > 2.0
    assert (capped.triangle[far] == -1).all() and np.isinf(capped.distance[far]).all()
    np.testing.assert_array_equal(capped.triangle[~far], got.triangle[~far])


def test_inside_is_the_winding_number_and_agrees_with_ray_parity_on_a_closed_mesh():
    scene = ss.scenes.icosphere(3)
    rng = np.random.default_rng(5)
    pts = rng.uniform(-1.3, 1.3, (4000, 3)).astype(np.float32)
    r = np.linalg.norm(pts, axis=1)
    clear = np.abs(r - 1) > 0.02  # away from the faceted surface
    w = ss.winding_number(scene, pts)
    np.testing.assert_allclose(w[clear], (r[clear] < 1).astype(float), atol=3e-2)
    occ = ss.occupancy(scene, pts)
    assert occ.dtype == np.float32
    # Ray parity: count crossings along +x.
    crossings = ss.count_hits(scene, pts, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(occ[clear], (crossings[clear] % 2).astype(np.float32))
    sd = ss.signed_distance(scene, pts)
    np.testing.assert_array_equal(np.sign(sd[clear]), np.where(occ[clear] > 0, -1, 1))
    np.testing.assert_allclose(np.abs(sd), ss.closest_points(scene, pts).distance)


def test_an_open_mesh_keeps_its_inside_where_ray_parity_loses_it():
    """A sphere with a cap cut off: the winding number inside stays above 0.5 away from the
    hole (ray parity through the hole says outside); far outside it stays near 0."""
    scene = ss.scenes.icosphere(3)
    v, f = scene.vertices, scene.faces
    keep = v[f].mean(1)[:, 2] < 0.8
    cut = ss.Scene.from_arrays(v, f[keep])
    inside = np.array([[0, 0, 0], [0.3, 0.2, -0.4], [0, 0, 0.5]], np.float32)
    np.testing.assert_array_equal(ss.occupancy(cut, inside), [1, 1, 1])
    up = ss.count_hits(cut, inside, [0.0, 0.0, 1.0])
    assert (up == 0).all(), "ray parity upward through the hole says outside"
    assert ss.occupancy(cut, [[0, 0, 3.0], [2.0, 0, 0]]).sum() == 0


@pytest.mark.parametrize("name", ["khr_clearcoat_car_paint", "khr_simple_instancing"])
def test_open3d_agrees_on_watertight_shared_scenes(name):
    o3d = pytest.importorskip("open3d")
    if name not in SHARED:
        pytest.skip("shared scenes not present")
    scene = load_quiet(SHARED[name])
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(
        o3d.core.Tensor(scene.vertices.astype(np.float32)),
        o3d.core.Tensor(scene.faces.astype(np.uint32)),
    )
    lo, hi = scene.bounds.astype(np.float64)
    rng = np.random.default_rng(0)
    pts = rng.uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), (20000, 3)).astype(np.float32)
    q = o3d.core.Tensor(pts)
    theirs = np.linalg.norm(rc.compute_closest_points(q)["points"].numpy() - pts, axis=1)
    ours = ss.closest_points(scene, pts).distance
    diag = float(np.linalg.norm(hi - lo))
    np.testing.assert_allclose(ours, theirs, rtol=1e-4, atol=1e-5 * diag)
    # Off the surface (farther than 1e-5 of the diagonal), the signs of Open3D's ray parity.
    clear = ours > 1e-5 * diag
    agree = (ss.occupancy(scene, pts) == rc.compute_occupancy(q).numpy())[clear].mean()
    assert agree >= 0.9999, agree
    sd = rc.compute_signed_distance(q).numpy()
    same = (np.sign(ss.signed_distance(scene, pts)) == np.sign(sd))[clear].mean()
    assert same >= 0.9999, same


def test_all_hits_are_the_k_nearest_with_no_k_and_count_them():
    scene = ss.scenes.shapes(seed=4, detail=1)
    cam = ss.Camera.look_at((3, 2, 3), (0, 0, 0), yfov=0.8, width=24, height=18)
    o, d = cam.pixel_rays()
    every = ss.all_hits(scene, o, d)
    counts = every.count
    assert counts.shape == (18, 24) and every.ray_splits.dtype == np.int64
    assert every.ray_splits[0] == 0 and every.ray_splits[-1] == len(every)
    k = int(counts.max())
    dense = ss.cast_rays(scene, o, d, max_hits=k)
    np.testing.assert_array_equal(dense.count, counts)
    flat_t = dense.t.reshape(-1, k)
    flat_tri = dense.triangle.reshape(-1, k)
    for i in range(counts.size):
        a, b = every.ray_splits[i], every.ray_splits[i + 1]
        np.testing.assert_array_equal(every.t[a:b], flat_t[i, : b - a])
        np.testing.assert_array_equal(every.triangle[a:b], flat_tri[i, : b - a])
    np.testing.assert_array_equal(every.ray_ids, np.repeat(np.arange(counts.size), counts.ravel()))
    np.testing.assert_array_equal(ss.count_hits(scene, o, d), counts)


def test_a_duplicated_surface_is_hit_once():
    scene = ss.scenes.icosphere(1)
    doubled = ss.Scene.from_arrays(
        np.concatenate([scene.vertices, scene.vertices]),
        np.concatenate([scene.faces, scene.faces + len(scene.vertices)]),
    )
    n = ss.count_hits(doubled, [[0, 0, 5.0]], [[0, 0, -1.0]])
    assert n.tolist() == [2]


def test_shapes_and_bad_input():
    scene = ss.scenes.icosphere(1)
    grid = np.zeros((2, 3, 4, 3), np.float32)
    r = ss.closest_points(scene, grid)
    assert r.distance.shape == r.triangle.shape == (2, 3, 4)
    assert r.point.shape == (2, 3, 4, 3) and r.barycentric.shape == (2, 3, 4, 2)
    assert ss.winding_number(scene, grid).shape == (2, 3, 4)
    assert ss.signed_distance(scene, [0.0, 0.0, 0.0]).shape == ()
    with pytest.raises(ss.InputError, match=r"points must have shape \(\.\.\., 3\)"):
        ss.closest_points(scene, np.zeros((4, 2)))
    bad = grid.copy()
    bad[1, 2, 3, 0] = np.nan
    with pytest.raises(ss.InputError, match=r"points\[1, 2, 3\] is not finite"):
        ss.closest_points(scene, bad)
    with pytest.raises(ss.InputError, match=r"points\[1, 2, 3\] is not finite"):
        ss.occupancy(scene, bad)
    with pytest.raises(ss.InputError, match="max_distance"):
        ss.closest_points(scene, grid, max_distance=-1.0)
    with pytest.raises(ss.InputError, match="threads"):
        ss.closest_points(scene, grid, threads=0)
    empty = ss.closest_points(scene, np.zeros((0, 3)))
    assert empty.distance.shape == (0,)


def test_surface_metrics_of_a_mesh_against_itself_and_a_grown_copy():
    scene = ss.scenes.icosphere(3)
    same = ss.evaluate(scene, scene, "surface", samples=20_000)
    assert same["accuracy_max"] < 1e-6 and same["completeness_max"] < 1e-6
    assert same["precision"] == same["recall"] == same["fscore"] == 1.0
    # Every vertex pushed out by 2% of the radius: every distance about 0.02 (the faceted
    # surface moves by 2% of its own distance from the centre, 0.98-1 here).
    grown = ss.Scene.from_arrays(scene.vertices * 1.02, scene.faces)
    m = ss.evaluate(grown, scene, "surface", samples=20_000, threshold=0.01)
    for k in ("accuracy", "completeness"):
        assert 0.019 < m[f"{k}_median"] < 0.0205, (k, m[f"{k}_median"])
    assert m["precision"] == m["recall"] == m["fscore"] == 0.0
    assert m["chamfer"] == pytest.approx((m["accuracy_mean"] + m["completeness_mean"]) / 2)
    assert m["hausdorff"] == max(m["accuracy_max"], m["completeness_max"])
    assert m["accuracy_distances"].shape == (20_000,)


def test_surface_metrics_take_points_meshes_and_trimesh_and_follow_the_seed():
    trimesh = pytest.importorskip("trimesh")
    scene = ss.scenes.shapes(seed=1, detail=1)
    cams = ss.scenes.reference_cameras(scene, 96)
    nr = ss.discretize(scene, cams, "nonredundant")
    mesh = ss.reconstruct(nr, "hybrid")
    points = nr.position[nr.mask]
    a = ss.evaluate(mesh, scene, "surface", samples=5000, seed=1)
    b = ss.evaluate(mesh.to_trimesh(), scene, "surface", samples=5000, seed=1)
    assert a["accuracy_mean"] == b["accuracy_mean"] and a["recall"] == b["recall"]
    c = ss.evaluate(mesh, scene, "surface", samples=5000, seed=2)
    assert c["accuracy_mean"] != a["accuracy_mean"]
    p = ss.evaluate(points, scene, "surface", samples=5000)
    # A point set's samples are the points themselves, which lie on the surface.
    assert p["accuracy_max"] < 1e-3 * np.linalg.norm(np.ptp(scene.bounds, axis=0))
    assert len(p["accuracy_distances"]) == len(points)
    epr = ss.scenes.reflective_room(spheres=2)
    pts = ss.discretize(epr, method="epr", eye=ss.scenes.reflective_room_eye(64), resolution=16)
    # EPR points lie in their triangle's plane, within their square's side of the triangle.
    assert ss.evaluate(pts, epr, "surface", samples=2000)["accuracy_max"] <= pts.length.max()
    box = trimesh.creation.box()
    assert ss.evaluate(box, ss.Scene.from_trimesh(box), "surface", samples=500)["fscore"] == 1
    with pytest.raises(ss.InputError, match="metric='surface' measures"):
        ss.evaluate(np.zeros((4, 2)), scene, "surface")
    with pytest.raises(ss.InputError, match="samples"):
        ss.evaluate(mesh, scene, "surface", samples=0)
    with pytest.raises(ss.InputError, match="threshold"):
        ss.evaluate(mesh, scene, "surface", threshold=-1.0)
