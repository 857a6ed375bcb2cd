"""solve(): a scene's radiosity by its method's chunks, on threads or a cluster, to a path count
or an error target.

Its stages: check the settings (``settings.Settings``), choose the method (Automatic's choice,
measured by pilots where it must be: ``forecast.measured_choice``), then run its chunks
(``chunks.run``: plan, state, runner, tallies, result).
"""
from __future__ import annotations

import time

import numpy as np

from . import methods
from .chunks import SolveResult, run
from .estimate.error_model import MAX_PATHS, check_estimator, check_positive
from .estimate.grouping import groups_for
from .forecast import measured_choice
from .methods import automatic
from .methods.tables import Speedups
from .names import AUTO, ERROR_SCALES, EXIT_POINTS, GATHERED, MEASURED, SAMPLINGS, SHOT, STOP_RULES
from .scene.diagnostics import check_bounces
from .settings import Settings

__all__ = ["Settings", "SolveResult", "solve", "chosen_method"]


def solve(scene, settings=None, *, progress=None, should_stop=None, target_mse=None, **changes):
    """Radiosity of ``scene`` by its method's chunks (the paper's shooting random walks unless
    ``settings.method`` says otherwise): a SolveResult.

    ``settings`` a Settings (default: the defaults), with ``changes`` by field name (a script's
    shorthand: ``solve(scene, paths=10**6)``); ``target_mse`` the paper's MSE as the target
    (``Settings.for_mse``).
    Runs ``paths`` paths, or, with ``target_error``, the paths formula (2)/(3) predicts for it
    (``stop_rule="predicted"``) or until the batch estimate meets it (``"measured"``, capped
    by ``paths`` if given, else 64 times the prediction). ``error_scale`` says what the error is
    relative to: the paper's b_ave (``"paper"``, a closed scene's mean reflected radiosity), or the
    run's own mean reflected radiosity as it goes (``"measured"``: ``plan.target_now``, where light
    leaves the scene and b_ave overstates the light in it). ``direct_apart``: where chunks gather
    the direct light, its part too (``SolveResult.direct_irradiance``). ``direct_light="gathered"`` (beyond the
    paper, ``first_shot``) gathers each patch's direct light by shadow rays and walks only its
    reflection; the paper's formulas do not predict its error, so with a target it always
    stops on the measured error. ``cluster`` (a ``dask.distributed.Client`` or a scheduler
    address, ``tcp://host:port`` or ``tls://host:port``, trusted like this machine) runs the chunks on
    a Dask cluster instead of threads: bitwise the same result. ``sampling="stratified"`` (beyond
    the paper) allots each chunk's paths to sources in proportion to power and draws the first
    ray from a randomly shifted low-discrepancy set: same expectation, usually less noise;
    the predicted path counts are derived for the paper's plain ``"independent"`` sampling.
    ``method="two_way"`` (beyond the paper, ``two_way``) carries the light generation by
    generation, every ray used as a shooting and a gathering estimate about a control variate,
    its direct light always gathered (``direct_light`` None: the method's own, gathered for it,
    shot for the walks); its error, too, is measured, never predicted. ``method="auto"`` runs
    it where its chunks give every patch enough rays, else the walk (:func:`.methods.choose`;
    with ``per_source``, where it would run the two-way iteration, pilots of both measure which
    is cheaper on this machine; ``SolveResult.method`` says which ran).
    ``progress(fraction, stats)`` and ``should_stop()`` are called from the calling thread
    between chunks (``stats["radiosity"](dtype)`` gives the result so far); ``max_seconds``
    bounds the wall time. A stopped run returns the complete chunks it has. ``speedups`` (:class:`.speedups.Speedups`) switches speed-ups on or off.
    ``chunk_paths`` replaces the plan's chunk size (the estimate's pilot: ``forecast``).
    ``per_source=True`` also gives each source group's own result from the same rays
    (``SolveResult.per_source``, an estimate.per_source.PerSource; ``groups``: grouping.source_groups's,
    default each light, and the patches of each emittance): what relighting.relight recombines.
    """
    start = time.perf_counter()  # (Automatic's pilots, with per-source results, count in the time)
    s = Settings.of(settings, **changes)
    if target_mse is not None:
        check_positive("target_mse", target_mse)
        s = Settings.for_mse(scene, target_mse, s)
    _check_amounts(s)
    s = s.but(paths=None if s.paths is None else int(s.paths), groups=groups_for(scene, s.per_source, s.groups))
    method = methods.create(chosen_method(scene, s), s.direct_light)
    _check(scene, s, method)
    return run(scene, s, method, start, progress, should_stop)


def chosen_method(scene, settings):
    """The name of the method a solve with ``settings`` runs: ``settings.method``, or where it is
    "auto" Automatic's choice (``methods.automatic``), measured by pilots of its candidates on
    this machine where it asks for that (with per-source results)."""
    if settings.method != AUTO:
        return settings.method
    choice = automatic.choose(scene, settings)
    if isinstance(choice, str):
        return choice
    return measured_choice(scene, settings, choice, margin=automatic.MEASURED_MARGIN)[0]


def _check_amounts(s):
    """ValueError, in one line, for an estimator, threshold or amount the solve cannot take."""
    check_estimator(s.estimator, s.threshold)
    for name, value, integer in (("paths", s.paths, True), ("target_error", s.target_error, False),
                                 ("max_seconds", s.max_seconds, False), ("threads", s.threads, True),
                                 ("chunk_paths", s.chunk_paths, True)):
        check_positive(name, value, integer=integer)
    paths = s.paths
    if paths is None and s.target_error is None:
        raise ValueError("give paths (a path count) or target_error (an error target)")
    if paths is not None and paths > MAX_PATHS:
        raise ValueError(f"paths must be at most {MAX_PATHS:,} (2^50: more than any run can trace); got {paths!r}")


def _check(scene, s, method):
    """ValueError, in one line, for any other setting the solve cannot run with; else nothing."""
    exit_point, sampling, stop_rule, error_scale, seed = s.exit_point, s.sampling, s.stop_rule, s.error_scale, s.seed
    if exit_point not in EXIT_POINTS:
        raise ValueError(f"exit_point must be one of {', '.join(EXIT_POINTS)}; got {exit_point!r}")
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {', '.join(SAMPLINGS)}; got {sampling!r}")
    if method.direct_light == SHOT and scene.lights.gathered_only():
        why = "; ".join(f"light '{name}' {reason}" for name, reason in scene.lights.gathered_only())
        raise ValueError(f"{why}: a shooting walk cannot carry its direct light; use direct_light='{GATHERED}' "
                         "(shadow rays from each patch)")
    if stop_rule not in STOP_RULES:
        raise ValueError(f"stop_rule must be one of {', '.join(STOP_RULES)}; got {stop_rule!r}")
    if error_scale not in ERROR_SCALES:
        raise ValueError(f"error_scale must be one of {', '.join(ERROR_SCALES)}; got {error_scale!r}")
    if stop_rule == MEASURED and s.target_error is None:
        raise ValueError("stop_rule='measured' needs a target_error")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative whole number; got {seed!r}")
    if s.speedups is not None and not isinstance(s.speedups, Speedups):
        raise ValueError(f"speedups must be a Speedups; got {s.speedups!r}")
    check_bounces(scene, s.estimator, s.threshold)
