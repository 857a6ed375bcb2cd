"""A job's settings (the panel's and the command line's, ``options``) and the core's Settings of
its solve: made once, frozen, read by every stage. No bpy."""
from __future__ import annotations

from dataclasses import dataclass, replace

from ..core import methods, predict
from ..core.estimate.plan import paper_target
from ..core.names import AUTO, PREDICTED
from ..core.settings import Settings
from ..core.solver import chosen_method
from . import options


@dataclass(frozen=True)
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
    light_output: bool = options.LIGHT_OUTPUT.default
    live_lamps: bool = options.LIVE_LAMPS.default  # textured: the lamps' direct light drawn by Blender
    display_cells: bool = options.DISPLAY_CELLS.default  # smooth colours on cells split where the direct light changes
    indirect_output: bool = options.INDIRECT_OUTPUT.default
    cluster: str = options.CLUSTER.default  # a Dask scheduler address; empty: this machine's threads
    direct_light: str = options.DIRECT_LIGHT.default  # "gathered": the first bounce by shadow rays (core first_shot)
    method: str = options.METHOD.default  # "two_way": the core's two-way iteration (it gathers its direct light)
    per_source: str = options.PER_SOURCE.default  # per-light results for relighting (relit.groups_for)
    detail: str = options.DETAIL.default  # adaptive patches (adaptive_patches): OFF, LOW, MEDIUM, HIGH

    def but(self, **changes):
        """These settings with ``changes``."""
        return replace(self, **changes)

    def core(self, scene=None, **changes):
        """The core's Settings of this job's solve (``changes`` by field): a path count, or the
        error target as it is (a relative error on the run's own light, ``options.ERROR_SCALE``);
        with ``scene``, the direct light as the method runs it (``direct_light_for``)."""
        direct_light = self.direct_light if scene is None or self.method == AUTO else direct_light_for(scene, self)
        return Settings(
            estimator=self.estimator, threshold=self.threshold, seed=int(self.seed),
            paths=int(self.paths) if self.paths else None, target_error=None if self.paths else self.relative_rms,
            stop_rule=self.stop_rule if not self.paths else PREDICTED, exit_point=self.exit_point,
            sampling=self.sampling, method=self.method, direct_light=direct_light,
            max_seconds=self.max_seconds or None, threads=self.threads or None, cluster=self.cluster or None,
            error_scale=options.ERROR_SCALE,
        ).but(**changes)


def prediction_for(scene, settings: SolveSettings):
    """(prediction, target_mse) of the paper's formulas for these settings, no tracing: what the
    panel shows beside the run's own forecast."""
    core = settings.core()
    target = paper_target(scene, core)
    return predict(scene, settings.estimator, threshold=settings.threshold, paths=core.paths, target_mse=target), target


def method_for(scene, settings: SolveSettings, groups=None) -> SolveSettings:
    """The settings with the method "auto" replaced by what it runs on this scene (the core's
    ``solver.chosen_method``; with per-source ``groups``, measured by pilots with them)."""
    if settings.method != AUTO:
        return settings
    return settings.but(method=chosen_method(scene, settings.core(per_source=groups is not None, groups=groups)))


def direct_light_for(scene, settings: SolveSettings) -> str:
    """How the direct light is computed (``settings.method`` resolved): as the settings say, but
    as the method has it where it has one alone (the two-way iteration gathers it), and
    gathered where a light's cannot be shot (``Lights.gathered_only``; ``light_notes`` says so)."""
    return methods.direct_light_for(settings.method, settings.direct_light, scene.lights)
