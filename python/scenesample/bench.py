"""``python -m scenesample.bench``: runs :mod:`scenesample.tools.bench` (the tools live apart
from the methods, in :mod:`scenesample.tools`)."""

from .tools.bench import main

if __name__ == "__main__":
    main()
