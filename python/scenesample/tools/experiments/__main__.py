"""``python -m scenesample.experiments
{sampling,shadows,reconstruction,epr,epr_animation,visibility_field,impostors,viewers}
[options]``; see each module."""

from __future__ import annotations

import argparse
from typing import Optional

from . import (
    epr,
    epr_animation,
    impostors,
    reconstruction,
    sampling,
    shadows,
    viewers,
    visibility_field,
)

EXPERIMENTS = {
    "sampling": sampling,
    "shadows": shadows,
    "reconstruction": reconstruction,
    "epr": epr,
    "epr_animation": epr_animation,
    "visibility_field": visibility_field,
    "impostors": impostors,
    "viewers": viewers,
}


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(prog="python -m scenesample.experiments")
    p.add_argument("experiment", choices=sorted(EXPERIMENTS))
    known, rest = p.parse_known_args(argv)
    EXPERIMENTS[known.experiment].main(rest)


if __name__ == "__main__":
    main()
