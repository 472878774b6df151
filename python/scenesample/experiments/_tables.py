"""Output shared by the experiments."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Optional


def write_csv(
    path: Path, rows: list[dict[str, Any]], fieldnames: Optional[Sequence[str]] = None
) -> None:
    """``rows`` as CSV with a header: ``fieldnames``, or the first row's keys."""
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(fieldnames or rows[0]))
        w.writeheader()
        w.writerows(rows)
