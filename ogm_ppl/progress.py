"""Progress of long runs: a tqdm bar on an interactive terminal, plain lines otherwise.

A run whose output goes to a log file or a pipe (a batch job, ``make run > log``, CI) gets no bar (its
carriage returns make logs unreadable) but one line at the start, one at most every ``every`` seconds while
it runs and one at the end::

    tasks: 0/40 (0 %), 0 s
    tasks: 7/40 (18 %), 63 s, ~5 min left; last: run/office/gibbs-border-L9/c1
    tasks: 40/40 (100 %), 371 s, done

>>> import io
>>> s = io.StringIO()
>>> with Progress(3, "tasks", stream=s, every=0.0) as p:
...     p.update(note="a"); p.update(); p.update()
>>> s.getvalue().splitlines()[0], s.getvalue().splitlines()[-1].endswith("done")
('tasks: 0/3 (0 %), 0 s', True)
"""

from __future__ import annotations

import contextlib
import sys
import time
from typing import IO

__all__ = ["Progress", "interactive", "progress_over"]


def interactive(stream: IO | None = None) -> bool:
    """Whether ``stream`` (default ``sys.stderr``) is an interactive terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _duration(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.0f} min"


class Progress:
    """Progress over ``total`` steps: tqdm when ``stream`` is a terminal, plain lines otherwise.

    Args:
        total: number of steps.
        desc: what is counted (the line's prefix).
        unit: tqdm's unit.
        enabled: ``False`` prints nothing.
        every: seconds between plain lines (the first and last lines always print).
        stream: where to write (default ``sys.stderr``).
        bar: force the tqdm bar (``True``) or plain lines (``False``); default: :func:`interactive`.
        initial: steps done before (a resumed run); the time left is estimated from this run's steps.
        after: plain lines only: the first line waits this many seconds, and a run that ends sooner prints
            nothing (a sampler's short runs stay quiet in logs and pipes).
    """

    def __init__(
        self,
        total: int,
        desc: str,
        *,
        unit: str = "task",
        enabled: bool = True,
        every: float = 10.0,
        stream: IO | None = None,
        bar: bool | None = None,
        initial: int = 0,
        after: float = 0.0,
    ) -> None:
        self.total, self.desc, self.enabled, self.every = int(total), desc, bool(enabled), float(every)
        self.stream = sys.stderr if stream is None else stream
        self.done = self.initial = int(initial)
        self._t0 = time.perf_counter()
        self._first: tuple[float, int] | None = None  # time and count after the first update: the pace after it
        self._last = -float("inf")
        self._printed = False
        self._bar = None
        if not self.enabled:
            return
        if interactive(self.stream) if bar is None else bar:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=self.total, initial=self.initial, desc=desc, unit=unit, file=self.stream)
        elif after > 0:
            self._last = self._t0 + after - self.every  # the first line once ``after`` seconds have passed
        else:
            self._line()

    def _line(self, note: str = "", final: bool = False) -> None:
        el = time.perf_counter() - self._t0
        pct = 100.0 * self.done / self.total if self.total else 100.0
        parts = [f"{self.desc}: {self.done}/{self.total} ({pct:.0f} %), {_duration(el)}"]
        if final:
            parts.append("done" if self.done >= self.total else "stopped")
        elif self._first is not None and self._first[1] < self.done < self.total:  # a pace after the first step
            t1, n1 = self._first
            per_step = (time.perf_counter() - t1) / (self.done - n1)
            parts.append(f"~{_duration(per_step * (self.total - self.done))} left")
        line = ", ".join(parts) + (f"; last: {note}" if note and not final else "")
        print(line, file=self.stream, flush=True)
        self._last = time.perf_counter()
        self._printed = True

    def update(self, n: int = 1, note: str = "") -> None:
        """``n`` more steps done; ``note`` (e.g. the task's name) goes into the next plain line."""
        self.done += int(n)
        if self._first is None:
            self._first = (time.perf_counter(), self.done)
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(n)
        elif time.perf_counter() - self._last >= self.every and self.done < self.total:
            self._line(note)

    def close(self) -> None:
        """The last line (plain mode) or closing the bar."""
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self._last != float("inf"):
            if self._printed:  # a run quieted by ``after`` that ended sooner prints nothing
                self._line(final=True)
            self._last = float("inf")

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def progress_over(
    progress: bool | Progress, total: int, desc: str, *, unit: str, initial: int = 0
) -> contextlib.AbstractContextManager[Progress]:
    """A context giving the :class:`Progress` of a run of ``total`` ``unit``: the caller's own (``progress`` a
    ``Progress``, which the run updates and leaves open: one chain run in several calls), or a new one (shown
    if ``progress`` is true; plain lines once the run has taken 10 s), closed at the end."""
    if isinstance(progress, Progress):
        return contextlib.nullcontext(progress)
    return Progress(total, desc, unit=unit, enabled=bool(progress), initial=initial, after=10.0)
