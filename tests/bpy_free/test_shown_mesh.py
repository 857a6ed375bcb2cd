"""The meshes the display is written on (addon/bpy_free/shown_mesh.py): the display's cells are the
same for the same seed (their new points' retries a count, not a time), every output is per polygon
of the written mesh, and turning them off writes one polygon a patch."""
import numpy as np
from many_lamps import room_objects

from addon.bpy_free import pipeline, shown_mesh


def _run(**settings):
    return pipeline.run_solve(room_objects(4), pipeline.SolveSettings(seed=3, relative_rms=0.1, patch_size=0.5,
                                                                      threads=2, **settings))


def test_the_same_seed_gives_the_same_cells_and_colours():
    """Two runs of a room lit by four lamps under its ceiling: the cells split (the lamps' hot spots on
    the ceiling), the same on both, and every colour the same to the bit."""
    first, second = _run(), _run()
    assert first.shown is not None
    for k, o in enumerate(first.patches.objects):
        mesh = shown_mesh.mesh_of(first, k)
        np.testing.assert_array_equal(mesh.corner_verts, shown_mesh.mesh_of(second, k).corner_verts)
        for name in ("smooth_colours", "light_colours", "face_colours"):
            np.testing.assert_array_equal(getattr(first, name)[k], getattr(second, name)[k])
        # per polygon of the written mesh: a colour a polygon, a corner colour a polygon corner
        assert len(first.face_colours[k]) == mesh.patch_count
        assert len(first.smooth_colours[k]) == len(mesh.corner_verts)
    assert sum(shown_mesh.mesh_of(first, k).patch_count for k in range(len(first.patches.objects))) > \
        first.patches.combined.patch_count


def test_without_display_cells_each_patch_is_one_polygon():
    out = _run(display_cells=False)
    assert out.shown is None
    for k in range(len(out.patches.objects)):
        assert shown_mesh.mesh_of(out, k) is out.patches.meshes[k]
        assert len(out.face_colours[k]) == out.patches.meshes[k].patch_count
