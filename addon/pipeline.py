"""The solve without threads: object arrays -> patches -> prediction -> solve -> colours.

:func:`run_solve` is the public synchronous way to run a job (scripts, the command line, the
operator's synchronous mode); ``worker`` runs the same on a thread. No bpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .core import meshing, predict, relative_rms_to_mse, solve
from . import options
from .patches import Patches, make_patches, scene_and_notes

@dataclass
class SolveSettings:
    """A job's settings; the defaults are the panel's and the command line's (``options``)."""

    estimator: str = options.ESTIMATOR.default
    threshold: float = options.THRESHOLD.default
    relative_rms: float = options.TARGET_ERROR.default / 100.0  # of the mean reflected radiosity
    paths: int | None = None  # fixed path count instead of the error target
    patch_size: float = options.PATCH_SIZE.default  # 0: automatic (patches.automatic_patch_size)
    exit_point: str = options.EXIT_POINT.default
    sampling: str = options.SAMPLING.default
    stop_rule: str = options.STOP_RULE.default
    seed: int = options.SEED.default
    max_seconds: float | None = None
    threads: int | None = None
    output: str = options.OUTPUT.default


@dataclass
class SolveOutput:
    patches: Patches
    result: object  # core SolveResult
    prediction: object  # core Prediction for the run's settings
    target_mse: float | None
    face_colours: list = field(default_factory=list)  # (P_k,3) per object
    point_colours: list = field(default_factory=list)  # (N_k,3) per object, or None
    notes: list = field(default_factory=list)  # the core's warnings, for the user
    settings_relative_rms: float | None = None  # the error target asked for (None: a path count)

    def blocked_fraction(self):
        """Share of the emitted power absorbed on the back side of faces."""
        energy = self.result.energy
        if not energy:
            return 0.0
        emitted = float(np.sum(energy["emitted"]))
        return float(np.sum(energy["blocked"])) / emitted if emitted > 0 else 0.0


def prediction_for(scene, settings: SolveSettings):
    """(prediction, target_mse) of the core for these settings, no tracing."""
    base = predict(scene, settings.estimator, threshold=settings.threshold)
    if settings.paths:
        return predict(scene, settings.estimator, threshold=settings.threshold, paths=int(settings.paths)), None
    target = relative_rms_to_mse(base, settings.relative_rms)
    return predict(scene, settings.estimator, threshold=settings.threshold, target_mse=target), target


def estimate(objects, settings: SolveSettings) -> dict:
    """What the panel shows before a run: sizes and the paper's predictions."""
    patches = make_patches(objects, settings.patch_size)
    scene, _ = scene_and_notes(patches)
    p, target = prediction_for(scene, settings)
    other = "biased_infinite" if settings.estimator == "finite" else "finite"
    return {
        "objects": len(objects),
        "patches": int(scene.patch_count),
        "paths": int(p.paths),
        "rays": float(p.expected_rays),
        "path_length": float(p.expected_path_length),
        "R_ave": float(p.R_ave),
        "relative_efficiency": float(predict(scene, "biased_infinite", threshold=settings.threshold).relative_efficiency),
        "target_mse": target,
        "predicted_mse": float(p.predicted_mse),
        "other_estimator": other,
    }


def run_solve(objects, settings: SolveSettings, progress=None, should_stop=None, on_prediction=None) -> SolveOutput:
    """Mesh, solve and compute the colours to write, for the given objects.

    ``on_prediction(prediction, patch_count)`` is called once the patches
    are known, before the first path.
    """
    patches = make_patches(objects, settings.patch_size)
    scene, notes = scene_and_notes(patches)
    prediction, target = prediction_for(scene, settings)
    if on_prediction is not None:
        on_prediction(prediction, int(scene.patch_count))
    result = solve(
        scene,
        settings.estimator,
        paths=int(settings.paths) if settings.paths else None,
        target_mse=target,
        threshold=settings.threshold,
        seed=int(settings.seed),
        exit_point=settings.exit_point,
        sampling=settings.sampling,
        stop_rule=settings.stop_rule if target is not None else "predicted",
        progress=progress,
        should_stop=should_stop,
        max_seconds=settings.max_seconds or None,
        threads=settings.threads or None,
    )
    out = SolveOutput(patches, result, prediction, target, notes=notes,
                      settings_relative_rms=None if settings.paths else settings.relative_rms)
    radiosity = np.asarray(result.radiosity, dtype=np.float64)
    for k, mesh in enumerate(patches.meshes):
        B = radiosity[patches.combined.patch_slice(k)]
        out.face_colours.append(B)
        out.point_colours.append(
            meshing.point_average(mesh, B) if settings.output in ("VERTEX", "BOTH") else None
        )
    return out
