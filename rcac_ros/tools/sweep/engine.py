"""``rcac sweep``: Monte Carlo campaigns of closed-loop runs on Dask distributed.

Three forms::

    rcac sweep CAMPAIGN --out DIR [--samples N] [--duration S] [--workers K]
               [--scheduler tcp://HOST:PORT] [--chunk C] [--resume]
    rcac sweep report RESULTS [--worst N] [--plot PNG]
    rcac sweep rerun RESULTS INDEX [--plot PNG]
    rcac sweep --bench [CAMPAIGN] [--samples N] [--duration S] [--out DIR]

A campaign (:mod:`rcac_ros.tools.sweep.campaign`) runs on a Dask ``LocalCluster`` (one
single-threaded worker process per core) or on the cluster of ``--scheduler``;
``--workers 0`` runs in this process, without Dask. Runs go in chunks, one task
each; every worker loads the numba kernels and the campaign's model once, through
a worker plugin. Each finished chunk is written at once as a Parquet part file
(``DIR/parts/``); at the end (or on Ctrl-C) the parts are merged into
``DIR/results.parquet``, one row per run, sorted by ``run``. ``--resume`` skips
every run already in the results or the parts, so nothing is run twice.
"""

import argparse
import glob
import json
import logging
import math
import os
import signal
import sys
import tempfile
import time
import uuid

import numpy as np

from rcac_ros.errors import ConfigError
from rcac_ros.tools.sweep import campaign as cp
from rcac_ros.tools.args import non_negative_int, positive_float, positive_int

ACTIONS = ("report", "rerun")
METRICS = ("rms_tracking_error", "max_tracking_error", "rms_tracking_error_last_5s",
           "parameter_error_norm_end", "final_abs_prediction_error", "max_abs_torque",
           "max_effort_ratio")
#: The campaign --bench runs when none is given: the paper's arm, 5-s runs, gains spread.
BENCH_CAMPAIGN = {
    "name": "bench", "seed": 1, "samples": 60,
    "scenario": {"model": "css_arm", "law": "composite", "duration": 5.0},
    "vary": {"K_D": {"uniform": {"low": 5e3, "high": 2e4}},
             "P": {"loguniform": {"low": 10.0, "high": 1000.0}},
             "noise_q": {"uniform": {"low": 0.0, "high": 1e-5}}},
}


# --------------------------------------------------------------------------- arguments

def scheduler_address(text):
    """argparse type of ``--scheduler``: ``tcp://HOST:PORT`` (or another Dask protocol)."""
    proto, sep, rest = text.partition("://")
    host, colon, port = rest.rpartition(":")
    if not sep or not proto or not colon or not host or not port.isdigit():
        raise argparse.ArgumentTypeError(f"expected tcp://HOST:PORT, got {text!r}")
    return text


def add_arguments(parser, argv=()):
    """The run form, or (``rcac sweep report|rerun ...``: ``argv``, the words after
    ``sweep``, starts with one) the two result subcommands."""
    parser.epilog = ("also: 'rcac sweep report RESULTS' (summary and plot) and "
                     "'rcac sweep rerun RESULTS INDEX' (one run again, alone)")
    if argv[:1] and argv[0] in ACTIONS:
        sub = parser.add_subparsers(dest="action", metavar="ACTION")
        sub.required = True
        rep = sub.add_parser("report", help="failure rate, worst cases, distributions, "
                             "sensitivity; printed and plotted")
        rep.add_argument("results", help="a results directory or its results.parquet")
        rep.add_argument("--worst", type=positive_int, default=10,
                         help="worst runs listed (default 10)")
        rep.add_argument("--plot", default=None, help="PNG (default RESULTS_DIR/report.png)")
        rer = sub.add_parser("rerun", help="rerun one run alone and compare with its row")
        rer.add_argument("results", help="a results directory or its results.parquet")
        rer.add_argument("index", type=non_negative_int, help="the run's index")
        rer.add_argument("--plot", default=None,
                         help="PNG (default RESULTS_DIR/rerun_INDEX.png)")
        return
    parser.set_defaults(action="run")
    parser.add_argument("campaign", nargs="?", metavar="CAMPAIGN", help="campaign YAML file")
    parser.add_argument("--out", default=None, metavar="DIR", help="results directory")
    parser.add_argument("--samples", type=positive_int, metavar="N", default=None,
                        help="random draws per grid cell (overrides the campaign's)")
    parser.add_argument("--duration", type=positive_float, metavar="S", default=None,
                        help="seconds simulated per run (overrides the scenario's)")
    parser.add_argument("--workers", type=non_negative_int, metavar="K", default=None,
                        help="LocalCluster workers (default: one per core; 0: this process, "
                             "no Dask)")
    parser.add_argument("--scheduler", type=scheduler_address, metavar="ADDRESS", default=None,
                        help="address of a running Dask scheduler, tcp://HOST:PORT")
    parser.add_argument("--chunk", type=positive_int, metavar="C", default=None,
                        help="runs per task (default: about 8 tasks per worker, <= 25)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the campaign in --out, skipping finished runs")
    parser.add_argument("--bench", action="store_true",
                        help="runs/s on 1 and 2 workers, scaling efficiency, overhead per run")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args):
    if args.action == "report":
        return report(args.results, worst=args.worst, plot=args.plot)
    if args.action == "rerun":
        return rerun(args.results, args.index, plot=args.plot)
    if args.bench:
        return bench(args.campaign, args.samples, args.duration, args.out)
    if args.campaign is None:
        raise ConfigError("CAMPAIGN: missing (rcac sweep CAMPAIGN --out DIR)")
    if args.out is None:
        raise ConfigError("--out: missing (the results directory)")
    if args.scheduler is not None and args.workers is not None:
        raise ConfigError("--workers: not with --scheduler (the cluster has its workers)")
    campaign = cp.with_overrides(cp.load(args.campaign), args.samples, args.duration)
    total = cp.run_count(campaign)
    cp.setup(campaign, 0)                  # a campaign that cannot build a run fails here
    store = Store(args.out)
    store.claim(campaign, resume=args.resume)
    t0 = time.perf_counter()
    done = execute(campaign, store, workers=args.workers, scheduler=args.scheduler,
                   chunk=args.chunk, progress=not args.quiet)
    table = store.merge()
    failed = int(sum(table.column("diverged").to_pylist()))
    print(f"{done} runs in {time.perf_counter() - t0:.1f} s; {table.num_rows}/{total} runs in "
          f"{store.results}; {failed} diverged; summary and plot: rcac sweep report {args.out}")
    return 0


# --------------------------------------------------------------------------- results

class Store:
    """A results directory: ``campaign.json``, ``parts/*.parquet``, ``results.parquet``."""

    def __init__(self, out):
        self.out = out
        self.parts = os.path.join(out, "parts")
        self.results = os.path.join(out, "results.parquet")
        self.campaign_file = os.path.join(out, "campaign.json")

    def claim(self, campaign, resume=False):
        """Record ``campaign`` here, or check it is the one already recorded (``resume``)."""
        key = dict(campaign, samples=None)
        if os.path.exists(self.campaign_file):
            if not resume:
                raise ConfigError(f"--out: {self.out} already holds a campaign; pass --resume "
                                  "to continue it, or choose another directory")
            with open(self.campaign_file, encoding="utf-8") as f:
                if dict(json.load(f), samples=None) != json.loads(json.dumps(key)):
                    raise ConfigError(f"--resume: the campaign differs from the one in "
                                      f"{self.campaign_file} (only --samples may change)")
        os.makedirs(self.parts, exist_ok=True)
        write_atomic(self.campaign_file, json.dumps(campaign, indent=1).encode())

    def campaign(self):
        """The recorded campaign."""
        try:
            with open(self.campaign_file, encoding="utf-8") as f:
                return json.load(f)
        except OSError:
            raise ConfigError(f"RESULTS: no campaign.json in {self.out}") from None

    def part_files(self):
        return sorted(glob.glob(os.path.join(self.parts, "part-*.parquet")))

    def done(self):
        """The indices of the finished runs (results and parts)."""
        import pyarrow.parquet as pq
        runs = set()
        for path in self.part_files() + ([self.results] if os.path.exists(self.results)
                                         else []):
            runs.update(pq.read_table(path, columns=["run"]).column("run").to_pylist())
        return runs

    def write(self, rows):
        """One finished chunk: a part file, written atomically."""
        import pyarrow as pa
        import pyarrow.parquet as pq
        path = os.path.join(self.parts, f"part-{rows[0]['run']:07d}-{len(rows)}.parquet")
        tmp = path + ".tmp"
        pq.write_table(pa.Table.from_pylist(rows), tmp)
        os.replace(tmp, path)

    def table(self):
        """Results and parts as one table sorted by ``run`` (ConfigError on a duplicate)."""
        import pyarrow as pa
        import pyarrow.parquet as pq
        tables = [pq.read_table(p) for p in self.part_files()]
        if os.path.exists(self.results):
            tables.insert(0, pq.read_table(self.results).replace_schema_metadata(None))
        if not tables:
            raise ConfigError(f"RESULTS: no results in {self.out}")
        table = pa.concat_tables(tables, promote_options="default").sort_by("run")
        runs = np.asarray(table.column("run"))
        if np.any(np.diff(runs) == 0):
            raise ConfigError(f"RESULTS: run {runs[1:][np.diff(runs) == 0][0]} appears twice")
        return table

    def merge(self):
        """Fold the parts into ``results.parquet`` (atomically), then delete them."""
        import pyarrow.parquet as pq
        parts = self.part_files()
        table = self.table()
        campaign = self.campaign()
        meta = {"campaign": campaign, "varied": cp.varied_columns(campaign),
                "metrics": list(METRICS)}
        table = table.replace_schema_metadata({"rcac_sweep": json.dumps(meta)})
        tmp = self.results + ".tmp"
        pq.write_table(table, tmp)
        os.replace(tmp, self.results)
        for p in parts:
            os.remove(p)
        return table


def write_atomic(path, data):
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def open_results(path):
    """A results directory or its ``results.parquet`` -> its :class:`Store`."""
    out = os.path.dirname(path) if path.endswith(".parquet") else path
    if not os.path.isdir(out):
        raise ConfigError(f"RESULTS: no such directory {out!r}")
    return Store(out or ".")


# --------------------------------------------------------------------------- engine

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


# --------------------------------------------------------------------------- report

def load_table(path):
    """``(DataFrame, metadata)`` of a results directory (results and unmerged parts)."""
    store = open_results(path)
    df = store.table().to_pandas()
    campaign = store.campaign()
    return df, {"campaign": campaign, "varied": cp.varied_columns(campaign)}, store


def sensitivity(df, inputs, metric="rms_tracking_error"):
    """Spearman rank correlation of ``metric`` with each numeric input (NaN if constant)."""
    numeric = [c for c in inputs if df[c].dtype.kind in "fiu" and df[c].nunique() > 1]
    if not numeric or len(df) < 3:
        return {}
    corr = df[numeric + [metric]].corr(method="spearman")[metric]
    return {c: float(corr[c]) for c in numeric}


def report(path, worst=10, plot=None):
    """Print the campaign's summary and write its figure."""
    import pandas as pd
    df, meta, store = load_table(path)
    varied = meta["varied"]
    n = len(df)
    expected = cp.run_count(meta["campaign"])
    div = df["diverged"].astype(bool)
    print(f"campaign {meta['campaign']['name']!r}: {n} of {expected} runs, "
          f"{int(div.sum())} diverged ({100.0 * div.mean():.1f} %)")
    if "channels" in varied:      # a law is a law and its channel set
        channels = df["channels"].fillna("").astype(str)
        df["law"] = np.where(channels != "", df["law"] + " " + channels, df["law"])
    laws = sorted(df["law"].unique())
    w = max(11, *(len(law) for law in laws))
    print("\nfailure rate per law:")
    for law in laws:
        sel = df["law"] == law
        print(f"  {law:{w}s} {int(div[sel].sum()):5d} / {int(sel.sum()):5d}  "
              f"({100.0 * div[sel].mean():.1f} %)")
    print("\nmetric distributions per law (median [5 %, 95 %] max; runs that did not "
          "diverge):")
    for m in METRICS:
        for law in laws:
            v = df.loc[(df["law"] == law) & ~div, m]
            if len(v):
                q = v.quantile([0.5, 0.05, 0.95])
                print(f"  {m:27s} {law:{w}s} {q.iloc[0]:11.4g} [{q.iloc[1]:10.4g}, "
                      f"{q.iloc[2]:10.4g}] {v.max():10.4g}")
    cols = ["run", "law", "status", "t_end", "rms_tracking_error", "max_tracking_error"] + [
        c for c in varied if c != "law"]
    # diverged first, the earliest divergence first; then the largest RMS error
    key = np.where(div, -df["t_end"].to_numpy(), df["rms_tracking_error"].to_numpy())
    order = df.assign(_d=div, _k=key).sort_values(["_d", "_k"], ascending=[False, False],
                                                  na_position="first")
    print(f"\nworst {min(worst, n)} runs (diverged first, earliest first; then by RMS error)"
          "; rerun one with 'rcac sweep rerun RESULTS INDEX':")
    with pd.option_context("display.width", 200, "display.max_columns", 30,
                           "display.float_format", "{:.4g}".format):
        print(order[cols].head(worst).to_string(index=False))
    print("\nsensitivity (Spearman rank correlation) of the RMS error of the runs that did "
          "not diverge, per law, and of divergence (0/1, all runs):")
    ok = df[~div]
    sens = {"all": sensitivity(ok, varied)}
    for law in laws:
        sens[law] = sensitivity(ok[ok["law"] == law], varied)
    if div.any():
        sens["diverged"] = sensitivity(df.assign(_div=div.astype(float)), varied, "_div")
    names = sorted({c for s in sens.values() for c in s}, key=lambda c: -abs(
        sens["all"].get(c, 0.0)))
    cw = max(12, *(len(k) + 2 for k in sens))
    print(f"  {'input':22s}" + "".join(f"{k:>{cw}s}" for k in sens))
    for c in names:
        print(f"  {c:22s}" + "".join(f"{s[c]:{cw}.3f}" if c in s else f"{'-':>{cw}s}"
                                     for s in sens.values()))
    for c in [c for c in varied if df[c].dtype.kind not in "fiu" and c != "law"]:
        medians = ok.groupby(c)["rms_tracking_error"].median()
        print(f"  {c}: median RMS per value: " + ", ".join(
            f"{k or '-'}: {v:.4g}" for k, v in medians.items()))
    plot = plot or os.path.join(store.out, "report.png")
    plot_report(df, div, laws, sens["all"], plot)
    print(f"\nwrote {plot}")
    return 0


def plot_report(df, div, laws, sens, path):
    """Four panels: RMS per law, failure rate per law, sensitivity, RMS vs the top input."""
    from rcac_ros.tools.plots import plt, save
    fig, axes = plt.subplots(1, 4, figsize=(22, 4.5))
    ok = df[~div]
    data = [np.clip(ok.loc[ok["law"] == law, "rms_tracking_error"].to_numpy(), 1e-12, None)
            for law in laws]
    axes[0].boxplot(data, tick_labels=laws)
    axes[0].set_yscale("log")
    axes[0].set_title("tracking RMS error per law (rad)")
    rates = [100.0 * div[df["law"] == law].mean() for law in laws]
    axes[1].bar(laws, rates, color="C3")
    axes[1].set_ylim(0.0, max(1.0, 1.1 * max(rates)))     # 0 %: an empty panel, not a gap
    axes[1].set_title("diverged runs per law (%)")
    names = sorted(sens, key=lambda c: abs(sens[c]))
    axes[2].barh(names, [sens[c] for c in names], color="C0")
    axes[2].set_xlim(-1, 1)
    axes[2].set_title("Spearman correlation with RMS error")
    if names:
        top = names[-1]
        for law in laws:
            sel = ok["law"] == law
            axes[3].scatter(ok.loc[sel, top], ok.loc[sel, "rms_tracking_error"], s=8, label=law)
        axes[3].set_yscale("log")
        axes[3].set_xlabel(top)
        axes[3].set_title(f"RMS error vs {top}")
        axes[3].legend(fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    save(fig, path, 100)


# --------------------------------------------------------------------------- rerun

def rerun(path, index, plot=None):
    """Run ``index`` again, alone, in this process; compare with its stored row; plot it."""
    df, meta, store = load_table(path)
    campaign = meta["campaign"]
    if index >= cp.run_count(campaign):
        raise ConfigError(f"INDEX: the campaign has {cp.run_count(campaign)} runs, got {index}")
    row, result = cp.simulate(campaign, index, keep_run=True)
    stored = df[df["run"] == index]
    cells = [f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()]
    print(f"run {index}: " + ", ".join(cells))
    if len(stored):
        old = stored.iloc[0]
        diffs = [abs(row[m] - old[m]) / max(abs(old[m]), 1e-300) for m in METRICS
                 if np.isfinite(old[m])]
        same = all(row[c] == old[c] for c in df.columns
                   if c not in METRICS + cp.TIMING and not (
                       isinstance(row[c], float) and np.isnan(row[c])))
        print(f"stored row: inputs {'identical' if same else 'DIFFER'}, largest relative "
              f"metric difference {max(diffs, default=0.0):.3g}")
    else:
        print("stored row: none (run not in the results yet)")
    from rcac_ros.tools.plots import plt, save
    plot = plot or os.path.join(store.out, f"rerun_{index}.png")
    fig, axes = plt.subplots(1, 3, figsize=(18, 4))
    t = result["t"]
    e = result["q"] - result["q_d"]
    for j in range(e.shape[1]):
        axes[0].plot(t, e[:, j], lw=0.8, label=f"joint {j + 1}")
    axes[0].set_title(f"run {index} ({row['law']}, {row['status']}): q - q_d (rad)")
    axes[0].legend(fontsize=7)
    theta = result["plant"].theta()
    axes[1].semilogy(t, np.linalg.norm((result["theta_hat"] - theta).reshape(len(t), -1),
                                       axis=1))
    axes[1].set_title("||theta_hat - theta||")
    axes[2].plot(t, result["E"], lw=0.8)
    axes[2].set_title("prediction error E")
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    save(fig, plot, 100)
    print(f"wrote {plot}")
    return 0


# --------------------------------------------------------------------------- bench

def timed_campaign(client, campaign, chunk=None):
    """``(wall s, summed in-run wall s, summed in-run CPU s, results.parquet bytes)``."""
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(tmp)
        store.claim(campaign)
        t0 = time.perf_counter()
        execute(campaign, store, chunk=chunk, progress=False, client=client)
        wall = time.perf_counter() - t0
        table = store.merge()
        return (wall, float(table.column("wall_time_s").to_numpy().sum()),
                float(table.column("cpu_time_s").to_numpy().sum()),
                os.path.getsize(store.results))


def worker_memory_mb(client):
    """Resident memory of each worker process, MB."""
    import psutil
    return [v / 2 ** 20 for v in client.run(lambda: psutil.Process().memory_info().rss)
            .values()]


def bench(path=None, samples=None, duration=None, out=None, rounds=3):
    """Runs/s on 1 and 2 LocalCluster workers, scaling efficiency, overhead per run.

    Both clusters are started and warmed first; then ``rounds`` alternating rounds of
    the whole campaign on each, and the best round of each is kept (the machine is
    shared: the best round is the one least disturbed by other load).
    """
    campaign = cp.load(path) if path else cp.validate(BENCH_CAMPAIGN)
    campaign = cp.with_overrides(campaign, samples, duration)
    n = cp.run_count(campaign)
    sim = campaign["scenario"]["duration"]
    print(f"bench: campaign {campaign['name']!r}, {n} runs of {sim:g} s simulated "
          f"({campaign['scenario']['model']}); load average {os.getloadavg()[0]:.2f} on "
          f"{os.cpu_count()} cores; best of {rounds} rounds")
    cp.warm_up()
    cp.simulate(campaign, 0)
    rows = run_chunk(campaign, range(n))
    cpu = float(np.mean([r["cpu_time_s"] for r in rows]))
    print(f"  one run in this process: {1e3 * np.median([r['wall_time_s'] for r in rows]):.1f}"
          f" ms wall (median), {1e3 * cpu:.1f} ms CPU (mean)")
    figures = {"runs": n, "duration_s": sim, "run_cpu_time_s": cpu, "rounds": rounds,
               "load_average_start": os.getloadavg()[0]}
    clients = {w: start_client(w, dashboard=":0") for w in (1, 2)}
    try:
        for client in clients.values():
            client.register_plugin(WarmUp(campaign), name="rcac-sweep-warm-up")
        results = {(1, None): [], (2, None): [], (1, 1): []}
        for _ in range(rounds):
            for workers, chunk in results:
                results[(workers, chunk)].append(timed_campaign(clients[workers], campaign,
                                                                chunk))
        memory = worker_memory_mb(clients[2])
    finally:
        for client in clients.values():
            close_client(client)
    figures["worker_rss_mb"] = max(memory)
    figures["results_bytes_per_run"] = results[(1, None)][0][3] / n
    print(f"  worker memory {max(memory):.0f} MB resident; results.parquet "
          f"{figures['results_bytes_per_run']:.0f} bytes per run")
    for (workers, chunk), measured in results.items():
        wall, task_time, task_cpu, _ = min(measured)
        # worker time not spent inside runs: scheduling, transfer, Parquet, idle at the end
        overhead = (wall * workers - task_time) / n
        share = task_cpu / (wall * workers)     # < 1: the cores were busy with other work too
        key = f"w{workers}{'_chunk1' if chunk else ''}"
        label = f"{workers} worker{'s' if workers > 1 else ''}, chunk " + (
            "1" if chunk else f"{auto_chunk(n, workers)}")
        print(f"  LocalCluster {label:18s} {n / wall:7.2f} runs/s  {1e3 * task_time / n:6.1f} "
              f"ms per run + overhead {1e3 * overhead:6.2f} ms "
              f"({100.0 * overhead * n / task_time:.1f} %); runs got {100.0 * share:.0f} % "
              "of the workers' time on CPU")
        figures[key] = dict(runs_per_s=n / wall, wall_s=wall, run_time_s=task_time / n,
                            overhead_per_run_s=overhead, cpu_share=share,
                            rounds_runs_per_s=[n / m[0] for m in measured])
    eff = figures["w2"]["runs_per_s"] / (2.0 * figures["w1"]["runs_per_s"])
    figures["efficiency_2_workers"] = eff
    w1 = figures["w1"]
    five = w1["run_time_s"] * 5.0 / sim
    figures["overhead_fraction_of_5s_run"] = w1["overhead_per_run_s"] / five
    figures["load_average_end"] = os.getloadavg()[0]
    shared = eff * figures["w1"]["cpu_share"] / figures["w2"]["cpu_share"]
    figures["efficiency_2_workers_per_cpu_share"] = shared
    print(f"  scaling efficiency on 2 workers: {100.0 * eff:.1f} % (goal >= 85 %); "
          f"{100.0 * shared:.1f} % if divided by the CPU share each got (other load)")
    print(f"  scheduling overhead per run (1 worker): {1e3 * w1['overhead_per_run_s']:.2f} ms "
          f"= {100.0 * figures['overhead_fraction_of_5s_run']:.2f} % of a 5-s run's "
          f"{1e3 * five:.0f} ms (goal <= 5 %)")
    print(f"  load average at the end {figures['load_average_end']:.2f}")
    if out:
        os.makedirs(out, exist_ok=True)
        write_atomic(os.path.join(out, "bench.json"), json.dumps(figures, indent=1).encode())
        print(f"wrote {os.path.join(out, 'bench.json')}")
    return 0
