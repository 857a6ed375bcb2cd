"""Where a solve's chunks run: this machine's threads (a cluster runner offers the same calls);
the display's shadow rays on this machine's threads (``local_threads``, ``on_threads``: made in
``scene.threads``, which the scene's build uses too, and handed on here).

A runner takes tasks "chunks k, k+1, ... of sizes n_k" and returns futures of their tallies.
Chunk k draws from its own stream, SeedSequence(seed, spawn_key=(k,)) (a group of chunks traced
together from its first chunk's), so a task's result depends on nothing but its arguments:
bitwise the same wherever and in whatever order it runs.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..scene.threads import (beside, each_on_threads, in_background, local_thread_count, local_threads,
                             machine_threads, on_threads)

__all__ = ["ThreadRunner", "beside", "chunk_generator", "each_on_threads", "in_background", "local_thread_count",
           "local_threads", "machine_threads", "on_threads", "run_chunks"]


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

    def restate(self, state):
        """The state the chunks submitted from now on read (their size changed)."""
        self._state = state

    def stop(self, pending):
        """Abandon the tasks still running (at their next step) or queued; wait for the threads."""
        self._abort.set()
        for future in pending:
            future.cancel()
        if self._executor is not None:
            self._executor.shutdown(wait=True)
