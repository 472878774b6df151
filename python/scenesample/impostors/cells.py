"""Multi-cell orthographic impostors (multi-cell-orthographic-impostors.txt): octree cells
imaged from the faces of a subdivided icosahedron, drawn at runtime as billboards beyond a
triangle budget."""

from __future__ import annotations

import math
import os
import zlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields
from typing import Any, Optional

import numpy as np

from .. import _core
from .._progress import Bar, Progress
from .._scene import Scene
from ..errors import InputError, check_integer
from ..imageio import linear_to_srgb

__all__ = ["Impostors", "ImpostorView", "PROJECTIONS"]

Camera = _core.Camera
PROJECTIONS = ("orthographic", "perspective")
CELL_DTYPE = np.dtype(
    [
        ("lo", "<f8", (3,)),
        ("hi", "<f8", (3,)),
        ("center", "<f8", (3,)),
        ("radius", "<f8"),
        ("index", "<i4", (3,)),
    ]
)
# Codes of ImpostorView.used.
CULLED, TRIANGLES = -2, -1


@dataclass(eq=False, repr=False)
class Impostors:
    """Per non-empty octree cell, images of it from every icosahedron direction.

    Attributes
    ----------
    cells : (C,) structured array
        ``lo``, ``hi`` (the cell's box), ``center``, ``radius`` (of the circumscribed sphere,
        the images' extent), ``index`` (leaf coordinates), all float64 but ``index`` int32.
    directions : (D, 3) float64
        Unit directions to the faces of the subdivided icosahedron (20 * 4**subdivisions); image
        (c, k) looks at cell c along ``-directions[k]``.
    color : (C, D, h, w, 4) uint8
        Lit linear RGB and alpha (255 where covered) of each image, cropped to its content and
        stored at the top left; h, w are the largest crop.
    depth : (C, D, h, w) float32
        Camera-space depth of each texel in its image's camera, +inf where empty.
    crops : (C, D, 4) int32
        Each image's crop rectangle in the full ``resolution``² image: x0, y0, width, height
        (all 0 for an empty image).
    triangle_counts : (C,) int64
        Triangles in each cell's images (with ``grow``, those intersecting its sphere).
    cell_triangles : tuple of ((C + 1,) uint32 offsets, (F,) uint32 triangle ids)
        The triangles that draw each cell as geometry (each triangle in the cell of its
        centroid), CSR.
    resolution, projection, fov, grow, octree_depth
        The settings used.
    stats : dict
        ``cells``, ``views`` (D), ``rays``, ``bytes_raw`` (the cropped texels: 4 bytes of
        colour and 4 of depth each) and ``bytes_compressed`` (those bytes deflated, zlib level
        6, one stream per cell; the paper reports ~18%).
    timings : dict of str to float
        Seconds: ``cells`` (octree), ``render`` (ray casting the images), ``crop``,
        ``compress``, ``total``.
    """

    cells: np.ndarray
    directions: np.ndarray
    color: np.ndarray
    depth: np.ndarray
    crops: np.ndarray
    triangle_counts: np.ndarray
    cell_triangles: tuple[np.ndarray, np.ndarray]
    resolution: int
    projection: str
    fov: Optional[float]
    grow: bool
    octree_depth: int
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    _handle: Any = None
    _scene: Optional[Scene] = None

    def __repr__(self) -> str:
        return (
            f"Impostors({len(self.cells)} cells x {len(self.directions)} {self.projection} "
            f"views of {self.resolution}^2)"
        )

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if not f.name.startswith("_")}


@dataclass(eq=False, repr=False)
class ImpostorView:
    """A view drawn from impostors and triangles.

    Attributes
    ----------
    color : (H, W, 3) float32
        Linear RGB, black where nothing is drawn.
    depth : (H, W) float32
        Camera-space depth (a billboard's is its plane's), +inf where nothing is drawn.
    used : (C,) int32
        Per cell: -2 culled, -1 drawn as triangles, otherwise the impostor direction index.
    camera : Camera
    stats : dict
        ``cells_culled``, ``cells_triangles``, ``cells_impostors``, ``triangles_drawn``,
        ``billboard_pixels``.
    timings : dict of str to float
        Seconds: ``cull`` (frustum culling and the sort), ``triangles`` (GPU), ``impostors``
        (billboards, CPU), ``total``.
    """

    color: np.ndarray
    depth: np.ndarray
    used: np.ndarray
    camera: Any
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    @classmethod
    def of_triangles(cls, scene: Scene, camera: Camera) -> ImpostorView:
        """Every triangle of ``scene`` from ``camera``, lit as impostors are: the reference
        the paper measures against."""
        if not isinstance(scene, Scene):
            raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
        if not isinstance(camera, Camera):
            raise InputError(f"camera must be a scenesample.Camera, got {type(camera).__name__}")
        d = _core.render_lit(scene._core, camera)
        return cls(
            color=d["color"],
            depth=d["depth"],
            used=np.zeros(0, dtype=np.int32),
            camera=camera,
            stats={"triangles_drawn": scene.triangle_count},
            timings={"triangles": d["seconds"], "total": d["seconds"]},
        )

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: pixels where something is drawn."""
        return np.isfinite(self.depth)

    def to_srgb8(self) -> np.ndarray:
        """(H, W, 3) uint8 for display."""
        return linear_to_srgb(self.color)

    def __repr__(self) -> str:
        h, w = self.depth.shape
        return f"ImpostorView({w}x{h}, {self.stats})"

    def as_dict(self) -> dict[str, Any]:
        """Every field by name, as a dict (the arrays are not copied)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def impostors(
    scene: Scene,
    *,
    octree_depth: int = 4,
    subdivisions: int = 2,
    resolution: int = 128,
    projection: str = "orthographic",
    fov: Optional[float] = None,
    grow: bool = True,
    progress: Progress = None,
) -> Impostors:
    """Multi-cell orthographic impostors (multi-cell-orthographic-impostors.txt §3.1): per
    non-empty octree cell and icosahedron direction, a ``resolution``² image of the cell
    ray-cast on the CPU through a BVH of the cell's triangles, lit view-independently (base
    colour x (0.3 + 0.7 |n . L|), L fixed), cropped to its content.

    Parameters
    ----------
    scene : Scene
    octree_depth : int
        Octree levels below the root: leaves are 2**octree_depth per axis of the cubic bounds
        (empty ones skipped); 0 is a single cell.
    subdivisions : int
        Icosahedron subdivisions: 20 * 4**s views per cell (320 for 2).
    resolution : int
        Image side in pixels (default 128).
    projection : {"orthographic", "perspective"}
        The paper's orthographic images, or perspective ones (camera at radius / sin(fov / 2)).
    fov : float, optional
        For ``"perspective"``: the field of view in radians.
    grow : bool
        Cell growing (§4.3): each cell's images show every triangle that intersects its bounding
        sphere; without it only the geometry inside the cell, rays clipped to its box.
    progress : bool, callable or None
        A tqdm bar over the cells (see :func:`visibility_field`).

    Returns
    -------
    Impostors
    """
    import time

    if not isinstance(scene, Scene):
        raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
    if projection not in PROJECTIONS:
        raise InputError(f"projection must be one of {list(PROJECTIONS)}, got {projection!r}")
    if fov is not None:
        try:
            fov = float(fov)
        except (TypeError, ValueError):
            raise InputError(f"fov must be a number of radians, got {fov!r}") from None
        if not (0 < fov < math.pi):
            raise InputError(f"fov must be in (0, pi) radians, got {fov!r}")
    start = time.perf_counter()
    with Bar(progress, "impostors", "cells") as bar:
        handle, d = _core.impostors(
            scene._core,
            check_integer("octree_depth", octree_depth, 0),
            check_integer("subdivisions", subdivisions, 0),
            check_integer("resolution", resolution),
            projection,
            fov,
            bool(grow),
            bar.callback,
        )
    c = len(d["size"])
    cells = np.zeros(c, dtype=CELL_DTYPE)
    cells["lo"] = d["lo"]
    cells["hi"] = d["lo"] + d["size"][:, None]
    cells["center"] = d["lo"] + d["size"][:, None] / 2
    cells["radius"] = d["size"] * math.sqrt(3) / 2
    cells["index"] = d["index"]
    crops = d["crops"].astype(np.int32)
    t = time.perf_counter()
    raw, packed = _storage(d["color"], d["depth"], crops)
    timings = dict(d["timings"])
    timings["compress"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - start
    return Impostors(
        cells=cells,
        directions=d["directions"],
        color=d["color"],
        depth=d["depth"],
        crops=crops,
        triangle_counts=d["triangle_counts"].astype(np.int64),
        cell_triangles=(d["offsets"], d["triangles"]),
        resolution=int(resolution),
        projection=projection,
        fov=fov,
        grow=bool(grow),
        octree_depth=int(octree_depth),
        stats={
            "cells": c,
            "views": len(d["directions"]),
            "rays": int(d["rays"]),
            "bytes_raw": raw,
            "bytes_compressed": packed,
        },
        timings=timings,
        _handle=handle,
        _scene=scene,
    )


def _storage(color: np.ndarray, depth: np.ndarray, crops: np.ndarray) -> tuple[int, int]:
    """Bytes of the cropped images (colour then depth, image after image) and their deflated
    size: each cell's images deflated together as one zlib stream (level 6), as the paper
    stores and compresses a cell's images (§5), the cells on every core (zlib lets go of the
    GIL while it deflates). The sizes add up in cell order, so the answer does not depend on
    how the threads ran."""
    crops = np.ascontiguousarray(crops)

    def cell(i: int) -> tuple[int, int]:
        data = b"".join(
            color[i, k, :h, :w].tobytes() + depth[i, k, :h, :w].tobytes()
            for k, (w, h) in enumerate(crops[i, :, 2:4].tolist())
            if w
        )
        return len(data), len(zlib.compress(data, 6))

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    workers = max(1, min(len(crops), cores or 1))
    pool = ThreadPoolExecutor(workers)
    try:
        sizes = list(pool.map(cell, range(len(crops))))
    finally:
        # On Ctrl-C, the cells not started are dropped rather than deflated first.
        pool.shutdown(wait=True, cancel_futures=True)
    return sum(r for r, _ in sizes), sum(z for _, z in sizes)


def impostor_view(
    imp: Impostors,
    camera: Camera,
    *,
    triangle_budget: Optional[int] = 0,
    scene: Optional[Scene] = None,
    screen_threshold: float = 0.0,
) -> ImpostorView:
    """Draw ``camera``'s view from impostors (multi-cell-orthographic-impostors.txt §3.2).

    Cells whose sphere (and triangles) lie outside the view are culled; the rest, nearest
    first, are drawn as triangles (GPU, lit like the impostors) while their triangles fit in
    ``triangle_budget`` and their sphere spans at least ``screen_threshold`` pixels; every other
    cell as the impostor whose direction makes the smallest angle with the direction from the
    cell to the eye, a billboard through the cell's centre, depth-tested, with no per-pixel
    correction.

    Parameters
    ----------
    imp : Impostors
    camera : Camera
    triangle_budget : int, optional
        Triangles that may be drawn as geometry (0: none; ``None``: no limit). Needs ``scene``
        when not 0.
    scene : Scene, optional
        The scene the impostors were built from, for the cells drawn as triangles.
    screen_threshold : float
        Smallest projected sphere diameter, in pixels, of a cell drawn as triangles.

    Returns
    -------
    ImpostorView
    """
    if not isinstance(camera, Camera):
        raise InputError(f"camera must be a scenesample.Camera, got {type(camera).__name__}")
    budget: Optional[int]
    if triangle_budget is None or (
        isinstance(triangle_budget, float) and math.isinf(triangle_budget)
    ):
        budget = None
    else:
        budget = check_integer("triangle_budget", triangle_budget, 0)
    if budget != 0:
        if scene is None:
            raise InputError(
                "a triangle budget needs scene= (the scene the impostors were made from)"
            )
        if scene is not imp._scene and scene.triangle_count != len(imp.cell_triangles[1]):
            raise InputError("scene is not the one the impostors were made from")
    try:
        threshold = float(screen_threshold)
    except (TypeError, ValueError):
        raise InputError(f"screen_threshold must be a number, got {screen_threshold!r}") from None
    d = _core.impostor_view(imp._handle, camera, budget, budget != 0, threshold)
    return ImpostorView(
        color=d["color"],
        depth=d["depth"],
        used=d["used"],
        camera=camera,
        stats={k: int(v) for k, v in d["stats"].items()},
        timings=dict(d["timings"]),
    )
