"""Posed scenes (``Scene.posed``): a rigid pose traces its objects' own trees through their
transforms (a two-level tree), and finds what the same geometry built flat finds, but where a ray
passes within the rounding of the posed vertices of an edge; with non-uniform scale, mirroring
and a 1e5 translation (where it traces the exact pose at least as well as the flat tree of the
rounded vertices); the images, points and point queries match flat pixel for pixel; every verb
runs on it; the same poses give the same bits in another process; bad transforms fail
clearly."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import scenesample as ss
import trimesh


def _rotation(axis, angle):
    m = np.eye(4)
    m[:3, :3] = trimesh.transformations.rotation_matrix(angle, axis)[:3, :3]
    return m


def _meshes():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    box = trimesh.creation.box(extents=(1.0, 0.6, 0.3))
    floor = (
        np.array([[-6, -6, -1.2], [6, -6, -1.2], [6, 6, -1.2], [-6, 6, -1.2]]),
        [[0, 1, 2], [0, 2, 3]],
    )
    parts = [(sphere.vertices, sphere.faces), (box.vertices, box.faces)] * 3 + [floor]
    places = [np.eye(4) for _ in parts]
    for k in range(6):
        places[k] = trimesh.transformations.translation_matrix(
            [3.0 * (k % 3) - 3.0, 2.5 * (k // 3) - 1.2, 0]
        )
    return parts, np.array(places)


def _poses(n):
    """Non-uniform scale, a mirror, a rotation and a far translation among the objects."""
    out = np.array([np.eye(4) for _ in range(n)])
    out[0] = trimesh.transformations.translation_matrix([0.3, 0.1, 0.2]) @ np.diag(
        [1.5, 0.7, 1.2, 1]
    )
    out[1] = _rotation([0, 0, 1], 0.7) @ np.diag([-1.0, 1, 1, 1])  # mirrored: det < 0
    out[2] = _rotation([1, 1, 0], 1.1)
    out[3] = trimesh.transformations.translation_matrix([0, 0, 0.5])
    return out


def _flat(posed):
    return ss.Scene.from_arrays(
        posed.vertices,
        posed.faces,
        normals=posed.normals,
        colors=posed.colors,
        material_ids=posed.material_ids,
        materials=posed.materials,
        object_ids=posed.object_ids,
        objects=posed.objects,
    )


@pytest.fixture(scope="module")
def scenes():
    parts, places = _meshes()
    base = ss.Scene.from_meshes(parts, places)
    posed = base.posed(_poses(len(parts)))
    return base, posed, _flat(posed)


def _rays(scene, n=40_000, seed=3):
    rng = np.random.default_rng(seed)
    lo, hi = scene.bounds
    o = rng.uniform(lo - 2, hi + 2, (n, 3)).astype(np.float32)
    target = scene.vertices[rng.integers(0, len(scene.vertices), n)]
    d = (target - o + rng.normal(0, 0.05, (n, 3))).astype(np.float32)
    return o, d


def test_a_posed_scene_moves_each_object_by_its_transform(scenes):
    base, posed, _ = scenes
    poses = _poses(len(base.objects))
    assert posed.transforms.shape == (len(base.objects), 4, 4)
    assert np.array_equal(posed.transforms, poses)
    assert base.transforms is None
    np.testing.assert_array_equal(posed.faces, base.faces)
    for k in range(len(base.objects)):
        idx = np.unique(base.faces[base.object_ids == k])
        moved = base.vertices[idx].astype(np.float64) @ poses[k][:3, :3].T + poses[k][:3, 3]
        np.testing.assert_allclose(posed.vertices[idx], moved, rtol=0, atol=1e-5)


def test_rays_on_a_posed_scene_match_the_same_geometry_built_flat(scenes):
    """The two-level tree traces the exact pose; the flat one its vertices rounded to float32:
    the same triangles but within that rounding of an edge, and ``t`` within a few ulps."""
    _, posed, flat = scenes
    assert ss.bvh_stats(posed)["instances"] == len(posed.objects)
    assert ss.bvh_stats(flat)["instances"] == 0
    o, d = _rays(posed)
    a, b = ss.cast_rays(posed, o, d), ss.cast_rays(flat, o, d)
    assert (a.triangle >= 0).mean() > 0.5
    assert (a.triangle != b.triangle).mean() <= 1e-4
    same = (a.triangle == b.triangle) & (a.triangle >= 0)
    np.testing.assert_allclose(a.t[same], b.t[same], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(a.barycentric[same], b.barycentric[same], atol=1e-3)
    assert (ss.occluded(posed, o, d) != ss.occluded(flat, o, d)).mean() <= 1e-4
    assert (ss.count_hits(posed, o, d) != ss.count_hits(flat, o, d)).mean() <= 1e-4


def _exact_closest(base, transforms, o, d):
    """The nearest triangle along each ray in float64 on the exact pose (each object's vertices
    as loaded moved by its transform in float64), edges included; -1 for none."""
    v = base.vertices.astype(np.float64)
    obj = np.zeros(len(v), dtype=np.int64)
    obj[base.faces.ravel()] = np.repeat(base.object_ids, 3)
    m = np.asarray(transforms)[obj]
    w = np.einsum("kij,kj->ki", m[:, :3, :3], v) + m[:, :3, 3]
    a, b, c = (w[base.faces[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    out = np.full(len(o), -1)
    for i, (oi, di) in enumerate(zip(o.astype(np.float64), d.astype(np.float64))):
        p = np.cross(di, e2)
        det = np.einsum("ij,ij->i", e1, p)
        tv = oi - a
        q = np.cross(tv, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.einsum("ij,ij->i", tv, p) / det
            v_ = (q @ di) / det
            t = np.einsum("ij,ij->i", e2, q) / det
        ok = (det != 0) & (u >= 0) & (v_ >= 0) & (u + v_ <= 1) & (t >= 0)
        if ok.any():
            out[i] = np.flatnonzero(ok)[np.argmin(t[ok])]
    return out


def test_a_far_translation_traces_the_exact_pose(scenes):
    """1e5 away, float32 rounds the posed vertices by 0.008, a twentieth of a triangle: the flat
    tree traces that rounded copy, the two-level tree the pose itself, and agrees with a
    float64 trace of the exact pose at least as often."""
    base, _, _ = scenes
    far = np.array([np.eye(4) for _ in base.objects])
    far[:, :3, 3] = [1e5, -1e5, 1e5]
    far[1] = far[1] @ _rotation([0, 1, 1], 0.8)
    posed = base.posed(far)
    flat = _flat(posed)
    o, d = _rays(posed, 1500, seed=5)
    a, b = ss.cast_rays(posed, o, d), ss.cast_rays(flat, o, d)
    assert (a.triangle >= 0).mean() > 0.3
    want = _exact_closest(base, far, o, d)
    two, one = (a.triangle == want).sum(), (b.triangle == want).sum()
    assert two >= one, (two, one)
    assert two >= 0.995 * len(o), two


def test_images_and_point_queries_match_flat(scenes):
    _, posed, flat = scenes
    cam = ss.Camera.look_at((0, -9, 5), (0, 0, 0), (0, 0, 1), yfov=0.9, width=96, height=80)
    for backend in ("cpu", "gpu"):
        a = ss.discretize(posed, cameras=[cam], backend=backend)
        b = ss.discretize(flat, cameras=[cam], backend=backend)
        assert (a.triangle >= 0).mean() > 0.3
        np.testing.assert_array_equal(a.triangle, b.triangle)
        np.testing.assert_array_equal(a.depth, b.depth)
    pts = np.random.default_rng(0).uniform(-5, 5, (3000, 3))
    ca, cb = ss.closest_points(posed, pts), ss.closest_points(flat, pts)
    np.testing.assert_array_equal(ca.triangle, cb.triangle)
    np.testing.assert_array_equal(ca.distance, cb.distance)
    np.testing.assert_array_equal(ss.winding_number(posed, pts), ss.winding_number(flat, pts))


def test_every_verb_runs_on_a_posed_scene():
    room = ss.scenes.reflective_room(spheres=3, seed=2, detail=2)
    moves = {
        f"sphere {k}": trimesh.transformations.translation_matrix([0.1 * k, 0, 0.05])
        for k in range(3)
    }
    posed = room.posed(moves)
    eye = ss.scenes.reflective_room_eye(48)
    flat = _flat(posed)
    for method in ("epr", "mvr"):
        a = ss.reflections(posed, eye, method=method)
        b = ss.reflections(flat, eye, method=method)
        np.testing.assert_array_equal(a.image, b.image)
    a = ss.omni_shadows(posed, eye, (0, 0, 1.8), 0.1, light_samples=4)
    b = ss.omni_shadows(flat, eye, (0, 0, 1.8), 0.1, light_samples=4)
    np.testing.assert_array_equal(a.visibility, b.visibility)
    fa, fb = ss.render(posed, eye, quality="fast"), ss.render(flat, eye, quality="fast")
    np.testing.assert_array_equal(fa.image, fb.image)
    imgs = ss.discretize(posed, cameras=[eye], method="nonredundant")
    assert ss.evaluate(imgs, ss.discretize(flat, cameras=[eye], method="nonredundant"))


def test_a_dict_names_objects_and_leaves_the_others(scenes):
    base, posed, _ = scenes
    up = trimesh.transformations.translation_matrix([0, 0, 1])
    by_name = posed.posed({base.objects[5]: up})
    by_index = posed.posed({5: up})
    np.testing.assert_array_equal(by_name.vertices, by_index.vertices)
    expect = posed.transforms.copy()
    expect[5] = up
    np.testing.assert_array_equal(by_name.transforms, expect)
    # Identity poses give the scene as loaded, bit for bit.
    same = base.posed(np.array([np.eye(4)] * len(base.objects)))
    np.testing.assert_array_equal(same.vertices, base.vertices)


def test_mirroring_flips_the_winding_as_the_flat_scene_does(scenes):
    _, posed, flat = scenes
    mirrored = posed.object_ids == 1
    np.testing.assert_array_equal(posed.faces[mirrored], flat.faces[mirrored])
    # A mirrored closed box alone: its winding number is -1 inside, as built flat.
    box = trimesh.creation.box(extents=(1.0, 0.6, 0.3))
    alone = ss.Scene.from_meshes([(box.vertices, box.faces)]).posed(_poses(7)[1:2])
    inside = np.array([[0.05, 0.02, 0.01]])
    assert ss.winding_number(alone, inside) == pytest.approx([-1.0])
    assert ss.winding_number(_flat(alone), inside) == pytest.approx([-1.0])


@pytest.mark.parametrize(
    "transforms, match",
    [
        ({"nobody": np.eye(4)}, "no object named"),
        ({99: np.eye(4)}, "no object 99"),
        ({0: np.full((4, 4), np.nan)}, "not finite"),
        ({0: np.diag([1.0, 0.0, 1.0, 1.0])}, "singular"),
        ({0: np.eye(3)}, "must be 4x4"),
        ({0: np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0.5, 0, 0, 1.0]])}, "not affine"),
        (
            {
                0: np.diag([1e38, 1e38, 1e38, 1.0])
                @ trimesh.transformations.translation_matrix([9, 9, 9])
            },
            "out of float32",
        ),
    ],
)
def test_bad_transforms_are_refused(scenes, transforms, match):
    base, _, _ = scenes
    with pytest.raises(ss.InputError, match=match):
        base.posed(transforms)


def test_a_wrong_number_of_transforms_is_refused(scenes):
    base, _, _ = scenes
    with pytest.raises(ss.InputError, match="one per object"):
        base.posed(np.array([np.eye(4)] * 2))


def test_the_same_poses_give_the_same_bits_in_another_process(scenes, tmp_path):
    code = textwrap.dedent(
        """
        import hashlib, sys
        import numpy as np
        sys.path.insert(0, sys.argv[1])
        import scenesample as ss
        from test_posed import _meshes, _poses, _rays
        parts, places = _meshes()
        posed = ss.Scene.from_meshes(parts, places).posed(_poses(len(parts)))
        o, d = _rays(posed)
        h = ss.cast_rays(posed, o, d)
        blob = h.t.tobytes() + h.triangle.tobytes() + h.barycentric.tobytes()
        print(hashlib.sha256(blob).hexdigest())
        """
    )
    here = str(__import__("pathlib").Path(__file__).parent)
    out = [
        subprocess.run(
            [sys.executable, "-c", code, here], capture_output=True, text=True, check=True
        ).stdout.strip()
        for _ in range(2)
    ]
    _, posed, _ = scenes
    o, d = _rays(posed)
    h = ss.cast_rays(posed, o, d)
    import hashlib

    mine = hashlib.sha256(
        h.t.tobytes() + h.triangle.tobytes() + h.barycentric.tobytes()
    ).hexdigest()
    assert out == [mine, mine]


def _posed_hits_hash(k: int) -> str:
    """A fork pool's work: pose the module's scene (its object trees built in the parent before
    the fork) with the poses of frame `k`, cast the rays, hash the hits."""
    import hashlib

    poses = _poses(len(_FORKED["parts"]))
    poses[2] = _rotation([1, 1, 0], 1.1 + 0.3 * k)
    poses[3] = trimesh.transformations.translation_matrix([0, 0.2 * k, 0.5])
    posed = _FORKED["base"].posed(poses)
    o, d = _rays(posed)
    h = ss.cast_rays(posed, o, d)
    return hashlib.sha256(
        h.t.tobytes() + h.triangle.tobytes() + h.barycentric.tobytes()
    ).hexdigest()


_FORKED: dict = {}


def test_poses_in_forked_workers_give_the_parents_bits():
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    parts, places = _meshes()
    _FORKED.update(base=ss.Scene.from_meshes(parts, places), parts=parts)
    mine = [_posed_hits_hash(k) for k in range(3)]  # builds and caches the object trees
    ex = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("fork"))
    try:
        theirs = list(ex.map(_posed_hits_hash, [2, 1, 0, 1]))
    finally:
        ex.shutdown()
        _FORKED.clear()
    assert theirs == [mine[2], mine[1], mine[0], mine[1]]
    assert len(set(mine)) == 3


def test_evaluate_a_sequence_reports_error_and_flicker_per_frame():
    rng = np.random.default_rng(4)
    ref = [rng.uniform(0, 1, (16, 16, 3)) for _ in range(4)]
    same = ss.evaluate(ref, ref, "image")
    assert same["overall"]["rmse"] == 0 and same["overall"]["flicker"] == 0
    assert np.isnan(same["flicker"][0]) and len(same["per_frame"]) == 4
    assert same["overall"]["reference_change"] > 0
    # A steady error does not flicker; an error that jumps does.
    steady = ss.evaluate([np.clip(r * 0.5, 0, 1) for r in ref], ref, "image")
    noisy = ss.evaluate([rng.uniform(0, 1, (16, 16, 3)) for _ in ref], ref, "image")
    assert steady["overall"]["rmse"] > 0
    assert noisy["overall"]["flicker"] > 2 * steady["overall"]["flicker"]
    with pytest.raises(ss.InputError, match="as many reference frames"):
        ss.evaluate(ref, ref[:2], "image")


def test_the_animation_experiment_runs_every_method_on_every_frame(tmp_path):
    from scenesample.tools.experiments import epr_animation

    epr_animation.main(["--quick", "--out", str(tmp_path)])
    md = (tmp_path / "epr_animation.md").read_text()
    for m in ("EPR", "MVR", "IVIR"):
        assert f"| {m} |" in md
    rows = (tmp_path / "epr_animation.csv").read_text().splitlines()
    assert len(rows) == 1 + 3 * 6


def _same_arrays(a, b, what, differ=0.0):
    """Every array field of two results equal (timings aside), but for at most a fraction
    ``differ`` of each one's entries; returns how many compared."""
    fields = {k: v for k, v in vars(a).items() if not k.startswith("_") and k != "timings"}
    n = 0
    for k, v in fields.items():
        if isinstance(v, np.ndarray):
            if differ == 0.0:
                np.testing.assert_array_equal(v, getattr(b, k), err_msg=f"{what}.{k}")
            else:
                assert v.shape == getattr(b, k).shape, f"{what}.{k}"
                assert (v != getattr(b, k)).mean() <= differ, f"{what}.{k}"
            n += 1
    return n


def test_peeling_the_field_impostors_and_epr_points_match_flat(scenes):
    """The methods the other posed tests do not compare: each on the posed scene gives what it
    gives on the same geometry built flat, array for array."""
    _, posed, flat = scenes
    cam = ss.Camera.look_at((0, -9, 5), (0, 0, 0), (0, 0, 1), yfov=0.9, width=64, height=48)
    runs = {
        "peeling": lambda s: ss.discretize(s, [cam], method="peeling", layers=3),
        "epr": lambda s: ss.discretize(
            s, method="epr", eye=cam, reflectors=list(s.objects[0:4:2]), progress=False
        ),
        "impostors": lambda s: ss.discretize(
            s, method="impostors", octree_depth=1, resolution=16, progress=False
        ),
    }
    for name, run in runs.items():
        assert _same_arrays(run(posed), run(flat), name) > 0, name
    fields = [
        ss.discretize(s, method="visibility_field", quality="fast", progress=False)
        for s in (posed, flat)
    ]
    # The field's samples are rays: the same but within float32's rounding of an edge.
    assert _same_arrays(*fields, "visibility_field", differ=1e-5) > 0
    views = [ss.reconstruct(f, cam, backend="cpu") for f in fields]
    np.testing.assert_array_equal(views[0].marked, views[1].marked)
    np.testing.assert_array_equal(views[0].image.triangle, views[1].image.triangle)
    np.testing.assert_array_equal(views[0].image.depth, views[1].image.depth)


def test_a_posed_scene_pickles_as_its_base_and_transforms(scenes):
    """A posed scene sent to another process (a sweep's workers) is posed again there: the same
    geometry and rays, the same transforms, and a further pose maps the objects as loaded, as in
    the parent (not the posed geometry as if it were loaded)."""
    import pickle

    base, posed, _ = scenes
    back = pickle.loads(pickle.dumps(posed))
    np.testing.assert_array_equal(back.transforms, posed.transforms)
    np.testing.assert_array_equal(back.vertices, posed.vertices)
    np.testing.assert_array_equal(back.faces, posed.faces)
    o, d = _rays(posed, 5_000)
    a, b = ss.cast_rays(posed, o, d), ss.cast_rays(back, o, d)
    np.testing.assert_array_equal(a.triangle, b.triangle)
    np.testing.assert_array_equal(a.t, b.t)
    lift = np.eye(4)
    lift[2, 3] = 1.0
    again, there = posed.posed({0: lift}), back.posed({0: lift})
    np.testing.assert_array_equal(there.vertices, again.vertices)
    np.testing.assert_array_equal(there.transforms, again.transforms)
    # A scene as loaded still pickles as its arrays.
    assert pickle.loads(pickle.dumps(base)).transforms is None


def _wave(v, amplitude=0.3):
    """A smooth deformation: every vertex lifted by a wave over x and y and sheared a little."""
    v = np.asarray(v, np.float64)
    lift = amplitude * np.sin(1.3 * v[:, 0]) * np.cos(0.9 * v[:, 1])
    return (v + np.stack([0.1 * v[:, 2], 0 * lift, lift], 1)).astype(np.float32)


@pytest.mark.parametrize("posed_first", [False, True])
def test_a_deformed_scene_matches_the_same_geometry_built_flat(scenes, posed_first):
    """Rays, images and point queries on a deformed scene (its tree refit) against the same
    vertices built flat; of a scene as loaded and of a posed one (refit from its base)."""
    base, posed, _ = scenes
    source = posed if posed_first else base
    deformed = source.deformed(_wave(source.vertices))
    flat = _flat(deformed)
    assert deformed.transforms is None and deformed.normals is None
    np.testing.assert_array_equal(deformed.faces, source.faces)
    np.testing.assert_array_equal(deformed.object_ids, source.object_ids)
    o, d = _rays(deformed)
    a, b = ss.cast_rays(deformed, o, d), ss.cast_rays(flat, o, d)
    assert (a.triangle >= 0).mean() > 0.5
    np.testing.assert_array_equal(a.triangle, b.triangle)
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(ss.occluded(deformed, o, d), ss.occluded(flat, o, d))
    cam = ss.Camera.look_at((0, -9, 5), (0, 0, 0), (0, 0, 1), yfov=0.9, width=96, height=80)
    ia = ss.discretize(deformed, cameras=[cam], backend="cpu")
    ib = ss.discretize(flat, cameras=[cam], backend="cpu")
    np.testing.assert_array_equal(ia.triangle, ib.triangle)
    pts = np.random.default_rng(1).uniform(-5, 5, (2000, 3))
    ca, cb = ss.closest_points(deformed, pts), ss.closest_points(flat, pts)
    np.testing.assert_array_equal(ca.triangle, cb.triangle)


def test_a_deformation_that_scatters_the_tree_is_built_afresh(scenes):
    """Refit while the tree keeps its quality (a wave: surface-area cost within 1.3x the rest
    pose's, a tree unlike a fresh build's); built afresh when the vertices are scattered (the
    same tree as a fresh build, and the same hits either way)."""
    base, _, _ = scenes
    gentle = base.deformed(_wave(base.vertices))
    rest = ss.bvh_stats(base)["sah"]
    refit = ss.bvh_stats(gentle)
    assert refit["sah"] <= 1.3 * rest
    assert refit["sah"] != ss.bvh_stats(_flat(gentle))["sah"]
    rng = np.random.default_rng(2)
    scattered = base.deformed(base.vertices[rng.permutation(len(base.vertices))])
    fresh = _flat(scattered)
    assert ss.bvh_stats(scattered)["sah"] == ss.bvh_stats(fresh)["sah"]
    o, d = _rays(scattered, 20_000)
    np.testing.assert_array_equal(
        ss.cast_rays(scattered, o, d).triangle, ss.cast_rays(fresh, o, d).triangle
    )


@pytest.mark.parametrize(
    "vertices, match",
    [
        (np.zeros((5, 3)), r"shape \(\d+, 3\) \(one per vertex\), got \(5, 3\)"),
        ("soft", "vertices must be numbers"),
        ([[0, 0], [1]], "vertices must be numbers"),
    ],
)
def test_bad_deformations_are_refused(scenes, vertices, match):
    base, _, _ = scenes
    with pytest.raises(ss.InputError, match=match):
        base.deformed(vertices)
    v = base.vertices.copy()
    v[3, 1] = np.nan
    with pytest.raises(ss.InputError, match="deformed vertex 3 is not finite"):
        base.deformed(v)
    with pytest.raises(ss.InputError, match="normals must have shape"):
        base.deformed(base.vertices, normals=np.zeros((2, 3)))


def test_deformed_refuses_complex_numbers_and_zero_normals():
    """A complex array lost its imaginary part silently, and a zero normal (no direction to
    shade with) was accepted."""
    scene = ss.Scene.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    v = scene.vertices
    with pytest.raises(ss.InputError, match="vertices must be real numbers"):
        scene.deformed(v + 1j)
    with pytest.raises(ss.InputError, match="normals must be real numbers"):
        scene.deformed(v, normals=np.ones((3, 3)) * (1 + 1j))
    normals = np.tile([0.0, 0.0, 1.0], (3, 1))
    normals[1] = 0
    with pytest.raises(ss.InputError, match="deformed normal 1 is zero"):
        scene.deformed(v, normals=normals)
    with pytest.raises(ss.InputError, match="the transform of 0 must be real numbers"):
        scene.posed({0: np.eye(4) * 1j})
    assert scene.deformed(v + 1, normals=np.tile([0.0, 0.0, 1.0], (3, 1))).normals is not None
