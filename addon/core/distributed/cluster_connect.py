"""Connecting to a Dask cluster: its address checked, its scheduler probed, its workers asked.

Dask's messages are pickles: a scheduler can run code in this process, so the cluster is trusted
like this machine. A ``tls://`` address authenticates it by the cluster's CA (Dask's configuration);
the address's form is checked, and the scheduler's first message read without pickle and with a size
limit, before Dask's client connects. Dask's ``distributed`` is optional: imported only when a
cluster is asked for.
"""
from __future__ import annotations

import os
import pickle
import re
import socket
import ssl
import struct
import sys
import time

INSTALL = "pip install 'dask[distributed]' (or pip install '.[distributed]' in the repository)"
CONNECT_SECONDS = 10
# A Dask scheduler's first message (its handshake) is about 60 bytes: far more is another service.
HANDSHAKE_LIMIT = 1 << 16
ADDRESS_FORMS = "tcp://HOST:PORT, or tls://HOST:PORT with the cluster's certificates"
TLS_SETTINGS = ("Dask's configuration distributed.comm.tls.ca-file, .client.cert and .client.key (environment: "
                "DASK_DISTRIBUTED__COMM__TLS__CA_FILE, DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT and "
                "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY)")
_ADDRESS = re.compile(r"(?:(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://)?"
                      r"(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_](?:[A-Za-z0-9_.-]*[A-Za-z0-9_])?):(?P<port>[0-9]{1,5})")




class ClusterError(ValueError):
    """A cluster the solve cannot use (Dask missing, a malformed address, a scheduler that cannot
    be reached or is not Dask's, workers without the core): said in one line, nothing run."""


def cluster_address(text):
    """``text`` as ``tcp://host:port`` or ``tls://host:port`` (a bare ``host:port`` is tcp), or
    ClusterError saying which forms are accepted; no connection is tried."""
    if not isinstance(text, str):
        raise ClusterError(f"the cluster must be a Dask scheduler's address ({ADDRESS_FORMS}); got {text!r}")
    match = _ADDRESS.fullmatch(text.strip())
    scheme = (match.group("scheme") or "tcp").lower() if match else None
    if match is None or scheme not in ("tcp", "tls"):
        raise ClusterError(f"the cluster address must be {ADDRESS_FORMS}; got {text!r}")
    port = int(match.group("port"))
    if not 1 <= port <= 65535:
        raise ClusterError(f"the cluster address's port must be between 1 and 65535; got {text!r}")
    return f"{scheme}://{match.group('host')}:{port}"


def connect(cluster):
    """A ``distributed.Client`` for ``cluster`` (a Client, or a scheduler address), and whether it
    was made here (to be closed after the solve): one line (ClusterError) within CONNECT_SECONDS
    (and a second or two) if the address is malformed, Dask missing, the scheduler unreachable, not
    Dask's or refusing the certificates, or its workers lack the core."""
    try:
        import distributed
    except ImportError as exc:
        raise ClusterError(f"solve(cluster=...) needs Dask's distributed package: {INSTALL}") from exc
    deadline = time.monotonic() + CONNECT_SECONDS
    if isinstance(cluster, distributed.Client):
        client, made = cluster, False
    elif isinstance(cluster, str):
        address = cluster_address(cluster)
        security = _security(address)
        context = security.get_connection_args("client")["ssl_context"] if address.startswith("tls") else None
        _probe(address, context, deadline)
        try:
            client = distributed.Client(address, timeout=max(1.0, deadline - time.monotonic()), security=security,
                                        set_as_default=False)
        except Exception as exc:  # noqa: BLE001 - any failure to connect is the one line
            raise ClusterError(f"cannot connect to the Dask scheduler at {address!r} ({_one_line(exc)})") from exc
        made = True
    else:
        raise ClusterError(f"cluster must be a dask.distributed.Client or a scheduler address; got {cluster!r}")
    try:
        _check_workers(client, deadline)
    except BaseException:
        if made:
            client.close(timeout=CONNECT_SECONDS)
        raise
    return client, made


def _check_workers(client, deadline):
    """ClusterError unless the scheduler can load the core (it unpickles the tasks' arguments)
    and the cluster has workers that can all run the walks."""
    try:
        client.run_on_scheduler(_loaded, callback_timeout=max(1.0, deadline - time.monotonic()))
    except Exception as exc:  # noqa: BLE001 - the scheduler could not load this function, or is silent
        raise ClusterError(f"the Dask scheduler at {client.scheduler.address} cannot load addon.core "
                           f"({_one_line(exc)}); start it with the repository on PYTHONPATH, as the workers") from exc
    try:
        workers = client.run(_worker_check, on_error="return", callback_timeout=max(1.0, deadline - time.monotonic()))
    except Exception as exc:  # noqa: BLE001 - a scheduler that does not answer in time
        raise ClusterError(f"the Dask cluster at {client.scheduler.address} did not answer ({_one_line(exc)})") from exc
    if not workers:
        raise ClusterError(f"the Dask cluster at {client.scheduler.address} has no workers")
    missing = {address: problem if isinstance(problem, str) else _one_line(problem)
               for address, problem in workers.items() if problem}
    if missing:
        address, problem = next(iter(missing.items()))
        raise ClusterError(f"{len(missing)} of the cluster's {len(workers)} workers cannot run the walks "
                           f"(e.g. {address}: {problem}); they need numpy, embreex and addon.core importable")


def _loaded():
    """Nothing: that it runs on the scheduler shows addon.core loads there."""
    return ""


def _worker_check():
    """'' if this worker can run walks, else what is missing (a worker without addon.core fails
    to load this function: the client gets that error instead)."""
    try:
        import embreex  # noqa: F401
    except Exception as exc:  # noqa: BLE001 - reported to the client
        return _one_line(exc)
    return ""


def _one_line(exc):
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _security(address):
    """Dask's Security from its configuration (files or DASK_* variables), checked against the
    address: tls:// needs the CA and the client's certificate and key; tcp:// must not be
    refused by the configuration."""
    from distributed.security import Security

    try:
        security = Security()
    except Exception as exc:  # noqa: BLE001 - a malformed setting
        raise ClusterError(f"Dask's TLS configuration is not usable ({_one_line(exc)})") from exc
    if address.startswith("tls://"):
        if not (security.tls_ca_file and security.tls_client_cert):
            raise ClusterError(f"a tls:// cluster needs the cluster's CA and this client's certificate and key in {TLS_SETTINGS}")
        for key, path in (("ca-file", security.tls_ca_file), ("client.cert", security.tls_client_cert),
                          ("client.key", security.tls_client_key)):
            if path and "\n" not in path and not os.path.isfile(path):  # (a setting may hold the PEM text)
                raise ClusterError(f"the file {path!r} named by distributed.comm.tls.{key} does not exist")
        try:
            security.get_connection_args("client")
        except Exception as exc:  # noqa: BLE001 - missing or unreadable files
            raise ClusterError(f"cannot load the cluster's certificates from {TLS_SETTINGS} ({_one_line(exc)})") from exc
    elif security.require_encryption:
        raise ClusterError(f"Dask's configuration requires encryption (distributed.comm.require-encryption): "
                           f"use a tls:// address, not {address!r}")
    return security


def _probe(address, ssl_context, deadline):
    """ClusterError unless a Dask scheduler answers at ``address`` before ``deadline``: one
    handshake each way with no pickle (the scheduler's first message, read with a size limit), so
    that another service, a TLS mismatch or silence is one line instead of Dask reading whatever
    comes as frames of any size."""
    scheme, rest = address.split("://")
    host, port = rest.rsplit(":", 1)
    host = host.strip("[]")
    try:
        sock = socket.create_connection((host, int(port)), timeout=max(0.1, deadline - time.monotonic()))
    except socket.gaierror as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {address!r} (unknown host {host!r})") from exc
    except OSError as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {address!r} ({_one_line(exc)})") from exc
    try:
        if ssl_context is not None:
            try:
                sock.settimeout(max(0.1, deadline - time.monotonic()))
                sock = ssl_context.wrap_socket(sock)
            except ssl.SSLError as exc:
                raise ClusterError(f"the TLS handshake with {address!r} failed ({exc.reason or _one_line(exc)}): "
                                   f"{_tls_hint(exc)}") from exc
        _send(sock, _handshake(), deadline)
        first = _receive(sock, 8, deadline)
        if ssl_context is None and len(first) >= 2 and first[0] in (0x15, 0x16) and first[1] == 3:
            raise ClusterError(f"the scheduler at {address!r} speaks TLS: use tls://{rest} with {TLS_SETTINGS}")
        if len(first) < 8:
            hint = "" if ssl_context else " (a scheduler with TLS? its address starts tls://)"
            raise ClusterError(f"{address!r} closed the connection without Dask's handshake{hint}")
        (size,) = struct.unpack("<Q", first)
        message = _receive(sock, size, deadline) if 16 <= size <= HANDSHAKE_LIMIT else b""
        if not _is_dask_handshake(message):
            raise ClusterError(f"{address!r} does not answer as a Dask scheduler (another service there?)")
    except (socket.timeout, TimeoutError) as exc:
        hint = "" if ssl_context else " (a scheduler with TLS? its address starts tls://)"
        raise ClusterError(f"no Dask handshake from {address!r} within {CONNECT_SECONDS} s{hint}") from exc
    except ssl.SSLError as exc:  # (with TLS 1.3 the scheduler refuses a certificate after the handshake)
        raise ClusterError(f"the TLS connection to {address!r} failed ({exc.reason or _one_line(exc)}): "
                           f"{_tls_hint(exc)}") from exc
    except OSError as exc:  # (a TLS server resets a connection that does not start with TLS)
        hint = "" if ssl_context else " (a scheduler with TLS? its address starts tls://)"
        raise ClusterError(f"the connection to {address!r} failed ({_one_line(exc)}){hint}") from exc
    finally:
        sock.close()


def _tls_hint(exc):
    """What a failed TLS handshake most likely means, in words."""
    if exc.reason in ("WRONG_VERSION_NUMBER", "RECORD_LAYER_FAILURE", "PACKET_LENGTH_TOO_LONG", "HTTP_REQUEST"):
        return "no TLS there (a scheduler without TLS has a tcp:// address)"
    return ("the scheduler's certificate is not of the CA in distributed.comm.tls.ca-file, or it refuses this "
            "client's certificate")


def _handshake():
    """What Dask's comms send first: one msgpack frame behind its size and the frame count."""
    import msgpack

    info = msgpack.packb({"compression": None, "python": tuple(sys.version_info[:3]),
                          "pickle-protocol": pickle.HIGHEST_PROTOCOL}, use_bin_type=True)
    return struct.pack("<QQQ", 16 + len(info), 1, len(info)) + info



def _send(sock, data, deadline):
    sock.settimeout(max(0.1, deadline - time.monotonic()))
    sock.sendall(data)


def _receive(sock, size, deadline):
    """Up to ``size`` bytes (fewer: the peer closed), each wait bounded by ``deadline``."""
    data = bytearray()
    while len(data) < size:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError
        sock.settimeout(remaining)
        part = sock.recv(min(size - len(data), 1 << 16))
        if not part:
            break
        data += part
    return bytes(data)


def _is_dask_handshake(message):
    """Whether ``message`` (frame count, frame sizes, frames) holds Dask's handshake: a map with
    the pickle protocol and Python version (read by msgpack alone: nothing is run)."""
    import msgpack

    if len(message) < 16:
        return False
    (count,) = struct.unpack_from("<Q", message)
    if not 1 <= count <= 16 or len(message) < 8 * (1 + count):
        return False
    sizes = struct.unpack_from(f"<{count}Q", message, 8)
    start = 8 * (1 + count)
    if start + sizes[0] > len(message):
        return False
    try:
        info = msgpack.unpackb(message[start:start + sizes[0]], raw=False, strict_map_key=False)
    except Exception:  # noqa: BLE001 - not msgpack: not Dask
        return False
    return isinstance(info, dict) and "pickle-protocol" in info and "python" in info
