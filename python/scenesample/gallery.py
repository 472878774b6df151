"""``python -m scenesample.gallery``: runs :mod:`scenesample.tools.gallery` (the tools live apart
from the methods, in :mod:`scenesample.tools`)."""

from .tools.gallery import main

if __name__ == "__main__":
    main()
