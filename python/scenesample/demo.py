"""``python -m scenesample.demo``: runs :mod:`scenesample.tools.demo` (the tools live apart
from the methods, in :mod:`scenesample.tools`)."""

from .tools.demo import main

if __name__ == "__main__":
    main()
