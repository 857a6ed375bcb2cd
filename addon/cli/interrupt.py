"""Ctrl-C on the command line: the running solve cancelled, nothing saved, one line and the
status 130, also when the main thread is held in Blender's C code."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import threading


class Interrupted(Exception):
    """Ctrl-C was pressed: the run stops at the next point that can stop."""


class Interrupt:
    """Ctrl-C on the command line: the running solve is cancelled, nothing is saved (the files
    are put in place only at the end, ``saving.Outputs``), one line is printed and the status is 130.

    The main thread stops at its next ``check()``; when it cannot (held in Blender's C code, a
    render or a save), a watchdog thread woken by the signal (``signal.set_wakeup_fd``) ends the
    process GRACE seconds later, with the same line and status, after removing the temporary
    files. Installed only over Python's own SIGINT handler, on the main thread."""

    GRACE = 0.5
    STATUS = 130
    MESSAGE = "interrupted: stopped by Ctrl-C; nothing was saved"

    def __init__(self):
        self.requested = threading.Event()
        self.finished = threading.Event()
        self.lock = threading.Lock()  # held while the files are put in place
        self.committed = False
        self.progress = None  # the ProgressLine to end
        self.outputs = None  # the Outputs to discard
        self._pipe = None

    def __enter__(self):
        if (threading.current_thread() is not threading.main_thread()
                or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
            return self  # someone else's handler (Blender's, a host's): left alone
        read, write = os.pipe()
        os.set_blocking(write, False)
        self._wakeup = signal.set_wakeup_fd(write, warn_on_full_buffer=False)
        self._previous = signal.signal(signal.SIGINT, self._on_signal)
        self._pipe = (read, write)
        self._watchdog = threading.Thread(target=self._watch, name="radiosity-interrupt", daemon=True)
        self._watchdog.start()
        return self

    def __exit__(self, *exc_info):
        self.finished.set()
        if self._pipe is not None:
            signal.signal(signal.SIGINT, self._previous)
            signal.set_wakeup_fd(self._wakeup)
            os.close(self._pipe[1])  # the watchdog reads the end of the pipe and ends
            self._watchdog.join(timeout=1)
            os.close(self._pipe[0])
            self._pipe = None
        return False

    def _on_signal(self, signum, frame):  # (main thread, between two Python steps: never raises)
        self._request()

    def _request(self):
        self.requested.set()
        worker = sys.modules.get(f"{__package__.rpartition('.')[0]}.bpy_free.worker")  # (no import here: it could wait on the main thread's)
        job = worker.running_job() if worker is not None else None
        if job is not None:
            job.cancel()

    def check(self):
        if self.requested.is_set():
            raise Interrupted

    def stopped(self):
        """The main thread's way out after Ctrl-C: discard, one line, the status."""
        with self.lock:
            self._leave()
        return self.STATUS

    def _leave(self):
        self.finished.set()
        if self.progress is not None:
            self.progress.end()
        if self.outputs is not None:
            self.outputs.discard()
        at_start = "\r" if _isatty(sys.stderr) else ""  # (over the "^C" the terminal echoed)
        print(at_start + self.MESSAGE, file=sys.stderr, flush=True)

    def _watch(self):
        read = self._pipe[0]
        while True:
            try:
                data = os.read(read, 64)
            except OSError:
                return
            if not data or self.finished.is_set():
                return
            if signal.SIGINT not in data:
                continue
            self._request()
            if self.finished.wait(self.GRACE):
                return
            with self.lock:  # (a commit under way ends first: its files are whole)
                if self.finished.is_set() or self.committed:
                    return
                self._leave()
                exit_now(self.STATUS)


def _isatty(stream):
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


def exit_now(status):
    """End the process at once (Blender's own exit takes half a second): streams flushed and
    Blender's session folder removed, as its exit would."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    blender_tempdir = None
    with contextlib.suppress(Exception):  # (bpy may still be importing: its folder exists already)
        blender_tempdir = sys.modules["bpy"].app.tempdir
    if blender_tempdir and os.path.basename(os.path.normpath(blender_tempdir)).startswith("blender_"):
        shutil.rmtree(blender_tempdir, ignore_errors=True)
    os._exit(status)

