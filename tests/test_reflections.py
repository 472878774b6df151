"""Cube-mapped reflections by EPR, MVR and iVIR (eye-based-point-rendering.txt §4): the three
agree with each other and with the 4x MVR reference, EPR leaves no holes where MVR sees a
surface, EPR shades far fewer texels, and bad input fails clearly."""

from __future__ import annotations

import numpy as np
import pytest
import scenesample as ss


@pytest.fixture(scope="module")
def room():
    scene = ss.scenes.reflective_room(spheres=4, seed=1, detail=3)
    eye = ss.scenes.reflective_room_eye(96)
    return scene, eye


@pytest.fixture(scope="module")
def results(room):
    scene, eye = room
    out = {m: ss.reflections(scene, eye, method=m) for m in ("epr", "mvr", "ivir")}
    out["ref"] = ss.reflection_reference(scene, eye)
    return out


def test_default_reflectors_are_the_mirror_spheres(room):
    scene, _ = room
    refl = ss.epr.reflectors_of(scene)
    assert [r.name for r in refl] == [f"sphere {k}" for k in range(4)]
    for r in refl:
        pts = scene.vertices[scene.faces[r.triangles].reshape(-1)]
        assert np.linalg.norm(pts - r.center, axis=1).max() <= r.radius * (1 + 1e-6)


def test_the_three_methods_agree_with_the_reference(results):
    """On the mirror pixels each method is within 20/255 RMSE of the 4x MVR reference, and EPR
    within 5/255 of MVR's own RMSE; over the whole image (where the reference's anti-aliased
    edges dominate, ~9/255 for all three at 96²) EPR is within 1/255 of MVR. The paper reports
    EPR within 0.07% of 255 of MVR at 1080p, where mirrors span hundreds of pixels, not ~10."""
    ref = results["ref"]
    errs = {m: ss.evaluate(results[m], ref) for m in ("epr", "mvr", "ivir")}
    for m, e in errs.items():
        assert e["rmse_reflective"] < 20, (m, e["rmse_reflective"])
        assert e["rmse"] < 12, (m, e["rmse"])
    assert errs["epr"]["rmse_reflective"] < errs["mvr"]["rmse_reflective"] + 5
    assert errs["epr"]["rmse"] < errs["mvr"]["rmse"] + 1
    # Outside the mirrors all three shade the same surfaces the same way.
    still = ~results["mvr"].reflective
    a = results["epr"].to_srgb8()[still].astype(int)
    b = results["mvr"].to_srgb8()[still].astype(int)
    assert np.abs(a - b).max() <= 1


def test_epr_leaves_no_holes_where_mvr_sees_a_surface(room):
    """Every texel of a cube face that rasterization covers holds a splatted point."""
    scene, eye = room
    pts = ss.discretize(scene, method="epr", eye=eye)
    b = ss.splat(pts, resolution=48)
    cams = [c.with_resolution(48, 48) for c in pts.cameras]
    raster = ss.discretize(scene, cams)
    # Rasterization of the cube faces without their near plane sees the reflector itself and
    # what lies inside its sphere; compare beyond the near plane only.
    beyond = np.isfinite(raster.depth) & (
        raster.depth >= np.array([c.znear for c in cams])[:, None, None]
    )
    holes = beyond & (b.index < 0)
    assert holes.sum() <= 0.002 * beyond.sum(), holes.sum() / beyond.sum()


def test_epr_shades_far_fewer_texels_and_keeps_fewer_points(results):
    epr, mvr, ivir = results["epr"], results["mvr"], results["ivir"]
    assert epr.stats["shading_ops"] * 10 < mvr.stats["shading_ops"]
    assert epr.stats["points"] < ivir.stats["points"]
    assert epr.stats["reflective_pixels"] == mvr.stats["reflective_pixels"] > 100
    for r in (epr, mvr, ivir):
        assert np.isfinite(r.image).all() and (r.image >= 0).all()
        assert set(r.timings) >= {"eye", "views", "deferred", "total"}


def test_second_bounce_changes_only_mirror_pixels_seeing_mirrors(room):
    scene, eye = room
    one = ss.reflections(scene, eye, method="epr", bounces=1)
    two = ss.reflections(scene, eye, method="epr", bounces=2)
    changed = np.any(one.image != two.image, axis=2)
    assert not changed[~one.reflective].any()
    # Some mirror pixels see another sphere: the second bounce changes them and costs shading.
    assert changed.sum() > 10
    assert two.stats["shading_ops"] > one.stats["shading_ops"]
    mvr2 = ss.reflections(scene, eye, method="mvr", bounces=2)
    assert mvr2.stats["shading_ops"] > ss.reflections(scene, eye, method="mvr").stats["shading_ops"]


def test_results_are_deterministic(room):
    scene, eye = room
    a = ss.reflections(scene, eye, method="epr", seed=2)
    b = ss.reflections(scene, eye, method="epr", seed=2)
    assert np.array_equal(a.image, b.image)


def test_adaptive_resolution_follows_the_reflector_and_moves_in_steps():
    scene = ss.scenes.reflective_room(spheres=1)
    refl = ss.epr.reflectors_of(scene)[0]
    near = ss.scenes.reflective_room_eye(512, distance=2.0)
    far = ss.scenes.reflective_room_eye(512, distance=6.0)
    a, b = ss.cube_resolution(near, refl), ss.cube_resolution(far, refl)
    assert 8 <= b < a <= 256
    assert ss.cube_resolution(far, refl, previous=b + 31) == b + 31
    assert ss.cube_resolution(far, refl, previous=b + 32) == b


def test_bad_input(room):
    scene, eye = room
    with pytest.raises(ss.InputError, match="method"):
        ss.reflections(scene, eye, method="raytrace")
    with pytest.raises(ss.InputError, match="bounces"):
        ss.reflections(scene, eye, bounces=0)
    with pytest.raises(ss.InputError, match="supersample"):
        ss.reflections(scene, eye, supersample=0)
    with pytest.raises(ss.InputError, match="reflective object"):
        ss.reflections(ss.scenes.grass(blades=10), eye)
    with pytest.raises(ss.InputError, match="no object named"):
        ss.reflections(scene, eye, reflectors=["teapot"])
    with pytest.raises(ss.InputError, match="shape"):
        ss.evaluate(np.zeros((4, 4, 3)), np.zeros((5, 4, 3)), "image")


def test_epr_experiment_writes_tables_and_figures(tmp_path):
    from scenesample.tools.experiments import epr

    epr.main(
        ["--spheres", "1", "2", "--resolution", "48", "--rho", "0.5", "--distances", "3.2"]
        + ["--figure-spheres", "2", "--out", str(tmp_path)]
        + ["--light-samples", "1", "3", "--shadow-spheres", "2", "--shadow-max-resolution", "64"]
    )
    md = (tmp_path / "epr.md").read_text()
    assert "| 2 | " in md and "| epr |" in md and "| mvr |" in md and "| ivir |" in md
    assert len((tmp_path / "epr.csv").read_text().splitlines()) == 1 + 2 * 3
    assert (tmp_path / "fig6.png").stat().st_size > 1000
    assert (tmp_path / "fig7.png").stat().st_size > 1000
    assert "Table 3 analogue" in md
    assert len((tmp_path / "table3.csv").read_text().splitlines()) == 1 + 2 * 3
    assert (tmp_path / "fig10.png").stat().st_size > 300


def _mirror_between_walls(double_sided_left: bool) -> ss.Scene:
    """A mirror sphere between two walls that turn their backs to it: red on the left
    (single-sided unless ``double_sided_left``), green on the right (double-sided), each
    material stated, so the left wall is the only thing sidedness can hide."""
    unit_v, unit_f = ss.scenes._icosphere_arrays(3)
    verts = [0.5 * unit_v]
    faces = [unit_f]
    mats = [np.zeros(len(unit_f), dtype=np.int64)]
    # Vertical walls at x = -1.5 (normal -x) and x = +1.5 (normal +x): fronts face away.
    for x, m in ((-1.5, 1), (1.5, 2)):
        base = sum(len(v) for v in verts)
        v = np.array([[x, -1.5, -1.5], [x, 1.5, -1.5], [x, 1.5, 1.5], [x, -1.5, 1.5]])
        f = np.array([[0, 1, 2], [0, 2, 3]]) if x > 0 else np.array([[0, 2, 1], [0, 3, 2]])
        verts.append(v)
        faces.append(f + base)
        mats.append(np.full(2, m))
    colors = np.ones((sum(len(v) for v in verts), 3))
    colors[len(unit_v) : len(unit_v) + 4] = (0.9, 0.05, 0.05)
    colors[len(unit_v) + 4 :] = (0.05, 0.9, 0.05)
    return ss.Scene.from_arrays(
        np.concatenate(verts),
        np.concatenate(faces),
        colors=colors,
        material_ids=np.concatenate(mats),
        materials=[
            {"name": "mirror", "metallic": 1.0, "roughness": 0.0},
            {"name": "left", "metallic": 0.0, "roughness": 0.8, "double_sided": double_sided_left},
            {"name": "right", "metallic": 0.0, "roughness": 0.8, "double_sided": True},
        ],
    )


@pytest.mark.parametrize("method", ["epr", "mvr", "ivir"])
def test_mirrors_follow_the_materials_sidedness(gpu, method):
    """glTF sidedness in the cube maps, the same for all three methods: the back of a
    single-sided wall never shows in the mirror, the back of a double-sided one does. The
    scene mixes both kinds, so MVR takes its two-draw path (culled and unculled, merged)."""
    eye = ss.Camera.look_at((0, -3, 0), (0, 0, 0), (0, 0, 1), yfov=0.5, width=64, height=64)

    def tint(double_sided_left: bool) -> tuple[int, int]:
        r = ss.reflections(_mirror_between_walls(double_sided_left), eye, method=method)
        rgb = r.image[r.reflective]
        red = (rgb[:, 0] > 0.02) & (rgb[:, 0] > 4 * rgb[:, 1])
        green = (rgb[:, 1] > 0.02) & (rgb[:, 1] > 4 * rgb[:, 0])
        return int(red.sum()), int(green.sum())

    red, green = tint(False)
    assert red == 0 and green > 20, (red, green)
    red, green = tint(True)
    assert red > 20 and green > 20, (red, green)


def test_reflective_room_is_wound_like_its_normals():
    """Its materials are single-sided, so a triangle wound against its normal would vanish from
    the cube maps: every triangle's winding agrees with its vertex normals."""
    scene = ss.scenes.reflective_room(spheres=6, seed=2, detail=1)
    v = scene.vertices.astype(np.float64)
    f = scene.faces
    wound = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    stated = scene.normals[f].sum(axis=1)
    assert ((wound * stated).sum(axis=1) > 0).all()
    assert not any(m["double_sided"] for m in scene.materials)
