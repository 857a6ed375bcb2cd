"""Per-object brightness of the preview against Cycles, taken apart (the picture benchmark's
window room, ``interior_scene.py``): Cycles' render passes split what the camera sees into the
diffuse part (Diffuse Color x (Direct + Indirect)) and the specular part (Glossy Color x
(Direct + Indirect)), and its light arriving (Diffuse Direct + Indirect, the product's H); the
product's preview is rendered again with its result materials cut down to base x scale x light
(no specular term), to the light alone, and to the smooth and flat radiosity.

    nice -n 10 .venv/bin/python benchmarks/brightness.py --samples 256 --tag b0         # the table below
    ... --only Sun | sky | "Ceiling Lamp" | "Wall Panel"   # one source at a time (the others removed)
    ... --diffuse                                            # Specular IOR Level 0 everywhere (Lambertian)
    ... --camera 0.4,0.4,1.6,4.5,3.5,0.8                     # another view (x, y, z, target x, y, z)
    ... --seeds 0,1,2,3 --cycles-from b0                     # the product alone over seeds, against a saved run's Cycles light
    ... --set patch_size=0.13 --target 2                 # a panel setting changed (option=value, comma-separated)
    .venv/bin/python -m benchmarks.brightness_display b0     # the display alternatives on a saved run

Per object (surface pixels of the picture benchmark's mask): cyc/ref, Cycles' combined over the
cached 256-sample reference where the scene is the benchmark's; prod/cyc, the preview over Cycles;
light p/c, the product's light arriving over Cycles'; diff p/c, base x scale x light over Cycles'
diffuse part; gloss, Cycles' specular part and the product's offset x light; Bflat/Bsmooth, the
flat radiosity's pixel mean over the smooth one's (what the smoothing moves as the camera sees it).
Saved to out/brightness/passes_<tag>.npz and .json. The product's solve runs under the reference's
light paths (Filter Glossy 0, ``--blur``); Cycles on ``--threads`` threads.
"""
import json, os, sys, tempfile, time
from pathlib import Path
import numpy as np
ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "brightness"
sys.path.insert(0, str(ROOT))
from benchmarks import interior_scene, picture as pic, picture_metrics as pm, exr_layers

import argparse
ap = argparse.ArgumentParser()
ap.add_argument("--scene", default="window_room")
ap.add_argument("--samples", type=int, default=64)
ap.add_argument("--blur", type=float, default=0.0)
ap.add_argument("--threads", type=int, default=1)
ap.add_argument("--camera", default="")  # "x,y,z,tx,ty,tz"
ap.add_argument("--diffuse", action="store_true")
ap.add_argument("--tag", default="a")
ap.add_argument("--seeds", default="")  # product only: seeds, compared with the Cycles light of --cycles-from
ap.add_argument("--cycles-from", default="")
ap.add_argument("--target", type=float, default=2.0)
ap.add_argument("--set", default="")  # panel settings option=value, comma-separated
ap.add_argument("--off", default="")  # comma list of lamp names / 'sky'
ap.add_argument("--only", default="")  # keep only this source (lamp name or 'sky')
args = ap.parse_args()

import bpy
info = interior_scene.build(args.scene)
if args.diffuse:
    interior_scene.make_diffuse()
scene = bpy.context.scene
off = [x for x in args.off.split(",") if x]
if args.only:
    off = [n for n in info.lamps + ["sky"] if n != args.only]
for name in off:
    if name == "sky":
        scene.world = None
    else:
        bpy.data.objects.remove(bpy.data.objects[name]); info.lamps.remove(name)
if args.camera:
    v = [float(x) for x in args.camera.split(",")]
    bpy.data.objects.remove(bpy.data.objects[info.camera])
    info.camera = interior_scene.look_at("Camera", v[:3], v[3:], 18.0).name
cache = pic.CACHE / f"{args.scene}_{pic.scene_fingerprint()}_256.npz"
ref = None
if cache.exists():
    d = np.load(cache); ref = 0.5 * (d["first"] + d["second"])
scene.cycles.blur_glossy = args.blur

PASSES = ("diffuse_direct", "diffuse_indirect", "diffuse_color", "glossy_direct", "glossy_indirect", "glossy_color", "emit", "environment")

def cycles_passes(samples):
    pic.configure_cycles(scene, samples, seed=5)
    scene.cycles.blur_glossy = args.blur
    scene.render.threads = args.threads
    pic.show_results(False)
    layer = scene.view_layers[0]
    for p in PASSES:
        setattr(layer, "use_pass_" + p, True)
    im = scene.render.image_settings
    im.media_type = "MULTI_LAYER_IMAGE" if hasattr(im, "media_type") else None
    im.file_format = "OPEN_EXR_MULTILAYER"
    im.color_depth = "32"
    im.exr_codec = "NONE"
    folder = tempfile.mkdtemp()
    path = os.path.join(folder, "r.exr")
    scene.render.filepath = path
    t = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    print("cycles passes", time.perf_counter() - t, "s", flush=True)
    ch = exr_layers.read_channels(path)
    os.remove(path)
    for p in PASSES:
        setattr(layer, "use_pass_" + p, False)
    im.media_type = "IMAGE"
    return ch

def rgb(ch, name):
    keys = [k for k in ch if k.split(".")[-2:-1] == [name]]
    return np.stack([ch[[k for k in keys if k.endswith("." + c)][0]] for c in "RGB"], -1)

pic.TARGET_ERROR = args.target
from addon.bpy_free import options as _opts
for kv in [x for x in args.set.split(",") if x]:
    k, v = kv.split("=")
    o = next(o for o in _opts.SETTINGS if o.name == k)
    object.__setattr__(o, "default", type(o.default)(v))
if args.seeds:
    if args.blur:
        pic.light_paths = lambda scene, unbiased=True: setattr(scene.cycles, "blur_glossy", args.blur)
    from addon.blender_write.results import previous_results
    ref_rows = json.loads((OUT / f"passes_{args.cycles_from}.json").read_text())["rows"]
    px = None
    for seed in [int(x) for x in args.seeds.split(",")]:
        image, solve, shown, stats = pic.product("TEXTURED", seed=seed)
        mats = [m for m in bpy.data.materials if "radiosity_textured_from" in m.keys() and m.users]
        for m in mats:
            n = [n for n in m.node_tree.nodes if n.label == "Reflectivity"][0]
            for l in list(n.inputs[0].links): m.node_tree.links.remove(l)
            n.inputs[0].default_value = (1, 1, 1); n.inputs[1].default_value = (1, 1, 1); n.inputs[2].default_value = (0, 0, 0)
        from addon.cli import preview
        sources = [o for o in bpy.data.objects if o.type == "MESH" and o not in previous_results()]
        changes = preview.preview_settings(scene, sources, 320, 16, 0.0)
        for o in sources: o.hide_render = True
        pic.show_results(True)
        img, _ = pic.render_exr(scene)
        for o in sources: o.hide_render = False
        changes.restore()
        if px is None:
            px = pic.pixel_map(info, previous_results())
            mask = pm.surface_mask(px["object_id"], [info.meshes.index(n) for n in info.emitters], px["lamp"])
        means = pm.object_means(img, px["object_id"], mask, len(info.meshes))
        print(f"seed {seed} error {stats['error']:.2f}% " + " ".join(
            f"{nm[:9]}:{(means[i] @ pm.LUMINANCE) / (np.array(ref_rows[nm]['cyc_light']) @ pm.LUMINANCE):.3f}"
            for i, nm in enumerate(info.meshes) if nm in ref_rows), flush=True)
    sys.exit(0)
# the product
image, solve, shown, stats = pic.product("TEXTURED", seed=0)
print("product", solve, shown, stats, flush=True)
from addon.blender_write.results import previous_results
from addon.cli import preview

def preview_image():
    sources = [o for o in bpy.data.objects if o.type == "MESH" and o not in previous_results()]
    changes = preview.preview_settings(scene, sources, 320, 16, 0.0)
    hidden = [(o, o.hide_render) for o in sources]
    try:
        for o, _ in hidden: o.hide_render = True
        pic.show_results(True)
        scene.render.threads_mode, scene.render.threads = "FIXED", 2
        img, _ = pic.render_exr(scene)
    finally:
        for o, h in hidden: o.hide_render = h
        changes.restore()
    return img

mats = [m for m in bpy.data.materials if "radiosity_textured_from" in m.keys()]
refl = {m.name: m.node_tree.nodes[[n.name for n in m.node_tree.nodes if n.label == "Reflectivity"][0]] for m in mats}
saved = {k: (tuple(n.inputs[1].default_value), tuple(n.inputs[2].default_value)) for k, n in refl.items()}
terms = {k: v for k, v in saved.items()}
full = preview_image()
for n in refl.values(): n.inputs[2].default_value = (0, 0, 0)
base_part = preview_image()
# light only: reflectivity 1
links = {}
for k, n in refl.items():
    for l in list(n.inputs[0].links): n.id_data.links.remove(l)
    n.inputs[0].default_value = (1, 1, 1); n.inputs[1].default_value = (1, 1, 1); n.inputs[2].default_value = (0, 0, 0)
light = preview_image()
lights = {}
for attr in ("Radiosity", "Radiosity Patches", "Radiosity Indirect"):
    for m in mats:
        for n in m.node_tree.nodes:
            if n.bl_idname == "ShaderNodeAttribute" and n.attribute_name in ("Radiosity Light", "Radiosity", "Radiosity Patches", "Radiosity Indirect"):
                n.attribute_name = attr
    lights[attr] = preview_image()

ch = cycles_passes(args.samples)
px = pic.pixel_map(info, previous_results())
bpy.context.view_layer.update()
origins, directions = pic.camera_rays(bpy.data.objects[info.camera], *interior_scene.RESOLUTION)
corners, _, _ = pic.mesh_triangles([bpy.data.objects[name] for name in info.meshes])
hit, _ = pic.first_hits(corners, origins, directions)
normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[np.maximum(hit, 0)]
normals /= np.linalg.norm(normals, axis=1, keepdims=True)
view_cosine = np.where(hit >= 0, np.abs(np.einsum("ij,ij->i", normals, directions)), 1.0).reshape(px["object_id"].shape)
mask = pm.surface_mask(px["object_id"], [info.meshes.index(n) for n in info.emitters], px["lamp"])
count = len(info.meshes)
C = {"combined": rgb(ch, "Combined")}
for short, name in (("dd", "Diffuse Direct"), ("di", "Diffuse Indirect"), ("dc", "Diffuse Color"), ("gd", "Glossy Direct"), ("gi", "Glossy Indirect"), ("gc", "Glossy Color"), ("emit", "Emission"), ("env", "Environment")):
    try: C[short] = rgb(ch, name)
    except IndexError: print("no pass", name, [k for k in ch][:40])
cyc_diff = C["dc"] * (C["dd"] + C["di"])
cyc_gloss = C["gc"] * (C["gd"] + C["gi"])
cyc_light = C["dd"] + C["di"]
def om(img): return pm.object_means(img, px["object_id"], mask, count)
def Y(a): return a @ pm.LUMINANCE
rows = {}
R = om(ref) if ref is not None else None
for i, nm in enumerate(info.meshes):
    if pm.object_pixels(px["object_id"], mask, count)[i] < 20: continue
    rows[nm] = dict(
        ref=(om(ref)[i].tolist() if ref is not None else None), cyc=om(C["combined"])[i].tolist(),
        cyc_diff=om(cyc_diff)[i].tolist(), cyc_gloss=om(cyc_gloss)[i].tolist(), cyc_light=om(cyc_light)[i].tolist(),
        cyc_dc=om(C["dc"])[i].tolist(),
        prod=om(full)[i].tolist(), prod_base=om(base_part)[i].tolist(), prod_light=om(light)[i].tolist(), B_smooth=om(lights["Radiosity"])[i].tolist(), B_flat=om(lights["Radiosity Patches"])[i].tolist())
print(f"{'object':18s} {'cyc/ref':>8s} {'prod/cyc':>8s} | {'light p/c':>9s} {'diff p/c':>8s} | gloss: {'cyc':>7s} {'prod':>7s} (share of cyc) | {'spec prod/cyc':>8s}")
for nm, r in rows.items():
    a = {k: np.array(v) if v is not None else None for k, v in r.items()}
    pspec = a["prod"] - a["prod_base"]
    print(f"{nm:18s} {Y(a['cyc'])/Y(a['ref']) if a['ref'] is not None else float('nan'):8.3f} {Y(a['prod'])/Y(a['cyc']):8.3f} | "
          f"{Y(a['prod_light'])/Y(a['cyc_light']):9.3f} {Y(a['prod_base'])/Y(a['cyc_diff']):8.3f} | "
          f"{Y(a['cyc_gloss']):7.4f} {Y(pspec):7.4f} ({Y(a['cyc_gloss'])/Y(a['cyc']):.3f}) | {Y(pspec)/max(Y(a['cyc_gloss']),1e-9):8.3f}"
          f"  light RGB p/c {np.round(a['prod_light']/a['cyc_light'],3)}  Bflat/Bsmooth {Y(a['B_flat'])/Y(a['B_smooth']):.3f}")
OUT.mkdir(parents=True, exist_ok=True)
out = OUT / f"passes_{args.tag}.npz"
np.savez_compressed(out, full=full, base=base_part, light=light, indirect=lights["Radiosity Indirect"], view_cosine=view_cosine, object_id=px["object_id"], patch_id=px["patch_id"], mask=mask,
                    **{k: v for k, v in C.items()})
(OUT / f"passes_{args.tag}.json").write_text(json.dumps({"rows": rows, "stats": stats, "terms": terms, "meshes": info.meshes}, indent=1))
