"""solve(..., cluster=...) on a Dask LocalCluster of 2 worker processes: bitwise the local
result, surviving a killed worker, with clear errors for an unreachable scheduler and a missing
Dask, and cancel keeping the complete chunks; on a LocalCluster with TLS (certificates made here
by openssl) the same result; malformed addresses, services that are not Dask's and TLS mismatches
are one line within the connection timeout."""
import os
import shutil
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from boxes import box_scene, rectangles_to_mesh

from addon.core import PatchScene, solve
from addon.core.names import GATHERED
from addon.core.names import BIASED_INFINITE, EXIT_HIT, EXIT_RANDOM, FINITE
from addon.core.distributed.cluster import ClusterError
from addon.core.estimate.plan import chunk_paths_for

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
    local = solve(scene, estimator=estimator, paths=60_000, seed=7, exit_point=exit_point, threads=2)
    remote = solve(scene, estimator=estimator, paths=60_000, seed=7, exit_point=exit_point, cluster=client)
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


def test_a_two_way_run_that_shrinks_its_chunks_on_a_cluster_is_bitwise_the_local_one(client):
    """After its first chunks a run to a loose target goes on with smaller chunks and a smaller
    gathering (chunks._Run, two_way_sizes.later_chunk): the workers rebuild that state too."""
    from boxes import grey_room

    room, _ = grey_room()
    local = solve(room, target_error=0.02, seed=1, method="two_way", threads=1)
    remote = solve(room, target_error=0.02, seed=1, method="two_way", cluster=client)
    from addon.core.estimate.plan import chunk_plan
    from addon.core.methods import TwoWay
    from addon.core.settings import Settings

    first = chunk_plan(room, TwoWay(), Settings(target_error=0.02, method="two_way")).chunk
    assert local.paths < local.chunks * first  # (its later chunks smaller)
    assert np.array_equal(local.radiosity, remote.radiosity) and local.paths == remote.paths and local.rays == remote.rays
    assert local.gather_rays == remote.gather_rays and local.stopped == remote.stopped == "target"


def _worker_table_ids():
    from addon.core.distributed import cluster

    return sorted(id(state.tables) for state in cluster._worker_states.values())


@pytest.mark.parametrize("method, direct_light, exit_point", [("walk", "shot", EXIT_RANDOM), ("walk", GATHERED, EXIT_HIT),
                                                               ("jacobi", "shot", EXIT_RANDOM), ("two_way", None, EXIT_HIT)])
def test_per_source_results_on_a_cluster_are_bitwise_the_local_ones(client, scene, method, direct_light, exit_point):
    """The groups travel with the solve's parameters: every group's result, and its covariance,
    bit for bit the local solve's."""
    from addon.core.lights.lights import PointLight

    lit = scene.with_materials(scene.reflectivity, scene.emission, [PointLight(np.array([0.3, 0.5, 0.4]), np.full(3, 0.05))])
    kw = dict(paths=40_000, seed=5, method=method, direct_light=direct_light, exit_point=exit_point, per_source=True)
    local, remote = solve(lit, threads=2, **kw).per_source, solve(lit, cluster=client, **kw).per_source
    assert local.count == 2
    assert np.array_equal(local.radiosity, remote.radiosity) and np.array_equal(local.irradiance, remote.irradiance)
    assert np.array_equal(local.covariance, remote.covariance)


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
    from addon.core.distributed import cluster

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
    monkeypatch.setattr(client, "run", lambda function, **options: answers)
    submitted = []
    monkeypatch.setattr(client, "submit", lambda *a, **k: submitted.append(a))
    with pytest.raises(ClusterError, match="1 of the cluster's 2 workers cannot run the walks.*embreex"):
        solve(scene, paths=1000, cluster=client)
    assert not submitted


def test_a_worker_that_cannot_load_the_core_is_one_clear_error(client, scene, monkeypatch):
    """A worker without addon.core cannot even load the check: its error comes back as its
    answer (simulated: the exception Dask returns for it), one line naming the worker."""
    answers = {"tcp://10.0.0.5:4000": ModuleNotFoundError("No module named 'addon'"), "tcp://10.0.0.6:4000": ""}
    asked = []

    def run(function, **options):
        asked.append(options)
        if options.get("on_error") != "return":
            raise answers["tcp://10.0.0.5:4000"]
        return answers

    monkeypatch.setattr(client, "run", run)
    with pytest.raises(ClusterError, match="1 of the cluster's 2 workers cannot run the walks.*No module named 'addon'"):
        solve(scene, paths=1000, cluster=client)
    assert asked and asked[0].get("callback_timeout")  # the check itself is bounded in time


def test_a_worker_without_the_core_is_one_clear_error(scene, tmp_path):
    """A real worker process that cannot import addon.core (started elsewhere, without the
    repository on its path) cannot even load the check: its answer names the missing module."""
    scheduler = distributed.LocalCluster(n_workers=0, processes=False, protocol="tcp", host="127.0.0.1",
                                         dashboard_address=None, silence_logs=50)
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", scheduler.scheduler_address,
                               "--nthreads", "1", "--no-nanny", "--no-dashboard"], cwd=str(tmp_path),
                              env=environment, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with distributed.Client(scheduler, set_as_default=False) as client:
            client.wait_for_workers(1, timeout=60)
        with pytest.raises(ClusterError, match="1 of the cluster's 1 workers cannot run the walks.*No module named 'addon'"):
            solve(scene, paths=1000, cluster=scheduler.scheduler_address)
    finally:
        worker.kill()
        worker.wait(timeout=30)
        scheduler.close()


def _free_port():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_a_scheduler_without_the_core_is_one_clear_error(scene, tmp_path):
    """Dask's scheduler unpickles the tasks' arguments: one started without addon.core on its path
    is said before any task (a worker with the core is there), not as a failed task's traceback."""
    address = f"tcp://127.0.0.1:{_free_port()}"
    environment = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", address.rsplit(":", 1)[1], "--dashboard-address", ":0"], cwd=str(tmp_path),
                                 env=environment, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                               "--no-nanny", "--no-dashboard"], cwd=str(tmp_path),
                              env={**environment, "PYTHONPATH": ROOT}, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with distributed.Client(address, timeout=60, set_as_default=False) as client:
            client.wait_for_workers(1, timeout=60)
        with pytest.raises(ClusterError, match="scheduler at .* cannot load addon.core.*No module named 'addon'"):
            solve(scene, paths=1000, cluster=address)
    finally:
        for process in (worker, scheduler):
            process.kill()
            process.wait(timeout=30)


MALFORMED = ["garbage", "http://127.0.0.1:8786", "inproc://127.0.0.1/1/1", "tcp://127.0.0.1:", "tcp://:8786",
             "tcp://127.0.0.1:0", "tcp://127.0.0.1:65536", "ws://127.0.0.1:8786", "tcp://127.0.0.1:8786/x", "",
             "tcp://127.0.0.1 :8786"]


@pytest.mark.parametrize("address", MALFORMED)
def test_a_malformed_address_is_one_line_and_no_connection_is_tried(scene, address, monkeypatch):
    tried = []
    monkeypatch.setattr(socket, "create_connection", lambda *a, **k: tried.append(a))
    monkeypatch.setattr(distributed, "Client", lambda *a, **k: tried.append(a))
    with pytest.raises(ClusterError, match=r"tcp://HOST:PORT|between 1 and 65535") as error:
        solve(scene, paths=1000, cluster=address)
    assert "\n" not in str(error.value) and not tried


@pytest.mark.parametrize("address", ["localhost:8786", "tcp://scheduler.example.org:8786", "TLS://10.0.0.1:1",
                                     "tls://[::1]:8786", " tcp://127.0.0.1:8786 "])
def test_the_address_forms_dask_takes_are_kept(address):
    from addon.core.distributed.cluster_connect import cluster_address

    scheme = "tls" if address.strip().lower().startswith("tls") else "tcp"
    assert cluster_address(address) == f"{scheme}://" + address.strip().split("://")[-1]


class _Server:
    """A TCP service on 127.0.0.1 that is not Dask's: on each connection, ``greeting`` (sent at
    once), then silence until the client leaves."""

    def __init__(self, greeting):
        self.greeting = greeting
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        self.connections = []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                connection, _ = self.sock.accept()
            except OSError:
                return
            self.connections.append(connection)
            connection.sendall(self.greeting)

    def close(self):
        self.sock.close()
        for connection in self.connections:
            connection.close()


# An HTTP server's reply (its first 8 bytes, read as Dask's frame size, are 3.07 EiB), an SSH
# server's greeting, bytes that are no frame size at all, and silence.
GREETINGS = [b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n", b"SSH-2.0-OpenSSH_9.6\r\n", b"\xff" * 64, b""]


@pytest.mark.parametrize("greeting", GREETINGS)
def test_a_service_that_is_not_dask_is_one_line_within_the_timeout(scene, greeting, monkeypatch):
    from addon.core.distributed import cluster_connect

    monkeypatch.setattr(cluster_connect, "CONNECT_SECONDS", 2)  # (the silent one waits it out)
    server = _Server(greeting)
    try:
        started = time.monotonic()
        with pytest.raises(ClusterError, match="not answer as a Dask scheduler|no Dask handshake") as error:
            solve(scene, paths=1000, cluster=server.address)
        assert time.monotonic() - started < 2 + 3  # the timeout, and the scene's own checks
        assert "\n" not in str(error.value) and server.address in str(error.value)
    finally:
        server.close()


def _openssl(*arguments, cwd):
    subprocess.run(["openssl", *arguments], cwd=cwd, check=True, capture_output=True, timeout=60)


def _certificates(folder, name):
    """A CA and a certificate it signs (key included) for 127.0.0.1: (ca file, cert file, key file)."""
    folder.mkdir()
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    _openssl("req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj", f"/CN={name} CA",
             "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign",
             cwd=folder)
    _openssl("req", *ec, "-keyout", "key.pem", "-out", "request.csr", "-subj", "/CN=127.0.0.1", cwd=folder)
    (folder / "extensions.cnf").write_text("basicConstraints=CA:FALSE\nsubjectAltName=IP:127.0.0.1\n"
                                           "subjectKeyIdentifier=hash\nauthorityKeyIdentifier=keyid\n")
    _openssl("x509", "-req", "-in", "request.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
             "-out", "cert.pem", "-days", "2", "-extfile", "extensions.cnf", cwd=folder)
    return str(folder / "ca.pem"), str(folder / "cert.pem"), str(folder / "key.pem")


def _tls_settings(ca, cert, key):
    return {"distributed.comm.tls.ca-file": ca, "distributed.comm.tls.client.cert": cert,
            "distributed.comm.tls.client.key": key}


@pytest.fixture(scope="module")
def tls_cluster(tmp_path_factory):
    """A LocalCluster that requires TLS (one worker process), and the certificates: this CA's, and
    another CA's that it does not trust."""
    if shutil.which("openssl") is None:
        pytest.skip("the TLS tests make their certificates with the openssl command, not found here")
    from distributed.security import Security

    root = tmp_path_factory.mktemp("tls")
    ca, cert, key = _certificates(root / "cluster", "cluster")
    other = _certificates(root / "other", "other")
    os.environ["PYTHONPATH"] = os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    security = Security(tls_ca_file=ca, tls_scheduler_cert=cert, tls_scheduler_key=key, tls_worker_cert=cert,
                        tls_worker_key=key, tls_client_cert=cert, tls_client_key=key, require_encryption=True)
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, protocol="tls",
                                       host="127.0.0.1", security=security, dashboard_address=None, silence_logs=50)
    yield cluster.scheduler_address, (ca, cert, key), other
    cluster.close()


def test_a_tls_cluster_solve_is_bitwise_the_local_one(tls_cluster, scene):
    """The certificates come from Dask's configuration (as from its files or DASK_* variables)."""
    address, mine, _ = tls_cluster
    assert address.startswith("tls://127.0.0.1:")
    local = solve(scene, paths=30_000, seed=4, threads=1)
    with dask.config.set(_tls_settings(*mine)):
        remote = solve(scene, paths=30_000, seed=4, cluster=address)
    assert np.array_equal(local.radiosity, remote.radiosity) and local.rays == remote.rays


def test_a_plain_address_to_a_tls_scheduler_is_one_line(tls_cluster, scene):
    address, _, _ = tls_cluster
    plain = address.replace("tls://", "tcp://")
    started = time.monotonic()
    with pytest.raises(ClusterError, match="TLS.*its address starts tls://|speaks TLS: use tls://") as error:
        solve(scene, paths=1000, cluster=plain)
    assert "\n" not in str(error.value) and time.monotonic() - started < 10


def test_tls_without_certificates_names_the_settings(tls_cluster, scene):
    address, _, _ = tls_cluster
    with dask.config.set(_tls_settings(None, None, None)):
        with pytest.raises(ClusterError, match="distributed.comm.tls.ca-file.*DASK_DISTRIBUTED__COMM__TLS__CA_FILE"):
            solve(scene, paths=1000, cluster=address)


def test_a_certificate_of_another_ca_is_refused_in_one_line(tls_cluster, scene):
    """The scheduler is authenticated by the CA: a client trusting another CA refuses it (and the
    scheduler refuses the client's certificate), before anything is unpickled."""
    address, _, other = tls_cluster
    started = time.monotonic()
    with dask.config.set(_tls_settings(*other)):
        with pytest.raises(ClusterError, match="TLS handshake with .* failed.*not of the CA") as error:
            solve(scene, paths=1000, cluster=address)
    assert "\n" not in str(error.value) and time.monotonic() - started < 10


def test_a_client_certificate_the_scheduler_does_not_trust_is_one_line(tls_cluster, scene):
    """The right CA, but this client's certificate is of another CA: the scheduler refuses it."""
    address, (ca, _, _), (_, cert, key) = tls_cluster
    started = time.monotonic()
    with dask.config.set(_tls_settings(ca, cert, key)):
        with pytest.raises(ClusterError, match="TLS (handshake|connection) .* failed.*refuses this client") as error:
            solve(scene, paths=1000, cluster=address)
    assert "\n" not in str(error.value) and time.monotonic() - started < 10


def test_a_tls_address_to_a_plain_scheduler_is_one_line(tls_cluster, client, scene):
    _, mine, _ = tls_cluster
    address = client.scheduler.address.replace("tcp://", "tls://")
    with dask.config.set(_tls_settings(*mine)):
        with pytest.raises(ClusterError, match="TLS handshake with .* failed.*no TLS there") as error:
            solve(scene, paths=1000, cluster=address)
    assert "\n" not in str(error.value)


def test_a_missing_certificate_file_is_named(tls_cluster, scene):
    address, (ca, cert, key), _ = tls_cluster
    with dask.config.set(_tls_settings(ca, cert + ".missing", key)):
        with pytest.raises(ClusterError, match=r"cert\.pem\.missing' named by distributed\.comm\.tls\.client\.cert"):
            solve(scene, paths=1000, cluster=address)


@pytest.mark.parametrize("method", ["walk", "two_way"])
def test_a_cluster_solve_on_adaptive_patches_is_bitwise_the_local_one(client, method):
    """Patches refined where a lamp's direct light changes (core.adaptive): the cluster's solve
    of the refined scene is bit for bit the local one."""
    from addon.core.mesh import meshing
    from addon.core.refine.adaptive_light import DETAILS, refine_by_direct_light
    from addon.core.lights.lights import PointLight

    corners = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]], float)
    faces = [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]]
    mesh = meshing.mesh_patches(corners, [4] * 6, sum(faces, []), 0.5)
    lamp = [PointLight(np.array([1.0, 1.0, 0.8]), np.full(3, 0.5))]
    P = mesh.patch_count
    first = PatchScene(mesh.points, mesh.triangles, mesh.triangle_patch, np.full((P, 3), 0.6), np.zeros((P, 3)), lights=lamp)
    refined = refine_by_direct_light([mesh], first, DETAILS["MEDIUM"], seed=2).meshes[0]
    assert refined.patch_count > P and (np.asarray(refined.face_sizes) > 4).any()  # (split, T-junctions resolved)
    Q = refined.patch_count
    scene = PatchScene(refined.points, refined.triangles, refined.triangle_patch, np.full((Q, 3), 0.6), np.zeros((Q, 3)),
                       lights=lamp)
    kw = dict(paths=40_000, seed=9, method=method, direct_light=GATHERED if method == "walk" else None, exit_point=EXIT_HIT)
    local, remote = solve(scene, estimator=FINITE, threads=2, **kw), solve(scene, estimator=FINITE, cluster=client, **kw)
    assert np.array_equal(local.radiosity, remote.radiosity)
    assert np.array_equal(local.reflected_variance, remote.reflected_variance, equal_nan=True)
