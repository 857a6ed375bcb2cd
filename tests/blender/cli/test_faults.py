"""The command line under faults: a failed or truncated save, an output folder that cannot be
made, Ctrl-C (on a pseudo-terminal, as a user presses it) and the progress line's end."""

import fcntl
import os
import pty
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
ENV = {**os.environ, "PYTHONPATH": ROOT}
INTERRUPTED = "interrupted: stopped by Ctrl-C; nothing was saved"

# A save whose file comes out truncated without an error (as on a nearly full disk, where the
# compressed writer's failure went unnoticed): Blender's save_post handler cuts the file in half.
TRUNCATING_SAVE = """
import os, sys
import bpy
from addon.__main__ import main

@bpy.app.handlers.persistent
def truncate(path, *_):
    with open(path, "r+b") as f:
        f.truncate(os.path.getsize(path) // 2)

bpy.app.handlers.save_post.append(truncate)
sys.exit(main(sys.argv[1:]))
"""

QUICK = ["--scene", "cornell", "--error", "20", "--patch-size", "0.4", "--threads", "1"]


def _cli(args, cwd, code=None, timeout=300):
    command = [sys.executable, "-c", code, *args] if code else [sys.executable, "-m", "addon", *args]
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=ENV)


def _earlier(tmp_path):
    """A good earlier output in out/, made by a first run: (folder, .blend, .png, their bytes)."""
    folder = tmp_path / "out"
    blend, png = folder / "box.blend", folder / "box.png"
    proc = _cli([*QUICK, "-o", str(blend), "--resolution", "32", "--samples", "1"], str(tmp_path))
    assert proc.returncode == 0, proc.stderr[-2000:]
    return folder, blend, png, blend.read_bytes(), png.read_bytes()


def test_a_truncated_save_keeps_the_earlier_file_and_says_so(tmp_path):
    folder, blend, png, blend_bytes, png_bytes = _earlier(tmp_path)
    proc = _cli([*QUICK, "--seed", "1", "-o", str(blend), "--resolution", "32", "--samples", "1"], str(tmp_path),
                code=TRUNCATING_SAVE)
    assert proc.returncode == 1, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "saved:" not in proc.stdout and "preview:" not in proc.stdout
    errors = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(errors) == 1 and errors[0].startswith(f"error: cannot save {blend}: "), proc.stderr
    assert "Missing DNA block" in errors[0] and "the earlier file is kept" in errors[0]
    # the earlier pair stays whole and together; no backup, no temporary left behind
    assert blend.read_bytes() == blend_bytes and png.read_bytes() == png_bytes
    assert sorted(os.listdir(folder)) == ["box.blend", "box.png"]


def test_a_preview_cut_short_is_not_taken_for_an_image(tmp_path):
    import zlib

    from addon.cli.saving import check_png

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 0, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(b"\x00\x80")) + chunk(b"IEND", b""))
    whole, cut = tmp_path / "whole.png", tmp_path / "cut.png"
    whole.write_bytes(png)
    cut.write_bytes(png[:-5])
    check_png(str(whole))
    for path in (cut, tmp_path / "empty.png"):
        path.touch()
        with pytest.raises(OSError, match="incomplete"):
            check_png(str(path))


def _tmpfs(path, size):
    path.mkdir()
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True)
    return proc.returncode == 0


def test_a_full_disk_keeps_the_earlier_file(tmp_path):
    """A small tmpfs filled but for a little (root only): wherever the writing fails (Blender
    notices "No space left on device", or not and the file comes out truncated: which one varies
    from run to run), the earlier file stays as it was, nothing is said saved and the status is 1."""
    disk = tmp_path / "disk"
    if not _tmpfs(disk, "1000k"):
        pytest.skip("mounting a tmpfs needs root (the injected truncation above covers the check)")
    try:
        blend = disk / "box.blend"
        proc = _cli([*QUICK, "-o", str(blend), "--no-preview"], str(tmp_path))
        assert proc.returncode == 0, proc.stderr[-2000:]
        earlier = blend.read_bytes()
        free = os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize
        for left in (0.0, 0.03, 0.25, 0.5, 0.8):  # the new file (about the earlier's size) fails at different points
            filler = disk / "fill"
            filler.write_bytes(b"\0" * int(free - left * len(earlier)))
            proc = _cli([*QUICK, "--seed", "1", "-o", str(blend), "--no-preview"], str(tmp_path))
            filler.unlink()
            assert proc.returncode == 1, proc.stdout[-2000:] + proc.stderr[-2000:]
            assert "saved:" not in proc.stdout
            errors = [line for line in proc.stderr.splitlines() if line.strip()]
            assert len(errors) == 1 and errors[0].startswith(f"error: cannot save {blend}: "), proc.stderr
            assert errors[0].endswith("the earlier file is kept")
            assert blend.read_bytes() == earlier and sorted(os.listdir(disk)) == ["box.blend"]
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def test_an_output_folder_that_cannot_be_made_is_one_line_before_the_run(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("not a folder")
    for args in (["-o", str(afile / "sub" / "x.blend")],
                 ["-o", str(tmp_path / "x.blend"), "--preview", str(afile / "x.png")],
                 ["-o", str(tmp_path)]):
        proc = _cli([*QUICK, *args], str(tmp_path))
        assert proc.returncode == 2, proc.stderr[-2000:]
        assert "Traceback" not in proc.stderr and "patches" not in proc.stdout  # said before the solve
        errors = [line for line in proc.stderr.splitlines() if line.strip()]
        assert len(errors) == 1 and errors[0].startswith("error: cannot "), proc.stderr
    assert sorted(os.listdir(tmp_path)) == ["afile"]


# ---------------------------------------------------------------------------------------------
# On a terminal: Ctrl-C and the progress line
# ---------------------------------------------------------------------------------------------

class Terminal:
    """``python -m addon`` on a pseudo-terminal ``columns`` wide, its output read as it comes."""

    def __init__(self, args, cwd, columns=80, env=None):
        pid, fd = pty.fork()
        if pid == 0:  # the child: the terminal's size, then the command line
            try:
                fcntl.ioctl(1, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
                # as a shell starts a job in the foreground: a test run started in the background
                # (CI) has SIGINT ignored (under nohup SIGHUP too), or a runner's thread has them
                # blocked; exec would hand both on, and a program rightly keeps an ignored signal
                stopping = {signal.SIGINT, signal.SIGHUP, signal.SIGTERM}
                for signum in stopping:
                    signal.signal(signum, signal.SIG_DFL)
                signal.pthread_sigmask(signal.SIG_UNBLOCK, stopping)
                os.chdir(cwd)
                os.execve(sys.executable, [sys.executable, "-m", "addon", *args], env or ENV)
            finally:
                os._exit(127)
        os.set_inheritable(fd, False)  # (no other child of this process keeps the terminal open)
        self.pid, self.fd, self.data, self.status = pid, fd, b"", None

    def state(self):
        """What the child is doing, for a failure's message: its threads' states and where they
        wait, its signals (pending, blocked, ignored, caught) and who else holds a terminal's master."""
        lines = []
        try:
            status = open(f"/proc/{self.pid}/status").read().splitlines()
            lines += [line for line in status if line.split(":")[0] in ("State", "SigPnd", "ShdPnd", "SigBlk", "SigIgn", "SigCgt")]
            for task in sorted(os.listdir(f"/proc/{self.pid}/task")):
                wchan = open(f"/proc/{self.pid}/task/{task}/wchan").read()
                comm = open(f"/proc/{self.pid}/task/{task}/comm").read().strip()
                lines.append(f"thread {task} {comm}: {wchan}")
        except OSError as exc:
            lines.append(f"(no /proc state: {exc})")
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                for fd in os.listdir(f"/proc/{pid}/fd"):
                    if os.readlink(f"/proc/{pid}/fd/{fd}") in ("/dev/ptmx", "/dev/pts/ptmx"):
                        lines.append(f"process {pid} holds a terminal master as fd {fd}")
            except OSError:
                continue
        return "\n".join(lines)

    @property
    def text(self):
        return self.data.decode(errors="replace")

    def _read(self, seconds):
        ready, _, _ = select.select([self.fd], [], [], seconds)
        if ready:
            try:
                chunk = os.read(self.fd, 65536)
            except OSError:  # the child has closed the terminal
                chunk = b""
            self.data += chunk
            return bool(chunk)
        return True

    def read_until(self, pattern, timeout):
        end = time.monotonic() + timeout
        while re.search(pattern, self.text) is None:
            assert time.monotonic() < end, f"no {pattern!r} in {self.text[-2000:]!r}"
            if not self._read(0.05):
                raise AssertionError(f"ended before {pattern!r}: {self.text[-2000:]!r}")

    def wait(self, timeout):
        """The exit status, reading the output until the process ends (None after ``timeout``)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                while self._read(0.05) and select.select([self.fd], [], [], 0)[0]:
                    pass
                self.status = os.waitstatus_to_exitcode(status)
                return self.status
            self._read(0.05)
        return None

    def close(self):
        if self.status is None:
            os.kill(self.pid, signal.SIGKILL)
            os.waitpid(self.pid, 0)
        os.close(self.fd)


def screen(text, columns):
    """The rows a terminal ``columns`` wide shows for ``text`` (carriage returns, line feeds and
    the wrap at the last column; colour codes dropped)."""
    rows, row, col, wrap = [], [], 0, False
    for ch in re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", text):
        if ch == "\r":
            col, wrap = 0, False
        elif ch == "\n":
            rows.append("".join(row).rstrip())
            row, col, wrap = [], 0, False
        elif ch >= " ":
            if wrap:
                rows.append("".join(row).rstrip())
                row, col, wrap = [], 0, False
            row[col:col + 1] = [ch] if col < len(row) else [" "] * (col - len(row)) + [ch]
            col += 1
            if col == columns:
                col, wrap = columns - 1, True
    return rows + ["".join(row).rstrip()]


SLOW = ["--scene", "cornell", "--error", "0.15", "--no-preview"]  # minutes (warned before): Ctrl-C comes first


@pytest.mark.parametrize("quiet", [False, True], ids=["progress", "quiet"])
@pytest.mark.parametrize("how", ["key", "signal"])
def test_ctrl_c_during_the_solve_stops_at_once_with_one_line_and_130(tmp_path, how, quiet):
    out = tmp_path / "out"
    term = Terminal([*SLOW, "-o", str(out / "slow.blend"), *(["-q"] if quiet else [])], str(tmp_path))
    try:
        if quiet:
            term.read_until(r"warning: Predicted", 120)  # said before the solve starts
            time.sleep(1.5)
        else:
            term.read_until(r"expected paths", 120)
        before = len(term.data)
        sent = time.monotonic()
        if how == "key":
            os.write(term.fd, b"\x03")  # the terminal makes it SIGINT, to the foreground group
        else:
            os.kill(term.pid, signal.SIGINT)
        status = term.wait(30)
        seconds = time.monotonic() - sent
    finally:
        term.close()
    after = term.data[before:].decode(errors="replace")
    assert status == 130, term.text[-3000:]
    assert seconds < 2.0, seconds
    assert "Traceback" not in term.text and "KeyboardInterrupt" not in term.text and "rror" not in after, after
    assert [row for row in screen(after, 80) if row.strip()] == [INTERRUPTED], repr(after)
    assert not out.exists()  # nothing written, not even the folder


def test_ctrl_c_during_the_preview_render_leaves_no_file(tmp_path):
    """The render holds the main thread in Blender's code: the watchdog ends the process."""
    out = tmp_path / "out"
    term = Terminal(["--scene", "cornell", "--error", "20", "--patch-size", "0.4", "--resolution", "2000",
                     "--samples", "4096", "-o", str(out / "box.blend")], str(tmp_path))
    try:
        term.read_until(r"sources: ", 120)
        time.sleep(1.0)  # rendering (minutes at this size)
        before = len(term.data)
        sent = time.monotonic()
        os.write(term.fd, b"\x03")
        status = term.wait(30)
        seconds = time.monotonic() - sent
    finally:
        term.close()
    after = term.data[before:].decode(errors="replace")
    assert status == 130 and seconds < 2.0, (status, seconds, term.text[-3000:])
    assert "Traceback" not in term.text and "saved:" not in term.text
    assert [row for row in screen(after, 80) if row.strip()] == [INTERRUPTED], repr(after)
    assert os.listdir(out) == []  # no half-written file, no temporary


def test_the_progress_line_ends_cleanly_on_a_narrow_terminal(tmp_path):
    """On a terminal narrower than the progress text, the line is rewritten in place (no trail
    of progress rows), cleared at the end, and the run's warnings start rows of their own."""
    columns = 60
    term = Terminal(["--scene", "cornell", "--error", "0.3", "--time-limit", "10", "--no-preview",
                     "-o", str(tmp_path / "t.blend")], str(tmp_path), columns=columns)
    try:
        status = term.wait(300)
    finally:
        term.close()
    assert status == 0, term.text[-3000:]
    assert "expected paths" in term.text  # a progress line was shown
    rows = screen(term.text, columns)
    progress = re.compile(r"^\s*\d+\.\d%  |expected paths|Mray/s|\d:\d\d left|\(target ")
    assert not [row for row in rows if progress.search(row)], rows
    assert any(row.startswith("Warning: Time limit reached") for row in rows), rows
    assert any(row.startswith("saved: ") for row in rows), rows


# ---------------------------------------------------------------------------------------------
# SIGTERM (a timeout, a CI cancel) and SIGHUP (the terminal closed): as Ctrl-C
# ---------------------------------------------------------------------------------------------

# A save that takes its time (save_post: the temporary .blend is on disk): the signal comes during it.
SLOW_SAVE = """
import sys, time
import bpy
from addon.__main__ import main

@bpy.app.handlers.persistent
def slow(path, *_):
    print("saving", file=sys.stderr, flush=True)  # (stdout is taken from the save)
    time.sleep(60)

bpy.app.handlers.save_post.append(slow)
sys.exit(main(sys.argv[1:]))
"""

# A host's script (as inside Blender: main(['--current'])) that would go on after main returns; its
# save waits in Python until the test says (a file appears), so the main thread itself meets the signal.
HOST = """
import os, sys, time
import bpy
from addon.__main__ import main

@bpy.app.handlers.persistent
def held(path, *_):
    print("saving", file=sys.stderr, flush=True)
    while not os.path.exists(os.environ["GO_ON"]):
        time.sleep(0.01)

bpy.app.handlers.save_post.append(held)
main(sys.argv[1:])
print("the host went on", flush=True)
"""

RENDER = ["--resolution", "2000", "--samples", "4096"]  # minutes of rendering: the signal comes first


class Piped:
    """The command line with its output on pipes (as under ``timeout`` or a CI runner), read as it
    comes, Blender's temporary folder in a folder of its own (``TMPDIR``)."""

    def __init__(self, args, cwd, temp, code=None, env=None):
        command = [sys.executable, "-c", code, *args] if code else [sys.executable, "-m", "addon", *args]
        self.proc = subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     env={**ENV, "TMPDIR": str(temp), **(env or {})}, start_new_session=True)
        self.data = b""

    def read_until(self, pattern, timeout):
        end = time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        while re.search(pattern, self.data.decode(errors="replace")) is None:
            assert time.monotonic() < end and self.proc.poll() is None, self.data.decode(errors="replace")[-2000:]
            if select.select([fd], [], [], 0.05)[0]:
                self.data += os.read(fd, 65536)

    def stop(self, signum, timeout=30, then=None):
        """Send ``signum`` (and call ``then()``): (exit status, seconds it took, what was printed after it)."""
        before = len(self.data)
        sent = time.monotonic()
        self.proc.send_signal(signum)
        if then is not None:
            time.sleep(0.05)  # (the signal handled first)
            then()
        try:
            rest, _ = self.proc.communicate(timeout=timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
        self.data += rest
        return self.proc.returncode, time.monotonic() - sent, self.data[before:].decode(errors="replace")


def _source_file(tmp_path):
    """A saved file to --open: its save comes before the preview, so a temporary .blend is on disk while it renders."""
    source = tmp_path / "src.blend"
    proc = _cli([*QUICK, "-o", str(source), "--no-preview", "-q"], str(tmp_path))
    assert proc.returncode == 0, proc.stderr[-2000:]
    return source


@pytest.mark.parametrize("stage", ["solve", "render", "save", "host"])
def test_sigterm_stops_as_ctrl_c_does_with_143_and_leaves_no_file(tmp_path, stage):
    """SIGTERM (``timeout``, a CI cancel) in the solve, in Blender's render holding the main
    thread (a temporary .blend already written), or in the save: one line, status 143, no
    temporary file beside the output and nothing left in the temporary folder. Called from a
    host's script, the process ends too, as SIGTERM's default would end it."""
    out, temp = tmp_path / "out", tmp_path / "tmp"
    temp.mkdir()
    args, code, ready = {
        "solve": ([*SLOW, "-q"], None, r"warning: Predicted"),
        "render": (["--open", str(_source_file(tmp_path)), *QUICK[2:], *RENDER], None, r"sources: "),
        "save": ([*QUICK, "--no-preview"], SLOW_SAVE, r"saving"),
        "host": ([*QUICK, "--no-preview"], HOST, r"saving"),
    }[stage]
    go_on = tmp_path / "go on"
    run = Piped([*args, "-o", str(out / "box.blend")], str(tmp_path), temp, code, {"GO_ON": str(go_on)})
    run.read_until(ready, 120)
    time.sleep(1.0)  # in the solve, the render or the save
    status, seconds, after = run.stop(signal.SIGTERM, then=go_on.touch)
    assert status == 143 and seconds < 3.0, (status, seconds, run.data.decode(errors="replace")[-3000:])
    assert [line for line in after.splitlines() if line.strip()] == [
        "interrupted: stopped by SIGTERM; nothing was saved"], after
    assert "saved:" not in run.data.decode(errors="replace")
    assert not out.exists() or os.listdir(out) == []  # no .box.PID.partial.blend
    assert os.listdir(temp) == []  # Blender's session folder removed


def test_a_closed_terminal_stops_the_run_with_129_and_leaves_no_file(tmp_path):
    """The terminal closed during the preview (SIGHUP; nothing left to print on): status 129,
    no temporary .blend beside the output, nothing left in the temporary folder."""
    out, temp = tmp_path / "out", tmp_path / "tmp"
    temp.mkdir()
    source = _source_file(tmp_path)
    term = Terminal(["--open", str(source), *QUICK[2:], *RENDER, "-o", str(out / "box.blend")], str(tmp_path),
                    env={**ENV, "TMPDIR": str(temp)})
    try:
        term.read_until(r"sources: ", 120)
        time.sleep(1.0)  # rendering
        os.close(term.fd)  # the terminal closes: its session's leader gets SIGHUP
        term.fd = os.open(os.devnull, os.O_RDONLY)  # (for close())
        end, status = time.monotonic() + 30, None
        while status is None and time.monotonic() < end:
            pid, raw = os.waitpid(term.pid, os.WNOHANG)
            status = os.waitstatus_to_exitcode(raw) if pid else None
            time.sleep(0.05)
        term.status = status
        state = term.state() if status is None else ""
    finally:
        term.close()
    assert status == 129, (status, state, term.text[-3000:])
    assert os.listdir(out) == [] and os.listdir(temp) == []
