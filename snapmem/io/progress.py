"""The progress display of long commands (trace, fold, simulate, sweep): one line on stderr.

On a terminal the line is redrawn in place; written to a file or a pipe (a batch job's log) it
appears as a new line at long intervals, or not at all, so that a log is not flooded with
redraws. Callers compose the text (steps, simulated time, designs per second) and may use
:func:`bar` and :func:`duration` for it.
"""

from __future__ import annotations

import math
import sys
import time


class Progress:
    """A one-line progress display.

    Parameters
    ----------
    enabled : bool
        False: nothing is ever written.
    stream : text stream, optional
        Where the line goes (default ``sys.stderr``).
    interval : float
        On a terminal, the shortest time between two redraws [s].
    file_interval : float or None
        On a file or pipe, the shortest time between two lines [s]; None writes nothing there.
    """

    def __init__(self, enabled: bool = True, stream=None, interval: float = 0.2,
                 file_interval: float | None = 10.0):
        self.stream = sys.stderr if stream is None else stream
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.enabled = bool(enabled) and (self.tty or file_interval is not None)
        self.interval = interval if self.tty else file_interval
        self.start = self.last = time.monotonic()
        self.text = None                 # the latest text given to show()
        self.drawn = True                # whether that text is on the stream

    @property
    def elapsed(self) -> float:
        """Wall time since the display was made [s]."""
        return time.monotonic() - self.start

    def show(self, text: str, force: bool = False):
        """Make ``text`` the current line; draw it if ``force`` or if the last draw is old enough."""
        self.text, self.drawn = text, False
        if not self.enabled:
            return
        now = time.monotonic()
        if force or now - self.last >= self.interval:
            self.last = now
            self._draw()

    def _draw(self):
        self.stream.write(f"\r{self.text}\033[K" if self.tty else self.text + "\n")
        self.stream.flush()
        self.drawn = True

    def close(self):
        """Draw the latest line if it is not shown yet, and end the line on a terminal."""
        if not self.enabled or self.text is None:
            return
        if not self.drawn:
            self._draw()
        if self.tty:
            self.stream.write("\n")
        self.stream.flush()


def bar(fraction: float, width: int, full: str = "#", empty: str = "-") -> str:
    """``fraction`` (0 to 1) of ``width`` characters filled: ``bar(0.5, 4) == '##--'``."""
    filled = int(width * min(max(fraction, 0.0), 1.0))
    return full * filled + empty * (width - filled)


def duration(seconds: float) -> str:
    """A duration as '42s', '3m07s' or '2h05m'; '?' when not finite."""
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{s:02d}s" if m else f"{s}s")
