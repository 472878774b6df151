"""glTF skins and morph targets posed by ``Scene.at``: small files written here, sampled at keys
and between them, against a plain float64 implementation of the spec written in this file
(glTF 2.0 §3.7.2.2 morph targets, §3.7.3 skins, Appendix C interpolation); the same geometry
built flat gives the same rays and images; pickles; and bad files refused by name."""

from __future__ import annotations

import base64
import pickle

import numpy as np
import pytest
import scenesample as ss
from gltf_builder import data_uri, write

# -- a plain implementation of the spec -------------------------------------------------------


def _quat_matrix(q):
    x, y, z, w = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _trs(t, r, s):
    m = np.eye(4)
    m[:3, :3] = _quat_matrix(r) * np.asarray(s, np.float64)
    m[:3, 3] = t
    return m


def _slerp(a, b, s):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    d = a @ b
    if d < 0:
        b, d = -b, -d
    if d > 0.9995:
        q = a + s * (b - a)
    else:
        th = np.arccos(d)
        q = (np.sin((1 - s) * th) * a + np.sin(s * th) * b) / np.sin(th)
    return q / np.linalg.norm(q)


def _sample(times, values, interpolation, path, t):
    """Appendix C: one channel's value at t (values: (keys, width), or (3 * keys, width) for
    CUBICSPLINE: in-tangent, value, out-tangent per key)."""
    times = np.asarray(times, np.float64)
    values = np.asarray(values, np.float64)
    cubic = interpolation == "CUBICSPLINE"
    value = (lambda k: values[3 * k + 1]) if cubic else (lambda k: values[k])
    t = min(max(t, times[0]), times[-1])
    if t >= times[-1]:
        return value(len(times) - 1)
    k = int(np.searchsorted(times, t, side="right") - 1)
    dt = times[k + 1] - times[k]
    s = (t - times[k]) / dt
    if interpolation == "STEP":
        return value(k)
    if interpolation == "LINEAR":
        if path == "rotation":
            return _slerp(value(k), value(k + 1), s)
        return (1 - s) * value(k) + s * value(k + 1)
    a, b = value(k), value(k + 1)
    out_a, in_b = values[3 * k + 2], values[3 * (k + 1)]
    s2, s3 = s * s, s * s * s
    return (
        (2 * s3 - 3 * s2 + 1) * a
        + (s3 - 2 * s2 + s) * dt * out_a
        + (-2 * s3 + 3 * s2) * b
        + (s3 - s2) * dt * in_b
    )


class Rig:
    """Nodes (TRS), one mesh with morph targets and/or a skin, and one clip; `document()` writes
    it as glTF, `reference(t)` poses it by the spec."""

    def __init__(self, positions, faces):
        self.positions = np.asarray(positions, np.float32)
        self.faces = np.asarray(faces, np.uint32)
        self.nodes = []  # dicts: parent, t, r, s, plus glTF extras
        self.targets = []  # (V, 3) position displacements
        self.mesh_weights = None
        self.skin = None  # (joint nodes, inverse bind matrices (J, 4, 4) or None)
        self.joints = None  # (V, 4) joint indices per set, list of sets
        self.weights = None
        self.channels = []  # (node, path, interpolation, times, values (rows, width))

    def node(self, parent=None, t=(0, 0, 0), r=(0, 0, 0, 1), s=(1, 1, 1), **extra):
        self.nodes.append({"parent": parent, "t": t, "r": r, "s": s, **extra})
        return len(self.nodes) - 1

    # The spec's answer.
    def _locals(self, t):
        trs = [dict(t=n["t"], r=n["r"], s=n["s"]) for n in self.nodes]
        weights = {}
        for node, path, interp, times, values in self.channels:
            v = _sample(times, values, interp, path, t)
            if path == "weights":
                weights[node] = v
            else:
                trs[node][{"translation": "t", "rotation": "r", "scale": "s"}[path]] = v
        return [_trs(**x) for x in trs], weights

    def _worlds(self, locals_):
        def world(i):
            p = self.nodes[i]["parent"]
            return locals_[i] if p is None else world(p) @ locals_[i]

        return [world(i) for i in range(len(self.nodes))]

    def reference(self, t, mesh_node):
        locals_, keyed = self._locals(t)
        worlds = self._worlds(locals_)
        p = self.positions.astype(np.float64)
        n = self.nodes[mesh_node]
        w = keyed.get(mesh_node, n.get("weights", self.mesh_weights))
        for k, delta in enumerate(self.targets):
            if w is not None and k < len(w):
                p = p + w[k] * delta.astype(np.float64)
        p = np.c_[p, np.ones(len(p))]
        if self.skin is None:
            return (p @ worlds[mesh_node].T)[:, :3]
        joints, ibms = self.skin
        mats = np.array(
            [worlds[j] @ (np.eye(4) if ibms is None else ibms[k]) for k, j in enumerate(joints)]
        )
        out = np.zeros((len(p), 4))
        for js, ws in zip(self.joints, self.weights):
            for c in range(4):
                m = mats[js[:, c]]
                out += ws[:, c, None] * np.einsum("vij,vj->vi", m, p)
        return out[:, :3]

    # The file.
    def document(self, mesh_node):
        bufs, views, accessors = [], [], []

        def accessor(data, type_, component=5126, normalized=False):
            blob = np.ascontiguousarray(data).tobytes()
            bufs.append({"byteLength": len(blob), "uri": data_uri(blob)})
            views.append({"buffer": len(bufs) - 1, "byteLength": len(blob)})
            a = {
                "bufferView": len(views) - 1,
                "componentType": component,
                "count": len(data),
                "type": type_,
            }
            if normalized:
                a["normalized"] = True
            accessors.append(a)
            return len(accessors) - 1

        prim = {
            "attributes": {"POSITION": accessor(self.positions, "VEC3")},
            "indices": accessor(self.faces.ravel(), "SCALAR", 5125),
        }
        if self.targets:
            prim["targets"] = [
                {"POSITION": accessor(np.asarray(d, np.float32), "VEC3")} for d in self.targets
            ]
        if self.joints is not None:
            for k, (js, ws) in enumerate(zip(self.joints, self.weights)):
                prim["attributes"][f"JOINTS_{k}"] = accessor(js.astype(np.uint16), "VEC4", 5123)
                prim["attributes"][f"WEIGHTS_{k}"] = accessor(ws.astype(np.float32), "VEC4")
        mesh = {"primitives": [prim]}
        if self.mesh_weights is not None:
            mesh["weights"] = list(map(float, self.mesh_weights))
        nodes = []
        for i, n in enumerate(self.nodes):
            out = {"translation": list(map(float, n["t"])), "rotation": list(map(float, n["r"]))}
            out["scale"] = list(map(float, n["s"]))
            children = [k for k, m in enumerate(self.nodes) if m["parent"] == i]
            if children:
                out["children"] = children
            if "weights" in n:
                out["weights"] = list(map(float, n["weights"]))
            nodes.append(out)
        nodes[mesh_node]["mesh"] = 0
        skins = []
        if self.skin is not None:
            joints, ibms = self.skin
            skin = {"joints": list(joints)}
            if ibms is not None:
                cols = np.asarray(ibms, np.float32).transpose(0, 2, 1).reshape(-1, 16)
                skin["inverseBindMatrices"] = accessor(cols, "MAT4")
            skins.append(skin)
            nodes[mesh_node]["skin"] = 0
        samplers, channels = [], []
        for node, path, interp, times, values in self.channels:
            i = accessor(np.asarray(times, np.float32), "SCALAR")
            v = np.asarray(values, np.float32)
            o = (
                accessor(v.ravel(), "SCALAR")
                if path == "weights"
                else accessor(v, {3: "VEC3", 4: "VEC4"}[v.shape[1]])
            )
            samplers.append({"input": i, "output": o, "interpolation": interp})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})
        roots = [i for i, n in enumerate(self.nodes) if n["parent"] is None]
        doc = {
            "asset": {"version": "2.0"},
            "buffers": bufs,
            "bufferViews": views,
            "accessors": accessors,
            "meshes": [mesh],
            "nodes": nodes,
            "scenes": [{"nodes": roots}],
            "scene": 0,
        }
        if skins:
            doc["skins"] = skins
        if samplers:
            doc["animations"] = [{"name": "clip", "samplers": samplers, "channels": channels}]
        return doc


def _strip(rows=8):
    """A vertical strip of quads from y = 0 to y = 2, two vertices per row."""
    y = np.linspace(0.0, 2.0, rows + 1)
    v = np.array([[x, yy, 0.0] for yy in y for x in (-0.25, 0.25)], np.float32)
    f = []
    for r in range(rows):
        a = 2 * r
        f += [[a, a + 1, a + 3], [a, a + 3, a + 2]]
    return v, np.array(f)


def _rz(angle):
    return [0.0, 0.0, np.sin(angle / 2), np.cos(angle / 2)]


def _skinned():
    """Khronos' simple skin, made harder: two joints (the second a child of the first, bending
    the strip's upper half), inverse bind matrices that are not the rest worlds' inverses, a
    mesh node whose own transform must be ignored, LINEAR rotation on the upper joint and a
    CUBICSPLINE translation of the root joint."""
    v, f = _strip()
    rig = Rig(v, f)
    mesh = rig.node(t=(5.0, 0.0, 0.0), r=_rz(0.3))  # ignored: the mesh is skinned
    j0 = rig.node(t=(0.0, 0.1, 0.0))
    j1 = rig.node(parent=j0, t=(0.0, 1.0, 0.0))
    ibm = np.array([np.eye(4), np.eye(4)])
    ibm[0][:3, 3] = [0.5, -0.1, 0.0]  # not the inverse of j0's rest world
    ibm[1][:3, 3] = [0.0, -1.1, 0.0]
    rig.skin = ([j0, j1], ibm)
    w1 = np.clip(v[:, 1] - 0.5, 0.0, 1.0)
    rig.joints = [np.tile([0, 1, 0, 0], (len(v), 1))]
    rig.weights = [np.c_[1 - w1, w1, np.zeros((len(v), 2))]]
    rig.channels = [
        (j1, "rotation", "LINEAR", [0.0, 1.0, 2.0], [_rz(0), _rz(1.2), _rz(-0.7)]),
        (
            j0,
            "translation",
            "CUBICSPLINE",
            [0.0, 2.0],
            [[0, 0, 0], [0, 0.1, 0], [1, 0, 0], [0, 0, 0], [0.5, 0.1, 0.2], [0, 0, 0]],
        ),
    ]
    return rig, mesh


def _morphed(interpolation="LINEAR"):
    """A strip with two morph targets (a bend in x, a bulge in z), default weights on the mesh
    and overriding ones on its node, a weights channel, and a node translation: the morphed
    mesh is placed by its node."""
    v, f = _strip()
    rig = Rig(v, f)
    rig.targets = [
        np.c_[0.3 * v[:, 1] ** 2, np.zeros(len(v)), np.zeros(len(v))],
        np.c_[np.zeros(len(v)), np.zeros(len(v)), np.sin(np.pi * v[:, 1] / 2)],
    ]
    rig.mesh_weights = [0.5, 0.5]
    mesh = rig.node(t=(0.0, 0.0, -3.0), weights=[0.25, 0.0])
    times = [0.0, 1.0, 2.5]
    values = [[0.0, 0.0], [1.0, 0.0], [0.2, 1.0]]
    if interpolation == "CUBICSPLINE":
        values = [row for v_ in values for row in ([0.5, -0.5], v_, [1.0, 0.25])]
    rig.channels = [(mesh, "weights", interpolation, times, values)]
    rig.channels.append((mesh, "translation", "LINEAR", [0.0, 2.5], [[0, 0, -3], [1, 0, -3]]))
    return rig, mesh


def _load(rig, mesh, tmp_path, name="rig.gltf"):
    return ss.Scene.load(write(rig.document(mesh), tmp_path / name))


TIMES = [0.0, 0.5, 1.0, 1.37, 2.0, 2.5, 9.0]


@pytest.mark.parametrize("make", [_skinned, _morphed, lambda: _morphed("CUBICSPLINE")])
def test_skins_and_morphs_follow_the_spec_at_keys_and_between(make, tmp_path):
    rig, mesh = make()
    scene = _load(rig, mesh, tmp_path)
    assert not scene.warnings
    # The scene loads in its rest pose: skinned by its joints as loaded, morphed by the node's
    # default weights, not the raw POSITION.
    still = Rig(rig.positions, rig.faces)
    still.__dict__.update({k: v for k, v in rig.__dict__.items() if k != "channels"})
    still.channels = []
    rest = still.reference(0.0, mesh)
    np.testing.assert_allclose(scene.vertices, rest, rtol=0, atol=2e-6)
    assert not np.allclose(scene.vertices, rig.positions, atol=1e-3)
    for t in TIMES:
        posed = scene.at(t)
        np.testing.assert_allclose(
            posed.vertices, rig.reference(t, mesh), rtol=0, atol=4e-6, err_msg=f"t={t}"
        )
    # It moves: the pose at 1.37 s is not the rest pose.
    assert np.abs(scene.at(1.37).vertices - scene.vertices).max() > 0.05


def test_a_skinned_meshs_own_node_transform_is_ignored_and_its_transform_is_the_identity(
    tmp_path,
):
    rig, mesh = _skinned()
    scene = _load(rig, mesh, tmp_path)
    # The mesh node sits at x = 5, turned: the skinned strip stays near the joints (x near 0).
    assert abs(scene.vertices[:, 0]).max() < 1.5
    posed = scene.at(1.0)
    np.testing.assert_array_equal(posed.transforms[0], np.eye(4))
    assert posed._core.deforms


def test_skinned_and_morphed_poses_trace_like_the_same_geometry_built_flat(tmp_path):
    for make in (_skinned, _morphed):
        rig, mesh = make()
        posed = _load(rig, mesh, tmp_path).at(1.37)
        flat = ss.Scene.from_arrays(posed.vertices, posed.faces)
        rng = np.random.default_rng(3)
        lo, hi = posed.bounds
        o = rng.uniform(lo - 1, hi + 1, (4000, 3)).astype(np.float32)
        d = rng.uniform(lo, hi, (4000, 3)).astype(np.float32) - o
        a, b = ss.cast_rays(posed, o, d), ss.cast_rays(flat, o, d)
        np.testing.assert_array_equal(a.triangle, b.triangle)
        np.testing.assert_array_equal(a.t, b.t)
        assert (a.triangle >= 0).sum() > 200
        mid = (lo + hi) / 2
        cam = ss.Camera.look_at(
            mid + (0.0, 0.0, 2.5), mid, (0, 1, 0), yfov=0.9, width=64, height=48
        )
        for backend in ("cpu", "gpu"):
            ia = ss.discretize(posed, cameras=[cam], backend=backend)
            ib = ss.discretize(flat, cameras=[cam], backend=backend)
            assert (ia.triangle >= 0).mean() > 0.1
            np.testing.assert_array_equal(ia.triangle, ib.triangle)
            np.testing.assert_array_equal(ia.depth, ib.depth)


def test_a_skinned_pose_travels_in_a_pickle_bit_for_bit(tmp_path):
    rig, mesh = _skinned()
    posed = _load(rig, mesh, tmp_path).at(0.7)
    back = pickle.loads(pickle.dumps(posed))
    np.testing.assert_array_equal(back.vertices, posed.vertices)
    np.testing.assert_array_equal(back.transforms, posed.transforms)
    assert back._core.deforms


def test_a_users_pose_moves_the_skinned_mesh_after_its_skin(tmp_path):
    rig, mesh = _skinned()
    scene = _load(rig, mesh, tmp_path)
    m = np.eye(4)
    m[:3, 3] = [0.0, 0.0, 10.0]
    posed = scene.posed([m]).at(1.0)
    np.testing.assert_allclose(
        posed.vertices, rig.reference(1.0, mesh) + [0, 0, 10.0], rtol=0, atol=4e-6
    )


def test_weights_channels_count_in_durations_and_key_times(tmp_path):
    rig, mesh = _morphed()
    rig.channels = rig.channels[:1]
    scene = _load(rig, mesh, tmp_path)
    assert scene.animations == [("clip", 2.5)]
    np.testing.assert_allclose(scene.key_times("clip"), [0.0, 1.0, 2.5])


def test_two_joint_sets_blend_like_one(tmp_path):
    """JOINTS_1 / WEIGHTS_1 carry the second half of each vertex's influences."""
    rig, mesh = _skinned()
    js, ws = rig.joints[0], rig.weights[0]
    rig.joints = [
        np.c_[js[:, :1], np.zeros((len(js), 3), int)],
        np.c_[js[:, 1:2], np.zeros((len(js), 3), int)],
    ]
    rig.weights = [
        np.c_[ws[:, :1], np.zeros((len(ws), 3))],
        np.c_[ws[:, 1:2], np.zeros((len(ws), 3))],
    ]
    scene = _load(rig, mesh, tmp_path)
    np.testing.assert_allclose(scene.at(1.37).vertices, rig.reference(1.37, mesh), atol=4e-6)


def _refused(doc, tmp_path, match):
    with pytest.raises(ss.SceneError, match=match):
        ss.Scene.load(write(doc, tmp_path / "bad.gltf"))


def test_bad_skins_are_refused_by_name(tmp_path):
    rig, mesh = _skinned()
    doc = rig.document(mesh)
    bad = dict(doc, skins=[dict(doc["skins"][0], joints=[1, 99])])
    _refused(bad, tmp_path, "skin 0 names node 99")
    bad = dict(doc, nodes=[dict(doc["nodes"][0], skin=3)] + doc["nodes"][1:])
    _refused(bad, tmp_path, "names skin 3")
    bad = dict(doc, skins=[dict(doc["skins"][0], joints=[1])])
    _refused(bad, tmp_path, "2 matrices for 1 joints|names joint 1 of a skin with 1")
    # A joint index past the skin's, with a weight.
    rig.joints = [np.tile([0, 7, 0, 0], (len(rig.positions), 1))]
    _refused(rig.document(mesh), tmp_path, "JOINTS_0: vertex .* names joint 7")
    # A negative weight.
    rig, mesh = _skinned()
    rig.weights[0][3, 0] = -1.0
    _refused(rig.document(mesh), tmp_path, "WEIGHTS_0: vertex 3 has weight -1")


def test_bad_morph_targets_are_refused_or_skipped_by_name(tmp_path):
    rig, mesh = _morphed()
    doc = rig.document(mesh)
    prim = doc["meshes"][0]["primitives"][0]
    prim["targets"][0]["POSITION"] = 999
    _refused(doc, tmp_path, "morph target 0 refers to accessor 999")
    # A weights channel on a node without morph targets is skipped with a warning.
    rig, mesh = _skinned()
    other = rig.node(t=(0, 0, 0))
    rig.channels.append((other, "weights", "LINEAR", [0.0, 1.0], [[0.0], [1.0]]))
    with pytest.warns(ss.SceneWarning, match="has no morph targets"):
        scene = _load(rig, mesh, tmp_path)
    np.testing.assert_allclose(scene.at(1.0).vertices, rig.reference(1.0, mesh), atol=4e-6)


def test_unweighted_vertices_follow_their_first_joint_with_a_warning(tmp_path):
    rig, mesh = _skinned()
    rig.weights[0][:2] = 0.0
    with pytest.warns(ss.SceneWarning, match="2 vertices have skin weights that sum to 0"):
        scene = _load(rig, mesh, tmp_path)
    rig.weights[0][:2, 0] = 1.0
    np.testing.assert_allclose(scene.at(1.0).vertices, rig.reference(1.0, mesh), atol=4e-6)


def test_a_glb_skin_reads_like_the_gltf(tmp_path):
    from gltf_builder import to_glb

    rig, mesh = _skinned()
    doc = rig.document(mesh)
    # Merge every data-URI buffer into buffer 0 so that to_glb moves it into the BIN chunk.
    blobs = [base64.b64decode(b["uri"].split(",", 1)[1]) for b in doc["buffers"]]
    offsets = np.cumsum([0] + [len(b) + (-len(b) % 4) for b in blobs])
    for v in doc["bufferViews"]:
        v["byteOffset"] = int(offsets[v["buffer"]])
        v["buffer"] = 0
    blob = b"".join(b + b"\0" * (-len(b) % 4) for b in blobs)
    doc["buffers"] = [{"byteLength": len(blob), "uri": data_uri(blob)}]
    path = tmp_path / "rig.glb"
    path.write_bytes(to_glb(doc))
    a = ss.Scene.load(path).at(1.37)
    b = _load(*_skinned(), tmp_path).at(1.37)
    np.testing.assert_array_equal(a.vertices, b.vertices)


def test_mutated_skinned_and_morphed_files_load_or_name_what_is_wrong(tmp_path):
    """300 seeded mutations each of a skinned and a morphed file, posed at two times: a scene or
    a typed error, never the reader's "internal error" (a panic caught)."""
    from fuzz_loaders import posing_internal_errors

    for make in (_skinned, _morphed):
        rig, mesh = make()
        data = write(rig.document(mesh), tmp_path / "rig.gltf").read_bytes()
        assert posing_internal_errors(data, 11, 300, tmp_path) == [], make.__name__


def test_a_bend_that_loosens_the_refit_tree_is_built_afresh(tmp_path):
    """A tube of 102,400 triangles bent by its 8 joints widens its root box: its refit tree
    would cost 2.5x a fresh one while its cost relative to the root grew only 1.28x, so the
    pose is built afresh (the same tree as a fresh build). Stretched by 1% instead, it is
    refit (a tree unlike a fresh build's). Hits agree with the flat build either way."""

    scene = ss.Scene.load(ss.scenes.bending_tube(tmp_path))
    bent = scene.at(0.5)
    stretched = scene.deformed(scene.vertices * np.float32([1.0, 1.01, 1.0]))
    for shape, rebuilt in ((bent, True), (stretched, False)):
        flat = ss.Scene.from_arrays(shape.vertices, shape.faces)
        assert (ss.bvh_stats(shape)["sah"] == ss.bvh_stats(flat)["sah"]) == rebuilt
        rng = np.random.default_rng(4)
        lo, hi = shape.bounds
        o = rng.uniform(lo - 1, hi + 1, (20_000, 3)).astype(np.float32)
        d = (shape.vertices[rng.integers(0, len(shape.vertices), 20_000)] - o).astype(np.float32)
        a, b = ss.cast_rays(shape, o, d), ss.cast_rays(flat, o, d)
        np.testing.assert_array_equal(a.triangle, b.triangle)
        assert (a.triangle >= 0).mean() > 0.5
