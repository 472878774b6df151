"""The public surface: exports, stubs checked against the native module, docstrings, typing
marker (ruff runs in `make test`'s lint stage)."""

from __future__ import annotations

import inspect
import subprocess
import sys
from pathlib import Path

import pytest
import scenesample as ss

PACKAGE = Path(ss.__file__).parent


def test_all_exports_exist() -> None:
    for name in ss.__all__:
        assert hasattr(ss, name), name


def test_stub_matches_native_module(tmp_path) -> None:
    """mypy's stubtest of the native module against `_core.pyi`. mypy analyses the stub and
    what it imports (numpy's types); the package's Python modules, which the stub does not
    need, are skipped (a third of the time: stubtest type-checked all of them)."""
    pytest.importorskip("mypy")
    config = tmp_path / "mypy.ini"
    config.write_text(
        "[mypy]\n[mypy-scenesample.*]\nfollow_imports = skip\n"
        "[mypy-scenesample._core]\nfollow_imports = normal\n"
    )
    r = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "scenesample._core", "--mypy-config-file", config],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Success" in r.stdout


def test_typed_marker_and_stub_are_shipped() -> None:
    assert (PACKAGE / "py.typed").exists() and (PACKAGE / "_core.pyi").exists()


@pytest.mark.parametrize(
    "obj",
    [
        ss.discretize,
        ss.cast_rays,
        ss.device_info,
        ss.Scene.load,
        ss.Scene.from_arrays,
        ss.Scene.from_trimesh,
        ss.DepthImages,
        ss.RayHits,
        ss.DepthImages.save_exr,
        ss.scenes.shapes,
    ],
)
def test_public_functions_document_themselves(obj) -> None:
    doc = inspect.getdoc(obj) or ""
    assert len(doc) > 40, obj


def test_errors_form_one_hierarchy() -> None:
    for name in ss.errors.__all__:
        cls = getattr(ss.errors, name)
        assert issubclass(cls, ss.ScenesampleError) or name == "SceneWarning"
    assert issubclass(ss.SceneFileError, OSError) and issubclass(ss.SceneFileError, ValueError)
    assert issubclass(ss.GpuUnavailableError, RuntimeError)


def test_the_namespace_is_the_public_api_and_the_stubs_declare_what_it_takes_from_core():
    import ast

    assert dir(ss) == sorted(ss.__all__)
    assert "annotations" not in dir(ss) and not any(n.startswith("_") for n in dir(ss))
    assert len(set(ss.__all__)) == len(ss.__all__)
    tree = ast.parse((PACKAGE / "_core.pyi").read_text())
    stub_all = next(
        ast.literal_eval(n.value)
        for n in tree.body
        if isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "__all__" for t in n.targets)
    )
    from_core = [
        n for n in ss.__all__ if getattr(getattr(ss, n), "__module__", "") == "scenesample._core"
    ]
    assert from_core and set(from_core) <= set(stub_all), from_core


def test_every_public_class_and_method_has_a_docstring():
    """help() and IDEs show what each name does: every public function and class, and every
    public method, property and static method of a class, has a docstring at run time (the
    native Camera's included)."""
    missing = []
    for name in ss.__all__:
        obj = getattr(ss, name)
        if inspect.ismodule(obj):
            continue
        if not (obj.__doc__ or "").strip():
            missing.append(name)
        if not inspect.isclass(obj):
            continue
        for key, member in vars(obj).items():
            if key.startswith("_"):
                continue
            if isinstance(member, (staticmethod, classmethod)):
                member = member.__func__
            kinds = ("getset_descriptor", "method_descriptor", "builtin_function_or_method")
            if callable(member) or isinstance(member, property) or type(member).__name__ in kinds:
                if not (getattr(member, "__doc__", None) or "").strip():
                    missing.append(f"{name}.{key}")
    assert missing == []
