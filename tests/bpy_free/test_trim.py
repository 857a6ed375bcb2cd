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


# A chunk's arrays made and freed ten times (20 MiB, above the fixed threshold): the page faults
# (thousands) of the loop, then the resident set (MiB) above the start once one more is freed.
ROOMY = """
import os, resource, sys
import numpy as np
from addon.bpy_free import trim
def resident():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
assert trim.fix_mmap_threshold()
before = resident()
with trim.roomy(int(sys.argv[1])):
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        a = np.ones(20 << 17)
        del a
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
a = np.ones(20 << 17)
del a
print(faults / 1000, resident() - before)
"""


def _roomy(patches):
    out = subprocess.run([sys.executable, "-c", ROOMY, str(patches)], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout
    return tuple(map(float, out.split()))


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc's malloc only")
def test_a_small_solve_keeps_its_freed_arrays_and_gives_them_back_after():
    """Under ``trim.roomy`` a small scene's chunk arrays are made from what the last chunk freed
    (an array's pages fault in once, not at every chunk: a tenth of the faults or less, however
    the kernel sizes its pages); a big scene's go back to the system at once, each array faulting
    in its own; after it, either way, what is freed leaves the resident set."""
    small_faults, small_after = _roomy(11_000)
    big_faults, big_after = _roomy(1_000_000)
    assert small_faults * 5 < big_faults
    assert small_after < 3 and big_after < 3
