"""The package on a dask cluster of worker processes against joblib on the same cores.

1. **The selection framework** (:func:`skhmmgmr.select_parameters`, thesis settings: top 10,
   K=1..20) on the simulated thesis protocol, once with joblib's process backend
   (``n_jobs=2``) and once on a ``LocalCluster`` of 2 worker processes of one thread each
   (:func:`skhmmgmr.cluster.use_cluster`), side by side: wall time, overhead of the cluster,
   tables equal. From the cluster run's task stream: number of tasks, compute seconds per
   task, bytes scattered to the workers: the inputs of the cost model of the performance page.
2. **One EM fit** of a K=5 model over all 18 features on the training recordings: the
   single-machine ``HMMGMRRegressor.fit`` against :func:`skhmmgmr.cluster.fit_on_cluster`
   over parquet files (one per driver) on the 2-worker cluster: wall time, seconds per EM
   iteration, the largest parameter difference.
3. **Worker memory against partition size**: the same fit on fresh clusters with the
   training rows in 2, 4 and 8 partitions (``--tile N``: N copies of the training recordings,
   for sizes that show); the resident memory of every worker sampled every 5 ms during the
   fit, its peak above the level after a small warm-up fit, against the bytes of the rows the
   worker held.

Run::

    python benchmarks/bench_cluster.py                              # 7 drivers, 5-min sections
    python benchmarks/bench_cluster.py --drivers 2 --duration 60    # reduced, a few minutes

The machine's load (``os.getloadavg``) is printed with the results: on shared cores the
times of both sides move together, the overhead less so.
"""

import argparse
import os
import tempfile
import time
import warnings

import joblib
import numpy as np
import pandas as pd
from _data import thesis_protocol
from sklearn.exceptions import ConvergenceWarning

from skhmmgmr import HMMGMRRegressor, select_parameters
from skhmmgmr._core._schema import FEATURE_NAMES, TARGET
from skhmmgmr.cluster import WORKER_ENVIRONMENT, fit_on_cluster, use_cluster

DEFAULT_CACHE = os.path.join(os.path.expanduser("~"), ".cache", "skhmmgmr-benchmarks")
TABLES = ["relevance", "candidates", "states", "bic", "test"]


def _load():
    return os.getloadavg()[0]


def _local_cluster():
    """Two worker processes of one thread each."""
    import distributed

    return distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        env=WORKER_ENVIRONMENT,
    )


def _cpu_seconds():
    """CPU seconds (user + system) of this process and all its descendants alive now."""
    import psutil

    total = 0.0
    me = psutil.Process()
    for process in [me, *me.children(recursive=True)]:
        try:
            times = process.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += times.user + times.system
    return total


def _framework(data, k_max, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        start = time.perf_counter()
        report = select_parameters(data, n_top=10, k_max=k_max, progress=False, **kwargs)
        return report, time.perf_counter() - start


def bench_framework(data, k_max):
    import distributed
    from dask.sizeof import sizeof

    print(f"load before: {_load():.1f}")
    with joblib.parallel_config(n_jobs=2):  # the workers start before the CPU clock
        joblib.Parallel()(joblib.delayed(abs)(i) for i in range(4))
    cpu = _cpu_seconds()
    local, local_s = _framework(data, k_max, n_jobs=2)
    local_cpu = _cpu_seconds() - cpu
    print(f"joblib n_jobs=2: {local_s:.1f} s, {local_cpu:.1f} CPU s (load {_load():.1f})")
    with (
        _local_cluster() as cluster,
        distributed.Client(cluster) as client,
    ):
        scattered, scatter = [], client.scatter

        def counting_scatter(data, *args, **kwargs):
            scattered.append(sizeof(data))
            return scatter(data, *args, **kwargs)

        client.scatter = counting_scatter
        cpu = _cpu_seconds()
        with use_cluster(client), distributed.get_task_stream(client) as stream:
            remote, remote_s = _framework(data, k_max)
        remote_cpu = _cpu_seconds() - cpu
        n_workers = len(client.scheduler_info()["workers"])
    print(
        f"dask LocalCluster 2 processes: {remote_s:.1f} s, {remote_cpu:.1f} CPU s "
        f"(load {_load():.1f})"
    )
    same = all(getattr(remote, t).equals(getattr(local, t)) for t in TABLES)
    tasks = [t for t in stream.data if "batch_of" in t["key"]]
    compute = [
        sum(s["stop"] - s["start"] for s in t["startstops"] if s["action"] == "compute")
        for t in tasks
    ]
    evaluations = len(remote.exhaustive) + len(remote.forward_paths) + len(remote.states)
    result = {
        "joblib_s": local_s,
        "cluster_s": remote_s,
        "overhead": remote_s / local_s - 1,
        "joblib_cpu_s": local_cpu,
        "cluster_cpu_s": remote_cpu,
        "cpu_overhead": remote_cpu / local_cpu - 1,
        "tables_equal": same,
        "dask_tasks": len(tasks),
        "compute_s_per_task": float(np.mean(compute)) if compute else float("nan"),
        "compute_s_total": float(np.sum(compute)),
        "scatters": len(scattered),
        "bytes_scattered": int(sum(scattered)) * n_workers,
        "evaluation_rows": evaluations,
    }
    print(
        f"framework: joblib {local_s:.1f} s, cluster {remote_s:.1f} s "
        f"(overhead {result['overhead']:+.1%}; CPU {result['cpu_overhead']:+.1%}), "
        f"tables equal: {same}; {len(tasks)} dask tasks, "
        f"{result['compute_s_per_task']:.2f} s compute per task, {len(scattered)} scatters, "
        f"{result['bytes_scattered'] / 1e6:.1f} MB shipped to {n_workers} workers"
    )
    return result


def _partition_files(train, n_partitions, folder):
    recordings = train["recording"].unique()
    paths = []
    for i, ids in enumerate(np.array_split(recordings, n_partitions)):
        path = os.path.join(folder, f"part-{n_partitions}-{i}.parquet")
        train[train["recording"].isin(ids)].to_parquet(path)
        paths.append(path)
    return paths


def _warm_up_and_sample():
    """In a worker: compile the kernels (a small fit), then sample the resident memory every
    5 ms in a thread; returns the resident memory now (MB), the baseline."""
    import gc
    import sys
    import threading

    import psutil

    rng = np.random.default_rng(0)
    HMMGMRRegressor(n_states=2, random_state=0).fit(
        rng.normal(size=(400, 3)), rng.normal(size=400), groups=np.repeat([0, 1], 200)
    )
    gc.collect()
    process = psutil.Process()
    state = {"peak": process.memory_info().rss, "run": True}

    def sample():
        while state["run"]:
            state["peak"] = max(state["peak"], process.memory_info().rss)
            time.sleep(0.005)

    threading.Thread(target=sample, daemon=True).start()
    sys.skhmmgmr_benchmark_rss = state
    return state["peak"] / 2**20


def _sampled_peak():
    """In a worker: stop the sampling; the largest resident memory seen (MB)."""
    import sys

    state = sys.skhmmgmr_benchmark_rss
    state["run"] = False
    return state["peak"] / 2**20


def bench_fit(train, n_partitions_list, folder):
    import distributed

    features = list(FEATURE_NAMES)
    params = dict(n_states=5, random_state=0, n_iter=30, tol=1e-4)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        local = HMMGMRRegressor(**params).fit(
            train[features], train[TARGET], groups=train["recording"]
        )
    local_s = time.perf_counter() - start
    print(f"local fit: {local_s:.1f} s, {local.n_iter_} iterations (load {_load():.1f})")
    rows = []
    for n_partitions in n_partitions_list:
        paths = _partition_files(train, n_partitions, folder)
        with (
            _local_cluster() as cluster,
            distributed.Client(cluster) as client,
        ):
            base = client.run(_warm_up_and_sample)
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)
                remote = fit_on_cluster(
                    HMMGMRRegressor(**params), paths, features=features, client=client
                )
            remote_s = time.perf_counter() - start
            peak = client.run(_sampled_peak)
        diff = max(
            float(np.max(np.abs(getattr(remote, a) - getattr(local, a))))
            for a in ("startprob_", "transmat_", "means_", "covars_")
        )
        per_worker_bytes = len(train) * (len(features) + 1) * 8 / 2
        increase = [peak[w] - base[w] for w in peak]
        rows.append(
            {
                "partitions": n_partitions,
                "rows_per_partition": len(train) // n_partitions,
                "MB_per_partition": len(train) * (len(features) + 1) * 8 / n_partitions / 1e6,
                "MB_per_worker": per_worker_bytes / 1e6,
                "fit_s": remote_s,
                "s_per_iteration": remote_s / remote.n_iter_,
                "local_s_per_iteration": local_s / local.n_iter_,
                "max_param_diff": diff,
                "worker_base_MB": float(np.mean(list(base.values()))),
                "worker_peak_MB": float(np.max(list(peak.values()))),
                "worker_peak_increase_MB": float(np.max(increase)),
            }
        )
        print(pd.DataFrame(rows[-1:]).round(3).to_string(index=False))
    return pd.DataFrame(rows)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drivers", type=int, default=7)
    parser.add_argument("--duration", type=float, default=300.0, help="seconds per section")
    parser.add_argument("--k-max", type=int, default=20)
    parser.add_argument("--cache", default=DEFAULT_CACHE, help="simulator cache directory")
    parser.add_argument("--skip-framework", action="store_true")
    parser.add_argument("--skip-fit", action="store_true")
    parser.add_argument(
        "--tile",
        type=int,
        default=1,
        help="fit on this many copies of the training recordings (new ids, for the memory)",
    )
    parser.add_argument("--partitions", type=int, nargs="+", default=[2, 4, 8])
    args = parser.parse_args(argv)
    data = thesis_protocol(args.drivers, duration=args.duration, cache=args.cache)
    print(f"data: {args.drivers} drivers, {len(data):,} rows; cores {os.cpu_count()}")
    if not args.skip_framework:
        result = bench_framework(data, args.k_max)
        print(pd.Series(result).to_string())
    if args.skip_fit:
        return
    train = data[data["split"] == "train"]
    train = pd.concat(
        [train.assign(recording=f"copy{i}-" + train["recording"]) for i in range(args.tile)],
        ignore_index=True,
    )
    print(f"fit data: {len(train):,} rows, {train['recording'].nunique()} recordings")
    with tempfile.TemporaryDirectory() as folder:
        table = bench_fit(train, args.partitions, folder)
    print(table.round(4).to_string(index=False))


if __name__ == "__main__":
    main()
