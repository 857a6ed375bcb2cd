"""Three interiors built with bpy as an artist models them, for the picture benchmark (``picture.py``).

    import bpy
    from benchmarks import interior_scene
    info = interior_scene.build("window_room")     # empty file, the scene, its camera; an Interior

Modelled the way rooms are modelled, not the way the solver would like them: walls, floor and
ceiling are boxes that overlap one another at every corner and edge (buried faces included),
a window wall is four pieces (left, right, sill, lintel) overlapping at their joints, furniture
is boxes run into each other inside one object, a ball is an ico-sphere under a Subdivision
modifier, every box has a UV map, and every material is a default Principled BSDF with only its
Base Color set (Emission too, for an emitter). Metres, Z up.

- ``window_room``: a 5 x 4 x 2.7 m room, a 2 x 1.3 m window opening in the south wall (y = 0)
  with a sun shining through it and a uniform sky (world Background colour), a point lamp
  0.25 m below the ceiling, a square area lamp on the east wall, a floor with a packed checker
  image (0.5 m squares, UV-mapped), a table, a sofa, a subdivided ball; camera in the north-east
  corner looking at the window.
- ``lamp_room``: a closed 4 x 6 x 2.5 m room (no window, no sky), a spot lamp on the ceiling
  aimed at the bed, an emissive strip under the ceiling along the east wall, a green west wall,
  a floor of packed plank stripes, a bed with a headboard, a wardrobe, a desk, a subdivided stool;
  camera at the south end looking in.
- ``loft``: a 6 x 5 x 3 m room added after the product's picture work was done on the other two
  (nothing tuned on it): a tall window in the south wall with a low afternoon sun from the south-west
  and a warm dim sky, a spot over a dark kitchen counter along the east wall, a soft point lamp
  beside an armchair, an emissive cube pendant hanging over a coffee table, a terracotta north
  wall, a bookshelf of boards run into its frame, a floor of packed grey planks, a subdivided pouf;
  camera in the south-east corner looking north-west.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

RESOLUTION = (320, 240)


@dataclass
class Interior:
    """What a builder made: object names by role, the room's inside box, the camera's name."""

    name: str
    room: tuple  # (lo (3,), hi (3,)) of the air inside the room
    surfaces: list = field(default_factory=list)  # mesh objects that reflect
    emitters: list = field(default_factory=list)  # mesh objects whose material emits
    lamps: list = field(default_factory=list)  # light objects
    camera: str = ""
    textured: str = ""  # the object whose Base Color comes from a packed image

    @property
    def meshes(self):
        return self.surfaces + self.emitters


def principled(name, base, emission=None, strength=0.0):
    """A Principled BSDF left at its defaults but for Base Color (and Emission for an emitter)."""
    import bpy

    m = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    node = m.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (*base, 1.0)
    if emission is not None:
        node.inputs["Emission Color"].default_value = (*emission, 1.0)
        node.inputs["Emission Strength"].default_value = strength
    m.diffuse_color = (*base, 1.0)
    return m


def image_material(name, image):
    """A default Principled BSDF whose Base Color is ``image`` on the object's UV map."""
    m = principled(name, (0.8, 0.8, 0.8))
    tree = m.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    texture.location = (-400, 200)
    tree.links.new(texture.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    return m


def packed_image(name, srgb):
    """A byte image of ``srgb`` (H, W, 3) pixels, row 0 at the bottom, packed into the .blend."""
    import bpy

    height, width = srgb.shape[:2]
    image = bpy.data.images.new(name, width, height, alpha=False)
    rgba = np.ones((height, width, 4), np.float32)
    rgba[..., :3] = srgb
    image.pixels.foreach_set(rgba.ravel())
    image.update()
    image.pack()
    return image


def checker(squares, pixels_each, a, b):
    """(H, W, 3) sRGB pixels of a checker of ``squares`` (columns, rows), colours a and b."""
    columns, rows = squares
    i = np.arange(rows * pixels_each)[:, None] // pixels_each
    j = np.arange(columns * pixels_each)[None, :] // pixels_each
    return np.where(((i + j) % 2 == 0)[..., None], np.asarray(a, np.float32), np.asarray(b, np.float32))


def stripes(count, pixels_each, a, b, height=8):
    """(H, W, 3) sRGB pixels of ``count`` vertical stripes alternating a and b (planks)."""
    j = np.arange(count * pixels_each)[None, :] // pixels_each
    row = np.where((j % 2 == 0)[..., None], np.asarray(a, np.float32), np.asarray(b, np.float32))
    return np.repeat(row, height, axis=0)


def boxes_object(name, boxes, material, collection=None):
    """One mesh object of axis-aligned boxes ((lo, hi) corners in world space, left overlapping as
    given), with a UV map ('UVMap', each face its own unit square as Blender's cube has)."""
    import bmesh
    import bpy
    from mathutils import Matrix

    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    for lo, hi in boxes:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        matrix = Matrix.Translation(tuple((lo + hi) / 2)) @ Matrix.Diagonal((*(hi - lo), 1.0))
        bmesh.ops.create_cube(bm, size=1.0, matrix=matrix, calc_uvs=True)
    return _link(name, bm, material, collection)


def _link(name, bm, material, collection, smooth=False):
    import bpy

    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(material)
    if smooth:
        mesh.polygons.foreach_set("use_smooth", np.ones(len(mesh.polygons), bool))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def planar_uv(obj, origin, size):
    """Set the object's UV map to its world x, y over ``size`` (metres per unit of UV) from
    ``origin``: a floor's texture laid flat, as an artist's top-view unwrap does."""
    mesh = obj.data
    co = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) @ np.array(obj.matrix_world)[:3, :3].T + np.array(obj.matrix_world)[:3, 3]
    corner = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corner)
    uv = (co[corner, :2] - np.asarray(origin, float)) / np.asarray(size, float)
    mesh.uv_layers["UVMap"].data.foreach_set("uv", uv.astype(np.float32).ravel())


def ball(name, centre, radius, material, subdivisions=2, levels=2, collection=None):
    """An ico-sphere with a Subdivision Surface modifier, shaded smooth."""
    import bmesh
    from mathutils import Matrix

    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_icosphere(bm, subdivisions=subdivisions, radius=radius, matrix=Matrix.Translation(centre), calc_uvs=True)
    obj = _link(name, bm, material, collection, smooth=True)
    modifier = obj.modifiers.new("Subdivision", "SUBSURF")
    modifier.levels = modifier.render_levels = levels
    return obj


def cylinder(name, centre, radius, height, material, segments=16, levels=2, collection=None):
    """A closed cylinder standing on ``centre`` (its base), with a Subdivision Surface modifier."""
    import bmesh
    from mathutils import Matrix

    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    matrix = Matrix.Translation((centre[0], centre[1], centre[2] + height / 2))
    bmesh.ops.create_cone(bm, cap_ends=True, segments=segments, radius1=radius, radius2=radius, depth=height,
                          matrix=matrix, calc_uvs=True)
    obj = _link(name, bm, material, collection, smooth=True)
    modifier = obj.modifiers.new("Subdivision", "SUBSURF")
    modifier.levels = modifier.render_levels = levels
    return obj


def lamp(name, kind, location, rotation=(0.0, 0.0, 0.0), **settings):
    import bpy

    data = bpy.data.lights.new(name, kind)
    for key, value in settings.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(name, data)
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


def sky(name, colour, strength):
    """The scene's world: a uniform Background of ``colour`` (RGB) at ``strength``."""
    import bpy

    world = bpy.data.worlds.new(name)
    background = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    background.inputs["Color"].default_value = (*colour, 1.0)
    background.inputs["Strength"].default_value = strength
    bpy.context.scene.world = world
    return world


def look_at(name, location, target, lens):
    """A camera at ``location`` looking at ``target`` (up +Z), the scene's camera, 320 x 240."""
    import bpy
    from mathutils import Vector

    data = bpy.data.cameras.new(name)
    data.lens = lens
    camera = bpy.data.objects.new(name, data)
    camera.location = location
    camera.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()
    scene = bpy.context.scene
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = RESOLUTION
    scene.render.resolution_percentage = 100
    return camera


def shell(size, wall, slab, paint, ceiling_paint, floor_material, window=None):
    """Floor and ceiling slabs and walls around the air box [0, size], all overlapping at their
    edges (the walls run into the slabs and past each other at the corners). ``window`` (x0, x1,
    z0, z1) cuts an opening into the south wall (y = 0), built as four pieces: left and right
    full height, sill and lintel between them. No two faces that face the same way overlap in
    one plane: Cycles then shades one of them in the other's shadow (black stripes)."""
    X, Y, Z = size
    t, s = wall, slab
    made = [boxes_object("Floor", [((-t, -t, -s), (X + t, Y + t, 0.0))], floor_material),
            boxes_object("Ceiling", [((-t, -t, Z), (X + t, Y + t, Z + s))], ceiling_paint)]
    full = (-s, Z + s)
    made += [boxes_object("Wall West", [((-t, -t, full[0]), (0.0, Y + t, full[1]))], paint),
             boxes_object("Wall East", [((X, -t, full[0]), (X + t, Y + t, full[1]))], paint),
             boxes_object("Wall North", [((-t, Y, full[0]), (X + t, Y + t, full[1]))], paint)]
    if window is None:
        made.append(boxes_object("Wall South", [((-t, -t, full[0]), (X + t, 0.0, full[1]))], paint))
        return made
    x0, x1, z0, z1 = window
    made += [boxes_object("Wall South Left", [((-t, -t, full[0]), (x0, 0.0, full[1]))], paint),
             boxes_object("Wall South Right", [((x1, -t, full[0]), (X + t, 0.0, full[1]))], paint),
             boxes_object("Wall South Sill", [((x0, -t, full[0]), (x1, 0.0, z0))], paint),
             boxes_object("Lintel", [((x0, -t, z1), (x1, 0.0, full[1]))], paint)]
    return made


def window_room():
    """The 5 x 4 x 2.7 m room with a window, sun and sky, a point and an area lamp."""
    size = (5.0, 4.0, 2.7)
    floor_image = packed_image("Floor Checker", checker((10, 8), 32, (0.75, 0.6, 0.45), (0.3, 0.2, 0.15)))
    walls = principled("Wall Paint", (0.8, 0.8, 0.78))
    made = shell(size, 0.15, 0.1, walls, principled("Ceiling Paint", (0.85, 0.85, 0.85)),
                 image_material("Floor", floor_image), window=(1.5, 3.5, 0.9, 2.2))
    planar_uv(made[0], (0.0, 0.0), size[:2])  # 10 x 8 squares of 0.5 m over the floor
    top, legs = 0.76, []
    for x in (1.85, 3.1):
        for y in (1.65, 2.3):
            legs.append(((x, y, 0.0), (x + 0.05, y + 0.05, top - 0.02)))
    made.append(boxes_object("Table", [((1.8, 1.6, top - 0.04), (3.2, 2.4, top)), *legs], principled("Wood", (0.45, 0.3, 0.2))))
    made.append(boxes_object("Sofa", [((0.5, 3.7, 0.0), (2.5, 3.9, 0.85)), ((0.7, 3.1, 0.0), (2.3, 3.75, 0.42)),
                                      ((0.505, 3.1, 0.0), (0.7, 3.8, 0.6)), ((2.3, 3.1, 0.0), (2.495, 3.8, 0.6))],
                             principled("Sofa Fabric", (0.2, 0.3, 0.5))))
    made.append(ball("Ball", (3.8, 2.8, 0.25), 0.25, principled("Red", (0.7, 0.1, 0.1))))
    lamps = [lamp("Sun", "SUN", (2.5, -3.0, 4.0), (math.radians(55), 0.0, math.radians(20)), energy=10.0),
             lamp("Ceiling Lamp", "POINT", (3.8, 1.2, size[2] - 0.25), energy=60.0, shadow_soft_size=0.05,
                  color=(1.0, 0.85, 0.7)),
             lamp("Wall Panel", "AREA", (4.85, 2.6, 1.6), (0.0, math.radians(90), 0.0), energy=40.0, size=0.6)]
    sky("Sky", (0.45, 0.6, 0.9), 0.6)
    camera = look_at("Camera", (4.7, 3.75, 1.7), (1.0, 0.8, 0.8), 18.0)
    return Interior("window_room", ((0, 0, 0), size), surfaces=[o.name for o in made], lamps=[o.name for o in lamps],
                    camera=camera.name, textured="Floor")


def lamp_room():
    """The closed 4 x 6 x 2.5 m room lit by a spot lamp and an emissive strip."""
    import bpy

    size = (4.0, 6.0, 2.5)
    planks = packed_image("Floor Planks", stripes(20, 16, (0.55, 0.38, 0.22), (0.42, 0.27, 0.15)))
    made = shell(size, 0.2, 0.15, principled("Wall Paint", (0.75, 0.72, 0.68)), principled("Ceiling Paint", (0.85, 0.85, 0.85)),
                 image_material("Floor", planks))
    planar_uv(made[0], (0.0, 0.0), (4.0, 4.0))  # planks of 0.2 m along y
    made[2].data.materials[0] = principled("Green Paint", (0.3, 0.5, 0.35))  # the west wall
    made.append(boxes_object("Bed", [((0.2, 3.8, 0.0), (1.8, 5.9, 0.5)), ((0.15, 5.8, 0.0), (1.85, 5.95, 1.0))],
                             principled("Linen", (0.7, 0.68, 0.6))))
    made.append(boxes_object("Wardrobe", [((3.3, 0.3, 0.0), (3.95, 1.7, 2.1))], principled("Oak", (0.5, 0.35, 0.2))))
    made.append(boxes_object("Desk", [((2.6, 3.0, 0.72), (3.95, 3.7, 0.76)), ((2.65, 3.02, 0.0), (2.7, 3.68, 0.74)),
                                      ((3.85, 3.02, 0.0), (3.9, 3.68, 0.74))], principled("White Desk", (0.8, 0.8, 0.8))))
    made.append(cylinder("Stool", (2.2, 3.3, 0.0), 0.18, 0.45, principled("Blue", (0.1, 0.2, 0.6))))
    strip = boxes_object("Light Strip", [((3.9, 1.5, 2.38), (3.96, 4.5, 2.42))],
                         principled("Strip", (0.8, 0.8, 0.8), emission=(1.0, 0.8, 0.6), strength=12.0))
    lamps = [lamp("Spot", "SPOT", (1.0, 3.0, 2.4), (math.radians(43), 0.0, 0.0), energy=300.0,
                  spot_size=math.radians(55), spot_blend=0.3, shadow_soft_size=0.05)]
    bpy.context.scene.world = None
    camera = look_at("Camera", (2.1, 0.3, 1.6), (1.9, 4.5, 0.8), 18.0)
    return Interior("lamp_room", ((0, 0, 0), size), surfaces=[o.name for o in made], emitters=[strip.name],
                    lamps=[o.name for o in lamps], camera=camera.name, textured="Floor")


def loft():
    """The 6 x 5 x 3 m loft: a tall south window with a low sun and a warm sky, a spot over the
    counter, a soft point lamp, an emissive pendant cube."""
    size = (6.0, 5.0, 3.0)
    planks = packed_image("Floor Boards", stripes(24, 12, (0.5, 0.5, 0.48), (0.36, 0.35, 0.33)))
    made = shell(size, 0.2, 0.2, principled("Warm White", (0.82, 0.8, 0.74)), principled("Ceiling White", (0.88, 0.88, 0.88)),
                 image_material("Floor", planks), window=(0.8, 2.6, 0.4, 2.6))
    planar_uv(made[0], (0.0, 0.0), (6.0, 3.0))  # boards of 0.25 m along y
    made[4].data.materials[0] = principled("Terracotta", (0.62, 0.3, 0.2))  # the north wall
    made.append(boxes_object("Counter", [((5.35, 0.8, 0.0), (6.0, 3.4, 0.9)), ((5.3, 0.75, 0.9), (6.0, 3.45, 0.94))],
                             principled("Charcoal", (0.12, 0.12, 0.13))))
    shelves = [((0.6 + 0.02, 4.62, z), (2.6 - 0.02, 4.98, z + 0.03)) for z in (0.4, 0.8, 1.2, 1.6)]
    made.append(boxes_object("Bookshelf", [((0.6, 4.6, 0.0), (0.64, 5.0, 2.0)), ((2.56, 4.6, 0.0), (2.6, 5.0, 2.0)),
                                           ((0.6, 4.6, 1.96), (2.6, 5.0, 2.0)), ((0.6, 4.6, 0.0), (2.6, 5.0, 0.06)), *shelves],
                             principled("Shelf White", (0.72, 0.72, 0.7))))
    made.append(boxes_object("Coffee Table", [((2.4, 2.0, 0.36), (3.6, 2.7, 0.42)), ((2.45, 2.05, 0.0), (3.55, 2.65, 0.08))],
                             principled("Walnut", (0.3, 0.18, 0.1))))
    made.append(boxes_object("Armchair", [((0.6, 2.0, 0.0), (1.5, 2.9, 0.45)), ((0.5, 2.0, 0.0), (0.72, 2.9, 0.95)),
                                          ((0.6, 1.85, 0.0), (1.5, 2.05, 0.65)), ((0.6, 2.85, 0.0), (1.5, 3.05, 0.65))],
                             principled("Mustard", (0.7, 0.52, 0.1))))
    made.append(cylinder("Pouf", (4.0, 3.4, 0.0), 0.3, 0.4, principled("Teal", (0.1, 0.4, 0.42))))
    pendant = boxes_object("Pendant", [((2.85, 2.2, 2.05), (3.15, 2.5, 2.35))],
                           principled("Pendant Glow", (0.8, 0.8, 0.8), emission=(1.0, 0.9, 0.75), strength=8.0))
    lamps = [lamp("Sun", "SUN", (-2.0, -4.0, 3.0), (math.radians(65), 0.0, math.radians(-35)), energy=6.0,
                  color=(1.0, 0.88, 0.72)),
             lamp("Counter Spot", "SPOT", (5.4, 2.1, 2.9), energy=200.0, spot_size=math.radians(70), spot_blend=0.4,
                  shadow_soft_size=0.03),
             lamp("Reading Lamp", "POINT", (0.45, 3.25, 1.5), energy=40.0, shadow_soft_size=0.15, color=(1.0, 0.8, 0.6))]
    sky("Evening Sky", (0.9, 0.7, 0.55), 0.3)
    camera = look_at("Camera", (5.6, 0.4, 1.7), (1.5, 4.0, 0.9), 16.0)
    return Interior("loft", ((0, 0, 0), size), surfaces=[o.name for o in made], emitters=[pendant.name],
                    lamps=[o.name for o in lamps], camera=camera.name, textured="Floor")


def make_diffuse():
    """Every material's Specular IOR Level set to 0: Principled without its dielectric layer,
    a Lambertian surface (the control that shows what the specular layer accounts for)."""
    import bpy

    for material in bpy.data.materials:
        node = material.node_tree.nodes.get("Principled BSDF") if material.node_tree else None
        if node is not None:
            node.inputs["Specular IOR Level"].default_value = 0.0


SCENES = {"window_room": window_room, "lamp_room": lamp_room, "loft": loft}


def build(name):
    """An empty file with the extension registered, then the interior ``name``: its Interior."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    from addon.cli.scenes import ensure_registered

    ensure_registered()
    return SCENES[name]()
