"""bwdesign.memo: answers kept by their exact arguments, copies in and out, bounded."""

from __future__ import annotations

import threading

import numpy as np

from bwdesign.memo import Memo, clear_all


def test_kept_by_exact_arguments_copied_and_bounded():
    memo: Memo[dict] = Memo(2)
    calls = []

    def compute(x):
        calls.append(x)
        return {"x": x, "arr": np.array([x])}

    a = memo.get((1.0,), lambda: compute(1.0))
    a["arr"][0] = 99.0  # the caller's copy
    b = memo.get((1.0,), lambda: compute(1.0))
    assert calls == [1.0] and b["arr"][0] == 1.0 and b is not a
    memo.get((np.nextafter(1.0, 2.0),), lambda: compute(2.0))  # the next float: new key
    memo.get((3.0,), lambda: compute(3.0))  # a third: the oldest (1.0) is dropped
    assert len(memo) == 2 and len(calls) == 3
    memo.get((1.0,), lambda: compute(1.0))
    assert len(calls) == 4

    def local():  # does not pickle: computed every time, never kept
        return None

    memo.get((local,), lambda: compute(5.0))
    memo.get((local,), lambda: compute(5.0))
    assert calls[-2:] == [5.0, 5.0] and len(memo) == 2
    clear_all()
    assert len(memo) == 0


def test_a_refusal_is_not_kept_and_threads_share_one_memo():
    memo: Memo[int] = Memo(4)
    tries = []

    def refuse():
        tries.append(1)
        raise ValueError("no")

    for _ in range(2):
        try:
            memo.get(("bad",), refuse)
        except ValueError:
            pass
    assert len(tries) == 2 and len(memo) == 0
    errors = []

    def work(i):
        try:
            for j in range(300):
                assert memo.get(((i + j) % 7,), lambda k=(i + j) % 7: k * k) == ((i + j) % 7) ** 2
        except Exception as err:  # noqa: BLE001 - reported below
            errors.append(err)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(memo) <= 4


def test_restore_brings_back_what_was_kept_and_drops_what_came_after():
    from bwdesign.memo import restore, snapshot

    memo: Memo[int] = Memo(4)
    memo.get((1,), lambda: 10)
    state = snapshot()
    clear_all()  # a test patches: everything forgotten
    assert len(memo) == 0
    assert memo.get((1,), lambda: -1) == -1  # computed afresh under the patch
    memo.get((2,), lambda: 20)
    late: Memo[int] = Memo(2)  # made after the snapshot
    late.get((3,), lambda: 30)
    restore(state)
    assert len(memo) == 1 and memo.get((1,), lambda: -2) == 10 and len(late) == 0
    kept = memo.kept()
    kept.clear()  # a copy of the dict: the memo keeps its answers
    assert len(memo) == 1
