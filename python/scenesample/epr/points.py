"""Eye-based point rendering (eye-based-point-rendering.txt): reflectors, EPR / iVIR point
generation (§3.1-3.4, §4.1.1) and ``splat`` (§3.5)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Optional, Union

import numpy as np

from .. import _core
from .._attributes import surface_attributes
from .._progress import Bar, Progress
from .._scene import Scene
from ..errors import InputError

Camera = _core.Camera

# Default reflectors: objects whose material is this metallic and this smooth (documented in
# ``reflectors_of``).
REFLECTOR_METALLIC = 0.9
REFLECTOR_ROUGHNESS = 0.1
# Adaptive cube-map resolution (§3.5, §4.1.1): at most half the eye's resolution, changed only
# when the needed size moves by at least this many pixels.
RESIZE_STEP = 32
MIN_CUBE_RESOLUTION = 8
# The paper's largest cube-map face (§4.2: "a maximum adaptive resolution of 512²").
MAX_CUBE_RESOLUTION = 512


def max_cube_resolution(eye: Camera) -> int:
    """Half the eye's resolution (§3.5), at most 512 and at least 8."""
    return max(MIN_CUBE_RESOLUTION, min(MAX_CUBE_RESOLUTION, max(eye.width, eye.height) // 2))


@dataclass(eq=False)
class Reflector:
    """A reflective object: its bounding sphere and the triangles it is made of.

    Attributes
    ----------
    center : (3,) float64
    radius : float
    triangles : (k,) int64
        Triangle ids of the object (left out of its own cube map).
    name : str
    """

    center: np.ndarray
    radius: float
    triangles: np.ndarray
    name: str = ""

    @classmethod
    def of_triangles(cls, scene: Scene, triangles: Any, name: str = "") -> Reflector:
        """The reflector made of ``triangles`` (ids into ``scene.faces``): the sphere around
        their vertices' bounding-box centre that holds them all."""
        ids = np.asarray(triangles, dtype=np.int64).reshape(-1)
        if ids.size == 0:
            raise InputError(f"reflector {name!r} has no triangles")
        if ids.min() < 0 or ids.max() >= scene.triangle_count:
            raise InputError(
                f"reflector {name!r} names triangles outside 0..{scene.triangle_count - 1}"
            )
        pts = scene.vertices[scene.faces[ids].reshape(-1)].astype(np.float64)
        center = (pts.min(axis=0) + pts.max(axis=0)) / 2
        radius = float(np.linalg.norm(pts - center, axis=1).max())
        return cls(center, radius, ids, name)

    @classmethod
    def sphere(cls, scene: Scene, center: Any, radius: float, name: str = "") -> Reflector:
        """A reflector given by a bounding sphere: its triangles are those whose three vertices
        lie inside the sphere."""
        c = np.asarray(center, dtype=np.float64).reshape(3)
        if not (np.isfinite(c).all() and np.isfinite(radius) and radius > 0):
            raise InputError(
                f"a reflector sphere needs a finite centre and radius > 0, got {c}, {radius}"
            )
        d = np.linalg.norm(scene.vertices.astype(np.float64) - c, axis=1) <= radius * (1 + 1e-6)
        inside = np.flatnonzero(d[scene.faces].all(axis=1))
        return cls(c, float(radius), inside, name)


def reflectors_of(scene: Scene, spec: Any = None) -> list[Reflector]:
    """The scene's reflectors.

    ``spec=None``: every object (glTF mesh node) with triangles whose material has metallic >=
    0.9 and roughness <= 0.1, one reflector per object made of those triangles. Otherwise a list
    whose items are object names (``scene.objects``), :class:`Reflector` objects, or
    ``(center, radius)`` bounding spheres."""
    if spec is None:
        shiny = [
            i
            for i, m in enumerate(scene.materials)
            if m.get("metallic", 0) >= REFLECTOR_METALLIC
            and m.get("roughness", 1) <= REFLECTOR_ROUGHNESS
        ]
        faces = np.isin(scene.material_ids, shiny)
        out = []
        for obj in np.unique(scene.object_ids[faces]):
            ids = np.flatnonzero(faces & (scene.object_ids == obj))
            out.append(Reflector.of_triangles(scene, ids, scene.objects[obj]))
        if not out:
            raise InputError(
                "the scene has no reflective object (material metallic >= 0.9 and roughness "
                "<= 0.1); pass reflectors= as object names, Reflector objects or "
                "(center, radius) spheres"
            )
        return out
    out = []
    for k, item in enumerate(spec):
        if isinstance(item, Reflector):
            out.append(item)
        elif isinstance(item, str):
            if item not in scene.objects:
                raise InputError(f"reflectors[{k}]: no object named {item!r} in the scene")
            ids = np.flatnonzero(scene.object_ids == scene.objects.index(item))
            out.append(Reflector.of_triangles(scene, ids, item))
        else:
            try:
                center, radius = item
            except (TypeError, ValueError):
                raise InputError(
                    f"reflectors[{k}] must be an object name, a Reflector or (center, radius), "
                    f"got {item!r}"
                ) from None
            out.append(Reflector.sphere(scene, center, float(radius), f"sphere {k}"))
    if not out:
        raise InputError("reflectors is empty")
    return out


def cube_resolution(eye: Camera, reflector: Reflector, previous: Optional[int] = None) -> int:
    """The cube-map resolution a reflector needs (§4.1.1): the diameter in eye pixels of its
    bounding sphere's projection, at most half the eye's resolution (and 512) and at least 8;
    with ``previous`` (last frame's), kept unless the need moved by >= 32 pixels (§3.5)."""
    limit = max_cube_resolution(eye)
    d = float(np.linalg.norm(reflector.center - np.asarray(eye.eye)))
    if eye.yfov is not None:
        pixel = 2 * math.tan(eye.yfov / 2) / eye.height
        if d <= reflector.radius:
            size = float(limit)
        else:
            size = 2 * math.tan(math.asin(reflector.radius / d)) / pixel
    else:
        size = 2 * reflector.radius / (2 * eye.ymag / eye.height)
    need = int(min(limit, max(MIN_CUBE_RESOLUTION, math.ceil(size))))
    if previous is not None and abs(need - previous) < RESIZE_STEP:
        return int(previous)
    return need


@dataclass(eq=False, repr=False)
class Points:
    """Points sampling a scene, each a world-space square in its triangle's plane.

    Attributes
    ----------
    center : (P, 3) float32
    length : (P,) float32
        Side of the point's square (Eq. 4), world units.
    triangle : (P,) int32
    normal : (P, 3) float32
        Unit geometric normal of the point's triangle.
    shading_normal : (P, 3) float32
        Unit shading normal at the point's centre (the vertices' normals interpolated, see
        :func:`scenesample.surface_attributes`).
    color : (P, 3) float32
        Linear base colour over the point's square (the material's texture filtered over its
        side).
    material : (P,) int32
        Material id (-1: none).
    views : (P, ceil(V / 64)) uint64
        Visibility bit strings: bit v % 64 of word v // 64 is set when view v may see the point
        (conservative frusta enlarged by 20%, §3.1).
    cameras : list of Camera
        The V off-screen views the bits refer to (six cube faces per reflector for EPR).
    reflectors : list of Reflector
    timings : dict of str to float
    stats : dict of str to float
        ``points``, ``triangles_sampled``, ``triangles_culled`` (stochastically, §3.2),
        ``triangles_outside_views``.
    """

    center: np.ndarray
    length: np.ndarray
    triangle: np.ndarray
    normal: np.ndarray
    shading_normal: np.ndarray
    color: np.ndarray
    material: np.ndarray
    views: np.ndarray
    cameras: list = field(default_factory=list)
    reflectors: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    _scene: Optional[Scene] = None

    @classmethod
    def from_arrays(
        cls,
        scene: Scene,
        center: Any,
        length: Any,
        triangle: Any,
        *,
        views: Any = None,
        cameras: Optional[Sequence[Camera]] = None,
    ) -> Points:
        """Points built by hand: (P, 3) centres, (P,) lengths, (P,) triangle ids of ``scene``;
        ``views`` (P, W) uint64 bit strings (default: every point in every view, which then
        needs ``cameras``)."""
        c = np.ascontiguousarray(center, dtype=np.float32).reshape(-1, 3)
        n = len(c)
        tri = np.ascontiguousarray(triangle, dtype=np.int32).reshape(-1)
        length = np.ascontiguousarray(length, dtype=np.float32).reshape(-1)
        cams = list(cameras) if cameras is not None else []
        if views is None:
            if not cams:
                raise InputError("pass views= bit strings or cameras= (every point in every view)")
            words = max(1, -(-len(cams) // 64))
            bits = np.zeros((n, words), dtype=np.uint64)
            for v in range(len(cams)):
                bits[:, v // 64] |= np.uint64(1) << np.uint64(v % 64)
        else:
            bits = np.ascontiguousarray(views, dtype=np.uint64)
            if bits.ndim != 2 or len(bits) != n:
                raise InputError(f"views must have shape ({n}, words), got {bits.shape}")
        ok = (tri >= 0) & (tri < scene.triangle_count)
        if not ok.all():
            bad = int(np.flatnonzero(~ok)[0])
            raise InputError(
                f"triangle[{bad}] is {int(tri[bad])}: the scene has {scene.triangle_count} "
                "triangles"
            )
        if len(length) != n:
            raise InputError(f"{n} centres need {n} lengths, got {len(length)}")
        a = surface_attributes(scene, triangle=tri, points=c, footprint=length)
        mat = np.asarray(scene.material_ids, dtype=np.int32)[tri]
        return cls(
            c, length, tri, a.normal, a.shading_normal, a.color, mat, bits, cams, [], {}, {}, scene
        )

    @classmethod
    def _from_core(
        cls, d: dict[str, Any], reflectors: list, scene: Scene, **stats: float
    ) -> Points:
        """Points from the native module's dict (``epr_points`` or ``epr_shadow_points``),
        with ``stats`` added to its own."""
        return cls(
            d["center"],
            d["length"],
            d["triangle"],
            d["normal"],
            d["shading_normal"],
            d["color"],
            d["material"],
            d["views"],
            list(d["cameras"]),
            reflectors,
            dict(d["timings"]),
            {**dict(d["stats"]), **stats},
            scene,
        )

    def __len__(self) -> int:
        return len(self.center)

    def __repr__(self) -> str:
        return f"Points({len(self):,} points over {len(self.cameras)} views)"

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}


@dataclass(eq=False, repr=False)
class SplatBuffers:
    """Off-screen index buffers filled by :func:`splat`.

    Attributes
    ----------
    packed : (V, H, W) uint64
        ``depth bits << 32 | point index`` of the nearest point, ``2**64 - 1`` where empty.
    depth : (V, H, W) float32
        Camera-space depth of that point's centre, +inf where empty.
    index : (V, H, W) int32
        Its index into the points, -1 where empty.
    cameras : list of Camera
    timings : dict of str to float
    stats : dict of str to int
        ``cube_maps``, ``splat_passes``, ``shadow_views``, ``rays_cast``: what this call ran.
    """

    packed: np.ndarray
    depth: np.ndarray
    index: np.ndarray
    cameras: list
    timings: dict
    stats: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        v, h, w = self.index.shape
        return f"SplatBuffers({v} views of {w}x{h})"

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def cube_maps(
    scene: Scene,
    eye: Camera,
    reflectors: Any,
    resolution: Union[None, int, Sequence[int]],
    largest: bool = False,
) -> tuple[list[Reflector], list[int]]:
    """The reflectors (see :func:`reflectors_of`) and their cube-map resolutions: the given
    one(s), or by default the adaptive size of §4.1.1 (``largest``: half the eye's, at most
    512, for every reflector). Checks the scene, the eye and the resolutions."""
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if not isinstance(eye, Camera):
        raise InputError(f"eye must be a scenesample.Camera, got {type(eye).__name__}")
    refl = reflectors_of(scene, reflectors)
    if resolution is None and largest:
        res = [max_cube_resolution(eye)] * len(refl)
    elif resolution is None:
        res = [cube_resolution(eye, r) for r in refl]
    elif isinstance(resolution, (int, np.integer)):
        res = [int(resolution)] * len(refl)
    else:
        res = [int(x) for x in resolution]
    if len(res) != len(refl) or min(res) < 1:
        raise InputError(
            f"resolution must be a positive int or one per reflector ({len(refl)}), "
            f"got {resolution!r}"
        )
    return refl, res


def reflector_arrays(refl: list[Reflector]) -> tuple[np.ndarray, list[float], list[np.ndarray]]:
    """Centres (R, 3), radii and triangle ids of the reflectors, as the native module takes
    them."""
    return (
        np.array([r.center for r in refl], dtype=np.float64).reshape(-1, 3),
        [float(r.radius) for r in refl],
        [np.asarray(r.triangles, dtype=np.int64) for r in refl],
    )


def epr_points(
    scene: Scene,
    eye: Camera,
    *,
    reflectors: Any = None,
    rho_scale: float = 0.5,
    seed: int = 0,
    resolution: Union[None, int, Sequence[int]] = None,
    density: str = "eye",
    progress: Progress = None,
) -> Points:
    """Points for the reflectors' cube maps (see :func:`scenesample.discretize`)."""
    refl, res = cube_maps(scene, eye, reflectors, resolution)
    label = "EPR points" if density == "eye" else "iVIR points"
    with Bar(progress, label, "triangles") as bar:
        d = _core.epr_points(
            scene._core,
            eye,
            *reflector_arrays(refl),
            res,
            density,
            float(rho_scale),
            int(seed),
            bar.callback,
        )
    return Points._from_core(d, refl, scene)


def splat(
    points: Points,
    views: Optional[Sequence[Camera]] = None,
    *,
    resolution: Optional[int] = None,
    clip_to_triangle: bool = True,
    scene: Optional[Scene] = None,
) -> SplatBuffers:
    """Scatter points into many off-screen views at once (eye-based-point-rendering.txt §3.5).

    Each point's world-space square (side ``points.length``, in its triangle's plane, along the
    triangle's longest edge) is projected into every view whose visibility bit it has set; the
    pixels of the projection's 2D bounding box receive the point through a 64-bit atomic on
    (depth bits << 32 | point index), so each pixel keeps the nearest point whatever order the
    GPU runs in (ties: the lower index). A point is skipped in a view when a corner of its
    square lies behind the camera or its centre is nearer than the view's ``znear`` (cube maps
    from ``discretize(method="epr")`` put it on the reflector's bounding sphere). Before the GPU
    pass the host drops (point, view) pairs whose square lies outside the view's frustum, which
    changes no pixel.

    Parameters
    ----------
    points : Points
        From ``discretize(scene, method="epr", ...)`` or :meth:`Points.from_arrays`.
    views : sequence of Camera, optional
        The V views the points' bit strings describe (default: ``points.cameras``); any
        cameras (``Camera.cube`` gives cube faces), all of one resolution.
    resolution : int, optional
        Render every view at ``resolution`` x ``resolution`` instead of its own size.
    clip_to_triangle : bool
        Keep only pixels whose square overlaps the point's projected triangle (default), which
        trims splats hanging over their triangle's edges without opening holes.
    scene : Scene, optional
        The scene the points sample; needed only for points built without one.

    Returns
    -------
    SplatBuffers
        ``packed`` (V, H, W) uint64, ``depth`` (V, H, W) float32, ``index`` (V, H, W) int32,
        ``cameras``, ``timings`` (upload, splat, readback, total).

    Raises
    ------
    InputError
        Views of different sizes, bit strings for another number of views, bad point arrays.
    GpuUnavailableError
        No adapter with 64-bit atomics (SHADER_INT64_ATOMIC_MIN_MAX).
    GpuLimitError
        Buffers beyond the device's storage limits.
    """
    if not isinstance(points, Points):
        raise InputError(f"points must be scenesample.Points, got {type(points).__name__}")
    sc = scene if scene is not None else points._scene
    if not isinstance(sc, Scene):
        raise InputError("the points carry no scene: pass scene=")
    cams = list(points.cameras if views is None else views)
    for i, c in enumerate(cams):
        if not isinstance(c, Camera):
            raise InputError(f"views[{i}] must be a scenesample.Camera, got {type(c).__name__}")
    if not cams:
        raise InputError("splat needs at least one view")
    if resolution is not None:
        if int(resolution) < 1:
            raise InputError(f"resolution must be >= 1, got {resolution}")
        cams = [c.with_resolution(int(resolution), int(resolution)) for c in cams]
    d = _core.splat(
        sc._core,
        points.center,
        points.length,
        points.triangle,
        np.ascontiguousarray(points.views, dtype=np.uint64),
        cams,
        bool(clip_to_triangle),
    )
    return SplatBuffers(
        d["packed"], d["depth"], d["index"], cams, dict(d["timings"]), dict(d["ops"])
    )
