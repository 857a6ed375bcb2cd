"""Settings (``scene.radiosity``) and the last run's statistics."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ..bpy_free import options
from ..bpy_free.pipeline import SolveSettings


def _changed(self, context):
    from . import estimate

    estimate.invalidate()


def _count(text) -> int:
    try:
        return int(text)
    except ValueError:  # edited by hand or a script: no statistics rather than an error in the panel
        return 0


def _decimal_count(name):
    """A whole-number property kept in the string property ``name`` (Blender's IntProperty
    stops at 2^31)."""
    return property(lambda self: _count(getattr(self, name)),
                    lambda self, value: setattr(self, name, str(int(value))))


def _enum(option, update=None):
    return EnumProperty(name=option.label, description=option.description, items=list(option.items),
                        default=option.default, **({"update": update} if update else {}))


def _number(option, update=None, **extra):
    """A property of ``option``'s default and range (0 allowed where 0 means a default)."""
    low = 0 if option.zero_means else option.low
    bounds = {"min": low} | ({"max": option.high} if option.high is not None else {})
    kind = IntProperty if option.integer else FloatProperty
    return kind(name=option.label, description=option.description, default=option.default,
                **bounds, **extra, **({"update": update} if update else {}))


class RadiositySettings(bpy.types.PropertyGroup):
    method: _enum(options.METHOD, _changed)
    estimator: _enum(options.ESTIMATOR, _changed)
    threshold: _number(options.THRESHOLD, _changed, precision=4, step=0.01)
    target_error: _number(options.TARGET_ERROR, _changed, soft_min=0.5, soft_max=20.0, precision=2, subtype="PERCENTAGE")
    patch_size: _number(options.PATCH_SIZE, _changed, soft_max=10.0, precision=3, subtype="DISTANCE", unit="LENGTH")
    detail: _enum(options.DETAIL, _changed)  # adaptive patches
    exit_point: _enum(options.EXIT_POINT)
    sampling: _enum(options.SAMPLING)
    direct_light: _enum(options.DIRECT_LIGHT, _changed)
    stop_rule: _enum(options.STOP_RULE, _changed)
    output: _enum(options.OUTPUT)
    per_source: _enum(options.PER_SOURCE, _changed)
    live_relight: BoolProperty(
        name="Live", default=True,
        description="Relight at once when a lamp's, the world's or an emissive material's strength or colour changes, "
        "or a lamp is hidden (needs the last solve's per-light results)")
    last_relit: StringProperty(name="Relit", default="", description="The last relight: its error and what is stale")
    show_patches: BoolProperty(
        name="Flat patches (paper)",
        description="Show each patch's own flat colour, the paper's view, instead of the textured or smooth picture: "
        "the result materials switch at once, no new run (the solid view shows the active colour attribute)",
        default=False,
    )
    clamp_reflectivity: BoolProperty(name=options.CLAMP.label, description=options.CLAMP.description,
                                     default=options.CLAMP.default, update=_changed)
    use_scene_objects: BoolProperty(name=options.SCENE_OBJECTS.label, description=options.SCENE_OBJECTS.description,
                                    default=options.SCENE_OBJECTS.default, update=_changed)
    live_lamps: BoolProperty(name=options.LIVE_LAMPS.label, description=options.LIVE_LAMPS.description,
                             default=options.LIVE_LAMPS.default)
    display_cells: BoolProperty(name=options.DISPLAY_CELLS.label, description=options.DISPLAY_CELLS.description,
                                default=options.DISPLAY_CELLS.default)
    light_output: BoolProperty(name=options.LIGHT_OUTPUT.label, description=options.LIGHT_OUTPUT.description,
                               default=options.LIGHT_OUTPUT.default)
    indirect_output: BoolProperty(name=options.INDIRECT_OUTPUT.label, description=options.INDIRECT_OUTPUT.description,
                                  default=options.INDIRECT_OUTPUT.default)
    cluster: StringProperty(name=options.CLUSTER.label, description=options.CLUSTER.description,
                            default=options.CLUSTER.default)
    seed: _number(options.SEED)
    time_limit: _number(options.TIME_LIMIT, soft_max=3600.0, subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE")
    threads: _number(options.THREADS)

    # statistics of the last finished run (written with the results). Path and ray counts pass
    # 2^31 in long runs: an IntProperty is 32-bit and a FloatProperty single precision, so they
    # are kept exactly as decimal text and read as Python ints through ``last_paths``/``last_rays``.
    last_path_count: StringProperty(name="Paths", default="0", description="Paths of the last run (decimal)")
    last_ray_count: StringProperty(name="Rays", default="0", description="Rays of the last run (decimal)")
    last_seconds: FloatProperty(name="Seconds", default=0.0)
    last_mean_path_length: FloatProperty(name="Mean path length", default=0.0)
    last_predicted_mse: FloatProperty(name="Predicted MSE", default=0.0)
    last_measured_mse: FloatProperty(name="Measured MSE", default=0.0)
    last_patches: IntProperty(name="Patches", default=0)
    last_patch_size: FloatProperty(name="Patch size used", default=0.0, subtype="DISTANCE", unit="LENGTH")
    last_stopped: StringProperty(name="Stopped by", default="")
    last_sources: StringProperty(name="Sources", default="", description="The sources of the last run and their shares of the power")
    last_light_account: StringProperty(name="Light", default="", description="Where the last run's emitted light went: absorbed by surfaces (and on the back of faces), left the scene, left undistributed")
    last_estimator: StringProperty(name="Estimator", default="")
    last_relative_error: FloatProperty(name="Error reached", default=-1.0, description="Measured relative RMS error of the last run, percent (-1: unknown)")
    last_target_error: FloatProperty(name="Error target", default=0.0, description="The last run's error target, percent (0: a path count was given)")

    last_paths = _decimal_count("last_path_count")
    last_rays = _decimal_count("last_ray_count")

    def solve_settings(self) -> SolveSettings:
        return SolveSettings(
            estimator=self.estimator,
            threshold=float(self.threshold),
            relative_rms=float(self.target_error) / 100.0,
            patch_size=float(self.patch_size),
            exit_point=self.exit_point,
            sampling=self.sampling,
            direct_light=self.direct_light,
            method=self.method,
            stop_rule=self.stop_rule,
            seed=int(self.seed),
            max_seconds=float(self.time_limit) or None,
            threads=int(self.threads) or None,
            output=self.output,
            light_output=bool(self.light_output),
            live_lamps=bool(self.live_lamps),
            display_cells=bool(self.display_cells),
            indirect_output=bool(self.indirect_output),
            cluster=self.cluster.strip(),
            per_source=self.per_source,
            detail=self.detail,
        )


classes = (RadiositySettings,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.radiosity = PointerProperty(type=RadiositySettings)


def unregister():
    if hasattr(bpy.types.Scene, "radiosity"):
        del bpy.types.Scene.radiosity
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
