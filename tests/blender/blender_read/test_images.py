"""Large image textures (addon/blender_read/images.py): converted once a run however many sockets
and objects use them, the estimate's conversion reused by the next read where the pixels are the
same (converted again where they changed), and an image too large for the memory refused in one
line naming it, nothing changed."""
import threading

import numpy as np
import pytest

import bpy

from addon.blender_read import images
from addon.blender_read.selection import read_selection
from addon.blender_write import solve_job
from addon.ui import estimate

from ..conftest import build_test_scene, make_object, box_arrays, result_objects
from ..test_extension import _snapshot, configure
from .test_lights import _world_image


def _textured_scene(size=512):
    """The test room, its white walls' base colour and a second box's from one sRGB byte image
    of ``size`` x ``size`` random pixels (four sockets read it: two objects' colour and surface
    terms, the texture itself per patch)."""
    build_test_scene()
    image = bpy.data.images.new("Big", size, size)
    image.pixels.foreach_set(np.float32(0.9) * np.random.default_rng(0).random(size * size * 4, dtype=np.float32))
    material = bpy.data.materials["White"]
    nodes = material.node_tree.nodes
    texture = nodes.new("ShaderNodeTexImage")
    texture.image = image
    material.node_tree.links.new(texture.outputs["Color"], nodes["Principled BSDF"].inputs["Base Color"])
    v, f = box_arrays((0.6, 0.6, 0.0), (0.8, 0.8, 0.2), inward=False)
    make_object("Crate", v, f, [material]).select_set(True)
    for name in ("Room", "Crate"):
        bpy.data.objects[name].data.uv_layers.new(name="UVMap")  # (each face the whole image)
    return image


def _conversions(monkeypatch):
    """A list that grows by one each time an image's pixels are converted to linear colour
    (sRGB to linear: once an image, and once a pixel where there is no table)."""
    calls = []
    convert = images.srgb_to_linear

    def counted(c):
        calls.append(np.size(c))
        return convert(c)

    monkeypatch.setattr(images, "srgb_to_linear", counted)
    return calls


def _where_pixels_are_worked(monkeypatch):
    """A list of (what, on the main thread) that grows each time an image's raw pixels are
    fingerprinted, converted or scaled by a material's terms."""
    calls = []
    for name in ("_fingerprint", "_converted", "scaled"):
        def spy(*args, _name=name, _real=getattr(images, name), **kwargs):
            calls.append((_name, threading.current_thread() is threading.main_thread()))
            return _real(*args, **kwargs)

        monkeypatch.setattr(images, name, spy)
    return calls


@pytest.mark.parametrize("metallic", [0.0, 0.5])
def test_a_textures_conversion_never_runs_on_the_main_thread_for_the_estimate_nor_the_run(blender, monkeypatch,
                                                                                          metallic):
    """The panel's estimate (its timer reads the selection on Blender's main thread) and the
    operator's start (the same): an image texture and the world's environment image are copied
    there, and fingerprinted, converted and scaled by the material's terms on the estimate's
    thread and the run's, once each; the run's end (main thread) writes the textured result
    without reading the image again (a dielectric's terms do not depend on its base colour, a
    metal's take the average the run read).
    (Before, all of it on the main thread: a 4096 x 4096 texture held the interface 4.4 s the
    first time, and the run's end converted it again.)"""
    _textured_scene()
    sky = bpy.data.images.new("Sky", 64, 32)
    sky.pixels.foreach_set(np.random.default_rng(1).random(64 * 32 * 4, dtype=np.float32))
    _world_image(blender, "Sky", sky, 0.5)
    bpy.data.materials["White"].node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = metallic
    configure(blender, output="TEXTURED")
    calls = _where_pixels_are_worked(monkeypatch)
    assert estimate._start() is None and not any(main for _, main in calls), calls
    estimate.STATE.thread.join(120)
    assert "error" not in estimate.STATE.value, estimate.STATE.value
    assert not any(main for _, main in calls)
    assert [what for what, _ in calls].count("_converted") == 2 and ("scaled", False) in calls  # (each image once)
    del calls[:]
    started = solve_job.start(blender)
    assert not calls
    started.job.start()
    started.job.join(120)
    assert started.job.error is None, started.job.error
    assert sorted(set(calls)) == [("_fingerprint", False), ("scaled", False)]  # (the estimate's conversions kept)
    del calls[:]
    assert solve_job.finish(blender, started).status == "FINISHED" and not calls
    assert bpy.data.materials.get("White Radiosity") is not None  # (the textured result was written)
    assert not images._CACHE


def test_an_image_used_by_two_objects_is_converted_once_a_read_and_once_for_the_estimate_and_the_run(
        blender, monkeypatch):
    """Two objects of the textured material: one read of the selection converts the image once
    (before, three times an object: the texture, its average for the colour and for the surface
    terms); the run after the estimate converts it not at all (the same pixels); changed pixels
    are converted again; the run lets go of what was kept for it."""
    image = _textured_scene()
    configure(blender)
    calls = _conversions(monkeypatch)
    objects, _ = read_selection(blender)
    assert len(calls) == 1 and calls[0] == 256  # (the table of the 256 byte values)
    assert sum(o.slot_textures[0] is not None for o in objects if o.slot_textures) == 2
    value = estimate.compute(blender)
    assert "error" not in value and len(calls) == 1
    assert bpy.ops.radiosity.solve() == {"FINISHED"} and len(calls) == 1
    assert not images._CACHE  # (the run's arrays hold the pixels; nothing kept beside them)
    image.pixels.foreach_set(np.zeros(image.size[0] * image.size[1] * 4, np.float32))
    read_selection(blender)
    read_selection(blender)
    assert len(calls) == 2


def test_the_linear_pixels_are_the_per_pixel_conversions_bit_for_bit(blender):
    """The table of byte values gives each pixel what converting it alone in float64 gives."""
    image = _textured_scene(size=64)
    raw = np.empty(64 * 64 * 4, np.float32)
    image.pixels.foreach_get(raw)
    expected = images.srgb_to_linear(raw.reshape(64, 64, 4)[..., :3]).astype(np.float32)
    pixels = images.linear_pixels(image)
    assert np.array_equal(pixels, expected) and not pixels.flags.writeable
    np.testing.assert_allclose(images.image_average(image), expected.reshape(-1, 3).mean(axis=0, dtype=np.float64), rtol=1e-12)


@pytest.mark.parametrize("how", ["limit", "memory"])
def test_an_image_too_large_for_the_memory_is_refused_in_one_line_naming_it(blender, monkeypatch, how):
    """A texture past the size a texture may take (a 512 x 512 one with the limit lowered to a
    megabyte), or one whose conversion the memory cannot hold (a MemoryError): the solve and the
    estimate say so in one line naming the image and its size, and nothing is changed. (Before,
    a 16384 x 16384 texture ended in a MemoryError's 20-line traceback.)"""
    _textured_scene()
    configure(blender)
    if how == "limit":
        monkeypatch.setattr(images, "MAX_TEXTURE_BYTES", 1 << 20, raising=False)
    else:
        def no_memory(*args, **kwargs):
            raise MemoryError

        monkeypatch.setattr(images, "_converted", no_memory, raising=False)
    before = _snapshot()
    finished = solve_job.run(bpy.context)
    error = finished.error
    assert finished.status == "CANCELLED"
    assert "image 'Big' is 512 x 512 pixels" in error and "\n" not in error and "Nothing was changed" in error, error
    assert not result_objects() and _snapshot() == before
    assert estimate.compute(blender)["error"] == error


def test_two_threads_reading_the_same_pixels_at_once_convert_them_once(blender, monkeypatch):
    """The estimate's thread converting an image when a run starts (the run's thread reads the
    same pixels meanwhile): one conversion, the other thread waits for it and takes it."""
    image = _textured_scene(size=64)
    images.release()
    calls = []
    convert = images._converted

    def slow(*args):
        calls.append(threading.current_thread().name)
        started.set()
        assert go.wait(30)  # (held until the other thread asks for the same pixels)
        return convert(*args)

    started, go = threading.Event(), threading.Event()
    monkeypatch.setattr(images, "_converted", slow)
    first, second = images.pixels_of(image), images.pixels_of(image)  # (two reads of the scene)
    out = {}
    threads = [threading.Thread(target=lambda k=k, p=p: out.__setitem__(k, p.read()), name=f"reader {k}")
               for k, p in enumerate((first, second))]
    threads[0].start()
    assert started.wait(30)
    threads[1].start()
    threads[1].join(0.5)  # (waiting for the first's conversion, not making its own)
    go.set()
    for thread in threads:
        thread.join(30)
    assert calls == ["reader 0"] and out[0][0] is out[1][0]
