"""Nothing lost: results survive save and reload, a failed write leaves the previous
results whole, a save during a solve holds no half result, and a re-run touches nothing
outside the "Radiosity" collection."""

import time

import bpy
import numpy as np
import pytest

from addon.bpy_free import pipeline
from addon.blender_write.results import MATERIAL_NAME, MATERIAL_PROPERTY, result_collection, write_colours
from addon.blender_write import results as result_writing
from addon.bpy_free import patches, worker
from addon.ui.operators import RADIOSITY_OT_solve

from ..conftest import build_test_scene, read_colours, result_objects
from ..test_extension import _drive, _modal_operator, _snapshot, configure


def _results():
    return {o.name: read_colours(o.data, "Radiosity")[1].tobytes() for o in result_objects()}


def _ours(material):
    return MATERIAL_PROPERTY in material.keys()


def test_reload_then_rerun_replaces_only_the_results(blender, tmp_path):
    build_test_scene()
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    saved = _results()
    path = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    assert _results() == saved  # bit for bit
    before = _snapshot()
    configure(bpy.context, seed=99)  # a different result
    for name in ("Room", "Lamp", "Block"):
        bpy.data.objects[name].select_set(True)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    again = _results()
    assert again.keys() == saved.keys() and again != saved
    assert _snapshot() == before  # originals and their materials untouched
    assert sum(_ours(m) for m in bpy.data.materials) == 1  # the result material reused, not copied
    assert len(bpy.data.collections["Radiosity"].objects) == 3


def test_rerun_touches_nothing_outside_the_radiosity_collection(blender):
    build_test_scene()
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    # The user keeps a copy of a result elsewhere, puts their own object in the collection, has
    # a material of the same name as ours, and a second scene.
    keep = bpy.data.objects["Room Radiosity"].copy()
    keep.data = keep.data.copy()
    keep.name = "Kept version"
    mine = bpy.data.collections.new("Mine")
    blender.scene.collection.children.link(mine)
    mine.objects.link(keep)
    kept_colours = read_colours(keep.data, "Radiosity")[1].tobytes()
    note = bpy.data.objects.new("Note", None)
    bpy.data.collections["Radiosity"].objects.link(note)
    own = bpy.data.materials.new("Radiosity Result")  # named like ours: becomes "...001"
    own.name = "Radiosity Result"  # takes the name: ours is renamed
    own.diffuse_color = (1, 0, 0, 1)
    other = bpy.data.scenes.new("Other")
    cube = bpy.data.objects.new("Other cube", bpy.data.meshes.new("Other cube"))
    other.collection.objects.link(cube)
    before = _snapshot()
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert "Kept version" in bpy.data.objects and keep.users_collection[0] == mine
    assert read_colours(keep.data, "Radiosity")[1].tobytes() == kept_colours
    assert "Note" in bpy.data.collections["Radiosity"].objects
    assert tuple(own.diffuse_color) == (1, 0, 0, 1) and not _ours(own)
    for o in result_objects():
        if o.name != "Kept version":
            assert all(_ours(m) for m in o.data.materials)
    assert "Other cube" in other.collection.objects
    # Everything outside the collection is as it was, except the kept copy we added ourselves.
    after = _snapshot()
    assert after == before


def test_a_failed_write_leaves_the_previous_results_whole(blender, monkeypatch):
    build_test_scene()
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    old = _results()
    objects, meshes = len(bpy.data.objects), len(bpy.data.meshes)
    real = write_colours
    calls = {"n": 0}

    def fail_on_the_second(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise MemoryError("out of memory (simulated)")
        return real(*args, **kwargs)

    monkeypatch.setattr(result_writing, "write_colours", fail_on_the_second)
    configure(blender, seed=42)
    with pytest.raises(RuntimeError, match=r"Writing the result failed, the scene is unchanged"):
        bpy.ops.radiosity.solve()
    assert calls["n"] == 2
    assert _results() == old
    assert (len(bpy.data.objects), len(bpy.data.meshes)) == (objects, meshes)  # nothing left over


def test_a_non_finite_result_is_never_written(blender, monkeypatch):
    build_test_scene()
    configure(blender)
    real = pipeline.run_solve

    def poisoned(*args, **kwargs):
        out = real(*args, **kwargs)
        out.face_colours[0][0, 0] = np.nan
        return out

    monkeypatch.setattr(worker, "run_solve", poisoned)
    with pytest.raises(RuntimeError, match=r"Writing the result failed.*not finite"):
        bpy.ops.radiosity.solve()
    assert not result_objects()


def test_saving_during_a_solve_saves_the_previous_complete_result(blender, tmp_path):
    build_test_scene()
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    old = _results()
    blender.scene.radiosity.target_error = 0.05  # a long run
    op = _modal_operator()
    assert op._start(blender) is None
    t0 = time.perf_counter()
    while op._started.job.snapshot()["paths"] == 0 and time.perf_counter() - t0 < 60:
        time.sleep(0.01)
    path = str(tmp_path / "during.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path, copy=True)
    op._started.job.cancel()
    assert _drive(op, blender) == {"CANCELLED"}
    assert not op._started.job.alive
    bpy.ops.wm.open_mainfile(filepath=path)
    assert _results() == old


def test_undo_removes_the_results_and_redo_brings_them_back(blender):
    """As from the interface: the solve runs with an undo push (the operator's UNDO flag), so
    Ctrl+Z removes the result objects, the collection and the statistics, and Ctrl+Shift+Z
    brings them back bit for bit. (Background Blender starts with undo off: one push turns it on.)"""
    assert {"REGISTER", "UNDO"} <= set(RADIOSITY_OT_solve.bl_options)
    build_test_scene()
    configure(blender)
    bpy.ops.ed.undo_push(message="scene built")
    before = _snapshot()
    assert bpy.ops.radiosity.solve("EXEC_DEFAULT", True) == {"FINISHED"}  # undo=True: as the UI calls it
    results = _results()
    assert len(results) == 3 and bpy.context.scene.radiosity.last_paths > 0
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert not result_objects() and "Radiosity" not in bpy.data.collections
    assert bpy.context.scene.radiosity.last_paths == 0
    assert _snapshot() == before
    assert bpy.ops.ed.redo() == {"FINISHED"}
    assert _results() == results and bpy.context.scene.radiosity.last_paths > 0
    objects, materials = _snapshot()
    assert objects == before[0]
    assert {k: v for k, v in materials.items() if k != MATERIAL_NAME} == before[1]


def _collection_colours(collection):
    return {o.name: read_colours(o.data, "Radiosity")[1].tobytes() for o in collection.objects}


def test_each_scene_keeps_its_own_results(blender):
    build_test_scene()
    configure(blender)
    first = blender.scene
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    first_results = result_collection(first, create=False)
    assert first_results.name == "Radiosity"
    kept = _collection_colours(first_results)
    # A second scene of the same file with objects of its own, solved there.
    second = bpy.data.scenes.new("Second")
    blender.window.scene = second
    build_test_scene()
    configure(bpy.context, seed=11)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    second_results = result_collection(second, create=False)
    assert second_results is not None and second_results != first_results
    assert len(second_results.objects) == 3
    assert first_results.name not in second.collection.children
    assert second_results.name not in first.collection.children
    assert _collection_colours(first_results) == kept  # the first scene's results untouched
    # A re-run in the first scene replaces its own results only.
    second_kept = _collection_colours(second_results)
    blender.window.scene = first
    configure(bpy.context, seed=12)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert _collection_colours(first_results).keys() == kept.keys()
    assert _collection_colours(first_results) != kept
    assert _collection_colours(second_results) == second_kept
