"""Result objects: small classes whose fields are numpy arrays, with ``as_dict()``."""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from . import _core
from ._scene import Scene
from .errors import InputError

__all__ = ["AllHits", "ClosestPoints", "DepthImages", "Mesh", "RayHits", "SurfaceSamples"]


@dataclass(eq=False, repr=False)
class DepthImages:
    """Depth images of a scene, one per camera (all cameras share a resolution).

    Attributes
    ----------
    depth : (n, H, W) float32
        Camera-space z (distance along the view axis, positive), ``+inf`` where no surface.
    triangle : (n, H, W) int32
        Scene face index of the surface at the pixel centre, -1 where no surface.
    normal : (n, H, W, 3) float32
        Unit world geometric normal of that triangle (from its winding, not flipped toward the
        camera); zero where no surface.
    shading_normal : (n, H, W, 3) float32
        Unit world shading normal: the vertices' normals (a glTF file's NORMAL, posed with the
        geometry by node transforms, skins and morph targets; OBJ's ``vn``; where a file has
        none, the area-weighted normals of the faces around each vertex) interpolated at the
        sample, as viewers shade; not flipped toward the camera; zero where no surface.
    position : (n, H, W, 3) float32
        World position of the surface point; NaN where no surface.
    color : (n, H, W, 3) float32
        Linear base colour, as viewers draw it unlit: the vertices' colours (material factor
        times COLOR_0) interpolated, times the material's base-colour texture sampled at the
        sample's texture coordinate (sRGB decoded; bilinear where magnified, trilinear between
        mip levels where minified, the level from the pixel's footprint by ray differentials;
        the sampler's wrap modes and ``KHR_texture_transform``); zero where no surface.
    cameras : list of Camera
        The camera of each image (for ``peeling``, the peeling camera, once per layer).
    method : str
        How the images were made: ``"conventional"``, ``"nonredundant"`` or ``"peeling"``.
    reference : list of Camera
        The reference viewpoints the set was made for (the cameras given to ``discretize``);
        ``evaluate`` interpolates its intermediate frames between them. Empty after
        :meth:`load_exr` for peeling layers (set it before evaluating).
    cull_backfaces : bool
        Whether back faces were culled (``evaluate`` renders its references the same way).
    backend : str
        ``"gpu"`` (raster) or ``"cpu"`` (ray cast); conventional images and peeling layers can
        come from either.
    backend_reason : str
        Why that backend ran: ``"requested"``, or the ``"auto"`` cost model's predictions.
    timings : dict of str to float
        Seconds per stage. From the CPU backend: ``bvh`` (building the scene's BVH, 0 when
        cached), ``trace`` (the pixel rays), ``edges`` (pixel centres on an edge decided by
        the raster's rule, with their rays), ``resolve``, ``ties`` (peeling) and ``total``.
        From the GPU: ``device`` (creating the GPU device, first call only), ``upload``
        (scene to GPU, 0 when cached), ``prepare`` (per-triangle resolve data, 0 when cached
        on the scene), ``raster`` (CPU time spent submitting and waiting for the GPU),
        ``raster_gpu`` (GPU timestamps, when the adapter has them), ``readback``,
        ``resolve`` (depth, position, normal and colour from each pixel's triangle id, by
        intersecting the pixel-centre ray with that triangle in float64) and ``total``.
        Images are processed in chunks and one chunk's resolve overlaps the next chunk's
        raster, so the stages can add up to more than ``total``.
    """

    depth: np.ndarray
    triangle: np.ndarray
    normal: np.ndarray
    shading_normal: np.ndarray
    position: np.ndarray
    color: np.ndarray
    cameras: list[Any]
    timings: dict[str, float] = field(default_factory=dict)
    method: str = "conventional"
    reference: list[Any] = field(default_factory=list)
    cull_backfaces: bool = False
    backend: str = "gpu"
    backend_reason: str = ""

    @classmethod
    def _from_core(cls, d: dict[str, Any], reference: list[Any], cull: bool) -> DepthImages:
        return cls(**d, reference=list(reference), cull_backfaces=cull)

    @property
    def n(self) -> int:
        """Number of images."""
        return int(self.depth.shape[0])

    @property
    def height(self) -> int:
        """Image height H in pixels."""
        return int(self.depth.shape[1])

    @property
    def width(self) -> int:
        """Image width W in pixels."""
        return int(self.depth.shape[2])

    @property
    def mask(self) -> np.ndarray:
        """(n, H, W) bool: pixels that see a surface."""
        return self.triangle >= 0

    def __len__(self) -> int:
        return self.n

    def as_dict(self) -> dict[str, Any]:
        """Every field by name (arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def save_exr(self, path: str | os.PathLike[str]) -> None:
        """Write all images to one multi-part EXR file, one part per image (``view0``, ...).

        Channels: ``Z`` (depth), ``triangle`` (uint32 holding the int32 bits: -1 is
        0xFFFFFFFF), ``N.X N.Y N.Z`` (normal), ``S.X S.Y S.Z`` (shading normal), ``P.X P.Y
        P.Z``, ``R G B``; each part carries its camera
        as JSON in the ``scenesample.camera`` attribute. ZIP compression, so
        :meth:`load_exr` returns every array bit for bit.
        """
        n, h, w = self.depth.shape
        shapes = {
            "triangle": (n, h, w),
            "normal": (n, h, w, 3),
            "shading_normal": (n, h, w, 3),
            "position": (n, h, w, 3),
            "color": (n, h, w, 3),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise InputError(f"{name} has shape {getattr(self, name).shape}, expected {shape}")
        if len(self.cameras) != n:
            raise InputError(f"{len(self.cameras)} cameras for {n} images")
        _core.write_exr(
            os.fspath(path),
            w,
            h,
            np.ascontiguousarray(self.depth, dtype=np.float32).reshape(-1, 1),
            np.ascontiguousarray(self.triangle, dtype=np.int32).reshape(-1),
            np.ascontiguousarray(self.normal, dtype=np.float32).reshape(-1, 3),
            np.ascontiguousarray(self.shading_normal, dtype=np.float32).reshape(-1, 3),
            np.ascontiguousarray(self.position, dtype=np.float32).reshape(-1, 3),
            np.ascontiguousarray(self.color, dtype=np.float32).reshape(-1, 3),
            list(self.cameras),
            str(self.method),
        )

    @classmethod
    def load_exr(cls, path: str | os.PathLike[str]) -> DepthImages:
        """Read a file written by :meth:`save_exr` (timings are empty)."""
        d = _core.read_exr(os.fspath(path))
        d["timings"] = {}
        reference = [] if d["method"] == "peeling" else list(d["cameras"])
        return cls(**d, reference=reference)

    def __repr__(self) -> str:
        covered = float(self.mask.mean()) if self.depth.size else 0.0
        total = self.timings.get("total", float("nan"))
        size = f"{self.width}x{self.height}"
        return (
            f"DepthImages({self.method}, n={self.n}, {size}, covered={covered:.1%}, "
            f"total={total:.4f}s)"
        )


@dataclass(eq=False, repr=False)
class RayHits:
    """Hits of a batch of rays (see :func:`scenesample.cast_rays`), shaped like the rays:
    ``...`` below is the batch shape the origins and directions broadcast to.

    Attributes
    ----------
    t : (...) float32, or (..., k) with ``max_hits=k > 1``
        Hit distance in units of each direction's length; ``+inf`` on a miss (and past the
        last hit of a ray with fewer than k).
    triangle : (...) or (..., k) int32
        Scene face index; -1 on a miss.
    barycentric : (..., 2) or (..., k, 2) float32
        (u, v) with hit point = (1-u-v)*v0 + u*v1 + v*v2 (Embree's convention); 0 on a miss.
    timings : dict of str to float
        ``bvh_build`` (0 when the scene's BVH was cached) and ``trace`` seconds.
    max_hits : int
        k: 1 for the closest hit (no hit axis), else the length of the hit axis.
    """

    t: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)
    max_hits: int = 1

    @property
    def shape(self) -> tuple[int, ...]:
        """The batch shape: one entry per ray."""
        return self.t.shape if self.max_hits == 1 else self.t.shape[:-1]

    @property
    def hit(self) -> np.ndarray:
        """(...) bool: rays that hit a triangle."""
        first = self.triangle if self.max_hits == 1 else self.triangle[..., 0]
        return first >= 0

    @property
    def count(self) -> np.ndarray:
        """(...) int: hits reported per ray (at most 1, or k with ``max_hits=k``)."""
        per_ray = self.triangle.reshape((*self.shape, -1))
        return (per_ray >= 0).sum(axis=-1)

    def __len__(self) -> int:
        """The number of rays."""
        return int(np.prod(self.shape, dtype=np.int64))

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def __repr__(self) -> str:
        trace = self.timings.get("trace", float("nan"))
        return f"RayHits(shape={self.shape}, hit={int(self.hit.sum())}, trace={trace:.4f}s)"


@dataclass(eq=False, repr=False)
class AllHits:
    """Every hit of a batch of rays (see :func:`scenesample.all_hits`), ragged: ray ``i`` (in
    C order over the batch) has the hits ``ray_splits[i]:ray_splits[i + 1]``, nearest first.

    Attributes
    ----------
    ray_splits : (N + 1,) int64
        Offsets of each ray's hits; ``np.diff(ray_splits)`` is each ray's count.
    t : (H,) float32
        Hit distances in units of the ray's direction.
    triangle : (H,) int32
        Scene face index of each hit.
    barycentric : (H, 2) float32
        (u, v) of each hit (Embree's convention).
    shape : tuple of int
        The rays' batch shape (N is its product).
    timings : dict of str to float
        ``bvh_build`` and ``trace`` seconds.
    """

    ray_splits: np.ndarray
    t: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    shape: tuple[int, ...] = ()
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def ray_ids(self) -> np.ndarray:
        """(H,) int64: the (flat) ray of each hit."""
        return np.repeat(np.arange(len(self.ray_splits) - 1), np.diff(self.ray_splits))

    @property
    def count(self) -> np.ndarray:
        """(...) int64: hits per ray, in the rays' batch shape."""
        return np.diff(self.ray_splits).reshape(self.shape)

    def __len__(self) -> int:
        """The number of hits."""
        return int(self.t.shape[0])

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def __repr__(self) -> str:
        return f"AllHits(shape={self.shape}, hits={len(self)})"


@dataclass(eq=False, repr=False)
class SurfaceSamples:
    """What the surface is where samples meet it (see :func:`scenesample.surface_attributes`),
    in the samples' shape ``...``.

    Attributes
    ----------
    texcoord : (..., 2) float32
        Texture coordinates as the file has them (the set the material's base-colour texture
        reads; before its ``KHR_texture_transform``); NaN where the sample sees nothing or the
        scene has no texture coordinates.
    color : (..., 3) float32
        Linear base colour: the vertices' colours interpolated times the material's texture
        there (sRGB decoded, filtered over the footprint); zero where nothing.
    shading_normal : (..., 3) float32
        Unit shading normal (the vertices' normals interpolated, as viewers shade; not turned
        toward the ray); zero where nothing.
    normal : (..., 3) float32
        Unit geometric normal of the triangle (from its winding); zero where nothing.
    """

    texcoord: np.ndarray
    color: np.ndarray
    shading_normal: np.ndarray
    normal: np.ndarray

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def __repr__(self) -> str:
        return f"SurfaceSamples(shape={self.color.shape[:-1]})"


@dataclass(eq=False, repr=False)
class ClosestPoints:
    """The closest surface point of each query point (see :func:`scenesample.closest_points`),
    in the points' batch shape ``...``.

    Attributes
    ----------
    point : (..., 3) float32
        The closest point of the scene's surface; NaN where none lies within ``max_distance``.
    distance : (...) float32
        Its distance (computed in float64); ``+inf`` where none lies within ``max_distance``.
    triangle : (...) int32
        The face it lies on (the smaller id where faces tie); -1 where none.
    barycentric : (..., 2) float32
        (u, v) on that face, point = (1-u-v)*v0 + u*v1 + v*v2; 0 where none.
    timings : dict of str to float
        ``bvh_build`` (0 when the scene's BVH was cached) and ``query`` seconds.
    """

    point: np.ndarray
    distance: np.ndarray
    triangle: np.ndarray
    barycentric: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def __repr__(self) -> str:
        q = self.timings.get("query", float("nan"))
        return f"ClosestPoints(shape={self.distance.shape}, query={q:.4f}s)"


@dataclass(eq=False, repr=False)
class Mesh:
    """A surface rebuilt from samples by :func:`scenesample.reconstruct`.

    Attributes
    ----------
    vertices : (V, 3) float32
        World positions.
    faces : (F, 3) uint32
        Vertex indices, counter-clockwise as seen from the camera of the face's sample.
    sample : (F,) int64
        Flat index (image * H * W + row * W + column) of the sample each face came from.
    method : str
        ``"mesh"``, ``"hybrid"`` or ``"points"``.
    timings : dict of str to float
        Seconds: ``offset`` (rendering the offset images, hybrid only) and the method's step.
    """

    vertices: np.ndarray
    faces: np.ndarray
    sample: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)
    method: str = "hybrid"

    def __len__(self) -> int:
        return int(self.faces.shape[0])

    def __repr__(self) -> str:
        return f"Mesh({self.method}, {len(self.vertices):,} vertices, {len(self.faces):,} faces)"

    @property
    def area(self) -> float:
        """Total area of the faces (float64)."""
        v = self.vertices.astype(np.float64)
        a, b, c = (v[self.faces[:, k]] for k in range(3))
        return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())

    def as_dict(self) -> dict[str, Any]:
        """Every field by name (arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def to_trimesh(self) -> Any:
        """A ``trimesh.Trimesh`` of the faces (vertices not merged, nothing removed)."""
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)

    def to_scene(self) -> Any:
        """The mesh as a :class:`scenesample.Scene` (to render, ray cast or evaluate it)."""
        return Scene.from_arrays(self.vertices, self.faces)
