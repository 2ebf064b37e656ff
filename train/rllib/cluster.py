"""Starting Ray: a local instance on this machine, or joining an existing cluster.

One machine: with no address, :func:`ray_session` starts a private local Ray
(``ray.init(address="local")``: it never joins a cluster by accident, even with
``RAY_ADDRESS`` set) with ``num_cpus`` CPUs and no dashboard.

A cluster: start Ray on every machine first, then give the head's address::

    ray start --head --port=6379                 # on the head machine
    ray start --address=HEAD_IP:6379             # on every other machine
    swarm-train --engine rllib --config configs/train/demo_rllib.yaml --address HEAD_IP:6379

``--address auto`` joins the cluster that ``ray start`` set up on this machine. Every
machine needs the same Python environment (this project installed with the
``distributed`` extra).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType

from train.rllib import INSTALL_HINT

__all__ = ["check_address", "check_num_cpus", "ray_session", "require_ray"]


def require_ray() -> ModuleType:
    """Import and return :mod:`ray`; :class:`ImportError` with the install hint if absent."""
    try:
        import ray
    except ImportError as err:
        raise ImportError(INSTALL_HINT) from err
    return ray


def check_address(address: str | None) -> str | None:
    """``None`` (start a local Ray) or a non-empty cluster address such as ``HOST:6379``.

    >>> check_address(" 10.0.0.5:6379 ")
    '10.0.0.5:6379'
    >>> check_address("")
    Traceback (most recent call last):
    ...
    ValueError: address must be HOST:PORT, auto, or ray://HOST:PORT; got ''
    """
    if address is None:
        return None
    if not isinstance(address, str) or not address.strip():
        raise ValueError(f"address must be HOST:PORT, auto, or ray://HOST:PORT; got {address!r}")
    return address.strip()


def check_num_cpus(num_cpus: int | None) -> int | None:
    """``None`` (all of this machine's CPUs) or an integer >= 1."""
    if num_cpus is None:
        return None
    if isinstance(num_cpus, bool) or not isinstance(num_cpus, int) or num_cpus < 1:
        raise ValueError(f"num_cpus must be null or an integer >= 1, got {num_cpus!r}")
    return num_cpus


@contextmanager
def ray_session(
    address: str | None = None, *, num_cpus: int | None = None, verbose: bool = True
) -> Iterator[ModuleType]:
    """Ray for the duration of a ``with`` block; yields the :mod:`ray` module.

    Args:
        address: ``None`` starts a private local Ray on this machine; anything else is
            passed to ``ray.init(address=...)`` to join a running cluster
            (``HOST:PORT``, ``auto``, or a Ray Client ``ray://HOST:10001``).
        num_cpus: CPUs of the local Ray (``None``: all of them). A cluster's CPUs are
            those its nodes were started with, so this is ignored with an address.
        verbose: print which Ray was started or joined, and its CPUs.

    If Ray is already initialised in this process (a caller's own ``ray.init``), it is
    used as it is and left running; otherwise the session shuts down what it started.

    Raises:
        ImportError: Ray is not installed.
        ValueError: a bad ``address`` or ``num_cpus``.
    """
    address = check_address(address)
    num_cpus = check_num_cpus(num_cpus)
    ray = require_ray()
    if ray.is_initialized():
        yield ray
        return
    if address is None:
        ray.init(address="local", num_cpus=num_cpus, include_dashboard=False)
    else:
        ray.init(address=address)
    try:
        if verbose:
            cpus = ray.cluster_resources().get("CPU", 0)
            where = "local Ray" if address is None else f"Ray cluster at {address}"
            print(f"{where}: {len(ray.nodes())} node(s), {cpus:g} CPUs")
        yield ray
    finally:
        ray.shutdown()
