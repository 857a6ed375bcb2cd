"""This machine's threads for work that is not a solve's chunks: the display's shadow rays and the
scene's probes of buried parts, the display's smoothing (``local_threads``, ``on_threads``,
``each_on_threads``), the user's threads setting; work traced on a thread of its own beside other
work (``in_background``, ``beside``).

Here, below every package that traces rays here, so that the scene's build may use them
(``distributed.runners`` hands the same names on, where the solve's own threads are).
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import threading
from concurrent.futures import ThreadPoolExecutor

# The threads the display's work takes here (None: the machine's), set by ``local_threads``.
_LOCAL_THREADS = contextvars.ContextVar("local_threads", default=None)


def machine_threads(threads=None):
    """``threads``, or where it is 0 or None this machine's cores (at most 8), as the solve's."""
    return int(threads or min(os.cpu_count() or 1, 8))


@contextlib.contextmanager
def local_threads(threads):
    """The work ``on_threads`` runs inside takes ``threads`` threads (0 or None: the machine's;
    1: the calling thread alone): the user's threads setting, for the display as for the solve."""
    token = _LOCAL_THREADS.set(machine_threads(threads))
    try:
        yield
    finally:
        _LOCAL_THREADS.reset(token)


@contextlib.contextmanager
def beside(active=True):
    """Within it, where ``active``, ``on_threads`` takes one thread: work made while another thread
    traces beside it (``in_background``), one thread each (two streams of numpy on two threads each
    wait on the GIL; one each, the other's ray casts let go of it)."""
    if not active:
        yield
        return
    with local_threads(1):
        yield


def in_background(work):
    """``work()`` on a thread of its own from now, inside a copy of the caller's context in which
    ``on_threads`` takes one thread (``beside``): a Future, whose ``result()`` waits for it and
    raises its error."""
    context = contextvars.copy_context()
    context.run(_LOCAL_THREADS.set, 1)
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="radiosity-beside")
    try:
        return pool.submit(context.run, work)
    finally:
        pool.shutdown(wait=False)  # (the work goes on; the pool takes no other)


def local_thread_count():
    """The threads ``on_threads`` takes here (``local_threads``)."""
    return machine_threads(_LOCAL_THREADS.get())


def on_threads(work, most):
    """Runs ``work()`` on up to ``most`` threads at once (``local_thread_count`` of them, the calling
    thread one of them), each inside a copy of the caller's context in which ``on_threads`` takes
    one thread (no pool inside a pool); returns when all have ended, raising the first error.
    ``work`` takes its tasks from a shared queue, so what each thread did must not matter."""
    count = max(1, min(int(most), local_thread_count()))
    if count == 1:
        return work()
    contexts = [contextvars.copy_context() for _ in range(count)]
    for context in contexts:
        context.run(_LOCAL_THREADS.set, 1)
    with ThreadPoolExecutor(max_workers=count - 1, thread_name_prefix="radiosity-local") as pool:
        futures = [pool.submit(context.run, work) for context in contexts[1:]]
        contexts[0].run(work)  # (the calling thread takes a share: one thread fewer to start)
    for future in futures:
        future.result()


def each_on_threads(count, task, most=None):
    """``task(i)`` for i in range(count), on the local threads (``on_threads``; at most ``most``),
    each taking the next; each task's work must be its own, so that the bits are the same on any
    number of threads."""
    lock, items = threading.Lock(), iter(range(count))

    def work():
        while True:
            with lock:
                i = next(items, None)
            if i is None:
                return
            task(i)

    on_threads(work, count if most is None else min(count, most))
