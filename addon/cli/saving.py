"""Saving: the .blend and the preview written under temporary names, checked whole, then put in
place together, so that a failure (a full disk, Ctrl-C) keeps the earlier files (bpy, imported
where used)."""

from __future__ import annotations

import contextlib
import io
import os

from .messages import one_line


def output_problem(path):
    """Why ``path`` cannot be written (a folder on the way is a file, or not writable), or None."""
    if os.path.isdir(path):
        return f"cannot write {path}: it is a folder"
    folder = os.path.dirname(path)
    existing = folder
    while not os.path.exists(existing):
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        return f"cannot create the folder {folder}: {existing} is a file"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"cannot write in {existing}: permission denied"
    return None


def save_blend(path):
    """Save the open file's data to ``path`` as a copy (the open file keeps its name), without
    Blender's report naming ``path`` (a temporary name)."""
    import bpy

    with contextlib.redirect_stdout(io.StringIO()):
        bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)


def check_blend(path):
    """Raise OSError unless Blender reads ``path`` back as a .blend file (a truncated one, e.g. on
    a full disk, lacks its DNA block)."""
    import bpy

    if os.path.getsize(path) == 0:
        raise OSError("the file written is empty")
    try:
        with bpy.data.libraries.load(path) as (_data_from, _data_to):
            pass
    except OSError as exc:
        reason = one_line(exc).rsplit(": ", 1)[-1]
        raise OSError(f"the file written does not read back ({reason})") from None


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"  # the empty IEND chunk that ends every PNG


def check_png(path):
    """Raise OSError unless ``path`` is a whole PNG file (its signature, and its IEND chunk last)."""
    with open(path, "rb") as f:
        head = f.read(len(PNG_SIGNATURE))
        f.seek(0, os.SEEK_END)
        f.seek(max(f.tell() - len(PNG_END), 0))
        tail = f.read()
    if head != PNG_SIGNATURE or tail != PNG_END:
        raise OSError("the image written is incomplete")


class Outputs:
    """The run's files, each written beside its target under a temporary name (the same folder:
    relative paths in a .blend stay right, and the rename is atomic), checked, then put in place
    together: until then an earlier file of the same name stays as it was."""

    def __init__(self):
        self.files = []  # (temporary path, target, check: raises OSError unless the file is whole)
        self.existed = set()
        self.stage = None  # the target being written

    def add(self, target, check):
        folder, name = os.path.split(target)
        stem, ext = os.path.splitext(name)
        self.files.append((os.path.join(folder, f".{stem}.{os.getpid()}.partial{ext}"), target, check))
        if os.path.exists(target):
            self.existed.add(target)

    def writing(self, target):
        """The temporary path to write ``target``'s content to."""
        self.stage = target
        return next(path for path, t, _ in self.files if t == target)

    def check(self):
        for path, target, check in self.files:
            self.stage = target
            check(path)
        self.stage = None

    def commit(self):
        for path, target, _ in self.files:
            self.stage = target
            os.replace(path, target)
        self.files, self.stage = [], None

    def discard(self):
        """Remove the temporary files (and Blender's own temporary, "<path>@"); never raises."""
        for path, _, _ in self.files:
            for name in (path, path + "@"):
                with contextlib.suppress(OSError):
                    os.remove(name)

    def failure(self, exc):
        """The one line saying what failed, and that the earlier files are kept."""
        reason = one_line(exc) if isinstance(exc, RuntimeError) else (exc.strerror or str(exc))
        where = f" {self.stage}" if self.stage else ""
        kept = "; the earlier file is kept" if self.existed else "; nothing was saved"
        if isinstance(exc, OSError) and exc.filename and not self.stage:
            where = f" {exc.filename}"
        return f"cannot save{where}: {reason}{kept}"

