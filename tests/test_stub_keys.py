"""The TypedDicts of ``_core.pyi`` name exactly the keys the native functions return: a renamed or
forgotten key fails here (stubtest checks signatures, not the keys of returned dicts)."""

import ast
from pathlib import Path

import numpy as np
import pytest
import scenesample as ss
import scenesample._core as core

STUB = Path(ss.__file__).with_name("_core.pyi")


def stub_types() -> tuple[dict[str, dict[str, str]], dict[str, str]]:
    """(TypedDict name -> {key: annotation}, function name -> return annotation)."""
    tree = ast.parse(STUB.read_text())
    dicts, returns = {}, {}
    for node in tree.body:
        bases = (
            [b.id for b in node.bases if isinstance(b, ast.Name)]
            if isinstance(node, ast.ClassDef)
            else []
        )
        if "TypedDict" in bases or any(b in dicts for b in bases):
            # A TypedDict subclass has its bases' keys too (bases come first in the stub).
            dicts[node.name] = {k: v for b in bases if b in dicts for k, v in dicts[b].items()}
            dicts[node.name].update(
                {
                    s.target.id: ast.unparse(s.annotation)
                    for s in node.body
                    if isinstance(s, ast.AnnAssign)
                }
            )
        elif isinstance(node, ast.FunctionDef) and node.returns is not None:
            returns[node.name] = ast.unparse(node.returns)
    return dicts, returns


def check(value, annotation: str, dicts: dict, where: str) -> None:
    """Raise AssertionError when ``value``'s keys differ from ``annotation``'s TypedDict."""
    if annotation.startswith("tuple["):
        parts = [p.strip() for p in annotation[6:-1].split(",")]
        for v, a in zip(value, parts):
            check(v, a, dicts, where)
        return
    if annotation.startswith("list[") and annotation[5:-1] in dicts:
        for v in value:
            check(v, annotation[5:-1], dicts, where)
        return
    if annotation not in dicts:
        return
    fields = dicts[annotation]
    assert set(value) == set(fields), (where, annotation, sorted(set(value) ^ set(fields)))
    for k, a in fields.items():
        check(value[k], a, dicts, f"{where}[{k!r}]")


def keep(x):
    return dict(x) if isinstance(x, dict) else x


@pytest.fixture
def recorded(monkeypatch):
    """Every dict-returning native function wrapped to keep what it returned."""
    dicts, returns = stub_types()
    seen: dict[str, object] = {}
    for name, ann in returns.items():
        if not (ann.startswith("_") or ann.startswith("tuple[")) or not hasattr(core, name):
            continue
        f = getattr(core, name)

        def wrap(*a, __f=f, __n=name, **k):
            r = __f(*a, **k)
            # A copy: the façade pops keys from what it is given.
            seen.setdefault(__n, tuple(map(keep, r)) if isinstance(r, tuple) else keep(r))
            return r

        monkeypatch.setattr(core, name, wrap)
    return dicts, returns, seen


def test_every_returned_dict_matches_its_stub(recorded, gpu, tmp_path):
    dicts, returns, seen = recorded
    scene = ss.scenes.reflective_room(spheres=2, seed=0)
    eye = ss.scenes.reflective_room_eye(32)
    cams = [
        eye,
        ss.Camera.look_at((0.2, -2.5, 1.2), (0, 0, 0.4), (0, 0, 1), yfov=0.9, width=32, height=32),
    ]
    images = ss.discretize(scene, cams)
    ss.discretize(scene, cams, "nonredundant")
    ss.discretize(scene, cams, "peeling", layers=2)
    ss.evaluate(images, scene, intermediate=2)
    ss.reconstruct(images, "mesh")
    images.save_exr(tmp_path / "a.exr")
    ss.DepthImages.load_exr(tmp_path / "a.exr")
    light = ss.AreaLight.above(scene, size=0.3, height=0.5)
    ss.soft_shadows(scene, eye, light, samples=(2, 2), discretization="raytraced")
    pts = ss.discretize(scene, method="epr", eye=eye, resolution=16)
    ss.splat(pts, resolution=16)
    ss.discretize(
        scene, method="epr", eye=eye, light=((0, 0, 1.5), 0.1), light_samples=1, resolution=16
    )
    ss.omni_shadows(scene, eye, (0, 0, 1.5), 0.1, light_samples=1, method="mvr", resolution=16)
    ss.reflections(scene, eye, method="mvr", resolution=16)
    field = ss.discretize(scene, method="visibility_field", uv=(2, 2), st=(2, 2))
    ss.evaluate(ss.reconstruct(field, eye), scene, "cells")
    imp = ss.discretize(scene, method="impostors", octree_depth=0, subdivisions=0, resolution=8)
    ss.reconstruct(imp, eye)
    ss.ImpostorView.of_triangles(scene, eye)
    o, d = (a.reshape(-1, 3) for a in eye.pixel_rays())
    ss.cast_rays(scene, o, d)
    ss.occluded(scene, o, d)
    ss.all_hits(scene, o, d)
    ss.count_hits(scene, o, d)
    ss.surface_attributes(scene, ss.closest_points(scene, o))
    ss.render(scene, eye, effects=[])
    ss.bvh_stats(scene)
    ss.device_info(triangles=1000, pixels=64 * 64)
    typed = {n for n, a in returns.items() if a.startswith("_") or a.startswith("tuple[")}
    missing = typed & {n for n in dir(core) if not n.startswith("_")} - set(seen)
    assert not missing, f"not exercised here: {sorted(missing)}"
    for name, value in seen.items():
        check(value, returns[name], dicts, name)


def test_the_checker_catches_a_renamed_key():
    dicts = {"_D": {"a": "int", "inner": "_E"}, "_E": {"x": "float"}}
    check({"a": 1, "inner": {"x": 1.0}}, "_D", dicts, "ok")
    with pytest.raises(AssertionError):
        check({"a": 1, "inner": {"y": 1.0}}, "_D", dicts, "renamed")
    with pytest.raises(AssertionError):
        check({"b": 1, "inner": {"x": 1.0}}, "_D", dicts, "renamed")
    assert np.isfinite(1.0)
