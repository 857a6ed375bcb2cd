"""Memory freed by one stage of a solve given back to the system before the next.

glibc's malloc keeps freed blocks below its mmap threshold (which grows to 32 MiB as large
arrays come and go) in its heaps, where they stay resident until ``malloc_trim``: between
meshing, building the core's scene and solving a million patches that was hundreds of MiB.
Elsewhere (other C libraries, Windows, macOS) this does nothing. No bpy.
"""
from __future__ import annotations

import ctypes
from contextlib import contextmanager


def _malloc_trim():
    try:
        return ctypes.CDLL(None).malloc_trim
    except Exception:  # noqa: BLE001 - no such function (not glibc), or no C library to ask
        return None


_MALLOC_TRIM = _malloc_trim()


def _mallopt():
    try:
        return ctypes.CDLL(None).mallopt
    except Exception:  # noqa: BLE001 - not glibc
        return None


_MALLOPT = _mallopt()
M_MMAP_THRESHOLD = -3
# Blocks of at least this size are mapped on their own and unmapped when freed: a solve's (C,P)
# arrays of a big scene (23 MiB at a million patches) come and go straight to the system, while
# a walk's per-step arrays (up to a few MiB) stay in the heaps (mapping those too cost 2x in time).
MMAP_THRESHOLD = 16 << 20


def fix_mmap_threshold() -> bool:
    """Fix glibc's mmap threshold at MMAP_THRESHOLD for the process (it otherwise grows with every
    large array freed, up to 32 MiB, and arrays below it stay resident after they are freed);
    True if it could. Once is enough; again is harmless."""
    if _MALLOPT is None:
        return False
    return bool(_MALLOPT(M_MMAP_THRESHOLD, MMAP_THRESHOLD))


def give_back() -> bool:
    """Return the freed memory of the process's heaps to the system (glibc: ``malloc_trim(0)``,
    a few ms); True if it could."""
    if _MALLOC_TRIM is None:
        return False
    _MALLOC_TRIM(0)
    return True


M_TRIM_THRESHOLD = -1
TRIM_THRESHOLD = 128 << 10  # glibc's default, which a fixed mmap threshold leaves in place
# Below this many patches building the scene, the solve and its colours keep what they free for
# their next arrays (``roomy``): given back at every free, they were faulted in again at the next
# allocation (benchmarks/results/operator_stages.md).
ROOMY_MAX_PATCHES = 1 << 17
ROOMY_BYTES = 64 << 20


@contextmanager
def roomy(patch_count):
    """While it lasts, blocks up to ROOMY_BYTES come from the heaps, and up to that much freed
    memory stays in them (glibc's mmap and trim thresholds), for a scene of at most
    ROOMY_MAX_PATCHES patches (a bigger one's memory stays as fixed: its arrays go back when
    freed); then the thresholds as before, and the freed memory given back (whatever the size)."""
    roomy_now = _MALLOPT is not None and patch_count <= ROOMY_MAX_PATCHES
    if roomy_now:
        _MALLOPT(M_MMAP_THRESHOLD, ROOMY_BYTES)
        _MALLOPT(M_TRIM_THRESHOLD, ROOMY_BYTES)
    try:
        yield
    finally:
        if roomy_now:
            _MALLOPT(M_MMAP_THRESHOLD, MMAP_THRESHOLD)
            _MALLOPT(M_TRIM_THRESHOLD, TRIM_THRESHOLD)
        give_back()
