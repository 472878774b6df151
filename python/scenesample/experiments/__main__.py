"""``python -m scenesample.experiments {sampling,shadows,epr} [options]``; see each module."""

from __future__ import annotations

import argparse
from typing import Optional

from . import epr, sampling, shadows

EXPERIMENTS = {"sampling": sampling, "shadows": shadows, "epr": epr}


def main(argv: Optional[list[str]] = None) -> None:
    p = argparse.ArgumentParser(prog="python -m scenesample.experiments")
    p.add_argument("experiment", choices=sorted(EXPERIMENTS))
    known, rest = p.parse_known_args(argv)
    EXPERIMENTS[known.experiment].main(rest)


if __name__ == "__main__":
    main()
