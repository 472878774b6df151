"""cast_rays cross-validated against raw Embree, watertightness on a closed mesh, units, limits
and bad input."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import scenesample as ss
from conftest import SHARED, load_quiet, orbit_cameras
from scenesample.references import EmbreeReference


def random_rays(scene: ss.Scene, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Rays from random points around the scene toward random points inside its bounds."""
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds.astype(np.float64)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    o = c + rng.normal(size=(n, 3)) * r
    d = lo + rng.uniform(size=(n, 3)) * (hi - lo) - o
    return o.astype(np.float32), d.astype(np.float32)


def compare_with_embree(scene: ss.Scene, o: np.ndarray, d: np.ndarray) -> dict:
    ref = EmbreeReference(scene).cast(o, d)
    ours = ss.cast_rays(scene, o, d)
    same_status = (ours.triangle >= 0) == (ref["triangle"] >= 0)
    assert same_status.mean() >= 0.999, f"hit/miss agree on only {same_status.mean():.5%}"
    both = (ours.triangle >= 0) & (ref["triangle"] >= 0)
    rel = np.abs(ours.t[both] - ref["t"][both]) / ref["t"][both]
    # Different triangles can be hit at a shared edge; where the same one is, t must agree.
    same_tri = ours.triangle[both] == ref["triangle"][both]
    assert same_tri.mean() >= 0.999
    assert (rel[same_tri] <= 1e-4).all(), f"max relative t difference {rel[same_tri].max():.3g}"
    assert (rel <= 1e-4).mean() >= 0.999
    # Both sides lose up to ~1e-3 to float32 cancellation on tiny triangles; ours are refined in
    # float64, so check them against float64 barycentrics instead, and Embree loosely.
    idx = np.flatnonzero(both)[same_tri]
    exact = exact_barycentric(scene, o[idx], d[idx], ours.triangle[idx])
    np.testing.assert_allclose(ours.barycentric[idx], exact, atol=1e-5)
    np.testing.assert_allclose(ref["barycentric"][idx], exact, atol=2e-3)
    return {"hit": int(both.sum())}


def exact_barycentric(scene: ss.Scene, o: np.ndarray, d: np.ndarray, tri: np.ndarray) -> np.ndarray:
    v = scene.vertices.astype(np.float64)[scene.faces[tri].astype(int)]
    o, d = o.astype(np.float64), d.astype(np.float64)
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=1)
    t = o - v[:, 0]
    q = np.cross(t, e1)
    return np.stack([np.sum(t * p, 1) / det, np.sum(d * q, 1) / det], -1)


def test_matches_embree_on_primary_and_random_rays() -> None:
    pytest.importorskip("embreex")
    s = ss.scenes.shapes(seed=3, detail=4)
    assert s.triangle_count > 100_000
    cam = orbit_cameras(s, 1, 256, 256, seed=3)[0]
    o, d = cam.pixel_rays()
    compare_with_embree(s, o.reshape(-1, 3), d.reshape(-1, 3))
    compare_with_embree(s, *random_rays(s, 200_000, seed=3))


def test_matches_embree_on_a_tree_traced_in_turns() -> None:
    """Trees larger than 8 MiB trace closest hits several rays in turns (Rust `interleave`)."""
    pytest.importorskip("embreex")
    s = ss.scenes.shapes(seed=5, detail=5)
    assert ss.bvh_stats(s)["bytes"] > 8 << 20
    cam = orbit_cameras(s, 1, 128, 128, seed=5)[0]
    o, d = cam.pixel_rays()
    compare_with_embree(s, o.reshape(-1, 3), d.reshape(-1, 3))
    o, d = random_rays(s, 50_001, seed=5)
    compare_with_embree(s, o, d)
    one = ss.cast_rays(s, o, d, threads=1)
    every = ss.cast_rays(s, o, d)
    np.testing.assert_array_equal(one.triangle, every.triangle)
    np.testing.assert_array_equal(one.t, every.t)


@pytest.mark.skipif("stanford_bunny" not in SHARED, reason="../shared/scenes is absent")
def test_matches_embree_on_the_bunny() -> None:
    pytest.importorskip("embreex")
    s = load_quiet(SHARED["stanford_bunny"])
    compare_with_embree(s, *random_rays(s, 100_000, seed=4))


def test_watertight_on_a_million_rays_at_vertices_and_edges() -> None:
    """10^6 rays from outside a closed icosphere aimed exactly at its vertices and edge midpoints
    (in float32): none may pass through."""
    s = ss.scenes.icosphere(5)
    v = s.vertices.astype(np.float64)
    f = s.faces.astype(np.int64)
    edges = np.unique(
        np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0
    )
    targets = np.concatenate([v, (v[edges[:, 0]] + v[edges[:, 1]]) / 2]).astype(np.float32)
    per_target = int(np.ceil(1_000_000 / len(targets)))
    rng = np.random.default_rng(0)
    t = np.repeat(targets, per_target, axis=0).astype(np.float64)
    n = t / np.linalg.norm(t, axis=1, keepdims=True)
    tangent = rng.normal(size=t.shape)
    tangent -= n * np.sum(tangent * n, axis=1, keepdims=True)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    # Up to ~40 degrees from the normal, so every ray enters the sphere at its target.
    out = n + tangent * rng.uniform(0, 0.84, size=(len(t), 1))
    origins = (t + 3 * out / np.linalg.norm(out, axis=1, keepdims=True)).astype(np.float32)
    directions = targets.repeat(per_target, axis=0) - origins
    assert len(origins) >= 1_000_000
    hits = ss.cast_rays(s, origins, directions)
    assert (hits.triangle >= 0).all(), f"{(hits.triangle < 0).sum()} rays passed through"
    # Each ray hits at (or just before) its target: t ~ 1 in units of the direction.
    assert np.abs(hits.t - 1).max() < 1e-3


def test_t_is_in_units_of_the_direction_and_limits_apply() -> None:
    s = ss.Scene.from_arrays([[-1, -1, 0], [1, -1, 0], [0, 1, 0]], [[0, 1, 2]])
    o = np.array([[0, 0, 2.0]] * 3)
    d = np.array([[0, 0, -1.0], [0, 0, -4.0], [0, 0, -0.5]])
    np.testing.assert_allclose(ss.cast_rays(s, o, d).t, [2.0, 0.5, 4.0])
    # One ray of shape (3,): results of shape ().
    assert ss.cast_rays(s, o[0], d[0], t_max=1.5).triangle == -1
    assert ss.cast_rays(s, o[0], d[0], t_min=2.5).triangle == -1
    back = ss.cast_rays(s, [0, 0, -2.0], [0, 0, 1.0])  # back faces count
    assert back.triangle.shape == () and back.barycentric.shape == (2,)
    assert back.triangle == 0 and back.t == pytest.approx(2.0)
    miss = ss.cast_rays(s, [5, 5, 2.0], [0, 0, -1.0])
    assert miss.t == np.inf and miss.triangle == -1 and (miss.barycentric == 0).all()


def test_bvh_is_cached_and_concurrent_calls_agree() -> None:
    s = ss.scenes.shapes(seed=9, detail=1)
    o, d = random_rays(s, 50_000, seed=9)
    first = ss.cast_rays(s, o, d)
    # The first call reports the build it did (the cached tree's own record); later ones none.
    assert first.timings["bvh_build"] == ss.bvh_stats(s)["build_seconds"]
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda _: ss.cast_rays(s, o, d), range(4)))
    for r in results:
        assert r.timings["bvh_build"] == 0
        np.testing.assert_array_equal(r.triangle, first.triangle)
        np.testing.assert_array_equal(r.t, first.t)


@pytest.mark.parametrize(
    "origins, directions, kwargs, match",
    [
        ([[0, 0, 0]], [[0, 0, 0]], {}, r"directions\[0\] must be finite and non-zero"),
        ([[0, 0, np.nan]], [[0, 0, 1]], {}, r"origins\[0\] is not finite"),
        ([[0, 0, 0], [0, np.inf, 0]], [[0, 0, 1]] * 2, {}, r"origins\[1\] is not finite"),
        ([[0, 0, 0]], [[np.inf, 0, 1]], {}, r"directions\[0\] must be finite and non-zero"),
        # Finite components whose squared length overflows float32.
        ([[0, 0, 0]], [[3e19, 0, 1]], {}, r"directions\[0\] must be finite and non-zero"),
        (
            [[0, 0, 0], [1, 1, 1]],
            [[0, 0, 1]] * 3,
            {},
            r"origins of shape \(2, 3\) and directions of shape \(3, 3\) do not broadcast",
        ),
        ([[0, 0]], [[0, 0, 1]], {}, r"origins must have shape \(\.\.\., 3\), got \(1, 2\)"),
        (5.0, [[0, 0, 1]], {}, r"origins must have shape \(\.\.\., 3\), got \(\)"),
        # A bad ray of a (2, 2, 3) batch is named by its index in the batch.
        (
            np.zeros((2, 2, 3)),
            [[[0, 0, 1], [0, 0, 1]], [[0, 0, 1], [0, 0, 0]]],
            {},
            r"directions\[1, 1\] must be finite and non-zero",
        ),
        ([[0, 0, 0]], [[0, 0, 1]], {"t_min": 2.0, "t_max": 1.0}, "t_min <= t_max"),
        ([[0, 0, 0]], [[0, 0, 1]], {"t_min": -1.0}, "0 <= t_min"),
        ([["x", 0, 0]], [[0, 0, 1]], {}, "origins must be an array of real numbers"),
    ],
)
def test_bad_rays_raise_input_error(origins, directions, kwargs, match) -> None:
    s = ss.scenes.icosphere(0)
    with pytest.raises(ss.InputError, match=match):
        ss.cast_rays(s, origins, directions, **kwargs)


def test_empty_batch() -> None:
    hits = ss.cast_rays(ss.scenes.icosphere(0), np.zeros((0, 3)), np.zeros((0, 3)))
    assert hits.t.shape == (0,) and hits.barycentric.shape == (0, 2)


def duplicated_soup(n: int, seed: int) -> ss.Scene:
    """Random triangles of many sizes; every fifth one also appears again with its corners
    rotated (a duplicated face: every ray through it meets two triangles at one depth)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-1, 1, (n, 1, 3))
    size = 0.02 + 0.3 * rng.uniform(0, 1, (n, 1, 1)) ** 3
    v = (centres + rng.uniform(-1, 1, (n, 3, 3)) * size).reshape(-1, 3)
    f = np.arange(3 * n).reshape(n, 3)
    dup = f[::5][:, [1, 2, 0]]
    return ss.Scene.from_arrays(v.astype(np.float32), np.concatenate([f, dup]))


def all_hits_float64(scene: ss.Scene, o: np.ndarray, d: np.ndarray) -> list[list[tuple]]:
    """Every hit of every ray by brute force in float64 (Moeller-Trumbore), sorted by
    (float32 t, triangle): (t, triangle) lists."""
    v = scene.vertices.astype(np.float64)[scene.faces.astype(np.int64)]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    out = []
    for oi, di in zip(o.astype(np.float64), d.astype(np.float64)):
        p = np.cross(di, e2)
        det = np.sum(e1 * p, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            tv = oi - v[:, 0]
            u = np.sum(tv * p, axis=1) / det
            q = np.cross(tv, e1)
            w = (q @ di) / det
            t = np.sum(e2 * q, axis=1) / det
        ok = (det != 0) & (u >= 0) & (w >= 0) & (u + w <= 1) & (t >= 0)
        hits = sorted((float(np.float32(t[i])), int(i)) for i in np.flatnonzero(ok))
        out.append(hits)
    return out


def test_max_hits_are_the_k_nearest_surfaces() -> None:
    """k nearest hits against a float64 brute force: nearest first, padded with +inf / -1,
    and two faces at the same depth (duplicated triangles) counted once, as the smaller index."""
    s = duplicated_soup(400, seed=5)
    o, d = random_rays(s, 400, seed=6)
    k = 5
    h = ss.cast_rays(s, o, d, max_hits=k)
    assert h.t.shape == (400, k) and h.triangle.shape == (400, k)
    assert h.barycentric.shape == (400, k, 2) and h.t.dtype == np.float32
    later = np.isfinite(h.t[:, 1:])
    assert (h.t[:, 1:][later] > h.t[:, :-1][later]).all(), "hits strictly increase"
    merged = 0
    for i, hits in enumerate(all_hits_float64(s, o, d)):
        want: list[tuple] = []
        for t, tri in hits:
            if want and t - want[-1][0] <= 1e-5 * t:
                merged += 1
                continue
            want.append((t, tri))
        want = want[:k]
        got_tri = h.triangle[i][: len(want)]
        np.testing.assert_array_equal(got_tri, [tri for _, tri in want], err_msg=f"ray {i}")
        np.testing.assert_allclose(h.t[i][: len(want)], [t for t, _ in want], rtol=1e-5)
        assert (h.triangle[i][len(want) :] == -1).all() and np.isinf(h.t[i][len(want) :]).all()
    assert merged > 10, "the duplicated faces were met"
    # The first of k hits is the closest hit; `count` says how many each ray got.
    one = ss.cast_rays(s, o, d)
    np.testing.assert_array_equal(h.t[:, 0], one.t)
    assert (h.count == (h.triangle >= 0).sum(axis=1)).all() and h.hit.shape == (400,)


def test_occluded_agrees_with_cast_rays_and_embree() -> None:
    pytest.importorskip("embreex")
    s = ss.scenes.shapes(seed=4, detail=3)
    o, d = random_rays(s, 100_000, seed=4)
    for t_max in (0.5, 1.0, np.inf):
        occ = ss.occluded(s, o, d, t_max=t_max)
        assert occ.dtype == bool and occ.shape == (len(o),)
        np.testing.assert_array_equal(occ, ss.cast_rays(s, o, d, t_max=t_max).hit)
        ref = EmbreeReference(s).occluded(o, d, t_max)
        assert (occ == ref).mean() >= 0.9999, f"t_max {t_max}: {(occ != ref).sum()} differ"
    # t_min applies too.
    near = ss.occluded(s, o, d, t_min=0.7, t_max=0.8)
    np.testing.assert_array_equal(near, ss.cast_rays(s, o, d, t_min=0.7, t_max=0.8).hit)


def test_every_thread_setting_gives_the_same_hits() -> None:
    s = ss.scenes.shapes(seed=2, detail=2)
    cam = orbit_cameras(s, 1, 200, 150, seed=2)[0]
    o, d = (a.reshape(-1, 3) for a in cam.pixel_rays())
    ro, rd = random_rays(s, 30_000, seed=2)
    o, d = np.concatenate([o, ro]), np.concatenate([d, rd])
    every = ss.cast_rays(s, o, d)
    for threads in (1, 2, 3):
        h = ss.cast_rays(s, o, d, threads=threads)
        for a, b in zip(
            (h.t, h.triangle, h.barycentric), (every.t, every.triangle, every.barycentric)
        ):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(ss.occluded(s, o, d, threads=threads), every.hit)
    # A fresh scene's BVH built on the calling thread only is the same tree.
    fresh = ss.Scene.from_arrays(s.vertices, s.faces)
    np.testing.assert_array_equal(ss.cast_rays(fresh, o, d, threads=1).triangle, every.triangle)


def test_hits_agree_with_open3d() -> None:
    pytest.importorskip("open3d")
    from scenesample.references import Open3DReference

    s = ss.scenes.shapes(seed=6, detail=3)
    o, d = random_rays(s, 50_000, seed=6)
    ours, ref = ss.cast_rays(s, o, d), Open3DReference(s).cast(o, d)
    assert (ours.triangle == ref["triangle"]).mean() >= 0.999
    both = (ours.triangle >= 0) & (ours.triangle == ref["triangle"])
    np.testing.assert_allclose(ours.t[both], ref["t"][both], rtol=1e-4)


def test_bvh_stats_and_memory() -> None:
    s = ss.scenes.shapes(seed=1, detail=2)
    st = ss.bvh_stats(s)
    assert st["triangles"] == s.triangle_count and st["nodes"] >= 1
    assert 4 * st["blocks"] >= s.triangle_count and st["depth"] >= 1
    # Nodes of 256 and blocks of 160 bytes, nothing else.
    assert st["bytes"] == 256 * st["nodes"] + 160 * st["blocks"]
    assert 20 < st["bytes"] / s.triangle_count < 100 and st["sah"] > 1


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"threads": 0}, "threads must be an integer >= 1"),
        ({"threads": -2}, "threads must be an integer >= 1"),
        ({"threads": 1.5}, "threads must be an integer >= 1"),
        ({"threads": True}, "threads must be an integer >= 1"),
        ({"max_hits": 0}, "max_hits must be an integer >= 1"),
        ({"max_hits": 2.0}, "max_hits must be an integer >= 1"),
    ],
)
def test_bad_query_options_raise_input_error(kwargs, match) -> None:
    s = ss.scenes.icosphere(0)
    with pytest.raises(ss.InputError, match=match):
        ss.cast_rays(s, [[0, 0, 3]], [[0, 0, -1]], **kwargs)
    if "threads" in kwargs:
        with pytest.raises(ss.InputError, match=match):
            ss.occluded(s, [[0, 0, 3]], [[0, 0, -1]], **kwargs)


def test_occluded_rejects_bad_rays_like_cast_rays() -> None:
    s = ss.scenes.icosphere(0)
    with pytest.raises(ss.InputError, match=r"directions\[1\] must be finite and non-zero"):
        ss.occluded(s, [[0, 0, 3]] * 2, [[0, 0, -1], [0, np.nan, 0]])
    assert ss.occluded(s, np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)


@pytest.mark.parametrize("batch", [(7,), (5, 6), (2, 3, 4)], ids=["N", "HxW", "AxBxC"])
@pytest.mark.parametrize("k", [1, 3])
def test_rays_of_any_batch_shape_give_hits_of_that_shape(batch, k) -> None:
    """(..., 3) origins and directions give (...) results, (..., 2) barycentrics, and with
    max_hits=k a hit axis after the batch; the hits are those of the same rays as (N, 3)."""
    s = ss.scenes.shapes(seed=2, detail=1)
    n = int(np.prod(batch))
    o, d = random_rays(s, n, seed=4)
    flat = ss.cast_rays(s, o, d, max_hits=k)
    hits = ss.cast_rays(s, o.reshape(*batch, 3), d.reshape(*batch, 3), max_hits=k)
    extra = () if k == 1 else (k,)
    assert hits.t.shape == hits.triangle.shape == (*batch, *extra)
    assert hits.barycentric.shape == (*batch, *extra, 2)
    assert hits.shape == batch and len(hits) == n and hits.hit.shape == batch
    np.testing.assert_array_equal(hits.triangle.reshape(n, *extra), flat.triangle)
    np.testing.assert_array_equal(hits.t.reshape(n, *extra), flat.t)
    np.testing.assert_array_equal(hits.count.reshape(n), flat.count)
    occ = ss.occluded(s, o.reshape(*batch, 3), d.reshape(*batch, 3))
    assert occ.shape == batch
    np.testing.assert_array_equal(occ.reshape(n), ss.occluded(s, o, d))


def test_one_origin_broadcasts_against_a_camera_s_pixel_rays() -> None:
    s = ss.scenes.shapes(seed=3, detail=1)
    cam = ss.Camera.look_at((3, 2, 3), (0, 0, 0), yfov=0.8, width=40, height=30)
    origins, dirs = cam.pixel_rays()
    direct = ss.cast_rays(s, origins, dirs)  # (H, W, 3) straight from the camera
    assert direct.t.shape == (30, 40) and direct.barycentric.shape == (30, 40, 2)
    one = ss.cast_rays(s, origins[0, 0], dirs)  # a pinhole: every ray leaves one point
    np.testing.assert_array_equal(one.triangle, direct.triangle)
    # Directions broadcast too: one direction from many origins.
    down = ss.cast_rays(s, origins.reshape(-1, 3), [0.0, -1.0, 0.0])
    assert down.t.shape == (1200,)
    assert ss.occluded(s, origins[0, 0], dirs, t_max=1e9).shape == (30, 40)


def _kernel_answers(scene: ss.Scene) -> list[np.ndarray]:
    """Every answer of the ray queries on rays that take each path of the traversal: camera rays
    in pixel order (packets, where the kernel has them), the same with a ``t`` window, shadow
    rays from their hits toward one light, rays from inside the scene along the axes, a batch
    that mixes coherent runs with incoherent rays, and the CPU images of the camera."""
    (cam,) = orbit_cameras(scene, 1, 64, 48, seed=3)
    o, d = (a.reshape(-1, 3) for a in cam.pixel_rays())
    hits = ss.cast_rays(scene, o, d)
    lo, hi = scene.bounds.astype(np.float64)
    seen = np.flatnonzero(hits.hit)
    points = o[seen] + d[seen] * hits.t[seen, None]
    light = np.array([(lo[0] + hi[0]) / 2, hi[1] + 0.2 * (hi[1] - lo[1]), (lo[2] + hi[2]) / 2])
    ro, rd = random_rays(scene, 1000, seed=5)
    inside = (lo + (hi - lo) * np.random.default_rng(9).uniform(0.2, 0.8, (300, 3))).repeat(6, 0)
    axes = np.tile(np.vstack([np.eye(3), -np.eye(3)]), (300, 1))
    mixed_o = np.concatenate([o[:800].reshape(100, 8, 3), ro[:800].reshape(100, 8, 3)], 1)
    mixed_d = np.concatenate([d[:800].reshape(100, 8, 3), rd[:800].reshape(100, 8, 3)], 1)
    mixed = (mixed_o.reshape(-1, 3), mixed_d.reshape(-1, 3))
    span = float(np.median(hits.t[seen])) if len(seen) else 1.0
    out = []
    for ro_, rd_, window in [
        (o, d, {}),
        (o, d, {"t_min": 0.9 * span, "t_max": 1.1 * span}),
        (points + 1e-4 * (light - points), (light - points) * (1 - 2e-4), {"t_max": 1.0}),
        (inside, axes, {}),
        (*mixed, {}),
    ]:
        h = ss.cast_rays(scene, ro_, rd_, **window)
        out += [h.t, h.triangle, h.barycentric, ss.occluded(scene, ro_, rd_, **window)]
        three = ss.cast_rays(scene, ro_, rd_, max_hits=3, **window)
        out += [three.t, three.triangle, three.barycentric]
    # CPU images, with and without back faces (culled views take the front-face sink), and
    # peeling (the k-nearest sink).
    for cull in (False, True):
        img = ss.discretize(scene, [cam], backend="cpu", cull_backfaces=cull)
        peeled = ss.discretize(
            scene, [cam], "peeling", layers=3, backend="cpu", cull_backfaces=cull
        )
        out += [img.triangle, img.depth, peeled.triangle, peeled.depth]
    return out


def _moves(scene: ss.Scene) -> np.ndarray:
    """One small rigid move per object of ``scene``: a turn about y and a shift of a few
    percent of the scene's size."""
    lo, hi = scene.bounds.astype(np.float64)
    out = np.tile(np.eye(4), (len(scene.objects), 1, 1))
    for i in range(len(out)):
        a = 0.05 * (i % 5)
        out[i, [0, 0, 2, 2], [0, 2, 0, 2]] = [np.cos(a), np.sin(a), -np.sin(a), np.cos(a)]
        out[i, :3, 3] = 0.02 * (hi - lo) * [i % 3, 0, (i + 1) % 2]
    return out


def _bits(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    return a.view(np.uint32) if a.dtype == np.float32 else a


@pytest.mark.parametrize("name", sorted(SHARED))
def test_every_kernel_gives_the_same_answers_on_shared_scenes(name: str) -> None:
    # The vector kernels trace coherent runs as packets and the portable one ray by ray: the
    # answers must agree bit for bit all the same. Each narrower kernel the CPU has is forced in
    # turn, so an AVX-512 machine checks its AVX2 and portable code too.
    best = ss.ray_kernel()
    kernels = ["avx512", "avx2", "portable"]
    kernels = kernels[kernels.index(best) :]
    if len(kernels) == 1:
        pytest.skip("the CPU has only the portable kernel")
    scene = load_quiet(SHARED[name])
    scenes = [scene]
    if len(scene.objects) > 1:
        # A rigid pose: a two-level tree, whose packets enter each instance together.
        scenes.append(scene.posed(_moves(scene)))
    answers = {}
    try:
        for k in kernels:
            assert ss.ray_kernel(k) == k
            answers[k] = [a for s in scenes for a in _kernel_answers(s)]
    finally:
        assert ss.ray_kernel("best") == best
    for k in kernels[1:]:
        for a, b in zip(answers[kernels[0]], answers[k]):
            np.testing.assert_array_equal(_bits(a), _bits(b), err_msg=f"{kernels[0]} vs {k}")


def test_ray_kernel_names_its_kernels() -> None:
    best = ss.ray_kernel()
    assert best in ("avx512", "avx2", "portable")
    try:
        # A kernel the CPU lacks is never used: asking for it gives the widest it has below.
        assert ss.ray_kernel("avx512") == best
        assert ss.ray_kernel("avx2") == ("portable" if best == "portable" else "avx2")
        assert ss.ray_kernel("portable") == "portable"
        assert ss.ray_kernel() == "portable"
    finally:
        assert ss.ray_kernel("best") == best
    with pytest.raises(ss.InputError, match="ray_kernel"):
        ss.ray_kernel("avx512-please")
    assert ss.ray_kernel() == best
