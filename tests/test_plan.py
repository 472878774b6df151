"""Only the effects a scene calls for: the planner reads lights, emissive objects and mirror
materials; render computes exactly the planned effects, and the operation counters prove it."""

from __future__ import annotations

import numpy as np
import pytest
import scenesample as ss

MIRROR = {"name": "mirror", "base_color": [0.9, 0.9, 0.9, 1], "metallic": 1.0, "roughness": 0.05}
MATTE = {"name": "matte", "base_color": [0.7, 0.6, 0.5, 1], "metallic": 0.0, "roughness": 0.8}


def room(mirror_sphere: bool = False, lights=None) -> ss.Scene:
    """A floor with two boxes (matte), and optionally one mirror sphere."""
    parts_v, parts_f, mats, objs = [], [], [], []

    def add(v, f, mat, obj):
        base = sum(len(x) for x in parts_v)
        parts_v.append(np.asarray(v, dtype=np.float32))
        parts_f.append(np.asarray(f) + base)
        mats.append(np.full(len(f), mat))
        objs.append(np.full(len(f), obj))

    add([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], [[0, 1, 2], [0, 2, 3]], 1, 0)
    cube = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
    cf = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
          [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]  # fmt: skip
    add(cube * 0.5 + [-1, -0.5, 0], cf, 1, 1)
    add(cube * [0.4, 0.4, 0.8] + [0.6, 0.3, 0], cf, 1, 2)
    names = ["floor", "box a", "box b"]
    if mirror_sphere:
        s = ss.scenes.icosphere(2, radius=0.3, center=(0.0, -1.0, 0.3))
        add(s.vertices, s.faces, 0, 3)
        names.append("sphere")
    return ss.Scene.from_arrays(
        np.concatenate(parts_v),
        np.concatenate(parts_f),
        material_ids=np.concatenate(mats),
        materials=[MIRROR, MATTE],
        object_ids=np.concatenate(objs),
        objects=names,
        lights=lights,
    )


EYE = ss.Camera.look_at((0.5, -4.0, 2.5), (0, 0, 0.3), (0, 0, 1), yfov=0.8, width=64, height=64)
POINT = {"type": "point", "name": "bulb", "position": [0.2, 0.3, 1.6], "intensity": 5.0}


def test_a_plain_scene_calls_for_nothing_and_runs_nothing():
    scene = room()
    assert ss.plan(scene) == []
    frame = ss.render(scene, EYE)
    for k in ("cube_maps", "splat_passes", "shadow_views", "rays_cast"):
        assert frame.stats[k] == 0, (k, frame.stats)
    assert frame.effects == {} and frame.stats["effects_run"] == 0
    assert frame.image.shape == (64, 64, 3) and np.isfinite(frame.image).all()
    assert frame.image.max() > 0.05  # the default light lit it


def test_one_metallic_sphere_adds_exactly_one_reflector():
    plain, mirrored = room(), room(mirror_sphere=True)
    assert [e.kind for e in ss.plan(plain)] == []
    effects = ss.plan(mirrored)
    assert [e.kind for e in effects] == ["reflections"]
    assert [r.name for r in effects[0].params["reflectors"]] == ["sphere"]
    assert "metallic" in effects[0].reason
    frame = ss.render(mirrored, EYE, quality="fast")
    assert frame.stats["reflectors"] == 1 and frame.stats["cube_maps"] == 1
    assert frame.stats["splat_passes"] >= 1
    assert frame.stats["shadow_views"] == 0 and frame.stats["rays_cast"] == 0
    result = frame.effects[effects[0].name]
    assert result.reflective.any()
    np.testing.assert_array_equal(frame.image[result.reflective], result.image[result.reflective])


def test_a_point_light_calls_for_omnidirectional_shadows_only():
    scene = room(lights=[POINT])
    effects = ss.plan(scene, quality="fast")
    assert [e.kind for e in effects] == ["omni_shadows"]
    assert "bulb" in effects[0].source
    frame = ss.render(scene, EYE, quality="fast")  # MVR: six shadow views per sample
    assert frame.stats["shadow_views"] == 6 and frame.stats["cube_maps"] == 0
    assert frame.stats["splat_passes"] == 0
    shadow = frame.effects[effects[0].name]
    # Something is in shadow: the boxes hide part of the floor from the bulb.
    assert (shadow.visibility[shadow.mask] < 1).mean() > 0.02
    # Shadowed floor pixels are darker than lit ones in the frame.
    lit = shadow.mask & (shadow.visibility == 1)
    dark = shadow.mask & (shadow.visibility == 0)
    assert frame.image[dark].mean() < frame.image[lit].mean()


def test_effects_can_be_narrowed_and_names_checked():
    scene = room(mirror_sphere=True, lights=[POINT])
    kinds = sorted(e.kind for e in ss.plan(scene))
    assert kinds == ["omni_shadows", "reflections"]
    frame = ss.render(scene, EYE, quality="fast", effects=["omni_shadows"])
    assert frame.stats["cube_maps"] == 0 and frame.stats["shadow_views"] == 6
    with pytest.raises(ss.InputError, match="unknown effect"):
        ss.render(scene, EYE, effects=["caustics"])


def test_emissive_and_user_area_lights_call_for_soft_shadows():
    glow = dict(MATTE, name="glow", emissive=[1, 1, 1])
    base = room()
    v = np.concatenate(
        [base.vertices, [[-0.3, -0.3, 1.8], [0.3, -0.3, 1.8], [0.3, 0.3, 1.8], [-0.3, 0.3, 1.8]]]
    )
    n = len(base.vertices)
    f = np.concatenate([base.faces, [[n, n + 1, n + 2], [n, n + 2, n + 3]]])
    scene = ss.Scene.from_arrays(
        v,
        f,
        material_ids=np.concatenate([np.ones(len(base.faces), int), [2, 2]]),
        materials=[MIRROR, MATTE, glow],
        object_ids=np.concatenate([base.object_ids, [3, 3]]),
        objects=base.objects + ["lamp"],
    )
    effects = ss.plan(scene)
    assert [e.kind for e in effects] == ["soft_shadows"] and "lamp" in effects[0].source
    light = effects[0].params["light"]
    np.testing.assert_allclose(light.center, (0, 0, 1.8), atol=1e-6)
    assert abs(light.diagonal - np.sqrt(0.6**2 + 0.6**2)) < 1e-6
    extra = ss.AreaLight((0, 0, 3.0), (1, 0, 0), (0, 1, 0))
    both = ss.plan(room(), area_lights=[extra])
    assert [e.kind for e in both] == ["soft_shadows"] and "user" in both[0].reason
    # The cheaper way on this machine's cost model is run, never one that loses.
    chosen = ss.plan(room(), area_lights=[extra], camera=EYE, quality="fast")[0]
    costs = chosen.params["estimated_seconds"]
    method = chosen.params["discretization"]
    assert costs[method] == min(costs.values()) == chosen.estimate["seconds"]
    assert method in chosen.reason
    frame = ss.render(room(), EYE, quality="fast", area_lights=[extra])
    if method == "raytraced":
        # One occlusion ray per pixel and light sample; nothing rasterized from the light.
        assert frame.stats["shadow_views"] == 0
        assert 0 < frame.stats["rays_cast"] <= 16 * EYE.width * EYE.height
    else:
        # Rasterized: the only rays are non-redundant rendering's walks past the boxes'
        # bottoms, which lie on the floor (coincident triangles), a sliver of the 16 views.
        assert frame.stats["shadow_views"] == 16
        assert frame.stats["rays_cast"] < 0.01 * 16 * 256**2


def test_the_planner_estimates_cost_before_running():
    scene = room(mirror_sphere=True, lights=[POINT])
    est = {
        q: sum(e.estimate["seconds"] for e in ss.plan(scene, quality=q)) for q in ss._plan.QUALITY
    }
    assert 0 < est["fast"] < est["balanced"] < est["high"] < 1e4
    for e in ss.plan(scene, camera=EYE):
        assert e.estimate["work"] and all(v > 0 for v in e.estimate["work"].values())
    frame = ss.render(scene, EYE, quality="fast")
    for name, s in frame.stats["effects"].items():
        assert s["estimated_seconds"] > 0 and s["seconds"] >= 0, name


def test_bad_input_is_refused():
    with pytest.raises(ss.InputError, match="quality"):
        ss.plan(room(), quality="ultra")
    with pytest.raises(ss.InputError, match="Camera"):
        ss.render(room(), "eye")
    with pytest.raises(ss.InputError, match="light type"):
        room(lights=[{"type": "laser", "position": [0, 0, 1]}])


def test_stats_are_per_call_when_two_renders_run_at_once():
    """Each frame reports what its own call ran, not process-wide counter differences."""
    from concurrent.futures import ThreadPoolExecutor

    mirrored, lit = room(mirror_sphere=True), room(lights=[POINT])
    alone = {
        "mirrored": ss.render(mirrored, EYE, quality="fast").stats,
        "lit": ss.render(lit, EYE, quality="fast").stats,
    }
    keys = ("cube_maps", "splat_passes", "shadow_views", "rays_cast")
    with ThreadPoolExecutor(2) as pool:
        for _ in range(2):
            a = pool.submit(ss.render, mirrored, EYE, quality="fast")
            b = pool.submit(ss.render, lit, EYE, quality="fast")
            for name, f in (("mirrored", a), ("lit", b)):
                got = f.result().stats
                assert {k: got[k] for k in keys} == {k: alone[name][k] for k in keys}, name
    assert alone["mirrored"]["shadow_views"] == 0 and alone["lit"]["cube_maps"] == 0


def test_a_finely_tessellated_emissive_object_gets_its_smallest_rectangle():
    """A disc of 4000 triangles: the light is the square around it (side = diameter), found
    from the hull of its vertices (trying every triangle edge took minutes on real scenes)."""
    from scenesample._plan import emissive_lights

    n = 4000
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rim = np.stack([np.cos(a), np.sin(a), np.full(n, 2.0)], axis=1)
    verts = np.concatenate([[[0.0, 0.0, 2.0]], rim]).astype(np.float32)
    faces = np.array([[0, 1 + i, 1 + (i + 1) % n] for i in range(n)], dtype=np.uint32)
    glow = dict(MATTE, name="glow", emissive=[1, 1, 1])
    disc = ss.Scene.from_arrays(verts, faces, material_ids=np.zeros(n, np.int32), materials=[glow])
    [(_, light)] = emissive_lights(disc)
    u, v = np.asarray(light.u), np.asarray(light.v)
    assert abs(np.linalg.norm(u) * np.linalg.norm(v) - 4.0) < 0.01
    np.testing.assert_allclose(light.center, [0, 0, 2], atol=1e-6)
    local = (verts - np.asarray(light.center)) @ np.stack([u, v], 1)
    assert (np.abs(local) <= np.array([u @ u, v @ v]) / 2 + 1e-6).all()
