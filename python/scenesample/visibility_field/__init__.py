"""The visibility field (visibility-field.txt): two-plane slabs, the precomputed field of grid
cells held by a Rust handle (§3, ``field``), and the views resampled from it (§4, ``view``).
The Rust side is ``src/visibility_field/``."""

from .field import (
    CELL_DTYPE,
    INTERPOLATIONS,
    QUALITIES,
    Slab,
    VisibilityField,
    default_settings,
    visibility_field,
)
from .view import FieldView, cells_metric, field_view

__all__ = [
    "CELL_DTYPE",
    "FieldView",
    "INTERPOLATIONS",
    "QUALITIES",
    "Slab",
    "VisibilityField",
    "cells_metric",
    "default_settings",
    "field_view",
    "visibility_field",
]
