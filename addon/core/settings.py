"""What a solve is asked for, in one frozen object: made once by the panel or the command line
(or a script) and read by the solve, its plan, its stop rule and its forecast.

The error target is one number throughout: ``target_error``, a relative RMS error of the patch
values' noise on ``error_scale`` (the paper's b_ave, or the run's own mean reflected radiosity).
The plan turns it into the paper's MSE where formulas (2)/(3) need one (``estimate.plan``), and
nowhere else; the paper's experiments, which give an MSE, say so by ``Settings.for_mse``.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

from .estimate.error_model import mse_to_relative_rms, predict
from .names import EXIT_RANDOM, FINITE, INDEPENDENT, PREDICTED, SCALE_PAPER, WALK


@dataclass(frozen=True)
class Settings:
    """A solve's settings. ``paths``: a path count (with a target, the cap); ``target_error``: the
    relative RMS error to stop at (``stop_rule`` "predicted": the paths formula (2)/(3) gives for
    it; "measured": once the batch estimate meets it); ``method`` "walk", "jacobi", "two_way" or
    "auto"; ``direct_light`` "shot" or "gathered" (None: the method's own); ``cluster`` a Dask
    client or scheduler address (None: this machine's ``threads``); ``chunk_paths`` a chunk size
    instead of the plan's (the forecast's pilots); ``per_source`` each source group's result too
    (``groups``: estimate.grouping's, default each light and each emittance's patches);
    ``direct_apart``: the gathered direct light's part kept apart; ``replaced_direct`` (an
    estimate.batches.Replaced) the source groups whose direct light the caller replaces after the
    solve, left out of its measured error, which is held to the target less the share left for
    the replacement's (the caller adds the replacement's error); ``speedups`` a
    methods.speedups Speedups (None: each scene's own)."""

    estimator: str = FINITE
    paths: int | None = None
    target_error: float | None = None
    threshold: float = 1e-3
    seed: int = 0
    exit_point: str = EXIT_RANDOM
    stop_rule: str = PREDICTED
    sampling: str = INDEPENDENT
    method: str = WALK
    direct_light: str | None = None
    max_seconds: float | None = None
    threads: int | None = None
    cluster: object = None
    chunk_paths: int | None = None
    per_source: bool = False
    groups: object = None
    error_scale: str = SCALE_PAPER
    direct_apart: bool = False
    speedups: object = None
    replaced_direct: object = None

    def but(self, **changes):
        """These settings with ``changes``."""
        return replace(self, **changes)

    @classmethod
    def of(cls, settings=None, **changes):
        """``settings`` (default: the defaults) with ``changes``; ValueError naming a field it has not."""
        unknown = sorted(set(changes) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f"no solve setting named {', '.join(map(repr, unknown))}")
        return replace(settings or cls(), **changes)

    @classmethod
    def for_mse(cls, scene, target_mse, settings=None, **changes):
        """Settings whose target is the paper's MSE ``target_mse`` on ``scene`` (its b_ave: the
        paper's experiments give their targets so)."""
        base = cls.of(settings, **changes)
        prediction = predict(scene, base.estimator, threshold=base.threshold)
        return base.but(target_error=mse_to_relative_rms(prediction, target_mse))
