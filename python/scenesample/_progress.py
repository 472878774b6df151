"""Progress bars for long work: a tqdm bar when tqdm is installed, nothing otherwise.

``progress=None`` (the default everywhere) shows a bar only once the work has run for
:data:`DELAY` seconds, so short calls stay silent; ``True`` shows it at once; ``False`` never;
a callable receives ``(done, total)`` instead of a bar. The Rust loops count real units (rays,
slab samples, cells, triangles) and the calling thread updates the bar while it polls for
Ctrl-C, so the bar costs the work nothing.
"""

from __future__ import annotations

from typing import Any, Callable, Optional, Union

from .errors import InputError

#: What every ``progress=`` argument takes: None, True, False, or ``f(done, total)``.
Progress = Union[None, bool, Callable[[int, int], Any]]

#: Seconds of work before an automatic bar (``progress=None``) appears.
DELAY = 2.0


class Bar:
    """A tqdm bar, a caller's ``f(done, total)``, or nothing. Use as a context manager;
    :attr:`callback` (``None`` when nobody listens) takes ``(done, total)`` from the Rust side,
    from the calling thread, at least once at the end (also when the work was interrupted);
    :meth:`update` counts steps."""

    def __init__(self, progress: Progress, desc: str, unit: str, total: int = 0) -> None:
        self._bar: Any = None
        self._fn: Optional[Callable[[int, int], Any]] = None
        self._n, self._total = 0, total
        if callable(progress) and not isinstance(progress, bool):
            self._fn = progress
            return
        if progress not in (None, True, False):
            raise InputError(
                f"progress must be None, True, False or a callable f(done, total), got {progress!r}"
            )
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
    def callback(self) -> Optional[Callable[[int, int], Any]]:
        if self._fn is not None:
            return self._fn
        return None if self._bar is None else self._to

    def _to(self, done: int, total: int) -> None:
        if total and self._bar.total != total:
            # No refresh here: that would show a bar that is still waiting out its delay.
            self._bar.total = total
        if done > self._bar.n:
            self._bar.update(done - self._bar.n)

    def update(self, n: int = 1) -> None:
        self._n += n
        if self._fn is not None:
            self._fn(self._n, self._total)
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


def steps(items: Any, desc: str, unit: str, progress: Progress = None) -> Any:
    """Iterate over ``items`` with a :class:`Bar` counting them (the experiments' outer loops)."""
    items = list(items)
    with Bar(progress, desc, unit, total=len(items)) as bar:
        for x in items:
            yield x
            bar.update(1)
