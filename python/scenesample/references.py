"""Adapters to the tools users cross-check against: pyrender (OpenGL raster, depth and unlit
colour), trimesh (a file's own normals), raw Embree
(through embreex) and Open3D's ``RaycastingScene`` (Embree on every core). Tests and
``scenesample.bench`` use these, so each tool's quirks are handled in exactly one place. All are
optional dependencies (``pip install scenesample[test]``).

Quirks handled here:

- pyrender needs ``np.infty`` (removed in numpy 2) and ``PYOPENGL_PLATFORM=egl`` headless.
- pyrender returns camera-space z with 0 for background: mapped to ``+inf``.
- pyrender resolves depth from a 4x multisampled buffer with a NEAREST blit, i.e. from one
  sub-sample rather than the pixel centre; ``multisample=False`` makes its buffers single-sample
  so it samples pixel centres like scenesample.
- pyrender's ``DEPTH_ONLY`` pass culls back faces even with ``SKIP_CULL_FACES``: every triangle
  is given to it in both windings.
- pyrender computes ``view @ model @ p`` in float32 on the GPU; for scenes far from the origin it
  is given vertices and camera relative to ``origin`` (computed in float64), so it renders
  exactly the same float32 geometry without losing precision to the offset.
- Embree (via trimesh) rescales rays; the raw ``EmbreeScene.run`` does not. It builds its BVH
  lazily, on the first ``run``; it always starts rays at ``t = 0`` (no ``t_min``); its occlusion
  query answers 0 for occluded and -1 for free.
- Open3D reports misses with the id ``2**32 - 1`` (uint32), takes rays as one (N, 6) tensor, and
  also builds lazily. Importing it needs the Debian package ``libusb-1.0-0``.
- Embree's memory is read from its own memory monitor (``rtcSetDeviceMemoryMonitorFunction``),
  called through ctypes on the library embreex ships.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from typing import Any, Optional

import numpy as np

from ._core import Camera
from ._scene import Scene

__all__ = [
    "PyrenderReference",
    "FileNormals",
    "pyrender_depth",
    "pyrender_unlit",
    "EmbreeReference",
    "Open3DReference",
    "embree_memory",
]


def _import_pyrender() -> Any:
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    if not hasattr(np, "infty"):
        # Through setattr: ruff's numpy-2 fix rewrites the attribute spelled out (NPY201),
        # which once turned this shim into `np.inf = np.inf`, a no-op.
        setattr(np, "infty", np.inf)  # noqa: B010
    import pyrender

    return pyrender


@contextlib.contextmanager
def _single_sample(pyrender: Any) -> Iterator[None]:
    """Make pyrender's 'multisample' renderbuffers single-sample while it creates them."""
    from OpenGL import GL

    module = pyrender.renderer
    original = module.glRenderbufferStorageMultisample

    def storage(target: int, _samples: int, fmt: int, w: int, h: int) -> None:
        GL.glRenderbufferStorageMultisample(target, 0, fmt, w, h)

    module.glRenderbufferStorageMultisample = storage
    try:
        yield
    finally:
        module.glRenderbufferStorageMultisample = original


def _clip_planes(cam: Camera, bounds: np.ndarray) -> tuple[float, float]:
    corners = np.array(
        [
            [bounds[i, 0], bounds[j, 1], bounds[k, 2]]
            for i in (0, 1)
            for j in (0, 1)
            for k in (0, 1)
        ],
        dtype=np.float64,
    )
    _, z = cam.project(corners)
    zfar = float(z.max()) * 1.05
    znear = max(float(z.min()) * 0.95, zfar * 1e-4)
    return znear, zfar


class PyrenderReference:
    """A pyrender offscreen renderer set up once for a scene, rendering depth for any cameras of
    one resolution (perspective only).

    Parameters
    ----------
    scene : Scene
    width, height : int
    multisample : bool
        Keep pyrender's 4x multisampled buffers (its default) instead of sampling pixel centres.
    origin : 3 floats, optional
        Render relative to this point (default: the scene's bounds centre), see module notes.
    """

    def __init__(
        self,
        scene: Scene,
        width: int,
        height: int,
        *,
        multisample: bool = False,
        origin: Optional[Sequence[float]] = None,
    ) -> None:
        self._pr = _import_pyrender()
        self._bounds = scene.bounds.astype(np.float64)
        self._origin = np.asarray(
            origin if origin is not None else self._bounds.mean(axis=0), dtype=np.float64
        )
        verts = (scene.vertices.astype(np.float64) - self._origin).astype(np.float32)
        faces = scene.faces.astype(np.int64)
        prim = self._pr.Primitive(
            positions=verts, indices=np.concatenate([faces, faces[:, ::-1]]), mode=4
        )
        self._scene = self._pr.Scene()
        self._scene.add(self._pr.Mesh([prim]))
        self._camera = self._pr.PerspectiveCamera(
            yfov=1.0, aspectRatio=width / height, znear=0.1, zfar=1.0
        )
        self._node = self._scene.add(self._camera, pose=np.eye(4))
        self._size = (width, height)
        self._single = None if multisample else _single_sample(self._pr)
        if self._single is not None:
            # pyrender creates its framebuffers lazily in render(): the patch stays on until close.
            self._single.__enter__()
        self._renderer = self._pr.OffscreenRenderer(width, height)

    def depth(self, cameras: Sequence[Camera]) -> np.ndarray:
        """(n, H, W) float32 camera-space z, ``+inf`` where no surface."""
        w, h = self._size
        out = np.zeros((len(cameras), h, w), dtype=np.float32)
        flags = self._pr.RenderFlags.DEPTH_ONLY | self._pr.RenderFlags.SKIP_CULL_FACES
        for i, cam in enumerate(cameras):
            if (cam.width, cam.height) != (w, h) or cam.yfov is None:
                raise ValueError(
                    "PyrenderReference renders perspective cameras of its own resolution"
                )
            self._camera.znear, self._camera.zfar = _clip_planes(cam, self._bounds)
            self._camera.yfov = cam.yfov
            pose = np.array(cam.pose, dtype=np.float64)
            pose[:3, 3] -= self._origin
            self._scene.set_pose(self._node, pose)
            depth = self._renderer.render(self._scene, flags=flags)
            out[i] = np.where(depth > 0, depth, np.inf)
        return out

    def close(self) -> None:
        self._renderer.delete()
        if self._single is not None:
            self._single.__exit__(None, None, None)
            self._single = None

    def __enter__(self) -> PyrenderReference:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def pyrender_depth(
    scene: Scene,
    cameras: Sequence[Camera],
    *,
    multisample: bool = False,
    origin: Optional[Sequence[float]] = None,
) -> np.ndarray:
    """Depth images rendered by pyrender (EGL) in scenesample's convention: (n, H, W) float32
    camera-space z, ``+inf`` where no surface. See :class:`PyrenderReference`."""
    with PyrenderReference(
        scene, cameras[0].width, cameras[0].height, multisample=multisample, origin=origin
    ) as r:
        return r.depth(cameras)


def pyrender_unlit(path: Any, cameras: Sequence[Camera]) -> tuple[np.ndarray, np.ndarray]:
    """What pyrender draws of the file at ``path`` (read by trimesh, as pyrender's users do),
    unlit (``RenderFlags.FLAT``: each pixel the material's base colour factor times its
    texture, as glTF viewers sample it), single-sampled at pixel centres, both sides of every
    face: ((n, H, W, 3) uint8 sRGB colour, (n, H, W) bool coverage) per perspective camera of
    one resolution. Its clip planes come from the file's bounds, widened; a scene that far
    from the origin loses float32 precision in pyrender, not here."""
    pr = _import_pyrender()
    import trimesh

    loaded = trimesh.load(str(path), force="scene")
    scene = pr.Scene.from_trimesh_scene(loaded, ambient_light=np.ones(3))
    bounds = np.asarray(loaded.bounds, dtype=np.float64)
    w, h = cameras[0].width, cameras[0].height
    node = scene.add(pr.PerspectiveCamera(yfov=1.0, aspectRatio=w / h), pose=np.eye(4))
    colors = np.zeros((len(cameras), h, w, 3), np.uint8)
    covered = np.zeros((len(cameras), h, w), bool)
    flags = pr.RenderFlags.FLAT | pr.RenderFlags.SKIP_CULL_FACES
    with _single_sample(pr):
        renderer = pr.OffscreenRenderer(w, h)
        try:
            for i, cam in enumerate(cameras):
                if (cam.width, cam.height) != (w, h) or cam.yfov is None:
                    raise ValueError("pyrender_unlit renders perspective cameras of one size")
                node.camera.yfov = cam.yfov
                node.camera.znear, node.camera.zfar = _clip_planes(cam, bounds)
                scene.set_pose(node, np.asarray(cam.pose, dtype=np.float64))
                color, depth = renderer.render(scene, flags=flags)
                colors[i] = color[..., :3]
                covered[i] = depth > 0
        finally:
            renderer.delete()
    return colors, covered


class FileNormals:
    """The normals a file gives its vertices, read by trimesh (``process=False``: NORMAL as
    stored), placed in world space by the inverse transpose of each node's transform, and
    interpolated at surface points: an independent reading of what scenesample's
    ``shading_normal`` should be."""

    def __init__(self, path: Any) -> None:
        import trimesh

        loaded = trimesh.load(str(path), force="scene", process=False)
        vertices, faces, normals, offset = [], [], [], 0
        for name in loaded.graph.nodes_geometry:
            transform, geometry = loaded.graph[name]
            mesh = loaded.geometry[geometry]
            if not isinstance(mesh, trimesh.Trimesh):
                continue
            linear = np.asarray(transform, dtype=np.float64)[:3, :3]
            v = np.asarray(mesh.vertices, dtype=np.float64) @ linear.T + transform[:3, 3]
            n = np.asarray(mesh.vertex_normals, dtype=np.float64) @ np.linalg.inv(linear)
            vertices.append(v)
            faces.append(np.asarray(mesh.faces) + offset)
            normals.append(n / np.linalg.norm(n, axis=1, keepdims=True))
            offset += len(v)
        self.mesh = trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=False)
        self.normals = np.concatenate(normals)

    def at(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((N, 3) unit normals interpolated at the surface point nearest each of ``points``,
        (N,) that point's distance)."""
        import trimesh

        near, distance, triangle = trimesh.proximity.closest_point(self.mesh, points)
        corners = self.mesh.faces[triangle]
        b = trimesh.triangles.points_to_barycentric(self.mesh.triangles[triangle], near)
        n = (self.normals[corners] * b[:, :, None]).sum(1)
        return n / np.linalg.norm(n, axis=1, keepdims=True), distance


class EmbreeReference:
    """Raw Embree ray casts (single-threaded, ``EmbreeScene.run``) on a scene's triangles."""

    def __init__(self, scene: Scene) -> None:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self._scene, scene.vertices.astype(np.float32), scene.faces.astype(np.int32))

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> dict[str, np.ndarray]:
        """Closest hits: ``t`` (+inf on a miss), ``triangle`` (-1), ``barycentric`` (u, v)."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        r = self._scene.run(o, d, output=1)
        tri = np.asarray(r["primID"], dtype=np.int32)
        hit = tri >= 0
        t = np.where(hit, np.asarray(r["tfar"], dtype=np.float32), np.float32(np.inf))
        bary = np.stack([r["u"], r["v"]], -1).astype(np.float32)
        return {
            "t": t,
            "triangle": np.where(hit, tri, -1),
            "barycentric": np.where(hit[:, None], bary, 0),
        }

    def occluded(self, origins: np.ndarray, directions: np.ndarray, t_max: float) -> np.ndarray:
        """(N,) bool: anything on each ray within ``0 <= t < t_max``."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        far = np.full(len(o), t_max, dtype=np.float32)
        return np.asarray(self._scene.run(o, d, dists=far, query="OCCLUDED")) == 0

    def raw(self, origins: np.ndarray, directions: np.ndarray, t_max: float) -> dict[str, Any]:
        """embreex's own calls on float32 C-contiguous copies of the rays made once, here:
        ``cast`` and ``occluded`` (no arguments; each returns what embreex returns), so that a
        benchmark times Embree's queries alone, not the conversions around them."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        far = np.full(len(o), t_max, dtype=np.float32)
        s = self._scene
        return {
            "cast": lambda: s.run(o, d, output=1),
            "occluded": lambda: s.run(o, d, dists=far, query="OCCLUDED"),
        }

    def commit(self) -> None:
        """Build the BVH now (embreex builds it on the first query)."""
        self.cast(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))


class Open3DReference:
    """Open3D's ``RaycastingScene`` (Embree, robust mode, on every core) on a scene's triangles."""

    def __init__(self, scene: Scene) -> None:
        import open3d as o3d

        self._o3d = o3d
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(
            o3d.core.Tensor(np.ascontiguousarray(scene.vertices, dtype=np.float32)),
            o3d.core.Tensor(np.ascontiguousarray(scene.faces, dtype=np.uint32)),
        )

    def _rays(self, origins: np.ndarray, directions: np.ndarray) -> Any:
        rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
        return self._o3d.core.Tensor(rays)

    def raw(self, origins: np.ndarray, directions: np.ndarray, t_max: float) -> dict[str, Any]:
        """Open3D's own calls on rays made into its tensor once, here: ``cast``, ``occluded``,
        ``count`` and ``list`` (no arguments; each returns what Open3D returns, unconverted), so
        that a benchmark times Open3D's query alone, not the conversions around it."""
        rays = self._rays(origins, directions)
        s = self._scene
        return {
            "cast": lambda: s.cast_rays(rays),
            "occluded": lambda: s.test_occlusions(rays, tfar=t_max),
            "count": lambda: s.count_intersections(rays),
            "list": lambda: s.list_intersections(rays),
        }

    def cast(
        self, origins: np.ndarray, directions: np.ndarray, threads: int = 0
    ) -> dict[str, np.ndarray]:
        """Closest hits: ``t`` (+inf on a miss), ``triangle`` (-1), ``barycentric`` (u, v), on
        ``threads`` threads (0: every core)."""
        r = self._scene.cast_rays(self._rays(origins, directions), nthreads=threads)
        ids = r["primitive_ids"].numpy()
        hit = ids != np.iinfo(np.uint32).max
        return {
            "t": np.where(hit, r["t_hit"].numpy(), np.float32(np.inf)),
            "triangle": np.where(hit, ids.astype(np.int64), -1).astype(np.int32),
            "barycentric": np.where(hit[:, None], r["primitive_uvs"].numpy(), 0),
        }

    def occluded(
        self, origins: np.ndarray, directions: np.ndarray, t_max: float, threads: int = 0
    ) -> np.ndarray:
        """(N,) bool: anything on each ray within ``0 <= t < t_max``, on ``threads`` threads."""
        r = self._scene.test_occlusions(
            self._rays(origins, directions), tfar=t_max, nthreads=threads
        )
        return r.numpy().astype(bool)

    def count_hits(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """``count_intersections``: (N,) int32, every hit along each whole ray."""
        return self._scene.count_intersections(self._rays(origins, directions)).numpy()

    def all_hits(self, origins: np.ndarray, directions: np.ndarray) -> dict[str, np.ndarray]:
        """``list_intersections``: ``ray_splits``, ``t_hit``, ``primitive_ids`` (ragged)."""
        r = self._scene.list_intersections(self._rays(origins, directions))
        return {k: r[k].numpy() for k in ("ray_splits", "t_hit", "primitive_ids")}

    def commit(self) -> None:
        """Build the BVH now (Open3D builds it on the first query)."""
        self.cast(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))

    def closest_points(self, points: np.ndarray) -> dict[str, np.ndarray]:
        """``compute_closest_points``: ``point`` (N, 3), ``distance`` (N,) float32 (measured
        here from the point Open3D returns), ``triangle`` (N,) int32."""
        r = self._scene.compute_closest_points(self._o3d.core.Tensor(points))
        p = r["points"].numpy()
        return {
            "point": p,
            "distance": np.linalg.norm(p - points, axis=1).astype(np.float32),
            "triangle": r["primitive_ids"].numpy().astype(np.int64).astype(np.int32),
        }

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """``compute_signed_distance`` (N,) float32: negative inside (by ray parity)."""
        return self._scene.compute_signed_distance(self._o3d.core.Tensor(points)).numpy()

    def occupancy(self, points: np.ndarray) -> np.ndarray:
        """``compute_occupancy`` (N,) float32: 1 inside, 0 outside (by ray parity)."""
        return self._scene.compute_occupancy(self._o3d.core.Tensor(points)).numpy()


def embree_memory(scene: Scene) -> int:
    """Bytes Embree holds for the BVH it builds over ``scene`` with embreex's settings (robust
    mode, default quality), read from Embree's memory monitor. The geometry is shared, not
    copied, so the figure is the acceleration structure alone."""
    import ctypes
    import glob

    import embreex

    libs = os.path.join(os.path.dirname(embreex.__file__), "..", "embreex.libs", "libembree4*")
    found = sorted(glob.glob(libs))
    if not found:
        raise RuntimeError(f"no Embree library beside embreex ({libs})")
    lib = ctypes.CDLL(found[0])
    vp = ctypes.c_void_p
    monitor_t = ctypes.CFUNCTYPE(ctypes.c_bool, vp, ctypes.c_ssize_t, ctypes.c_bool)
    lib.rtcNewDevice.restype = vp
    lib.rtcNewDevice.argtypes = [ctypes.c_char_p]
    lib.rtcNewScene.restype = vp
    lib.rtcNewScene.argtypes = [vp]
    lib.rtcNewGeometry.restype = vp
    lib.rtcNewGeometry.argtypes = [vp, ctypes.c_int]
    lib.rtcSetSceneFlags.argtypes = [vp, ctypes.c_int]
    lib.rtcSetDeviceMemoryMonitorFunction.argtypes = [vp, monitor_t, vp]
    lib.rtcSetSharedGeometryBuffer.argtypes = [vp, ctypes.c_int, ctypes.c_uint, ctypes.c_int, vp]
    lib.rtcSetSharedGeometryBuffer.argtypes += [ctypes.c_size_t] * 3
    lib.rtcAttachGeometry.argtypes = [vp, vp]
    lib.rtcGetDeviceError.argtypes = [vp]
    for f in ("rtcCommitGeometry", "rtcReleaseGeometry", "rtcCommitScene", "rtcReleaseScene"):
        getattr(lib, f).argtypes = [vp]
    lib.rtcReleaseDevice.argtypes = [vp]
    held = [0]

    @monitor_t
    def monitor(_user: Any, nbytes: int, _post: bool) -> bool:
        held[0] += nbytes
        return True

    # Embree reads vertex buffers 16 bytes at a time: pad the last vertex (its documented rule).
    vertices = np.zeros(scene.vertices.size + 1, dtype=np.float32)
    vertices[:-1] = scene.vertices.ravel()
    faces = np.ascontiguousarray(scene.faces, dtype=np.uint32)
    device = lib.rtcNewDevice(None)
    try:
        handle = lib.rtcNewScene(device)
        lib.rtcSetSceneFlags(handle, 1 << 2)  # RTC_SCENE_FLAG_ROBUST, as embreex sets it
        geom = lib.rtcNewGeometry(device, 0)  # RTC_GEOMETRY_TYPE_TRIANGLE
        nv, nf = len(scene.vertices), len(faces)
        # RTC_BUFFER_TYPE_VERTEX = 1 with RTC_FORMAT_FLOAT3; RTC_BUFFER_TYPE_INDEX = 0, UINT3.
        lib.rtcSetSharedGeometryBuffer(geom, 1, 0, 0x9003, vertices.ctypes.data, 0, 12, nv)
        lib.rtcSetSharedGeometryBuffer(geom, 0, 0, 0x5003, faces.ctypes.data, 0, 12, nf)
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(handle, geom)
        lib.rtcReleaseGeometry(geom)
        lib.rtcSetDeviceMemoryMonitorFunction(device, monitor, None)
        lib.rtcCommitScene(handle)
        error = lib.rtcGetDeviceError(device)
        built = held[0]
        lib.rtcReleaseScene(handle)
    finally:
        lib.rtcReleaseDevice(device)
    if error:
        raise RuntimeError(f"Embree reported error {error} while building")
    return built
