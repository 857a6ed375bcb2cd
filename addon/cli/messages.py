"""One-line messages: an error raised through ``bpy.ops`` made one line, and an error printed
with the status it ends the run with."""

from __future__ import annotations

import sys

from ..bpy_free import options


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


def for_command_line(text) -> str:
    """A message naming a panel switch ("turn on 'Clamp bright colours'") as its command-line
    flag ("add --clamp-bright-colours"): the flags are what works here."""
    for option in options.SETTINGS:
        if isinstance(option, options.Flag):
            off = "--no-" + option.flag[2:]
            for said, meant in ((f"turn on '{option.label}'", f"add {option.flag}"),
                                (f"turn off '{option.label}'", f"add {off}"),
                                (f"'{option.label}' is on", f"{option.flag} is on"),
                                (f"'{option.label}' is off", f"{off} is given")):
                text = text.replace(said, meant)
    return text


def fail(message, status=1):
    print(f"error: {for_command_line(message)}", file=sys.stderr)
    return status

