"""The glue's memory give-back (addon/trim.py): with glibc's mmap threshold fixed, a freed array
of a solve's (C,P) size leaves the resident set at once (it lowers the million-patch peak)."""
import platform
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# In a fresh process (a heap with free blocks of the size would serve the arrays from them):
# a float64 array of a million patches' three channels (23 MiB, above the fixed threshold),
# made and freed three times, the resident set (MiB) with it and after it each time.
SCRIPT = """
import os, sys
import numpy as np
from addon.bpy_free import trim
def resident():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
if sys.argv[1] == "fixed":
    assert trim.fix_mmap_threshold()
before = resident()
for _ in range(3):
    a = np.ones(3 * 1_000_000)
    print(resident() - before, end=" ")
    del a
    print(resident() - before)
"""


def _run(mode):
    out = subprocess.run([sys.executable, "-c", SCRIPT, mode], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [tuple(map(float, line.split())) for line in out.splitlines()]


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc's malloc only")
def test_freed_big_arrays_leave_the_resident_set_with_the_threshold_fixed():
    fixed, unfixed = _run("fixed"), _run("unfixed")
    assert all(held > 20 and after < 3 for held, after in fixed)
    # (glibc's own threshold rises past the first array freed: the later ones stay resident)
    assert unfixed[0][1] < 3 and all(after > 20 for _, after in unfixed[1:])
