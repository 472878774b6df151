"""Soft shadows from a discretized scene (non-redundant-rendering.txt §5, Algorithm 5)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, Optional

import numpy as np

from .. import _core
from .._scene import Scene
from ..errors import InputError

__all__ = ["AreaLight", "ShadowResult", "soft_shadows", "DISCRETIZATIONS"]

DISCRETIZATIONS = ("nonredundant", "conventional", "peeling", "geometry", "raytraced")


@dataclass(frozen=True)
class AreaLight:
    """A rectangular area light: corners ``center +- u/2 +- v/2`` (u and v are its full edge
    vectors, world units), emitting toward the scene."""

    center: tuple[float, float, float]
    u: tuple[float, float, float]
    v: tuple[float, float, float]

    def __post_init__(self) -> None:
        for name in ("center", "u", "v"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != (3,) or not np.isfinite(a).all():
                raise InputError(f"AreaLight.{name} must be 3 finite numbers, got {a!r}")
            object.__setattr__(self, name, tuple(float(x) for x in a))
        if np.linalg.norm(np.cross(self.u, self.v)) <= 0:
            raise InputError("AreaLight u and v must be non-zero and not parallel")

    @property
    def diagonal(self) -> float:
        """Length of the rectangle's diagonal."""
        return float(np.linalg.norm(np.add(self.u, self.v)))

    @classmethod
    def above(
        cls, scene: Scene, size: float = 1.0, height: float = 1.0, up: str = "z"
    ) -> AreaLight:
        """A square light centred above ``scene``, its diagonal ``size`` times the scene's
        bounding-box diagonal (the paper's light size), ``height`` diagonals above its centre
        along ``up`` ("x", "y" or "z")."""
        lo, hi = scene.bounds.astype(np.float64)
        diag = float(np.linalg.norm(hi - lo))
        axis = {"x": 0, "y": 1, "z": 2}.get(up)
        if axis is None:
            raise InputError(f"up must be 'x', 'y' or 'z', got {up!r}")
        centre = (lo + hi) / 2
        centre[axis] = hi[axis] + height * diag
        e = [np.eye(3)[k] for k in range(3) if k != axis]
        side = size * diag / np.sqrt(2.0)
        return cls(tuple(centre), tuple(e[0] * side), tuple(e[1] * side))

    @classmethod
    def from_scene(cls, scene: Scene) -> AreaLight:
        """The light of the scene's emissive rectangle: the faces whose material has a non-zero
        emissive factor must form one planar quad (two triangles); raises ``InputError``
        otherwise."""
        emissive = [i for i, m in enumerate(scene.materials) if max(m.get("emissive", (0,))) > 0]
        faces = np.flatnonzero(np.isin(scene.material_ids, emissive))
        if len(faces) != 2:
            raise InputError(
                f"the scene has {len(faces)} emissive faces; an area light needs exactly one "
                "emissive quad (two triangles)"
            )
        pts = np.unique(
            scene.vertices[scene.faces[faces]].reshape(-1, 3).astype(np.float64), axis=0
        )
        if len(pts) != 4:
            raise InputError("the emissive faces do not form a quad with four corners")
        centre = pts.mean(axis=0)
        # The corner farthest from pts[0] is its opposite; the other two give the edges.
        far = int(np.argmax(np.linalg.norm(pts - pts[0], axis=1)))
        others = [k for k in range(1, 4) if k != far]
        u, v = pts[others[0]] - pts[0], pts[others[1]] - pts[0]
        if abs(np.dot(u, v)) > 1e-3 * np.linalg.norm(u) * np.linalg.norm(v):
            raise InputError("the emissive quad is not a rectangle")
        return cls(tuple(centre), tuple(u), tuple(v))


@dataclass(eq=False, repr=False)
class ShadowResult:
    """Soft shadows seen from one camera.

    Attributes
    ----------
    visibility : (H, W) float32
        Fraction of light samples visible from each pixel's surface point, in [0, 1]; 1 where the
        pixel sees no surface.
    visible : (H, W, S) bool
        Per light sample (samples row by row along the light's v, then u fastest).
    mask : (H, W) bool
        Pixels that see a surface.
    discretization : str
    occluder_triangles : int
        Triangles each shadow map drew (the reconstruction's, or the scene's for ``geometry``;
        0 for ``raytraced``).
    stats : dict of str to int
        ``cube_maps``, ``splat_passes``, ``shadow_views``, ``rays_cast``: what this call ran
        (its own counts, whatever else runs at the same time).
    timings : dict of str to float
        Seconds: ``eye`` (the output image's surface points), ``discretize`` (step 1),
        ``reconstruct`` (step 2), ``shadow`` (steps 4-9, or the ray casts), ``total``.
    """

    visibility: np.ndarray
    visible: np.ndarray
    mask: np.ndarray
    discretization: str
    occluder_triangles: int
    timings: dict[str, float] = field(default_factory=dict)
    stats: dict[str, int] = field(default_factory=dict)

    @property
    def samples(self) -> int:
        """The number of light samples each pixel's visibility averages."""
        return int(self.visible.shape[-1])

    def __repr__(self) -> str:
        h, w = self.visibility.shape
        return f"ShadowResult({self.discretization}, {w}x{h}, {self.samples} light samples)"

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def soft_shadows(
    scene: Scene,
    camera: Any,
    light: AreaLight,
    *,
    samples: tuple[int, int] = (16, 16),
    discretization: str = "nonredundant",
    resolution: int = 1024,
    views: str = "corners",
    reconstruction: str = "hybrid",
    shadow_resolution: Optional[int] = None,
    layers: int = 4,
) -> ShadowResult:
    """Soft shadows of a rectangular area light (non-redundant-rendering.txt Algorithm 5).

    The output image's surface points are those of a conventional depth image from ``camera``.
    Each is tested against ``samples[0] x samples[1]`` light samples at the centres of a grid
    over the light. A sample behind the point's surface (as seen from the camera) is never
    visible.

    Parameters
    ----------
    scene : Scene
    camera : Camera
        The output view.
    light : AreaLight
    samples : (int, int)
        Light samples along u and v.
    discretization : {"nonredundant", "conventional", "peeling", "geometry", "raytraced"}
        How occluders are represented. The first three discretize the scene from the light
        (step 1: depth images of ``resolution``^2 from the light's four corners, or
        ``layers`` peeling layers from its centre; each image's camera faces the scene along
        the light's normal and holds the scene's bounding box), reconstruct them (step 2,
        ``reconstruction``), and shadow-map the meshes from every light sample on the GPU
        (steps 4-9). ``"geometry"``: shadow maps of the original triangles (the paper's
        reference). ``"raytraced"``: exact visibility, one BVH ray per point and sample.
    resolution : int
        Resolution of the light's depth images.
    views : {"corners", "center"}
        Where the non-redundant and conventional images are rendered from.
    reconstruction : {"hybrid", "mesh", "points"}
        See :func:`scenesample.reconstruct`.
    shadow_resolution : int, optional
        Each light sample's shadow map (square; default ``resolution``). A point is lit when it
        lies no more than ``1.5 * texel(d) * (1 + min(tan theta, 8)) + 1e-4 * diagonal``
        beyond the stored depth (texel(d): texel size at the point's distance d; theta: angle
        between its normal and the light sample).
    layers : int
        Peeling layers (the paper uses four).

    Returns
    -------
    ShadowResult
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if not isinstance(camera, _core.Camera):
        raise InputError(f"camera must be a scenesample.Camera, got {type(camera).__name__}")
    if not isinstance(light, AreaLight):
        raise InputError(f"light must be an AreaLight, got {type(light).__name__}")
    if discretization not in DISCRETIZATIONS:
        raise InputError(
            f"discretization must be one of {list(DISCRETIZATIONS)}, got {discretization!r}"
        )
    if views not in ("corners", "center"):
        raise InputError(f"views must be 'corners' or 'center', got {views!r}")
    try:
        nu, nv = (int(x) for x in samples)
    except (TypeError, ValueError):
        raise InputError(f"samples must be two positive integers, got {samples!r}") from None
    for name, val in (("samples", min(nu, nv)), ("resolution", resolution), ("layers", layers)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1:
            raise InputError(f"{name} must be positive integers, got {val!r}")
    sres = resolution if shadow_resolution is None else shadow_resolution
    if isinstance(sres, bool) or not isinstance(sres, (int, np.integer)) or sres < 1:
        raise InputError(f"shadow_resolution must be a positive integer, got {sres!r}")
    d = _core.soft_shadows(
        scene._core,
        camera,
        light.center,
        light.u,
        light.v,
        (nu, nv),
        discretization,
        int(resolution),
        views == "corners",
        reconstruction,
        int(sres),
        int(layers),
    )
    ops = d.pop("ops")
    return ShadowResult(**d, discretization=discretization, stats=dict(ops))
