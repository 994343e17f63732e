"""Starting or joining a Ray cluster, with every listener of a local one on the loopback interface.

``connect(address=None)``: without an address, a new local cluster on this machine
(``num_cpus`` CPUs, no dashboard); with one (``"auto"``, ``"HOST:6379"`` from ``ray start
--head``, or a Ray Client ``"ray://HOST:10001"``), joins that cluster. An already initialised
Ray is used as it is.

Localhost only, locally: Ray picks the node's IP address for its servers (GCS, raylet, workers,
agents) and on Linux binds them to the machine's external address or to all interfaces. For a
local cluster we set ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`` before Ray starts: Ray then takes
the loopback address as the node's address (what it does on a laptop), and every server it starts
binds to 127.0.0.1 (checked by ``tests/parallel/test_ray_runner.py``). The variable is set for
this process and inherited by the processes Ray starts; it is not set when joining a cluster at
another machine's address, whose nodes must reach each other.
"""

from __future__ import annotations

import os
from typing import Any

#: The environment variable (Ray's own) that, set to "0", makes the node's address the
#: loopback address (see the module doc).
LOCAL_ONLY_VARIABLE = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


def require_ray():
    """The ``ray`` module, or an ImportError that says how to install it."""
    try:
        import ray
    except ImportError as err:  # pragma: no cover - exercised where ray is missing
        raise ImportError(
            "Ray is an optional dependency of drake-abs: install it with "
            "pip install 'drake-abs[ray]' (or pip install ray)"
        ) from err
    return ray


def connect(
    address: str | None = None, *, num_cpus: int | None = None, quiet: bool = True
) -> dict[str, Any]:
    """Start a local Ray cluster (``address=None``) or join one; returns the cluster's resources
    (``ray.cluster_resources()``).

    Args:
        address: None for a new local cluster bound to 127.0.0.1; ``"auto"`` for the cluster
            ``ray start`` runs on this machine; ``"HOST:PORT"`` (the head's GCS address printed by
            ``ray start --head``) or ``"ray://HOST:10001"`` (Ray Client) for a remote one.
        num_cpus: CPUs of a new local cluster (default: all of this machine's). Not allowed with
            ``address``: a cluster's nodes declare their own.
        quiet: do not forward the workers' log lines to this process's terminal.
    """
    if address is not None and (not isinstance(address, str) or not address.strip()):
        raise ValueError(
            f"address must be None (a local cluster), 'auto', 'HOST:PORT' or 'ray://HOST:PORT'; "
            f"got {address!r}"
        )
    if num_cpus is not None and (isinstance(num_cpus, bool) or int(num_cpus) != num_cpus
                                 or num_cpus < 1):  # fmt: skip
        raise ValueError(f"num_cpus must be a whole number >= 1; got {num_cpus!r}")
    if address is not None and num_cpus is not None:
        raise ValueError("num_cpus is for a local cluster; a joined cluster's nodes declare theirs")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no report leaves this machine
    if address is None or _loopback(address):
        os.environ[LOCAL_ONLY_VARIABLE] = "0"
    ray = require_ray()
    if ray.is_initialized():
        return ray.cluster_resources()
    if address is None or _loopback(address):
        _local_only_in_this_process()
    if address is None:
        ray.init(
            address="local",  # always a new cluster (never one a stale session file names)
            num_cpus=None if num_cpus is None else int(num_cpus),
            include_dashboard=False,
            dashboard_host="127.0.0.1",
            log_to_driver=not quiet,
            configure_logging=True,
            logging_level="WARNING",
        )
    else:
        try:
            ray.init(address=address.strip(), log_to_driver=not quiet, logging_level="WARNING")
        except (ConnectionError, RuntimeError) as err:
            raise ConnectionError(
                f"could not join the Ray cluster at {address!r}: {_first_line(err)}. Check that "
                "'ray start --head' runs there and that this machine reaches it; a cluster with "
                "token authentication (Ray's default for clusters started on one machine) needs "
                "RAY_AUTH_MODE=token and its token (RAY_AUTH_TOKEN, from 'ray get-auth-token' on "
                "the head) in this process's environment"
            ) from err
    return ray.cluster_resources()


def _first_line(err: BaseException) -> str:
    text = str(err).strip()
    causes = [text.splitlines()[0] if text else type(err).__name__]
    cause = err.__cause__
    while cause is not None:  # Ray wraps the reason (e.g. an authentication error)
        causes.append(str(cause).strip().splitlines()[-1] if str(cause).strip() else "")
        cause = cause.__cause__
    return "; ".join(c for c in causes if c)[:400]


def _loopback(address: str) -> bool:
    """Whether a cluster address names this machine's loopback interface (a cluster started
    here with ``ray start --head``): this process then takes 127.0.0.1 as its node address too."""
    host = address.strip().removeprefix("ray://").rsplit(":", 1)[0].strip("[]")
    return host in ("localhost", "::1") or host.startswith("127.")


def _local_only_in_this_process() -> None:
    """Ray reads the variable when it is imported; if it was imported before :func:`connect`
    set it, set Ray's constant too (Ray's address lookup reads the constant at call time)."""
    from ray._private import ray_constants

    ray_constants.ENABLE_RAY_CLUSTER = False


def shutdown() -> None:
    """Stop this process's connection to Ray (and a local cluster it started)."""
    ray = require_ray()
    if ray.is_initialized():
        ray.shutdown()


def cluster_cpus() -> int:
    """The CPUs of the connected cluster (all nodes)."""
    ray = require_ray()
    if not ray.is_initialized():
        raise RuntimeError("Ray is not initialised: call drake_abs.parallel.cluster.connect()")
    return int(ray.cluster_resources().get("CPU", 0))
