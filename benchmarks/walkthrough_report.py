"""The walkthrough's reports (numpy and PIL): an interior's page (the walk's numbers per picture
kind, view by view, object by object), the summary over the interiors, and the contact sheet
(each view: reference | EEVEE | baked | Cycles at the solve's time, small, with their errors).
"""
from __future__ import annotations


from benchmarks import picture_metrics as pm

#: Picture kinds as the reports name them, in their order.
LABELS = {"eevee": "EEVEE (Material Preview, with the scene's lamps and world on)",
          "baked": "baked display (stored light x surface, as emission: no lamps)",
          "attribute": "'Radiosity' attribute alone (Solid view, exporters)",
          "preview": "the product's own Cycles preview (live lamps, 1 bounce, denoised)",
          "cycles": "Cycles + OpenImageDenoise, the ten views in the solve's time",
          "baked_unlive": "baked display of a second run with Live lamps off"}
SHORT = {"eevee": "EEVEE", "baked": "baked", "attribute": "attribute", "preview": "preview",
         "cycles": "Cycles same time", "baked_unlive": "baked, Live off"}
SHEET = ("reference", "eevee", "baked", "cycles")
TILE = (120, 90)


def percent(x):
    return f"{100 * x:.1f}%"


def kinds_of(a):
    return [k for k in LABELS if k in a["kinds"]]


def walk_table(a):
    """Over the walk, per kind: error, RMS, brightness, worst object, seconds."""
    lines = ["| picture | image error (mean abs.) | RMS, reference noise out | brightness | worst object | seconds (all views) |",
             "|---|---|---|---|---|---|"]
    for kind in kinds_of(a):
        w, seconds = a["kinds"][kind]["walk"], sum(a["kinds"][kind]["seconds"])
        worst = f"{w['worst'][0]} {w['worst'][1]:.2f}" if w["worst"] else "-"
        lines.append(f"| {LABELS[kind]} | {percent(w['error'])} | {percent(w['rms'])} | {w['brightness']:.2f} | {worst} "
                     f"| {seconds:.1f} |")
    return lines


def view_tables(a):
    """View by view: each kind's error and brightness; then its worst object."""
    kinds = kinds_of(a)
    head = "| view | reference's own error | " + " | ".join(SHORT[k] for k in kinds) + " |"
    rule = "|---|---|" + "---|" * len(kinds)
    errors, worst = [head, rule], [head.replace("reference's own error", "surface pixels"), rule]
    for k, view in enumerate(a["views"]):
        name = f"{k + 1}. {view['label']}"
        cells = [a["kinds"][kind]["views"][k] for kind in kinds]
        errors.append(f"| {name} | {percent(a['reference_error']['views'][k])} | "
                      + " | ".join(f"{percent(c['error'])} (x{c['brightness']:.2f})" for c in cells) + " |")
        worst.append(f"| {name} | {view['surface_pixels']:,} | "
                     + " | ".join(f"{c['worst'][0]} {c['worst'][1]:.2f}" if c["worst"] else "-" for c in cells) + " |")
    return errors, worst


def object_table(a):
    """Each object's brightness over the walk (its pixels of every view), per kind."""
    kinds = kinds_of(a)
    objects = a["kinds"][kinds[0]]["walk"]["objects"]
    noise = a["stats"].get("object_noise")  # (runs before it was measured: no column)
    own = " the product's own (±) |" if noise else ""
    lines = [f"| object | pixels | the reference's own (±) |{own} " + " | ".join(SHORT[k] for k in kinds) + " |",
             "|---|---|---|" + "---|" * (len(kinds) + bool(noise))]
    for name, (_, pixels, spread) in sorted(objects.items(), key=lambda item: -item[1][1]):
        ratios = [a["kinds"][k]["walk"]["objects"].get(name, [float("nan")])[0] for k in kinds]
        mine = f" {noise.get(name, float('nan')):.3f} |" if noise else ""
        lines.append(f"| {name} | {pixels:,} | {spread:.3f} |{mine} " + " | ".join(f"{r:.2f}" for r in ratios) + " |")
    return lines


def setting_lines(a):
    run, stats = a["run"], a["stats"]
    cycles = a["kinds"].get("cycles")
    spent = sum(cycles["seconds"]) if cycles else 0.0
    lines = [f"`{run['command']}`; {len(a['views'])} views of {run['size'][0]} x {run['size'][1]}; the whole run "
             f"{run['seconds'] / 60:.0f} min (load average {run['loads'][0]:.1f} at the start, {run['loads'][1]:.1f} at the end, "
             "on 2 cores shared with other work).", "",
             f"- Reference: Cycles, {run['reference_samples']} samples a view in two halves of different seeds, 64 bounces, "
             f"no clamping ({sum(a['reference_seconds']) / 60:.0f} min for the views, or cached); its own error over the "
             f"walk {percent(a['reference_error']['walk'])} (by view {percent(min(a['reference_error']['views']))}-"
             f"{percent(max(a['reference_error']['views']))}).",
             f"- The product: the panel's operator at its defaults ({run['target']:g}% target, textured, Live lamps "
             f"{'on' if stats['live_lamps'] else 'off'}): {stats['patches']:,} patches of {stats['patch_size']:.3g} m, "
             f"{stats['method']}, error estimate {stats['error']:.2f}%; the solve took **{a['solve']:.1f} s** (the operator's "
             "wall time, after a warm-up solve).",
             f"- EEVEE: {run['eevee_samples']} samples (software OpenGL here: its times mean nothing); baked and attribute: "
             f"Cycles without bounces, {run['baked_samples']} samples (anti-aliasing); the preview: {run['preview_samples']} samples."]
    if cycles:
        lines.append(f"- Cycles at the solve's time: samples by view {', '.join(map(str, a['samples']))}; the ten renders "
                     f"took {spent:.1f} s against the solve's {a['solve']:.1f} s ({spent / a['solve']:.2f}x; by view "
                     f"{min(cycles['seconds']):.1f}-{max(cycles['seconds']):.1f} s).")
    if a.get("unlive_stats"):
        u = a["unlive_stats"]
        lines.append(f"- The run with Live lamps off: {u['patches']:,} patches, error estimate {u['error']:.2f}%, its solver "
                     f"{u['solver_seconds']:.1f} s.")
    return lines


def interior_page(a):
    """The markdown page of one interior's walk (``walkthrough.analyse``'s dict, with its run)."""
    errors, worst = view_tables(a)
    name = a["interior"]
    return "\n".join([
        f"# The walkthrough: {name}", "",
        "Every picture against the reference, on the luminance of surface pixels (emitters, lamps, the background "
        "and their neighbours left out): the mean absolute error over the reference's mean, the RMS error with the "
        "reference's own noise taken out, the brightness (the picture's mean over the reference's), and the object "
        "whose mean is furthest from the reference's. Numbers in "
        f"`walkthrough_{name}.json`; made by `benchmarks/walkthrough.py`.", "",
        *setting_lines(a), "", "## Over the walk", "", *walk_table(a), "",
        "## View by view", "", "Image error (brightness):", "", *errors, "", "The worst object (its brightness):", "",
        *worst, "", "## Object by object, over the walk", "", *object_table(a), "",
        f"![{name}: reference, EEVEE, baked, Cycles at the solve's time]({a['run']['sheet']})", ""])


def summary_page(done):
    """The summary over the interiors walked (name -> analysed dict)."""
    lines = ["# The walkthrough: one solve, every view, every display", "",
             "Over the ten views of each interior (`benchmarks/walkthrough.py`; each interior's page gives the views "
             "one by one): image error (mean absolute luminance error on surface pixels over the reference's mean), "
             "brightness against the reference, and the object furthest from it.", ""]
    for name, a in done.items():
        lines += [f"## [{name}](walkthrough_{name}.md)", "",
                  f"The solve {a['solve']:.1f} s ({a['stats']['patches']:,} patches); the reference's own error "
                  f"{percent(a['reference_error']['walk'])}; the run {a['run']['seconds'] / 60:.0f} min.", "",
                  *walk_table(a), ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- the contact sheet

def tile(image, exposure, text):
    """A small display tile of a linear image, ``text`` in its corner."""
    from PIL import Image, ImageDraw, ImageFont

    out = Image.fromarray(pm.to_display(image, exposure)).resize(TILE, Image.LANCZOS)
    draw = ImageDraw.Draw(out)
    font = ImageFont.load_default(size=10)
    box = draw.textbbox((3, 2), text, font=font)
    draw.rectangle((box[0] - 2, box[1] - 1, box[2] + 2, box[3] + 1), fill=(0, 0, 0))
    draw.text((3, 2), text, fill=(255, 255, 255), font=font)
    return out


def contact_sheet(m, masks, path):
    """Each view a row: reference | EEVEE | baked | Cycles same time, exposed alike (the reference's
    median surface luminance to mid grey), each with its image error; a 256-colour PNG."""
    from PIL import Image, ImageDraw, ImageFont

    label = 14
    width, height = TILE
    rows = len(m["refs"])
    canvas = Image.new("RGB", (len(SHEET) * width, label + rows * height), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    font = ImageFont.load_default(size=11)
    for column, kind in enumerate(SHEET):
        draw.text((column * width + 4, 1), "reference" if kind == "reference" else SHORT[kind], fill=(0, 0, 0), font=font)
    for k, (ref_view, mask) in enumerate(zip(m["refs"], masks)):
        ref = 0.5 * (ref_view["first"] + ref_view["second"])
        exposure = pm.exposure_for(ref, mask)
        for column, kind in enumerate(SHEET):
            if kind == "reference":
                piece = tile(ref, exposure, f"{k + 1}")
            elif kind in m["images"]:
                image = m["images"][kind][k][0]
                piece = tile(image, exposure, percent(pm.relative_mae(image, ref, mask)))
            else:
                piece = Image.new("RGB", TILE, (90, 90, 90))
            canvas.paste(piece, (column * width, label + k * height))
    canvas.quantize(256, dither=Image.Dither.NONE).save(path, optimize=True)
