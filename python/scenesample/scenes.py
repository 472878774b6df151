"""Seeded, deterministic procedural scenes, and the real third-party scenes of ``../shared``.

Every generator takes a ``seed`` and returns a :class:`scenesample.Scene`; the same arguments give
the same triangles, bit for bit.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ._core import Camera
from ._paper_scenes import PAPER_SCENES, bird_nest, grass, reference_cameras, tree, turtles, urban
from ._scene import Scene
from .errors import SceneFileError

__all__ = [
    "PAPER_SCENES",
    "bending_tube",
    "bird_nest",
    "grass",
    "icosphere",
    "reference_cameras",
    "reflective_room",
    "reflective_room_eye",
    "shapes",
    "shared",
    "shared_scene_files",
    "shared_scenes_dir",
    "tree",
    "turtles",
    "urban",
]


def _icosphere_arrays(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    t = (1.0 + 5.0**0.5) / 2.0
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
         (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]  # fmt: skip
    verts = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in v]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]  # fmt: skip
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}
        nxt = []
        for a, b, c in faces:
            ab, bc, ca = (_midpoint(verts, cache, x, y) for x, y in ((a, b), (b, c), (c, a)))
            nxt += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = nxt
    return np.array(verts), np.array(faces, dtype=np.int64)


def _midpoint(verts: list, cache: dict[tuple[int, int], int], a: int, b: int) -> int:
    """Index of the unit-sphere midpoint of edge (a, b), created once per edge."""
    key = (min(a, b), max(a, b))
    if key not in cache:
        m = verts[a] + verts[b]
        verts.append(m / np.linalg.norm(m))
        cache[key] = len(verts) - 1
    return cache[key]


def icosphere(subdivisions: int = 3, radius: float = 1.0, center=(0.0, 0.0, 0.0)) -> Scene:
    """A closed icosphere: 20 * 4**subdivisions triangles sharing every edge and vertex."""
    v, f = _icosphere_arrays(subdivisions)
    return Scene.from_arrays(v * radius + np.asarray(center, dtype=np.float64), f)


def _box(lo: np.ndarray, hi: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box, each face an n x n grid of quads (outward counter-clockwise)."""
    verts, faces = [], []
    s = np.linspace(0.0, 1.0, n + 1)
    uu, vv = np.meshgrid(s, s, indexing="ij")
    for axis in range(3):
        for side in (0, 1):
            a, b = (axis + 1) % 3, (axis + 2) % 3
            p = np.zeros(((n + 1) ** 2, 3))
            p[:, axis] = (lo, hi)[side][axis]
            p[:, a] = lo[a] + uu.ravel() * (hi[a] - lo[a])
            p[:, b] = lo[b] + vv.ravel() * (hi[b] - lo[b])
            base = sum(len(x) for x in verts)
            idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1) + base
            q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(
                -1, 4
            )
            tri = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
            if side == 0:
                tri = tri[:, ::-1]
            verts.append(p)
            faces.append(tri)
    return np.concatenate(verts), np.concatenate(faces)


def _torus(r_major: float, r_minor: float, nu: int, nv: int) -> tuple[np.ndarray, np.ndarray]:
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    v = np.linspace(0, 2 * np.pi, nv, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    x = (r_major + r_minor * np.cos(vv)) * np.cos(uu)
    z = (r_major + r_minor * np.cos(vv)) * np.sin(uu)
    y = r_minor * np.sin(vv)
    verts = np.stack([x, y, z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = i * nv + j
    b = ((i + 1) % nu) * nv + j
    c = ((i + 1) % nu) * nv + (j + 1) % nv
    d = i * nv + (j + 1) % nv
    faces = np.concatenate(
        [np.stack([a, d, c], -1).reshape(-1, 3), np.stack([a, c, b], -1).reshape(-1, 3)]
    )
    return verts, faces


def shapes(seed: int = 0, detail: int = 2, offset=(0.0, 0.0, 0.0), scale: float = 1.0) -> Scene:
    """A multi-object scene: a ground grid, boxes, spheres and tori placed at random (seeded).

    ``detail`` sets the tessellation: 4,544 triangles at 1, 18,176 at 2, 49,856 at 3,
    134,144 at 4 and 409,280 at 5 (seed 0; other seeds differ slightly).
    ``offset`` and ``scale`` move the whole scene (to test precision far from the origin).
    Each object has its own colour, so colour images show which object a pixel sees.
    """
    rng = np.random.default_rng(seed)
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    g = 8 * detail
    ground_v, ground_f = _box(np.array([-6.0, -0.2, -6.0]), np.array([6.0, 0.0, 6.0]), g)
    parts.append((ground_v, ground_f, np.array([0.6, 0.6, 0.55])))
    sphere_v, sphere_f = _icosphere_arrays(detail + 1)
    torus_v, torus_f = _torus(1.0, 0.3, 24 * detail, 12 * detail)
    for _ in range(12):
        kind = rng.integers(3)
        pos = np.array([rng.uniform(-4.5, 4.5), 0.0, rng.uniform(-4.5, 4.5)])
        size = rng.uniform(0.4, 1.2)
        color = rng.uniform(0.2, 0.95, size=3)
        if kind == 0:
            half = np.array([size, size * rng.uniform(0.5, 2.0), size]) * 0.5
            v, f = _box(pos - half * [1, 0, 1], pos + half * [1, 2, 1], 2 * detail)
        elif kind == 1:
            v, f = sphere_v * size * 0.6 + pos + [0, size * 0.6, 0], sphere_f
        else:
            v, f = torus_v * size * 0.6 + pos + [0, size * 0.25, 0], torus_f
        parts.append((v, f, color))
    verts, faces, colors = [], [], []
    n = 0
    for v, f, c in parts:
        verts.append(v)
        faces.append(f + n)
        colors.append(np.broadcast_to(c, v.shape))
        n += len(v)
    v = np.concatenate(verts) * scale + np.asarray(offset, dtype=np.float64)
    return Scene.from_arrays(v, np.concatenate(faces), colors=np.concatenate(colors))


def reflective_room(spheres: int = 10, seed: int = 0, detail: int = 3) -> Scene:
    """A room with mirror spheres, for reflections (eye-based-point-rendering.txt §4.2 uses
    1, 10, 20 and 50 reflective objects): a checkered floor (4 x 4, z = 0) and three walls 2
    high, a dozen coloured boxes, and ``spheres`` icospheres (``detail`` subdivisions, smooth
    vertex normals) of radius 0.12-0.2 at seeded positions that do not overlap, with a mirror
    material (metallic 1, roughness 0.05, objects ``sphere 0`` ...). Everything else is diffuse
    (metallic 0, roughness 0.8). Every material is single-sided and every triangle wound
    counter-clockwise seen from the side its normal points to (into the room for the floor and
    walls, outward for boxes and spheres). z is up; see :func:`reflective_room_eye`."""
    if spheres < 0:
        raise ValueError(f"spheres must be >= 0, got {spheres}")
    rng = np.random.default_rng(seed)
    verts, faces, cols, norms, mats, objs = [], [], [], [], [], []
    names = ["room"]

    def add(v, f, color, normals, material, obj):
        base = sum(len(x) for x in verts)
        verts.append(np.asarray(v, dtype=np.float64))
        faces.append(np.asarray(f, dtype=np.int64) + base)
        cols.append(np.broadcast_to(np.asarray(color, dtype=np.float64), (len(v), 3)))
        norms.append(np.asarray(normals, dtype=np.float64))
        mats.append(np.full(len(f), material))
        objs.append(np.full(len(f), obj))

    # Floor: 8 x 8 checker tiles, each its own quad so colours stay flat.
    for i in range(8):
        for j in range(8):
            x0, y0 = -2 + 0.5 * i, -2 + 0.5 * j
            v = [[x0, y0, 0], [x0 + 0.5, y0, 0], [x0 + 0.5, y0 + 0.5, 0], [x0, y0 + 0.5, 0]]
            c = (0.8, 0.78, 0.7) if (i + j) % 2 == 0 else (0.25, 0.25, 0.3)
            add(v, [[0, 1, 2], [0, 2, 3]], c, [[0, 0, 1]] * 4, 0, 0)
    walls = [  # corners, inward normal, colour
        ([[-2, 2, 0], [2, 2, 0], [2, 2, 2], [-2, 2, 2]], [0, -1, 0], (0.7, 0.3, 0.25)),
        ([[-2, -2, 0], [-2, 2, 0], [-2, 2, 2], [-2, -2, 2]], [1, 0, 0], (0.3, 0.55, 0.35)),
        ([[2, 2, 0], [2, -2, 0], [2, -2, 2], [2, 2, 2]], [-1, 0, 0], (0.3, 0.4, 0.7)),
    ]
    for v, n, c in walls:  # counter-clockwise seen from inside: fronts face the room
        add(v, [[0, 1, 2], [0, 2, 3]], c, [n] * 4, 0, 0)
    occupied: list[tuple[np.ndarray, float]] = []
    for k in range(12):
        lo = np.array([rng.uniform(-1.8, 1.5), rng.uniform(-1.8, 1.5), 0.0])
        size = np.array([rng.uniform(0.15, 0.35), rng.uniform(0.15, 0.35), rng.uniform(0.2, 0.9)])
        v, f = _box(lo, lo + size, 1)
        normals = np.zeros_like(v)
        for q in range(6):  # four vertices per box face, in _box's order
            axis, side = q // 2, q % 2
            normals[4 * q : 4 * q + 4, axis] = 1 if side else -1
        names.append(f"box {k}")
        add(v, f, rng.uniform(0.2, 0.9, 3), normals, 0, len(names) - 1)
        occupied.append((lo + size / 2, float(np.linalg.norm(size[:2]) / 2)))
    unit_v, unit_f = _icosphere_arrays(detail)
    placed = 0
    tries = 0
    while placed < spheres:
        tries += 1
        if tries > 20000:
            raise ValueError(f"could not place {spheres} spheres without overlap")
        r = rng.uniform(0.12, 0.2)
        c = np.array([rng.uniform(-1.7, 1.7), rng.uniform(-1.7, 1.7), rng.uniform(0.3, 1.6)])
        if any(np.linalg.norm(c[:2] - o[:2]) < r + orad + 0.02 for o, orad in occupied):
            continue
        occupied.append((c, r))
        names.append(f"sphere {placed}")
        tint = (0.95, 0.93, 0.88) if placed % 3 else (0.95, 0.75, 0.45)
        add(unit_v * r + c, unit_f, tint, unit_v, 1, len(names) - 1)
        placed += 1
    v = np.concatenate(verts)
    return Scene.from_arrays(
        v,
        np.concatenate(faces),
        normals=np.concatenate(norms),
        colors=np.concatenate(cols),
        material_ids=np.concatenate(mats),
        materials=[
            {"name": "diffuse", "metallic": 0.0, "roughness": 0.8},
            {"name": "mirror", "metallic": 1.0, "roughness": 0.05},
        ],
        object_ids=np.concatenate(objs),
        objects=names,
    )


def reflective_room_eye(resolution: int = 512, angle: float = 0.0, distance: float = 3.2) -> Any:
    """The eye for :func:`reflective_room`: ``distance`` from the room's centre axis, 1.6 high,
    turned ``angle`` radians about z (0: looking along +y), looking at (0, 0, 0.7)."""
    eye = (distance * np.sin(angle), -distance * np.cos(angle), 1.6)
    return Camera.look_at(
        eye, (0.0, 0.0, 0.7), (0.0, 0.0, 1.0), yfov=0.9, width=resolution, height=resolution
    )


def shared_scenes_dir() -> Optional[Path]:
    """The folder of real third-party scenes: ``$SCENESAMPLE_SCENES``, else ``../shared/scenes``
    beside the current directory or beside this source checkout; None when absent."""
    env = os.environ.get("SCENESAMPLE_SCENES")
    candidates = [Path(env)] if env else []
    candidates += [
        Path.cwd() / ".." / "shared" / "scenes",
        Path(__file__).resolve().parents[3] / "shared" / "scenes",
    ]
    for c in candidates:
        if c.is_dir():
            return c.resolve()
    return None


_SCENE_SUFFIXES = (".glb", ".gltf", ".obj")


def shared_scene_files() -> dict[str, Path]:
    """Scene name -> main file (glTF/GLB preferred over OBJ) for each folder of the shared
    scenes, sorted by name; empty when the folder is absent."""
    root = shared_scenes_dir()
    if root is None:
        return {}
    out = {}
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        files = sorted(f for f in d.iterdir() if f.suffix.lower() in _SCENE_SUFFIXES)
        files.sort(key=lambda f: _SCENE_SUFFIXES.index(f.suffix.lower()))
        if files:
            out[d.name] = files[0]
    return out


def shared(name: str) -> Path:
    """The main file of the shared scene ``name`` (a folder of :func:`shared_scenes_dir`, e.g.
    ``"stanford_bunny"``): glTF/GLB before OBJ. Raises :class:`SceneFileError` naming where it
    looked when the folder or the scene is absent."""
    files = shared_scene_files()
    if name not in files:
        where = shared_scenes_dir()
        raise SceneFileError(
            f"no shared scene {name!r}: "
            + (
                f"{where} has {sorted(files)}"
                if where
                else "set SCENESAMPLE_SCENES to the folder of the shared scenes"
            )
        )
    return files[name]


def bending_tube(
    folder: Optional[os.PathLike] = None, rows: int = 200, around: int = 256, joints: int = 8
) -> Path:
    """Write a skinned, animated glTF file and return its path: a tube of radius 0.3 and
    ``joints - 1`` units high (``2 * rows * around`` triangles, NORMAL included) on a chain of
    ``joints`` joints one unit apart, each vertex weighted between the two joints nearest its
    height, and a 2-second clip ``"bend"`` that turns every joint about a horizontal axis.
    ``folder`` defaults to a new temporary directory. The same arguments write the same bytes.
    """
    out = Path(folder) if folder is not None else Path(tempfile.mkdtemp(prefix="scenesample-"))
    y = np.linspace(0.0, joints - 1.0, rows + 1)
    a = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
    yy, aa = np.meshgrid(y, a, indexing="ij")
    v = np.stack([0.3 * np.cos(aa), yy, 0.3 * np.sin(aa)], -1).reshape(-1, 3)
    n = np.stack([np.cos(aa), 0 * aa, np.sin(aa)], -1).reshape(-1, 3)
    r, c = np.meshgrid(np.arange(rows), np.arange(around), indexing="ij")
    p0, p1 = r * around + c, r * around + (c + 1) % around
    q0, q1 = p0 + around, p1 + around
    faces = np.stack([np.stack([p0, q0, p1], -1), np.stack([p1, q0, q1], -1)], 2)
    low = np.minimum(np.floor(v[:, 1]).astype(np.uint16), joints - 2)
    w = v[:, 1] - low
    js = np.stack([low, low + 1, low * 0, low * 0], -1).astype(np.uint16)
    ws = np.stack([1 - w, w, 0 * w, 0 * w], -1).astype(np.float32)
    ibm = np.tile(np.eye(4, dtype=np.float32), (joints, 1, 1))
    ibm[:, 1, 3] = -np.arange(joints)
    times = np.linspace(0.0, 2.0, 9, dtype=np.float32)
    parts = [v.astype(np.float32), faces.reshape(-1).astype(np.uint32), js, ws]
    parts += [ibm.transpose(0, 2, 1).copy(), times, n.astype(np.float32)]
    for k in range(1, joints):
        angle = 0.25 * np.sin(np.pi * times + k)
        axis = np.array([np.cos(k), 0.0, np.sin(k)])
        parts.append(np.c_[np.outer(np.sin(angle / 2), axis), np.cos(angle / 2)].astype(np.float32))
    blob, views, accessors = b"", [], []
    kinds = [("VEC3", 5126), ("SCALAR", 5125), ("VEC4", 5123), ("VEC4", 5126), ("MAT4", 5126)]
    kinds += [("SCALAR", 5126), ("VEC3", 5126)] + [("VEC4", 5126)] * (joints - 1)
    for data, (kind, component) in zip(parts, kinds):
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": data.nbytes})
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[kind]
        accessors.append(
            {"bufferView": len(views) - 1, "componentType": component,
             "count": data.size // width, "type": kind}
        )  # fmt: skip
        blob += data.tobytes()
    (out / "tube.bin").write_bytes(blob)
    nodes: list[dict[str, Any]] = [{"mesh": 0, "skin": 0}]
    for k in range(joints):
        node: dict[str, Any] = {"translation": [0.0, float(k > 0), 0.0]}
        if k + 1 < joints:
            node["children"] = [k + 2]
        nodes.append(node)
    attributes = {"POSITION": 0, "NORMAL": 6, "JOINTS_0": 2, "WEIGHTS_0": 3}
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob), "uri": "tube.bin"}],
        "bufferViews": views,
        "accessors": accessors,
        "meshes": [{"primitives": [{"attributes": attributes, "indices": 1}]}],
        "nodes": nodes,
        "skins": [{"joints": list(range(1, joints + 1)), "inverseBindMatrices": 4}],
        "animations": [
            {
                "name": "bend",
                "samplers": [
                    {"input": 5, "output": 6 + k, "interpolation": "LINEAR"}
                    for k in range(1, joints)
                ],
                "channels": [
                    {"sampler": k - 1, "target": {"node": k + 1, "path": "rotation"}}
                    for k in range(1, joints)
                ],
            }
        ],
        "scenes": [{"nodes": [0, 1]}],
        "scene": 0,
    }
    path = out / "tube.gltf"
    path.write_text(json.dumps(doc))
    return path
