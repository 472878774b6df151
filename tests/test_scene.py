"""Scene from arrays and trimesh: properties, face order, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import scenesample as ss

QUAD_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
QUAD_F = np.array([[0, 1, 2], [0, 2, 3]])


def test_properties_dtypes_and_shapes() -> None:
    s = ss.Scene.from_arrays(QUAD_V, QUAD_F, colors=np.full((4, 3), 0.5))
    assert s.vertices.dtype == np.float32 and s.vertices.shape == (4, 3)
    assert s.faces.dtype == np.uint32 and s.faces.shape == (2, 3)
    assert s.triangle_count == 2 and s.degenerate_count == 0
    np.testing.assert_array_equal(s.bounds, [[0, 0, 0], [1, 1, 0]])
    assert s.bounds.dtype == np.float32
    assert s.material_ids.dtype == np.int32 and (s.material_ids == -1).all()
    assert s.materials == [] and s.lights == [] and s.cameras == []
    np.testing.assert_array_equal(s.colors, 0.5)
    assert s.normals is None
    assert "2 triangles" in repr(s)


@pytest.mark.parametrize(
    "dtype", [np.int8, np.uint8, np.int16, np.uint16, np.int32, np.uint32, np.int64, np.uint64]
)
def test_faces_accept_any_integer_dtype_and_keep_order(dtype) -> None:
    f = np.array([[0, 2, 3], [0, 1, 2], [3, 2, 1]], dtype=dtype)
    s = ss.Scene.from_arrays(QUAD_V.astype(np.float32), f)
    np.testing.assert_array_equal(s.faces, f.astype(np.uint32))


def test_non_contiguous_and_list_input() -> None:
    v = np.asfortranarray(np.concatenate([QUAD_V, QUAD_V * 2], axis=1))[:, ::2]
    s = ss.Scene.from_arrays(v, QUAD_F.tolist())
    np.testing.assert_array_equal(s.vertices, v.astype(np.float32))


def test_degenerate_triangles_are_kept_and_counted() -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], dtype=np.float32)
    s = ss.Scene.from_arrays(v, [[0, 1, 2], [0, 1, 3], [1, 1, 3]])
    assert s.triangle_count == 3 and s.degenerate_count == 2


def test_from_trimesh_mesh_and_scene() -> None:
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box(extents=(1, 2, 3))
    s = ss.Scene.from_trimesh(box)
    np.testing.assert_array_equal(s.faces, box.faces)
    sc = trimesh.Scene()
    sc.add_geometry(box, transform=trimesh.transformations.translation_matrix([10, 0, 0]))
    sc.add_geometry(trimesh.creation.icosphere(subdivisions=1))
    s2 = ss.Scene.from_trimesh(sc)
    assert s2.triangle_count == len(box.faces) + 80
    assert s2.bounds[1, 0] == pytest.approx(10.5)


def test_from_trimesh_rejects_other_types() -> None:
    pytest.importorskip("trimesh")
    with pytest.raises(TypeError, match="trimesh"):
        ss.Scene.from_trimesh(np.zeros((3, 3)))


def test_load_obj_through_trimesh(tmp_path) -> None:
    pytest.importorskip("trimesh")
    p = tmp_path / "quad.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n")
    s = ss.Scene.load(p)
    assert s.triangle_count == 2


@pytest.mark.parametrize(
    "vertices, faces, kwargs, exc, match",
    [
        (
            np.array([[0, 0, 0], [1, np.nan, 0], [0, 1, 0]]),
            [[0, 1, 2]],
            {},
            ss.SceneError,
            "vertex 1",
        ),
        (
            np.array([[0, 0, 0], [1, 0, np.inf], [0, 1, 0]]),
            [[0, 1, 2]],
            {},
            ss.SceneError,
            "vertex 1",
        ),
        (QUAD_V, [[0, 1, 4]], {}, ss.SceneError, r"faces\[0\].*vertex 4"),
        (QUAD_V, [[0, 1, 2], [0, -1, 2]], {}, ss.SceneError, r"faces\[1\].*vertex -1"),
        (
            QUAD_V[:, :2],
            QUAD_F,
            {},
            ss.InputError,
            r"vertices must have shape \(n, 3\), got \(4, 2\)",
        ),
        (
            QUAD_V,
            [[0, 1, 2, 3]],
            {},
            ss.InputError,
            r"faces must have shape \(m, 3\), got \(1, 4\)",
        ),
        (
            QUAD_V,
            QUAD_F.astype(float),
            {},
            ss.InputError,
            "faces must be an array of integers, got dtype float64",
        ),
        (
            np.array([["a", "b", "c"]] * 3),
            [[0, 1, 2]],
            {},
            ss.InputError,
            "vertices must be an array of real numbers",
        ),
        (np.zeros((0, 3)), np.zeros((0, 3), dtype=int), {}, ss.SceneError, "no triangles"),
        (
            QUAD_V,
            QUAD_F,
            {"normals": np.zeros((3, 3))},
            ss.SceneError,
            "normals has 3 rows but there are 4 vertices",
        ),
        (QUAD_V, QUAD_F, {"colors": np.full((4, 3), np.nan)}, ss.SceneError, "color 0"),
        (
            QUAD_V,
            QUAD_F,
            {"colors": np.ones((4, 4))},
            ss.InputError,
            r"colors must have shape \(n, 3\)",
        ),
    ],
)
def test_bad_arrays_raise_typed_errors(vertices, faces, kwargs, exc, match) -> None:
    with pytest.raises(exc, match=match) as info:
        ss.Scene.from_arrays(vertices, faces, **kwargs)
    assert isinstance(info.value, ValueError)


def test_scene_constructor_is_not_public() -> None:
    with pytest.raises(TypeError):
        ss.Scene(None)  # type: ignore[arg-type]
