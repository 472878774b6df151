"""Typed exceptions raised by scenesample.

Every error a user can cause is one of these, with a message that names the offending argument
or file element. Each also inherits the built-in exception a Python user would try first
(``ValueError`` for bad values, ``OSError`` for unreadable files, ``RuntimeError`` for the GPU).
"""

from __future__ import annotations

__all__ = [
    "ScenesampleError",
    "InputError",
    "SceneError",
    "SceneFileError",
    "GpuError",
    "GpuUnavailableError",
    "GpuLimitError",
    "ExrError",
    "MissingDependencyError",
    "SceneWarning",
]


class ScenesampleError(Exception):
    """Base class of every scenesample exception."""


class InputError(ScenesampleError, ValueError):
    """An argument has the wrong shape, dtype or value."""


class SceneError(ScenesampleError, ValueError):
    """Scene content cannot be used: non-finite vertices, bad indices, node cycles, bad accessors,
    no triangles."""


class SceneFileError(SceneError, OSError):
    """A scene file, or a file it references, is missing, truncated or corrupt."""


class GpuError(ScenesampleError, RuntimeError):
    """The GPU reported an error while running work."""


class GpuUnavailableError(GpuError):
    """No usable GPU adapter. On a machine without a GPU, Mesa's software Vulkan driver
    (Debian package ``mesa-vulkan-drivers``) provides one."""


class GpuLimitError(GpuError, ValueError):
    """A request exceeds the device's limits (refused before anything is submitted)."""


class ExrError(ScenesampleError, OSError):
    """An EXR file could not be written or read back."""


class MissingDependencyError(ScenesampleError, ImportError):
    """A function needs an optional package that is not installed (scenesample itself needs only
    numpy). The message says what needs which package and the extra that brings it, e.g.
    "the gallery needs matplotlib: pip install 'scenesample[demo]'"; ``purpose``, ``package``
    and ``extra`` hold the three parts."""

    def __init__(self, purpose: str, package: str, extra: str) -> None:
        super().__init__(
            f"{purpose} needs {package}: pip install 'scenesample[{extra}]'", name=package
        )
        self.purpose, self.package, self.extra = purpose, package, extra

    def __reduce__(self) -> tuple[type, tuple[str, str, str]]:
        return (type(self), (self.purpose, self.package, self.extra))


class SceneWarning(UserWarning):
    """A scene loaded, but something in it was skipped or approximated (missing image, unknown
    extension, point or line primitives)."""


def check_integer(name: str, value: object, minimum: int = 1) -> int:
    """``value`` as an int, or an :class:`InputError` naming ``name`` when it is not an integer
    >= ``minimum`` (bools are refused)."""
    import numpy as np

    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)
