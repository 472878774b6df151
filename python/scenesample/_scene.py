"""The ``Scene`` façade: loading dispatch (glTF natively, other formats through trimesh),
warnings, and numpydoc documentation over ``scenesample._core.Scene``."""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Optional

import numpy as np

from . import _core
from .errors import InputError, SceneFileError, SceneWarning

__all__ = ["Scene"]

_GLTF_SUFFIXES = {".gltf", ".glb"}


class Scene:
    """A validated triangle scene.

    Build one with :meth:`load`, :meth:`from_arrays` or :meth:`from_trimesh`. Scenes are
    immutable; the BVH used by :func:`scenesample.cast_rays` and the GPU buffers used by
    :func:`scenesample.discretize` are built on first use and cached.

    Triangle ids everywhere in scenesample are indices into :attr:`faces`.
    """

    __slots__ = ("_core",)

    def __init__(self, core: _core.Scene) -> None:
        if not isinstance(core, _core.Scene):
            raise TypeError("use Scene.load, Scene.from_arrays or Scene.from_trimesh")
        self._core = core

    # -- construction -------------------------------------------------------------------------

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Scene:
        """Load a scene file.

        glTF 2.0 (``.gltf`` with external or data-URI buffers, ``.glb``) is read natively: every
        triangle primitive of every mesh instance (node hierarchy flattened with world transforms,
        ``EXT_mesh_gpu_instancing`` expanded; strips and fans converted), metallic-roughness
        materials, ``KHR_lights_punctual`` lights and glTF cameras. Compressed and quantized
        geometry is decoded: ``KHR_draco_mesh_compression``, ``EXT_meshopt_compression`` (and
        ``KHR_meshopt_compression``), ``KHR_mesh_quantization``. Points and lines, missing
        images and unknown extensions are skipped with a :class:`SceneWarning`; a file that
        requires an extension nothing here decodes is a :class:`SceneError` naming it.

        Wavefront OBJ is read natively too, with its MTL materials: ``Kd`` times the mean texel
        of ``map_Kd`` as the base colour, ``Ke`` as emissive, roughness from ``Pr`` or else
        ``1 - sqrt(clamp(Ns, 0, 1000) / 1000)`` (the inverse of Blender's exporter), metallic
        from ``Pm`` (else 0), alpha from ``d`` or ``1 - Tr``; every OBJ material is double
        sided. Faces get ``material_ids`` from ``usemtl`` and ``object_ids`` from ``o``/``g``;
        polygons are fan triangulated. A missing MTL file, texture or material is a
        :class:`SceneWarning`; names may contain spaces and Windows separators. Other formats
        (PLY, STL, ...) are read with trimesh when it is installed.

        Parameters
        ----------
        path : str or PathLike
            The file to read.

        Raises
        ------
        SceneFileError
            The file (or a buffer it references) is missing, truncated or corrupt.
        SceneError
            The content is invalid (non-finite vertices, out-of-range indices, node cycles,
            accessors of the wrong type or out of bounds, a required extension we cannot decode).
        """
        p = Path(path)
        native = {
            ".obj": _core.Scene.load_obj,
            **dict.fromkeys(_GLTF_SUFFIXES, _core.Scene.load_gltf),
        }
        if p.suffix.lower() in native:
            scene = cls(native[p.suffix.lower()](str(p)))
            for message in scene.warnings:
                warnings.warn(message, SceneWarning, stacklevel=2)
            return scene
        if not p.exists():
            raise SceneFileError(f"{p}: no such file")
        try:
            import trimesh
        except ImportError:
            raise SceneFileError(
                f"{p}: only glTF (.gltf, .glb) is read natively; install trimesh to read "
                f"{p.suffix or 'this'} files"
            ) from None
        try:
            loaded = trimesh.load(str(p), force="scene", process=False)
        except Exception as e:  # trimesh raises many types for unreadable files
            raise SceneFileError(f"{p}: trimesh could not read it: {e}") from e
        return cls.from_trimesh(loaded)

    @classmethod
    def from_arrays(
        cls,
        vertices: Any,
        faces: Any,
        *,
        normals: Optional[Any] = None,
        colors: Optional[Any] = None,
        material_ids: Optional[Any] = None,
        materials: Optional[list[dict[str, Any]]] = None,
        object_ids: Optional[Any] = None,
        objects: Optional[list[str]] = None,
        lights: Optional[list[dict[str, Any]]] = None,
        texcoords: Optional[Any] = None,
        textures: Optional[list[Any]] = None,
        cameras: Optional[list[Any]] = None,
        animations: Optional[str] = None,
    ) -> Scene:
        """A scene from plain arrays; face order is kept, so triangle ids are face indices.

        Parameters
        ----------
        vertices : (N, 3) array_like of float
            Vertex positions, converted to float32; must be finite.
        faces : (M, 3) array_like of int
            Vertex indices, any integer dtype; each in ``0..N``.
        normals : (N, 3) array_like of float, optional
            Per-vertex normals, kept as given: the images' ``shading_normal`` interpolates
            them (a zero row: that vertex takes the area-weighted normal of its faces; without
            any, every vertex does). ``normal`` stays geometric.
        colors : (N, 3) array_like of float, optional
            Per-vertex linear RGB base colour; white when omitted. A textured material's
            texture multiplies it at each sample.
        material_ids : (M,) array_like of int, optional
            Per-face index into ``materials``, -1 for none (the default for every face).
        materials : list of dict, optional
            Each with any of ``name``, ``base_color`` (RGB/RGBA), ``metallic``, ``roughness``,
            ``emissive``, ``double_sided`` (glTF's defaults for the rest), and a
            ``base_color_texture`` as :attr:`materials` reports it (``texture``: an index into
            ``textures``; ``wrap_s``, ``wrap_t``, ``mag_filter``, ``min_filter``: glTF's sampler
            enums, default REPEAT and LINEAR(_MIPMAP_LINEAR); ``transform``: 2x3 rows mapping
            texture coordinates, default identity) with its ``base_color_factor`` (default:
            ``base_color``).
        object_ids : (M,) array_like of int, optional
            Per-face index into ``objects`` (default: one object, "mesh").
        objects : list of str, optional
            Object names.
        lights : list of dict, optional
            Punctual lights, with the keys :attr:`lights` reports: ``type`` ("point", "spot"
            or "directional"), ``position``, ``direction``, and optionally ``name``, ``color``,
            ``intensity``, ``range``, ``inner_cone_angle``, ``outer_cone_angle``.
        texcoords : (N, 2) array_like of float, optional
            Per-vertex texture coordinates (0..1 spans an image, v down), read by textured
            materials.
        textures : list of (H, W, 4) or (H, W, 3) uint8 arrays, optional
            Base-colour textures, sRGB-encoded texels, row 0 at the top (as :attr:`textures`).
        cameras : list of Camera, optional
            Cameras that travel with the scene (as :attr:`cameras`).
        animations : str, optional
            A scene's animations as a pickle carries them (internal; checked against the
            scene).
        """

        def plain(a: Any) -> Any:
            # Any array_like, including views, misaligned buffers (e.g. unpickled) and lists.
            return None if a is None else np.require(np.asarray(a), requirements=["C", "A"])

        return cls(
            _core.Scene.from_arrays(
                plain(vertices),
                plain(faces),
                plain(normals),
                plain(colors),
                plain(material_ids),
                materials,
                plain(object_ids),
                objects,
                lights,
                plain(texcoords),
                None if textures is None else [np.ascontiguousarray(t) for t in textures],
                cameras,
                animations,
            )
        )

    @classmethod
    def from_trimesh(cls, obj: Any) -> Scene:
        """A scene from a ``trimesh.Trimesh`` or ``trimesh.Scene`` (flattened with its graph's
        world transforms). Faces keep their order: mesh after mesh, in graph order.
        Per-vertex colours are kept when the visual has them."""
        import trimesh

        if isinstance(obj, trimesh.Trimesh):
            meshes = [(obj, np.eye(4))]
            names = ["mesh"]
        elif isinstance(obj, trimesh.Scene):
            meshes, names = [], []
            for node in obj.graph.nodes_geometry:
                transform, geometry = obj.graph[node]
                mesh = obj.geometry[geometry]
                if isinstance(mesh, trimesh.Trimesh):
                    meshes.append((mesh, transform))
                    names.append(str(node))
        else:
            raise TypeError(
                f"from_trimesh takes a trimesh.Trimesh or trimesh.Scene, got {type(obj)}"
            )
        if not meshes:
            return cls.from_arrays(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
        vertices, faces, ids = _placed(
            [(mesh.vertices, mesh.faces) for mesh, _ in meshes], [m for _, m in meshes]
        )
        return cls.from_arrays(
            vertices,
            faces,
            colors=np.concatenate([_vertex_colors(mesh) for mesh, _ in meshes]),
            object_ids=ids,
            objects=names,
        )

    @classmethod
    def from_meshes(
        cls,
        meshes: Any,
        transforms: Optional[Any] = None,
        *,
        names: Optional[list[str]] = None,
    ) -> Scene:
        """A scene of several meshes, one object each (the unit :meth:`posed` moves).

        Parameters
        ----------
        meshes : sequence of (vertices, faces) pairs
            Each ``vertices`` (N_i, 3) float and ``faces`` (M_i, 3) int indexing its own
            vertices. The same pair may appear several times: one instance per appearance.
        transforms : (len(meshes), 4, 4) array_like of float, optional
            Each instance's placement in world space (identity when omitted): its vertices as
            given are mapped by it. A mirroring transform (negative determinant) keeps
            counter-clockwise fronts by reversing the instance's winding.
        names : list of str, optional
            Object names (default ``mesh0``, ``mesh1``, ...).

        Faces follow mesh after mesh, so triangle ``j`` of mesh ``i`` is face
        ``sum(M_0..M_{i-1}) + j``.
        """
        meshes = list(meshes)
        if not meshes:
            raise InputError("from_meshes needs at least one mesh")
        if transforms is None:
            transforms = np.broadcast_to(np.eye(4), (len(meshes), 4, 4))
        transforms = np.asarray(transforms, dtype=np.float64)
        if transforms.shape != (len(meshes), 4, 4):
            raise InputError(
                f"transforms must have shape ({len(meshes)}, 4, 4), got {transforms.shape}"
            )
        if names is not None and len(names) != len(meshes):
            raise InputError(f"{len(names)} names for {len(meshes)} meshes")
        pairs = []
        for k, (mesh, m) in enumerate(zip(meshes, transforms)):
            try:
                v, f = mesh
            except (TypeError, ValueError):
                raise InputError(f"meshes[{k}] must be a (vertices, faces) pair") from None
            v, f = np.asarray(v, dtype=np.float64), np.asarray(f)
            if v.ndim != 2 or v.shape[1:] != (3,) or f.ndim != 2 or f.shape[1:] != (3,):
                raise InputError(
                    f"meshes[{k}]: vertices must be (N, 3) and faces (M, 3), got "
                    f"{v.shape} and {f.shape}"
                )
            if not np.isfinite(m).all():
                raise InputError(f"transforms[{k}] is not finite")
            pairs.append((v, f))
        vertices, faces, ids = _placed(pairs, transforms)
        return cls.from_arrays(
            vertices,
            faces,
            object_ids=ids,
            objects=list(names) if names is not None else [f"mesh{k}" for k in range(len(meshes))],
        )

    # -- poses ---------------------------------------------------------------------------------

    def posed(self, transforms: Any) -> Scene:
        """This scene with its objects moved, sharing the unchanged geometry.

        Parameters
        ----------
        transforms : dict or (len(objects), 4, 4) array_like of float
            Either a dict from an object's name or index (see :attr:`objects`) to a 4x4
            matrix, the objects it does not name staying where they are in this scene; or
            one matrix per object. Each matrix maps its object's vertices *as loaded* to
            their new place in world space. It must be finite, affine (last row 0, 0, 0, 1)
            and non-singular. Normals follow by the inverse transpose; a mirroring matrix
            moves the vertices only, so the faces' winding (which side is the front) flips.

        Returns
        -------
        Scene
            A scene whose every query and method works as on any other. Triangle ids are the
            faces' indices, the same in every pose. A vertex that faces of two objects share is
            split (one copy per object, appended), so :attr:`vertices` may have more rows than
            this scene's. Lights and cameras stay where the scene as loaded has them
            (:meth:`at` moves those on animated nodes).

            A pose costs O(objects). The first pose of a scene builds one BVH per object, in
            the coordinates as loaded, and every pose shares them: rays run on a two-level
            tree, a small tree over the objects' instances built for the pose, each ray moved
            into an object's frame as it enters it (:func:`bvh_stats` reports ``instances``).
            :attr:`vertices`, :attr:`normals` and :attr:`bounds` are made on first use (each
            vertex moved in float64 and rounded once to float32). Rays trace the exact pose:
            they agree with the same :attr:`vertices` built flat but where a ray passes within
            that rounding of an edge (none of 40,000 rays in the tests), and ``t`` to a few
            ulps. Point queries (closest points, signed distance, winding numbers) run on a
            flat tree of the pose, refit from the objects' trees on first use.
        """
        objects = self.objects
        current = self.transforms
        if current is None:
            current = np.broadcast_to(np.eye(4), (len(objects), 4, 4))
        if isinstance(transforms, dict):
            out = np.array(current, dtype=np.float64)
            index = {name: k for k, name in reversed(list(enumerate(objects)))}
            for key, m in transforms.items():
                if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
                    if not 0 <= key < len(objects):
                        raise InputError(f"no object {key}: the scene has {len(objects)} objects")
                    k = int(key)
                elif isinstance(key, str) and key in index:
                    k = index[key]
                else:
                    raise InputError(f"no object named {key!r}; the objects are {objects[:8]}...")
                m = _float_array(m, f"the transform of {key!r}")
                if m.shape != (4, 4):
                    raise InputError(f"the transform of {key!r} must be 4x4, got {m.shape}")
                out[k] = m
        else:
            out = _float_array(transforms, "transforms")
            if out.shape != (len(objects), 4, 4):
                raise InputError(
                    f"transforms must have shape ({len(objects)}, 4, 4) (one per object), "
                    f"got {out.shape}"
                )
        flat = np.ascontiguousarray(out).reshape(-1, 4)
        return Scene(self._core.posed(flat))

    def deformed(self, vertices: Any, normals: Any = None) -> Scene:
        """This scene with every vertex moved (cloth, a soft body, a deforming scan), its
        faces, objects and materials unchanged.

        Parameters
        ----------
        vertices : (len(vertices), 3) array_like of float
            The new position of each of this scene's :attr:`vertices`, finite.
        normals : (len(vertices), 3) array_like of float, optional
            Per-vertex normals of the deformed surface. Without them the result has none: the
            normals that came with this scene no longer fit it.

        Returns
        -------
        Scene
            A scene whose every query and method works as on any other; triangle ids are the
            faces' indices. Its BVH is not built again: the trees of the scene it deforms (the
            scene as loaded, for a posed or deformed one) are refit to the new corners, on
            every core, unless the refit tree's surface-area cost grows past
            ``1.3`` times the rest pose's (a deformation that scatters what the tree kept
            together), when it is built afresh. Lights and cameras stay; the result has no
            animations (its vertices are yours) and :attr:`transforms` is None.
        """
        v = _float_array(vertices, "vertices", np.float32)
        n = None if normals is None else _float_array(normals, "normals", np.float32)
        count = self._core.vertex_count
        for name, a in (("vertices", v), ("normals", n)):
            if a is not None and a.shape != (count, 3):
                raise InputError(
                    f"deformed {name} must have shape ({count}, 3) (one per vertex), got {a.shape}"
                )
        return Scene(self._core.deformed(v, n))

    @property
    def animations(self) -> list[tuple[str, float]]:
        """The glTF animation clips as ``(name, duration in seconds)``; empty without any.
        Unnamed clips are ``animation0``, ``animation1``, ..."""
        return self._core.animations

    def key_times(self, animation: int | str = 0) -> np.ndarray:
        """(K,) float64: every key time of one clip (its index in :attr:`animations`, or its
        name) over all its channels, in seconds, ascending, each once: the frames where its
        keys sit, for sampling it at its keys or between them."""
        return self._core.key_times(self._clip(animation))

    def at(self, t: float, animation: int | str | Sequence[int | str] = 0) -> Scene:
        """The scene posed at ``t`` seconds into one animation clip, or several played together
        (glTF animations: translation, rotation, scale and morph target weights, STEP, LINEAR
        or CUBICSPLINE; skins and morph targets move their meshes' vertices).

        Parameters
        ----------
        t : float
            Seconds into the clip; clamped to ``[0, duration]`` (each clip's own), as glTF's
            samplers hold their first and last keys. A finite real number (not a bool).
        animation : int, str, or a sequence of them
            The clip's index in :attr:`animations`, or its name; a list or tuple plays those
            clips together, and where two of them key the same property of a node, the later
            one in the list wins.

        Returns
        -------
        Scene
            :meth:`posed` with each object's transform from its place as loaded to its place at
            ``t``; the :attr:`lights` and :attr:`cameras` on animated nodes move with their
            nodes too (a camera keeps only its node's rotation and translation, as at load).
            As glTF asks, winding follows the sign of each node's world determinant: an
            object that the clip mirrors relative to its place as loaded has its faces wound
            the other way, so its counter-clockwise side stays its front (``posed`` keeps the
            faces as they are). A zero scale hides its object at that time (or flattens it,
            when only some axes are 0): its triangles have no area and no ray meets them; an
            object loaded with a zero scale keeps only what the scale left of it. On a posed
            scene, ``scene.posed(T).at(t)``, the clip moves each object first and the pose
            after: object ``o`` is at ``T[o] @ A_t[o]`` in world space (the pose's lights and
            cameras are the clip's), and a further ``at`` composes with ``T`` again.

            Skins and morph targets (glTF 2.0 §3.7.2.2 and §3.7.3) move vertices: a mesh's
            POSITION is displaced by its morph targets with the weights at ``t`` (the node's
            ``weights`` channel, else the node's or the mesh's default weights), and a skinned
            mesh is then blended by its joints' world transforms at ``t`` times their inverse
            bind matrices (linear blend skinning; the skinned mesh's own node transform is
            ignored, as the spec says, and its entry in :attr:`transforms` is the identity).
            The scene as loaded is in this rest pose too. Morph NORMAL displacements are not
            read: a glTF scene's normals are its faces' (:attr:`normals` is None). Where skins
            or morphs moved vertices, the BVH is refit as :meth:`deformed`'s is (or built
            afresh past the same limit).
        """
        real = (int, float, np.integer, np.floating)
        if isinstance(t, (bool, np.bool_)) or not isinstance(t, real):
            raise InputError(f"t must be a finite number of seconds, got {t!r}")
        try:
            seconds = float(t)
        except OverflowError:
            raise InputError(f"t must be a finite number of seconds, got {t!r}") from None
        clips = list(animation) if isinstance(animation, (list, tuple)) else [animation]
        if not clips:
            raise InputError("animation must name at least one clip")
        return Scene(self._core.at(seconds, [self._clip(c) for c in clips]))

    def _clip(self, animation: Any) -> int | str:
        """A clip's index (an int) or name (a str, never read as a number), checked."""
        if isinstance(animation, (bool, np.bool_)) or not isinstance(
            animation, (int, np.integer, str)
        ):
            raise InputError(f"animation must be an index or a name, got {animation!r}")
        if not self.animations:
            raise InputError("the scene has no animations")
        if not isinstance(animation, str):
            if not 0 <= animation < len(self.animations):
                raise InputError(f"no animation {animation}: the scene has {len(self.animations)}")
            return int(animation)
        return animation

    @property
    def transforms(self) -> Optional[np.ndarray]:
        """(len(objects), 4, 4) float64: each object's transform from the scene as loaded,
        or None for a scene that was not posed."""
        return self._core.transforms

    # -- data ----------------------------------------------------------------------------------

    @property
    def vertices(self) -> np.ndarray:
        """(N, 3) float32 world positions."""
        return self._core.vertices

    @property
    def faces(self) -> np.ndarray:
        """(M, 3) uint32 vertex indices; row i is triangle id i."""
        return self._core.faces

    @property
    def normals(self) -> Optional[np.ndarray]:
        """(N, 3) float32 per-vertex normals: a glTF file's NORMAL (world space, posed with
        the geometry: node transforms by their inverse transpose, skins by their blended joint
        matrices, morph NORMAL targets weighted like positions), OBJ's ``vn``, or those given to
        :meth:`from_arrays` or :meth:`deformed`; a zero row where a primitive or corner had
        none. None when the scene has none at all. Wherever a vertex has none, shading uses
        the area-weighted normal of the faces around it (``shading_normal`` of every sample)."""
        return self._core.normals

    @property
    def colors(self) -> np.ndarray:
        """(N, 3) float32 per-vertex linear base colour (glTF: the material's base colour
        factor x COLOR_0). A textured material's texture multiplies it at each sample (see
        :func:`scenesample.surface_attributes`); the material's one colour, factor x mean texel,
        is its ``base_color`` in :attr:`materials`."""
        return self._core.colors

    @property
    def texcoords(self) -> Optional[np.ndarray]:
        """(N, 2) float32 per-vertex texture coordinates: the set each vertex's material's
        base-colour texture reads (0..1 spans the image, v down; OBJ's ``vt`` as the file has
        it, v up, its material's transform flipping it); None when no material is textured."""
        return self._core.texcoords

    @property
    def textures(self) -> list[np.ndarray]:
        """The base-colour textures the materials read: (H, W, 4) uint8 sRGB-encoded texels,
        row 0 at the top."""
        return self._core.textures

    @property
    def triangle_count(self) -> int:
        """Number of triangles M (degenerate ones included)."""
        return self._core.triangle_count

    @property
    def degenerate_count(self) -> int:
        """Number of zero-area triangles (kept, never rasterised, zero normal)."""
        return self._core.degenerate_count

    @property
    def closed(self) -> bool:
        """Whether the surface is closed: with vertices welded by position, every edge is walked
        as often from one end as from the other by the triangles that have it (an STL triangle
        soup of a closed solid counts; a mesh wound inside out is closed too). Its winding
        number is then an integer off the surface, and :func:`scenesample.winding_number`,
        :func:`~scenesample.occupancy` and :func:`~scenesample.signed_distance` answer with one
        ray per point. Found on first use and kept with the scene."""
        return self._core.closed

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float32 ``[min, max]`` of the vertices that faces use."""
        return self._core.bounds

    @property
    def material_ids(self) -> np.ndarray:
        """(M,) int32 index into :attr:`materials`; -1 is glTF's default material."""
        return self._core.material_ids

    @property
    def object_ids(self) -> np.ndarray:
        """(M,) int32 index into :attr:`objects` (one object per glTF mesh instance)."""
        return self._core.object_ids

    @property
    def objects(self) -> list[str]:
        """Object names (node or mesh name; ``name#i`` for GPU instances)."""
        return self._core.objects

    @property
    def materials(self) -> list[dict[str, Any]]:
        """Materials as dicts: ``name``, ``base_color`` (linear RGBA: factor x mean texel of the
        base-colour texture, sRGB decoded, or the factor alone: the material's one colour),
        ``base_color_factor``, ``base_color_textured``, ``base_color_texture`` (None, or how
        samples read it: ``texture``, an index into :attr:`textures`; ``wrap_s``, ``wrap_t``,
        ``mag_filter``, ``min_filter``, glTF's sampler enums; ``transform``, 2x3 rows from the
        file's texture coordinates to the image's, ``KHR_texture_transform``), ``metallic``,
        ``roughness``, ``emissive``, ``double_sided``."""
        return self._core.materials

    @property
    def lights(self) -> list[dict[str, Any]]:
        """``KHR_lights_punctual`` lights as dicts: ``name``, ``type`` (point, spot, directional),
        ``color``, ``intensity``, ``range``, world ``position`` and unit ``direction``,
        ``inner_cone_angle``, ``outer_cone_angle``."""
        return self._core.lights

    @property
    def cameras(self) -> list[_core.Camera]:
        """glTF cameras with world poses (scale removed); 512 pixels high, width from the aspect
        ratio."""
        return self._core.cameras

    @property
    def warnings(self) -> list[str]:
        """What loading skipped or approximated (also emitted as :class:`SceneWarning`)."""
        return self._core.warnings

    def __repr__(self) -> str:
        return repr(self._core)

    def __reduce__(self) -> tuple[Any, tuple[dict[str, Any]]]:
        """Pickling (e.g. to the workers that render an animation's frames): geometry,
        normals, colours, texture coordinates and textures, materials, objects, lights,
        cameras and animations travel (``copy.deepcopy`` goes the same way); load warnings do
        not. A posed scene travels as the scene it was posed from and its transforms, and is
        posed again where it lands: its :attr:`transforms` and the meaning of a further
        :meth:`posed` (which maps the objects as loaded) are the same in every process. A pose
        whose skins or morph targets moved vertices carries its vertices and normals too."""
        base = self._core.base
        if base is None:
            return (_from_state, (_state(self._core),))
        deforms = self._core.deforms
        state = {
            "base": _state(base),
            "transforms": self.transforms,
            "rewinds": self._core.rewinds,
            "lights": self.lights,
            "vertices": self.vertices if deforms else None,
            "normals": self.normals if deforms else None,
        }
        return (_from_posed_state, (state,))


def _state(core: _core.Scene) -> dict[str, Any]:
    return {
        "vertices": core.vertices,
        "faces": core.faces,
        "normals": core.normals,
        "colors": core.colors,
        "material_ids": core.material_ids,
        "materials": core.materials,
        "object_ids": core.object_ids,
        "objects": core.objects,
        "lights": core.lights,
        "texcoords": core.texcoords,
        "textures": core.textures,
        "cameras": core.cameras,
        "animations": core.animations_state,
    }


def _from_state(state: dict[str, Any]) -> Scene:
    return Scene.from_arrays(**state)


def _from_posed_state(state: dict[str, Any]) -> Scene:
    base = Scene.from_arrays(**state["base"])
    rows = np.ascontiguousarray(state["transforms"], dtype=np.float64).reshape(-1, 4)
    vertices, normals = state.get("vertices"), state.get("normals")
    return Scene(base._core.posed(rows, state["rewinds"], state["lights"], vertices, normals))


def _float_array(value: Any, what: str, dtype: Any = np.float64) -> np.ndarray:
    """``value`` as an array of ``dtype``, or an InputError naming ``what`` when it is not
    real numbers in a regular shape (text, None, ragged lists, complex numbers, whose imaginary
    part a conversion would silently drop)."""
    try:
        out = np.asarray(value)
        if np.iscomplexobj(out):
            raise InputError(f"{what} must be real numbers, got complex ones ({out.dtype})")
        out = np.asarray(out, dtype=dtype)
    except (TypeError, ValueError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(f"{what} must be numbers in a regular array: {e}") from None
    return out


def _placed(meshes: list, transforms: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Meshes ``(vertices, faces)`` placed by their 4x4 ``transforms`` and stacked: float64
    vertices, int64 faces (each mesh's offset by the vertices before it; reversed under a
    mirroring transform, which keeps counter-clockwise fronts) and each face's mesh index."""
    verts, faces, ids = [], [], []
    offset = 0
    for k, ((v, f), m) in enumerate(zip(meshes, transforms)):
        m = np.asarray(m, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        f = np.asarray(f, dtype=np.int64)
        if np.linalg.det(m[:3, :3]) < 0:
            f = f[:, ::-1]
        verts.append(v @ m[:3, :3].T + m[:3, 3])
        faces.append(f + offset)
        ids.append(np.full(len(f), k, dtype=np.int32))
        offset += len(v)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(ids)


def _vertex_colors(mesh: Any) -> np.ndarray:
    n = len(mesh.vertices)
    visual = getattr(mesh, "visual", None)
    if visual is not None and getattr(visual, "kind", None) == "vertex":
        c = np.asarray(visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
        # sRGB-encoded 8-bit colours to linear, like glTF base colours.
        return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return np.ones((n, 3))


def core_of(scene: Any) -> _core.Scene:
    """The Rust scene behind ``scene``; :class:`InputError` when it is not a :class:`Scene`."""
    if isinstance(scene, Scene):
        return scene._core
    raise InputError(f"scene must be a scenesample.Scene, got {type(scene).__name__}")
