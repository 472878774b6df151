"""One function per method, each with its own keyword-only options, defaults and docstring.

``discretize(scene, cameras, method, **options)`` and ``reconstruct(source, method,
**options)`` dispatch here: an option the chosen method does not take raises
:class:`~scenesample.InputError` naming it and listing the ones the method accepts.

Sampling (``discretize``):

- :func:`conventional`, :func:`nonredundant`, :func:`peeling`: depth images
  (non-redundant-rendering.txt);
- :func:`epr`, :func:`ivir`: points for many off-screen views (eye-based-point-rendering.txt);
- :func:`visibility_field` (visibility-field.txt);
- :func:`impostors` (multi-cell-orthographic-impostors.txt).

Rebuilding (``reconstruct``): :func:`mesh`, :func:`hybrid`, :func:`points` from depth images;
:func:`field_view` from a visibility field; :func:`impostor_view` from impostors.
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any, Callable, Union

import numpy as np

from . import _core
from ._conventional import conventional
from ._progress import Progress
from ._scene import Scene
from .epr.omni import shadow_points
from .epr.points import Points, epr_points
from .errors import InputError
from .impostors.cells import impostor_view, impostors
from .nonredundant.images import hybrid, mesh, nonredundant, peeling, points
from .visibility_field import field_view, visibility_field

Camera = _core.Camera

__all__ = [
    "conventional",
    "nonredundant",
    "peeling",
    "epr",
    "ivir",
    "visibility_field",
    "impostors",
    "mesh",
    "hybrid",
    "points",
    "field_view",
    "impostor_view",
]


def _points(
    scene: Scene,
    eye: Camera,
    density: str,
    reflectors: Any,
    light: Any,
    light_samples: int,
    rho_scale: float,
    seed: int,
    resolution: Union[None, int, Sequence[int]],
    progress: Progress,
) -> Points:
    if not isinstance(eye, Camera):
        raise InputError(f"eye must be a scenesample.Camera, got {type(eye).__name__}")
    if light is None:
        return epr_points(
            scene,
            eye,
            reflectors=reflectors,
            rho_scale=rho_scale,
            seed=seed,
            resolution=resolution,
            density=density,
            progress=progress,
        )
    if reflectors is not None:
        raise InputError("pass reflectors= (reflections) or light= (shadows), not both")
    if resolution is not None and not isinstance(resolution, (int, np.integer)):
        raise InputError(f"shadow cube maps share one resolution; got {resolution!r}")
    return shadow_points(
        scene,
        eye,
        light,
        light_samples=light_samples,
        rho_scale=rho_scale,
        seed=seed,
        resolution=resolution,
        density=density,
    )


def epr(
    scene: Scene,
    *,
    eye: Camera,
    reflectors: Any = None,
    light: Any = None,
    light_samples: int = 20,
    rho_scale: float = 0.5,
    seed: int = 0,
    resolution: Union[None, int, Sequence[int]] = None,
    progress: Progress = None,
) -> Points:
    """Eye-based point sampling (eye-based-point-rendering.txt §3.1-3.4, Eq. 2-4): points for
    the cube maps of reflectors, or of a light's shadows, spaced by what ``eye`` can resolve.

    Per triangle, one visibility bit per cube-map view (conservative: dropped only when all
    vertices lie outside one plane of the 20%-enlarged frustum; a reflector's own triangles are
    left out of its own cube, and so is a triangle whose material is single-sided
    (``double_sided`` false) and turns its back to the reflector's centre, as §3.2 samples a
    triangle only for the views it faces; triangles without a material count as double-sided);
    point spacing = the eye's pixel footprint at the distance light travels from the triangle
    via the nearest reflector's bounding sphere to the eye, divided by ``rho_scale``, never
    finer than the finest cube map that sees the triangle; triangles under 1/10 point-cell
    dropped with probability 1 - 10 A; every lattice cell overlapping the triangle gives a
    point (exact conservative rasterization, on the CPU, since wgpu here has none).

    Parameters
    ----------
    scene : Scene
    eye : Camera
        The eye whose pixels the points must fill (required).
    reflectors : list, optional
        Object names, :class:`Reflector` objects or ``(center, radius)`` bounding spheres; by
        default every object whose material has metallic >= 0.9 and roughness <= 0.1. Each
        gets a cube map of six views.
    light : (center, radius), optional
        Points for the shadow cube maps of this spherical light (§5.1) instead of reflections:
        six views per light sample, in ``Camera.cube`` order, sample after sample. Spacing: the
        eye's pixel footprint at the nearest of the triangle's shadow volumes over
        ``rho_scale`` (Eq. 5), never finer than the cube-map texel at the triangle's distance
        from the nearest light sample (so an eye inside a shadow volume gets a finite density).
    light_samples : int
        With ``light``: samples on the light (its centre for 1, else a Fibonacci lattice on its
        sphere).
    rho_scale : float
        Points per eye pixel along each axis (§3.2; 0.5 is the paper's choice).
    seed : int
        Seeds the stochastic culling of sub-1/10-pixel triangles.
    resolution : int or sequence of int, optional
        Cube-map face resolution (one, or one per reflector); by default the adaptive size of
        §4.1.1 (see :func:`scenesample.cube_resolution`), or for shadow points Eq. 6 (see
        :func:`scenesample.omni_shadows`).
    progress : bool, callable or None
        A tqdm bar over the triangles of reflector points (see :func:`visibility_field`).

    Returns
    -------
    Points
    """
    return _points(
        scene, eye, "eye", reflectors, light, light_samples, rho_scale, seed, resolution, progress
    )


def ivir(
    scene: Scene,
    *,
    eye: Camera,
    reflectors: Any = None,
    light: Any = None,
    light_samples: int = 20,
    seed: int = 0,
    resolution: Union[None, int, Sequence[int]] = None,
    progress: Progress = None,
) -> Points:
    """Points at the cube maps' own density (iVIR, the baseline of
    eye-based-point-rendering.txt §6): as :func:`epr`, but each triangle is spaced by the
    cube-map texel at its distance from the reflector (or light sample), whatever the eye
    resolves. Options as :func:`epr`, without ``rho_scale``."""
    return _points(
        scene, eye, "offscreen", reflectors, light, light_samples, 0.5, seed, resolution, progress
    )


#: method name -> (function, whether it takes cameras)
DISCRETIZE: dict[str, tuple[Callable[..., Any], bool]] = {
    "conventional": (conventional, True),
    "nonredundant": (nonredundant, True),
    "peeling": (peeling, True),
    "epr": (epr, False),
    "ivir": (ivir, False),
    "visibility_field": (visibility_field, False),
    "impostors": (impostors, False),
}

#: reconstruct methods for depth images
RECONSTRUCT: dict[str, Callable[..., Any]] = {"mesh": mesh, "hybrid": hybrid, "points": points}


def options_of(fn: Callable[..., Any]) -> list[inspect.Parameter]:
    """The keyword-only parameters of a method function, in order."""
    return [p for p in inspect.signature(fn).parameters.values() if p.kind is p.KEYWORD_ONLY]


def check_options(
    method: str, fn: Callable[..., Any], options: dict[str, Any], family: dict[str, Any]
) -> None:
    """Raise :class:`InputError` for an option ``fn`` does not take (naming the options it
    takes, and the methods of ``family`` that take the stray one) or a required one missing."""
    params = options_of(fn)
    names = [p.name for p in params]
    for name in options:
        if name in names:
            continue
        takes = [m for m, f in family.items() if name in _names(f)]
        where = f"; it would apply to method={', '.join(map(repr, takes))}" if takes else ""
        if name == "backend" and takes:
            where = (
                f": {method!r} runs on the GPU only; the methods with a CPU backend: "
                f"{', '.join(map(repr, takes))}"
            )
        accepted = ", ".join(f"{n}=" for n in names) or "none"
        raise InputError(
            f"{name}= does not apply to method={method!r} (its options: {accepted}){where}"
        )
    for p in params:
        if p.default is p.empty and p.name not in options:
            raise InputError(f"method={method!r} needs {p.name}=")


def _names(entry: Any) -> list[str]:
    fn = entry[0] if isinstance(entry, tuple) else entry
    return [p.name for p in options_of(fn)]
