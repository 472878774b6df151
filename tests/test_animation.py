"""glTF node animations (``Scene.animations``, ``Scene.at``): each interpolation against poses
computed by hand at keys and between them, clamping outside a clip, a parent's animation
carrying its child, and bad input."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import scenesample as ss
from gltf_builder import add_accessor, document, write

TRI = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
ROOT = np.array([10.0, 0.0, 0.0])


def _animated(tmp_path, lit=False):
    """The triangle on node 0, a child of node 1 (translated by ROOT), with three clips; `lit`:
    a spot light and a camera on node 2, also a child of node 1, one unit along x from it and
    turned 90 degrees about x (its -Z along +y)."""
    doc = document(TRI)
    doc["nodes"] = [{"mesh": 0, "name": "tri"}, {"children": [0], "translation": list(ROOT)}]
    doc["scenes"] = [{"nodes": [1]}]
    if lit:
        doc["nodes"][1]["children"].append(2)
        doc["nodes"].append(
            {
                "translation": [1, 0, 0],
                "rotation": [np.sin(np.pi / 4), 0, 0, np.cos(np.pi / 4)],
                "camera": 0,
                "extensions": {"KHR_lights_punctual": {"light": 0}},
            }
        )
        doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}]
        doc["extensionsUsed"] = ["KHR_lights_punctual"]
        doc["extensions"] = {
            "KHR_lights_punctual": {"lights": [{"type": "spot", "name": "s", "spot": {}}]}
        }

    def sampler(times, values, kind, interpolation):
        i = add_accessor(doc, np.asarray(times, np.float32)[:, None], "SCALAR")
        o = add_accessor(doc, np.asarray(values, np.float32), kind)
        return {"input": i, "output": o, "interpolation": interpolation}

    z, one, three = [0, 0, 0], [1, 1, 1], [3, 3, 3]
    quarter = [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]
    clips = [
        ("move", 0, "translation", sampler([0, 1, 2], [z, [1, 0, 0], [1, 2, 0]], "VEC3", "LINEAR")),
        ("turn", 1, "rotation", sampler([0, 1], [[0, 0, 0, 1], quarter], "VEC4", "STEP")),
        ("grow", 0, "scale", sampler([0, 2], [z, one, z, z, three, z], "VEC3", "CUBICSPLINE")),
        ("spin", 1, "rotation", sampler([0, 2], [[0, 0, 0, 1], quarter], "VEC4", "LINEAR")),
    ]
    doc["animations"] = [
        {
            "name": name,
            "samplers": [s],
            "channels": [{"sampler": 0, "target": {"node": node, "path": path}}],
        }
        for name, node, path, s in clips
    ]
    # The accessors' buffers are data URIs of their own; byteLength must match each.
    return ss.Scene.load(write(doc, tmp_path / "animated.gltf"))


def _rz(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@pytest.fixture
def scene(tmp_path):
    return _animated(tmp_path)


def test_clips_are_listed_with_their_durations(scene):
    assert scene.animations == [("move", 2.0), ("turn", 1.0), ("grow", 2.0), ("spin", 2.0)]
    np.testing.assert_allclose(scene.vertices, TRI + ROOT)


@pytest.mark.parametrize(
    "clip, t, expect",
    [
        ("move", 0.0, TRI + ROOT),
        ("move", 0.5, TRI + ROOT + [0.5, 0, 0]),
        ("move", 1.0, TRI + ROOT + [1, 0, 0]),
        ("move", 1.5, TRI + ROOT + [1, 1, 0]),
        ("move", 99.0, TRI + ROOT + [1, 2, 0]),  # clamped to the last key
        ("move", -3.0, TRI + ROOT),  # and to the first
        ("turn", 0.99, TRI + ROOT),  # STEP holds the key before
        ("turn", 1.0, TRI @ _rz(np.pi / 2).T + ROOT),
        ("grow", 1.0, 2 * TRI + ROOT),  # zero tangents: smoothstep(0.5) = 0.5 of the way
        ("grow", 0.5, (1 + 2 * (3 * 0.0625 - 2 * 0.015625)) * TRI + ROOT),
        ("grow", 2.0, 3 * TRI + ROOT),
        ("spin", 1.0, TRI @ _rz(np.pi / 4).T + ROOT),  # slerp halfway: an eighth turn
    ],
)
def test_each_interpolation_at_keys_and_between(scene, clip, t, expect):
    posed = scene.at(t, clip)
    np.testing.assert_allclose(posed.vertices, expect, atol=2e-6)


def test_a_clip_by_index_equals_it_by_name(scene):
    np.testing.assert_array_equal(scene.at(0.7, 3).vertices, scene.at(0.7, "spin").vertices)
    # A posed scene animates from the scene as loaded.
    np.testing.assert_array_equal(
        scene.at(1.0, "move").at(0.7, 3).vertices, scene.at(0.7, 3).vertices
    )


def test_rays_see_the_animated_triangle(scene):
    posed = scene.at(1.5, "move")
    hit = ss.cast_rays(posed, [[11.2, 1.2, 5]], [[0, 0, -1]])
    assert hit.triangle[0] == 0 and hit.t[0] == pytest.approx(5.0)
    assert ss.cast_rays(scene, [[11.2, 1.2, 5]], [[0, 0, -1]]).triangle[0] == -1


def test_lights_and_cameras_on_animated_nodes_move_with_them(tmp_path):
    """Clip "spin" turns node 1 (the light's and camera's parent) a quarter about z over 2 s:
    the light's position and direction and the camera's pose follow; "move" animates only the
    triangle's node, so they stay where they were loaded."""
    scene = _animated(tmp_path, lit=True)
    turn = np.eye(4)
    turn[:3, :3] = _rz(np.pi / 2)
    local = np.eye(4)
    local[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # 90 degrees about x
    local[:3, 3] = [1, 0, 0]
    for clip, t, parent in [("spin", 2.0, turn), ("spin", 0.0, np.eye(4)), ("move", 2.0, None)]:
        at = scene.at(t, clip)
        world = local.copy() if parent is None else parent @ local
        world[:3, 3] += ROOT
        light = at.lights[0]  # the file's quaternions are float32: 1e-7 off
        np.testing.assert_allclose(light["position"], world[:3, 3], atol=1e-6)
        np.testing.assert_allclose(light["direction"], -world[:3, 2], atol=1e-6)
        np.testing.assert_allclose(at.cameras[0].pose, world, atol=1e-6)
    still = scene.at(1.0, "move")
    assert still.lights[0] == scene.lights[0]
    np.testing.assert_array_equal(still.cameras[0].pose, scene.cameras[0].pose)
    # A pose given by hand moves objects only.
    assert scene.posed({0: np.eye(4)}).lights[0] == scene.lights[0]


def test_a_scene_without_animations_has_none(tmp_path):
    plain = ss.Scene.load(write(document(TRI), tmp_path / "plain.gltf"))
    assert plain.animations == []
    with pytest.raises(ss.InputError, match="no animations"):
        plain.at(0.0)
    assert ss.Scene.from_arrays(TRI, [[0, 1, 2]]).animations == []


@pytest.mark.parametrize(
    "t, clip, match",
    [
        (float("nan"), 0, "finite"),
        (float("inf"), 0, "finite"),
        (0.0, 7, "no animation 7"),
        (0.0, "dance", "no animation"),
        (0.0, 1.5, "index or a name"),
    ],
)
def test_bad_times_and_clips_are_refused(scene, t, clip, match):
    with pytest.raises(ss.InputError, match=match):
        scene.at(t, clip)


def test_a_broken_channel_is_skipped_with_a_warning(tmp_path):
    doc = document(TRI)
    i = add_accessor(doc, np.array([[0.0], [1.0]]), "SCALAR")
    o = add_accessor(doc, np.array([[0, 0, 0]]), "VEC3")  # one value for two keys
    doc["animations"] = [
        {
            "samplers": [{"input": i, "output": o}],
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
        }
    ]
    with pytest.warns(ss.SceneWarning, match="skipped"):
        s = ss.Scene.load(write(doc, tmp_path / "broken.gltf"))
    assert s.animations == [("animation0", 0.0)]
    np.testing.assert_array_equal(s.at(0.5).vertices, s.vertices)


def test_skins_warn_and_stay_in_their_rest_pose(tmp_path):
    doc = document(TRI)
    doc["nodes"] = [{"mesh": 0, "skin": 0}, {"name": "joint"}]
    doc["scenes"] = [{"nodes": [0, 1]}]
    doc["skins"] = [{"joints": [1]}]
    with pytest.warns(ss.SceneWarning, match="skins are not posed"):
        s = ss.Scene.load(write(doc, tmp_path / "skinned.gltf"))
    np.testing.assert_array_equal(s.vertices, TRI)


def test_a_clip_that_mirrors_a_node_keeps_its_fronts(tmp_path):
    """glTF winds a node's triangles by the sign of its world determinant: a scale through -1
    on x turns the triangle over, and its counter-clockwise side must stay the one facing +z
    (posed() with a mirroring matrix keeps the faces, and the front flips: documented)."""
    doc = document(TRI)
    doc["nodes"] = [{"mesh": 0, "name": "tri"}]
    doc["scenes"] = [{"nodes": [0]}]
    i = add_accessor(doc, np.array([[0.0], [1.0]], np.float32), "SCALAR")
    o = add_accessor(doc, np.array([[1, 1, 1], [-1, 1, 1]], np.float32), "VEC3")
    doc["animations"] = [
        {
            "name": "mirror",
            "samplers": [{"input": i, "output": o, "interpolation": "LINEAR"}],
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "scale"}}],
        }
    ]
    scene = ss.Scene.load(write(doc, tmp_path / "mirror.gltf"))

    def normal(s):
        a, b, c = s.vertices[s.faces[0]].astype(np.float64)
        return np.cross(b - a, c - a)

    assert normal(scene)[2] > 0
    half = scene.at(0.25, "mirror")  # scale x 0.5: not mirrored
    np.testing.assert_array_equal(half.faces, scene.faces)
    mirrored = scene.at(1.0, "mirror")
    np.testing.assert_allclose(mirrored.vertices[scene.faces[0]], TRI * [-1, 1, 1])
    np.testing.assert_array_equal(mirrored.faces, scene.faces[:, [0, 2, 1]])
    assert normal(mirrored)[2] > 0
    hit = ss.cast_rays(mirrored, [[-0.2, 0.2, 1]], [[0, 0, -1]])
    assert hit.triangle[0] == 0 and hit.t[0] == pytest.approx(1.0)
    # posed() with the same matrix moves the vertices only: the front turns to -z.
    assert normal(scene.posed(np.array([np.diag([-1.0, 1, 1, 1])])))[2] < 0
    # Pickled, the pose is made again the same way, winding included.
    back = pickle.loads(pickle.dumps(mirrored))
    np.testing.assert_array_equal(back.faces, mirrored.faces)
    np.testing.assert_array_equal(back.transforms, mirrored.transforms)


def test_lights_moved_by_a_clip_travel_in_a_pickle(tmp_path):
    loaded = _animated(tmp_path, lit=True)
    moved = loaded.at(1.0, "spin")
    back = pickle.loads(pickle.dumps(moved))
    (a,), (b,) = back.lights, moved.lights
    assert a["position"] == b["position"] != loaded.lights[0]["position"]
    # A light's direction is normalised again as it is read back (an ulp).
    np.testing.assert_allclose(a["direction"], b["direction"], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(back.vertices, moved.vertices)
