"""glTF loading: every feature on small generated files, every malformed file as a typed error,
and every shared scene with the triangle count its README gives."""

from __future__ import annotations

import io
import json
import warnings

import numpy as np
import pytest
import scenesample as ss
from conftest import SHARED, load_quiet
from gltf_builder import (
    FAN,
    LINES,
    POINTS,
    QUAD,
    STRIP,
    TRI,
    add_accessor,
    data_uri,
    document,
    to_glb,
    write,
)


def test_indexed_and_non_indexed_triangles(tmp_path) -> None:
    s = ss.Scene.load(write(document(QUAD, [[0, 1, 2], [0, 2, 3]]), tmp_path / "a.gltf"))
    assert s.triangle_count == 2
    np.testing.assert_array_equal(s.vertices, QUAD)
    s = ss.Scene.load(write(document(TRI), tmp_path / "b.gltf"))
    np.testing.assert_array_equal(s.faces, [[0, 1, 2]])


def test_strips_and_fans_are_converted_with_consistent_winding(tmp_path) -> None:
    strip = ss.Scene.load(write(document(QUAD, [0, 1, 3, 2], mode=STRIP), tmp_path / "s.gltf"))
    fan = ss.Scene.load(write(document(QUAD, [0, 1, 2, 3], mode=FAN), tmp_path / "f.gltf"))
    for s in (strip, fan):
        assert s.triangle_count == 2
        v = s.vertices[s.faces.astype(int)]
        normals = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        assert (normals[:, 2] > 0).all(), "every triangle keeps the counter-clockwise front"


def test_points_and_lines_are_skipped_with_a_warning(tmp_path) -> None:
    doc = document(QUAD, [[0, 1, 2], [0, 2, 3]])
    doc["meshes"][0]["primitives"] += [
        {"attributes": {"POSITION": 0}, "mode": POINTS},
        {"attributes": {"POSITION": 0}, "mode": LINES},
    ]
    with pytest.warns(ss.SceneWarning, match="(Points|Lines) primitives are not triangles") as rec:
        s = ss.Scene.load(write(doc, tmp_path / "p.gltf"))
    assert sorted(str(w.message).split(": ")[2].split()[0] for w in rec) == ["Lines", "Points"]
    assert s.triangle_count == 2


def test_node_hierarchy_is_flattened_and_mirrors_keep_fronts(tmp_path) -> None:
    doc = document(TRI)
    doc["nodes"] = [
        {"translation": [10, 0, 0], "children": [1]},
        {"mesh": 0, "rotation": [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)], "scale": [2, 2, 2]},
        {"mesh": 0, "scale": [-1, 1, 1]},
    ]
    doc["scenes"] = [{"nodes": [0, 2]}]
    s = ss.Scene.load(write(doc, tmp_path / "h.gltf"))
    assert s.triangle_count == 2 and len(s.objects) == 2
    # Rotated 90 degrees about z, scaled by 2, moved by 10 in x.
    np.testing.assert_allclose(s.vertices[:3], [[10, 0, 0], [10, 2, 0], [8, 0, 0]], atol=1e-6)
    v = s.vertices[s.faces.astype(int)]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    assert (n[:, 2] > 0).all()
    np.testing.assert_array_equal(s.object_ids, [0, 1])


def test_gpu_instancing_is_expanded(tmp_path) -> None:
    doc = document(TRI)
    t = add_accessor(doc, np.array([[0, 0, 0], [5, 0, 0], [0, 5, 0]]), "VEC3")
    doc["nodes"][0]["extensions"] = {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": t}}}
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["EXT_mesh_gpu_instancing"]
    s = ss.Scene.load(write(doc, tmp_path / "i.gltf"))
    assert s.triangle_count == 3
    np.testing.assert_allclose(s.vertices[[0, 3, 6]], [[0, 0, 0], [5, 0, 0], [0, 5, 0]])


def test_materials_with_texture_average(tmp_path) -> None:
    pil = pytest.importorskip("PIL.Image")
    img = pil.new("RGB", (2, 1))
    img.putpixel((0, 0), (255, 0, 0))
    img.putpixel((1, 0), (0, 0, 255))
    png = io.BytesIO()
    img.save(png, format="PNG")
    doc = document(TRI)
    doc["images"] = [{"uri": data_uri(png.getvalue(), "image/png")}]
    doc["textures"] = [{"source": 0}]
    doc["materials"] = [
        {
            "name": "tex",
            "pbrMetallicRoughness": {
                "baseColorFactor": [1, 0.5, 1, 1],
                "baseColorTexture": {"index": 0},
                "metallicFactor": 0.25,
                "roughnessFactor": 0.75,
            },
            "emissiveFactor": [1, 0.5, 0],
            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}},
        }
    ]
    doc["extensionsUsed"] = ["KHR_materials_emissive_strength"]
    prim = doc["meshes"][0]["primitives"][0]
    prim["material"] = 0
    uv = np.array([[0.25, 0.5], [0.75, 0.5], [0.25, 0.5]], np.float32)
    prim["attributes"]["TEXCOORD_0"] = add_accessor(doc, uv, "VEC2")
    s = ss.Scene.load(write(doc, tmp_path / "m.gltf"))
    (m,) = s.materials
    assert m["base_color_textured"] and m["metallic"] == 0.25 and m["roughness"] == 0.75
    # The material's one colour: the mean of linear red (1,0,0) and blue (0,0,1), times the
    # factor.
    np.testing.assert_allclose(m["base_color"], [0.5, 0.0, 0.5, 1.0], atol=1e-6)
    np.testing.assert_allclose(m["emissive"], [4, 2, 0])
    np.testing.assert_array_equal(s.material_ids, [0])
    # The vertices carry the factor; the texture multiplies it where each sample lies: red at
    # the first texel's centre, blue at the second's.
    np.testing.assert_allclose(s.colors, [[1, 0.5, 1]] * 3)
    a = ss.surface_attributes(s, triangle=[0, 0], barycentric=[[0, 0], [1, 0]])
    np.testing.assert_allclose(a.color, [[1, 0, 0], [0, 0, 1]], atol=1e-6)
    np.testing.assert_allclose(a.texcoord, uv[:2])


def test_missing_image_is_tolerated_with_a_warning(tmp_path) -> None:
    doc = document(TRI)
    doc["images"] = [{"uri": "nowhere.png"}]
    doc["textures"] = [{"source": 0}]
    doc["materials"] = [
        {
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.2, 0.4, 0.6, 1],
                "baseColorTexture": {"index": 0},
            }
        }
    ]
    doc["meshes"][0]["primitives"][0]["material"] = 0
    with pytest.warns(ss.SceneWarning, match="nowhere.png"):
        s = ss.Scene.load(write(doc, tmp_path / "mi.gltf"))
    assert s.materials[0]["base_color"] == pytest.approx([0.2, 0.4, 0.6, 1])
    assert not s.materials[0]["base_color_textured"]


def test_lights_and_cameras_in_world_space(tmp_path) -> None:
    doc = document(TRI)
    doc["extensionsUsed"] = ["KHR_lights_punctual"]
    doc["extensions"] = {
        "KHR_lights_punctual": {
            "lights": [
                {"type": "point", "intensity": 3},
                {"type": "spot", "spot": {"outerConeAngle": 0.5}},
            ]
        }
    }
    down = [-np.sin(np.pi / 4), 0, 0, np.cos(np.pi / 4)]  # -90 degrees about x: -Z becomes -Y
    doc["cameras"] = [
        {"type": "perspective", "perspective": {"yfov": 0.7, "aspectRatio": 1.5, "znear": 0.1}},
        {"type": "orthographic", "orthographic": {"xmag": 2, "ymag": 1, "znear": 0.1, "zfar": 50}},
    ]
    doc["nodes"] += [
        {"translation": [1, 2, 3], "extensions": {"KHR_lights_punctual": {"light": 0}}},
        {
            "translation": [0, 5, 0],
            "rotation": down,
            "extensions": {"KHR_lights_punctual": {"light": 1}},
        },
        {"translation": [0, 0, 9], "camera": 0, "scale": [3, 3, 3]},
        {"camera": 1},
    ]
    doc["scenes"][0]["nodes"] += [1, 2, 3, 4]
    s = ss.Scene.load(write(doc, tmp_path / "l.gltf"))
    point, spot = s.lights
    assert point["type"] == "point" and point["position"] == [1, 2, 3] and point["intensity"] == 3
    assert spot["type"] == "spot" and spot["outer_cone_angle"] == 0.5
    np.testing.assert_allclose(spot["direction"], [0, -1, 0], atol=1e-6)  # f32 quaternion
    persp, ortho = s.cameras
    assert (persp.width, persp.height, persp.yfov, persp.znear, persp.zfar) == (
        768,
        512,
        pytest.approx(0.7),
        pytest.approx(0.1),
        None,
    )
    np.testing.assert_allclose(persp.pose[:3, :3], np.eye(3), atol=1e-12)  # scale removed
    assert ortho.projection == "orthographic" and (ortho.xmag, ortho.ymag, ortho.width) == (
        2,
        1,
        1024,
    )


def test_unknown_extension_warns_and_required_codec_is_an_error(tmp_path) -> None:
    doc = document(TRI)
    doc["extensionsUsed"] = ["VENDOR_sparkles"]
    with pytest.warns(ss.SceneWarning, match="VENDOR_sparkles"):
        ss.Scene.load(write(doc, tmp_path / "u.gltf"))
    # Draco decodes now (tests/test_compressed.py); a codec nothing here reads is refused.
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["EXT_texture_webp"]
    with pytest.raises(ss.SceneError, match="requires the extension EXT_texture_webp"):
        ss.Scene.load(write(doc, tmp_path / "d.gltf"))


def test_glb_round_trip(tmp_path) -> None:
    p = tmp_path / "q.glb"
    p.write_bytes(to_glb(document(QUAD, [[0, 1, 2], [0, 2, 3]])))
    assert ss.Scene.load(p).triangle_count == 2


def _mutate(doc, path):
    def set_(d, keys, value):
        for k in keys[:-1]:
            d = d[k]
        d[keys[-1]] = value

    out = json.loads(json.dumps(doc))
    set_(out, path[0], path[1])
    return out


BAD_DOCUMENTS = [
    (("accessors", 0, "type"), "VEC2", r"accessor 0 has type Vec2"),
    (("accessors", 0, "count"), 40, r"accessor 0 reads 480 bytes but buffer view 0 has 48"),
    (("bufferViews", 0, "byteLength"), 4000, r"buffer view 0 .* lies outside buffer 0"),
    (
        ("meshes", 0, "primitives", 0, "attributes", "POSITION"),
        99,
        r"attribute .*Positions.* refers to accessor 99, but the file has 2",
    ),
    (("nodes",), [{"mesh": 0, "children": [1]}, {"children": [0]}], r"node cycle|own ancestor"),
    (("meshes", 0, "primitives", 0, "attributes"), {}, r"POSITION"),
]


@pytest.mark.parametrize("keys, value, match", BAD_DOCUMENTS, ids=[m for *_, m in BAD_DOCUMENTS])
def test_malformed_documents_raise_scene_error(tmp_path, keys, value, match) -> None:
    doc = _mutate(document(QUAD, [[0, 1, 2], [0, 2, 3]]), (keys, value))
    with pytest.raises(ss.SceneError, match=match) as info:
        ss.Scene.load(write(doc, tmp_path / "bad.gltf"))
    assert "bad.gltf" in str(info.value)


def test_out_of_range_index_and_nan_vertex(tmp_path) -> None:
    with pytest.raises(
        ss.SceneError, match=r"mesh 0 primitive 0: index accessor 1 has index 7 at position 5"
    ):
        ss.Scene.load(write(document(QUAD, [[0, 1, 2], [0, 2, 7]]), tmp_path / "i.gltf"))
    bad = QUAD.copy()
    bad[2, 1] = np.nan
    with pytest.raises(
        ss.SceneError, match=r"POSITION accessor 0 has a non-finite value at index 2"
    ):
        ss.Scene.load(write(document(bad, [[0, 1, 2]]), tmp_path / "n.gltf"))


def test_file_problems_raise_scene_file_error(tmp_path) -> None:
    with pytest.raises(ss.SceneFileError, match="cannot read the file") as info:
        ss.Scene.load(tmp_path / "absent.gltf")
    assert isinstance(info.value, OSError) and isinstance(info.value, ValueError)
    doc = document(TRI)
    doc["buffers"][0]["uri"] = "missing.bin"
    with pytest.raises(ss.SceneFileError, match=r"buffer 0 \('missing.bin'\)"):
        ss.Scene.load(write(doc, tmp_path / "m.gltf"))
    doc = document(TRI)
    doc["buffers"][0]["byteLength"] = 4096
    with pytest.raises(ss.SceneFileError, match="truncated"):
        ss.Scene.load(write(doc, tmp_path / "t.gltf"))
    glb = to_glb(document(QUAD, [[0, 1, 2], [0, 2, 3]]))
    (tmp_path / "cut.glb").write_bytes(glb[: len(glb) // 2])
    with pytest.raises(ss.SceneFileError):
        ss.Scene.load(tmp_path / "cut.glb")
    (tmp_path / "junk.gltf").write_text("{ not json")
    with pytest.raises(ss.SceneFileError, match="truncated or corrupt"):
        ss.Scene.load(tmp_path / "junk.gltf")


def test_empty_document_has_no_triangles(tmp_path) -> None:
    with pytest.raises(ss.SceneError, match="no triangles"):
        ss.Scene.load(write({"asset": {"version": "2.0"}}, tmp_path / "e.gltf"))


def test_random_corruption_never_escapes_as_an_untyped_error(tmp_path) -> None:
    """Flip bytes of a valid GLB: every load either succeeds or raises a ScenesampleError."""
    glb = bytearray(to_glb(document(QUAD, [[0, 1, 2], [0, 2, 3]])))
    rng = np.random.default_rng(7)
    outcomes = {"ok": 0, "error": 0}
    for i in range(300):
        b = bytearray(glb)
        for k in rng.integers(0, len(b), size=rng.integers(1, 6)):
            b[k] = rng.integers(0, 256)
        p = tmp_path / f"f{i}.glb"
        p.write_bytes(bytes(b))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ss.SceneWarning)
                ss.Scene.load(p)
            outcomes["ok"] += 1
        except ss.ScenesampleError:
            outcomes["error"] += 1
    assert outcomes["error"] > 50, outcomes


# Triangle counts from ../shared/scenes/README.md: the loader must flatten instances exactly.
EXPECTED_TRIANGLES = {
    "cornell_box": 3968, "stanford_bunny": 69451, "khr_metal_rough_spheres_notex": 1040409,
    "khr_simple_instancing": 1500, "khr_lights_punctual_lamp": 6000, "khr_cameras": 2,
    "khr_toy_car": 108936, "khr_transmission_test": 128775, "khr_specular_test": 44828,
    "khr_clearcoat_car_paint": 3072, "khr_glass_vase_flowers": 14036, "pine_tree": 1650,
    "intel_sponza_ivy": 15870, "intel_sponza_curtains": 55115, "balloon": 35698,
}  # fmt: skip


@pytest.mark.skipif(not SHARED, reason="../shared/scenes is absent")
@pytest.mark.parametrize("name", sorted(SHARED))
def test_shared_scene_loads_with_expected_triangle_count(name) -> None:
    s = load_quiet(SHARED[name])
    assert s.triangle_count == EXPECTED_TRIANGLES[name]
    assert np.isfinite(s.vertices).all()
    assert s.material_ids.shape == (s.triangle_count,)


@pytest.mark.skipif(not SHARED, reason="../shared/scenes is absent")
def test_shared_scene_specifics() -> None:
    with pytest.warns(ss.SceneWarning, match="is missing"):
        ss.Scene.load(SHARED["intel_sponza_curtains"])
    with pytest.warns(ss.SceneWarning, match="M_TreeAtlas_normal.png"):
        ss.Scene.load(SHARED["pine_tree"])
    assert len(load_quiet(SHARED["khr_lights_punctual_lamp"]).lights) == 5
    assert len(load_quiet(SHARED["khr_toy_car"]).cameras) == 8
    cams = load_quiet(SHARED["khr_cameras"]).cameras
    assert sorted(c.projection for c in cams) == ["orthographic", "perspective"]
    spheres = load_quiet(SHARED["khr_metal_rough_spheres_notex"])
    metallic = {round(m["metallic"], 2) for m in spheres.materials}
    assert len(metallic) > 3
