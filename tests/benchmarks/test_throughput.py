"""The throughput breakdown's replay (benchmarks/throughput.py): the casts are traced in order,
each after a pause proportional to its rays, and only the casts' own time is counted."""
import time

import numpy as np

from benchmarks.throughput import replay


def _spin(seconds):
    """``seconds`` of this thread's CPU: at least that much of the process's, which the replay
    counts, and of wall time (a busy machine stretches the wall time, not this; the process's CPU
    time alone ran faster than the wall where another thread of the process was busy: 16.9 ms
    between two casts that the test asked 17 ms of, on a clean clone's CI)."""
    until = time.thread_time() + seconds
    while time.thread_time() < until:
        pass


def test_replay_pauses_before_each_cast_and_counts_the_casts_alone():
    casts = [(np.zeros((n, 3), np.float32), np.ones((n, 3), np.float32)) for n in (1000, 3000, 2000)]
    calls = []

    def trace(origins, directions):
        calls.append((time.perf_counter(), len(origins)))
        _spin(0.002)  # 2 ms of CPU a cast
        return np.full(len(origins), -1, np.int32)

    def counted(trace_, origins, directions):
        return trace_(origins, directions)

    lines = iter(range(0, 10**6, 600))  # a counter read before and after: 600 "lines" in all
    pause_a_ray = 5e-6  # 5, 15 and 10 ms before the casts
    start = time.perf_counter()
    rate, lines_a_ray = replay(trace, casts, pause_a_ray, counted, lambda: next(lines))
    wall = time.perf_counter() - start

    assert [n for _, n in calls] == [1000, 3000, 2000]  # every cast, in order
    # Each cast starts at least its pause after the one before it ended (2 ms of tracing).
    assert calls[0][0] - start >= 1000 * pause_a_ray
    for (before, _), (after, n) in zip(calls, calls[1:]):
        assert after - before >= 0.002 + n * pause_a_ray
    # The rate counts the casts' CPU time (about 6 ms), not the 30 ms of pauses.
    counted_seconds = 6000 / rate
    assert counted_seconds >= 0.0055  # at least the casts' own spinning (process time resolution)
    assert counted_seconds < 0.5 * wall  # the pauses (30 of about 36 ms) are left out
    assert lines_a_ray == 600 / 6000


def test_replay_without_pause_traces_back_to_back():
    casts = [(np.zeros((500, 3), np.float32), np.ones((500, 3), np.float32))] * 4
    calls = []

    def trace(origins, directions):
        calls.append(time.perf_counter())
        _spin(0.001)

    rate, lines_a_ray = replay(trace, casts, 0.0, lambda t, o, d: t(o, d), lambda: float("nan"))
    assert len(calls) == 4
    assert np.isnan(lines_a_ray)  # no counters: NaN, as the breakdown prints n/a
    assert 2000 / rate >= 0.004  # the four casts' own CPU


def test_steal_is_read_and_a_round_is_quiet_only_when_each_measurement_lost_little():
    from benchmarks.throughput import is_quiet, stolen_seconds

    first = stolen_seconds()
    second = stolen_seconds()
    assert np.isnan(first) or 0 <= first <= second  # a counter since boot (NaN off Linux)
    assert is_quiet((0.0, 0.02, 0.004))
    assert not is_quiet((0.0, 0.021, 0.0))  # the solve lost more than 2%
    assert not is_quiet((0.05, 0.0, 0.0), quiet_steal=0.01)
    assert is_quiet((np.nan, np.nan, np.nan))  # unreadable: every round counts
