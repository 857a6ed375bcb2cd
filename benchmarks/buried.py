"""Buried parts of patches (rooms of overlapping boxes): how dark the edge patches come out
without the visibility cells and with them, and what finding them costs.

    python -m benchmarks.buried            # -> benchmarks/results/buried.md

1. Edge patches. A 5 x 4 x 2.75 m room of 0.4 m thick slabs that run into each other at every
   edge (reaches 0.125 / 0.375 m, or 0.1 / 0.3 m where the buried border does not fall on a
   visibility cell line), 0.25 m patches, a 1 x 1 m ceiling panel emitting. Its twin is the same
   room whose slabs are cut at the room's edges (meeting without overlap), with the same patch
   cuts inside, so every visible part of the first is a whole patch of the second. Per inner
   patch, B(overlapping) / B(twin), area-weighted over the edge patches (partly buried) and
   over the others; one walk each, the twin solved once.
2. Cost. build_geometry with and without the visibility step, alternately in one run: the
   sample scenes (nothing buried), and the overlapping room (reaches 0.1 / 0.3 m) at about 10^5
   and 10^6 patches and its twin (nothing crosses it: only the in-plane rays).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from addon.core import PatchScene, solve  # noqa: E402
from addon.core.scene.geometry_build import build_geometry  # noqa: E402

SIZE = np.array([5.0, 4.0, 2.75])
THICKNESS = 0.4
OUT = ROOT / "benchmarks" / "results" / "buried.md"


def _lines(lo, hi, step):
    """Cuts of [lo, hi] into equal patches of about ``step`` (as meshing cuts a face)."""
    return np.linspace(lo, hi, max(1, int(round((hi - lo) / step))) + 1)


def room(reaches, step, overlap=True, twin_cuts=True):
    """(origin, u, v) (P,3) of the slab room's patches and (P,) bool inner: the slab across axis
    a reaches ``reaches[a][k]`` past the room along axis k; its inner face is cut into equal
    patches of about ``step`` (the twin, ``overlap=False``: the same cuts clipped to the room, or
    with ``twin_cuts=False`` its own equal patches)."""
    origins, us, vs, inner = [], [], [], []
    for a in range(3):
        for side in (0, 1):
            lower, upper = np.zeros(3), SIZE.copy()
            cuts = {}
            for k, r in reaches[a].items():
                lines = _lines(-r, SIZE[k] + r, step)
                if overlap:
                    lower[k], upper[k] = -r, SIZE[k] + r
                elif twin_cuts:
                    lines = np.unique(np.concatenate([[0.0], lines.clip(0, SIZE[k]), [SIZE[k]]]))
                else:
                    lines = _lines(0.0, SIZE[k], step)
                cuts[k] = lines
            lower[a], upper[a] = (-THICKNESS, 0.0) if side == 0 else (SIZE[a], SIZE[a] + THICKNESS)
            for face_axis in range(3):
                for face_side in (0, 1):
                    b, c = (face_axis + 1) % 3, (face_axis + 2) % 3
                    first, second = (b, c) if face_side else (c, b)
                    is_inner = face_axis == a and face_side == 1 - side
                    l1 = cuts[first] if is_inner else np.array([lower[first], upper[first]])
                    l2 = cuts[second] if is_inner else np.array([lower[second], upper[second]])
                    i, j = np.meshgrid(np.arange(l1.size - 1), np.arange(l2.size - 1), indexing="ij")
                    i, j = i.ravel(), j.ravel()
                    o = np.tile(lower, (i.size, 1))
                    if face_side:
                        o[:, face_axis] = upper[face_axis]
                    o[:, first], o[:, second] = l1[i], l2[j]
                    u = np.zeros((i.size, 3))
                    v = np.zeros((i.size, 3))
                    u[:, first] = l1[i + 1] - l1[i]
                    v[:, second] = l2[j + 1] - l2[j]
                    origins.append(o)
                    us.append(u)
                    vs.append(v)
                    inner.append(np.full(i.size, is_inner))
    return np.concatenate(origins), np.concatenate(us), np.concatenate(vs), np.concatenate(inner)


def mesh(origin, u, v):
    corners = np.stack([origin, origin + u, origin + u + v, origin + v], axis=1).reshape(-1, 3)
    base = 4 * np.arange(origin.shape[0])[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    return corners, triangles, np.repeat(np.arange(origin.shape[0]), 2)


def room_scene(reaches, step, overlap=True, visible_parts=True):
    origin, u, v, inner = room(reaches, step, overlap)
    V, T, TP = mesh(origin, u, v)
    centre = origin + 0.5 * (u + v)
    normal = np.cross(u, v)
    ceiling = inner & (normal[:, 2] < 0)
    panel = ceiling & (np.abs(centre[:, 0] - SIZE[0] / 2) < 0.5) & (np.abs(centre[:, 1] - SIZE[1] / 2) < 0.5)
    floor = inner & (normal[:, 2] > 0)
    R = np.where(floor, 0.4, 0.7)
    E = np.where(panel, 1.0, 0.0)
    g = build_geometry(V, T, TP, origin.shape[0], visible_parts=visible_parts)
    return PatchScene(V, T, TP, R, E, _geometry=g), origin, u, v, inner


def visible_key(origin, u, v):
    """Each patch's visible rectangle (clipped to the room), rounded, as a hashable key."""
    lo = np.minimum(origin, origin + u + v).clip(0, SIZE)
    hi = np.maximum(origin, origin + u + v).clip(0, SIZE)
    return [tuple(x) for x in np.round(np.hstack([lo, hi]), 6)]


def edge_ratios(reaches, step, paths, seed=1, settings=None):
    settings = settings or {}
    twin, to, tu, tv, tin = room_scene(reaches, step, overlap=False)
    assert twin.geometry.buried is None
    reference = solve(twin, paths=paths, seed=seed + 100, **settings)
    index = {k: i for i, k in enumerate(visible_key(to, tu, tv)) if tin[i]}
    rows = {}
    for visible_parts in (False, True):
        scene, o, u, v, inner = room_scene(reaches, step, overlap=True, visible_parts=visible_parts)
        r = solve(scene, paths=paths, seed=seed, **settings)
        keys = visible_key(o, u, v)
        full_area = np.linalg.norm(np.cross(u, v), axis=1)
        normal_axis = np.argmax(np.abs(np.cross(u, v)), axis=1)
        extent = np.array(keys)[:, 3:] - np.array(keys)[:, :3]
        extent[np.arange(extent.shape[0]), normal_axis] = 1.0
        vis = extent.prod(axis=1)
        f_true = vis / full_area
        use = np.flatnonzero(inner & (f_true > 1e-9))
        twin_of = np.array([index[keys[i]] for i in use])
        B, Bt = r.radiosity[use, 0], reference.radiosity[twin_of, 0]
        var = r.reflected_variance[use, 0] + reference.reflected_variance[twin_of, 0]
        w = vis[use]
        edge = f_true[use] < 1 - 1e-9
        out = {}
        for name, sel in (("edge", edge), ("other", ~edge)):
            ratio = float((w[sel] * B[sel]).sum() / (w[sel] * Bt[sel]).sum())
            sd = float(np.sqrt((w[sel] ** 2 * var[sel]).sum()) / (w[sel] * Bt[sel]).sum())
            out[name] = (ratio, sd, int(sel.sum()))
        f_est = scene.patch_area[use] / full_area[use]
        out["f_error"] = float(np.abs(f_est[edge] - f_true[use][edge]).max()) if visible_parts else float("nan")
        z = (B - Bt) / np.sqrt(var)
        out["z"] = (float(np.abs(z[edge]).max()), float(z[edge].mean()))
        rows[visible_parts] = out
    return rows


def timed_builds(make, repeats=3):
    """(seconds without, seconds with the visibility step), best of ``repeats``, alternating."""
    V, T, TP, P = make()
    best = {False: np.inf, True: np.inf}
    buried = None
    for _ in range(repeats):
        for visible_parts in (False, True):
            t = time.perf_counter()
            g = build_geometry(V, T, TP, P, visible_parts=visible_parts)
            _ = g.surface_tracer  # (the walks build it anyway; counted on both sides)
            best[visible_parts] = min(best[visible_parts], time.perf_counter() - t)
            if visible_parts:
                buried = g.buried
            del g
    return best[False], best[True], 0 if buried is None else buried.patch.size


def main():
    lines = ["# Buried parts of patches: edge patches of overlapping boxes, and the cost of finding them", ""]
    lines += ["`python -m benchmarks.buried` (machine shared with other jobs: times are best of 3, the two sides "
              "alternating in one run).", ""]
    aligned = ({1: 0.375, 2: 0.125}, {0: 0.125, 2: 0.375}, {0: 0.375, 1: 0.125})
    unaligned = ({1: 0.3, 2: 0.1}, {0: 0.1, 2: 0.3}, {0: 0.3, 1: 0.1})
    lines += ["## Edge patches: B(overlapping room) / B(its twin without overlaps), area-weighted", "",
              "5 x 4 x 2.75 m room of 0.4 m slabs, 0.25 m patches, ceiling panel 1 x 1 m; walk, random exit, "
              "2,000,000 paths each (twin: one solve); sd from the batch variances.", "",
              "| borders | method | visibility | edge patches (n) | ratio | sd | edge patches' z: max abs, mean | other patches ratio | max f error |",
              "|---|---|---|---|---|---|---|---|---|"]
    for label, reaches in (("on cell lines", aligned), ("between cell lines", unaligned)):
        for mlabel, settings in (("walk", {}), ("two_way", {"method": "two_way"})):
            rows = edge_ratios(reaches, 0.25, 2_000_000, settings=settings)
            for visible_parts in (False, True):
                r = rows[visible_parts]
                lines.append(f"| {label} | {mlabel} | {'on' if visible_parts else 'off (main)'} | {r['edge'][2]} | {r['edge'][0]:.4f} | "
                             f"{r['edge'][1]:.4f} | {r['z'][0]:.1f}, {r['z'][1]:+.2f} | {r['other'][0]:.4f} ± {r['other'][1]:.4f} | "
                             f"{'' if visible_parts is False else format(r['f_error'], '.4f')} |")
                print(lines[-1], flush=True)
    lines += ["", "## Cost: build_geometry without / with the visibility step (s)", "",
              "| scene | patches | partly buried | without | with | overhead |", "|---|---|---|---|---|---|"]
    import sample_scenes

    def sample(name):
        def make():
            s = sample_scenes.build(name).scene
            return s.vertices, s.triangles, s.triangle_patch, s.patch_count
        return make

    def slab(step, overlap):
        def make():
            o, u, v, _ = room(unaligned, step, overlap, twin_cuts=False)
            V, T, TP = mesh(o, u, v)
            return V, T, TP, o.shape[0]
        return make

    cases = [(n, sample(n)) for n in ("fig1_r0.5", "fig6_room", "cornell_box", "fig4_room")]
    for step in (0.03125, 0.0125 if "--quick" in sys.argv else 0.009765625):
        for overlap in (True, False):
            cases.append((f"slab room {'overlapping' if overlap else 'twin'}, {step:g} m patches", slab(step, overlap)))
    for name, make in cases:
        without, with_, buried = timed_builds(make, repeats=2 if "0.00977" in name else 3)
        P = make()[3]
        lines.append(f"| {name} | {P:,} | {buried:,} | {without:.3f} | {with_:.3f} | {with_ - without:+.3f} ({(with_ / without - 1):+.0%}) |")
        print(lines[-1], flush=True)
    OUT.write_text("\n".join(lines) + "\n")
    print("wrote", OUT)


if __name__ == "__main__":
    main()
