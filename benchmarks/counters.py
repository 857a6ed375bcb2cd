"""The processor's own counters for the calling thread (Linux perf_event_open, through ctypes):
cycles and lines fetched from memory, counted in user space only. Lines from memory are the
data cache fills from DRAM on AMD Zen 3 and later (raw event 0x44, unit mask 0x08: the generic
"cache-misses" event counts L2 misses there, most of which the L3 cache serves), and last-level
cache read misses elsewhere.

Used by the throughput breakdown to show where Embree's time goes inside a walk. Where the
kernel refuses (another OS, perf_event_paranoid > 2, a virtual machine without a PMU),
``Counters.open()`` returns None and the benchmark says "n/a"."""
from __future__ import annotations

import ctypes
import fcntl
import os
import platform
import struct

PERF_TYPE_HARDWARE, PERF_TYPE_HW_CACHE, PERF_TYPE_RAW = 0, 3, 4
PERF_COUNT_HW_CPU_CYCLES = 0
LAST_LEVEL_READ_MISSES = 2 | (0 << 8) | (1 << 16)  # PERF_COUNT_HW_CACHE_LL, _OP_READ, _RESULT_MISS
AMD_ZEN_FILLS_FROM_DRAM = 0x0844  # LsAnyFillsFromSys, DRAM (Zen 3, 4, 5)
_SYSCALL_PERF_EVENT_OPEN = {"x86_64": 298, "aarch64": 241}
_ENABLE, _DISABLE = 0x2400, 0x2401  # PERF_EVENT_IOC_ENABLE, PERF_EVENT_IOC_DISABLE
_ATTR_SIZE = 128
_FLAGS = (1 << 0) | (1 << 5) | (1 << 6)  # disabled, exclude_kernel, exclude_hv


class Counters:
    """Cycles and lines fetched from memory of the calling thread, while started. ``read()``
    gives the totals so far as a dict."""

    names = ("cycles", "from_memory")

    def __init__(self, fds):
        self._fds = fds

    @classmethod
    def open(cls):
        number = _SYSCALL_PERF_EVENT_OPEN.get(platform.machine())
        if platform.system() != "Linux" or number is None:
            return None
        libc = ctypes.CDLL(None, use_errno=True)
        libc.syscall.restype = ctypes.c_long
        fds = []
        for kind, config in ((PERF_TYPE_HARDWARE, PERF_COUNT_HW_CPU_CYCLES), _from_memory_event()):
            attr = bytearray(_ATTR_SIZE)
            struct.pack_into("IIQQQQQ", attr, 0, kind, _ATTR_SIZE, config, 0, 0, 0, _FLAGS)
            buffer = ctypes.create_string_buffer(bytes(attr), _ATTR_SIZE)
            fd = libc.syscall(number, buffer, 0, -1, -1, 0)  # this thread, any CPU
            if fd < 0:
                for other in fds:
                    os.close(other)
                return None
            fds.append(fd)
        return cls(fds)

    def start(self):
        for fd in self._fds:
            fcntl.ioctl(fd, _ENABLE)

    def stop(self):
        for fd in self._fds:
            fcntl.ioctl(fd, _DISABLE)

    def read(self):
        return {name: struct.unpack("Q", os.read(fd, 8))[0] for name, fd in zip(self.names, self._fds)}

    def close(self):
        for fd in self._fds:
            os.close(fd)
        self._fds = []


def _from_memory_event():
    """(perf type, config) of the event counting lines fetched from memory on this processor."""
    vendor, family = "", 0
    try:
        with open("/proc/cpuinfo") as info:
            for line in info:
                key, _, value = line.partition(":")
                if key.strip() == "vendor_id":
                    vendor = value.strip()
                elif key.strip() == "cpu family":
                    family = int(value)
                    break
    except (OSError, ValueError):
        pass
    if vendor == "AuthenticAMD" and family >= 0x19:
        return PERF_TYPE_RAW, AMD_ZEN_FILLS_FROM_DRAM
    return PERF_TYPE_HW_CACHE, LAST_LEVEL_READ_MISSES
