"""Plots of scenesample's tables (matplotlib, imported when called)."""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from ._optional import require
from .errors import InputError

__all__ = ["tradeoff"]


def _column(table: Any, name: str) -> np.ndarray:
    try:
        return np.asarray(table[name])
    except (KeyError, ValueError, IndexError):
        raise InputError(f"the table has no column {name!r}") from None


def tradeoff(table: Any, *, ax: Optional[Any] = None, label: Optional[str] = None) -> Any:
    """Error against time of a :func:`scenesample.tradeoff` table (DataFrame or structured
    array), every setting a point labelled by its knobs, the Pareto front joined and
    highlighted. Returns the matplotlib Axes."""
    plt = require("matplotlib.pyplot", "scenesample.plot")

    err, sec, front = (_column(table, k) for k in ("error", "seconds", "pareto"))
    names = list(table.columns) if hasattr(table, "columns") else list(table.dtype.names)
    knobs = names[: names.index("error")]
    if ax is None:
        _, ax = plt.subplots(figsize=(6.5, 4.2))
    ax.scatter(sec[~front], err[~front], color="0.6", s=18, label="settings")
    order = np.argsort(sec[front])
    ax.plot(
        sec[front][order],
        err[front][order],
        "o-",
        color="C3",
        label="Pareto front" if label is None else label,
    )
    for i in np.flatnonzero(front):
        text = ", ".join(f"{k}={_column(table, k)[i]}" for k in knobs)
        ax.annotate(text, (sec[i], err[i]), fontsize=7, xytext=(4, 4), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_xlabel("seconds")
    attrs = getattr(table, "attrs", {})
    ax.set_ylabel(attrs.get("error", "error"))
    ax.set_title(f"accuracy vs time: {attrs.get('effect', '')}".rstrip(": "))
    ax.legend(fontsize=8)
    return ax
