"""The compiled kernels run in a process of their own, started before the heavy imports.

numba brings LLVM: importing it and loading the batch kernels costs about 160 MB of
resident memory (LLVM's library alone about 95 MB), in whichever process runs them. A
command that needs a few batched runs beside scipy, python-control, cvxpy and matplotlib
(the report: its falsifier and baseline comparison) would carry both. :func:`running`
forks a small process at the start of such a command, while only the standard library
is loaded; *that* process imports numpy and the kernels (:mod:`bwdesign.sim.compiled`)
at once, on the core the command leaves idle while it imports the rest, and every batch
of the command is run there: the arrays go through a socket (pickled), the kernel runs
on them, the array it writes comes back.

The kernel process runs the very code this process would (the same compiled functions
on the same arrays, read from numba's same cache), so the results are the same to the
bit (tested). Anything that goes wrong there (the process killed, an exception, a
connection closed) only means that run is done here instead (:func:`run` then imports
the kernels in this process), so errors are raised here, as without it. A process
forked later from the one that started it (:mod:`bwdesign.study.background`'s child)
connects on its first batch and is served too, one request at a time; a client that
dies mid-request only loses its own connection. Started only where a fork is safe
(:func:`fork_is_safe`). The kernel process ignores Ctrl-C, is killed when the block
ends (and stops by itself if the process that started it is gone), and never runs
this process's exit handlers.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import secrets
import select
import signal
import socket
import struct
import sys
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["fork_is_safe", "fork", "running", "run", "active"]


def fork_is_safe() -> bool:
    """True where a child can be forked: Linux, and no other Python thread runs.

    A fork copies only the thread that calls it; a lock another thread held at that
    moment would stay locked in the child, so a process running other threads (a test
    runner's, a GUI's) works alone.
    """
    return (
        sys.platform.startswith("linux")
        and hasattr(os, "fork")
        and threading.current_thread() is threading.main_thread()
        and threading.active_count() == 1
    )


def fork() -> int:
    """``os.fork()`` for a child that works beside this process: the standard streams
    flushed first (nothing buffered is written twice), SIGINT blocked across the fork and
    left blocked in the child (0 returned there; it ignores Ctrl-C, its parent ends it),
    restored here. ``OSError`` (no process to be had) with the mask restored."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError, AttributeError):  # closed or None
            stream.flush()
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        pid = os.fork()
    except OSError:
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        raise
    if pid != 0:  # here: as before; the child keeps SIGINT blocked
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
    return pid


class _Process:
    """The forked kernel process and its address (a Linux abstract-namespace socket: no
    file). Each process that asks (the one that forked it, or a child forked from that
    one later) gets a connection of its own, so one that dies mid-request harms no other."""

    def __init__(self) -> None:
        self.owner = os.getpid()
        self.address = f"\0bwdesign-kernels-{self.owner}-{secrets.token_hex(8)}"
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            listener.bind(self.address)
            listener.listen(8)
        except OSError:
            listener.close()
            raise
        try:
            pid = fork()
        except OSError:
            listener.close()
            raise
        if pid == 0:  # the kernel process (SIGINT stays blocked): never returns
            _serve(listener, self.owner)
        listener.close()
        self.pid = pid
        self.connections: dict[int, Any] = {}  # pid -> its connection's file
        self.broken: set[int] = set()  # pids whose connection failed: they work alone
        self.lock = threading.Lock()

    def _connection(self) -> Any:
        me = os.getpid()
        if me not in self.connections:
            conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            conn.connect(self.address)
            self.connections[me] = conn.makefile("rwb")
            conn.close()  # the file keeps the socket open
        return self.connections[me]

    def call(self, name: str, args: tuple, out: int) -> Any:
        """The array ``args[out]`` after ``compiled.<name>(*args)`` in the kernel process,
        or None (the process is gone or the call failed there: run it here)."""
        if os.getpid() in self.broken:
            return None
        with self.lock:
            try:
                f = self._connection()
                pickle.dump((name, args, out), f, protocol=pickle.HIGHEST_PROTOCOL)
                f.flush()
                ok, value = pickle.load(f)
            except Exception:  # noqa: BLE001 - connection refused or closed: work alone
                self.broken.add(os.getpid())
                return None
        return value if ok else None

    def close(self) -> None:
        """End the kernel process and reap it (in the process that started it)."""
        for f in self.connections.values():
            with contextlib.suppress(OSError):
                f.close()
        self.connections.clear()
        if os.getpid() != self.owner:
            return
        try:  # it keeps nothing: stopped at once
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        except (ChildProcessError, ProcessLookupError):
            pass


def _preload() -> None:
    """Import numpy and the kernels (numba) at once, before the first request: the
    command that forked this process spends its first second importing scipy, cvxpy and
    python-control on one core, and this import (about 0.6 s of CPU) then runs on the
    other instead of when the first batch waits for it. A failure here only means the
    first request imports them (and fails there the same way, answered as such)."""
    with contextlib.suppress(Exception):
        from . import compiled  # noqa: F401


def _answer(f: Any) -> bool:
    """Answer one ``(name, args, out)`` request on ``f``; False when the client is gone."""
    try:
        name, args, out = pickle.load(f)
    except Exception:  # noqa: BLE001 - closed, or died mid-request
        return False
    try:
        from . import compiled

        getattr(compiled, name)(*args)
        reply: tuple[bool, Any] = (True, args[out])
    except Exception as err:  # noqa: BLE001 - the caller runs it itself
        reply = (False, f"{type(err).__name__}: {err}")
    try:
        pickle.dump(reply, f, protocol=pickle.HIGHEST_PROTOCOL)
        f.flush()
    except OSError:
        return False
    return True


def _peer_uid(conn: socket.socket) -> int:
    """The user id of the process at the other end (``SO_PEERCRED``; -1 if unknown).

    An abstract socket's name is listed in ``/proc/net/unix`` for every user to see, and
    a request is a pickle, which runs code when loaded: only a process of this user (who
    can run code as this user anyway) is answered.
    """
    try:
        cred = conn.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
        return struct.unpack("3i", cred)[1]
    except (OSError, AttributeError, struct.error):
        return -1


def _serve(listener: socket.socket, owner: int) -> None:
    """Answer requests, one at a time, on every connection, while ``owner`` lives; exit
    without cleanup."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        _preload()
        clients: dict[Any, Any] = {}  # socket -> its file
        while os.getppid() == owner:  # orphaned (the owner was killed): stop
            ready, _, _ = select.select([listener, *clients], [], [], 1.0)
            for sock in ready:
                if sock is listener:
                    conn, _ = listener.accept()
                    if _peer_uid(conn) != os.getuid():  # another user's process: refused
                        conn.close()
                        continue
                    clients[conn] = conn.makefile("rwb")
                elif not _answer(clients[sock]):
                    clients.pop(sock).close()
                    sock.close()
    except BaseException:  # noqa: BLE001 - the clients work alone from here
        code = 1
    finally:
        os._exit(code)


_active: _Process | None = None


def active() -> bool:
    """True when a kernel process runs for this process (started here or in a parent)."""
    return _active is not None and os.getpid() not in _active.broken


@contextlib.contextmanager
def running() -> Iterator[bool]:
    """A kernel process for the block (yields whether one was started).

    Start it before importing numpy, scipy and the rest: it is a copy of this process
    at the fork. Not started where a fork is not safe, when one is running already, or
    when this process has loaded the kernels already (there is no memory left to save).
    """
    global _active
    if _active is not None or "bwdesign.sim.compiled" in sys.modules or not fork_is_safe():
        yield False  # one runs already; the kernels are loaded here already; or no fork
        return
    try:
        _active = _Process()
    except OSError:  # no process or pipe to be had: work alone
        yield False
        return
    try:
        yield True
    finally:
        proc, _active = _active, None
        proc.close()


def run(name: str, args: tuple, out: int) -> None:
    """``compiled.<name>(*args)``, which writes the array ``args[out]``: in the kernel
    process when one runs for this process (its result copied into ``args[out]``),
    else here."""
    if _active is not None:
        value = _active.call(name, args, out)
        if value is not None:
            args[out][...] = value
            return
    from . import compiled

    getattr(compiled, name)(*args)
