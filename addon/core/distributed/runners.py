"""Where a solve's chunks run: this machine's threads (a cluster runner offers the same calls);
and the display's shadow rays on this machine's threads (``local_threads``, ``on_threads``).

A runner takes tasks "chunks k, k+1, ... of sizes n_k" and returns futures of their tallies.
Chunk k draws from its own stream, SeedSequence(seed, spawn_key=(k,)) (a group of chunks traced
together from its first chunk's), so a task's result depends on nothing but its arguments:
bitwise the same wherever and in whatever order it runs.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np


def chunk_generator(seed, first_chunk):
    """The random numbers of chunk ``first_chunk`` (and of the chunks traced with it)."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(first_chunk,))))


def run_chunks(state, seed, first_chunk, sizes, abort=None):
    """The tallies of chunks ``first_chunk``, ``first_chunk`` + 1, ... of ``sizes`` paths of the
    method whose state (``methods.base.Integrator``) is ``state``."""
    return state.run(sizes, chunk_generator(seed, first_chunk), abort)


class ThreadRunner:
    """Chunks on threads of this process; walks take turns at numpy and trace in parallel."""

    def __init__(self, threads):
        self.threads = threads
        self.slots = threads + 1  # every thread busy, and one task queued beyond them
        self._abort = threading.Event()
        self._executor = None

    def start(self, state, seed):
        self._state, self._seed = state, seed
        self._executor = ThreadPoolExecutor(max_workers=self.threads, thread_name_prefix="radiosity")

    def submit(self, first_chunk, sizes):
        """A future of the tallies of chunks ``first_chunk``... of ``sizes`` paths."""
        return self._executor.submit(run_chunks, self._state, self._seed, first_chunk, sizes, self._abort)

    def stop(self, pending):
        """Abandon the tasks still running (at their next step) or queued; wait for the threads."""
        self._abort.set()
        for future in pending:
            future.cancel()
        if self._executor is not None:
            self._executor.shutdown(wait=True)


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


def local_thread_count():
    """The threads ``on_threads`` takes here (``local_threads``)."""
    return machine_threads(_LOCAL_THREADS.get())


def on_threads(work, most):
    """Runs ``work()`` on up to ``most`` threads at once (``local_thread_count`` of them; one: on
    the calling thread), each inside a copy of the caller's context in which ``on_threads`` takes
    one thread (no pool inside a pool); returns when all have ended, raising the first error.
    ``work`` takes its tasks from a shared queue, so what each thread did must not matter."""
    count = max(1, min(int(most), local_thread_count()))
    if count == 1:
        return work()
    contexts = [contextvars.copy_context() for _ in range(count)]
    for context in contexts:
        context.run(_LOCAL_THREADS.set, 1)
    with ThreadPoolExecutor(max_workers=count, thread_name_prefix="radiosity-local") as pool:
        futures = [pool.submit(context.run, work) for context in contexts]
    for future in futures:
        future.result()

