"""Omnidirectional soft shadows of a spherical light (eye-based-point-rendering.txt §5) by
EPR, MVR and iVIR, with exact ray-cast visibility as the reference."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, Optional

import numpy as np

from .. import _core
from .._scene import Scene
from ..errors import InputError, check_integer
from .points import Points

__all__ = ["OmniShadowResult", "omni_shadows", "OMNI_METHODS"]

Camera = _core.Camera
OMNI_METHODS = ("epr", "mvr", "ivir", "raytraced")
# The paper's largest adaptive shadow cube-map face (§5.2).
MAX_SHADOW_RESOLUTION = 1024


@dataclass(eq=False, repr=False)
class OmniShadowResult:
    """Omnidirectional soft shadows seen from one eye.

    Attributes
    ----------
    visibility : (H, W) float32
        Fraction of light samples visible from each pixel's surface point, in [0, 1]; 1 where
        the pixel sees no surface.
    visible : (H, W, S) bool
        Per light sample.
    mask : (H, W) bool
        Pixels that see a surface.
    light_samples : (S, 3) float64
        The light samples: the centre for one sample, otherwise a Fibonacci lattice on the
        light's sphere.
    method : str
    resolution : int
        Face resolution of every shadow cube map (0 for ``raytraced``).
    stats : dict of str to float
        ``light_samples``, ``views`` (6 per sample), ``resolution``, ``receivers`` (eye pixels
        with a surface); EPR / iVIR add the point statistics of :class:`Points` (``points``,
        ``triangles_culled``, ...) and ``buffer_bytes`` (the splatted cube maps); MVR adds
        ``triangles_drawn`` (the scene's triangles times the views); and ``cube_maps``,
        ``splat_passes``, ``shadow_views``, ``rays_cast``: what this call ran.
    timings : dict of str to float
        Seconds: ``eye`` (the eye's depth image), ``resolution`` (Eq. 6), then ``points``,
        ``splat`` (GPU pass and readback; ``splat_gpu`` the pass alone) and ``test`` for EPR /
        iVIR, or ``shadow`` (raster and test, or the ray casts), and ``total``.
    """

    visibility: np.ndarray
    visible: np.ndarray
    mask: np.ndarray
    light_samples: np.ndarray
    method: str
    resolution: int
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    @property
    def samples(self) -> int:
        """The number of light samples each pixel's visibility averages."""
        return int(self.visible.shape[-1])

    def __repr__(self) -> str:
        h, w = self.visibility.shape
        return (
            f"OmniShadowResult({self.method}, {w}x{h}, {self.samples} light samples, "
            f"cube faces {self.resolution}^2)"
        )

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _light(center: Any, radius: Any) -> tuple[np.ndarray, float]:
    c = np.asarray(center, dtype=np.float64)
    if c.shape != (3,) or not np.isfinite(c).all():
        raise InputError(f"light_center must be 3 finite numbers, got {center!r}")
    try:
        r = float(radius)
    except (TypeError, ValueError):
        raise InputError(f"light_radius must be a number, got {radius!r}") from None
    if not (np.isfinite(r) and r >= 0):
        raise InputError(f"light_radius must be finite and >= 0, got {radius!r}")
    return c, r


def _rho(rho_scale: Any) -> float:
    try:
        r = float(rho_scale)
    except (TypeError, ValueError):
        raise InputError(f"rho_scale must be a number, got {rho_scale!r}") from None
    if not (np.isfinite(r) and r > 0):
        raise InputError(f"rho_scale must be finite and > 0, got {rho_scale!r}")
    return r


def _check(scene: Any, eye: Any) -> None:
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if not isinstance(eye, Camera):
        raise InputError(f"eye must be a scenesample.Camera, got {type(eye).__name__}")


def omni_shadows(
    scene: Scene,
    eye: Camera,
    light_center: Any,
    light_radius: float,
    *,
    light_samples: int = 20,
    method: str = "epr",
    rho_scale: float = 0.5,
    resolution: Optional[int] = None,
    max_resolution: int = MAX_SHADOW_RESOLUTION,
    seed: int = 0,
) -> OmniShadowResult:
    """Soft shadows of a spherical light that shines in every direction
    (eye-based-point-rendering.txt §5): six shadow views (a cube map) per light sample.

    The receivers are the surfaces a conventional depth image from ``eye`` sees. Every light
    sample gets a depth cube map of the occluders, and every receiver is tested against the
    face its direction from the sample falls in: lit when it lies no more than ``1.5 *
    texel(d) * (1 + min(tan theta, 8)) + 1e-4 * diagonal`` beyond the stored occluder (the
    bias of :func:`scenesample.soft_shadows`); a receiver facing away from a sample does not
    see it.

    Parameters
    ----------
    scene : Scene
    eye : Camera
        The output view.
    light_center : (3,) float
    light_radius : float
        Radius of the light's sphere (>= 0).
    light_samples : int
        Samples on the light: its centre for 1, otherwise a Fibonacci lattice on its sphere.
    method : {"epr", "mvr", "ivir", "raytraced"}
        ``"mvr"``: every face rasterizes the scene's triangles (6 x samples passes), and the
        test runs on the GPU. ``"epr"`` (§5.1): points spaced by the eye's pixel footprint at
        the nearest of the triangle's shadow volumes over ``rho_scale``, never finer than the
        cube-map texel at the triangle's distance from the nearest light sample (Eq. 5; an eye
        inside a shadow volume gets that cap), splatted into all faces in one GPU pass, clipped
        to their triangles (§3.5); the faces are read back and tested on the CPU, with the
        occluder depth taken where the receiver's ray meets the stored point's plane (a splat
        stores one depth for its whole square). ``"ivir"``: the same with points spaced by the
        cube-map texel. ``"raytraced"``: one BVH ray per receiver and sample (exact; the
        reference).
    rho_scale : float
        EPR points per eye pixel along each axis.
    resolution : int, optional
        Face resolution of every cube map; by default Eq. 6 for the receivers the eye sees:
        the smallest face whose texel, where it lands on a receiver, is no larger than the
        eye's pixel there (a texel at distance d spans at most 2 d / resolution), at most
        ``max_resolution`` (the paper's 1024).
    max_resolution : int
    seed : int
        Seeds the stochastic culling of sub-1/10-cell triangles (EPR, iVIR).

    Returns
    -------
    OmniShadowResult

    Raises
    ------
    InputError
        Bad scene, eye, light, counts or method.
    GpuUnavailableError
        No GPU adapter, or (EPR, iVIR) one without 64-bit atomics.
    GpuLimitError
        The cube maps or the visibility bits exceed the device's limits.
    """
    _check(scene, eye)
    c, r = _light(light_center, light_radius)
    if method not in OMNI_METHODS:
        raise InputError(f"method must be one of {list(OMNI_METHODS)}, got {method!r}")
    n = check_integer("light_samples", light_samples)
    res = 0 if resolution is None else check_integer("resolution", resolution)
    d = _core.omni_shadows(
        scene._core,
        eye,
        c,
        r,
        n,
        method,
        _rho(rho_scale),
        res,
        check_integer("max_resolution", max_resolution),
        check_integer("seed", seed, 0),
    )
    return OmniShadowResult(
        visibility=d["visibility"],
        visible=d["visible"],
        mask=d["mask"],
        light_samples=d["light_samples"],
        method=method,
        resolution=int(d["resolution"]),
        stats={**d["stats"], **d["ops"]},
        timings=dict(d["timings"]),
    )


def shadow_points(
    scene: Scene,
    eye: Camera,
    light: Any,
    *,
    light_samples: int = 20,
    rho_scale: float = 0.5,
    seed: int = 0,
    resolution: Optional[int] = None,
    density: str = "eye",
) -> Points:
    """Points for the shadow cube maps of a spherical light ``light = (center, radius)`` (see
    :func:`scenesample.discretize`)."""
    _check(scene, eye)
    try:
        center, radius = light
    except (TypeError, ValueError):
        raise InputError(f"light must be (center, radius), got {light!r}") from None
    c, r = _light(center, radius)
    n = check_integer("light_samples", light_samples)
    res = 0 if resolution is None else check_integer("resolution", resolution)
    d = _core.epr_shadow_points(
        scene._core,
        eye,
        c,
        r,
        n,
        res,
        MAX_SHADOW_RESOLUTION,
        density,
        _rho(rho_scale),
        check_integer("seed", seed, 0),
    )
    return Points._from_core(d, [], scene, light_samples=float(n))
