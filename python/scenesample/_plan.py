"""Simulate only the effects a scene calls for: ``plan`` reads the scene's content and lists
the effects it needs, with the reason and an estimated cost; ``render`` computes exactly those
(or the subset asked for) and composes a frame."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Optional, Union

import numpy as np

from . import _core
from ._conventional import conventional
from ._scene import Scene
from .epr.omni import omni_shadows
from .epr.points import reflectors_of
from .epr.reflections import reflections
from .errors import GpuError, InputError
from .imageio import auto_exposure, linear_to_srgb
from .nonredundant.shadows import AreaLight, soft_shadows

__all__ = ["Effect", "Frame", "plan", "render", "rates", "QUALITY", "THROUGHPUT"]

Camera = _core.Camera
EFFECT_KINDS = ("soft_shadows", "omni_shadows", "spot_shadows", "reflections")

# Settings per quality level.
QUALITY: dict[str, dict[str, Any]] = {
    "fast": dict(
        soft_samples=(4, 4),
        soft_resolution=256,
        omni_samples=1,
        omni_method="mvr",
        light_radius=0.0,
        rho_scale=0.25,
        bounces=1,
    ),
    "balanced": dict(
        soft_samples=(8, 8),
        soft_resolution=512,
        omni_samples=8,
        omni_method="epr",
        light_radius=0.01,
        rho_scale=0.5,
        bounces=1,
    ),
    "high": dict(
        soft_samples=(16, 16),
        soft_resolution=1024,
        omni_samples=20,
        omni_method="epr",
        light_radius=0.02,
        rho_scale=1.0,
        bounces=2,
    ),
}

# Throughputs of this project's machine (2 cores, lavapipe), used by the cost model: scene
# triangles rasterized per second per view, reconstruction triangles (about a pixel each) per
# second into light-sample shadow maps, pixels resolved per second, shadow-map tests per second,
# (point, view) splat pairs per second, rays per second, shading operations per second.
THROUGHPUT = {
    "raster_triangles": 6e7,
    "shadow_triangles": 6e7,
    "pixels": 3e7,
    "shadow_tests": 5e7,
    "splat_pairs": 6e6,
    "rays": 1.5e7,
    "shading": 4e6,
}


@dataclass(frozen=True, eq=False)
class Effect:
    """One effect a scene calls for.

    Attributes
    ----------
    kind : {"soft_shadows", "omni_shadows", "spot_shadows", "reflections"}
    source : str
        What calls for it: the light or the reflective objects.
    reason : str
        Why, in words.
    params : dict
        What ``render`` runs it with (the light, the reflectors, the quality's settings).
    estimate : dict
        The cost model's prediction before running: ``work`` (counts of the operations it will
        do: triangles rasterized, pixels, shadow tests, splat pairs, rays, shading operations)
        and ``seconds`` (the work divided by the rates of :func:`rates`: this machine's
        measured raster, pixel and ray rates, :data:`THROUGHPUT`'s defaults for the rest, listed
        under ``measured_rates``). A model, not a promise.
    """

    kind: str
    source: str
    reason: str
    params: dict = field(default_factory=dict)
    estimate: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
        """``kind: source``, e.g. ``reflections: sphere 0``."""
        return f"{self.kind}: {self.source}"

    def __repr__(self) -> str:
        return (
            f"Effect({self.name!r}, ~{self.estimate.get('seconds', float('nan')):.3g} s: "
            f"{self.reason})"
        )


@dataclass(eq=False, repr=False)
class Frame:
    """A rendered frame.

    Attributes
    ----------
    image : (H, W, 3) float32
        Linear RGB, shaded in Rust by the package's one model (``src/shading.rs``, the one
        reflections and impostors use): Lambertian diffuse plus a GGX specular lobe from each
        material's metallic and roughness, under the scene's punctual lights (colour x
        intensity, inverse-square falloff, glTF range and spot cones) and its area lights
        (emissive objects and ``area_lights``: a unit-radiance source toward each centre), each
        scaled by its shadow effect's visibility where one ran; plus 0.08 ambient. With no
        light at all, or lights that leave the view dark (fewer than 10% of the visible pixels
        get direct light as bright as their ambient light: the toy car's one emissive part),
        the default light from the camera's upper left joins them (``stats["default_light"]``).
        Where a reflections effect ran, its reflective pixels are that effect's image.
    effects : dict of str to result
        Each effect run, by :attr:`Effect.name`: a ShadowResult, OmniShadowResult or
        ReflectionResult.
    plan : list of Effect
        The effects that ran.
    mask : (H, W) bool
        Pixels that see a surface.
    stats : dict
        ``effects_run``, ``reflectors``, ``lights``, ``default_light``, the operations counted
        while rendering
        (``cube_maps``, ``splat_passes``, ``shadow_views``, ``rays_cast``), and per effect
        ``estimated_seconds`` and ``seconds``.
    timings : dict of str to float
        Seconds: ``gbuffer``, each effect by name, ``compose``, ``total``.
    """

    image: np.ndarray
    effects: dict
    plan: list
    mask: np.ndarray
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    def to_srgb8(self, exposure: Union[float, str] = 1.0) -> np.ndarray:
        """(H, W, 3) uint8 sRGB of :attr:`image` times ``exposure``: a number (1: the image as
        shaded, what the image metrics compare), or ``"auto"``, which meters the view as a
        camera does: the log-average luminance of the pixels that see a surface becomes 0.18
        (mid grey; Reinhard et al., "Photographic Tone Reproduction", 2002), the scale kept
        within 1/16..16 (:func:`scenesample.imageio.auto_exposure`)."""
        if exposure == "auto":
            exposure = auto_exposure(self.image, self.mask)
        if isinstance(exposure, str) or not np.isfinite(exposure) or exposure <= 0:
            raise InputError(f"exposure must be a positive number or 'auto', got {exposure!r}")
        return linear_to_srgb(self.image * np.float32(exposure))

    def __repr__(self) -> str:
        h, w, _ = self.image.shape
        return f"Frame({w}x{h}, effects {list(self.effects)})"

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def emissive_lights(scene: Scene) -> list[tuple[str, AreaLight]]:
    """An area light per object whose faces have an emissive material: the smallest rectangle
    that bounds its vertices in their best-fit plane (exact for an emissive rectangle). The
    smallest bounding rectangle has a side along an edge of the points' convex hull, so only
    the hull's edges are tried: O(n log n) in the object's vertices."""
    emissive = [i for i, m in enumerate(scene.materials) if max(m.get("emissive", (0,))) > 0]
    if not emissive:
        return []
    faces = np.flatnonzero(np.isin(scene.material_ids, emissive))
    out = []
    for obj in np.unique(scene.object_ids[faces]):
        sel = faces[scene.object_ids[faces] == obj]
        pts = scene.vertices[np.unique(scene.faces[sel])].astype(np.float64)
        c = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
        u, v = vt[0], vt[1] if len(vt) > 1 else np.cross(vt[0], [0.0, 0.0, 1.0])
        flat = np.stack([(pts - c) @ u, (pts - c) @ v], axis=1)
        a, b = u, v
        best = np.inf
        for e in _hull_edges(flat):
            pe, pf = flat @ e, flat @ np.array([-e[1], e[0]])
            area = np.ptp(pe) * np.ptp(pf)
            if area < best - 1e-12:
                best = area
                a, b = e[0] * u + e[1] * v, -e[1] * u + e[0] * v
        pa, pb = (pts - c) @ a, (pts - c) @ b
        centre = c + a * (pa.max() + pa.min()) / 2 + b * (pb.max() + pb.min()) / 2
        ext_a = max(pa.max() - pa.min(), 1e-9 * scene_diagonal(scene))
        ext_b = max(pb.max() - pb.min(), 1e-9 * scene_diagonal(scene))
        name = scene.objects[obj] if 0 <= obj < len(scene.objects) else f"object {obj}"
        out.append((name, AreaLight(tuple(centre), tuple(a * ext_a), tuple(b * ext_b))))
    return out


def _outside_octagon(p: np.ndarray) -> np.ndarray:
    """``p`` (sorted) without the points strictly inside the convex polygon of its extremes along
    x, y and the two diagonals (Akl-Toussaint): they cannot be on the hull, and dropping them
    first keeps the hull's Python loop short on finely tessellated objects."""
    if len(p) < 16:
        return p
    keys = np.stack([p[:, 0], p[:, 0] + p[:, 1], p[:, 1], p[:, 1] - p[:, 0]], axis=1)
    order = [
        np.argmax(keys[:, 0]),
        np.argmax(keys[:, 1]),
        np.argmax(keys[:, 2]),
        np.argmax(keys[:, 3]),
        np.argmin(keys[:, 0]),
        np.argmin(keys[:, 1]),
        np.argmin(keys[:, 2]),
        np.argmin(keys[:, 3]),
    ]  # counter-clockwise around the set
    poly = p[order]
    poly = poly[np.r_[True, np.any(np.diff(poly, axis=0) != 0, axis=1)]]
    if len(poly) < 3:
        return p
    inside = np.ones(len(p), dtype=bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        if np.all(a == b):
            continue
        cross = (b[0] - a[0]) * (p[:, 1] - a[1]) - (b[1] - a[1]) * (p[:, 0] - a[0])
        inside &= cross > 0
    return p[~inside]


def _hull_edges(p: np.ndarray) -> np.ndarray:
    """Unit directions of the edges of the convex hull of 2D points ``p`` (Andrew's monotone
    chain); empty when the points are all one point."""
    pts = _outside_octagon(np.unique(p, axis=0))
    if len(pts) < 2:
        return np.zeros((0, 2))

    def half(seq: np.ndarray) -> list:
        chain: list = []
        for q in seq:
            while len(chain) >= 2:
                (ax, ay), (bx, by) = chain[-2], chain[-1]
                if (bx - ax) * (q[1] - ay) - (by - ay) * (q[0] - ax) > 0:
                    break
                chain.pop()
            chain.append(q)
        return chain

    lower, upper = half(pts), half(pts[::-1])
    hull = np.array(lower[:-1] + upper[:-1])
    d = np.roll(hull, -1, axis=0) - hull
    n = np.linalg.norm(d, axis=1)
    return d[n > 0] / n[n > 0, None]


def scene_diagonal(scene: Scene) -> float:
    lo, hi = scene.bounds.astype(np.float64)
    return float(np.linalg.norm(hi - lo))


def _pixels(camera: Optional[Camera]) -> int:
    return 512 * 512 if camera is None else camera.width * camera.height


def rates(triangles: int) -> dict[str, float]:
    """:data:`THROUGHPUT` with what this machine measured in place of the defaults: raster
    triangles per view and pixels per second from the GPU cost model that
    ``discretize(..., backend="auto")`` calibrates (once per machine), rays per second from its
    CPU model at ``triangles`` triangles. The keys it measured are listed under ``measured``."""
    out: dict[str, Any] = dict(THROUGHPUT)
    measured = []
    try:
        c = _core.choose_backend(max(int(triangles), 2), 512 * 512)["coefficients"]
    except GpuError:  # the probes failed: the defaults stand
        c = {}
    # A pixel's ray that meets the scene's box (the model holds log2 t at its small probe's).
    per_ray = (
        c.get("cpu_per_pixel", 0.0)
        + c.get("cpu_per_box_ray", 0.0)
        + c.get("cpu_per_box_ray_log2", 0.0) * np.log2(max(int(triangles), 4608))
    )
    for key, seconds in (
        ("raster_triangles", c.get("gpu_per_triangle", 0.0)),
        ("pixels", c.get("gpu_per_pixel", 0.0)),
        ("rays", per_ray),
    ):
        if seconds > 0:
            out[key] = 1.0 / seconds
            measured.append(key)
    out["measured"] = measured
    return out


def _estimate(work: dict[str, float], rate: dict[str, Any]) -> dict[str, Any]:
    seconds = sum(work[k] / rate[k] for k in work)
    return {
        "work": {k: float(v) for k, v in work.items()},
        "seconds": float(seconds),
        "measured_rates": [k for k in work if k in rate["measured"]],
    }


def plan(
    scene: Scene,
    *,
    area_lights: Sequence[AreaLight] = (),
    camera: Optional[Camera] = None,
    quality: str = "balanced",
) -> list[Effect]:
    """The effects ``scene`` calls for, each with its reason and estimated cost, and nothing
    else:

    - an area light (an object with an emissive material, or one of ``area_lights``) calls for
      soft shadows: by Algorithm 5 of non-redundant-rendering.txt or by ray tracing (exact),
      whichever the cost model, calibrated once per machine, finds cheaper
      (``params["discretization"]``; the reason gives both estimates). On a machine without
      a fast GPU that is ray tracing;
    - a ``KHR_lights_punctual`` point light calls for omnidirectional shadows
      (eye-based-point-rendering.txt §5), a spot light for spot shadows (a cube map of its
      position, the lighting restricted to its cone); a directional light lights the frame
      unshadowed;
    - reflective materials (metallic >= 0.9 and roughness <= 0.1; see
      :func:`scenesample.epr.reflectors_of`) call for cube-mapped reflections (§4), one
      reflector per reflective object.

    ``camera`` (default: a 512² view) and ``quality`` ("fast", "balanced", "high") set what
    the estimates assume.
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if quality not in QUALITY:
        raise InputError(f"quality must be one of {list(QUALITY)}, got {quality!r}")
    for k, a in enumerate(area_lights):
        if not isinstance(a, AreaLight):
            raise InputError(f"area_lights[{k}] must be an AreaLight, got {type(a).__name__}")
    if camera is not None and not isinstance(camera, Camera):
        raise InputError(f"camera must be a scenesample.Camera, got {type(camera).__name__}")
    q = QUALITY[quality]
    rate = rates(scene.triangle_count)
    px = _pixels(camera)
    lights = [(name, a, "emissive object") for name, a in emissive_lights(scene)]
    lights += [
        (f"area light {k}", a, "area light added by the user") for k, a in enumerate(area_lights)
    ]
    out = [_soft_shadows(scene, name, light, why, q, rate, px) for name, light, why in lights]
    out += [
        _point_shadows(scene, k, light, q, rate, px)
        for k, light in enumerate(scene.lights)
        if light["type"] != "directional"
    ]
    try:
        refl = reflectors_of(scene)
    except InputError:  # no object with a mirror material
        refl = []
    if refl:
        out.append(_reflections(scene, refl, q, rate, px))
    return out


def _soft_shadows(
    scene: Scene, name: str, light: AreaLight, why: str, q: dict, rate: dict, px: float
) -> Effect:
    """The soft shadows of one area light, by the cheaper of Algorithm 5 and ray tracing."""
    tris = scene.triangle_count
    nu, nv = q["soft_samples"]
    res = q["soft_resolution"]
    # Non-redundant (Algorithm 5): four corner images and their offset images; each light
    # sample shadow-maps the reconstruction (about two triangles per covered pixel of the
    # four images).
    recon = 2 * 4 * res * res * 0.5
    nonredundant = _estimate(
        {
            "raster_triangles": 8 * tris,
            "shadow_triangles": nu * nv * recon,
            "pixels": 8 * res * res + nu * nv * res * res,
            "shadow_tests": nu * nv * px,
        },
        rate,
    )
    # Ray traced: one occlusion ray per pixel and light sample, exact. Without a fast GPU
    # it is the cheaper one by far (docs/bench/methods.md: 30-50x on lavapipe), and the
    # cheaper of the two is run, never a method that loses.
    raytraced = _estimate({"rays": nu * nv * px}, rate)
    if raytraced["seconds"] <= nonredundant["seconds"]:
        method, estimate, other = "raytraced", raytraced, nonredundant
    else:
        method, estimate, other = "nonredundant", nonredundant, raytraced
    return Effect(
        "soft_shadows",
        name,
        f"{why} {name!r} emits light over an area: its shadows are soft; {method} "
        f"(estimated {estimate['seconds']:.3g} s on this machine, against "
        f"{other['seconds']:.3g} s the other way)",
        {
            "light": light,
            "samples": (nu, nv),
            "resolution": res,
            "discretization": method,
            "estimated_seconds": {
                "raytraced": raytraced["seconds"],
                "nonredundant": nonredundant["seconds"],
            },
        },
        estimate,
    )


def _point_shadows(scene: Scene, k: int, light: dict, q: dict, rate: dict, px: float) -> Effect:
    """The shadows of punctual light ``k`` (point: omnidirectional; spot: inside its cone)."""
    kind = light["type"]
    label = light.get("name") or f"light {k}"
    s = q["omni_samples"]
    faces = 6 * s
    work = {
        "raster_triangles": faces * scene.triangle_count,
        "pixels": faces * 256 * 256,
        "shadow_tests": faces * px,
    }
    if q["omni_method"] == "epr":
        work["splat_pairs"] = 2.0 * s * px
    return Effect(
        "omni_shadows" if kind == "point" else "spot_shadows",
        f"{label} ({kind})",
        (
            f"{kind} light {label!r} shines in every direction: six shadow views per sample"
            if kind == "point"
            else f"spot light {label!r}: shadows inside its cone"
        ),
        {
            "light": light,
            "index": k,
            "samples": s,
            "radius": q["light_radius"] * scene_diagonal(scene),
            "method": q["omni_method"],
        },
        _estimate(work, rate),
    )


def _reflections(scene: Scene, refl: list, q: dict, rate: dict, px: float) -> Effect:
    """Cube-mapped reflections of the reflective objects ``refl``."""
    views = 6 * len(refl)
    work = {
        "splat_pairs": views * px * q["rho_scale"] ** 2 / 4,
        "raster_triangles": scene.triangle_count,
        "shading": 25 * px * 0.2,
    }
    return Effect(
        "reflections",
        f"{len(refl)} reflective object(s)",
        "objects with mirror-like materials (metallic >= 0.9, roughness <= 0.1): "
        + ", ".join(r.name for r in refl[:5])
        + (" ..." if len(refl) > 5 else ""),
        {"reflectors": refl, "rho_scale": q["rho_scale"], "bounces": q["bounces"]},
        _estimate(work, rate),
    )


def _select(planned: list[Effect], effects: Any) -> list[Effect]:
    if effects is None:
        return planned
    chosen = []
    for e in effects:
        if isinstance(e, Effect):
            chosen.append(e)
        elif isinstance(e, str):
            if e not in EFFECT_KINDS and not any(p.name == e for p in planned):
                raise InputError(
                    f"unknown effect {e!r}: one of {list(EFFECT_KINDS)} or a planned effect's "
                    f"name {[p.name for p in planned]}"
                )
            chosen += [p for p in planned if p.kind == e or p.name == e]
        else:
            raise InputError(f"effects must be Effects or names, got {type(e).__name__}")
    return chosen


OPS = ("cube_maps", "splat_passes", "shadow_views", "rays_cast")


def render(
    scene: Scene,
    camera: Camera,
    *,
    quality: str = "balanced",
    effects: Optional[Sequence[Union[str, Effect]]] = None,
    area_lights: Sequence[AreaLight] = (),
    seed: int = 0,
) -> Frame:
    """Render ``camera``'s view computing exactly the effects :func:`plan` finds (or, with
    ``effects``, only those kinds or planned effects), and compose them (see :class:`Frame`).
    A scene that calls for nothing is lit without shadows or reflections; with no lights at all
    a default light from the camera's upper left lights it."""
    if not isinstance(camera, Camera):
        raise InputError(f"camera must be a scenesample.Camera, got {type(camera).__name__}")
    total = time.perf_counter()
    planned = plan(scene, area_lights=area_lights, camera=camera, quality=quality)
    chosen = _select(planned, effects)
    timings: dict[str, float] = {}
    t = time.perf_counter()
    g = conventional(scene, camera)
    timings["gbuffer"] = time.perf_counter() - t
    results = {}
    for e in chosen:
        t = time.perf_counter()
        results[e.name] = _run_effect(e, scene, camera, seed)
        timings[e.name] = time.perf_counter() - t
    t = time.perf_counter()
    image, lights, rig = _compose(scene, camera, g, chosen, results, area_lights)
    timings["compose"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - total
    # What this call ran: the sum of its effects' own counts (never process-wide differences,
    # which other calls running at the same time would pollute).
    stats: dict[str, Any] = {k: sum(int(r.stats.get(k, 0)) for r in results.values()) for k in OPS}
    stats["effects_run"] = len(chosen)
    stats["reflectors"] = sum(
        len(e.params["reflectors"]) for e in chosen if e.kind == "reflections"
    )
    stats["lights"] = lights
    stats["default_light"] = rig
    stats["effects"] = {
        e.name: {"estimated_seconds": e.estimate["seconds"], "seconds": timings[e.name]}
        for e in chosen
    }
    return Frame(
        image=image,
        effects=results,
        plan=chosen,
        mask=g.triangle[0] >= 0,
        stats=stats,
        timings=timings,
    )


def _run_effect(e: Effect, scene: Scene, camera: Camera, seed: int) -> Any:
    """Run one planned effect from ``camera``."""
    if e.kind == "soft_shadows":
        return soft_shadows(
            scene,
            camera,
            e.params["light"],
            samples=e.params["samples"],
            resolution=e.params["resolution"],
            discretization=e.params.get("discretization", "nonredundant"),
        )
    if e.kind in ("omni_shadows", "spot_shadows"):
        return omni_shadows(
            scene,
            camera,
            e.params["light"]["position"],
            e.params["radius"],
            light_samples=e.params["samples"],
            method=e.params["method"],
            seed=seed,
        )
    return reflections(
        scene,
        camera,
        reflectors=e.params["reflectors"],
        rho_scale=e.params["rho_scale"],
        bounces=e.params["bounces"],
        seed=seed,
    )


def _compose(
    scene: Scene,
    camera: Camera,
    g: Any,
    chosen: Sequence[Effect],
    results: dict[str, Any],
    area_lights: Sequence[AreaLight],
) -> tuple[np.ndarray, int]:
    """The frame's image, shaded in Rust by the package's one model (``shading::frame``):
    each light scaled by its shadow effect's visibility; the reflective pixels are the
    reflections effect's image. Also returns how many lights lit it, and whether the default
    light was added because the scene's left the view dark."""
    point_vis: dict[int, np.ndarray] = {}
    area_vis: dict[str, np.ndarray] = {}
    reflected = None
    for e in chosen:
        r = results[e.name]
        if e.kind == "soft_shadows":
            area_vis[e.source] = r.visibility
        elif e.kind in ("omni_shadows", "spot_shadows"):
            point_vis[e.params["index"]] = r.visibility
        else:
            reflected = r
    areas = emissive_lights(scene) + [(f"area light {k}", a) for k, a in enumerate(area_lights)]
    image, rig = _core.shade_frame(
        scene._core,
        camera,
        (g.triangle[0], g.position[0].reshape(-1, 3), g.color[0].reshape(-1, 3)),
        [point_vis.get(k) for k in range(len(scene.lights))],
        [(np.asarray(light.center, dtype=np.float64), area_vis.get(name)) for name, light in areas],
    )
    if reflected is not None:
        image[reflected.reflective] = reflected.image[reflected.reflective]
    return image, len(scene.lights) + len(areas), rig
