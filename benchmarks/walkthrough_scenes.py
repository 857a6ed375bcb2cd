"""Two interiors for the walkthrough benchmark (``walkthrough.py``), built with bpy as an artist
models them (``interior_scene.py``'s way: overlapping boxes, default Principled materials with
only Base Color set, packed image textures, subdivided round things), each with the ten views
of someone walking through it.

    from benchmarks import walkthrough_scenes
    walk = walkthrough_scenes.build("skylight_hall")   # empty file, the scene; a Walk

- ``skylight_hall``: an L-shaped gallery hall (a 9 x 8 x 3.2 m shell round a solid core, wings
  3.2 m and 3 m wide) under a 1.8 x 1.6 m skylight at the corner, lit by the sun and a blue sky
  through it alone, a spot on a painting (a packed image), two wall sconces; a checker-tiled
  floor, a striped rug, a bench, a pedestal with a subdivided ball, a planter with a shrub, a
  console table.
- ``studio_flat``: a closed 7 x 5 x 2.7 m flat at night (no world): an emissive ceiling panel
  over the dining table, two spots over the kitchen counter, a floor lamp beside the sofa; a
  partition wall between living room and kitchen, a planked floor, a striped wallpaper on the
  west wall, a checkered rug, black chairs, a subdivided ball and vase.

The existing interiors (``interior_scene.SCENES``) are walked too: their views are placed by
``walkthrough_views.auto_views`` among their furniture's bounding boxes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from benchmarks import interior_scene as rooms
from benchmarks.walkthrough_views import View


@dataclass
class Walk:
    """An interior to walk through: what its builder made, the air inside (boxes whose union is
    the room), what stands in it (boxes a camera keeps clear of) and the views."""

    info: rooms.Interior
    air: list
    obstacles: list = field(default_factory=list)
    views: list = field(default_factory=list)


# --------------------------------------------------------------------------- the hall

HALL = (9.0, 8.0, 3.2)  # the shell's air box; the core fills x < 6, y > 3.2
HALL_WALL, HALL_SLAB = 0.2, 0.25
HALL_AIR = [((0.0, 0.0, 0.0), (9.0, 3.2, 3.2)), ((6.0, 0.0, 0.0), (9.0, 8.0, 3.2))]
SKYLIGHT = (6.6, 8.4, 0.8, 2.4)  # x0, x1, y0, y1 of the opening in the ceiling
HALL_FURNITURE = {
    "Bench": [((1.0, 0.25, 0.42), (3.4, 0.7, 0.47)), ((1.1, 0.3, 0.0), (1.16, 0.65, 0.44)),
              ((3.24, 0.3, 0.0), (3.3, 0.65, 0.44))],
    "Pedestal": [((4.3, 1.3, 0.0), (4.8, 1.8, 1.0))],
    "Console": [((5.97, 5.0, 0.82), (6.45, 6.6, 0.86)), ((6.38, 5.03, 0.0), (6.43, 5.08, 0.84)),
                ((6.38, 6.52, 0.0), (6.43, 6.57, 0.84))],
    "Painting": [((2.0, 3.14, 1.2), (3.6, 3.24, 2.2))],
    "Rug": [((6.8, 4.4, -0.005), (8.3, 7.0, 0.015))],
}
HALL_ROUND = {"Bronze Ball": ((4.55, 1.55, 1.2), 0.2), "Shrub": ((8.4, 0.55, 0.93), 0.38)}  # centre, radius
PLANTER = ((8.4, 0.55, 0.0), 0.3, 0.55)  # base centre, radius, height
HALL_LAMPS = {"Painting Spot": (2.8, 1.6, 3.05), "Sconce North": (8.75, 7.2, 2.1), "Sconce South": (8.75, 4.8, 2.1)}
HALL_VIEWS = [
    View((0.6, 1.6, 1.6), (9.0, 1.6, 1.2), 20.0, "entrance, down the hall"),
    View((3.0, 1.3, 1.6), (2.8, 3.2, 1.7), 22.0, "the painting under its spot"),
    View((5.2, 0.35, 1.6), (0.0, 0.6, 1.0), 18.0, "along the south wall, close"),
    View((7.6, 1.4, 1.65), (6.9, 3.6, 0.0), 18.0, "under the skylight, the sun's patch"),
    View((7.4, 0.5, 1.6), (7.5, 8.0, 1.3), 20.0, "up the north wing"),
    View((8.3, 4.0, 1.6), (9.0, 5.8, 1.9), 20.0, "the sconces' hot spots"),
    View((7.5, 7.6, 1.6), (7.2, 0.0, 1.2), 18.0, "back to the skylight corner"),
    View((8.5, 6.0, 1.6), (6.0, 5.8, 0.9), 20.0, "the console on the core"),
    View((6.4, 3.7, 1.6), (6.3, 8.0, 1.1), 18.0, "along the core's face, close"),
    View((4.2, 2.8, 1.6), (0.4, 0.4, 0.6), 20.0, "back to the bench and the entrance"),
]


def colour_blocks(pixels=96):
    """(H, W, 3) sRGB pixels of a painting: coloured blocks on off-white, black bars."""
    image = np.full((pixels, int(pixels * 1.6), 3), 0.92, np.float32)
    h, w = image.shape[:2]
    image[: h // 2, : w // 3] = (0.8, 0.12, 0.1)
    image[h // 2 :, 2 * w // 3 :] = (0.1, 0.2, 0.65)
    image[h // 3 : h // 2, w // 2 :] = (0.95, 0.8, 0.1)
    image[h // 2 - 2 : h // 2 + 2] = 0.05
    image[:, w // 3 - 2 : w // 3 + 2] = 0.05
    image[:, 2 * w // 3 - 2 : 2 * w // 3 + 2] = 0.05
    return image


def pointed(name, kind, location, target, **settings):
    """A lamp at ``location`` aimed at ``target`` (its -Z towards it)."""
    from mathutils import Vector

    rotation = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()
    return rooms.lamp(name, kind, location, tuple(rotation), **settings)


def hall_shell(floor, walls, core, ceiling):
    """Floor slab, four walls and a ceiling in four pieces round the skylight, all overlapping at
    their edges, and the core: a solid block run into the west and north walls and both slabs."""
    (X, Y, H), t, s = HALL, HALL_WALL, HALL_SLAB
    x0, x1, y0, y1 = SKYLIGHT
    box = rooms.boxes_object
    full = (-s, H + s)
    return [box("Floor", [((-t, -t, -s), (X + t, Y + t, 0.0))], floor),
            box("Ceiling West", [((-t, -t, H), (x0, Y + t, H + s))], ceiling),
            box("Ceiling East", [((x1, -t, H), (X + t, Y + t, H + s))], ceiling),
            box("Ceiling South", [((x0, -t, H), (x1, y0, H + s))], ceiling),
            box("Ceiling North", [((x0, y1, H), (x1, Y + t, H + s))], ceiling),
            box("Wall South", [((-t, -t, full[0]), (X + t, 0.0, full[1]))], walls),
            box("Wall West", [((-t, -t, full[0]), (0.0, Y + t, full[1]))], walls),
            box("Wall East", [((X, -t, full[0]), (X + t, Y + t, full[1]))], walls),
            box("Wall North", [((-t, Y, full[0]), (X + t, Y + t, full[1]))], walls),
            box("Core", [((-t / 2, 3.2, -s / 2), (6.0, Y + t / 2, H + s / 2))], core)]


def skylight_hall():
    """The L-shaped hall under a skylight: sun and sky through it, a spot, two sconces."""
    p = rooms.principled
    tiles = rooms.packed_image("Hall Tiles", rooms.checker((15, 14), 24, (0.72, 0.7, 0.64), (0.36, 0.34, 0.31)))
    made = hall_shell(rooms.image_material("Hall Floor", tiles), p("Hall Paint", (0.82, 0.8, 0.76)),
                      p("Core Grey", (0.5, 0.56, 0.62)), p("Hall Ceiling", (0.86, 0.86, 0.86)))
    rooms.planar_uv(made[0], (0.0, 0.0), (9.0, 8.4))  # 0.6 m tiles
    painting = rooms.packed_image("Painting Image", colour_blocks())
    rug = rooms.packed_image("Rug Stripes", rooms.stripes(9, 16, (0.55, 0.15, 0.12), (0.85, 0.75, 0.55), height=32))
    materials = {"Bench": p("Bench Wood", (0.45, 0.3, 0.2)), "Pedestal": p("Pedestal White", (0.85, 0.85, 0.83)),
                 "Console": p("Console Walnut", (0.28, 0.17, 0.1)), "Painting": rooms.image_material("Painting", painting),
                 "Rug": rooms.image_material("Rug", rug)}
    made += [rooms.boxes_object(name, boxes, materials[name]) for name, boxes in HALL_FURNITURE.items()]
    colours = {"Bronze Ball": (0.55, 0.35, 0.15), "Shrub": (0.15, 0.35, 0.12)}
    made += [rooms.ball(name, centre, radius, p(name, colours[name])) for name, (centre, radius) in HALL_ROUND.items()]
    made.append(rooms.cylinder("Planter", *PLANTER, p("Planter Clay", (0.6, 0.3, 0.2))))
    warm = (1.0, 0.8, 0.6)
    lamps = [rooms.lamp("Sun", "SUN", (7.5, -2.0, 8.0), (math.radians(30), 0.0, math.radians(20)), energy=5.0,
                        color=(1.0, 0.93, 0.8)),
             pointed("Painting Spot", "SPOT", HALL_LAMPS["Painting Spot"], (2.8, 3.14, 1.7), energy=15.0,
                     spot_size=math.radians(40), spot_blend=0.3, shadow_soft_size=0.03),
             rooms.lamp("Sconce South", "POINT", HALL_LAMPS["Sconce South"], energy=30.0, shadow_soft_size=0.04, color=warm),
             rooms.lamp("Sconce North", "POINT", HALL_LAMPS["Sconce North"], energy=30.0, shadow_soft_size=0.04, color=warm)]
    rooms.sky("Hall Sky", (0.5, 0.65, 0.95), 1.0)
    camera = rooms.look_at("Camera", HALL_VIEWS[0].location, HALL_VIEWS[0].target, HALL_VIEWS[0].lens)
    info = rooms.Interior("skylight_hall", ((0.0, 0.0, 0.0), HALL), surfaces=[o.name for o in made],
                          lamps=[o.name for o in lamps], camera=camera.name, textured="Floor")
    return Walk(info, HALL_AIR, hall_obstacles(), list(HALL_VIEWS))


def hall_obstacles():
    """The hall's furniture, round things and lamps as boxes (the core is not air: no box)."""
    return furniture_boxes(HALL_FURNITURE, HALL_ROUND, [PLANTER], HALL_LAMPS)


# --------------------------------------------------------------------------- the flat

FLAT = (7.0, 5.0, 2.7)
FLAT_WALL, FLAT_SLAB = 0.15, 0.15
FLAT_FURNITURE = {
    "Partition": [((4.0, 3.0, -0.075), (4.12, 5.075, 2.775))],
    "Dining Table": [((4.8, 1.4, 0.72), (6.2, 2.4, 0.76)), *[((x, y, 0.0), (x + 0.05, y + 0.05, 0.74))
                                                              for x in (4.85, 6.1) for y in (1.45, 2.3)]],
    "Chairs": [((5.0, 0.9, 0.44), (5.45, 1.35, 0.48)), ((5.0, 0.86, 0.44), (5.45, 0.9, 0.95)),
               ((5.0, 0.9, 0.0), (5.04, 0.94, 0.46)), ((5.41, 0.9, 0.0), (5.45, 0.94, 0.46)),
               ((5.0, 1.31, 0.0), (5.04, 1.35, 0.46)), ((5.41, 1.31, 0.0), (5.45, 1.35, 0.46)),
               ((5.55, 2.45, 0.44), (6.0, 2.9, 0.48)), ((5.55, 2.9, 0.44), (6.0, 2.94, 0.95)),
               ((5.55, 2.45, 0.0), (5.59, 2.49, 0.46)), ((5.96, 2.45, 0.0), (6.0, 2.49, 0.46)),
               ((5.55, 2.86, 0.0), (5.59, 2.9, 0.46)), ((5.96, 2.86, 0.0), (6.0, 2.9, 0.46))],
    "Counter": [((6.35, 2.4, 0.0), (7.05, 5.05, 0.88)), ((6.3, 2.35, 0.88), (7.05, 5.05, 0.92)),
                ((6.65, 2.4, 1.5), (7.05, 5.05, 2.2))],
    "Sofa": [((-0.05, 1.0, 0.0), (0.3, 3.2, 0.85)), ((0.25, 1.05, 0.0), (1.0, 3.15, 0.42)),
             ((-0.05, 0.85, 0.0), (1.0, 1.05, 0.62)), ((-0.05, 3.15, 0.0), (1.0, 3.35, 0.62))],
    "Coffee Table": [((1.5, 1.6, 0.38), (2.3, 2.6, 0.42)), ((1.6, 1.7, 0.0), (2.2, 2.5, 0.38))],
    "Sideboard": [((1.2, 4.6, 0.0), (3.2, 5.05, 0.8))],
    "Lamp Stand": [((0.4, 0.4, 0.0), (0.7, 0.7, 0.03)), ((0.53, 0.53, 0.03), (0.57, 0.57, 1.42))],
    "Rug": [((1.2, 1.2, -0.005), (2.9, 3.0, 0.012))],
}
PANEL = [((4.9, 1.6, 2.64), (6.1, 2.2, 2.68))]  # 2 cm under the ceiling
FLAT_ROUND = {"Ball": ((3.4, 1.0, 0.2), 0.2)}
VASE = ((5.5, 1.9, 0.76), 0.08, 0.3)
FLAT_LAMPS = {"Floor Lamp": (0.55, 0.55, 1.55), "Counter Spot South": (6.45, 3.0, 2.62), "Counter Spot North": (6.45, 4.3, 2.62)}
FLAT_VIEWS = [
    View((6.5, 0.4, 1.6), (1.0, 4.5, 0.9), 18.0, "the door, across the flat"),
    View((2.6, 1.0, 1.6), (5.5, 1.9, 1.2), 22.0, "the dining table under the panel"),
    View((5.3, 3.6, 1.6), (6.8, 3.6, 0.9), 20.0, "the counter's spots"),
    View((3.0, 0.3, 1.6), (7.0, 0.6, 1.0), 18.0, "along the south wall, close"),
    View((5.5, 0.45, 1.3), (5.5, 2.0, 1.9), 18.0, "seated, up at the panel"),
    View((3.6, 4.4, 1.6), (0.5, 1.0, 0.9), 18.0, "behind the partition, to the sofa"),
    View((2.0, 0.5, 1.6), (0.0, 0.7, 1.6), 20.0, "the floor lamp on the wallpaper"),
    View((5.2, 4.6, 1.6), (5.6, 0.4, 0.6), 18.0, "the kitchen's end, to the table"),
    View((2.2, 4.15, 1.5), (2.2, 5.0, 0.7), 20.0, "down at the sideboard, close"),
    View((2.4, 3.0, 1.6), (7.0, 1.2, 1.2), 20.0, "the living room, to the kitchen"),
]


def studio_flat():
    """The closed flat at night: an emissive ceiling panel, two spots, a floor lamp."""
    import bpy

    p = rooms.principled
    planks = rooms.packed_image("Flat Planks", rooms.stripes(28, 12, (0.62, 0.45, 0.3), (0.5, 0.35, 0.22)))
    made = rooms.shell(FLAT, FLAT_WALL, FLAT_SLAB, p("Flat Paint", (0.8, 0.78, 0.74)), p("Flat Ceiling", (0.88, 0.88, 0.88)),
                       rooms.image_material("Flat Floor", planks))
    rooms.planar_uv(made[0], (0.0, 0.0), (7.0, 3.5))  # planks of 0.25 m along y
    stripes = rooms.stripes(20, 8, (0.55, 0.62, 0.52), (0.78, 0.76, 0.66))
    paper = rooms.packed_image("Wallpaper", np.ascontiguousarray(stripes.swapaxes(0, 1)))  # (upright on the wall's UV)
    made[2].data.materials[0] = rooms.image_material("Wallpaper", paper)  # the west wall
    rug = rooms.packed_image("Rug Checker", rooms.checker((6, 6), 16, (0.75, 0.7, 0.6), (0.25, 0.3, 0.4)))
    colours = {"Partition": (0.3, 0.36, 0.45), "Dining Table": (0.55, 0.4, 0.25), "Chairs": (0.06, 0.06, 0.07),
               "Counter": (0.85, 0.85, 0.82), "Sofa": (0.35, 0.35, 0.38), "Coffee Table": (0.3, 0.18, 0.1),
               "Sideboard": (0.7, 0.66, 0.6), "Lamp Stand": (0.1, 0.1, 0.1)}
    for name, boxes in FLAT_FURNITURE.items():
        material = rooms.image_material("Rug", rug) if name == "Rug" else p(name, colours[name])
        made.append(rooms.boxes_object(name, boxes, material))
    made.append(rooms.ball("Ball", *FLAT_ROUND["Ball"], p("Yellow", (0.8, 0.6, 0.1))))
    made.append(rooms.cylinder("Vase", *VASE, p("Vase Blue", (0.15, 0.3, 0.6))))
    panel = rooms.boxes_object("Ceiling Panel", PANEL, p("Panel Glow", (0.8, 0.8, 0.8), emission=(1.0, 0.95, 0.85), strength=10.0))
    spot = dict(energy=80.0, spot_size=math.radians(70), spot_blend=0.5, shadow_soft_size=0.02)
    lamps = [rooms.lamp("Floor Lamp", "POINT", FLAT_LAMPS["Floor Lamp"], energy=50.0, shadow_soft_size=0.12, color=(1.0, 0.8, 0.6)),
             rooms.lamp("Counter Spot South", "SPOT", FLAT_LAMPS["Counter Spot South"], **spot),
             rooms.lamp("Counter Spot North", "SPOT", FLAT_LAMPS["Counter Spot North"], **spot)]
    bpy.context.scene.world = None
    camera = rooms.look_at("Camera", FLAT_VIEWS[0].location, FLAT_VIEWS[0].target, FLAT_VIEWS[0].lens)
    info = rooms.Interior("studio_flat", ((0.0, 0.0, 0.0), FLAT), surfaces=[o.name for o in made], emitters=[panel.name],
                          lamps=[o.name for o in lamps], camera=camera.name, textured="Floor")
    return Walk(info, [((0.0, 0.0, 0.0), FLAT)], flat_obstacles(), list(FLAT_VIEWS))


def flat_obstacles():
    return furniture_boxes({**FLAT_FURNITURE, "Ceiling Panel": PANEL}, FLAT_ROUND, [VASE], FLAT_LAMPS)


# --------------------------------------------------------------------------- any interior

def furniture_boxes(boxes, balls, cylinders, lamps, lamp_reach=0.2):
    """(lo, hi) boxes of everything standing in a room: furniture boxes as built, balls and
    cylinders bounded, lamps as cubes of ``lamp_reach``."""
    out = [(np.asarray(lo, float), np.asarray(hi, float)) for parts in boxes.values() for lo, hi in parts]
    out += [(np.subtract(c, r), np.add(c, r)) for c, r in balls.values()]
    out += [(np.subtract(c, (r, r, 0.0)), np.add(c, (r, r, h))) for c, r, h in cylinders]
    out += [(np.subtract(c, lamp_reach), np.add(c, lamp_reach)) for c in lamps.values()]
    return out


SCENES = {"skylight_hall": skylight_hall, "studio_flat": studio_flat}
NAMES = (*SCENES, *rooms.SCENES)


def build(name, views=10):
    """An empty file with the extension registered, then the interior ``name`` (new or one of
    ``interior_scene``'s, whose views are placed here): its Walk, at most ``views`` views."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    from addon.cli.scenes import ensure_registered

    ensure_registered()
    if name in SCENES:
        walk = SCENES[name]()
    else:
        walk = existing(rooms.SCENES[name](), views)
    walk.views = walk.views[:views]
    return walk


def existing(info, count):
    """A Walk of an ``interior_scene`` room: its air box, its furniture's and lamps' bounding
    boxes read from Blender, views from ``auto_views`` looking at its lamps and walls."""
    import bpy

    from benchmarks import walkthrough_views as placing

    lo, hi = (np.asarray(c, float) for c in info.room)
    obstacles = []
    for name in info.meshes:
        box = world_box(bpy.data.objects[name])
        if not placing.spans_room(box, (lo, hi)):  # (walls, floor and ceiling span the room)
            obstacles.append(box)
    lamps = [np.array(bpy.data.objects[n].matrix_world.translation) for n in info.lamps
             if bpy.data.objects[n].data.type != "SUN"]
    obstacles += [(c - 0.2, c + 0.2) for c in lamps]
    targets = [*lamps, *placing.wall_middles((lo, hi))]
    views = placing.auto_views([(lo, hi)], obstacles, targets, count)
    return Walk(info, [(lo, hi)], obstacles, views)


def world_box(obj):
    """(lo, hi) of an object's evaluated vertices in world space."""
    import bpy

    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    try:
        co = np.empty(3 * len(mesh.vertices), np.float32)
        mesh.vertices.foreach_get("co", co)
    finally:
        evaluated.to_mesh_clear()
    m = np.array(evaluated.matrix_world, np.float64)
    points = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return points.min(axis=0), points.max(axis=0)
