"""solve(..., cluster=...) on a Dask LocalCluster of 2 worker processes: bitwise the local
result, surviving a killed worker, with clear errors for an unreachable scheduler and a missing
Dask, and cancel keeping the complete chunks."""
import os
import sys
import time

import numpy as np
import pytest
from boxes import box_scene, rectangles_to_mesh

from addon.core import GATHERED, PatchScene, solve
from addon.core.names import BIASED_INFINITE, EXIT_HIT, EXIT_RANDOM, FINITE
from addon.core.cluster import ClusterError
from addon.core.solver import chunk_paths_for

dask = pytest.importorskip("dask", reason="Dask is in requirements.txt: CI installs it")
distributed = pytest.importorskip("distributed", reason="Dask's distributed is in requirements.txt: CI installs it")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
R_FACES = [(0.7, 0.7, 0.7), (0.5, 0.5, 0.5), (0.8, 0.2, 0.2), (0.2, 0.8, 0.2), (0.6, 0.6, 0.6), (0.4, 0.4, 0.9)]
E_FACES = [(0, 0, 0), (1, 1, 1), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0)]


@pytest.fixture(scope="module")
def client():
    # The workers are new processes: they find addon.core through PYTHONPATH.
    os.environ["PYTHONPATH"] = os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    dask.config.set({"distributed.nanny.pre-spawn-environ": {}})  # (README: workers without Dask's malloc trim)
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=40)
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="module")
def scene():
    return box_scene(R_FACES, E_FACES, n=4)[0]


@pytest.mark.parametrize("estimator", [FINITE, BIASED_INFINITE])
@pytest.mark.parametrize("exit_point", [EXIT_RANDOM, EXIT_HIT])
def test_a_cluster_solve_is_bitwise_the_local_one(client, scene, estimator, exit_point):
    local = solve(scene, estimator, paths=60_000, seed=7, exit_point=exit_point, threads=2)
    remote = solve(scene, estimator, paths=60_000, seed=7, exit_point=exit_point, cluster=client)
    assert np.array_equal(local.radiosity, remote.radiosity)
    assert np.array_equal(local.reflected_variance, remote.reflected_variance, equal_nan=True)
    assert (local.paths, local.rays, local.chunks) == (remote.paths, remote.rays, remote.chunks)
    for key in local.energy:
        assert np.array_equal(local.energy[key], remote.energy[key])


def test_the_gathered_first_shot_and_the_measured_stop_rule_on_a_cluster(client, scene):
    local = solve(scene, target_mse=1e-5, seed=3, direct_light=GATHERED, threads=1)
    remote = solve(scene, target_mse=1e-5, seed=3, direct_light=GATHERED, cluster=client)
    assert np.array_equal(local.radiosity, remote.radiosity) and local.stopped == remote.stopped == "target"


@pytest.mark.parametrize("exit_point", [EXIT_RANDOM, EXIT_HIT])
def test_the_two_way_iteration_on_a_cluster_is_bitwise_the_local_one(client, scene, exit_point):
    local = solve(scene, paths=30_000, seed=5, method="two_way", exit_point=exit_point, threads=2)
    remote = solve(scene, paths=30_000, seed=5, method="two_way", exit_point=exit_point, cluster=client)
    assert np.array_equal(local.radiosity, remote.radiosity) and local.rays == remote.rays
    assert np.array_equal(local.reflected_variance, remote.reflected_variance, equal_nan=True)


def _worker_table_ids():
    from addon.core import cluster

    return sorted(id(tables) for tables in cluster._worker_tables.values())


def test_each_solve_s_light_fates_reach_the_workers_and_the_tables_are_kept_across_seeds(client):
    """An emitter under a card that faces away: the light found on no front is split between
    escaped and blocked by each solve's own fate_shares. On the cluster the accounts are bitwise
    the local ones for either seed, and the second seed reuses the workers' tables (the split
    travels with the solve, not in the tables' key)."""
    origin = np.array([[0.0, 0, 0], [0.0, 0, 0.5]])
    u, v = np.array([[1.0, 0, 0], [1.0, 0, 0]]), np.array([[0.0, 1, 0], [0.0, 1, 0]])
    card = PatchScene(*rectangles_to_mesh(origin, u, v), [0.5, 0.7], [1.0, 0.0])
    tables = None
    for seed in (5, 6):
        local = solve(card, paths=20_000, seed=seed, method="two_way", threads=2)
        remote = solve(card, paths=20_000, seed=seed, method="two_way", cluster=client)
        assert local.energy["blocked"][0] > 0 and local.energy["escaped"][0] > 0
        for key in local.energy:
            assert np.array_equal(local.energy[key], remote.energy[key]), key
        now = client.run(_worker_table_ids)
        assert tables is None or now == tables
        tables = now


def test_a_killed_worker_loses_no_paths(client, scene):
    """A worker process killed mid-solve: its tasks run again on the other worker (Dask retries
    the tasks of lost workers), and the result is still bitwise the local one."""
    local = solve(scene, paths=400_000, seed=11, threads=1)
    killed = []

    def kill_one(fraction, stats):
        if not killed and stats["paths"] > 0:
            workers = client.run(os.getpid)
            address, pid = sorted(workers.items())[0]
            os.kill(pid, 9)
            killed.append(address)

    remote = solve(scene, paths=400_000, seed=11, cluster=client, progress=kill_one)
    assert killed
    assert np.array_equal(local.radiosity, remote.radiosity) and remote.paths == local.paths
    client.wait_for_workers(2, timeout=60)  # the nanny restarts it for the next tests


def test_cancel_keeps_the_complete_chunks_and_stops_the_tasks(client, scene):
    calls = []

    def stop_after_three():
        calls.append(1)
        return len(calls) > 3

    r = solve(scene, paths=2_000_000, seed=5, cluster=client, should_stop=stop_after_three)
    assert r.stopped == "cancelled" and 0 < r.paths < 2_000_000
    chunk = chunk_paths_for(r.prediction.expected_path_length, 2_000_000)
    assert r.paths == r.chunks * chunk  # whole chunks only, in order from the first
    assert np.isfinite(r.radiosity).all()
    deadline = time.time() + 30
    while any(client.processing().values()) and time.time() < deadline:
        time.sleep(0.1)
    assert not any(client.processing().values())  # the remaining tasks were cancelled


def test_an_unreachable_scheduler_is_one_clear_error_before_tracing(scene):
    started = time.time()
    with pytest.raises(ClusterError, match="cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'"):
        solve(scene, paths=1000, cluster="tcp://127.0.0.1:9")
    assert time.time() - started < 30


def test_without_dask_the_cluster_option_says_how_to_install_it(scene, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(ClusterError, match="pip install"):
        solve(scene, paths=1000, cluster="tcp://127.0.0.1:8786")
    # and everything else works without it
    assert solve(scene, paths=1000, threads=1).paths == 1000


def _worker_geometries():
    from addon.core import cluster

    return {key: id(geometry) for key, geometry in cluster._worker_geometries.items()}


def test_workers_keep_the_geometry_and_its_embree_scene_across_solves(client, scene):
    """A second solve of the same geometry with other materials reuses each worker's geometry
    (with its Embree scene): the same objects, not rebuilt."""
    solve(scene, paths=20_000, seed=1, cluster=client)
    before = client.run(_worker_geometries)
    other = scene.with_materials(scene.reflectivity * 0.5, scene.emission)
    solve(other, paths=20_000, seed=1, cluster=client)
    after = client.run(_worker_geometries)
    for address, geometries in before.items():
        for key, identity in geometries.items():
            assert after[address][key] == identity


def test_the_time_limit_stops_the_cluster_and_keeps_whole_chunks(client, scene):
    r = solve(scene, paths=50_000_000, seed=9, cluster=client, max_seconds=1.5)
    assert r.stopped == "time_limit" and 0 < r.paths < 50_000_000
    assert r.paths == r.chunks * chunk_paths_for(r.prediction.expected_path_length, 50_000_000)
    deadline = time.time() + 30
    while any(client.processing().values()) and time.time() < deadline:
        time.sleep(0.1)
    assert not any(client.processing().values())


def test_workers_without_the_core_are_one_clear_error_before_tracing(client, scene, monkeypatch):
    """Each worker is asked first whether it can import embreex and addon.core; one that cannot
    stops the solve before any task (simulated: the answer of a worker without embreex)."""
    answers = {"tcp://10.0.0.5:4000": "ModuleNotFoundError: No module named 'embreex'", "tcp://10.0.0.6:4000": ""}
    monkeypatch.setattr(client, "run", lambda function: answers)
    submitted = []
    monkeypatch.setattr(client, "submit", lambda *a, **k: submitted.append(a))
    with pytest.raises(ClusterError, match="1 of the cluster's 2 workers cannot run the walks.*embreex"):
        solve(scene, paths=1000, cluster=client)
    assert not submitted
