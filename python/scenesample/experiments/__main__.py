"""``python -m scenesample.experiments NAME``: the papers' tables and figures
(:mod:`scenesample.tools.experiments`)."""

from ..tools.experiments.__main__ import main

if __name__ == "__main__":
    main()
