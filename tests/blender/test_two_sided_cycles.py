"""Emitting faces emit from both sides in Cycles (its emission closure's |cos|, whatever the
material's Emission Sampling, which only chooses which sides light sampling aims at) and in the
solve: an emitting panel facing away from a floor lights it from its back, as Cycles bakes it."""
import sys
from pathlib import Path

import bpy
import numpy as np

from addon.core import solve
from addon.core.estimate.reference import rectangle_form_factors, solve_radiosity_system

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "core"))
from test_two_sided import E_PANEL, N, R_FLOOR, R_WALL, panel_scene  # noqa: E402

BLOCK, COLUMNS = 16, 8  # pixels a side of each patch's block, blocks a row
SAMPLES = 32


def _material(name, albedo=None, emission=None, image=None):
    m = bpy.data.materials.new(name)
    tree = m.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    if emission is not None:
        shader = tree.nodes.new("ShaderNodeEmission")
        shader.inputs["Strength"].default_value = emission
    else:
        shader = tree.nodes.new("ShaderNodeBsdfDiffuse")
        shader.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
    tree.links.new(shader.outputs[0], out.inputs["Surface"])
    if image is not None:  # (the bake target: the active image node)
        texture = tree.nodes.new("ShaderNodeTexImage")
        texture.image = image
        tree.nodes.active = texture
    return m


def _cycles_bakes(seeds):
    """The receivers' patch means of Cycles' COMBINED bake (B = R H), one (2 n^2,) row a seed,
    and each row's pixels (for the noise)."""
    from benchmarks.cycles_comparison import block_mesh, configure_bake, quads, selected_object

    _, origin, u, v, _, _ = panel_scene()
    receivers = 2 * N * N
    mesh, image, rows = block_mesh("Receivers", quads(origin[:receivers], u[:receivers], v[:receivers]), BLOCK, COLUMNS)
    mesh.materials.append(_material("Floor", albedo=R_FLOOR, image=image))
    mesh.materials.append(_material("Wall", albedo=R_WALL, image=image))
    mesh.polygons.foreach_set("material_index", np.repeat([0, 1], N * N).astype(np.int32))
    mesh.update()
    panel = bpy.data.meshes.new("Panel")
    panel.from_pydata(quads(origin[-1:], u[-1:], v[-1:]).reshape(-1, 3).tolist(), [], [[0, 1, 2, 3]])
    panel.materials.append(_material("Glow", emission=E_PANEL))
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Panel", panel))
    selected_object(mesh)
    scene = bpy.context.scene
    configure_bake(scene, threads=2)
    scene.cycles.samples = SAMPLES
    pixels = []
    for seed in seeds:
        scene.cycles.seed = seed
        assert bpy.ops.object.bake(type="COMBINED") == {"FINISHED"}
        values = np.empty(image.size[0] * image.size[1] * 4, np.float32)
        image.pixels.foreach_get(values)
        grey = values.reshape(image.size[1], image.size[0], 4)[..., 0].astype(np.float64)
        blocks = grey.reshape(rows, BLOCK, COLUMNS, BLOCK).transpose(0, 2, 1, 3).reshape(rows * COLUMNS, BLOCK * BLOCK)
        pixels.append(blocks[:receivers])
    return np.stack(pixels)  # (seeds, patches, pixels)


def test_an_emitting_panel_lights_the_floor_behind_it_as_cycles_bakes_it(blender):
    """The panel faces up, away from the floor; the floor and the wall's lower half see only its
    back. Our continuous walk (hit exit, direct light gathered) against Cycles' bake, patch by
    patch (its block's mean): z within 5 on all 32 patches, from the bake's noise (two seeds'
    pixel differences) and ours (batch means), their mean square about 1; the front alone
    leaves the floor far darker in the discrete system."""
    pixels = _cycles_bakes((1, 2))
    cycles = pixels.mean(axis=(0, 2))
    noise = (pixels[0] - pixels[1]).var(axis=1, ddof=1) / 2  # (a pixel's variance, one bake)
    cycles_var = noise / pixels[0].shape[1] / 2
    scene = panel_scene()[0]
    r = solve(scene, paths=400_000, seed=3, method="walk", direct_light="gathered", exit_point="hit", threads=2)
    rows = np.arange(2 * N * N)
    ours, ours_var = r.radiosity[rows, 0], r.reflected_variance[rows, 0]
    z = (ours - cycles) / np.sqrt(cycles_var + ours_var)
    assert np.abs(z).max() < 5.0, (np.abs(z).max(), ours / cycles)
    assert 0.3 < np.mean(z**2) < 2.5, np.mean(z**2)  # (the noise bands are of the right size)
    floor = np.arange(N * N)
    _, origin, u, v, R, E = panel_scene()
    front_only = solve_radiosity_system(rectangle_form_factors(origin, u, v), R, E)[floor, 0]
    assert cycles[floor].sum() > 3 * front_only.sum()  # (what a one-sided panel gives the floor: the wall's light)
