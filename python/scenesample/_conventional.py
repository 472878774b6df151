"""Conventional depth images, one per camera: the baseline of non-redundant-rendering.txt §3,
and the reference every room compares with (the image floor; Rust: ``src/image/``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal, Union

from . import _core
from ._scene import Scene, core_of
from .errors import InputError
from .results import DepthImages

Camera = _core.Camera


def camera_list(cameras: Union[Camera, Sequence[Camera]]) -> list[Camera]:
    cams = [cameras] if isinstance(cameras, Camera) else list(cameras)
    for i, c in enumerate(cams):
        if not isinstance(c, Camera):
            raise InputError(f"cameras[{i}] must be a scenesample.Camera, got {type(c).__name__}")
    if not cams:
        raise InputError("discretize needs at least one camera")
    return cams


def _images(d: Any, scene: Scene, cams: list[Camera], cull: bool, method: str, redundancy: str):
    images = DepthImages._from_core(d, cams, cull)
    # Provenance, so that ``reconstruct(images, "hybrid")`` can render the offset images.
    images._source = (scene, method, redundancy)
    return images


def conventional(
    scene: Scene,
    cameras: Union[Camera, Sequence[Camera]],
    *,
    cull_backfaces: bool = False,
    backend: Literal["auto", "gpu", "cpu"] = "auto",
) -> DepthImages:
    """One depth image per camera, each sampling every surface it sees
    (non-redundant-rendering.txt §6.1, the baseline): the nearest surface at each pixel centre,
    no multisampling, either rasterized on the GPU or ray-cast on the CPU.

    Parameters
    ----------
    scene : Scene
    cameras : Camera or sequence of Camera
        Poses and projections may differ; resolutions must match.
    cull_backfaces : bool
        Drop triangles whose counter-clockwise front faces away (off by default).
    backend : {"auto", "gpu", "cpu"}
        ``"gpu"``: one raster pass per image (Vulkan; Mesa's software driver without a GPU).
        ``"cpu"``: the pixel-centre rays cast through the scene's BVH on all cores (built
        once per scene, then cached), from the near plane on; the same fields, dtypes and
        conventions, resolved by the same float64 code, so depths agree with the GPU's to
        float32 rounding. Where a pixel centre lies within 1/64 pixel of an edge, the pixel is
        decided as the rasteriser decides it (vertices snapped to 1/256 pixel, the top-left
        fill rule; candidates from rays just across the edge), so triangle ids match the
        GPU's there too, and may differ from ``cast_rays`` on those pixels; they still differ
        from the GPU's where its own float32 transform rounds a vertex to the neighbouring
        grid point, or where two surfaces meet at one depth (99.99% of the pixels agree on
        the shared scenes, 99.988% on a 4M-triangle tiling).
        ``"auto"`` (default): the backend a cost model of this machine predicts is faster for
        the triangles, pixels and images (as if the scene's BVH and GPU copy existed, so the
        choice does not depend on what ran before), where a GPU adapter exists; images wider
        or taller than the GPU's largest texture go to the CPU. The model is measured once per
        machine (about half a second of probes, by the first process that needs it, under a
        file lock) and kept in a calibration file, ``$SCENESAMPLE_CACHE_DIR`` or
        ``~/.cache/scenesample/cost-model.json``; every process uses what that file holds, and
        none decides from its own timings. With ``SCENESAMPLE_CACHE_DIR=""`` (or a cache that
        cannot be written) a built-in model for the adapter's kind is used instead. So the same
        call gives the same images in every process on a machine; across machines, the two
        backends' ids differ at a few edge pixels, so pass the backend explicitly where
        results must match bit for bit across machines. See :func:`scenesample.device_info`.

    Returns
    -------
    DepthImages
        ``backend`` and ``backend_reason`` say which backend ran and why.
        ``depth`` (n, H, W) float32 camera-space z (+inf empty), ``triangle`` (n, H, W) int32
        (-1 empty), ``normal``/``position``/``color`` (n, H, W, 3) float32, ``cameras``,
        ``method``, ``reference`` (= ``cameras``), ``timings``; n is ``len(cameras)``.

        At the edges: a camera inside a closed mesh sees its inside on every pixel; with an
        explicit ``znear`` that cuts through the scene each pixel holds the nearest surface at
        or beyond the near plane (``cast_rays(t_min=znear)`` along camera-z directions gives
        the same); a triangle far smaller than a pixel's footprint appears only where it covers
        a pixel centre; triangle ids stay exact past 2^24 (int32 up to 2^31 - 1).

    Raises
    ------
    GpuUnavailableError
        ``backend="gpu"`` without a GPU adapter (install ``mesa-vulkan-drivers`` for a
        software one); ``"auto"`` falls back to the CPU instead.
    GpuLimitError
        ``backend="gpu"`` and images beyond the device's texture or buffer limits.
    InputError
        No camera, cameras of different resolutions, an unknown backend.
    """
    cams, cull = camera_list(cameras), bool(cull_backfaces)
    d = _core.discretize_conventional(core_of(scene), cams, cull, backend)
    return _images(d, scene, cams, cull, "conventional", "pixel")
