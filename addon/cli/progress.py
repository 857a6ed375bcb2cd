"""The progress line: one line on a terminal, rewritten while the solve runs (paths, ray rate,
error against the target, time left)."""

from __future__ import annotations

import io
import math
import os
import threading
import time


class ProgressLine:
    """One line on a terminal, rewritten after batches (at most every PERIOD seconds): paths
    done of planned, ray rate, the error estimate against the target, and the time left.
    Cut to the terminal's width: a line that wraps cannot be rewritten, each rewrite would
    leave a line behind."""

    PERIOD = 0.25

    def __init__(self, stream):
        self.stream, self.shown, self.width = stream, 0.0, 0
        self._lock = threading.Lock()  # (ended by the interrupt's watchdog too)

    def __call__(self, job):
        now = time.perf_counter()
        if now - self.shown < self.PERIOD:
            return
        self.shown = now
        self.write(progress_text(job))

    def write(self, text):
        with self._lock:
            text = text[:terminal_columns(self.stream) - 1]
            self.stream.write("\r" + text.ljust(self.width))
            self.stream.flush()
            self.width = len(text)

    def end(self):
        """Clear the line (and a "^C" the terminal echoed after it)."""
        with self._lock:
            if self.width:
                blank = min(self.width + 2, terminal_columns(self.stream) - 1)
                self.stream.write("\r" + " " * blank + "\r")
                self.stream.flush()
                self.width = 0


def terminal_columns(stream) -> int:
    """The width of the terminal ``stream`` writes to (80 where it does not say)."""
    try:
        columns = os.get_terminal_size(stream.fileno()).columns
    except (AttributeError, ValueError, OSError, io.UnsupportedOperation):
        columns = 0
    return columns if columns > 1 else 80


def progress_text(job) -> str:
    """The progress line of a running job (worker.SolveJob)."""
    p = job.snapshot()
    fraction, paths, seconds = p.get("fraction", 0.0), p.get("paths", 0), p.get("seconds", 0.0)
    planned = p.get("expected_paths", math.nan)  # where the run is expected to end, from its measured error
    planned = int(planned) if planned == planned and planned is not None else getattr(job.prediction, "paths", None)
    parts = [f"{fraction * 100:5.1f}%", f"{paths:,} of {planned:,} expected paths" if planned else f"{paths:,} paths"]
    if p.get("rays_per_second"):
        parts.append(f"{p['rays_per_second'] / 1e6:.2f} Mray/s")
    error = job.relative_error(p)
    if error is not None:
        target = job.settings.relative_rms
        parts.append(f"error {error * 100:.2f}%" + (f" (target {target * 100:g}%)" if not job.settings.paths else ""))
    left = p.get("seconds_left", math.nan)
    if left == left and left is not None and fraction < 1:  # (NaN until the run has measured its error)
        parts.append(f"{int(left // 60)}:{int(left % 60):02d} left")
    return "  ".join(parts)

