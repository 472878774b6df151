"""Reproductions of the papers' tables and figures: ``python -m scenesample.experiments NAME``.

- ``sampling``: non-redundant-rendering.txt Tables 1 and 2, Fig. 6 and Fig. 7.
- ``shadows``: non-redundant-rendering.txt Tables 3-5, Figs. 8 and 9.
- ``epr``: eye-based-point-rendering.txt Tables 1-2, Figs. 6 and 7.
"""
