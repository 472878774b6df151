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
from ._depth import conventional
from ._epr import reflectors_of
from ._omni import omni_shadows
from ._reflections import reflections
from ._scene import Scene
from ._shadows import AreaLight, soft_shadows
from .errors import InputError
from .imageio import linear_to_srgb

__all__ = ["Effect", "Frame", "plan", "render", "QUALITY", "THROUGHPUT"]

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

# Throughputs of this project's machine (2 cores, lavapipe), used by the cost model: triangles
# rasterized per second per view, pixels resolved per second, shadow-map tests per second,
# (point, view) splat pairs per second, rays per second, shading operations per second.
THROUGHPUT = {
    "raster_triangles": 6e7,
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
        and ``seconds`` (the work divided by :data:`THROUGHPUT`). A model, not a promise.
    """

    kind: str
    source: str
    reason: str
    params: dict = field(default_factory=dict)
    estimate: dict = field(default_factory=dict)

    @property
    def name(self) -> str:
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
        Linear RGB: each pixel's base colour lit by the scene's lights (a light's contribution
        is its colour x cos(theta), scaled by (d0 / d)^2 for point and spot lights, d0 the
        light's distance to the scene's centre; a spot light only inside its cone), each
        shadowed by its effect's visibility where one ran; plus 0.1 ambient. Where a
        reflections effect ran, its reflective pixels are that effect's image.
    effects : dict of str to result
        Each effect run, by :attr:`Effect.name`: a ShadowResult, OmniShadowResult or
        ReflectionResult.
    plan : list of Effect
        The effects that ran.
    mask : (H, W) bool
        Pixels that see a surface.
    stats : dict
        ``effects_run``, ``reflectors``, ``lights``, the operations counted while rendering
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

    def to_srgb8(self) -> np.ndarray:
        return linear_to_srgb(self.image)

    def __repr__(self) -> str:
        h, w, _ = self.image.shape
        return f"Frame({w}x{h}, effects {list(self.effects)})"

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def emissive_lights(scene: Scene) -> list[tuple[str, AreaLight]]:
    """An area light per object whose faces have an emissive material: the smallest rectangle,
    with a side along one of the object's edges, that bounds its vertices in their best-fit
    plane (exact for an emissive rectangle)."""
    emissive = [i for i, m in enumerate(scene.materials) if max(m.get("emissive", (0,))) > 0]
    if not emissive:
        return []
    faces = np.flatnonzero(np.isin(scene.material_ids, emissive))
    out = []
    for obj in np.unique(scene.object_ids[faces]):
        sel = faces[scene.object_ids[faces] == obj]
        pts = scene.vertices[scene.faces[sel]].reshape(-1, 3).astype(np.float64)
        c = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
        normal = vt[2]
        tri = scene.vertices[scene.faces[sel]].astype(np.float64)
        edges = np.concatenate(
            [tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]]
        )
        edges -= np.outer(edges @ normal, normal)
        edges = edges[np.linalg.norm(edges, axis=1) > 0]
        best = None
        for e in edges / np.linalg.norm(edges, axis=1, keepdims=True):
            f = np.cross(normal, e)
            pe, pf = (pts - c) @ e, (pts - c) @ f
            area = np.ptp(pe) * np.ptp(pf)
            if best is None or area < best[0] - 1e-12:
                best = (area, e, f)
        a, b = (vt[0], vt[1]) if best is None else (best[1], best[2])
        pa, pb = (pts - c) @ a, (pts - c) @ b
        centre = c + a * (pa.max() + pa.min()) / 2 + b * (pb.max() + pb.min()) / 2
        ext_a = max(pa.max() - pa.min(), 1e-9 * scene_diagonal(scene))
        ext_b = max(pb.max() - pb.min(), 1e-9 * scene_diagonal(scene))
        name = scene.objects[obj] if 0 <= obj < len(scene.objects) else f"object {obj}"
        out.append((name, AreaLight(tuple(centre), tuple(a * ext_a), tuple(b * ext_b))))
    return out


def scene_diagonal(scene: Scene) -> float:
    lo, hi = scene.bounds.astype(np.float64)
    return float(np.linalg.norm(hi - lo))


def _pixels(camera: Optional[Camera]) -> int:
    return 512 * 512 if camera is None else camera.width * camera.height


def _estimate(work: dict[str, float]) -> dict[str, Any]:
    seconds = sum(work[k] / THROUGHPUT[k] for k in work)
    return {"work": {k: float(v) for k, v in work.items()}, "seconds": float(seconds)}


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
      soft shadows (non-redundant-rendering.txt Algorithm 5);
    - a ``KHR_lights_punctual`` point light calls for omnidirectional shadows
      (eye-based-point-rendering.txt §5), a spot light for spot shadows (a cube map of its
      position, the lighting restricted to its cone); a directional light lights the frame
      unshadowed;
    - reflective materials (metallic >= 0.9 and roughness <= 0.1; see
      :func:`scenesample._epr.reflectors_of`) call for cube-mapped reflections (§4), one
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
    tris = scene.triangle_count
    px = _pixels(camera)
    diag = scene_diagonal(scene)
    out: list[Effect] = []
    lights = [(name, a, "emissive object") for name, a in emissive_lights(scene)]
    lights += [
        (f"area light {k}", a, "area light added by the user") for k, a in enumerate(area_lights)
    ]
    for name, light, why in lights:
        nu, nv = q["soft_samples"]
        res = q["soft_resolution"]
        # Four corner images and their offset images; each light sample shadow-maps the
        # reconstruction (about two triangles per covered pixel of the four images).
        recon = 2 * 4 * res * res * 0.5
        work = {
            "raster_triangles": 8 * tris + nu * nv * recon,
            "pixels": 8 * res * res + nu * nv * res * res,
            "shadow_tests": nu * nv * px,
        }
        out.append(
            Effect(
                "soft_shadows",
                name,
                f"{why} {name!r} emits light over an area: its shadows are soft",
                {"light": light, "samples": (nu, nv), "resolution": res},
                _estimate(work),
            )
        )
    for k, light in enumerate(scene.lights):
        kind = light["type"]
        label = light.get("name") or f"light {k}"
        if kind == "directional":
            continue
        s = q["omni_samples"]
        faces = 6 * s
        work = {
            "raster_triangles": faces * tris,
            "pixels": faces * 256 * 256,
            "shadow_tests": faces * px,
        }
        if q["omni_method"] == "epr":
            work["splat_pairs"] = 2.0 * s * px
        out.append(
            Effect(
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
                    "radius": q["light_radius"] * diag,
                    "method": q["omni_method"],
                },
                _estimate(work),
            )
        )
    try:
        refl = reflectors_of(scene)
    except InputError:  # no object with a mirror material
        refl = []
    if refl:
        views = 6 * len(refl)
        work = {
            "splat_pairs": views * px * q["rho_scale"] ** 2 / 4,
            "raster_triangles": tris,
            "shading": 25 * px * 0.2,
        }
        out.append(
            Effect(
                "reflections",
                f"{len(refl)} reflective object(s)",
                "objects with mirror-like materials (metallic >= 0.9, roughness <= 0.1): "
                + ", ".join(r.name for r in refl[:5])
                + (" ..." if len(refl) > 5 else ""),
                {"reflectors": refl, "rho_scale": q["rho_scale"], "bounces": q["bounces"]},
                _estimate(work),
            )
        )
    return out


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
    tri = g.triangle[0]
    mask = tri >= 0
    base = g.color[0].astype(np.float64)
    pos = g.position[0].astype(np.float64)
    n = g.normal[0].astype(np.float64)
    eye = np.array(camera.eye)
    view = eye - pos
    # Normals toward the eye.
    n = np.where(((n * view).sum(-1) < 0)[..., None], -n, n)

    results: dict[str, Any] = {}
    stats_eff: dict[str, dict[str, float]] = {}
    visibility: dict[int, np.ndarray] = {}
    area_vis: dict[str, np.ndarray] = {}
    refl_result = None
    for e in chosen:
        t = time.perf_counter()
        if e.kind == "soft_shadows":
            r = soft_shadows(
                scene,
                camera,
                e.params["light"],
                samples=e.params["samples"],
                resolution=e.params["resolution"],
            )
            area_vis[e.source] = r.visibility
        elif e.kind in ("omni_shadows", "spot_shadows"):
            light = e.params["light"]
            r = omni_shadows(
                scene,
                camera,
                light["position"],
                e.params["radius"],
                light_samples=e.params["samples"],
                method=e.params["method"],
                seed=seed,
            )
            visibility[e.params["index"]] = r.visibility
        else:
            r = reflections(
                scene,
                camera,
                reflectors=e.params["reflectors"],
                rho_scale=e.params["rho_scale"],
                bounces=e.params["bounces"],
                seed=seed,
            )
            refl_result = r
        dt = time.perf_counter() - t
        timings[e.name] = dt
        results[e.name] = r
        stats_eff[e.name] = {"estimated_seconds": e.estimate["seconds"], "seconds": dt}

    t = time.perf_counter()
    diag = scene_diagonal(scene)
    lo, hi = scene.bounds.astype(np.float64)
    centre = (lo + hi) / 2
    light_sum = np.zeros(base.shape)
    lights = scene.lights
    for k, light in enumerate(lights):
        col = np.asarray(light.get("color", (1, 1, 1)), dtype=np.float64)
        if light["type"] == "directional":
            w = -np.asarray(light["direction"], dtype=np.float64)
            cos = np.clip((n * w).sum(-1), 0, None)
            light_sum += col * cos[..., None]
            continue
        lp = np.asarray(light["position"], dtype=np.float64)
        to = lp - pos
        d = np.linalg.norm(to, axis=-1)
        w = to / np.maximum(d, 1e-30)[..., None]
        cos = np.clip((n * w).sum(-1), 0, None)
        d0 = max(float(np.linalg.norm(lp - centre)), 1e-3 * diag)
        att = np.minimum((d0 / np.maximum(d, 1e-12)) ** 2, 16.0)
        if light["type"] == "spot":
            outer = light.get("outer_cone_angle") or np.pi / 4
            axis = np.asarray(light["direction"], dtype=np.float64)
            att = att * ((-w * axis).sum(-1) >= np.cos(outer))
        vis = visibility.get(k, np.ones(cos.shape))
        light_sum += col * (cos * att * vis)[..., None]
    areas = emissive_lights(scene) + [(f"area light {k}", a) for k, a in enumerate(area_lights)]
    for name, light in areas:
        to = np.asarray(light.center) - pos
        w = to / np.maximum(np.linalg.norm(to, axis=-1), 1e-30)[..., None]
        cos = np.clip((n * w).sum(-1), 0, None)
        vis = area_vis.get(name, np.ones(cos.shape))
        light_sum += (cos * vis)[..., None]
    if not lights and not areas:
        fwd = np.array(camera.forward)
        up = np.array([0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        w = -fwd + 0.5 * up + 0.3 * np.cross(fwd, up)
        w /= np.linalg.norm(w)
        light_sum += np.clip((n * w).sum(-1), 0, None)[..., None]
    image = base * (0.1 + light_sum)
    image[~mask] = 0.0
    if refl_result is not None:
        image[refl_result.reflective] = refl_result.image[refl_result.reflective]
    timings["compose"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - total
    # What this call ran: the sum of its effects' own counts (never process-wide differences,
    # which other calls running at the same time would pollute).
    stats: dict[str, Any] = {k: 0 for k in OPS}
    for r in results.values():
        for k in OPS:
            stats[k] += int(r.stats.get(k, 0))
    stats["effects_run"] = len(chosen)
    stats["reflectors"] = sum(
        len(e.params["reflectors"]) for e in chosen if e.kind == "reflections"
    )
    stats["lights"] = len(lights) + len(areas)
    stats["effects"] = stats_eff
    return Frame(
        image=image.astype(np.float32),
        effects=results,
        plan=chosen,
        mask=mask,
        stats=stats,
        timings=timings,
    )
