"""Reading a Blender image's pixels as linear RGB (bpy glue, one reader for materials and the world).

An image is converted once however many sockets, materials and objects read it, and once for the
estimate and the run that follows it: each read takes its raw pixels (a copy Blender makes fast)
and looks its conversion up by the image and a fingerprint of those pixels (``_CACHE``, the
most recent up to CACHE_BYTES, let go of by ``release``). A byte image's 256 values are converted
by a table, a block of rows at a time, in float32 (a 4096 x 4096 image took 7-11 s and 2.2 GB
converted whole in float64, three times a read). An image whose raw and converted pixels would
pass MAX_TEXTURE_BYTES, or that the memory cannot hold, is refused in one line naming it.
"""

from __future__ import annotations

from collections import OrderedDict
from contextlib import contextmanager

import numpy as np

from . import SceneError

MAX_TEXTURE_BYTES = 4 << 30  # raw (float32, every channel) and linear (float32 RGB) pixels of one image
CACHE_BYTES = 1 << 30  # converted images kept for the next read (the estimate's for the run)
ROWS_BYTES = 1 << 24  # raw pixels converted at a time

_CACHE = OrderedDict()  # (image identity, fingerprint) -> (pixels (H,W,3) float32, read-only; average (3,))
_READING = None  # during one read of the scene (``one_read``): image identity -> (pixels, average)


def srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def release():
    """Lets go of the converted images kept for the next read (a run's own are in its arrays)."""
    _CACHE.clear()


@contextmanager
def one_read():
    """A read of the scene: an image read twice in it is not read again (its pixels cannot
    change meanwhile)."""
    global _READING
    outer = _READING
    _READING = {} if outer is None else outer
    try:
        yield
    finally:
        _READING = outer


def linear_pixels(image, dtype=np.float32):
    """(H, W, 3) linear pixels of an image, row 0 at the bottom (Blender's order), or None if
    it has none (a missing file); read-only in float32 (shared by every reader), a copy in
    another ``dtype``. Byte images hold their colour space's values; float images are scene
    linear. SceneError where the image is too large to read."""
    read = _read(image)
    if read is None:
        return None
    pixels = read[0]
    return pixels if dtype == np.float32 else pixels.astype(dtype)


def image_average(image):
    """Average linear RGB of an image's pixels, or None if it has none (missing file)."""
    read = _read(image)
    return None if read is None else read[1].copy()


def scaled(pixels, scale, offset):
    """``pixels`` (H,W,3) float32 times ``scale`` (3,) plus ``offset`` (3,) (a material's surface
    terms), float32 (half the memory and time of float64), made once in a read of the scene."""
    key = (id(pixels), np.asarray(scale, np.float64).tobytes(), np.asarray(offset, np.float64).tobytes())
    if _READING is not None and key in _READING:
        return _READING[key][0]
    out = pixels * np.asarray(scale, np.float32)
    out += np.asarray(offset, np.float32)
    if _READING is not None:
        _READING[key] = (out, pixels)  # (the source kept with it: its id stays its own)
    return out


def _read(image):
    """(pixels, average) of ``image`` from the cache, else converted and kept; None without pixels."""
    try:
        width, height = image.size[:]
        channels = image.channels
    except Exception:  # noqa: BLE001 - unreadable image: the caller falls back and says so
        return None
    if width * height == 0 or channels < 1:
        return None
    identity = (image.session_uid, image.name_full)
    if _READING is not None and identity in _READING:
        return _READING[identity]
    made = _fresh(image, width, height, channels)
    if _READING is not None:
        _READING[identity] = made
    return made


def _fresh(image, width, height, channels):
    """``_read`` of an image not read yet in this read of the scene."""
    _check_size(image, width, height, channels)
    try:
        raw = np.empty(width * height * channels, dtype=np.float32)
        image.pixels.foreach_get(raw)
    except MemoryError:
        raise SceneError(_too_large(image, width, height, channels)) from None
    except Exception:  # noqa: BLE001 - unreadable image: the caller falls back and says so
        return None
    key = (image.session_uid, image.name_full, width, height, channels, bool(image.is_float),
           image.colorspace_settings.name, _fingerprint(raw))
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    srgb = not image.is_float and image.colorspace_settings.name == "sRGB"
    try:
        pixels = _converted(raw, height, width, channels, srgb)
    except MemoryError:
        raise SceneError(_too_large(image, width, height, channels)) from None
    del raw
    pixels.flags.writeable = False
    made = (pixels, pixels.reshape(-1, 3).mean(axis=0, dtype=np.float64))
    _CACHE[key] = made
    while sum(p.nbytes for p, _ in _CACHE.values()) > CACHE_BYTES and len(_CACHE) > 1:
        _CACHE.popitem(last=False)
    if pixels.nbytes > CACHE_BYTES:
        _CACHE.pop(key)
    return made


def _check_size(image, width, height, channels):
    if _bytes(width, height, channels) > MAX_TEXTURE_BYTES:
        raise SceneError(_too_large(image, width, height, channels))


def _bytes(width, height, channels):
    """Bytes of an image's raw pixels and its linear ones, both float32."""
    return width * height * (channels + 3) * 4


def _too_large(image, width, height, channels):
    need, limit = _bytes(width, height, channels) / 2**30, MAX_TEXTURE_BYTES / 2**30
    return (f"image '{image.name}' is {width:,} x {height:,} pixels: reading it as linear colour takes "
            f"{need:.1f} GB, more than the {limit:.1f} GB a texture may take (or this machine's free memory); "
            "scale it down (Image > Resize) or use a smaller copy. Nothing was changed")


def _fingerprint(raw):
    """Two sums over the raw pixels' bits (a changed pixel changes them)."""
    words = raw.view(np.uint32)
    step = max(1, words.size // (1 << 22))  # (every word; the second sum weighs a sample by place)
    return int(words.sum(dtype=np.uint64)), int((words[::step].astype(np.uint64) * np.arange(
        1, words[::step].size + 1, dtype=np.uint64)).sum(dtype=np.uint64))


def _converted(raw, height, width, channels, srgb):
    """(H, W, 3) float32 linear pixels of ``raw`` (H*W*channels), a block of rows at a time:
    an sRGB byte value through a table of the 256 (the same float64 conversion as each pixel's
    alone), any other value converted itself."""
    out = np.empty((height, width, 3), np.float32)
    raw = raw.reshape(height, width, channels)
    step = max(1, ROWS_BYTES // max(width * channels * 4, 1))
    table = None
    for start in range(0, height, step):
        block = raw[start:start + step]
        rgb = block[..., :3] if channels >= 3 else np.repeat(block[..., :1], 3, axis=2)
        if not srgb:
            out[start:start + step] = rgb
            continue
        level = (rgb * np.float32(255.0) + np.float32(0.5)).astype(np.uint8)  # (a value out of range: odd below)
        if table is None:
            values = np.arange(256, dtype=np.float32) * np.float32(1.0 / 255.0)  # (a byte's float as Blender gives it)
            table = (values, srgb_to_linear(values).astype(np.float32))
        converted = table[1][level]
        odd = table[0][level] != rgb  # (not a byte's value: a float written to a byte image's buffer)
        if odd.any():
            converted[odd] = srgb_to_linear(rgb[odd]).astype(np.float32)
        out[start:start + step] = converted
    return out
