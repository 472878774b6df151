"""Compressed and quantized meshes (issue 72, item 3): a Draco-compressed copy of a mesh
(`KHR_draco_mesh_compression`, written by Google's encoder through DracoPy) against its
uncompressed twin, attributes quantized by `KHR_mesh_quantization`, and a file that needs an
extension nothing here decodes refused by that extension's name."""

from __future__ import annotations

import copy
import json
import warnings

import numpy as np
import pytest
import scenesample as ss
from gltf_builder import add_accessor, data_uri, write
from test_surfaces import checker, png, sphere

#: Draco's attribute types (draco/attributes/geometry_attribute.h), as DracoPy reports them.
DRACO_TYPES = {0: "POSITION", 1: "NORMAL", 3: "TEXCOORD_0"}


def twin(v: np.ndarray, f: np.ndarray) -> dict:
    """A glTF document of the mesh with NORMAL (its unit positions: a sphere's own normals),
    TEXCOORD_0 and a checkerboard texture, all plain float32 accessors."""
    from gltf_builder import document

    doc = document(v, f)
    prim = doc["meshes"][0]["primitives"][0]
    prim["attributes"]["NORMAL"] = add_accessor(doc, v / np.linalg.norm(v, axis=1)[:, None], "VEC3")
    uv = np.stack([np.arctan2(v[:, 2], v[:, 0]) / (2 * np.pi) + 0.5, 0.5 - v[:, 1] / 2], -1)
    prim["attributes"]["TEXCOORD_0"] = add_accessor(doc, uv, "VEC2")
    prim["material"] = 0
    doc["images"] = [{"uri": data_uri(png(checker(16, cell=2)), "image/png")}]
    doc["textures"] = [{"source": 0}]
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    return doc


def test_a_draco_copy_decodes_to_its_uncompressed_twin(tmp_path):
    """Positions, normals and texture coordinates within the encoder's quantization, the same
    triangles, and images of the two that agree."""
    draco = pytest.importorskip("DracoPy")
    v, f = sphere(16, 32)
    plain = twin(v, f)
    path = write(plain, tmp_path / "plain.gltf")
    reference = ss.Scene.load(path)
    n, uv = reference.normals.astype(np.float64), reference.texcoords.astype(np.float64)
    stream = draco.encode(
        v.astype(np.float64), f, quantization_bits=16, normals=n, tex_coord=uv,
        normal_quantization_bits=12, tex_coord_quantization_bits=14, preserve_order=True,
    )  # fmt: skip
    ids = {
        DRACO_TYPES[a["attribute_type"]]: a["unique_id"] for a in draco.decode(stream).attributes
    }
    doc = copy.deepcopy(plain)
    prim = doc["meshes"][0]["primitives"][0]
    # The compressed primitive's accessors keep their type and count but lose their data.
    for k in [*prim["attributes"].values(), prim.pop("indices")]:
        doc["accessors"][k].pop("bufferView", None)
    prim["indices"] = len(doc["accessors"])
    doc["accessors"].append({"componentType": 5125, "count": f.size, "type": "SCALAR"})
    doc["buffers"].append({"byteLength": len(stream), "uri": data_uri(stream)})
    doc["bufferViews"].append({"buffer": len(doc["buffers"]) - 1, "byteLength": len(stream)})
    ext = {"bufferView": len(doc["bufferViews"]) - 1, "attributes": ids}
    prim["extensions"] = {"KHR_draco_mesh_compression": ext}
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    scene = ss.Scene.load(write(doc, tmp_path / "draco.gltf"))
    np.testing.assert_array_equal(scene.faces, reference.faces)
    np.testing.assert_allclose(scene.vertices, reference.vertices, atol=4e-5)
    np.testing.assert_allclose(scene.normals, reference.normals, atol=2e-3)
    np.testing.assert_allclose(scene.texcoords, reference.texcoords, atol=2e-4)
    cam = ss.Camera.look_at((0.5, 1.0, 3.0), (0, 0, 0), yfov=0.8, width=64, height=64)
    a = ss.discretize(reference, [cam], backend="cpu")
    b = ss.discretize(scene, [cam], backend="cpu")
    same = (a.triangle == b.triangle) & (a.triangle >= 0)
    assert same.sum() > 0.98 * (a.triangle >= 0).sum()
    assert np.abs(a.color[same] - b.color[same]).max() < 0.02
    # A stream that is not Draco is refused by the extension's name, never a panic.
    junk = b"DRACO\x02\x02" + bytes(40)
    doc["buffers"][-1].update(uri=data_uri(junk), byteLength=len(junk))
    doc["bufferViews"][-1]["byteLength"] = len(junk)
    with pytest.raises(ss.SceneError, match="KHR_draco_mesh_compression could not be decoded"):
        ss.Scene.load(write(doc, tmp_path / "broken.gltf"))


def test_mutated_draco_streams_load_or_name_what_is_wrong(tmp_path):
    """300 seeded mutations of a Draco stream (bytes flipped, cut, repeated): each file loads or
    is refused with a SceneError, never the reader's "internal error" (a panic caught)."""
    draco = pytest.importorskip("DracoPy")
    v, f = sphere(6, 12)
    stream = draco.encode(v.astype(np.float64), f, quantization_bits=12, compression_level=7)
    ids = {
        DRACO_TYPES[a["attribute_type"]]: a["unique_id"] for a in draco.decode(stream).attributes
    }
    rng = np.random.default_rng(72)
    failures = []
    for k in range(300):
        data = bytearray(stream)
        for _ in range(rng.integers(1, 6)):
            if len(data) < 2:
                break
            at = int(rng.integers(len(data)))
            kind = rng.integers(3)
            if kind == 0:
                data[at] = int(rng.integers(256))
            elif kind == 1:
                del data[at:]
            else:
                data[at:at] = data[at : at + int(rng.integers(1, 16))]
        doc = twin(v, f)
        prim = doc["meshes"][0]["primitives"][0]
        prim["attributes"] = {"POSITION": prim["attributes"]["POSITION"]}
        prim.pop("material")
        doc["buffers"].append({"byteLength": len(data), "uri": data_uri(bytes(data))})
        doc["bufferViews"].append({"buffer": len(doc["buffers"]) - 1, "byteLength": len(data)})
        ext = {"bufferView": len(doc["bufferViews"]) - 1, "attributes": ids}
        prim["extensions"] = {"KHR_draco_mesh_compression": ext}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ss.Scene.load(write(doc, tmp_path / "mutant.gltf"))
        except ss.SceneError as e:
            if "internal error" in str(e):
                failures.append((k, str(e)))
    assert failures == []


def test_quantized_attributes_read_as_the_spec_converts_them(tmp_path):
    """KHR_mesh_quantization: positions as unnormalized int16 (the node's scale dequantizes
    them), normals as normalized int8, texture coordinates as normalized uint16."""
    v, f = sphere(8, 16)
    doc = twin(v, f)
    prim = doc["meshes"][0]["primitives"][0]
    reference = ss.Scene.load(write(doc, tmp_path / "plain.gltf"))

    def quantized(data: np.ndarray, dtype, kind: str, component: int, normalized: bool) -> int:
        rows = np.zeros((len(data), 4), dtype)  # each element 4-byte aligned, as the spec asks
        rows[:, : data.shape[1]] = data
        blob = rows.tobytes()
        doc["buffers"].append({"byteLength": len(blob), "uri": data_uri(blob)})
        stride = rows.itemsize * 4
        doc["bufferViews"].append(
            {"buffer": len(doc["buffers"]) - 1, "byteLength": len(blob), "byteStride": stride}
        )
        doc["accessors"].append(
            {"bufferView": len(doc["bufferViews"]) - 1, "componentType": component,
             "normalized": normalized, "count": len(data), "type": kind}
        )  # fmt: skip
        return len(doc["accessors"]) - 1

    position = np.round(v * 10000).astype(np.int16)
    prim["attributes"]["POSITION"] = quantized(position, np.int16, "VEC3", 5122, False)
    doc["accessors"][-1].update(min=position.min(0).tolist(), max=position.max(0).tolist())
    normal = np.round(reference.normals * 127).astype(np.int8)
    prim["attributes"]["NORMAL"] = quantized(normal, np.int8, "VEC3", 5120, True)
    texcoord = np.round(reference.texcoords * 65535).astype(np.uint16)
    prim["attributes"]["TEXCOORD_0"] = quantized(texcoord, np.uint16, "VEC2", 5123, True)
    doc["nodes"][0]["scale"] = [1e-4] * 3
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    scene = ss.Scene.load(write(doc, tmp_path / "quantized.gltf"))
    np.testing.assert_allclose(scene.vertices, reference.vertices, atol=1e-4)
    np.testing.assert_allclose(scene.normals, reference.normals, atol=0.02)
    np.testing.assert_allclose(scene.texcoords, reference.texcoords, atol=2e-5)


def test_a_file_that_needs_an_unknown_extension_is_refused_by_its_name(tmp_path):
    v, f = sphere(4, 8)
    doc = twin(v, f)
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["EXT_meshopt_compression"]
    with pytest.raises(ss.SceneError, match="requires the extension EXT_meshopt_compression"):
        ss.Scene.load(write(doc, tmp_path / "meshopt.gltf"))
    doc["extensionsRequired"] = []
    with pytest.warns(ss.SceneWarning, match="EXT_meshopt_compression is not simulated"):
        ss.Scene.load(write(doc, tmp_path / "used.gltf"))
    json.dumps(doc)  # the document stays plain JSON
