"""Running a campaign's runs on Dask distributed (or in this process), doc/campaigns.md.

A campaign (:mod:`rcac_ros.tools.sweep.campaign`) runs on a Dask ``LocalCluster`` (one
single-threaded worker process per core) or on the cluster of ``--scheduler``;
``--workers 0`` runs in this process, without Dask. Runs go in chunks, one task
each; every worker loads the numba kernels and the campaign's model once, through
a worker plugin. Each finished chunk is written at once to the results directory
(:mod:`rcac_ros.tools.sweep.store`), so that an interrupted campaign keeps its runs and
``--resume`` runs none twice.
"""

import logging
import math
import os
import signal
import socket
import sys
import uuid

from rcac_ros.errors import ConfigError
from rcac_ros.tools.sweep import campaign as cp

#: s a TCP connection to ``--scheduler`` may take before the address is refused
CONNECT_TIMEOUT = 3.0


def run_chunk(campaign, indices):
    """A task: the rows of some runs (on a worker, or here)."""
    return [cp.simulate(campaign, i) for i in indices]


try:
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError:                                  # pragma: no cover - dask is required
    WorkerPlugin = object


class WarmUp(WorkerPlugin):
    """Worker plugin: load the numba kernels and the campaign's model once per worker."""

    def __init__(self, campaign):
        self.campaign = campaign

    def setup(self, worker):
        cp.warm_up()
        run_chunk(cp.with_overrides(self.campaign, duration=0.01), [0])


class DeferredInterrupt:
    """Ctrl-C inside ``with guard:`` waits for the block's end (a numba kernel must not be
    interrupted half-way: it would surface as a SystemError); a second Ctrl-C, or one
    outside the block, interrupts at once."""

    def __init__(self):
        self.inside = self.requested = False
        self.previous = None

    def handler(self, signum, frame):
        if self.inside and not self.requested:
            self.requested = True
            return
        raise KeyboardInterrupt

    def __enter__(self):
        if self.previous is None:                    # the outer use installs the handler
            try:
                self.previous = signal.signal(signal.SIGINT, self.handler)
            except ValueError:                       # not the main thread: nothing to defer
                self.previous = signal.default_int_handler
            return self
        self.inside = True
        return self

    def __exit__(self, *exc):
        if self.inside:
            self.inside = False
            if self.requested and exc[0] is None:
                raise KeyboardInterrupt
            return False
        if signal.getsignal(signal.SIGINT) == self.handler:
            signal.signal(signal.SIGINT, self.previous)
        self.previous = None
        return False


def chunks_of(pending, chunk):
    return [pending[i:i + chunk] for i in range(0, len(pending), chunk)]


def auto_chunk(pending, workers):
    """About 8 tasks per worker (balance, progress), at most 25 runs per task."""
    return max(1, min(25, math.ceil(pending / (8 * max(1, workers)))))


def reachable(scheduler, timeout=CONNECT_TIMEOUT):
    """Raise :class:`ConfigError` at once if the ``tcp://HOST:PORT`` of ``scheduler`` takes no
    TCP connection within ``timeout`` s (Dask's client retries a refused port for its whole
    timeout); other protocols are left to Dask."""
    proto, _, rest = scheduler.partition("://")
    if proto != "tcp":
        return
    host, _, port = rest.rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as err:
        raise ConfigError(f"--scheduler: cannot connect to {scheduler} "
                          f"({err.strerror or err})") from None


def start_client(workers=None, scheduler=None, dashboard=":8787"):
    """A Dask client: on ``scheduler``'s cluster, or on a new LocalCluster."""
    from distributed import Client, LocalCluster
    if scheduler is not None:
        try:
            return Client(scheduler, timeout="10s")
        except OSError as err:
            raise ConfigError(f"--scheduler: cannot connect to {scheduler} ({err})") from None
    cluster = LocalCluster(n_workers=workers or os.cpu_count(), threads_per_worker=1,
                           processes=True, dashboard_address=dashboard,
                           silence_logs=logging.WARNING)
    return Client(cluster)


def close_client(client):
    cluster = client.cluster
    client.close()
    if cluster is not None:
        # the in-process scheduler logs its shutdown at INFO: not the user's business
        logging.getLogger("distributed").setLevel(logging.WARNING)
        cluster.close()


def execute(campaign, store, workers=None, scheduler=None, chunk=None, progress=True,
            client=None):
    """Run every run of ``campaign`` not yet in ``store``; return how many ran.

    ``workers=0`` runs in this process (no Dask); otherwise on ``client``, or on a
    client this call starts (and closes).
    """
    from tqdm import tqdm
    pending = sorted(set(range(cp.run_count(campaign))) - store.done())
    if not pending:
        return 0
    serial = workers == 0 and client is None and scheduler is None
    own = client is None and not serial
    bar = None
    try:
        if own:
            client = start_client(workers, scheduler)
        if not serial:
            nworkers = len(client.scheduler_info(n_workers=-1)["workers"]) or 1
            if progress:
                print(f"Dask dashboard: {client.dashboard_link} ({nworkers} workers); "
                      f"{len(pending)} runs to go", file=sys.stderr)
        bar = tqdm(total=len(pending), unit="run", disable=not progress, file=sys.stderr,
                   smoothing=0.1, dynamic_ncols=True)
        if serial:
            cp.warm_up()
            with DeferredInterrupt() as guard:
                for indices in chunks_of(pending, chunk or 1):
                    with guard:
                        rows = run_chunk(campaign, indices)
                    store.write(rows)
                    bar.update(len(indices))
        else:
            distribute(client, campaign, store, chunks_of(
                pending, chunk or auto_chunk(len(pending), nworkers)), bar)
        return len(pending)
    except KeyboardInterrupt:
        if bar is not None:
            bar.close()
        kept = len(store.done())
        if kept:
            store.merge()
        print(f"interrupted: {kept} finished runs kept in {store.results}; "
              "--resume continues", file=sys.stderr)
        raise
    finally:
        if bar is not None:
            bar.close()
        if own and client is not None:
            close_client(client)


def distribute(client, campaign, store, chunks, bar):
    """Submit the chunks to ``client`` and write each one as it completes."""
    from distributed import as_completed
    client.register_plugin(WarmUp(campaign), name="rcac-sweep-warm-up")
    token = uuid.uuid4().hex[:12]
    futures = [client.submit(run_chunk, campaign, indices, pure=False,
                             key=f"rcac-sweep-{token}-{indices[0]}-{len(indices)}")
               for indices in chunks]
    for future in as_completed(futures):
        rows = future.result()
        store.write(rows)
        bar.update(len(rows))
        future.release()
