"""Cube-mapped reflections by EPR, MVR and iVIR (eye-based-point-rendering.txt §4)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any, Optional, Union

import numpy as np

from .. import _core
from .._scene import Scene
from ..errors import InputError
from ..imageio import linear_to_srgb
from .points import (
    cube_maps,
    cube_resolution,
    max_cube_resolution,
    reflector_arrays,
    reflectors_of,
)

Camera = _core.Camera
REFLECTION_METHODS = ("epr", "mvr", "ivir")


@dataclass(eq=False, repr=False)
class ReflectionResult:
    """An eye image with cube-mapped reflections.

    Attributes
    ----------
    image : (H, W, 3) float32
        Linear RGB radiance.
    reflective : (H, W) bool
        Pixels showing a reflector.
    method : str
    resolutions : list of int
        Cube-map face resolution per reflector.
    stats : dict of str to float
        ``points`` (EPR / iVIR), ``shading_ops`` (shading evaluations: EPR shades each
        looked-up texel once, MVR / iVIR every covered texel), ``offscreen_pixels``,
        ``buffer_bytes``, ``reflective_pixels``; ``cube_maps``, ``splat_passes``,
        ``shadow_views``, ``rays_cast``: what this call ran.
    timings : dict of str to float
        ``eye`` (G-buffer), ``points``, ``views`` (splat or raster), ``shade`` (MVR / iVIR),
        ``deferred`` (the eye's lookups, and EPR's lazy shading), ``total``.
    """

    image: np.ndarray
    reflective: np.ndarray
    method: str
    resolutions: list
    stats: dict
    timings: dict

    def __repr__(self) -> str:
        h, w = self.reflective.shape
        return (
            f"ReflectionResult({self.method}, {w}x{h}, {int(self.stats['shading_ops']):,} "
            f"shading ops, {self.timings['total']:.3f} s)"
        )

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def to_srgb8(self) -> np.ndarray:
        """(H, W, 3) uint8: clamped to [0, 1] and sRGB encoded, for display and for the image
        metric."""
        return linear_to_srgb(self.image)


def reflections(
    scene: Scene,
    eye: Camera,
    *,
    method: str = "epr",
    bounces: int = 1,
    supersample: int = 25,
    rho_scale: float = 0.5,
    reflectors: Any = None,
    resolution: Union[None, int, Sequence[int]] = None,
    seed: int = 0,
) -> ReflectionResult:
    """Render ``eye`` with dynamic cube-mapped reflections (eye-based-point-rendering.txt §4).

    Parameters
    ----------
    scene : Scene
    eye : Camera
    method : {"epr", "mvr", "ivir"}
        ``"epr"``: eye-resolution points splatted into index-only cube maps, eye-based deferred
        shading (a texel is shaded only when a reflective pixel looks it up, once), ``supersample``
        Poisson-distributed lookups per reflective pixel from its normal gradient (§4.1.3),
        further bounces through the looked-up points' own cube maps (§4.1.4).
        ``"mvr"``: the six faces of every cube map rasterized, every covered texel shaded,
        trilinear mip-mapped lookups at the pixel's reflection footprint.
        ``"ivir"``: points at the cube maps' texel density, splatted, then shaded and looked up
        like MVR's.
    bounces : int
        Reflections of reflections (1-8).
    supersample : int
        EPR lookups per reflective pixel (the paper's 25).
    rho_scale : float
        EPR points per eye pixel along each axis (the paper's 1/2).
    reflectors : list, optional
        As for ``discretize(method="epr")``: default, the objects with metallic >= 0.9 and
        roughness <= 0.1.
    resolution : int or sequence of int, optional
        Cube-map face resolution (one, or one per reflector). Default: for EPR the adaptive
        size of §4.1.1 (:func:`scenesample.cube_resolution`); for MVR and iVIR the largest
        (half the eye's resolution, at most 512), as in the paper's configuration: its MVR
        shading counts (Table 1: ~1.5M per reflector) are those of ~500² faces, and iVIR samples
        points for every off-screen pixel.
    seed : int
        Seeds EPR's stochastic culling.

    Sidedness (shared by all methods, glTF's ``doubleSided``): a cube map does not see the back
    of a triangle whose material is single-sided (MVR culls it; EPR and iVIR sample a triangle
    only for the cube maps it faces, §3.2); it sees both sides of a double-sided one, and of a
    triangle without a material. In a closed, consistently wound scene this changes no pixel.

    Shading (shared by all methods): Lambert + GGX under the scene's punctual lights (one default
    directional light when it has none) plus ambient, no shadows; reflective pixels show their
    albedo times the reflected radiance; where a lookup finds nothing, a constant sky.

    Returns
    -------
    ReflectionResult
    """
    if method not in REFLECTION_METHODS:
        raise InputError(f"method must be one of {list(REFLECTION_METHODS)}, got {method!r}")
    refl, res = cube_maps(scene, eye, reflectors, resolution, largest=method in ("mvr", "ivir"))
    d = _core.reflections(
        scene._core,
        eye,
        *reflector_arrays(refl),
        res,
        method,
        int(bounces),
        int(supersample),
        float(rho_scale),
        int(seed),
    )
    return ReflectionResult(
        d["image"], d["reflective"], method, res, {**d["stats"], **d["ops"]}, dict(d["timings"])
    )


def reflection_reference(
    scene: Scene,
    eye: Camera,
    *,
    factor: int = 4,
    bounces: int = 1,
    reflectors: Any = None,
    resolution: Optional[Sequence[int]] = None,
) -> ReflectionResult:
    """The reference of §4.2: MVR at ``factor`` x the eye's resolution in each dimension, its
    cube maps ``factor`` x the adaptive resolution each reflector needs at the original eye (or
    ``factor`` x ``resolution``), capped at MVR's largest for the supersampled eye, and the image
    box-filtered down to the eye's resolution."""
    if factor < 1:
        raise InputError(f"factor must be >= 1, got {factor}")
    big = eye.with_resolution(eye.width * factor, eye.height * factor)
    refl = reflectors_of(scene, reflectors)
    base = resolution if resolution is not None else [cube_resolution(eye, r) for r in refl]
    res = [min(int(x) * factor, max_cube_resolution(big)) for x in base]
    r = reflections(scene, big, method="mvr", bounces=bounces, reflectors=refl, resolution=res)
    h, w = eye.height, eye.width
    img = r.image.reshape(h, factor, w, factor, 3).mean(axis=(1, 3)).astype(np.float32)
    refl_px = r.reflective.reshape(h, factor, w, factor).mean(axis=(1, 3)) >= 0.5
    timings = dict(r.timings)
    return ReflectionResult(img, refl_px, f"mvr x{factor}", r.resolutions, dict(r.stats), timings)
