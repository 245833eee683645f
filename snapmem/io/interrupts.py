"""Interrupts (SIGINT, Ctrl-C, and SIGTERM, which is handled the same way) taken where it is safe.

Python runs a signal's handler between two bytecodes, so an interrupt can land anywhere: inside
a compiled kernel (where a KeyboardInterrupt comes back as ``SystemError``), halfway through
writing a file, between two files of one result. :class:`HeldInterrupts` replaces the handlers
while a block runs: the first signal is only noted (``received``), and the code polls it where
stopping is safe (between two time steps, after the last file of a set is in place). A second
signal raises ``KeyboardInterrupt`` at once, for a user who does not want to wait.

:func:`sigterm_as_interrupt` makes SIGTERM raise ``KeyboardInterrupt`` like SIGINT does (the
command line installs it), so ``kill PID`` ends a run as Ctrl-C does: cleaned up, exit 130.
"""

from __future__ import annotations

import contextlib
import signal
import threading

#: The signals treated as an interrupt.
SIGNALS = tuple(s for s in (signal.SIGINT, getattr(signal, "SIGTERM", None)) if s is not None)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class HeldInterrupts:
    """Within the block, SIGINT and SIGTERM are noted, not raised; a second one raises at once.

    Outside the main thread (where handlers cannot be set) it does nothing, and a signal the
    process ignores (a sweep's worker ignores SIGINT: its parent handles it) stays ignored.

    Attributes
    ----------
    received : int or None
        The first signal received in the block (its number), None if none.
    """

    def __init__(self):
        self.received = None
        self._previous = {}

    def _handler(self, signum, frame):
        if self.received is not None:
            raise KeyboardInterrupt
        self.received = signum

    def __enter__(self) -> "HeldInterrupts":
        if _main_thread():
            for sig in SIGNALS:
                if signal.getsignal(sig) is signal.SIG_IGN:     # ignored here (a sweep's worker): stays so
                    continue
                self._previous[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc) -> bool:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous = {}
        return False


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


@contextlib.contextmanager
def sigterm_as_interrupt():
    """Within the block SIGTERM raises ``KeyboardInterrupt``, as SIGINT does."""
    sig = getattr(signal, "SIGTERM", None)
    if sig is None or not _main_thread():
        yield
        return
    previous = signal.signal(sig, _raise_interrupt)
    try:
        yield
    finally:
        signal.signal(sig, previous)
