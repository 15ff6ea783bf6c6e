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
import sys
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any, NoReturn

__all__ = ["check", "deferred", "handling", "interrupt", "pending", "record"]

#: SIGINTs recorded inside :func:`handling`; None outside it.
_recorded: list[int] | None = None
#: Whether the first SIGINT's KeyboardInterrupt was raised where it propagates.
_raised = False
#: The ``sys.unraisablehook`` :func:`handling` replaced.
_hooks: list[Any] = []


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
    global _raised
    first = not _raised
    record()
    if first:  # later ones only count: the cleanup after the first must finish
        _raised = True
        raise KeyboardInterrupt


def _ignored(args: Any) -> None:
    """``sys.unraisablehook`` inside :func:`handling`.

    A SIGINT that arrives while Python runs a weakref callback or a ``__del__`` (the
    import system's lock clean-up, for one) raises its KeyboardInterrupt where Python
    ignores exceptions: it would print "Exception ignored ... Traceback" and go on. The
    interrupt is recorded, so the next :func:`check` raises it (every LMI solve, every
    part of a study, every output committed asks); such a KeyboardInterrupt is not
    printed, and the next SIGINT raises again. Anything else goes to the previous hook.
    """
    global _raised
    if isinstance(args.exc_value, KeyboardInterrupt) and _recorded is not None:
        _raised = False
        return
    _hooks[-1](args)


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
    global _recorded, _raised
    if _recorded is not None or not _main_thread():
        yield
        return
    previous: Any = signal.getsignal(signal.SIGINT)
    _recorded, _raised = [], False
    _hooks.append(sys.unraisablehook)
    sys.unraisablehook = _ignored
    try:
        signal.signal(signal.SIGINT, _on_sigint)
        yield
    finally:
        if then_ignore:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        else:  # None: a handler not set from Python, which cannot be put back
            signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)
        sys.unraisablehook = _hooks.pop()
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
        global _raised
        _raised = True  # as the handler's first raise: later SIGINTs are only recorded
        raise KeyboardInterrupt
