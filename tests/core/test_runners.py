"""The display's work on this machine's threads (addon/core/distributed/runners.py): ``on_threads``
runs a worker on the threads ``local_threads`` allows (the threads setting; 1: the
calling thread alone), raises a worker's error, and nests no pool inside a pool; work traced in
the background shares the threads with its caller (``in_background``, ``beside``)."""
import threading

import pytest

from addon.core.distributed import runners


def test_the_work_runs_on_two_threads_at_once():
    """Two tasks that each wait for the other (a barrier of 2): they finish only if two threads
    run them at once; every task is done once."""
    meet, threads, done = threading.Barrier(2, timeout=20), set(), []

    def task(k):
        if k < 2:
            meet.wait()
        threads.add(threading.get_ident())
        done.append(k)

    with runners.local_threads(2):
        runners.each_on_threads(7, task, most=7)
    assert len(threads) == 2 and sorted(done) == list(range(7))


def test_one_thread_runs_every_task_on_the_calling_thread():
    seen = []
    with runners.local_threads(1):
        assert runners.local_thread_count() == 1
        runners.each_on_threads(5, lambda k: seen.append(threading.get_ident()), most=5)
    assert seen == [threading.get_ident()] * 5
    with runners.local_threads(2):  # (one task: no pool)
        runners.each_on_threads(3, lambda k: seen.append(threading.get_ident()), most=1)
    assert set(seen) == {threading.get_ident()}


def test_a_workers_error_is_raised_and_no_pool_starts_inside_a_pool():
    inner = []

    def task(k):
        inner.append(runners.local_thread_count())
        if k == 3:
            raise ValueError("task 3")

    with runners.local_threads(2), pytest.raises(ValueError, match="task 3"):
        runners.each_on_threads(6, task, most=6)
    assert inner and set(inner) == {1}


def test_the_threads_setting_of_0_or_none_is_the_machines_as_the_solves():
    with runners.local_threads(0):
        assert runners.local_thread_count() == runners.machine_threads() >= 1
    with runners.local_threads(3):
        assert runners.local_thread_count() == 3


def test_work_in_the_background_takes_one_thread_and_its_caller_one_beside_it():
    """``in_background``: the work runs on a thread of its own, its ``on_threads`` on one thread;
    its caller, ``beside`` it, on one thread too, then on its own count again; ``beside(False)``
    leaves the threads as they are."""
    started, counts = threading.Event(), []

    def work():
        counts.append((threading.get_ident(), runners.local_thread_count()))
        started.set()
        return "made"

    with runners.local_threads(2):
        future = runners.in_background(work)
        with runners.beside(True):
            assert started.wait(20) and runners.local_thread_count() == 1
        assert runners.local_thread_count() == 2  # (the caller's again)
        assert future.result() == "made"
        with runners.beside(False):
            assert runners.local_thread_count() == 2
    (ident, count), = counts
    assert ident != threading.get_ident() and count == 1


def test_an_error_in_the_background_is_raised_by_its_result():
    def work():
        raise ValueError("traced beside")

    with runners.local_threads(2):
        future = runners.in_background(work)
        with pytest.raises(ValueError, match="traced beside"):
            future.result()
