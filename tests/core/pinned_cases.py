"""Solves pinned bit for bit: the scenes, settings and speed-ups of ``test_pinned``, and the
fingerprint of a result. The pins in ``pinned_results.json`` were made on commit 4187daa, before
the walk was split into named stages, with that commit's module constants set as each case's
speed-ups say (counted=False: COUNTED_MAX_PATCHES = 0; sorted_paths=True: SORT_MIN_PATCHES = 1;
patch_classes=True: CLASSES_MIN_PATCHES = 1; grids=False: patch_grids.MAX_TRIANGLE_FRACTION = 0;
grouped_chunks=False: that commit's solver.GROUP_MAX_CHUNKS = 1)."""
import hashlib

import numpy as np
from boxes import box_rectangles, open_box_with_card, rectangles_to_mesh

from addon.core import PatchScene, relative_rms_to_mse


def mixed_box():
    """A closed unit box: four faces of 3 x 3 parallelogram patches, two faces of triangle
    patches (each half of a cell its own patch), a trapezoid card inside (a patch of two
    triangles that is no parallelogram), random colour reflectivities, two emitters."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=3)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    split = np.repeat((face == 4) | (face == 5), 2)
    kept = np.flatnonzero(~split)
    T = np.vstack([T[kept], T[split]])
    TP = np.concatenate([np.repeat(np.arange(kept.size // 2), 2), kept.size // 2 + np.arange(split.sum())])
    P = TP.max() + 1
    card = np.array([[0.2, 0.3, 0.6], [0.6, 0.3, 0.6], [0.5, 0.7, 0.6], [0.3, 0.7, 0.6]])
    T = np.vstack([T, V.shape[0] + np.array([[0, 2, 1], [0, 3, 2]])])
    V = np.vstack([V, card])
    TP = np.append(TP, [P, P])
    P += 1
    rng = np.random.default_rng(3)
    reflectivity = rng.uniform(0.1, 0.8, (P, 3))
    emission = np.zeros((P, 3))
    emission[[4, 40]] = [[2.0, 1.5, 1.0], [0.5, 0.5, 1.0]]
    return PatchScene(V, T, TP, reflectivity, emission)


def sample(name):
    import sample_scenes

    return sample_scenes.build(name).scene


SCENES = {
    "fig1": lambda: sample("fig1_r0.5"),
    "cornell": lambda: sample("cornell_box"),
    "card": lambda: open_box_with_card(0.6),
    "mixed": mixed_box,
    "fig4": lambda: sample("fig4_room"),
}

WALKS = [(e, x) for e in ("finite", "biased_infinite") for x in ("random", "hit")]


def _cases():
    cases = []

    def add(scene, estimator="finite", exit_point="random", speedups=None, **solve):
        solve.setdefault("paths", 20_000)
        solve.setdefault("threads", 2)
        tag = "-".join(f"{k}={v}" for k, v in sorted({**(speedups or {}), **solve}.items()))
        cases.append({
            "id": f"{scene}-{estimator}-{exit_point}-{tag}",
            "scene": scene,
            "estimator": estimator,
            "exit_point": exit_point,
            "speedups": speedups or {},
            "solve": solve,
        })

    for scene in ("fig1", "cornell", "card", "mixed"):
        for estimator, exit_point in WALKS:
            add(scene, estimator, exit_point)
        add(scene, sampling="stratified")
        add(scene, "biased_infinite", "hit", sampling="stratified", threshold=0.01)
    for estimator, exit_point in WALKS:
        add("fig1", estimator, exit_point, paths=400_000)
        add("cornell", estimator, exit_point, speedups={"sorted_paths": True, "patch_classes": True})
        add("fig1", estimator, exit_point, speedups={"grids": False})
        add("cornell", estimator, exit_point, speedups={"grouped_chunks": False})
    add("fig1", speedups={"counted": False})
    add("fig1", speedups={"counted": False, "patch_classes": True}, sampling="stratified")
    add("fig1", speedups={"patch_classes": True}, paths=400_000)
    add("mixed", speedups={"counted": False})
    add("mixed", "finite", "hit", speedups={"sorted_paths": True})
    add("fig1", threads=1)
    add("fig1", stop_rule="measured", relative_rms=0.03)
    add("cornell", "biased_infinite", stop_rule="measured", relative_rms=0.05, threads=1)
    add("fig1", paths=3, threads=1)
    add("fig4", paths=30_000)
    add("fig4", "finite", "hit", paths=30_000)
    add("fig4", "biased_infinite", "random", paths=30_000)
    return cases


CASES = _cases()


def solve_arguments(scene, case):
    """solve()'s keyword arguments for a case (an error target as a relative RMS)."""
    kw = dict(case["solve"], estimator=case["estimator"], exit_point=case["exit_point"])
    relative = kw.pop("relative_rms", None)
    if relative is not None:
        kw["target_mse"] = relative_rms_to_mse(scene, relative)
        kw.pop("paths", None)
    return kw


def fingerprint(result):
    """Everything a solve returns that the walk decides, as hashes and exact numbers."""

    def digest(a):
        return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:24]

    return {
        "radiosity": digest(result.radiosity),
        "variance": digest(np.nan_to_num(result.reflected_variance, nan=-1.0)),
        "energy": {k: [float(x).hex() for x in v] for k, v in sorted(result.energy.items())},
        "paths": int(result.paths),
        "rays": int(result.rays),
        "chunks": int(result.chunks),
        "stopped": result.stopped,
        "path_ends": {k: int(v) for k, v in sorted(result.path_ends.items())},
    }


def every_light():
    """The open box with a card, an emissive patch and a light of every kind."""
    from addon.core.lights.lights import AreaLight, PointLight, SunLight, WorldLight

    base = open_box_with_card()
    lights = [
        PointLight(np.array([0.5, 0.5, 0.3]), np.array([1.0, 0.8, 0.6]), radius=0.05),
        AreaLight(np.array([0.7, 0.3, 0.9]), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]), np.array([0, 0, -1.0]),
                  np.full(3, 2.0)),
        SunLight(np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0]), np.full(3, 1.5), angle=0.1),
        WorldLight(irradiance=np.array([0.2, 0.3, 0.4])),
    ]
    return base.with_materials(base.reflectivity, base.emission, lights=lights)


SCENES["lights"] = every_light


def glossy_lights():
    """``every_light`` with a glossy lobe on every patch (a Principled surface's specular share)."""
    base = every_light()
    share = np.full((base.patch_count, 3), 0.1)
    return base.with_materials(base.reflectivity, base.emission, glossy=(share, np.full(base.patch_count, 0.3)))


SCENES["glossy_lights"] = glossy_lights


def _method_cases():
    """Every method, direct light, exit point and stop rule solve() runs (the walk's shot cases
    are CASES): the gathered walk, stochastic Jacobi, the two-way iteration, Automatic, the
    measured stop rule, a time limit that changes the plan but never ends the run, and a chunk
    size given."""
    cases = []

    def add(scene, estimator="finite", exit_point="random", **solve):
        solve.setdefault("paths", 20_000)
        solve.setdefault("threads", 2)
        tag = "-".join(f"{k}={v}" for k, v in sorted(solve.items()))
        cases.append({"id": f"{scene}-{estimator}-{exit_point}-{tag}", "scene": scene, "estimator": estimator,
                      "exit_point": exit_point, "speedups": {}, "solve": solve})

    for scene in ("cornell", "mixed"):
        for estimator, exit_point in WALKS:
            add(scene, estimator, exit_point, direct_light="gathered")
    add("lights", direct_light="gathered", sampling="stratified")
    add("lights", "biased_infinite", "hit", direct_light="gathered")
    add("fig1", direct_light="gathered", paths=3_000)
    for scene in ("cornell", "mixed", "lights", "fig1"):
        for exit_point in ("random", "hit"):
            add(scene, "finite", exit_point, method="two_way")
    add("cornell", "biased_infinite", "random", method="two_way", seed=5)
    add("fig4", method="two_way", paths=30_000)
    add("cornell", method="jacobi")
    add("mixed", method="jacobi")
    add("cornell", method="jacobi", direct_light="gathered")
    add("fig1", method="jacobi", paths=3_000)
    add("cornell", method="auto", paths=200_000)
    add("cornell", method="auto", paths=2_000)
    add("cornell", method="auto", relative_rms=0.05)
    add("cornell", method="auto", paths=200_000, max_seconds=1e6)
    add("cornell", method="two_way", relative_rms=0.05)
    add("cornell", method="two_way", relative_rms=0.05, stop_rule="measured")
    add("cornell", direct_light="gathered", relative_rms=0.05)
    add("mixed", "biased_infinite", "hit", direct_light="gathered", relative_rms=0.08, stop_rule="measured")
    add("cornell", method="jacobi", relative_rms=0.05, stop_rule="measured")
    add("cornell", method="two_way", paths=50_000, max_seconds=1e6)
    add("fig1", paths=50_000, max_seconds=1e6)
    add("cornell", method="two_way", paths=8_000, chunk_paths=1_000)
    add("fig1", paths=8_000, chunk_paths=500)
    add("fig1", direct_light="gathered", paths=8_000, chunk_paths=500)
    # the panel's default: per-source results (relighting), the hit exit, a glossy lobe
    add("lights", "finite", "hit", method="two_way", per_source=True)
    add("glossy_lights", "finite", "hit", method="two_way", per_source=True)
    add("glossy_lights", "finite", "hit", direct_light="gathered", per_source=True)
    return cases


METHOD_CASES = _method_cases()


def method_fingerprint(result):
    """fingerprint(), and what the method decides beyond the walk: which ran, its direct light,
    its gathering rays and the light arriving."""
    digest = hashlib.sha256(np.ascontiguousarray(result.irradiance).tobytes()).hexdigest()[:24]
    found = {**fingerprint(result), "irradiance": digest, "method": result.method,
             "direct_light": result.direct_light, "gather_rays": int(result.gather_rays)}
    if result.per_source is not None:  # (each group's own light, and their covariance)
        found["per_source"] = hashlib.sha256(np.ascontiguousarray(result.per_source.irradiance).tobytes()
                                             + np.ascontiguousarray(result.per_source.covariance).tobytes()).hexdigest()[:24]
    return found
