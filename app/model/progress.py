"""Time left of a long job, one rule for every progress display (the app's and the CLI's). Qt-free.

The rate is measured over the last few steps only (:attr:`TimeLeft.WINDOW`): steps that went
by instantly at the start — captures a resumed session already holds — leave the window
after a few real ones instead of promising a finish that never comes.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable


class TimeLeft:
    """Estimate the seconds left from ``(step, total)`` reports.

    Parameters
    ----------
    clock : callable
        Seconds, monotonic (tests pass a fake one).

    Examples
    --------
    >>> now = [0.0]
    >>> eta = TimeLeft(clock=lambda: now[0])
    >>> eta.update(0, 10) is None  # no step done yet: no rate
    True
    >>> now[0] = 2.0; eta.update(1, 10)
    18.0
    """

    #: Steps the rate is measured over.
    WINDOW = 8

    def __init__(self, *, clock: Callable[[], float] = time.monotonic):
        self.clock = clock
        self.reset()

    def reset(self) -> None:
        """Forget every report (a new run)."""
        self._seen: deque[tuple[float, int]] = deque(maxlen=self.WINDOW + 1)
        self.seconds: float | None = None

    def update(self, step: int, total: int) -> float | None:
        """Record a report; returns the seconds left, or None while the rate is unknown."""
        now, step = self.clock(), int(step)
        if not self._seen or step != self._seen[-1][1]:
            self._seen.append((now, step))
        (t0, s0), (t1, s1) = self._seen[0], self._seen[-1]
        self.seconds = None
        if s1 > s0 and t1 > t0:
            self.seconds = max(int(total) - step, 0) * (t1 - t0) / (s1 - s0)
        return self.seconds


def format_duration(seconds: float) -> str:
    """Short, human duration: ``"<1 s"``, ``"42 s"``, ``"3 min 05 s"``, ``"2 h 07 min"``.

    Examples
    --------
    >>> [format_duration(s) for s in (0.2, 42, 185, 7625)]
    ['<1 s', '42 s', '3 min 05 s', '2 h 07 min']
    """
    s = max(float(seconds), 0.0)
    if s < 1:
        return "<1 s"
    if s < 60:
        return f"{s:.0f} s"
    if s < 3600:
        m, r = divmod(int(round(s)), 60)
        return f"{m} min {r:02d} s"
    h, r = divmod(int(round(s)), 3600)
    return f"{h} h {r // 60:02d} min"
