"""``--relight`` where the stored results cannot follow the change (addon/cli/relight.py
``cannot_follow``): light the solve did not have (a material that did not emit set to emit, the
world turned on, a lamp that was off) and a lamp whose share of the paths a far brighter emitter
hid relit to most of the light. Before, each was relit and saved ("relit: error 4.5%"; the lamp
black at "error 0%"); now exit status 2, one line saying why and to solve again, nothing written.
An unknown name's line lists the solve's sources, at most ten (test_relight_cli.py has the line)."""
import bpy
import pytest

from addon.cli import run as cli_run

from ..ui import relight_scene as rs
from ..ui.test_relight_new_light import background, emits, swamped


def _saved(tmp_path, name="room.blend"):
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / name))


def _refused(tmp_path, capsys, *args):
    out = tmp_path / "never.blend"
    capsys.readouterr()
    status = cli_run.main(["--current", "--relight", *args, "-o", str(out), "--no-preview"])
    err = capsys.readouterr().err.strip()
    assert status == 2 and "\n" not in err and not out.exists(), (status, err)
    return err


def test_a_material_set_to_emit_is_refused(blender, tmp_path, capsys):
    rs.build(blender, "TEXTURED")
    emits("White", 0.0)
    _saved(tmp_path)
    assert _refused(tmp_path, capsys, "--strength", "White=5") == (
        "error: material White: light the solve did not have (off, dark or absent then) cannot be relit: solve again "
        "(--open room.blend without --relight)")


def test_the_world_turned_on_or_a_lamp_that_was_off_is_refused(blender, tmp_path, capsys):
    rs.build(blender, "TEXTURED")
    background().inputs["Strength"].default_value = 0.0
    rs.lamp("POINT", "Spare", (0.5, 0.3, 0.5), 0.0)
    _saved(tmp_path)
    assert _refused(tmp_path, capsys, "--strength", "World=1").startswith(
        "error: world World: light the solve did not have")
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "room.blend"))  # (as saved: the world black again)
    assert _refused(tmp_path, capsys, "--strength", "Spare=20").startswith("error: Spare: light the solve did not have")


def test_a_lamp_hidden_by_a_far_brighter_emitter_relit_to_most_of_the_light_is_refused(blender, tmp_path, capsys):
    swamped(blender, 1e10)
    _saved(tmp_path)
    assert _refused(tmp_path, capsys, "--strength", "Glow=0") == (
        "error: Bulb had too few of the solve's paths (light in fewer than 2 batches) to be relit to this share of "
        "the light: solve again (--open room.blend without --relight)")


@pytest.mark.parametrize("count,expected", [
    (0, ""), (3, "; the solve's sources: 'a', 'b', 'c'"),
    (13, "; the solve's sources: 'a', 'b', 'c', 'd', 'e', 'f', 'g', 'h', 'i', 'j' and 3 more")])
def test_the_list_of_sources_is_shortened_past_ten(count, expected):
    from addon.cli.relight import listed

    assert listed([chr(ord("a") + k) for k in reversed(range(count))]) == expected
