"""Ctrl-C (SIGINT) that always cancels: remembered, never swallowed, never half-handled.

Python turns SIGINT into :class:`KeyboardInterrupt`, but a library can lose it:
SCS installs its own SIGINT handler while it solves and reports the interrupt
as a failed solve (which the LMI layer would answer by moving on), and code
that catches broad exceptions can eat the KeyboardInterrupt itself. So the
command line runs inside :func:`handling`, whose handler *records* every
SIGINT before it raises; the places that must not continue after one ask
:func:`check` (after every solver call, before an output is committed, before
the command's exit code is returned). A solver that reports having caught a
SIGINT itself calls :func:`interrupt`.

:func:`deferred` is for starting helper processes (Dask's workers): they
inherit a blocked SIGINT, so a Ctrl-C at the terminal (sent to the whole
process group) reaches only this process, which then shuts them down, and
this process raises it when the block ends.

Outside :func:`handling` (bwdesign used as a library) nothing is recorded:
Python's own handling applies, and :func:`check` never raises.

Limit: a Ctrl-C while the interpreter itself starts (its ``site`` import, the
first ~20-50 ms, before any bwdesign code runs) is Python's: it prints a
traceback. From ``import bwdesign.cli`` on (about 20 ms more: ``import
bwdesign`` loads its API on first use) the entry points handle it.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any, NoReturn

__all__ = ["check", "deferred", "handling", "interrupt", "pending", "record"]

#: SIGINTs recorded inside :func:`handling`; None outside it.
_recorded: list[int] | None = None


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def record() -> None:
    """Remember an interrupt (inside :func:`handling`; a no-op outside it)."""
    if _recorded is not None:
        _recorded.append(signal.SIGINT)


def pending() -> bool:
    """True once an interrupt was recorded inside the current :func:`handling` block."""
    return bool(_recorded)


def check() -> None:
    """Raise :class:`KeyboardInterrupt` if an interrupt was recorded (and swallowed since)."""
    if pending():
        raise KeyboardInterrupt


def interrupt() -> NoReturn:
    """Record an interrupt that a library caught itself, and raise it."""
    record()
    raise KeyboardInterrupt


def _on_sigint(signum: int, frame: FrameType | None) -> None:
    first = not pending()
    record()
    if first:  # later ones only count: the cleanup after the first must finish
        raise KeyboardInterrupt


@contextlib.contextmanager
def handling(*, then_ignore: bool = False) -> Iterator[None]:
    """Record every SIGINT while the block runs; the first one raises KeyboardInterrupt.

    Later SIGINTs are recorded only, so that the cleanup the first one started
    (removing a staging directory, closing a cluster) is not cut short. On exit
    the previous handler is restored, or SIGINT is ignored (``then_ignore``:
    the process only exits from here on, and a late Ctrl-C must not print a
    traceback). Re-entering while active, or outside the main thread, does not
    install anything.
    """
    global _recorded
    if _recorded is not None or not _main_thread():
        yield
        return
    previous: Any = signal.getsignal(signal.SIGINT)
    _recorded = []
    try:
        signal.signal(signal.SIGINT, _on_sigint)
        yield
    finally:
        if then_ignore:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        else:  # None: a handler not set from Python, which cannot be put back
            signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)
        _recorded = None


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """SIGINT blocked for this thread and every thread and process started in the block.

    Child processes started inside (through threads started inside, too) keep
    SIGINT blocked for their whole life: a Ctrl-C at the terminal does not
    reach them, their parent shuts them down. A SIGINT for this process that
    arrives meanwhile is raised as :class:`KeyboardInterrupt` when the block
    ends (in the main thread; in another thread Python never raises it there).
    """
    from multiprocessing import resource_tracker

    # Started now: the first process a thread spawns starts multiprocessing's
    # resource tracker, which *unblocks* SIGINT in that thread afterwards
    # (CPython 3.11-3.13), so later children of that thread would see Ctrl-C.
    resource_tracker.ensure_running()
    seen: list[int] = []
    swap = _main_thread() and signal.getsignal(signal.SIGINT) is not None
    previous: Any = None
    if swap:

        def remember(signum: int, frame: FrameType | None) -> None:
            seen.append(signum)
            record()

        previous = signal.signal(signal.SIGINT, remember)
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        if swap:
            signal.signal(signal.SIGINT, previous)
        # a SIGINT that waited for the unblock is delivered here, to ``previous``
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
    if seen and swap and previous is not signal.SIG_IGN:
        raise KeyboardInterrupt
