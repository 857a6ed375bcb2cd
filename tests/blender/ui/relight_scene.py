"""A scene lit by every kind of source, for the relighting tests: an open box (floor and four
walls, facing in) under a sun and a sky, with a point lamp, an area lamp and an emissive panel
inside."""
import math

import bpy
import numpy as np

from benchmarks import interior_scene

from ..conftest import box_arrays, make_object, principled

SOURCES = ("Bulb", "Panel", "Sun", "World", "Glow")  # point, area, sun, world, emissive material


def lamp(kind, name, location, energy, colour=(1, 1, 1), rotation=(0, 0, 0), **settings):
    return interior_scene.lamp(name, kind, location, rotation, energy=energy, color=colour, **settings)


def build(context, output="FACE"):
    """The scene, its settings (patch size 0.25, per-light results on, 1 thread)."""
    v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    open_top = [face for face in f if not all(v[i][2] == 1 for i in face)]
    room = make_object("Room", v, open_top, [principled("White", (0.6, 0.6, 0.6))])
    glow_v = np.array([(0.02, 0.3, 0.3), (0.02, 0.7, 0.3), (0.02, 0.7, 0.6), (0.02, 0.3, 0.6)])
    glow = make_object("Strip", glow_v, [(0, 1, 2, 3)], [principled("Glow", (0.5, 0.5, 0.5), (1, 0.9, 0.8), 3.0)])
    for obj in (room, glow):
        obj.select_set(True)
    lamp("POINT", "Bulb", (0.5, 0.5, 0.5), 30.0, (1.0, 0.9, 0.8))
    lamp("AREA", "Panel", (0.5, 0.5, 0.95), 20.0, (0.8, 0.9, 1.0), size=0.3)
    lamp("SUN", "Sun", (0, 0, 3), 2.0, (1.0, 1.0, 0.9), rotation=(0.4, 0.2, 0))
    world = bpy.data.worlds.new("World")
    context.scene.world = world
    background = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    background.inputs["Color"].default_value = (0.4, 0.5, 0.7, 1.0)
    background.inputs["Strength"].default_value = 1.0
    s = context.scene.radiosity
    s.patch_size, s.threads, s.output, s.per_source = 0.25, 1, output, "ON"
    s.method, s.target_error = "walk", 5.0
    return s


def change(context):
    """Tints and strengths: the bulb off, the panel hidden, the sun warmer and brighter, the sky
    dimmer and bluer, the glow redder."""
    bpy.data.objects["Bulb"].data.energy = 0.0
    bpy.data.objects["Panel"].hide_render = True
    sun = bpy.data.objects["Sun"].data
    sun.energy, sun.color = 3.0, (1.0, 0.7, 0.4)
    background = next(n for n in context.scene.world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    background.inputs["Color"].default_value = (0.2, 0.3, 0.9, 1.0)
    background.inputs["Strength"].default_value = 0.7
    node = bpy.data.materials["Glow"].node_tree.nodes["Principled BSDF"]
    node.inputs["Emission Color"].default_value = (1.0, 0.3, 0.2, 1.0)
    node.inputs["Emission Strength"].default_value = 5.0


def patch_values(name="Radiosity"):
    """(P,3) each result polygon's first corner's colour, and (P,) its area, objects by name."""
    from addon.blender_write.results import previous_results

    values, areas = [], []
    for obj in sorted(previous_results(bpy.context.scene), key=lambda o: o.name):
        mesh = obj.data
        attribute = mesh.attributes[name]
        data = np.empty(len(attribute.data) * 4, np.float32)
        attribute.data.foreach_get("color", data)
        data = data.reshape(-1, 4)[:, :3]
        if attribute.domain == "CORNER":
            starts = np.empty(len(mesh.polygons), np.int32)
            mesh.polygons.foreach_get("loop_start", starts)
            data = data[starts]
        area = np.empty(len(mesh.polygons), np.float32)
        mesh.polygons.foreach_get("area", area)
        values.append(data)
        areas.append(area)
    return np.concatenate(values).astype(np.float64), np.concatenate(areas).astype(np.float64)


# The joint-noise statistic of the relighting tests (test_relight.py's docstring): |z| < Z passes.
Z = 5.0
CORRELATION_ALLOWANCE = 2.0


def joint_noise_z(a, b, mse_a, mse_b, variance_b, area):
    weight = area / area.sum()
    T = float((weight[:, None] * (a - b) ** 2).sum() / 3) / (mse_a + mse_b)
    terms = (weight[:, None] * 2 * variance_b).ravel()
    n_eff = terms.sum() ** 2 / (terms**2).sum()
    return (T - 1.0) / (math.sqrt(2.0 / n_eff) * CORRELATION_ALLOWANCE)


def solve(monkeypatch, seed):
    """Solves through the operator and returns the run's output (its variances)."""
    from tests.blender.conftest import solve_outputs

    kept = solve_outputs(monkeypatch)
    bpy.context.scene.radiosity.seed = seed
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    return kept[-1]


def spy_solves(monkeypatch):
    """The group names of every core solve from here on."""
    from addon.core import solver
    from addon.core.relight import resolve

    calls = []
    original = solver.solve

    def spy(scene, settings=None, **kwargs):
        groups = solver.Settings.of(settings).groups
        calls.append(tuple(groups.names) if groups is not None else None)
        return original(scene, settings, **kwargs)

    monkeypatch.setattr(resolve, "solve", spy)
    monkeypatch.setattr("addon.bpy_free.pipeline.solve", spy)
    return calls
