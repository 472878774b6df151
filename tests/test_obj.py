"""OBJ files are read natively with their MTL materials, so the planner sees them: colours,
emission, roughness, metallic and alpha, per-face material and object ids, and warnings (never
errors) for what is missing."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scenesample as ss
from conftest import SHARED


def write_png(path, rgb):
    from PIL import Image

    Image.fromarray(np.full((4, 4, 3), rgb, dtype=np.uint8)).save(path)


def load(path) -> tuple[ss.Scene, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = ss.Scene.load(path)
    return scene, [str(w.message) for w in caught if issubclass(w.category, ss.SceneWarning)]


@pytest.mark.skipif("cornell_box" not in SHARED, reason="../shared/scenes is absent")
def test_the_cornell_box_keeps_its_materials_and_objects():
    scene, said = load(SHARED["cornell_box"])
    assert said == []
    names = [m["name"] for m in scene.materials]
    assert sorted(names) == ["Green", "Material.001", "Metal", "Red"]
    assert scene.objects == ["cornell_box", "Suzanne", "box2", "box1", "light"]
    assert scene.triangle_count == 3968 and (scene.material_ids >= 0).all()
    m = {x["name"]: x for x in scene.materials}
    np.testing.assert_allclose(m["Green"]["base_color"], [0, 0.8, 0, 1], atol=1e-6)
    np.testing.assert_allclose(m["Red"]["base_color"], [0.8, 0, 0, 1], atol=1e-6)
    # Ns 250 -> 1 - sqrt(0.25); Ns 887.94 -> 1 - sqrt(0.888).
    assert m["Green"]["roughness"] == pytest.approx(0.5)
    assert m["Metal"]["roughness"] == pytest.approx(1 - np.sqrt(0.887943848), abs=1e-6)
    assert all(x["metallic"] == 0 and x["double_sided"] for x in scene.materials)
    # Every face's vertex colour is its material's colour.
    red = names.index("Red")
    faces = scene.faces[scene.material_ids == red]
    np.testing.assert_allclose(scene.colors[faces.ravel()], [[0.8, 0, 0]] * faces.size, atol=1e-6)
    suzanne = scene.objects.index("Suzanne")
    assert {names[i] for i in np.unique(scene.material_ids[scene.object_ids == suzanne])} == {
        "Metal"
    }


@pytest.mark.skipif("cornell_box" not in SHARED, reason="../shared/scenes is absent")
def test_the_geometry_is_what_trimesh_reads():
    trimesh = pytest.importorskip("trimesh")
    ours, _ = load(SHARED["cornell_box"])
    theirs = trimesh.load(str(SHARED["cornell_box"]), force="mesh", process=False)
    a = np.sort(ours.vertices[ours.faces].reshape(-1, 9), axis=0)
    b = np.sort(
        np.asarray(theirs.vertices, np.float32)[np.asarray(theirs.faces)].reshape(-1, 9), axis=0
    )
    np.testing.assert_array_equal(a, b)


def test_mtl_statements_spaces_windows_paths_and_warnings(tmp_path):
    (tmp_path / "tex dir").mkdir()
    write_png(tmp_path / "tex dir" / "half red.png", (255, 0, 0))
    (tmp_path / "my materials.mtl").write_text(
        "newmtl lamp\nKd 1 1 1\nKe 4 3 2\n"
        "newmtl painted wood\nKd 0.5 0.5 0.5\nmap_Kd -s 1 1 1 .\\tex dir\\half red.png\n"
        "Pr 0.25\nPm 0.75\nd 0.5\n"
        "newmtl lost\nKd 0.2 0.3 0.4\nmap_Kd nowhere.png\nTr 0.25\nNs 90\n"
    )
    (tmp_path / "room.obj").write_text(
        "mtllib my materials.mtl\nmtllib absent.mtl\n"
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1 0.5 0.5 0.5\n"
        "o ceiling\nusemtl lamp\nf 1 2 3 4\n"
        "g table top\nusemtl painted wood\nf 1/1/1 2/2/1 5/3/1\n"
        "usemtl lost\nf -1 -2 -3\n"
        "o ceiling\nusemtl nonexistent\nf 2 3 5\n"
    )
    scene, said = load(tmp_path / "room.obj")
    assert scene.triangle_count == 5
    assert scene.objects == ["ceiling", "table top"]
    assert scene.object_ids.tolist() == [0, 0, 1, 1, 0]
    m = {x["name"]: x for x in scene.materials}
    assert scene.material_ids.tolist() == [0, 0, 1, 2, -1]
    assert m["lamp"]["emissive"] == pytest.approx([4, 3, 2])
    wood = m["painted wood"]
    assert wood["base_color_textured"]
    np.testing.assert_allclose(wood["base_color"], [0.5, 0, 0, 0.5], atol=1e-6)
    assert (wood["roughness"], wood["metallic"]) == (0.25, 0.75)
    lost = m["lost"]
    assert not lost["base_color_textured"]
    np.testing.assert_allclose(lost["base_color"], [0.2, 0.3, 0.4, 0.75], atol=1e-6)
    assert lost["roughness"] == pytest.approx(1 - np.sqrt(0.09))
    assert any("absent.mtl" in s and "missing" in s for s in said)
    assert any("nowhere.png" in s for s in said)
    assert any("nonexistent" in s for s in said)
    # The vertex colour of v5 multiplies its material's Kd, and the texture (all red) the
    # two where the face is sampled; the face's vt and vn references name none that exist.
    f = scene.faces[2]
    np.testing.assert_allclose(scene.colors[f[2]], [0.25, 0.25, 0.25], atol=1e-6)
    a = ss.surface_attributes(scene, triangle=[2], barycentric=[[0.0, 1.0]])
    np.testing.assert_allclose(a.color, [[0.25, 0, 0]], atol=1e-6)
    assert any("texture coordinate 1" in s and "does not exist" in s for s in said)


def test_a_plan_of_an_obj_with_an_emissive_material_has_soft_shadows(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl light\nKe 10 10 10\nnewmtl floor\nKd 0.7 0.7 0.7\n")
    (tmp_path / "lit.obj").write_text(
        "mtllib m.mtl\n"
        "v -2 0 -2\nv 2 0 -2\nv 2 0 2\nv -2 0 2\n"
        "v -0.3 2 -0.3\nv 0.3 2 -0.3\nv 0.3 2 0.3\nv -0.3 2 0.3\n"
        "v -0.5 0 -0.5\nv 0.5 0 -0.5\nv 0 1 0\n"
        "o floor\nusemtl floor\nf 1 4 3 2\nf 9 10 11\n"
        "o light\nusemtl light\nf 5 6 7 8\n"
    )
    scene, _ = load(tmp_path / "lit.obj")
    effects = ss.plan(scene)
    assert [e.kind for e in effects] == ["soft_shadows"]
    assert "light" in effects[0].reason


@pytest.mark.parametrize(
    "text, match",
    [("v 0 0 0\nf 1 2 3\n", "vertex 2 does not exist"), ("v 0 0 inf\n", "finite"),
     ("v 0 0 0\nf 1 a 1\n", "bad vertex reference")],
)  # fmt: skip
def test_broken_obj_files_are_scene_errors_naming_the_line(tmp_path, text, match):
    (tmp_path / "bad.obj").write_text(text)
    with pytest.raises(ss.SceneError, match=f"bad.obj:\\d+: .*{match}"):
        ss.Scene.load(tmp_path / "bad.obj")


def test_a_missing_obj_is_a_scene_file_error(tmp_path):
    with pytest.raises(ss.SceneFileError, match="cannot read"):
        ss.Scene.load(tmp_path / "none.obj")
