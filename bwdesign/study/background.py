"""Work done beside the main process: a forked child computes a list of tasks meanwhile.

The report's slow parts that do not depend on each other (the per-tier synthesis beside
the certificates, the tuning and the tracking runs: :data:`bwdesign.study.compute.BESIDE`;
the robust section's loops beside the baselines; half the figures beside the other
half) run on a second core: :class:`Background` forks a child that runs its tasks in
order and sends each result back (pickled) as soon as it has it, while this process goes
on with its own work and asks for a result when it needs it. :class:`Split` shares a
list of tasks between a child and this process, or between two children while this
process goes on.

The child is a copy of this process at the fork, so it computes exactly what this
process would: a result it sends is the very value computed here. Anything that goes
wrong in the child (an exception, a result that does not pickle, the child killed)
only means the result is not delivered; :meth:`Background.result` then answers
``(False, None)`` and the caller computes the task itself, so errors are raised here,
as without the child. The child ignores Ctrl-C (it is killed by :meth:`close`, which
the caller runs in a ``finally``) and never runs this process's exit handlers.

Only where :func:`os.fork` exists and is safe enough (Linux); elsewhere
:func:`start` returns ``None`` and the caller works alone.
"""

from __future__ import annotations

import io
import os
import pickle
import signal
from collections.abc import Callable, Sequence
from typing import Any

from ..sim import kernel_process

__all__ = ["Background", "Pending", "Split", "start", "available", "split"]


def available() -> bool:
    """True where a background child can be forked: Linux, and no other Python thread runs
    (:func:`bwdesign.sim.kernel_process.fork_is_safe`)."""
    return kernel_process.fork_is_safe()


def start(tasks: Sequence[tuple[str, Callable[[], Any]]]) -> Background | None:
    """A :class:`Background` running ``tasks``, or ``None`` (no task, or no fork here)."""
    if not tasks or not available():
        return None
    try:
        return Background(tasks)
    except OSError:  # no process or pipe to be had: the caller works alone
        return None


def split(tasks: Sequence[tuple[str, Callable[[], Any]]], *, here: bool = True) -> list[Any]:
    """The values of ``tasks`` (``(key, function)`` pairs, distinct keys) in their order,
    every second task computed meanwhile by a forked child where one can be forked
    (:func:`available`); the values are the same either way.

    ``here=False``: the other tasks too are computed by a child of their own while this
    process waits, so what they allocate is not added to this process's memory (a
    child's resident memory starts below its parent's). The error is the one computing
    the tasks in order meets first: a task computed here that raises is raised in its
    turn, after the tasks before it; a task a child did not deliver (it raised there, or
    the child is gone) is computed here then.
    """
    return Split(tasks, here=here).values()


class Split:
    """:func:`split` begun: with ``here=False`` the children are at work as it returns,
    and :meth:`values` (called once) collects their values while this process went on
    meanwhile; :meth:`close` stops them (the values not needed)."""

    def __init__(self, tasks: Sequence[tuple[str, Callable[[], Any]]], *, here: bool) -> None:
        self.tasks = list(tasks)
        self.mine = list(tasks[0::2])
        self.children: list[Background] = []
        if len(self.tasks) < 2:
            self.mine = self.tasks
            return
        other = start(self.tasks[1::2])
        second = start(self.mine) if other is not None and not here else None
        self.children = [c for c in (other, second) if c is not None]
        if other is None:  # no child: this process computes every task
            self.mine = self.tasks
        elif second is not None:
            self.mine = []

    def values(self) -> list[Any]:
        """The tasks' values in order (the error computing them in order meets first)."""
        alone = not self.children
        done: dict[str, tuple[bool, Any]] = {}
        try:
            for key, task in self.mine:
                try:
                    done[key] = (True, task())
                except Exception as exc:  # noqa: BLE001 - raised in its turn below
                    done[key] = (False, exc)
                    if alone:
                        break  # working alone: the tasks after it are not needed
            out = []
            for key, task in self.tasks:
                if key in done:
                    ok, value = done[key]
                    if not ok:
                        raise value
                    out.append(value)
                    continue
                got, value = False, None
                for child in self.children:
                    if key in child.keys:
                        got, value = child.result(key)
                out.append(value if got else task())
            return out
        finally:
            self.close()

    def close(self) -> None:
        """Stop and reap the children (if any still run)."""
        for child in self.children:
            child.close()


class Pending:
    """A value being computed beside this process: :meth:`result` (called once) waits for
    it and gives it, :meth:`close` gives it up (stopping what computes it)."""

    def __init__(self, result: Callable[[], Any], close: Callable[[], None]) -> None:
        self.result = result
        self.close = close


class Background:
    """A forked child running ``tasks`` (``(key, function)`` pairs) in order.

    The results are read from the child's pipe when asked for (:meth:`result`), in this
    thread: this process runs no thread for the child, so it may fork again meanwhile
    (:func:`available`). A value larger than the pipe holds (64 KB) waits in the child
    until it is asked for; the report's values are a few KB.

    Parameters
    ----------
    tasks : sequence of (str, callable)
        Each function is called without arguments in the child; its value is sent back.
        The child stops at the first task that raises or whose value does not pickle.
    """

    def __init__(self, tasks: Sequence[tuple[str, Callable[[], Any]]]) -> None:
        self.keys = tuple(k for k, _ in tasks)
        self._results: dict[str, Any] = {}
        fd, write = os.pipe()
        try:
            pid = kernel_process.fork()  # streams flushed, SIGINT blocked in the child
        except OSError:
            os.close(fd)
            os.close(write)
            raise
        if pid == 0:  # the child (SIGINT stays blocked): never returns
            os.close(fd)
            _child(tasks, write)
        self.pid = pid
        os.close(write)
        self._pipe: io.BufferedReader | None = open(fd, "rb")  # closed by close()

    def result(self, key: str) -> tuple[bool, Any]:
        """``(True, value)`` once the child sent ``key``; ``(False, None)`` if it never will."""
        while key not in self._results and self._pipe is not None:
            try:
                got, value = pickle.load(self._pipe)
            except Exception:  # noqa: BLE001 - the end of the pipe (the child is done or gone)
                self._end_pipe()
                break
            self._results[got] = value
        if key in self._results:
            return True, self._results.pop(key)
        return False, None

    def _end_pipe(self) -> None:
        if self._pipe is not None:
            self._pipe.close()
            self._pipe = None

    def close(self) -> None:
        """Stop the child (if still running) and reap it."""
        if self.pid:
            try:
                pid, _ = os.waitpid(self.pid, os.WNOHANG)
                if pid == 0:
                    os.kill(self.pid, signal.SIGKILL)
                    os.waitpid(self.pid, 0)
            except ChildProcessError:
                pass
            self.pid = 0
        self._end_pipe()

    def __enter__(self) -> Background:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _child(tasks: Sequence[tuple[str, Callable[[], Any]]], fd: int) -> None:
    """Run ``tasks``, writing ``(key, value)`` pickles to ``fd``; exit without cleanup."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        with open(fd, "wb", buffering=0) as out:
            for key, task in tasks:
                buf = io.BytesIO()
                pickle.dump((key, task()), buf, protocol=pickle.HIGHEST_PROTOCOL)
                data = memoryview(buf.getvalue())
                while data:  # a raw write to a pipe may take only part of it
                    data = data[out.write(data) :]
    except BaseException:  # noqa: BLE001 - any failure: the parent computes it itself
        code = 1
    finally:
        os._exit(code)
