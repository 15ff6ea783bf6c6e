"""Answers of pure functions kept by their exact arguments, in this process.

A :class:`Memo` keeps a bounded number of answers, each under the pickled bytes of the
arguments that produced it (every float to the bit, so a changed argument is a new
key). A copy goes in and a copy comes out, so no caller can change what another
caller is given. Arguments that do not pickle (a user's own class defined in a
function, say) are not kept: the function is computed each time.

Only pure functions of their arguments belong here: the package keeps
:func:`bwdesign.digital_tuning`, :func:`bwdesign.model.envelope.derive_envelope`,
:func:`bwdesign.certify`, :func:`bwdesign.certify_robust` and :func:`bwdesign.synthesize`
(the report's parts, the design searches, the checks and the commands ask for the same
stage's answers again). A function replaced inside the package (a test's monkeypatch) is
not an argument: :func:`clear_all` forgets what was kept.
"""

from __future__ import annotations

import copy
import pickle
import threading
from collections.abc import Callable
from typing import Generic, TypeVar

__all__ = ["Memo", "clear_all", "snapshot", "restore"]

T = TypeVar("T")


#: Every :class:`Memo` made, for :func:`clear_all`.
_ALL: list[Memo] = []


def clear_all() -> None:
    """Forget every answer every :class:`Memo` keeps (after the package's own functions
    were replaced, say: a test's monkeypatch)."""
    for memo in _ALL:
        memo.clear()


def snapshot() -> list[tuple[Memo, dict[bytes, object]]]:
    """Every :class:`Memo`'s kept answers as they are now, for :func:`restore`.

    The answers themselves are not copied: a memo hands out copies only, so what it
    keeps is never changed."""
    return [(memo, memo.kept()) for memo in _ALL]


def restore(state: list[tuple[Memo, dict[bytes, object]]]) -> None:
    """Every :class:`Memo` back to the answers of ``state`` (:func:`snapshot`); one made
    since is emptied. A test suite takes a snapshot before a test replaces a function of
    the package and restores it after: nothing computed under the replacement is kept,
    and what was kept before comes back for the tests that follow."""
    before = {id(memo): kept for memo, kept in state}
    for memo in _ALL:
        memo.replace_kept(before.get(id(memo), {}))


class Memo(Generic[T]):
    """At most ``size`` answers, the oldest dropped first."""

    def __init__(self, size: int = 16):
        self.size = size
        self._kept: dict[bytes, T] = {}
        self._lock = threading.Lock()  # a sweep's threads may ask at once
        _ALL.append(self)

    @staticmethod
    def key(args: tuple) -> bytes | None:
        """The arguments' exact bytes, or None (they do not pickle: not kept)."""
        try:
            return pickle.dumps(args, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # noqa: BLE001 - an argument that does not pickle: computed each time
            return None

    def get(self, args: tuple, compute: Callable[[], T]) -> T:
        """The answer for ``args``: a copy of the kept one, else ``compute()`` (kept)."""
        key = self.key(args)
        with self._lock:
            kept = self._kept.get(key) if key is not None else None
        if kept is not None:
            return copy.deepcopy(kept)
        answer = compute()  # outside the lock: a long computation blocks no other caller
        if key is not None:
            kept = copy.deepcopy(answer)
            with self._lock:
                while len(self._kept) >= self.size:
                    self._kept.pop(next(iter(self._kept)))
                self._kept[key] = kept
        return answer

    def clear(self) -> None:
        """Forget every kept answer."""
        with self._lock:
            self._kept.clear()

    def kept(self) -> dict[bytes, T]:
        """The kept answers by key (a new dict; the answers are the kept ones)."""
        with self._lock:
            return dict(self._kept)

    def replace_kept(self, kept: dict[bytes, T]) -> None:
        """Keep exactly ``kept`` (from :meth:`kept`), oldest first as it is ordered."""
        with self._lock:
            self._kept = dict(kept)

    def __len__(self) -> int:
        return len(self._kept)
