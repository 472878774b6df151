"""Output shared by the experiments."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Optional


def write_csv(
    path: Path, rows: list[dict[str, Any]], fieldnames: Optional[Sequence[str]] = None
) -> None:
    """``rows`` as CSV with a header: ``fieldnames``, or every key of the rows in the order
    they first appear (a row without a key leaves its cell empty)."""
    names = list(fieldnames or dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=names, restval="")
        w.writeheader()
        w.writerows(rows)
