"""Per-photo work and the compression on Dask: local processes or a ``dask.distributed`` cluster.

One machine: :func:`open_client` starts a :class:`distributed.LocalCluster` of ``workers``
processes (one thread each). Many machines: ``scheduler='tcp://HOST:PORT'`` connects to a
running cluster (``dask scheduler`` on one machine, ``dask worker tcp://HOST:PORT`` on each of
the others; docs/scale.md). Workers read the photos and write the store themselves, so every
worker must see the capture folder and the store at the same path (a shared file system).

:class:`DaskRunner` is the runner the store's tasks take (:mod:`ffls.store.ingest`,
:mod:`ffls.relight.stream`): ``map(fn, items, desc)`` submits one task per item, shows a tqdm bar
that advances as the cluster finishes them (``as_completed``), and returns the results in order.
:mod:`ffls.cluster.lights` runs the light estimation's per-photo work the same way.
"""
from __future__ import annotations

import contextlib
import os
import sys

from ffls.errors import InputError

__all__ = ["DaskRunner", "open_client", "default_workers"]


def default_workers() -> int:
    """Local worker processes by default: every core."""
    return max(1, os.cpu_count() or 1)


class DaskRunner:
    """Maps tasks on a ``distributed.Client``, with progress from the cluster.

    Parameters
    ----------
    client : distributed.Client
    progress : bool
        A tqdm bar on stderr (not when stderr is not a terminal, or ``CI`` is set).
    """

    def __init__(self, client, progress: bool = True):
        self.client = client
        self.progress = progress

    @property
    def n_workers(self) -> int:
        """Workers connected now (at least 1)."""
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def map(self, fn, items, desc: str = "") -> list:
        """``[fn(x) for x in items]`` on the cluster, in order; the first task error is raised here."""
        from distributed import as_completed
        from tqdm import tqdm

        items = list(items)
        if not items:
            return []
        futures = self.client.map(fn, items, pure=False)
        disable = not self.progress or not sys.stderr.isatty() or bool(os.environ.get("CI"))
        try:
            with tqdm(total=len(futures), desc=desc, unit="task", disable=disable, leave=False) as bar:
                for fut in as_completed(futures):
                    if fut.status == "error":
                        fut.result()  # raises the task's exception (an InputError keeps its one line)
                    bar.update(1)
            return self.client.gather(futures)
        finally:
            for fut in futures:
                fut.release()


def check_scheduler_address(text: str) -> str:
    """``text`` if it is a dask.distributed scheduler address ``SCHEME://HOST:PORT``, else ValueError.

    The address is parsed by distributed itself (``parse_address``, ``parse_host_port``); the
    scheme must be one distributed can open (``registry.backends``: tcp, tls, ws, ...), the host
    must be named and the port must lie in 1..65535. Nothing is connected.
    """
    from distributed.comm import registry
    from distributed.comm.addressing import parse_address, parse_host_port

    text = str(text).strip()
    scheme, location = parse_address(text)  # ValueError on a malformed address
    if scheme not in registry.backends or scheme == "inproc":
        raise ValueError(f"unknown scheme {scheme!r} in {text!r} (expected one of "
                         f"{', '.join(sorted(b for b in registry.backends if b != 'inproc'))})")
    host, port = parse_host_port(location)  # ValueError without a port
    if not host:
        raise ValueError(f"no host in {text!r} (expected SCHEME://HOST:PORT)")
    if not 1 <= int(port) <= 65535:
        raise ValueError(f"port {port} in {text!r} is not in 1..65535")
    return text


def _quiet_cluster_atexit() -> None:
    """Make distributed's exit hook, which closes the local clusters still open, quiet.

    A Ctrl-C while ``LocalCluster`` starts leaves a cluster whose workers never left their
    ``init`` state; at exit the hook's ``cluster.close`` then fails an assertion and Python printed
    "Exception ignored in atexit callback" and a 25-line traceback after ffls's one line. The hook
    is registered again with its errors suppressed (once per process): the worker processes are
    daemonic, and multiprocessing's own exit hook ends them.
    """
    import atexit

    from distributed.deploy import spec

    if _QUIET_HOOKS:
        return
    hook = spec.close_clusters

    def close_clusters():
        with contextlib.suppress(Exception):
            hook()

    atexit.unregister(hook)
    atexit.register(close_clusters)
    _QUIET_HOOKS.append(close_clusters)


#: The quiet exit hook of :func:`_quiet_cluster_atexit`, once installed.
_QUIET_HOOKS: list = []


@contextlib.contextmanager
def open_client(workers: int | None = None, scheduler: str | None = None, progress: bool = True):
    """A :class:`DaskRunner` on a local cluster of ``workers`` processes, or on the cluster at ``scheduler``.

    Parameters
    ----------
    workers : int, optional
        Local worker processes (one thread each); default :func:`default_workers`.
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running scheduler; ``workers`` is then ignored.

    Raises
    ------
    InputError
        The scheduler cannot be reached (one line naming it).
    """
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as e:
            raise InputError(f"cannot reach the Dask scheduler {scheduler}: {e}") from None
        try:
            yield DaskRunner(client, progress)
        finally:
            client.close()
        return
    n = default_workers() if workers is None else max(1, int(workers))
    _quiet_cluster_atexit()
    # no dashboard, and the scheduler's HTTP routes on a free port: with its default (8787) a second
    # cluster on the machine (another ffls run, a notebook) made distributed warn "Port 8787 is
    # already in use", a library's warning line
    # (Ctrl-C while it starts leaves unfinished start-up tasks that asyncio logs at exit: the CLI
    # silences that logger on an interrupt, ffls.cli.main)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
                           silence_logs=logging.CRITICAL)
    try:
        client = Client(cluster)
        try:
            yield DaskRunner(client, progress)
        finally:
            client.close()
    finally:
        cluster.close()
