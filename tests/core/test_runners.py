"""The display's work on this machine's threads (addon/core/distributed/runners.py): ``each`` shares
its items among the threads ``local_threads`` allows (the threads setting; 1: the calling thread
alone), gives each result its item's, raises a task's error, and nests no pool inside a pool."""
import threading

import pytest

from addon.core.distributed import runners


def test_each_runs_on_two_threads_at_once_with_the_results_in_order():
    """Two tasks that each wait for the other (a barrier of 2): they finish only if two threads
    run them at once; the results are the items' whatever thread made them."""
    meet = threading.Barrier(2, timeout=20)
    threads = set()

    def task(k):
        if k < 2:
            meet.wait()
        threads.add(threading.get_ident())
        return k * k

    with runners.local_threads(2):
        assert runners.each(task, range(7)) == [k * k for k in range(7)]
    assert len(threads) == 2


def test_one_thread_runs_every_task_on_the_calling_thread():
    seen = []
    with runners.local_threads(1):
        assert runners.local_thread_count() == 1
        assert runners.each(lambda k: seen.append(threading.get_ident()) or -k, range(5)) == [0, -1, -2, -3, -4]
    assert set(seen) == {threading.get_ident()}


def test_a_tasks_error_is_raised_and_no_pool_starts_inside_a_pool():
    inner = []

    def task(k):
        inner.append(runners.local_thread_count())
        if k == 3:
            raise ValueError("task 3")
        return k

    with runners.local_threads(2), pytest.raises(ValueError, match="task 3"):
        runners.each(task, range(6))
    assert inner and set(inner) == {1}


def test_the_threads_setting_of_0_or_none_is_the_machines_as_the_solves():
    with runners.local_threads(0):
        assert runners.local_thread_count() == runners.machine_threads() >= 1
    with runners.local_threads(3):
        assert runners.local_thread_count() == 3


def test_tasks_whose_temporaries_pass_the_bound_run_one_at_a_time():
    """Two smoothing channels side by side at 162,560 patches took 36 MiB more at the run's
    peak: tasks of more than SIDE_BY_SIDE_BYTES of temporaries run on the calling thread alone."""
    seen = []
    with runners.local_threads(2):
        runners.each(lambda k: seen.append(threading.get_ident()), range(6), task_bytes=runners.SIDE_BY_SIDE_BYTES + 1)
    assert set(seen) == {threading.get_ident()}
