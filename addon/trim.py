"""Memory freed by one stage of a solve given back to the system before the next (issue 26).

glibc's malloc keeps freed blocks below its mmap threshold (which grows to 32 MiB as large
arrays come and go) in its heaps, where they stay resident until ``malloc_trim``: between
meshing, building the core's scene and solving a million patches that was hundreds of MiB.
Elsewhere (other C libraries, Windows, macOS) this does nothing. No bpy.
"""
from __future__ import annotations

import ctypes


def _malloc_trim():
    try:
        return ctypes.CDLL(None).malloc_trim
    except Exception:  # noqa: BLE001 - no such function (not glibc), or no C library to ask
        return None


_MALLOC_TRIM = _malloc_trim()


def give_back() -> bool:
    """Return the freed memory of the process's heaps to the system (glibc: ``malloc_trim(0)``,
    a few ms); True if it could."""
    if _MALLOC_TRIM is None:
        return False
    _MALLOC_TRIM(0)
    return True
