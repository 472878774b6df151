"""Multi-cell orthographic impostors (multi-cell-orthographic-impostors.txt): cells of the
scene, each captured from a set of directions, and views composed from them. The Rust side is
``src/impostors/``."""

from .cells import PROJECTIONS, Impostors, ImpostorView, impostor_view, impostors

__all__ = ["PROJECTIONS", "ImpostorView", "Impostors", "impostor_view", "impostors"]
