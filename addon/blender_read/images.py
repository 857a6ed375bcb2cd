"""Reading a Blender image's pixels as linear RGB (bpy glue, one reader for materials and the world).

Only the raw pixels' copy (``image.pixels.foreach_get``, which bpy needs on the main thread) is
made where the scene is read (``pixels_of``); the rest, on whatever thread asks (the panel's
estimate's, the run's: ``Pixels.read``), needs no bpy. An image is converted once however many
sockets, materials and objects read it, and once for the estimate and the run that follows it:
its conversion is looked up by the image and a fingerprint of its raw pixels (``_CACHE``, the
most recent up to CACHE_BYTES, let go of by ``release``). A byte image's 256 values are converted
by a table, a block of rows at a time, in float32 (a 4096 x 4096 image took 7-11 s and 2.2 GB
converted whole in float64, three times a read). An image whose raw and converted pixels would
pass MAX_TEXTURE_BYTES, or that the memory cannot hold, is refused in one line naming it.
``texture_of`` finds the image texture a material's socket reads per patch.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from contextlib import contextmanager

import numpy as np

from . import SceneError

MAX_TEXTURE_BYTES = 4 << 30  # raw (float32, every channel) and linear (float32 RGB) pixels of one image
CACHE_BYTES = 1 << 30  # converted images kept for the next read (the estimate's for the run)
ROWS_BYTES = 1 << 24  # raw pixels converted at a time

_CACHE = OrderedDict()  # (image identity, fingerprint) -> (pixels (H,W,3) float32, read-only; average (3,))
_LOCK = threading.Lock()  # (the estimate's thread and the run's may read the same image at once)
_CONVERTING = {}  # cache key -> the lock of its conversion under way
_AVERAGES = {}  # image identity -> the average of its pixels as last read (``last_average``)
_READING = None  # during one read of the scene (``one_read``): image identity -> its Pixels


def srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def release():
    """Lets go of the converted images kept for the next read (a run's own are in its arrays)."""
    with _LOCK:
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


class Pixels:
    """An image's raw pixels as the scene's read copied them (main thread), and how to make
    them linear: ``read`` converts them once (or finds them converted), on any thread."""

    def __init__(self, image, raw, width, height, channels):
        self.name, self.width, self.height, self.channels = image.name, width, height, channels
        self.srgb = not image.is_float and image.colorspace_settings.name == "sRGB"
        self.key = (image.session_uid, image.name_full, width, height, channels, bool(image.is_float),
                    image.colorspace_settings.name)
        self.raw = raw
        self._made = None
        self._lock = threading.Lock()

    def read(self):
        """(pixels (H, W, 3) float32 read-only, row 0 at the bottom; average (3,) float64)."""
        with self._lock:
            if self._made is None:
                self._made = _made(self)
                self.raw = None
                with _LOCK:
                    _AVERAGES[self.key[:2]] = self._made[1]
            return self._made

    def too_large(self):
        return _too_large(self.name, self.width, self.height, self.channels)


class Average:
    """The average colour of an image's pixels, known once ``Pixels.read`` has run; ``note`` (or
    None) says it was used, its value added where ``colour`` gives it."""

    def __init__(self, pixels, note):
        self.pixels, self.note = pixels, note


def colour(value, notes):
    """``value`` itself, or an Average's colour (a copy), its note added to ``notes``."""
    if not isinstance(value, Average):
        return value
    average = value.pixels.read()[1].copy()
    if value.note is not None:
        notes.append(value.note + "(" + ", ".join(f"{c:.3g}" for c in average) + ") was used")
    return average


def last_average(image):
    """The average of an image's pixels as a read of the scene last found it (the run's, for
    its results' materials), without reading them again; None where none has."""
    with _LOCK:
        average = _AVERAGES.get((image.session_uid, image.name_full))
    return None if average is None else average.copy()


def pixels_of(image):
    """The Pixels of an image (bpy: the main thread), or None if it has none (a missing file);
    one a read of the scene. SceneError where the image is too large to read."""
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
    if _bytes(width, height, channels) > MAX_TEXTURE_BYTES:
        raise SceneError(_too_large(image.name, width, height, channels))
    try:
        raw = np.empty(width * height * channels, dtype=np.float32)
        image.pixels.foreach_get(raw)
        made = Pixels(image, raw, width, height, channels)
    except MemoryError:
        raise SceneError(_too_large(image.name, width, height, channels)) from None
    except Exception:  # noqa: BLE001 - unreadable image: the caller falls back and says so
        made = None
    if _READING is not None:
        _READING[identity] = made
    return made


def linear_pixels(image, dtype=np.float32):
    """(H, W, 3) linear pixels of an image, row 0 at the bottom (Blender's order), or None if
    it has none (a missing file); read-only in float32 (shared by every reader), a copy in
    another ``dtype``. Byte images hold their colour space's values; float images are scene
    linear. SceneError where the image is too large to read. (Here and now: a read of the
    scene leaves this to its thread, ``pixels_of``.)"""
    made = pixels_of(image)
    if made is None:
        return None
    pixels = made.read()[0]
    return pixels if dtype == np.float32 else pixels.astype(dtype)


def image_average(image):
    """Average linear RGB of an image's pixels, or None if it has none (missing file)."""
    made = pixels_of(image)
    return None if made is None else made.read()[1].copy()


def scaled(pixels, scale, offset, memo=None):
    """``pixels`` (H,W,3) float32 times ``scale`` (3,) plus ``offset`` (3,) (a material's surface
    terms), float32 (half the memory and time of float64), made once a ``memo`` (a dict: one
    resolve of a read)."""
    key = (id(pixels), np.asarray(scale, np.float64).tobytes(), np.asarray(offset, np.float64).tobytes())
    if memo is not None and key in memo:
        return memo[key][0]
    out = pixels * np.asarray(scale, np.float32)
    out += np.asarray(offset, np.float32)
    if memo is not None:
        memo[key] = (out, pixels)  # (the source kept with it: its id stays its own)
    return out


def texture_of(socket):
    """(images.Pixels, affine (2,3), UV map name or '') of an image texture driving ``socket`` through
    a UV map and at most one affine Mapping node, or None where it is anything else."""
    if not socket.is_linked:
        return None
    node = socket.links[0].from_node
    while node.bl_idname == "NodeReroute" and node.inputs[0].is_linked:
        node = node.inputs[0].links[0].from_node
    if node.bl_idname != "ShaderNodeTexImage" or node.image is None or node.projection != "FLAT":
        return None
    affine, uv_name = np.eye(2, 3), ""
    vector = node.inputs["Vector"]
    if vector.is_linked:
        link = vector.links[0]
        if link.from_node.bl_idname == "ShaderNodeMapping":
            affine = _mapping_affine(link.from_node)
            if affine is None or not link.from_node.inputs["Vector"].is_linked:
                return None
            link = link.from_node.inputs["Vector"].links[0]
        if link.from_node.bl_idname == "ShaderNodeUVMap":
            uv_name = link.from_node.uv_map
        elif not (link.from_node.bl_idname == "ShaderNodeTexCoord" and link.from_socket.name == "UV"):
            return None
    pixels = pixels_of(node.image)  # (read where they are used: materials.slot_values)
    if pixels is None:
        return None
    return pixels, affine, uv_name


def _mapping_affine(node):
    """The 2D affine map of a Mapping node (Point or Texture type, rotation about Z only, no
    linked inputs), or None."""
    if node.vector_type not in ("POINT", "TEXTURE"):
        return None
    inputs = {name: node.inputs[name] for name in ("Location", "Rotation", "Scale")}
    if any(socket.is_linked for socket in inputs.values()):
        return None
    location = np.array(inputs["Location"].default_value[:2], dtype=np.float64)
    rx, ry, rz = inputs["Rotation"].default_value[:3]
    if abs(rx) > 1e-9 or abs(ry) > 1e-9:
        return None
    scale = np.array(inputs["Scale"].default_value[:2], dtype=np.float64)
    rotation = np.array([[np.cos(rz), -np.sin(rz)], [np.sin(rz), np.cos(rz)]])
    linear = rotation @ np.diag(scale)
    if node.vector_type == "TEXTURE":  # the inverse of Point
        if abs(np.linalg.det(linear)) < 1e-12:
            return None
        inverse = np.linalg.inv(linear)
        return np.column_stack([inverse, -inverse @ location])
    return np.column_stack([linear, location])


def _made(made):
    """(pixels, average) of a Pixels from the cache, else converted and kept (no bpy). Two
    threads reading the same pixels (the estimate's, a run started meanwhile) convert them once."""
    key = (*made.key, _fingerprint(made.raw))
    with _LOCK:
        converting = _CONVERTING.setdefault(key, threading.Lock())
    try:
        with converting:
            return _cached(key) or _kept(key, _converted_or_refused(made))
    finally:
        with _LOCK:
            _CONVERTING.pop(key, None)


def _cached(key):
    with _LOCK:
        if key in _CACHE:
            _CACHE.move_to_end(key)
            return _CACHE[key]
    return None


def _converted_or_refused(made):
    try:
        pixels = _converted(made.raw, made.height, made.width, made.channels, made.srgb)
    except MemoryError:
        raise SceneError(made.too_large()) from None
    pixels.flags.writeable = False
    return pixels, pixels.reshape(-1, 3).mean(axis=0, dtype=np.float64)


def _kept(key, out):
    """``out`` kept in the cache (the most recent up to CACHE_BYTES)."""
    with _LOCK:
        _CACHE[key] = out
        while sum(p.nbytes for p, _ in _CACHE.values()) > CACHE_BYTES and len(_CACHE) > 1:
            _CACHE.popitem(last=False)
        if out[0].nbytes > CACHE_BYTES:
            _CACHE.pop(key)
    return out


def _bytes(width, height, channels):
    """Bytes of an image's raw pixels and its linear ones, both float32."""
    return width * height * (channels + 3) * 4


def _too_large(name, width, height, channels):
    need, limit = _bytes(width, height, channels) / 2**30, MAX_TEXTURE_BYTES / 2**30
    return (f"image '{name}' is {width:,} x {height:,} pixels: reading it as linear colour takes "
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
