"""Procedural analogues of the test models of non-redundant-rendering.txt (§6.1.3: Grass 56K,
Urban 50K, Bird Nest 67K and Tree 113K triangles) and a herd of turtles (one object copied many
times), each seeded and deterministic, with three reference cameras like the paper's (the
corners of a viewpoint translation triangle in front of the scene, all looking at its centre).

The geometry is built with numpy from a few primitives (strips, tubes, boxes, ellipsoids),
all vectorised over the copies of a primitive.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from ._core import Camera
from ._scene import Scene

__all__ = ["grass", "urban", "bird_nest", "tree", "turtles", "reference_cameras", "PAPER_SCENES"]


def _merge(
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]], labels: Optional[list[str]] = None
) -> Scene:
    """(vertices (k, n, 3), faces (f, 3) shared by the k copies, colour (k, 3)) parts -> Scene.
    With ``labels`` (one per part), every copy is its own object, named "label i" ("label"
    for a part with one copy); otherwise the scene is one object."""
    verts, faces, colors, objs, names = [], [], [], [], []
    base = 0
    for p, (v, f, c) in enumerate(parts):
        k, n, _ = v.shape
        offsets = base + n * np.arange(k)[:, None, None]
        faces.append((f[None] + offsets).reshape(-1, 3))
        verts.append(v.reshape(-1, 3))
        colors.append(np.repeat(c, n, axis=0))
        base += k * n
        if labels is not None:
            objs.append(len(names) + np.repeat(np.arange(k), len(f)))
            names += [labels[p] if k == 1 else f"{labels[p]} {i}" for i in range(k)]
    extra: dict = {}
    if labels is not None:
        extra = {"object_ids": np.concatenate(objs), "objects": names}
    return Scene.from_arrays(
        np.concatenate(verts), np.concatenate(faces), colors=np.concatenate(colors), **extra
    )


def _grid_faces(rows: int, cols: int, wrap: bool) -> np.ndarray:
    """Faces of a rows x cols vertex grid (row-major); columns wrap around for tubes."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols if wrap else cols - 1), indexing="ij")
    a = r * cols + c
    b = r * cols + (c + 1) % cols
    d = (r + 1) * cols + c
    e = (r + 1) * cols + (c + 1) % cols
    quads = np.stack([a, b, e, d], -1).reshape(-1, 4)
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])


def _tubes(paths: np.ndarray, radius: np.ndarray, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """Tubes along k paths (k, m, 3) with radii (k,) or (k, m): (k, m*sides, 3) and faces."""
    k, m, _ = paths.shape
    t = np.gradient(paths, axis=1)
    t /= np.linalg.norm(t, axis=2, keepdims=True)
    ref = np.where(np.abs(t[..., 2:3]) < 0.9, [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    u = np.cross(t, ref)
    u /= np.linalg.norm(u, axis=2, keepdims=True)
    w = np.cross(t, u)
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    r = np.broadcast_to(np.asarray(radius, dtype=np.float64).reshape(k, -1), (k, m))
    ring = (
        np.cos(ang)[None, None, :, None] * u[:, :, None]
        + np.sin(ang)[None, None, :, None] * w[:, :, None]
    )
    v = paths[:, :, None] + r[:, :, None, None] * ring
    return v.reshape(k, m * sides, 3), _grid_faces(m, sides, wrap=True)


def _ellipsoids(centres: np.ndarray, radii: np.ndarray, n: int = 8) -> tuple[np.ndarray, ...]:
    """k ellipsoids (UV spheres, n rings): (k, verts, 3) and faces."""
    th = np.linspace(0.02, np.pi - 0.02, n)
    ph = np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    tt, pp = np.meshgrid(th, ph, indexing="ij")
    unit = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1)
    v = centres[:, None] + radii[:, None] * unit.reshape(1, -1, 3)
    return v, _grid_faces(n, 2 * n, wrap=True)


def _ground(size: float, z: float = 0.0, color=(0.35, 0.3, 0.2)) -> tuple[np.ndarray, ...]:
    h = size / 2
    v = np.array([[[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]]])
    return v, np.array([[0, 1, 2], [0, 2, 3]]), np.array([color])


def grass(seed: int = 0, blades: int = 4000) -> Scene:
    """A patch of thin curved grass blades (two-sided strips, 7 segments each) on a ground
    square: 56,002 triangles with the default 4000 blades. z is up."""
    rng = np.random.default_rng(seed)
    seg = 7
    base = rng.uniform(-1, 1, size=(blades, 2))
    height = rng.uniform(0.25, 0.6, blades)
    facing = rng.uniform(0, 2 * np.pi, blades)
    lean = rng.uniform(0.1, 0.5, blades)
    width = rng.uniform(0.012, 0.025, blades)
    s = np.linspace(0, 1, seg + 1)
    d = np.stack([np.cos(facing), np.sin(facing)], -1)
    side = np.stack([-d[:, 1], d[:, 0]], -1)
    centre = np.zeros((blades, seg + 1, 3))
    centre[..., :2] = (
        base[:, None] + (lean * height)[:, None, None] * (s**2)[None, :, None] * d[:, None]
    )
    centre[..., 2] = height[:, None] * s[None]
    half = (width[:, None] * (1 - s[None] * 0.9))[..., None]
    off = np.zeros((blades, 1, 3))
    off[..., 0, :2] = side
    v = np.stack([centre - half * off, centre + half * off], axis=2).reshape(blades, -1, 3)
    f = _grid_faces(seg + 1, 2, wrap=False)
    green = np.stack(
        [
            rng.uniform(0.1, 0.3, blades),
            rng.uniform(0.4, 0.8, blades),
            rng.uniform(0.05, 0.2, blades),
        ],
        -1,
    )
    return _merge([(v, f, green), _ground(2.4)])


def urban(seed: int = 0, blocks: int = 18) -> Scene:
    """Buildings of random heights on a blocks x blocks street grid, each a box closed but for
    its floor, its faces split into 4 x 4 grids: 51,842 triangles by default. z is up."""
    rng = np.random.default_rng(seed)
    n = 4
    unit_v, unit_f = _unit_box(n)
    k = blocks * blocks
    ij = np.stack(np.meshgrid(np.arange(blocks), np.arange(blocks), indexing="ij"), -1).reshape(
        -1, 2
    )
    pitch = 2.0 / blocks
    foot = rng.uniform(0.45, 0.8, size=(k, 2)) * pitch
    height = rng.lognormal(np.log(0.15), 0.6, k).clip(0.04, 0.9)
    centre = (ij + 0.5) * pitch - 1.0 + rng.uniform(-0.08, 0.08, size=(k, 2)) * pitch
    lo = np.concatenate([centre - foot / 2, np.zeros((k, 1))], 1)
    hi = np.concatenate([centre + foot / 2, height[:, None]], 1)
    v = lo[:, None] + unit_v[None] * (hi - lo)[:, None]
    grey = rng.uniform(0.4, 0.8, k)[:, None] * np.array([[1.0, 0.97, 0.92]])
    return _merge([(v, unit_f, grey), _ground(2.2, color=(0.25, 0.25, 0.25))])


def _unit_box(n: int) -> tuple[np.ndarray, np.ndarray]:
    s = np.linspace(0.0, 1.0, n + 1)
    uu, vv = np.meshgrid(s, s, indexing="ij")
    verts, faces = [], []
    for axis in range(3):
        for side in (0, 1):
            if axis == 2 and side == 0:
                continue  # no floor: buildings stand on the ground
            a, b = (axis + 1) % 3, (axis + 2) % 3
            p = np.zeros(((n + 1) ** 2, 3))
            p[:, axis] = side
            p[:, a] = uu.ravel()
            p[:, b] = vv.ravel()
            f = _grid_faces(n + 1, n + 1, wrap=False) + sum(len(x) for x in verts)
            faces.append(f if side == 1 else f[:, ::-1])
            verts.append(p)
    return np.concatenate(verts), np.concatenate(faces)


def bird_nest(seed: int = 0, twigs: int = 700) -> Scene:
    """A bowl of interwoven twigs (tubes of 6 sides x 8 rings wandering over a bowl's surface
    at random inclinations): 67,200 triangles with the default 700 twigs. z is up."""
    rng = np.random.default_rng(seed)
    m, sides = 9, 6
    start = rng.uniform(0, 2 * np.pi, twigs)
    sweep = rng.uniform(0.8, 2.0, twigs) * rng.choice([-1, 1], twigs)
    tilt = rng.uniform(-0.6, 0.6, twigs)
    layer = rng.uniform(0.0, 1.0, twigs)
    s = np.linspace(0, 1, m)
    phi = start[:, None] + sweep[:, None] * s[None]
    # Height on the bowl wanders with the twig's inclination, so twigs cross over and under.
    z = (layer[:, None] + tilt[:, None] * (s[None] - 0.5)).clip(0, 1)
    radius = 0.45 + 0.55 * np.sqrt(z)
    paths = np.stack([radius * np.cos(phi), radius * np.sin(phi), 0.8 * z], -1)
    paths += rng.normal(0, 0.02, size=paths.shape)
    v, f = _tubes(paths, rng.uniform(0.012, 0.025, twigs), sides)
    brown = rng.uniform(0.5, 0.9, twigs)[:, None] * np.array([[0.45, 0.3, 0.15]])
    return _merge([(v, f, brown)])


def tree(seed: int = 0, leaves: int = 50000) -> Scene:
    """A branching tree: a trunk and three levels of branches (tubes, 8 sides) carrying
    ``leaves`` two-triangle leaves: about 113K triangles by default. z is up."""
    rng = np.random.default_rng(seed)
    sides, m = 8, 6
    # Branch segments: (start, direction, length, radius) per level.
    starts = [np.array([[0.0, 0.0, 0.0]])]
    dirs = [np.array([[0.0, 0.0, 1.0]])]
    lengths = [np.array([1.0])]
    radii = [np.array([0.06])]
    for count in (7, 5, 4):
        ps, ds, ls, rs = starts[-1], dirs[-1], lengths[-1], radii[-1]
        k = len(ps) * count
        parent = np.repeat(np.arange(len(ps)), count)
        at = rng.uniform(0.35, 1.0, k)
        s = ps[parent] + ds[parent] * (ls[parent] * at)[:, None]
        rand = rng.normal(size=(k, 3))
        d = ds[parent] * 0.6 + rand / np.linalg.norm(rand, axis=1, keepdims=True)
        d[:, 2] = np.abs(d[:, 2]) * 0.6 + 0.1
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        starts.append(s)
        dirs.append(d)
        lengths.append(ls[parent] * rng.uniform(0.35, 0.55, k))
        radii.append(rs[parent] * 0.45)
    s_all = np.concatenate(starts)
    d_all = np.concatenate(dirs)
    l_all = np.concatenate(lengths)
    r_all = np.concatenate(radii)
    t = np.linspace(0, 1, m)
    paths = s_all[:, None] + d_all[:, None] * (l_all[:, None] * t[None])[..., None]
    taper = r_all[:, None] * (1 - 0.5 * t[None])
    bv, bf = _tubes(paths, taper, sides)
    bark = np.tile([[0.35, 0.25, 0.15]], (len(s_all), 1))
    # Leaves on the last two levels' branches.
    tips = np.concatenate(starts[-2:])
    tip_d = np.concatenate(dirs[-2:])
    tip_l = np.concatenate(lengths[-2:])
    host = rng.integers(0, len(tips), leaves)
    centre = tips[host] + tip_d[host] * (tip_l[host] * rng.uniform(0.1, 1.1, leaves))[:, None]
    centre += rng.normal(0, 0.05, size=(leaves, 3))
    a = rng.normal(size=(leaves, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(a, rng.normal(size=(leaves, 3)))
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    size = rng.uniform(0.02, 0.04, leaves)[:, None]
    lv = np.stack(
        [centre - a * size, centre + b * size * 0.5, centre + a * size, centre - b * size * 0.5],
        1,
    )
    lf = np.array([[0, 1, 2], [0, 2, 3]])
    leaf = np.stack(
        [
            rng.uniform(0.1, 0.3, leaves),
            rng.uniform(0.35, 0.7, leaves),
            rng.uniform(0.05, 0.2, leaves),
        ],
        -1,
    )
    return _merge([(bv, bf, bark), (lv, lf, leaf), _ground(1.8)])


def turtles(seed: int = 0, count: int = 16) -> Scene:
    """``count`` copies of one turtle (a shell, a head and four legs: closed ellipsoids) on a
    grid, each turned and shifted at random, on a ground square: several copies of one object.
    Each turtle is its own object ("turtle 0", ...), as is the "ground". z is up."""
    rng = np.random.default_rng(seed)
    parts_c = np.array(
        [
            [0, 0, 0.12],
            [0.3, 0, 0.1],
            [0.15, 0.15, 0.04],
            [0.15, -0.15, 0.04],
            [-0.15, 0.15, 0.04],
            [-0.15, -0.15, 0.04],
        ]
    )
    parts_r = np.array(
        [
            [0.28, 0.22, 0.12],
            [0.08, 0.06, 0.06],
            [0.07, 0.05, 0.04],
            [0.07, 0.05, 0.04],
            [0.07, 0.05, 0.04],
            [0.07, 0.05, 0.04],
        ]
    )
    v, f = _ellipsoids(parts_c, parts_r, n=16)
    one_v = v.reshape(-1, 3)
    per = v.shape[1]
    one_f = np.concatenate([f + i * per for i in range(len(parts_c))])
    side = int(np.ceil(np.sqrt(count)))
    ij = np.stack(np.divmod(np.arange(count), side), -1).astype(float)
    offset = (ij - (side - 1) / 2) * 0.8 + rng.uniform(-0.15, 0.15, size=(count, 2))
    ang = rng.uniform(0, 2 * np.pi, count)
    rot = np.zeros((count, 3, 3))
    rot[:, 0, 0] = rot[:, 1, 1] = np.cos(ang)
    rot[:, 0, 1], rot[:, 1, 0] = -np.sin(ang), np.sin(ang)
    rot[:, 2, 2] = 1
    verts = np.einsum("kij,nj->kni", rot, one_v)
    verts[..., :2] += offset[:, None]
    green = np.tile([[0.3, 0.5, 0.25]], (count, 1))
    return _merge([(verts, one_f, green), _ground(0.8 * side + 0.6)], ["turtle", "ground"])


def reference_cameras(
    scene: Scene,
    resolution: int = 512,
    spread: float = 0.25,
    yfov: float = 0.9,
    up: str = "z",
) -> list[Any]:
    """Three cameras at the corners of a viewpoint translation triangle, as in the paper: the
    triangle's centre 0.8 scene diagonals from the scene's centre, in front of it and 35 degrees
    above it (``up`` is ``"z"`` for these procedural scenes, ``"y"`` for glTF ones), its side
    ``spread`` diagonals, all looking at the centre."""
    if up not in ("y", "z"):
        raise ValueError(f"up must be 'y' or 'z', got {up!r}")
    lo, hi = np.asarray(scene.bounds, dtype=np.float64)
    c = (lo + hi) / 2
    diag = float(np.linalg.norm(hi - lo))
    elev = np.radians(35)
    if up == "z":
        upv, view = np.array([0.0, 0.0, 1.0]), np.array([0.0, -np.cos(elev), np.sin(elev)])
    else:
        upv, view = np.array([0.0, 1.0, 0.0]), np.array([0.0, np.sin(elev), np.cos(elev)])
    eye = c + view * 0.8 * diag
    right = np.cross(view, upv)
    right /= np.linalg.norm(right)
    up = np.cross(right, view)
    r = spread * diag / np.sqrt(3)
    corners = [eye + r * (np.cos(a) * right + np.sin(a) * up) for a in np.radians([90, 210, 330])]
    return [
        Camera.look_at(e, c, tuple(upv), yfov=yfov, width=resolution, height=resolution)
        for e in corners
    ]


PAPER_SCENES = {"grass": grass, "urban": urban, "bird_nest": bird_nest, "tree": tree}
