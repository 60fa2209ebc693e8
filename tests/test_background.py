"""``microfacet._background``: work on a thread (a ``Future``) or in a forked process (its items)."""
import os
import signal

import numpy as np
import pytest

from microfacet._background import Handoff, can_fork, in_background, in_process_items


def _pid_and_sum(a):
    return os.getpid(), float(np.sum(a))


def test_in_background_runs_on_a_thread_of_this_process():
    pid, total = in_background(_pid_and_sum, np.ones(3)).result(timeout=60)
    assert (pid, total) == (os.getpid(), 3.0)


def _pids_and_squares(n, fail_at=None):
    for k in range(n):
        if k == fail_at:
            raise ValueError(f"bad item {k}")
        yield os.getpid(), k * k


def _unpicklable():
    yield lambda: 0


def test_in_process_items_arrive_in_order_from_another_process():
    items = list(in_process_items(_pids_and_squares, 4))
    assert [v for _, v in items] == [0, 1, 4, 9]
    assert all((pid != os.getpid()) == can_fork() for pid, _ in items)


def test_in_process_items_raise_the_workers_exception_after_the_items_made():
    got = []
    with pytest.raises(ValueError, match="bad item 2"):
        for _, v in in_process_items(_pids_and_squares, 5, 2):
            got.append(v)
    assert got == [0, 1]


@pytest.mark.skipif(not can_fork(), reason="this machine's in_process_items runs in this process (one CPU or not Linux)")
def test_in_process_items_left_early_stop_the_worker():
    def endless():
        yield os.getpid()
        while True:
            yield 0
    items = in_process_items(endless)
    pid = next(items)
    items.close()                                # the caller stops reading
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


@pytest.mark.skipif(not can_fork(), reason="this machine's in_process_items runs in this process (one CPU or not Linux)")
def test_in_process_items_say_when_their_worker_dies():
    def dies_after_one():
        yield 1
        os.kill(os.getpid(), signal.SIGKILL)
        yield 2
    items = in_process_items(dies_after_one)
    assert next(items) == 1
    with pytest.raises(RuntimeError, match="worker process ended"):
        next(items)


@pytest.mark.skipif(not can_fork(), reason="this machine's in_process_items runs in this process (one CPU or not Linux)")
def test_in_process_items_say_when_an_item_does_not_pickle():
    with pytest.raises((RuntimeError, AttributeError, TypeError), match="pickle|_unpicklable|lambda"):
        list(in_process_items(_unpicklable))


def _scaled_by_what_comes(handoff, xs):
    k = handoff.get()
    for x in xs:
        yield os.getpid(), k[:3] * x


def test_handoff_gives_the_child_a_value_made_after_the_fork():
    """A Handoff carries to the child a value put after in_process_items forked it; put does
    not wait for the child to read it (a value larger than a pipe's buffer); without a fork the
    generator reads the value put here."""
    handoff = Handoff()
    items = in_process_items(_scaled_by_what_comes, handoff, [1.0, 2.0])
    value = np.arange(1_000_000, dtype=float)                  # 8 MB
    handoff.put(value)
    got = list(items)
    assert [v.tolist() for _, v in got] == [[0.0, 1.0, 2.0], [0.0, 2.0, 4.0]]
    assert all((pid != os.getpid()) == can_fork() for pid, _ in got)
    here = Handoff()
    items = _scaled_by_what_comes(here, [3.0])
    here.put(value)
    assert [v.tolist() for _, v in items] == [[0.0, 3.0, 6.0]]
    with pytest.raises(RuntimeError, match="nothing was put"):
        Handoff().get()
