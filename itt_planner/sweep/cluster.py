"""The Ray session of a sweep: a private local instance on 127.0.0.1, or an existing cluster.

Local (no address): `ray.init(address="local")` starts a fresh instance that lives as long
as the command (never one that happens to run on the machine already) with
`num_cpus` = the workers asked for, no dashboard, and every Ray process on the loopback
interface. Ray 2.60 makes that last part non-obvious: it rewrites the node address
"127.0.0.1" to the machine's outward IP (`services.resolve_ip_for_localhost`), and a node
with an outward IP has its GCS, raylet and worker gRPC servers listen on every
interface. Ray's own switch for single-machine use, the environment variable
`RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`, keeps 127.0.0.1 (then they listen on loopback
only); it is read when Ray is imported, so it is set before the import, and in a
process that imported Ray earlier its module constant is set too. The session then
checks that every node really is on 127.0.0.1 and refuses to run otherwise.

Cluster (`address`): `ray.init(address=...)` joins it and leaves it running. An address on
127.0.0.1 (a cluster started with `ray start --node-ip-address=127.0.0.1`) gets the same
loopback treatment, or Ray would look for it on the outward IP.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from itt_planner.errors import IttError

log = logging.getLogger(__name__)

LOOPBACK = "127.0.0.1"
_LOOPBACK_NAMES = ("127.0.0.1", "localhost")
#: Ray's switch that keeps 127.0.0.1 as the node address (module docstring).
_LOOPBACK_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"


class RayClusterError(IttError):
    """Ray could not be started or joined, or did not bind where it must."""


@dataclass(frozen=True)
class RaySession:
    """What the sweep runs on: address, whether we started it, nodes and CPUs."""

    address: str
    local: bool
    nodes: tuple[str, ...]
    cpus: int


def is_loopback(address: str) -> bool:
    """True for `127.0.0.1:PORT`, `localhost:PORT` (and the bare hosts)."""
    return address.rsplit(":", 1)[0] in _LOOPBACK_NAMES


def _keep_loopback() -> None:
    """Make Ray keep 127.0.0.1 as the node address in this process and its children."""
    os.environ[_LOOPBACK_ENV] = "0"
    constants = sys.modules.get("ray._private.ray_constants")
    if constants is not None:
        # Ray read the variable at import, before we could set it; its own code reads the
        # constant at call time, so setting it has the effect the variable would have had.
        constants.ENABLE_RAY_CLUSTER = False  # type: ignore[attr-defined]  # Ray's private module


@contextmanager
def ray_session(address: str | None = None, workers: int | None = None) -> Iterator[RaySession]:
    """Start (no `address`) or join a Ray cluster for the duration of the block.

    Raises:
        RayClusterError: Ray failed to start or connect, or a local node is not on 127.0.0.1.
    """
    local = address is None
    if address is None or is_loopback(address):
        _keep_loopback()
    import ray  # noqa: PLC0415 - the environment above must be set first

    if ray.is_initialized():
        raise RayClusterError("Ray is already initialised in this process: one sweep at a time")
    kwargs: dict[str, Any] = {"log_to_driver": False, "configure_logging": False}
    try:
        if address is None:
            ray.init(address="local", _node_ip_address=LOOPBACK, include_dashboard=False,
                     num_cpus=workers or os.cpu_count() or 1, **kwargs)
        else:
            if is_loopback(address):
                kwargs["_node_ip_address"] = LOOPBACK
            ray.init(address=address, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as err:
        where = "a local Ray instance" if local else f"the Ray cluster at {address}"
        raise RayClusterError(f"could not start or join {where}: {err}") from None
    try:
        nodes = [n for n in ray.nodes() if n.get("Alive")]
        addresses = tuple(sorted({str(n["NodeManagerAddress"]) for n in nodes}))
        if local and addresses != (LOOPBACK,):
            raise RayClusterError(f"the local Ray instance is on {', '.join(addresses)}, "
                                  f"not only {LOOPBACK}: refusing to run")
        session = RaySession(address=ray.get_runtime_context().gcs_address, local=local,
                             nodes=tuple(n["NodeID"] for n in nodes),
                             cpus=int(ray.cluster_resources().get("CPU", 0)))
        log.info("Ray %s at %s: %d node(s), %d CPU(s)", "started" if local else "joined",
                 session.address, len(session.nodes), session.cpus)
        yield session
    finally:
        ray.shutdown()
