"""``microfacet._background``: work on a thread or in a forked process, as a ``Future``."""
import os
import signal

import numpy as np
import pytest

from microfacet._background import can_fork, in_background, in_process


def _pid_and_sum(a):
    return os.getpid(), float(np.sum(a))


def _fails():
    raise ValueError("bad parameter: alpha")


def _dies():
    os.kill(os.getpid(), signal.SIGKILL)


def test_in_process_returns_the_result_from_another_process():
    pid, total = in_process(_pid_and_sum, np.arange(10.0)).result(timeout=60)
    assert total == 45.0
    assert (pid != os.getpid()) == can_fork()


def test_in_process_raises_the_workers_exception():
    with pytest.raises(ValueError, match="bad parameter: alpha"):
        in_process(_fails).result(timeout=60)


@pytest.mark.skipif(not can_fork(), reason="this machine's in_process runs on a thread (one CPU or not Linux)")
def test_in_process_says_when_its_worker_dies():
    with pytest.raises(RuntimeError, match="worker process ended"):
        in_process(_dies).result(timeout=60)


def test_in_background_runs_on_a_thread_of_this_process():
    pid, total = in_background(_pid_and_sum, np.ones(3)).result(timeout=60)
    assert (pid, total) == (os.getpid(), 3.0)
