"""Progress bars for long work: a tqdm bar when tqdm is installed, nothing otherwise.

``progress=None`` (the default everywhere) shows a bar only once the work has run for
:data:`DELAY` seconds, so short calls stay silent; ``True`` shows it at once; ``False`` never.
The Rust loops count real units (slab samples, cells, triangles) and the calling thread
updates the bar while it polls for Ctrl-C, so the bar costs the work nothing.
"""

from __future__ import annotations

from typing import Any, Callable, Optional

from .errors import InputError

#: Seconds of work before an automatic bar (``progress=None``) appears.
DELAY = 2.0


class Bar:
    """A tqdm bar, or nothing. Use as a context manager; :attr:`callback` (``None`` when no bar
    is shown) takes ``(done, total)`` from the Rust side; :meth:`update` counts steps."""

    def __init__(self, progress: Optional[bool], desc: str, unit: str, total: int = 0) -> None:
        if progress not in (None, True, False):
            raise InputError(f"progress must be None, True or False, got {progress!r}")
        self._bar: Any = None
        if progress is False:
            return
        try:
            from tqdm.auto import tqdm
        except ImportError:
            return
        self._bar = tqdm(
            total=total or None,
            desc=desc,
            unit=unit,
            delay=0.0 if progress else DELAY,
            leave=bool(progress),
        )

    @property
    def callback(self) -> Optional[Callable[[int, int], None]]:
        return None if self._bar is None else self._to

    def _to(self, done: int, total: int) -> None:
        if total and self._bar.total != total:
            self._bar.total = total
            self._bar.refresh()
        if done > self._bar.n:
            self._bar.update(done - self._bar.n)

    def update(self, n: int = 1) -> None:
        if self._bar is not None:
            self._bar.update(n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> Bar:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def steps(items: Any, desc: str, unit: str, progress: Optional[bool] = None) -> Any:
    """Iterate over ``items`` with a :class:`Bar` counting them (the experiments' outer loops)."""
    items = list(items)
    with Bar(progress, desc, unit, total=len(items)) as bar:
        for x in items:
            yield x
            bar.update(1)
