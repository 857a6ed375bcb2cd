"""What the preview could show of a default Principled surface, against what Cycles' camera sees,
per object, from a saved ``brightness.py`` run (made with ``--set indirect_output=True``):

- hemispherical (the product): base x scale x light + offset x light, the surface's mean over
  view directions under even light;
- view diffuse: the diffuse part with Cycles' closure weight at the pixel's view cosine
  (1 - the specular layer's estimate), the specular part as above;
- view diffuse + specular: both at the pixel's view cosine, under even light;
- specular of indirect light: offset x the light arriving after a bounce (highlights of lamps,
  sun and sky left out);
- diffuse only: no specular term.

    .venv/bin/python -m benchmarks.brightness_display view1 view2

Each object's ratio to Cycles, and divided by the light's ratio (the display alone, as if the
light arriving were exact).
"""
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from addon.core.materials import principled  # noqa: E402
from benchmarks import picture_metrics as pm  # noqa: E402

OUT = ROOT / "out" / "brightness"


def variants(z):
    """name -> (H, W, 3) image of each display, from a run's saved images."""
    p = principled.PrincipledInputs()
    energy, weight = principled._layers_out(p, np.array([0.8, 0.8, 0.8]))
    mu_nodes = principled.mu_nodes()[0]
    scale, offset = principled.surface_terms(p)
    mu = z["view_cosine"][..., None]
    w, e = np.interp(mu, mu_nodes, weight[:, 0]), np.interp(mu, mu_nodes, energy[:, 0])
    diffuse, specular, light = z["base"], z["full"] - z["base"], z["light"]
    with np.errstate(invalid="ignore", divide="ignore"):
        per_light = np.where(light > 1e-9, specular / light, 0.0)  # the material's offset, per pixel
    return {"hemispherical (product)": diffuse + specular,
            "view diffuse": diffuse * w / scale[0] + specular,
            "view diffuse + specular": diffuse * w / scale[0] + specular * e / offset[0],
            "specular of indirect light": diffuse + per_light * z["indirect"],
            "diffuse only": diffuse}


def table(tag):
    z = np.load(OUT / f"passes_{tag}.npz")
    names = json.loads((OUT / f"passes_{tag}.json").read_text())["meshes"]
    mask, ids, count = z["mask"], z["object_id"], len(names)
    pixels = pm.object_pixels(ids, mask, count)
    seen = pixels >= 20
    cycles = pm.object_means(z["combined"], ids, mask, count) @ pm.LUMINANCE
    light = (pm.object_means(z["light"], ids, mask, count) @ pm.LUMINANCE
             / (pm.object_means(z["dd"] + z["di"], ids, mask, count) @ pm.LUMINANCE))
    ratios = {k: pm.object_means(v, ids, mask, count) @ pm.LUMINANCE / cycles for k, v in variants(z).items()}
    lines = [f"### {tag}", "", "| object | pixels | light | " + " | ".join(ratios) + " |", "|---|---|---|" + "---|" * len(ratios)]
    for i in np.flatnonzero(seen):
        lines.append(f"| {names[i]} | {pixels[i]:,} | {light[i]:.3f} | "
                     + " | ".join(f"{r[i]:.3f} ({r[i] / light[i]:.3f})" for r in ratios.values()) + " |")
    for label, f in (("max", lambda d: np.abs(d).max()), ("pixel-weighted mean", lambda d: np.average(np.abs(d), weights=pixels[seen]))):
        lines.append(f"| {label} abs. deviation | | | " + " | ".join(
            f"{f(r[seen] - 1):.3f} ({f(r[seen] / light[seen] - 1):.3f})" for r in ratios.values()) + " |")
    return lines + [""]


if __name__ == "__main__":
    print("\n".join(line for tag in sys.argv[1:] for line in table(tag)))
