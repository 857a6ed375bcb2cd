"""Random Walk Radiosity's numerical core: pure numpy + embreex, no bpy.

    from addon.core import PatchScene, Settings, solve, predict
    scene = PatchScene(vertices, triangles, triangle_patch, reflectivity, emission)
    result = solve(scene, Settings(estimator="finite", paths=1_000_000, seed=0))
    p = predict(scene, estimator="finite", target_mse=1e-4)

The method is Sbert & Brusi's shooting random walk radiosity: the finite (Phi_T) estimator and
the biased infinite one, with the paper's heuristic MSE formulas (2), (3) and the relative
efficiency (4). Its packages are listed in docs/code.md.
"""
from .estimate.error_model import Prediction, mse_to_relative_rms, predict, relative_rms_to_mse
from .estimate.grouping import SourceGroups, source_groups
from .estimate.per_source import PerSource
from .mesh.validation import RELATIVE_DEGENERATE_AREA, PatchError
from .methods.tables import Speedups
from .names import BIASED_INFINITE, EXIT_HIT, EXIT_RANDOM, FINITE
from .relight.relighting import Relit, relight
from .scene.scene import PatchScene
from .settings import Settings
from .solver import SolveResult, solve

__all__ = ["PatchScene", "PatchError", "Settings", "solve", "predict", "Prediction", "SolveResult", "relight",
           "Relit", "PerSource", "source_groups", "SourceGroups", "relative_rms_to_mse", "mse_to_relative_rms",
           "Speedups", "FINITE", "BIASED_INFINITE", "EXIT_RANDOM", "EXIT_HIT", "RELATIVE_DEGENERATE_AREA"]
