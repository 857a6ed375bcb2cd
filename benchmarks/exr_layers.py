"""A reader of the uncompressed multilayer OpenEXR files Cycles writes (numpy only): every
channel of a render's passes, by name, as (H, W) float arrays.

Only what Blender writes with ``exr_codec = 'NONE'``: scanline images, single-part or multipart
(a part per pass), HALF or FLOAT channels (``read_channels`` raises ValueError for anything else).
"""
from __future__ import annotations

import struct

import numpy as np

_PIXEL_TYPES = {1: np.dtype("<f2"), 2: np.dtype("<f4")}  # HALF, FLOAT (UINT is not written for passes)
_TILED, _DEEP, _MULTIPART = 0x02, 0x08, 0x10  # flags of the version field's second byte


def _header(data, pos):
    """(name -> raw bytes of one header's attributes, offset after it)."""
    out = {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        end_type = data.index(b"\0", end + 1)
        size = struct.unpack_from("<i", data, end_type + 1)[0]
        start = end_type + 5
        out[name] = data[start:start + size]
        pos = start + size
    return out, pos + 1


def _channels(raw):
    """[(name, dtype)] in file order (alphabetical, as the format stores them)."""
    out, pos = [], 0
    while raw[pos] != 0:
        end = raw.index(b"\0", pos)
        name = raw[pos:end].decode()
        pixel_type = struct.unpack_from("<i", raw, end + 1)[0]
        if pixel_type not in _PIXEL_TYPES:
            raise ValueError(f"channel {name}: pixel type {pixel_type} is not read")
        out.append((name, _PIXEL_TYPES[pixel_type]))
        pos = end + 1 + 16
    return out


def read_channels(path):
    """{channel name: (H, W) float32 array, row 0 at the top} of an uncompressed scanline EXR."""
    data = open(path, "rb").read()
    if data[:4] != b"\x76\x2f\x31\x01":
        raise ValueError(f"{path}: not an OpenEXR file")
    if data[5] & (_TILED | _DEEP):
        raise ValueError(f"{path}: only scanline OpenEXR files are read")
    multipart = bool(data[5] & _MULTIPART)
    headers, pos = [], 8
    while True:
        header, pos = _header(data, pos)
        headers.append(header)
        if not multipart or data[pos] == 0:
            break
    pos += multipart  # the empty header that ends a multipart file's list
    out = {}
    parts = []
    for header in headers:
        if header["compression"][0] != 0:
            raise ValueError(f"{path}: only uncompressed OpenEXR files are read (exr_codec 'NONE')")
        x0, y0, x1, y1 = struct.unpack("<4i", header["dataWindow"])
        width, height = x1 - x0 + 1, y1 - y0 + 1
        channels = _channels(header["channels"])
        offsets = np.frombuffer(data, "<u8", height, pos)
        pos += 8 * height
        parts.append((y0, width, height, channels, offsets))
    for y0, width, height, channels, offsets in parts:
        line = np.dtype([(name, dtype, (width,)) for name, dtype in channels])
        image = {name: np.empty((height, width), np.float32) for name, _ in channels}
        for offset in offsets:
            at = int(offset) + 4 * multipart  # (a part number first in a multipart file)
            y = struct.unpack_from("<i", data, at)[0] - y0
            row = np.frombuffer(data, line, 1, at + 8)[0]
            for name, _ in channels:
                image[name][y] = row[name]
        out.update(image)
    return out
