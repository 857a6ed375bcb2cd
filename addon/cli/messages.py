"""One-line messages: an error raised through ``bpy.ops`` made one line, and an error printed
with the status it ends the run with."""

from __future__ import annotations

import sys


def one_line(exc) -> str:
    """An error raised through ``bpy.ops`` (RuntimeError 'Error: ...') as one line."""
    lines = [line.strip() for line in str(exc).strip().splitlines() if line.strip()]
    if any(line.startswith("Traceback") or "Python: Traceback" in line for line in lines):
        lines = lines[-1:]  # an exception inside an operator: its last line says what
    text = " ".join(lines)
    for prefix in ("Error:", "Python:"):
        if text.startswith(prefix):
            text = text[len(prefix):].strip()
    return text or type(exc).__name__


def fail(message, status=1):
    print(f"error: {message}", file=sys.stderr)
    return status

