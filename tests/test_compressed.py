"""Compressed and quantized meshes (issue 72, item 3): a Draco-compressed copy of a mesh
(`KHR_draco_mesh_compression`, written by Google's encoder through DracoPy) against its
uncompressed twin; `EXT_meshopt_compression` streams written by meshoptimizer's encoder
(tests/data/meshopt_streams.json says how) against the arrays they encode and meshoptimizer's
own decode; attributes quantized by `KHR_mesh_quantization`; and a file that needs an extension
nothing here decodes refused by that extension's name."""

from __future__ import annotations

import copy
import json
import warnings
from pathlib import Path

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


def _load_mutant(doc, tmp_path):
    """Load a mutated document quietly: the message of the SceneError it raised, else None."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ss.Scene.load(write(doc, tmp_path / "mutant.gltf"))
    except ss.SceneError as e:
        return str(e)
    return None


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


def mutated(stream: bytes, rng: np.random.Generator) -> bytes:
    """``stream`` with 1 to 5 seeded mutations: a byte replaced, the rest cut off, or a run of
    up to 15 bytes repeated in place."""
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
    return bytes(data)


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
        data = mutated(stream, rng)
        doc = twin(v, f)
        prim = doc["meshes"][0]["primitives"][0]
        prim["attributes"] = {"POSITION": prim["attributes"]["POSITION"]}
        prim.pop("material")
        doc["buffers"].append({"byteLength": len(data), "uri": data_uri(data)})
        doc["bufferViews"].append({"buffer": len(doc["buffers"]) - 1, "byteLength": len(data)})
        ext = {"bufferView": len(doc["bufferViews"]) - 1, "attributes": ids}
        prim["extensions"] = {"KHR_draco_mesh_compression": ext}
        error = _load_mutant(doc, tmp_path)
        if error and "internal error" in error:
            failures.append((k, error))
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
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["EXT_example_compression"]
    with pytest.raises(ss.SceneError, match="requires the extension EXT_example_compression"):
        ss.Scene.load(write(doc, tmp_path / "unknown.gltf"))
    doc["extensionsRequired"] = []
    with pytest.warns(ss.SceneWarning, match="EXT_example_compression is not simulated"):
        ss.Scene.load(write(doc, tmp_path / "used.gltf"))
    json.dumps(doc)  # the document stays plain JSON


# EXT_meshopt_compression --------------------------------------------------------------------

MESHOPT = json.loads((Path(__file__).parent / "data" / "meshopt_streams.json").read_text())
STREAMS = {k: bytes.fromhex(v) for k, v in MESHOPT["streams"].items()}


def grid(n: int = 17) -> tuple[np.ndarray, np.ndarray]:
    """The fixture's mesh: an n x n grid whose heights are exact binary fractions (so float32
    holds every coordinate exactly), two triangles per cell."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    z = ((i * 7 + j * 3) % 11) / 64.0
    v = np.stack([i / 16.0, j / 16.0, z], -1).reshape(-1, 3).astype(np.float32)
    k = np.arange(n * n).reshape(n, n)
    a, b, c, d = k[:-1, :-1], k[1:, :-1], k[1:, 1:], k[:-1, 1:]
    tris = [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    return v, np.concatenate(tris).astype(np.uint32)


def grid_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals of the grid, unit length (what the fixture's normals
    encode)."""
    n = np.zeros(v.shape, np.float64)
    t = v[f].astype(np.float64)
    face = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    for k in range(3):
        np.add.at(n, f[:, k], face)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def meshopt_document(
    views: dict[str, tuple[str, int, str, str]], ext: str = "EXT_meshopt_compression"
) -> tuple[dict, dict[str, int]]:
    """A glTF document whose buffer views are the fixture's streams: ``views`` maps a role to
    (stream name, byteStride, mode, filter). Buffer 0 holds the streams, buffer 1 is the
    extension's fallback buffer (no data: the decoded views go there). Returns the document and
    each role's buffer view."""
    blob, out, fallback = b"", {}, 0
    doc: dict = {
        "asset": {"version": "2.0"},
        "bufferViews": [],
        "extensionsUsed": [ext, "KHR_mesh_quantization"],
        "extensionsRequired": [ext, "KHR_mesh_quantization"],
    }
    for role, (name, stride, mode, filt) in views.items():
        data = STREAMS[name]
        count = 512 * 3 if mode != "ATTRIBUTES" else 289
        size = count * stride
        view = {"buffer": 1, "byteOffset": fallback, "byteLength": size}
        if mode == "ATTRIBUTES":
            view["byteStride"] = stride
        view["extensions"] = {
            ext: {
                "buffer": 0, "byteOffset": len(blob), "byteLength": len(data),
                "byteStride": stride, "count": count, "mode": mode, "filter": filt,
            }
        }  # fmt: skip
        out[role] = len(doc["bufferViews"])
        doc["bufferViews"].append(view)
        blob += data + bytes(-len(data) % 4)
        fallback += size + (-size % 4)
    doc["buffers"] = [
        {"byteLength": len(blob), "uri": data_uri(blob)},
        {"byteLength": fallback, "extensions": {ext: {"fallback": True}}},
    ]
    return doc, out


def meshopt_mesh(
    positions: str, stride: int, filt: str, indices: str, normals: bool = False, **kw
) -> dict:
    """The grid as one primitive: positions (float32 VEC3) from stream ``positions``, indices
    (uint32) from ``indices`` (TRIANGLES or INDICES), optionally int8 octahedral normals and
    uint8 COLOR-filtered vertex colours."""
    mode = "TRIANGLES" if indices == "triangles" else "INDICES"
    views = {
        "position": (positions, stride, "ATTRIBUTES", filt),
        "index": (indices, 4, mode, "NONE"),
    }
    if normals:
        views["normal"] = ("normals_oct", 4, "ATTRIBUTES", "OCTAHEDRAL")
        views["color"] = ("colors_color", 4, "ATTRIBUTES", "COLOR")
    doc, at = meshopt_document(views, **kw)
    doc["accessors"] = [
        {"bufferView": at["position"], "componentType": 5126, "count": 289, "type": "VEC3",
         "min": [0, 0, 0], "max": [1, 1, 0.25]},
        {"bufferView": at["index"], "componentType": 5125, "count": 1536, "type": "SCALAR"},
    ]  # fmt: skip
    attributes = {"POSITION": 0}
    if normals:
        doc["accessors"].append(
            {"bufferView": at["normal"], "componentType": 5120, "normalized": True,
             "count": 289, "type": "VEC3"}
        )  # fmt: skip
        attributes["NORMAL"] = 2
        doc["accessors"].append(
            {"bufferView": at["color"], "componentType": 5121, "normalized": True,
             "count": 289, "type": "VEC4"}
        )  # fmt: skip
        attributes["COLOR_0"] = 3
    doc["meshes"] = [{"primitives": [{"attributes": attributes, "indices": 1}]}]
    doc["nodes"] = [{"mesh": 0}]
    doc["scenes"] = [{"nodes": [0]}]
    return doc


@pytest.mark.parametrize(
    "positions, indices",
    [("positions_v0", "triangles"), ("positions_v1", "sequence")],
)
def test_meshopt_streams_decode_to_the_arrays_they_encode(tmp_path, positions, indices):
    """Vertex codec versions 0 and 1, the triangle codec and the index sequence codec: the
    positions and triangles come back exactly."""
    v, f = grid()
    doc = meshopt_mesh(positions, 12, "NONE", indices)
    scene = ss.Scene.load(write(doc, tmp_path / "meshopt.gltf"))
    np.testing.assert_array_equal(scene.vertices, v)
    # The triangle codec may start a triangle at another corner (same winding).
    np.testing.assert_array_equal(rotated_first_lowest(scene.faces), rotated_first_lowest(f))
    if indices == "sequence":
        np.testing.assert_array_equal(scene.faces, f)
    # A GLB of the same document, its streams in the binary chunk, reads the same.
    glb = copy.deepcopy(doc)
    path = tmp_path / "meshopt.glb"
    path.write_bytes(to_glb_with_bin(glb, base64_blob(glb["buffers"][0].pop("uri"))))
    again = ss.Scene.load(path)
    np.testing.assert_array_equal(again.vertices, scene.vertices)
    np.testing.assert_array_equal(again.faces, scene.faces)


def rotated_first_lowest(f: np.ndarray) -> np.ndarray:
    """Each triangle's corners rotated (winding kept) so that its lowest index comes first."""
    k = np.argmin(f, axis=1)[:, None]
    return np.take_along_axis(f, (k + np.arange(3)) % 3, axis=1)


def base64_blob(uri: str) -> bytes:
    import base64

    return base64.b64decode(uri.split(",", 1)[1])


def to_glb_with_bin(doc: dict, blob: bytes) -> bytes:
    """A GLB whose buffer 0 is its binary chunk."""
    import struct

    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob += bytes(-len(blob) % 4)
    body = (
        struct.pack("<II", len(text), 0x4E4F534A)
        + text
        + struct.pack("<II", len(blob), 0x004E4942)
        + blob
    )
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def test_meshopt_filters_match_meshoptimizers_own_decode(tmp_path):
    """OCTAHEDRAL normals, EXPONENTIAL positions and COLOR vertex colours read exactly as
    meshoptimizer decodes them, and within their quantization of the arrays they encode;
    KHR_meshopt_compression reads the same streams."""
    v, f = grid()
    for ext in ("EXT_meshopt_compression", "KHR_meshopt_compression"):
        doc = meshopt_mesh("positions_exp", 12, "EXPONENTIAL", "triangles", normals=True, ext=ext)
        scene = ss.Scene.load(write(doc, tmp_path / "filtered.gltf"))
        reference = np.frombuffer(STREAMS["positions_exp_decoded"], np.float32).reshape(-1, 3)
        np.testing.assert_array_equal(scene.vertices, reference)
        np.testing.assert_allclose(scene.vertices, v, atol=2.0**-14)
        octa = np.frombuffer(STREAMS["normals_oct_decoded"], np.int8).reshape(-1, 4)[:, :3]
        expected = np.maximum(octa / 127.0, -1.0)  # snorm8, then unit length as loaded
        expected /= np.linalg.norm(expected, axis=1, keepdims=True)
        np.testing.assert_allclose(scene.normals, expected, atol=1e-6)
        cosine = np.sum(scene.normals * grid_normals(v, f), axis=1)
        angle = np.degrees(np.arccos(np.clip(cosine, -1, 1)))
        assert angle.max() < 2.0, angle.max()
        rgba = np.frombuffer(STREAMS["colors_color_decoded"], np.uint8).reshape(-1, 4)
        np.testing.assert_allclose(scene.colors, rgba[:, :3] / 255.0, atol=1e-6)
        np.testing.assert_allclose(scene.colors, grid_colors(v)[:, :3], atol=3 / 255)


def grid_colors(v: np.ndarray) -> np.ndarray:
    """The fixture's vertex colours (RGBA) of the grid's vertices."""
    return np.stack([v[:, 0], v[:, 1], v[:, 2] * 4, 0.25 + 0.75 * v[:, 0]], -1)


def test_meshopt_quaternion_rotations_play(tmp_path):
    """A clip's rotation output as a QUATERNION-filtered stream (normalized int16): the posed
    vertices are the ones meshoptimizer's decode of the stream gives, and within the filter's
    12 bits of the rotations it encodes."""
    v, f = grid()
    doc, at = meshopt_document({"rotation": ("rotations_quat", 8, "ATTRIBUTES", "QUATERNION")})
    times = (np.arange(289) / 10).astype(np.float32)
    plain = len(doc["buffers"])
    blob = v.tobytes() + times.tobytes() + f.tobytes()
    doc["buffers"].append({"byteLength": len(blob), "uri": data_uri(blob)})
    n = len(doc["bufferViews"])
    for offset, size in (
        (0, v.nbytes),
        (v.nbytes, times.nbytes),
        (v.nbytes + times.nbytes, f.nbytes),
    ):
        doc["bufferViews"].append({"buffer": plain, "byteOffset": offset, "byteLength": size})
    doc["accessors"] = [
        {"bufferView": n, "componentType": 5126, "count": 289, "type": "VEC3",
         "min": [0, 0, 0], "max": [1, 1, 0.25]},
        {"bufferView": n + 2, "componentType": 5125, "count": 1536, "type": "SCALAR"},
        {"bufferView": n + 1, "componentType": 5126, "count": 289, "type": "SCALAR",
         "min": [0.0], "max": [float(times[-1])]},
        {"bufferView": at["rotation"], "componentType": 5122, "normalized": True,
         "count": 289, "type": "VEC4"},
    ]  # fmt: skip
    doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}]
    doc["nodes"] = [{"mesh": 0}]
    doc["scenes"] = [{"nodes": [0]}]
    doc["animations"] = [{
        "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}],
        "samplers": [{"input": 2, "output": 3, "interpolation": "LINEAR"}],
    }]  # fmt: skip
    scene = ss.Scene.load(write(doc, tmp_path / "quat.gltf"))
    decoded = np.frombuffer(STREAMS["rotations_quat_decoded"], np.int16).reshape(-1, 4)
    for k in (0, 40, 288):
        q = np.maximum(decoded[k] / 32767.0, -1.0)
        q = q / np.linalg.norm(q)
        x, y, z, w = q
        rotation = np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ])  # fmt: skip
        posed = scene.at(float(times[k])).vertices
        np.testing.assert_allclose(posed, v @ rotation.T, atol=1e-5)
        angle = k * 0.05
        exact = np.array(
            [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
        )
        np.testing.assert_allclose(posed, v @ exact.T, atol=2e-3)


def test_mutated_meshopt_streams_load_or_name_what_is_wrong(tmp_path):
    """300 seeded mutations of the vertex and index streams (bytes flipped, cut, repeated):
    each file loads or is refused with a SceneError (naming the stream's buffer view, or an
    index the stream decoded to that names no vertex), never the reader's "internal error" (a
    panic caught); and a stream that decodes to more than its view holds is refused."""
    rng = np.random.default_rng(73)
    failures, refusals = [], set()
    original = dict(STREAMS)
    try:
        for k in range(300):
            name = ("positions_v0", "positions_v1", "triangles", "sequence")[k % 4]
            STREAMS[name] = mutated(original[name], rng)
            positions = name if name.startswith("positions") else "positions_v0"
            indices = name if name in ("triangles", "sequence") else "triangles"
            doc = meshopt_mesh(positions, 12, "NONE", indices)
            error = _load_mutant(doc, tmp_path)
            if error and "internal error" in error:
                failures.append((k, error))
            elif error:
                refusals.add(error.split(": ", 1)[1].split(" ")[0])
            STREAMS[name] = original[name]
    finally:
        STREAMS.update(original)
    assert failures == []
    assert refusals <= {"buffer", "mesh"}, refusals
    doc = meshopt_mesh("positions_v0", 12, "NONE", "triangles")
    doc["bufferViews"][0]["byteLength"] = 12 * 288
    with pytest.raises(ss.SceneError, match="EXT_meshopt_compression decodes to 289 x 12 bytes"):
        ss.Scene.load(write(doc, tmp_path / "short.gltf"))
    doc = meshopt_mesh("positions_v0", 12, "NONE", "triangles")
    doc["buffers"][1]["byteLength"] = 2**62
    with pytest.raises(ss.SceneError, match="fallback buffer.*cannot be allocated"):
        ss.Scene.load(write(doc, tmp_path / "huge.gltf"))


@pytest.mark.parametrize(
    "key, value, match",
    [
        ("byteStride", 0, "byteStride must be 4..=256"),
        ("byteStride", "12", "byteStride is not a count"),
        ("mode", "QUADS", "mode QUADS is not one of"),
        ("filter", "WAVELET", "filter WAVELET is not one of"),
        ("count", 2**40, "decodes to 1099511627776 x 12 bytes"),
        ("buffer", 9, "of buffer 9, which it does not have"),
        ("mode", None, "has no mode"),
    ],
)
def test_meshopt_parameters_that_make_no_sense_are_named(tmp_path, key, value, match):
    doc = meshopt_mesh("positions_v0", 12, "NONE", "triangles")
    ext = doc["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]
    if value is None:
        del ext[key]
    else:
        ext[key] = value
    with pytest.raises(ss.SceneError, match=f"buffer view 0: EXT_meshopt_compression.*{match}"):
        ss.Scene.load(write(doc, tmp_path / "bad.gltf"))
