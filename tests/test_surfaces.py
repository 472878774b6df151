"""Colour and shading normals as viewers draw them (issue 72): the base-colour texture sampled
per sample (bilinear where magnified, mip-mapped where minified, wrap modes, texture
transforms) and the file's normals interpolated (posed by nodes, skins and morph targets),
each checked against an independent per-pixel reference written here in numpy: the file's
attributes interpolated by barycentrics and sampled bilinearly."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import scenesample as ss
from gltf_builder import add_accessor, data_uri, document, write
from scenesample.imageio import linear_to_srgb

QUAD = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
QUAD_FACES = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)


def srgb_to_linear(u8: np.ndarray) -> np.ndarray:
    c = u8.astype(np.float64) / 255
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def wrapped(i: np.ndarray, n: int, mode: int) -> np.ndarray:
    if mode == 33071:  # CLAMP_TO_EDGE
        return np.clip(i, 0, n - 1)
    if mode == 33648:  # MIRRORED_REPEAT
        m = np.mod(i, 2 * n)
        return np.where(m < n, m, 2 * n - 1 - m)
    return np.mod(i, n)  # REPEAT


def bilinear(texels: np.ndarray, uv: np.ndarray, wrap=(10497, 10497)) -> np.ndarray:
    """The reference texture lookup: sRGB decoded, then bilinear between texel centres."""
    h, w = texels.shape[:2]
    lin = srgb_to_linear(texels[..., :3])
    x, y = uv[..., 0] * w - 0.5, uv[..., 1] * h - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    xs = [wrapped(x0 + k, w, wrap[0]) for k in (0, 1)]
    ys = [wrapped(y0 + k, h, wrap[1]) for k in (0, 1)]
    top = lin[ys[0], xs[0]] * (1 - fx) + lin[ys[0], xs[1]] * fx
    bottom = lin[ys[1], xs[0]] * (1 - fx) + lin[ys[1], xs[1]] * fx
    return top * (1 - fy) + bottom * fy


def barycentrics(vertices, faces, triangle, position) -> np.ndarray:
    """(b1, b2) of each position on its triangle, in float64 (least squares in the plane)."""
    p = vertices.astype(np.float64)[faces[triangle]]
    e1, e2, r = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], position - p[:, 0]
    d11, d12, d22 = (e1 * e1).sum(-1), (e1 * e2).sum(-1), (e2 * e2).sum(-1)
    r1, r2 = (r * e1).sum(-1), (r * e2).sum(-1)
    det = d11 * d22 - d12 * d12
    return np.stack([(d22 * r1 - d12 * r2) / det, (d11 * r2 - d12 * r1) / det], -1)


def interpolate(values, faces, triangle, b) -> np.ndarray:
    v = values.astype(np.float64)[faces[triangle]]
    return v[:, 0] * (1 - b[:, :1] - b[:, 1:]) + v[:, 1] * b[:, :1] + v[:, 2] * b[:, 1:]


def checker(n: int, cell: int = 1) -> np.ndarray:
    """(n, n, 4) uint8: a checkerboard whose dark and light squares also vary in colour across
    the image (so that a flipped or shifted lookup shows)."""
    j, i = np.meshgrid(np.arange(n), np.arange(n))
    light = (i // cell + j // cell) % 2 == 0
    rgb = np.where(
        light[..., None],
        np.stack([np.full_like(i, 230), 40 + 200 * i // n, 30 + 200 * j // n], -1),
        np.stack([np.full_like(i, 20), 220 - 200 * j // n, np.full_like(i, 90)], -1),
    )
    return np.concatenate([rgb, np.full((n, n, 1), 255)], -1).astype(np.uint8)


def png(texels: np.ndarray) -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(texels).save(out, format="PNG")
    return out.getvalue()


def textured_quad(tmp_path, texels, uv, *, sampler=None, transform=None, name="quad.gltf"):
    """The unit quad in z = 0 with TEXCOORD_0 `uv`, its material's base colour texture
    `texels` (a PNG in a data URI), an optional sampler and KHR_texture_transform."""
    doc = document(QUAD, QUAD_FACES)
    prim = doc["meshes"][0]["primitives"][0]
    prim["attributes"]["TEXCOORD_0"] = add_accessor(doc, uv, "VEC2")
    prim["material"] = 0
    doc["images"] = [{"uri": data_uri(png(texels), "image/png")}]
    doc["textures"] = [{"source": 0, **({"sampler": 0} if sampler else {})}]
    if sampler:
        doc["samplers"] = [sampler]
    info = {"index": 0}
    if transform:
        info["extensions"] = {"KHR_texture_transform": transform}
        doc["extensionsUsed"] = ["KHR_texture_transform"]
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": info}}]
    return ss.Scene.load(write(doc, tmp_path / name))


def front(pixels: int, distance: float = 1.6, yfov: float = 0.7) -> ss.Camera:
    return ss.Camera.look_at(
        (0.5, 0.5, distance), (0.5, 0.5, 0), (0, 1, 0), yfov=yfov, width=pixels, height=pixels
    )


def reference_colors(scene, img, k, texels, wrap=(10497, 10497), transform=None):
    """The reference colour at every covered pixel of image k: texture coordinates interpolated
    from the vertices at the pixel's point, through `transform` (2x3), sampled bilinearly."""
    mask = img.triangle[k] >= 0
    tri, pos = img.triangle[k][mask], img.position[k][mask].astype(np.float64)
    b = barycentrics(scene.vertices, scene.faces, tri, pos)
    uv = interpolate(scene.texcoords, scene.faces, tri, b)
    if transform is not None:
        uv = uv @ np.asarray(transform)[:, :2].T + np.asarray(transform)[:, 2]
    return mask, bilinear(texels, uv, wrap)


def srgb_error(ours: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per-pixel colour difference in 8-bit display values (the largest channel)."""
    a = linear_to_srgb(ours).astype(np.int32)
    b = linear_to_srgb(ref).astype(np.int32)
    return np.abs(a - b).max(-1)


@pytest.fixture(params=["cpu", "gpu"])
def backend(request):
    if request.param == "gpu" and not ss.device_info()["available"]:
        pytest.skip("no GPU adapter")
    return request.param


def test_a_magnified_texture_is_the_bilinear_lookup_of_every_pixel(tmp_path, backend):
    """8x8 texels over 128x128 pixels: each pixel's colour is the reference's bilinear lookup
    at its texture coordinate (median <= 2/255 and 95th percentile <= 16/255 in display values,
    the issue's targets; here far tighter). With textures read as their mean, the median error
    is near 100/255."""
    tex = checker(8)
    scene = textured_quad(tmp_path, tex, QUAD[:, :2].copy())
    img = ss.discretize(scene, [front(128)], backend=backend)
    mask, ref = reference_colors(scene, img, 0, tex)
    err = srgb_error(img.color[0][mask], ref)
    assert mask.sum() > 8000
    assert np.median(err) <= 1 and np.percentile(err, 95) <= 2, np.percentile(err, [50, 95, 100])
    # The vertices' colour stays the factor (white), the texture multiplies it per sample.
    np.testing.assert_array_equal(scene.colors, np.ones((4, 3), np.float32))


def test_a_minified_texture_reads_the_mip_level_of_its_footprint(tmp_path, backend):
    """A 256x256 black-and-white checkerboard of single texels over about 30x30 pixels: each
    pixel covers some 8x8 texels, so it reads the grey of their mean (linear 0.5, 188 in sRGB)
    from the mip chain, where a lookup of the finest level alone aliases to black and white."""
    n = 256
    j, i = np.meshgrid(np.arange(n), np.arange(n))
    bw = np.where(((i + j) % 2 == 0)[..., None], 255, 0).astype(np.uint8)
    tex = np.concatenate([np.repeat(bw, 3, -1), np.full((n, n, 1), 255, np.uint8)], -1)
    scene = textured_quad(tmp_path, tex, QUAD[:, :2].copy())
    img = ss.discretize(scene, [front(64, distance=4.0, yfov=0.5)], backend=backend)
    inner = img.triangle[0] >= 0
    shown = linear_to_srgb(img.color[0][inner]).astype(np.float64)
    assert inner.sum() > 400
    assert abs(np.median(shown) - 188) <= 3 and np.percentile(np.abs(shown - 188), 95) <= 6


@pytest.mark.parametrize(
    "wrap, transform",
    [
        ((33071, 33071), None),
        ((33648, 10497), None),
        ((10497, 10497), {"offset": [0.25, 0.5], "rotation": 0.4, "scale": [1.5, 0.75]}),
    ],
)
def test_wrap_modes_and_texture_transforms(tmp_path, wrap, transform):
    """Texture coordinates from -0.5 to 1.5 across the quad, clamped, mirrored or repeated as
    the sampler says, and moved by KHR_texture_transform (T * R * S, the sample renderer's
    rotation) before the lookup."""
    tex = checker(8)
    uv = QUAD[:, :2] * 2 - 0.5
    sampler = {"wrapS": wrap[0], "wrapT": wrap[1], "magFilter": 9729}
    scene = textured_quad(tmp_path, tex, uv, sampler=sampler, transform=transform)
    m = None
    if transform:
        c, s = np.cos(transform["rotation"]), np.sin(transform["rotation"])
        (sx, sy), (ox, oy) = transform["scale"], transform["offset"]
        m = [[c * sx, s * sy, ox], [-s * sx, c * sy, oy]]
        np.testing.assert_allclose(scene.materials[0]["base_color_texture"]["transform"], m)
    img = ss.discretize(scene, [front(96)], backend="cpu")
    mask, ref = reference_colors(scene, img, 0, tex, wrap, m)
    err = srgb_error(img.color[0][mask], ref)
    assert np.median(err) <= 1 and np.percentile(err, 95) <= 2, np.percentile(err, [50, 95, 100])


def test_every_path_that_makes_a_colour_samples_the_texture(tmp_path, gpu):
    """Peeled layers, non-redundant images, the visibility field's views, EPR points and ray
    hits take their colour from the texture too, not from a material's mean."""
    tex = checker(8)
    scene = textured_quad(tmp_path, tex, QUAD[:, :2].copy())
    cam = front(96)
    paths = {
        "peeling": ss.discretize(scene, [cam], "peeling", layers=2),
        "nonredundant": ss.discretize(scene, [cam, front(96, distance=1.7)], "nonredundant"),
    }
    field = ss.discretize(scene, method="visibility_field", uv=(8, 8), st=(8, 8))
    paths["visibility field"] = ss.reconstruct(field, cam).image
    for name, img in paths.items():
        mask, ref = reference_colors(scene, img, 0, tex)
        err = srgb_error(img.color[0][mask], ref)
        assert mask.sum() > 3000 and np.median(err) <= 1, (name, np.percentile(err, [50, 95]))
    o, d = cam.pixel_rays()
    hits = ss.cast_rays(scene, o, d)
    a = ss.surface_attributes(scene, hits)
    ref = bilinear(tex, a.texcoord[hits.hit])
    assert np.median(srgb_error(a.color[hits.hit], ref)) <= 1
    pts = ss.Points.from_arrays(
        scene, [[0.1, 0.2, 0], [0.6, 0.3, 0], [0.45, 0.9, 0]], [1e-3] * 3, [1, 0, 1], cameras=[cam]
    )
    ref = bilinear(tex, pts.center[:, :2].astype(np.float64))
    assert srgb_error(pts.color, ref).max() <= 2


def sphere(rows: int = 12, cols: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere of radius 1: its vertices (also its analytic normals) and faces."""
    theta = np.linspace(0, np.pi, rows + 1)
    phi = np.linspace(0, 2 * np.pi, cols + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    v = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a, b = r * (cols + 1) + c, r * (cols + 1) + c + 1
    f = np.concatenate(
        [np.stack([a, b, a + cols + 1], -1), np.stack([b, b + cols + 1, a + cols + 1], -1)]
    )
    return v.astype(np.float32), f.reshape(-1, 3).astype(np.uint32)


def angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Degrees between unit vectors."""
    cos = (a * b).sum(-1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def test_shading_normals_are_the_files_normals_interpolated(tmp_path, backend):
    """A UV sphere whose NORMAL is its analytic normal, under a rotated and non-uniformly scaled
    node: the images' shading normal is the file's normals, placed by the node's inverse
    transpose, interpolated at each pixel (median <= 0.5 deg and 99th percentile <= 3 deg, the
    issue's targets; here within 0.01 deg), where the geometric normal is off by the facets."""
    v, f = sphere()
    doc = document(v, f)
    doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = add_accessor(doc, v, "VEC3")
    q = np.array([0.2, 0.3, 0.1, 0.927]) / np.linalg.norm([0.2, 0.3, 0.1, 0.927])
    doc["nodes"][0].update(rotation=q.tolist(), scale=[1.0, 0.6, 1.3])
    scene = ss.Scene.load(write(doc, tmp_path / "sphere.gltf"))
    # The node's normal matrix: the inverse transpose of its linear part.
    x, y, z, w = q
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    linear = rot @ np.diag([1.0, 0.6, 1.3])
    placed = v @ np.linalg.inv(linear)
    placed /= np.linalg.norm(placed, axis=1, keepdims=True)
    np.testing.assert_allclose(scene.normals, placed, atol=1e-6)
    cam = ss.Camera.look_at((0.3, 0.4, 3.5), (0, 0, 0), yfov=0.8, width=96, height=96)
    img = ss.discretize(scene, [cam], backend=backend)
    mask = img.triangle[0] >= 0
    tri, pos = img.triangle[0][mask], img.position[0][mask].astype(np.float64)
    b = barycentrics(scene.vertices, scene.faces, tri, pos)
    ref = interpolate(scene.normals, scene.faces, tri, b)
    err = angles(img.shading_normal[0][mask], ref)
    assert np.median(err) <= 0.01 and np.percentile(err, 99) <= 0.05, np.percentile(err, [50, 99])
    assert np.median(angles(img.normal[0][mask], ref)) > 0.5  # the facets, not the file's


def skinned_strip(tmp_path, angle: float):
    """A strip along x (z = 0, NORMAL +z) skinned to two joints at x = 0 and x = 1: vertices
    with x <= 0.5 follow joint 0, x >= 1.5 joint 1, between them a linear blend; one clip turns
    joint 1 about x by `angle` over a second, and morph target 0 tilts every normal toward +x
    (NORMAL displacement (1, 0, 0)), keyed to weight 0.5 by the same clip."""
    xs = np.linspace(0, 2, 9)
    v = np.array([[x, y, 0] for x in xs for y in (0.0, 0.2)], np.float32)
    f = np.array(
        [[2 * k, 2 * k + 2, 2 * k + 1] for k in range(8)]
        + [[2 * k + 1, 2 * k + 2, 2 * k + 3] for k in range(8)],
        np.uint32,
    )
    doc = document(v, f)
    prim = doc["meshes"][0]["primitives"][0]
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1)).astype(np.float32)
    prim["attributes"]["NORMAL"] = add_accessor(doc, n, "VEC3")
    w1 = np.clip(v[:, 0] - 0.5, 0, 1)
    weights = np.stack([1 - w1, w1, 0 * w1, 0 * w1], -1).astype(np.float32)
    joints = np.tile([0, 1, 0, 0], (len(v), 1)).astype(np.uint16)
    blob = joints.tobytes()
    doc["buffers"].append({"byteLength": len(blob), "uri": data_uri(blob)})
    doc["bufferViews"].append({"buffer": len(doc["buffers"]) - 1, "byteLength": len(blob)})
    doc["accessors"].append(
        {"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5123, "count": len(v),
         "type": "VEC4"}
    )  # fmt: skip
    prim["attributes"]["JOINTS_0"] = len(doc["accessors"]) - 1
    prim["attributes"]["WEIGHTS_0"] = add_accessor(doc, weights, "VEC4")
    deltas = np.zeros_like(v)
    tilt = np.tile([1.0, 0.0, 0.0], (len(v), 1)).astype(np.float32)
    prim["targets"] = [
        {"POSITION": add_accessor(doc, deltas, "VEC3"), "NORMAL": add_accessor(doc, tilt, "VEC3")}
    ]
    ibm = np.tile(np.eye(4, dtype=np.float32), (2, 1, 1))
    ibm[1, 0, 3] = -1.0
    doc["nodes"] = [
        {"mesh": 0, "skin": 0},
        {"children": [2]},
        {"translation": [1.0, 0.0, 0.0]},
    ]
    columns = ibm.transpose(0, 2, 1).reshape(-1, 16)
    doc["skins"] = [{"joints": [1, 2], "inverseBindMatrices": add_accessor(doc, columns, "MAT4")}]
    t = add_accessor(doc, np.array([[0.0], [1.0]], np.float32), "SCALAR")
    q = [[0, 0, 0, 1], [np.sin(angle / 2), 0, 0, np.cos(angle / 2)]]
    turn = add_accessor(doc, np.array(q, np.float32), "VEC4")
    weight = add_accessor(doc, np.array([[0.0], [0.5]], np.float32), "SCALAR")
    doc["animations"] = [
        {
            "name": "bend",
            "samplers": [{"input": t, "output": turn}, {"input": t, "output": weight}],
            "channels": [
                {"sampler": 0, "target": {"node": 2, "path": "rotation"}},
                {"sampler": 1, "target": {"node": 0, "path": "weights"}},
            ],
        }
    ]
    doc["scenes"] = [{"nodes": [0, 1]}]
    return ss.Scene.load(write(doc, tmp_path / "strip.gltf")), v, weights


def test_skinned_and_morphed_normals_follow_the_joints(tmp_path):
    """Linear blend skinning of normals, against a float64 reading of the spec written here:
    the morphed normal (+z plus weight x (1, 0, 0)) through the inverse transpose of each
    vertex's blended joint matrix, normalized. The images' shading normal interpolates them."""
    angle = 1.1
    scene, v, weights = skinned_strip(tmp_path, angle)
    np.testing.assert_allclose(scene.normals, np.tile([0, 0, 1.0], (len(v), 1)), atol=1e-7)
    posed = scene.at(1.0)
    c, s = np.cos(angle), np.sin(angle)
    turn = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    morphed = np.array([0.5, 0.0, 1.0])
    expect = []
    for w1 in weights[:, 1]:
        blend = (1 - w1) * np.eye(3) + w1 * turn
        n = np.linalg.inv(blend).T @ morphed
        expect.append(n / np.linalg.norm(n))
    np.testing.assert_allclose(posed.normals, expect, atol=1e-6)
    cam = ss.Camera.look_at((1.0, -1.5, 2.5), (1.0, 0.2, 0.2), yfov=0.9, width=64, height=64)
    img = ss.discretize(posed, [cam], backend="cpu")
    mask = img.triangle[0] >= 0
    tri, pos = img.triangle[0][mask], img.position[0][mask].astype(np.float64)
    b = barycentrics(posed.vertices, posed.faces, tri, pos)
    ref = interpolate(posed.normals, posed.faces, tri, b)
    err = angles(img.shading_normal[0][mask], ref)
    assert mask.sum() > 100 and np.median(err) <= 0.01 and np.percentile(err, 99) <= 0.05


def test_animated_scenes_keep_their_animations_through_pickle_and_deepcopy(tmp_path):
    """A user who sends a scene to worker processes to render frames needs its clips: once,
    they were dropped ("the scene has no animations")."""
    import copy
    import pickle

    scene, _, _ = skinned_strip(tmp_path, 0.8)
    for other in (pickle.loads(pickle.dumps(scene)), copy.deepcopy(scene)):
        assert other.animations == scene.animations
        for t in (0.25, 1.0):
            a, b = scene.at(t), other.at(t)
            np.testing.assert_array_equal(a.vertices, b.vertices)
            np.testing.assert_array_equal(a.normals, b.normals)
        # A pose whose skin moved vertices travels with its vertices and normals.
        posed = pickle.loads(pickle.dumps(scene.at(0.5)))
        np.testing.assert_array_equal(posed.normals, scene.at(0.5).normals)


def test_a_tampered_pickle_of_animations_is_refused_by_name(tmp_path):
    scene, _, _ = skinned_strip(tmp_path, 0.8)
    _, (state,) = scene.__reduce__()
    for path, value in [
        (("clips", 0, "channels", 0, "node"), 99),
        (("rigging", "skins", 0, "joints", 0), 7),
        (("nodes", 1, "parent"), 1),
    ]:
        a = json.loads(state["animations"])
        target = a
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
        with pytest.raises(ss.InputError, match="the animations do not fit their scene"):
            ss.Scene.from_arrays(**{**state, "animations": json.dumps(a)})
    with pytest.raises(ss.InputError, match="the animations cannot be read"):
        ss.Scene.from_arrays(**{**state, "animations": "{"})


def test_a_textured_scene_travels_in_a_pickle_bit_for_bit(tmp_path):
    tex = checker(8)
    scene = textured_quad(tmp_path, tex, QUAD[:, :2].copy(), sampler={"wrapS": 33071})
    import pickle

    back = pickle.loads(pickle.dumps(scene))
    np.testing.assert_array_equal(back.textures[0], tex)
    assert back.materials == scene.materials
    a = ss.discretize(scene, [front(48)], backend="cpu")
    b = ss.discretize(back, [front(48)], backend="cpu")
    np.testing.assert_array_equal(a.color, b.color)


def test_surface_attributes_take_any_hits_and_check_their_input(tmp_path):
    tex = checker(8)
    scene = textured_quad(tmp_path, tex, QUAD[:, :2].copy())
    o = np.tile([[0.3, 0.6, 1.0]], (5, 1)) + np.linspace(0, 0.2, 5)[:, None] * [1, 0, 0]
    d = np.tile([0.0, 0.0, -1.0], (5, 1))
    two = ss.cast_rays(scene, o, d, max_hits=2)
    a = ss.surface_attributes(scene, two)
    assert a.color.shape == (5, 2, 3) and a.texcoord.shape == (5, 2, 2)
    assert np.isnan(a.texcoord[:, 1]).all() and (a.color[:, 1] == 0).all()
    np.testing.assert_allclose(a.texcoord[:, 0], o[:, :2], atol=1e-6)
    np.testing.assert_allclose(a.shading_normal[:, 0], np.tile([0, 0, 1.0], (5, 1)))
    every = ss.surface_attributes(scene, ss.all_hits(scene, o, d))
    np.testing.assert_array_equal(every.color, a.color[:, 0])
    # A footprint of the whole quad reads the texture's mean.
    wide = ss.surface_attributes(scene, triangle=[0], barycentric=[[0.3, 0.3]], footprint=2.0)
    mean = srgb_to_linear(tex[..., :3]).mean((0, 1))
    np.testing.assert_allclose(wide.color[0], mean, atol=0.02)
    with pytest.raises(ss.InputError, match="triangle\\[1\\] is 7"):
        ss.surface_attributes(scene, triangle=[0, 7], barycentric=[[0, 0], [0, 0]])
    with pytest.raises(ss.InputError, match="barycentric must have shape"):
        ss.surface_attributes(scene, triangle=[0, 1], barycentric=[[0, 0]])
    with pytest.raises(ss.InputError, match="triangle and barycentric"):
        ss.surface_attributes(scene, np.zeros(3))
