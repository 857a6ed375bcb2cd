"""Bad input is refused with a ValueError that names the problem and the offending indices."""
import warnings

import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.mesh.validation import CoincidentFacesWarning
from boxes import box_rectangles, box_scene, rectangles_to_mesh


@pytest.fixture(scope="module")
def mesh():
    origin, u, v, face = box_rectangles(n=2)
    return rectangles_to_mesh(origin, u, v)  # 24 patches


def make(mesh, R=None, E=None, **changes):
    V, T, TP = mesh
    P = 24
    R = np.full(P, 0.5) if R is None else R
    E = np.r_[np.zeros(4), np.ones(4), np.zeros(16)] if E is None else E
    args = dict(vertices=V, triangles=T, triangle_patch=TP, reflectivity=R, emission=E)
    args.update(changes)
    return PatchScene(**args)


def with_value(n, index, value, channels=None):
    a = np.full((n, 3), 0.5) if channels else np.full(n, 0.5)
    a[index] = value
    return a


def test_valid_scene(mesh):
    scene = make(mesh)
    assert scene.patch_count == 24 and scene.triangle_count == 48
    np.testing.assert_allclose(scene.patch_area, 0.25)


@pytest.mark.parametrize(
    "R, E, message",
    [
        (with_value(24, 7, np.nan), None, r"reflectivity is NaN or infinite on patches 7"),
        (with_value(24, 3, np.inf), None, r"reflectivity is NaN or infinite on patches 3"),
        (with_value(24, [2, 9], 1.0), None, r"reflectivity must lie in \[0, 1\).*patches 2, 9"),
        (with_value(24, 5, -0.1), None, r"reflectivity must lie in \[0, 1\).*patches 5"),
        (None, with_value(24, 11, -1.0), r"emission is negative on patches 11"),
        (None, with_value(24, 12, np.nan, channels=3), r"emission is NaN or infinite on patches 12"),
        (None, np.zeros(24), r"no emitting patch"),
        (np.full(23, 0.5), None, r"^reflectivity has 23 values but the scene has 24 patches$"),
        (np.full((23, 3), 0.5), None, r"^reflectivity has 23 rows but the scene has 24 patches$"),
        (np.full(25, 0.5), None, r"^reflectivity has 25 values but the scene has 24 patches$"),
        (np.full(23, 0.5), np.ones(25), r"^reflectivity has 23 rows and emission 25: each needs one row per patch "
                                       r"\(the triangles name 24 patches\)$"),
        (None, np.ones(25), r"emission has 25 values but the scene has 24 patches"),
        (np.full((24, 2), 0.5), None, r"shape \(P,\) or \(P, 3\)"),
    ],
)
def test_bad_materials(mesh, R, E, message):
    with pytest.raises(ValueError, match=message):
        make(mesh, R=R, E=E)


def test_bad_geometry(mesh):
    V, T, TP = mesh
    with pytest.raises(ValueError, match=r"vertices are NaN or infinite at vertex indices 5"):
        V2 = V.copy()
        V2[5, 1] = np.nan
        make(mesh, vertices=V2)
    with pytest.raises(ValueError, match=r"triangles 4 use vertex indices outside"):
        T2 = T.copy()
        T2[4, 0] = len(V)
        make(mesh, triangles=T2)
    with pytest.raises(ValueError, match=r"triangles 6 name patches outside \[0, 24\)"):
        TP2 = TP.copy()
        TP2[6] = 24
        make(mesh, triangle_patch=TP2)
    with pytest.raises(ValueError, match=r"triangle_patch must have shape \(48,\)"):
        make(mesh, triangle_patch=TP[:-1])
    with pytest.raises(ValueError, match=r"triangles must have shape"):
        make(mesh, triangles=T[:, :2])
    with pytest.raises(ValueError, match=r"patches 0 have triangles of opposite winding"):
        T3 = T.copy()
        T3[0] = T3[0, ::-1]  # flip one of patch 0's two equal triangles: the normals cancel
        make(mesh, triangles=T3)
    with pytest.raises(ValueError, match=r"patches 0 mix triangles of different orientation"):
        # Patch 0 (floor, normal +z) also takes a big flipped triangle of the ceiling (normal +z
        # after flipping is wrong: it faces out of the box, 180 degrees from the ceiling's own).
        far = V[T[0]] + [0, 0, 0.5]
        V4 = np.vstack([V, far[::-1] * [1, 1, 1]])
        extra = np.arange(len(V), len(V) + 3)[None]
        T4 = np.vstack([T, extra, extra[:, ::-1], extra[:, ::-1]])
        with pytest.warns(CoincidentFacesWarning):  # the three extra triangles coincide
            make(mesh, vertices=V4, triangles=T4, triangle_patch=np.r_[TP, 0, 0, 0])


def test_degenerate_triangles_dropped_with_warning(mesh):
    V, T, TP = mesh
    # Add a zero-area triangle (repeated vertex) to patch 3: dropped, patch 3 keeps its area.
    T2 = np.vstack([T, [[0, 0, 1]]])
    TP2 = np.r_[TP, 3]
    with pytest.warns(UserWarning, match=r"dropped 1 degenerate"):
        scene = make(mesh, triangles=T2, triangle_patch=TP2)
    np.testing.assert_allclose(scene.patch_area, 0.25)


def test_patch_without_area_is_an_error(mesh):
    V, T, TP = mesh
    # Patch 3's two triangles collapse to a line: it is left with no area.
    T2 = T.copy()
    T2[TP == 3] = [[0, 0, 1], [1, 1, 0]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match=r"patches 3 have no area"):
            make(mesh, triangles=T2)


def test_solve_arguments(mesh):
    scene = make(mesh)
    for kwargs, message in [
        (dict(paths=0), r"paths must be a positive whole number"),
        (dict(paths=1.5), r"paths must be a positive whole number"),
        (dict(target_mse=0.0), r"target_mse must be a positive number"),
        (dict(target_mse=float("nan")), r"target_mse must be a positive number"),
        (dict(), r"give paths"),
        (dict(paths=10, exit_point="middle"), r"exit_point"),
        (dict(paths=10, estimator="biased_infinite", threshold=0.0), r"threshold"),
        (dict(paths=10, estimator="biased_infinite", threshold=1.0), r"threshold"),
        (dict(paths=10, stop_rule="measured"), r"needs a target_error"),
        (dict(target_error=-0.1), r"target_error must be a positive number"),
        (dict(paths=10, colour=1), r"no solve setting named 'colour'"),
        (dict(paths=10, threads=0), r"threads"),
        (dict(paths=10, seed=-1), r"seed"),
        (dict(paths=10, max_seconds=-1), r"max_seconds"),
    ]:
        estimator = kwargs.pop("estimator", "finite")
        with pytest.raises(ValueError, match=message):
            solve(scene, estimator=estimator, **kwargs)


def test_with_materials_shares_geometry_and_tracer(mesh):
    scene = make(mesh)
    tracer = scene.tracer
    other = scene.with_materials(np.full(24, 0.2), np.ones(24))
    assert other.geometry is scene.geometry
    assert other.tracer is tracer
    with pytest.raises(ValueError, match=r"reflectivity must lie"):
        scene.with_materials(np.full(24, 1.0), np.ones(24))


def test_patch_errors_carry_the_patch_indices(mesh):
    from addon.core import PatchError

    with pytest.raises(PatchError) as info:
        make(mesh, R=with_value(24, [2, 9], 1.0))
    assert list(info.value.patches) == [2, 9]
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize("method", ["walk", "two_way", "jacobi", "auto"])
@pytest.mark.parametrize("stop_rule", ["predicted", "measured"])
def test_an_absolute_target_no_run_could_reach_is_refused_before_it_runs(mesh, method, stop_rule, monkeypatch):
    """Sources of 1e30 with an absolute target of 1e-4 would plan about 1e63 paths (it ran until
    killed): one ValueError naming the target and the paths, before a single chunk. The same
    sources with a relative target solve as any scene does."""
    from addon.core import predict, relative_rms_to_mse
    from addon.core.methods.base import Method

    scene = make(mesh, E=np.r_[np.zeros(4), np.full(4, 1e30), np.zeros(16)])
    monkeypatch.setattr(Method, "create", lambda *a, **k: pytest.fail("a chunk's state was built"))
    with pytest.raises(ValueError, match=r"target_mse 0\.0001 would take about 3\.\d+e\+63 paths .* more than any run"):
        solve(scene, target_mse=1e-4, method=method, stop_rule=stop_rule, threads=1)
    monkeypatch.undo()
    r = solve(scene, target_mse=relative_rms_to_mse(predict(scene), 0.05), method=method, stop_rule=stop_rule, seed=1,
              threads=1)
    assert r.paths > 0 and np.isfinite(r.radiosity).all() and np.isfinite(r.irradiance_variance).all()


def test_more_paths_than_any_run_could_trace_are_refused(mesh):
    with pytest.raises(ValueError, match=r"paths must be at most 1,125,899,906,842,624"):
        solve(make(mesh), paths=10**20)


@pytest.mark.parametrize("emission", [1e160, 1e300])
def test_sources_whose_squares_overflow_are_refused_in_one_line(mesh, emission):
    """Emission of 1e160 made the paper's formula square 1e160 (a bare OverflowError from
    predict); now the scene is refused, naming the power and what to do."""
    with pytest.raises(ValueError, match=r"the sources' power .* above 1e\+100: .*overflow; scale the emission"):
        make(mesh, E=np.r_[np.zeros(4), np.full(4, emission), np.zeros(16)])
