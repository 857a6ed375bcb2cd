"""Each method is a unit behind one interface (addon/core/methods): its policy read by the solver,
the forecast, the panel's words and the cluster; the state its chunks read built once, never
changed after; a worker's state rebuilt from its spec gives the same bits."""
import importlib

import numpy as np
import pytest
from pinned_cases import every_light, mixed_box

from addon.core import chunks
from addon.core.settings import Settings
from addon.core import solver
from addon.core.distributed.runners import chunk_generator
from addon.core.methods.tables import Speedups
from addon.core.methods.tables import WalkTables
from boxes import box_scene

# (method, direct light): every method solve() runs, each with every direct light it takes.
KINDS = [("walk", "shot"), ("walk", "gathered"), ("jacobi", "shot"), ("jacobi", "gathered"), ("two_way", "gathered")]


@pytest.fixture(scope="module")
def scene():
    return box_scene([0.5, 0.6, 0.4, 0.5, 0.7, 0.3], [0, 1.0, 0, 0, 0, 0], n=3)[0]


@pytest.mark.parametrize("name, direct_light", KINDS + [("auto", None)])
def test_a_solve_never_changes_the_tables_it_built(scene, monkeypatch, name, direct_light):
    """The walk tables a solve builds hold what every method reads; a method's own state (its
    gathering) is its own, so no attribute of the tables is set or replaced after they are built."""
    built = []

    class Recorded(WalkTables):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            built.append((self, dict(vars(self))))

    monkeypatch.setattr(chunks, "WalkTables", Recorded)
    r = solver.solve(scene, paths=20_000, seed=1, method=name, direct_light=direct_light, threads=2)
    assert r.paths == 20_000 and len(built) == 1
    tables, before = built[0]
    after = vars(tables)
    assert after.keys() == before.keys(), set(after) ^ set(before)
    assert [k for k, v in before.items() if after[k] is not v] == []


def test_the_tables_have_the_same_attributes_in_every_scene():
    """No attribute exists only sometimes: parallelograms or triangles, patch classes or not,
    random or hit exit, lights or none, the tables have the same names (None where unused)."""
    names = set()
    for scene in (box_scene([0.5] * 6, [0, 1.0, 0, 0, 0, 0], n=2)[0], mixed_box(), every_light()):
        for exit_point in ("random", "hit"):
            for classes in (True, False):
                tables = WalkTables(scene, "finite", 1e-3, exit_point, speedups=Speedups(patch_classes=classes))
                names.add(frozenset(vars(tables)))
    assert len(names) == 1


@pytest.mark.parametrize("name, direct_light", KINDS)
@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_a_state_rebuilt_from_its_spec_runs_the_same_chunks(name, direct_light, exit_point):
    """What a cluster worker does: the method's state rebuilt from its spec (on tables of its
    own) gives the chunks, bit for bit, that the solve's own state gives; a spec with another
    solve's split of the lost light is taken as that solve's."""
    from addon.core import methods
    from addon.core.estimate.plan import chunk_plan

    scene = every_light()
    method = methods.create(name, direct_light)
    tables = WalkTables(scene, "finite", 1e-3, exit_point)
    state = method.create(scene, tables, 2_000, 7, chunk_plan(scene, method, Settings(paths=2_000)).prediction)
    again = method.rebuild(scene, WalkTables(scene, "finite", 1e-3, exit_point), state.spec)
    a = state.run([2_000, 500], chunk_generator(7, 0))
    b = again.run([2_000, 500], chunk_generator(7, 0))
    for x, y in zip(a, b):
        assert np.array_equal(x.incident, y.incident) and x.rays == y.rays
        assert np.array_equal(x.escaped, y.escaped) and np.array_equal(x.blocked, y.blocked)
    assert (state.spec is None) == (direct_light == "shot")
    if state.spec is not None:
        other = type(state.spec)(state.spec.samples, (0.25, 0.75))
        assert other == state.spec and again.with_spec(other).gathering.fate_shares == (0.25, 0.75)
        assert again.gathering.fate_shares == state.gathering.fate_shares  # (the kept state is unchanged)


def test_each_method_says_what_it_predicts_and_plans():
    """The paper's formulas predict the shot walk's error alone; the others plan for a fraction
    of the paths they predict and are measured. The two-way iteration's variance per path falls
    as its chunks grow; a walk's does not depend on them."""
    from addon.core import methods

    predicted = {(n, d): methods.create(n, d).predicted for n, d in KINDS}
    assert predicted == {k: k == ("walk", "shot") for k in KINDS}
    assert methods.create("walk").planned_paths(4_000) == 4_000
    assert {methods.create(n, d).planned_paths(4_000) for n, d in KINDS if (n, d) != ("walk", "shot")} == {1_000}
    assert methods.create("walk").variance_scale(1_000, 4_000, 16_000) == 1.0
    assert methods.create("two_way").variance_scale(1_000, 4_000, 16_000) < 1.0
    assert methods.create("two_way").direct_light == "gathered" and methods.create("walk").direct_light == "shot"
    with pytest.raises(ValueError, match="gathers its direct light"):
        methods.create("two_way", "shot")
    with pytest.raises(ValueError, match="method must be one of walk, jacobi, two_way, auto"):
        methods.create("bogus")
    with pytest.raises(ValueError, match="direct_light must be one of shot, gathered"):
        methods.create("jacobi", "both")


def test_bad_method_arguments_are_one_line_before_anything_runs(scene):
    """Automatic without a path count or a target, a method that cannot take the direct light
    asked, an unknown method: one line each, no chunk traced."""
    for kwargs, message in (({"method": "auto"}, "give paths"),
                            ({"method": "two_way", "direct_light": "shot", "paths": 10}, "gathers its direct light"),
                            ({"method": "paper", "paths": 10}, "method must be one of")):
        with pytest.raises(ValueError, match=message):
            solver.solve(scene, **kwargs)


def test_the_automatic_tooltip_quotes_the_bound_automatic_keeps(monkeypatch):
    """The panel's words for Automatic are made from AUTO_MAX_PATCHES, not a copy of it."""
    from addon.bpy_free import options
    from addon.core.methods import automatic

    assert "about 390,000 patches" in options.METHOD.items[0][2]
    monkeypatch.setattr(automatic, "AUTO_MAX_PATCHES", 1_000_000)
    try:
        assert "about 1,000,000 patches" in importlib.reload(options).METHOD.items[0][2]
    finally:
        monkeypatch.undo()
        importlib.reload(options)
