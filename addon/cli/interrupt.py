"""Ctrl-C on the command line, and SIGTERM (a ``timeout``, a CI cancel) and SIGHUP (the terminal
closed) the same way: the running solve cancelled, nothing saved, one line and the signal's
status (130, 143, 129), also when the main thread is held in Blender's C code."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import threading

# The signals a run stops on, as the one line names them; each is taken over only from its default.
STOPPING = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM"}
if hasattr(signal, "SIGHUP"):  # (POSIX only)
    STOPPING[signal.SIGHUP] = "SIGHUP (the terminal closed)"


def status_of(signum) -> int:
    """The conventional exit status of a program stopped by ``signum``: 128 + its number."""
    return 128 + int(signum)


def message_of(signum) -> str:
    return f"interrupted: stopped by {STOPPING[signum]}; nothing was saved"


class Interrupted(Exception):
    """A stopping signal came: the run stops at the next point that can stop."""


class Interrupt:
    """Ctrl-C, SIGTERM or SIGHUP on the command line: the running solve is cancelled, nothing is
    saved (the files are put in place only at the end, ``saving.Outputs``), one line is printed
    and the status is the signal's (130 for Ctrl-C).

    The main thread stops at its next ``check()``; when it cannot (held in Blender's C code, a
    render or a save), a watchdog thread woken by the signal (``signal.set_wakeup_fd``) ends the
    process GRACE seconds later, with the same line and status, after removing the temporary
    files. A signal is taken over only from its default handler (Python's for SIGINT), on the main
    thread: a host's own handler, or one ignored (``nohup``), is left alone."""

    GRACE = 0.5
    STATUS = status_of(signal.SIGINT)
    MESSAGE = message_of(signal.SIGINT)
    STATUSES = frozenset(status_of(s) for s in STOPPING)

    def __init__(self):
        self.requested = threading.Event()
        self.finished = threading.Event()
        self.lock = threading.Lock()  # held while the files are put in place
        self.committed = False
        self.signum = signal.SIGINT  # the first stopping signal that came
        self.progress = None  # the ProgressLine to end
        self.outputs = None  # the Outputs to discard
        self._pipe = None
        self._previous = {}

    def __enter__(self):
        if threading.current_thread() is not threading.main_thread():
            return self
        defaults = {s: signal.default_int_handler if s == signal.SIGINT else signal.SIG_DFL for s in STOPPING}
        taken = [s for s in STOPPING if signal.getsignal(s) is defaults[s]]
        if not taken:
            return self  # someone else's handlers (Blender's, a host's): left alone
        read, write = os.pipe()
        os.set_blocking(write, False)
        self._wakeup = signal.set_wakeup_fd(write, warn_on_full_buffer=False)
        self._previous = {s: signal.signal(s, self._on_signal) for s in taken}
        self._pipe = (read, write)
        self._watchdog = threading.Thread(target=self._watch, name="radiosity-interrupt", daemon=True)
        self._watchdog.start()
        return self

    def __exit__(self, *exc_info):
        self.finished.set()
        if self._pipe is not None:
            for s, previous in self._previous.items():
                signal.signal(s, previous)
            signal.set_wakeup_fd(self._wakeup)
            os.close(self._pipe[1])  # the watchdog reads the end of the pipe and ends
            self._watchdog.join(timeout=1)
            os.close(self._pipe[0])
            self._pipe = None
        return False

    @property
    def status(self):
        return status_of(self.signum)

    def _on_signal(self, signum, frame):  # (main thread, between two Python steps: never raises)
        self._request(signum)

    def _request(self, signum):
        if not self.requested.is_set():
            self.signum = signum
        self.requested.set()
        worker = sys.modules.get(f"{__package__.rpartition('.')[0]}.bpy_free.worker")  # (no import here: it could wait on the main thread's)
        job = worker.running_job() if worker is not None else None
        if job is not None:
            job.cancel()

    def check(self):
        if self.requested.is_set():
            raise Interrupted

    def stopped(self):
        """The main thread's way out after the signal: discard, one line, the status."""
        with self.lock:
            self._leave()
        return self.status

    def _leave(self):
        self.finished.set()
        if self.progress is not None:
            with contextlib.suppress(OSError, ValueError):  # (a closed terminal)
                self.progress.end()
        if self.outputs is not None:
            self.outputs.discard()
        at_start = "\r" if _isatty(sys.stderr) else ""  # (over the "^C" the terminal echoed)
        with contextlib.suppress(OSError, ValueError):
            print(at_start + message_of(self.signum), file=sys.stderr, flush=True)

    def _watch(self):
        read = self._pipe[0]
        while True:
            try:
                data = os.read(read, 64)
            except OSError:
                return
            if not data or self.finished.is_set():
                return
            signum = next((s for s in data if s in self._previous), None)
            if signum is None:
                continue
            self._request(signal.Signals(signum))
            if self.finished.wait(self.GRACE):
                return
            with self.lock:  # (a commit under way ends first: its files are whole)
                if self.finished.is_set() or self.committed:
                    return
                self._leave()
                exit_now(self.status)


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
