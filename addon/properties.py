"""Settings (``scene.radiosity``) and the last run's statistics."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from .pipeline import SolveSettings


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


class RadiositySettings(bpy.types.PropertyGroup):
    estimator: EnumProperty(
        name="Estimator",
        items=[
            ("finite", "Finite (Phi_T)", "Shooting random walk with expected finite path length: "
             "every visited patch gets the path's power, survival with probability R"),
            ("biased_infinite", "Biased infinite", "Infinite path length estimator, cut when the "
             "accumulated reflectivity falls below the threshold t"),
        ],
        default="finite",
        update=_changed,
    )
    threshold: FloatProperty(
        name="Threshold t",
        description="Biased infinite estimator: a path ends when the product of reflectivities "
        "along it is below t",
        default=1e-3, min=1e-6, max=0.5, precision=4, step=0.01,
        update=_changed,
    )
    target_error: FloatProperty(
        name="Error target",
        description="Relative RMS error wanted, as a percentage of the scene's average reflected "
        "radiosity (converted to a mean square error with the paper's formulas)",
        default=5.0, min=0.05, max=100.0, soft_min=0.5, soft_max=20.0, precision=2,
        subtype="PERCENTAGE",
        update=_changed,
    )
    patch_size: FloatProperty(
        name="Patch size",
        description="Largest patch edge: faces longer than this are subdivided",
        default=0.5, min=1e-4, soft_max=10.0, precision=3, subtype="DISTANCE", unit="LENGTH",
        update=_changed,
    )
    exit_point: EnumProperty(
        name="Exit point",
        items=[
            ("random", "Random", "The next ray leaves from a random point of the hit patch"),
            ("hit", "Hit point", "The next ray leaves from the point that was hit"),
        ],
        default="random",
    )
    sampling: EnumProperty(
        name="Sampling",
        items=[
            ("independent", "Plain (paper)", "Sources and first rays drawn independently, as in the paper: "
             "the predicted path counts are derived for this"),
            ("stratified", "Stratified", "Paths allotted to sources in proportion to power and a randomly "
             "shifted low-discrepancy first ray: same expected result, usually less noise for the same time"),
        ],
        default="independent",
    )
    stop_rule: EnumProperty(
        name="Stop at",
        items=[
            ("predicted", "Predicted paths", "Run the number of paths the paper's formula predicts for the "
             "error target"),
            ("measured", "Measured error", "Run until the run's own estimate of its error (from independent "
             "batches) meets the target, at most 64 times the predicted paths"),
        ],
        default="predicted",
    )
    output: EnumProperty(
        name="Output",
        items=[
            ("FACE", "Face colours", "Flat colour per patch on the CORNER domain"),
            ("VERTEX", "Vertex colours", "Area-weighted average of the adjacent patches on the POINT domain"),
            ("BOTH", "Both", "Face colours as 'Radiosity', vertex colours as 'Radiosity Vertex'"),
        ],
        default="FACE",
    )
    clamp_reflectivity: BoolProperty(
        name="Clamp bright colours",
        description="Use 0.99 for base colours above it (white is 1.0) instead of refusing colours of "
        "1 or more, which would never let a path end in a closed room; reported as a warning",
        default=False,
        update=_changed,
    )
    seed: IntProperty(name="Seed", default=0, min=0, description="Random seed (same seed, same result)")
    time_limit: FloatProperty(
        name="Time limit", default=0.0, min=0.0, soft_max=3600.0, subtype="TIME_ABSOLUTE", unit="TIME_ABSOLUTE",
        description="Stop after this many seconds (0: no limit); the paths done so far are kept",
    )
    threads: IntProperty(
        name="Threads", default=0, min=0, max=64,
        description="Worker threads for the ray tracing (0: automatic). Same seed and threads give the same result",
    )

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
    last_stopped: StringProperty(name="Stopped by", default="")
    last_estimator: StringProperty(name="Estimator", default="")

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
            stop_rule=self.stop_rule,
            seed=int(self.seed),
            max_seconds=float(self.time_limit) or None,
            threads=int(self.threads) or None,
            output=self.output,
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
