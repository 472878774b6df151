"""Reproductions of the papers' tables and figures: ``python -m scenesample.experiments NAME``.

- ``sampling``: non-redundant-rendering.txt Tables 1 and 2, Fig. 6 and Fig. 7.
"""
