"""The benchmark's processor counters (benchmarks/counters.py): where the kernel lets a process
read them they count this thread's work, and only while started; elsewhere open() is None."""
import numpy as np
import pytest

from benchmarks.counters import Counters


def test_counters_count_this_threads_work_only_while_started():
    counters = Counters.open()
    if counters is None:  # the breakdown then prints n/a; say so rather than pass silently
        pytest.skip("this kernel refuses perf_event_open (perf_event_paranoid > 2 or no PMU)")
    try:
        table = np.random.default_rng(0).random(1 << 23)  # 64 MB, far more than any cache
        index = np.random.default_rng(1).integers(0, table.size, 1 << 20)
        idle = counters.read()
        table.take(index)  # not counted: the counters are stopped
        assert counters.read() == idle
        counters.start()
        table.take(index)
        counters.stop()
        counted = counters.read()
        assert counted["cycles"] - idle["cycles"] > 1_000_000
        # A million random reads of a 64 MB table fetch most of their lines from memory.
        assert counted["from_memory"] - idle["from_memory"] > 100_000
    finally:
        counters.close()
