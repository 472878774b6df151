"""``python -m scenesample.experiments NAME``: runs :mod:`scenesample.tools.experiments` (the
tools live apart from the methods, in :mod:`scenesample.tools`)."""
