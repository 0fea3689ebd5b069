"""``rcac sweep --bench``: runs/s on 1 and 2 LocalCluster workers, scaling efficiency,
overhead per run (doc/campaigns.md, "Speed of the engine")."""

import json
import os
import tempfile
import time

import numpy as np

from rcac_ros.tools.sweep import campaign as cp
from rcac_ros.tools.sweep.engine import (auto_chunk, close_client, execute, run_chunk,
                                         start_client, WarmUp)
from rcac_ros.tools.sweep.store import Store, write_atomic

#: The campaign --bench runs when none is given: the paper's arm, 5-s runs, gains spread.
BENCH_CAMPAIGN = {
    "name": "bench", "seed": 1, "samples": 60,
    "scenario": {"model": "css_arm", "law": "composite", "duration": 5.0},
    "vary": {"K_D": {"uniform": {"low": 5e3, "high": 2e4}},
             "P": {"loguniform": {"low": 10.0, "high": 1000.0}},
             "noise_q": {"uniform": {"low": 0.0, "high": 1e-5}}},
}


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
