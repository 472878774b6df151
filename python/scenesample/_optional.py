"""Optional packages, imported where a function needs them. scenesample itself needs only numpy;
a missing optional package raises :class:`~scenesample.errors.MissingDependencyError` naming it
and the extra of pyproject.toml that brings it."""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import MissingDependencyError

#: module -> (the distribution to install, the scenesample extra that brings it)
KNOWN = {
    "matplotlib": ("matplotlib", "demo"),
    "PIL": ("pillow", "demo"),
}


def require(module: str, purpose: str) -> ModuleType:
    """``module`` imported, or a :class:`MissingDependencyError` saying that ``purpose`` (e.g.
    "the gallery") needs it and how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        package, extra = KNOWN[module.split(".")[0]]
        raise MissingDependencyError(purpose, package, extra) from None


def pyplot(purpose: str) -> ModuleType:
    """matplotlib.pyplot on the Agg backend (files only, no display), via :func:`require`."""
    matplotlib = require("matplotlib", purpose)
    matplotlib.use("Agg")
    return importlib.import_module("matplotlib.pyplot")
