"""The Detail's refinement from the solve's own estimates (bpy_free.solve_refinement): refining
solves at a looser target split where the solved light changes, the final solve meets the user's
target on the final mesh, reproducibly for a seed (on a cluster too), and cancel stops it."""
import os
import time

import numpy as np
import pytest

from addon.bpy_free import adaptive_patches, pipeline, solve_refinement
from addon.core.refine import adaptive_light
from addon.core.refine.adaptive_light import Detail

from test_adaptive_patches import room

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.fixture(autouse=True)
def roomy(monkeypatch):
    """Medium with room left after the direct light's refinement (the test room's lamp takes
    all of Medium's own budget), and two refining solves (the product's one, and a repeat)."""
    monkeypatch.setitem(adaptive_light.DETAILS, "MEDIUM", Detail(levels=2, contrast=0.25, budget=6.0))
    monkeypatch.setattr(adaptive_patches, "ROUNDS", 2)


def settings(**more):
    return pipeline.SolveSettings(**{"patch_size": 0.2, "detail": "MEDIUM", "relative_rms": 0.05, "seed": 3, **more})


def test_refining_solves_split_and_the_final_solve_meets_the_target():
    out = pipeline.run_solve(room(), settings())
    steps = out.patches.refinement
    solved = [s for s in steps if s.get("solve")]
    assert solved and solved[0]["split"] > 0
    direct = [s for s in steps if not s.get("solve")][-1]["patches"]
    assert out.patches.combined.patch_count == solved[-1]["patches"] > direct
    assert out.patches.combined.patch_count <= max(int(6.0 * steps[0]["first"]), direct)
    r = out.result
    assert r.stopped == "target"
    assert r.measured_mse <= out.target_mse
    assert len(out.face_colours[0]) == out.patches.combined.patch_count
    assert "at most" in adaptive_patches.refinement_text(out.patches)


def test_without_refining_solves_the_direct_light_refinement_alone(monkeypatch):
    monkeypatch.setattr(adaptive_patches, "ROUNDS", 0)
    out = pipeline.run_solve(room(), settings())
    assert not any(s.get("solve") for s in out.patches.refinement)


def test_the_same_seed_makes_the_same_mesh_and_result():
    first = pipeline.run_solve(room(), settings())
    second = pipeline.run_solve(room(), settings())
    assert first.patches.combined.patch_count == second.patches.combined.patch_count
    assert np.array_equal(first.result.radiosity, second.result.radiosity)


def test_cancel_after_a_refining_solve_stops_the_run(monkeypatch):
    """A cancel that comes while the mesh is refined by a solve's estimates: no refined mesh is
    solved further, the run ends cancelled (the operator then writes nothing)."""
    cancelled = []
    refine = solve_refinement.refine_by_solve

    def refine_then_cancel(*args, **kwargs):
        cancelled.append(True)
        return refine(*args, **kwargs)

    monkeypatch.setattr(solve_refinement, "refine_by_solve", refine_then_cancel)
    out = pipeline.run_solve(room(), settings(), should_stop=lambda: bool(cancelled))
    assert len(cancelled) == 1  # (the second refining solve never ran)
    assert out.result.stopped == "cancelled"


def test_the_final_solve_has_what_is_left_of_the_time_limit():
    s = settings(max_seconds=10.0, method="auto", per_source="OFF")
    final = solve_refinement._final(s, "walk", time.perf_counter() - 3.0)
    assert final.method == "walk" and 6.9 < final.max_seconds < 7.01
    late = solve_refinement._final(s, "walk", time.perf_counter() - 30.0)
    assert late.max_seconds == pytest.approx(10.0 * solve_refinement.FINAL)
    assert solve_refinement._final(settings(per_source="ON"), "walk", time.perf_counter()).method == "auto"


def test_the_predicted_time_counts_the_refining_solves():
    objects = room()
    patches = adaptive_patches.refined(objects, pipeline.make_patches(objects, 0.2), "MEDIUM", 3)
    assert solve_refinement.predicted_seconds(patches, 8.0) == pytest.approx(8.0 * (1 + 2 / 4))
    assert solve_refinement.predicted_seconds(pipeline.make_patches(objects, 0.2), 8.0) == 8.0


def test_on_a_cluster_the_refinement_and_result_are_bitwise_the_local_ones():
    distributed = pytest.importorskip("distributed", reason="Dask's distributed is in requirements.txt: CI installs it")
    import dask

    os.environ["PYTHONPATH"] = os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    dask.config.set({"distributed.nanny.pre-spawn-environ": {}})
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=40) as cluster:
        remote = pipeline.run_solve(room(), settings(cluster=cluster.scheduler_address))
    local = pipeline.run_solve(room(), settings())
    assert [s["patches"] for s in remote.patches.refinement] == [s["patches"] for s in local.patches.refinement]
    assert np.array_equal(remote.result.radiosity, local.result.radiosity)


def test_the_estimate_shows_the_patch_budget_and_the_refining_solves():
    objects = room()
    value = pipeline.estimate(objects, settings())
    first = pipeline.make_patches(objects, 0.2).combined.patch_count
    assert value["refinement"].startswith(f"refined from {first:,} ")
    assert value["refinement"].endswith(f"at most {int(6.0 * first):,} after up to 2 refining solves")
    adaptive_patches.ROUNDS = 1  # (the product's; the fixture's monkeypatch puts it back)
    assert adaptive_patches.refinement_text(adaptive_patches.refined(objects, pipeline.make_patches(objects, 0.2),
                                                                     "MEDIUM", 3)).endswith("after a refining solve")


def test_the_live_view_is_given_each_refining_steps_mesh_and_its_result(monkeypatch):
    """The running job hears of every mesh the refinement makes (the live view draws each step's
    result on it), the final one last, and every live result it keeps is on the mesh it has then."""
    from addon.bpy_free import worker

    monkeypatch.setattr(worker, "LIVE_SECONDS", 0.0)
    job = worker.SolveJob(room(), settings())
    job.live_view = True
    seen, drawn = [], []
    hear_prediction, hear_progress = job._on_prediction, job._on_progress

    def on_prediction(prediction, patch_count, patches=None):
        seen.append(patch_count)
        hear_prediction(prediction, patch_count, patches)

    def on_progress(fraction, stats):
        hear_progress(fraction, stats)
        drawn.append((len(job.live[1]), job.patches.combined.patch_count))

    job._on_prediction, job._on_progress = on_prediction, on_progress
    job.run()
    assert job.error is None
    assert len(set(seen)) >= 2 and seen == sorted(seen) and seen[-1] == job.output.patches.combined.patch_count
    assert {n for n, _ in drawn} == set(seen) and all(n == p for n, p in drawn)


def test_with_a_time_limit_late_refining_steps_are_skipped_and_the_final_solve_keeps_half(monkeypatch):
    """Refining steps that have taken more than REFINING of the time limit start no more (a clock
    that moves 3 s a reading: the first step ends 9 s in, past 40% of 10 s), and the final solve
    has at least FINAL of it (before, it had what was left, and could not finish a batch)."""
    class Clock:
        now = 0.0

        def perf_counter(self):
            self.now += 3.0
            return self.now

    monkeypatch.setitem(adaptive_light.DETAILS, "MEDIUM", Detail(levels=2, contrast=0.25, budget=12.0))
    unlimited = pipeline.run_solve(room(), settings())
    assert sum(1 for s in unlimited.patches.refinement if s.get("solve")) == 2
    finals = []
    monkeypatch.setattr(solve_refinement, "time", Clock())
    final = solve_refinement._final
    monkeypatch.setattr(solve_refinement, "_final", lambda *a: finals.append(final(*a)) or finals[-1])
    limited = pipeline.run_solve(room(), settings(max_seconds=10.0))
    assert sum(1 for s in limited.patches.refinement if s.get("solve")) == 1
    assert finals[0].max_seconds == pytest.approx(10.0 * solve_refinement.FINAL)
    assert limited.result.paths > 0


def test_a_refining_solve_is_a_quarter_of_the_fewest_paths_the_final_solve_runs(monkeypatch):
    """With an error target the refining solve runs MEASURED_STOP_CHUNKS chunks of a quarter of
    the final solve's planned chunk (a looser target stopped on its measured error ran many small
    chunks, more paths than the final solve), and the final solve's first RESIZE_AFTER chunks are
    of that plan (its later ones sized by what they measure: chunks.RESIZE_AFTER); with a path
    count, a quarter of it."""
    from addon.core.estimate.plan import MEASURED_STOP_CHUNKS, RESIZE_AFTER

    monkeypatch.setattr(adaptive_patches, "ROUNDS", 1)
    runs = []
    solve = solve_refinement.solve
    monkeypatch.setattr(solve_refinement, "solve", lambda *a, **k: runs.append((a[1], solve(*a, **k))) or runs[-1][1])
    out = pipeline.run_solve(room(), settings())
    (core, refining), = runs
    assert core.target_error is None and refining.chunks == MEASURED_STOP_CHUNKS
    assert refining.paths == MEASURED_STOP_CHUNKS * core.chunk_paths
    assert out.result.paths > RESIZE_AFTER * 4 * core.chunk_paths and out.result.stopped == "target"
    runs.clear()
    pipeline.run_solve(room(), settings(paths=40_000))
    assert runs[0][1].paths == 10_000
