"""The whole parameter-selection framework at the thesis' scale, with two comparisons.

Data: the simulator's thesis protocol for 7 drivers (the three styles in turn), 12 training,
6 validation and 6 test sections of 5 minutes per driver at 20 Hz: 84 training and 42
validation recordings (504,000 and 252,000 rows), 18 measured features.

1. **Fast path**: :func:`skhmmgmr.select_parameters` (Spearman filter, exhaustive wrapper over
   the top 10 with K=2, per-recording forward wrapper over all 18 for 11 trade-offs, candidate
   subsets, state sweep K=1..20, final test), ``n_jobs`` workers. Wall time per stage.
2. **Peer's exhaustive step**: the same K=2 model fitted by hmmlearn's ``GaussianHMM`` (full
   covariance, same start and tolerance), timed on a sample of subsets of the top 10 (two per
   size) next to the package on the same subsets, then extrapolated to all 1023 subsets and
   divided by ``n_jobs``.
3. **Slow reference path**: the same framework with :class:`_reference.ReferenceHMMGMR`, an EM
   built from sklearn.mixture's densities and hmmlearn's recursions (k-means on all rows), and
   a comparison of every selection: per-recording best subsets, relevance, candidates, the
   chosen subset and K.

Run::

    python benchmarks/bench_framework.py                   # all three, about 45 minutes
    python benchmarks/bench_framework.py --skip-reference  # fast path and peer, ~10 minutes
"""

import argparse
import itertools
import os
import time
import types
import warnings
from math import comb

import joblib
import numpy as np
import pandas as pd
from _data import thesis_protocol
from _reference import PeerHMMGMR, ReferenceHMMGMR
from sklearn.exceptions import ConvergenceWarning
from threadpoolctl import threadpool_limits

from skhmmgmr import HMMGMRRegressor, select_parameters
from skhmmgmr._core._schema import TARGET
from skhmmgmr.metrics import evaluate_recordings
from skhmmgmr.selection._search._score_tables import best_per_recording, rescore_table

DEFAULT_CACHE = os.path.join(os.path.expanduser("~"), ".cache", "skhmmgmr-benchmarks")


def load_protocol(n_drivers, cache, duration=300.0):
    start = time.perf_counter()
    data = thesis_protocol(n_drivers, duration=duration, cache=cache)
    seconds = time.perf_counter() - start
    counts = data.groupby("split")["recording"].nunique().to_dict()
    print(
        f"data: {n_drivers} drivers (seeds {data.attrs['seeds']}), {len(data):,} rows, "
        f"recordings {counts}, simulated or loaded in {seconds:.0f} s"
    )
    return data


def run_framework(data, estimator, n_jobs, label, save=None):
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        report = select_parameters(
            data, n_top=10, k_max=20, n_jobs=n_jobs, progress=False, estimator=estimator
        )
    wall = time.perf_counter() - start
    stages = ", ".join(f"{name} {seconds:.0f} s" for name, seconds in report.timings.items())
    print(f"{label}: {wall:.0f} s wall ({stages})")
    print(f"  subset: {', '.join(report.features)}; K={report.n_states}")
    if save:
        os.makedirs(save, exist_ok=True)
        report_tables = {k: v for k, v in vars(report).items() if not k.endswith("_model")}
        report_tables["wall_s"] = wall
        joblib.dump(report_tables, os.path.join(save, f"{label.replace(' ', '_')}.joblib"))
    return report, wall


def load_tables(path):
    """The tables of a run saved with ``--save`` (e.g. ``reference_path.joblib``), as a
    report-like namespace, and that run's wall time."""
    tables = joblib.load(path)
    wall = tables.pop("wall_s", None)
    if wall is None:
        wall = sum(tables["timings"].values())
    return types.SimpleNamespace(**tables), wall


def _time_subsets(estimator, data, subsets):
    """Seconds to fit, predict and evaluate each subset's model (one thread)."""
    train, val = data[data["split"] == "train"], data[data["split"] == "validation"]
    y, groups = train[TARGET].to_numpy(), pd.factorize(train["recording"])[0]
    y_val, groups_val = val[TARGET].to_numpy(), pd.factorize(val["recording"])[0]
    seconds = []
    with threadpool_limits(limits=1), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for subset in subsets:
            start = time.perf_counter()
            model = estimator.fit(train[list(subset)].to_numpy(), y, groups=groups)
            prediction = model.predict(val[list(subset)].to_numpy(), groups=groups_val)
            evaluate_recordings(y_val, prediction, groups=groups_val, sampling_period=0.05)
            seconds.append(time.perf_counter() - start)
    return np.asarray(seconds)


def peer_exhaustive(data, top, n_jobs, per_size=2, seed=0):
    """Per-subset times of hmmlearn and the package on a sample, extrapolated to 2^10 - 1."""
    rng = np.random.default_rng(seed)
    sample = []
    for size in range(1, len(top) + 1):
        subsets = list(itertools.combinations(top, size))
        picks = rng.choice(len(subsets), size=min(per_size, len(subsets)), replace=False)
        sample.extend(subsets[i] for i in picks)
    sizes = np.array([len(s) for s in sample])
    ours = _time_subsets(HMMGMRRegressor(n_states=2, random_state=0), data, sample)
    peer = _time_subsets(PeerHMMGMR(n_states=2, random_state=0), data, sample)

    def extrapolate(seconds):
        return sum(
            comb(len(top), size) * seconds[sizes == size].mean() for size in np.unique(sizes)
        )

    result = {
        "n_subsets_timed": len(sample),
        "peer_per_subset_s": float(peer.mean()),
        "ours_per_subset_s": float(ours.mean()),
        "peer_exhaustive_s": extrapolate(peer) / n_jobs,
        "ours_exhaustive_extrapolated_s": extrapolate(ours) / n_jobs,
    }
    print(
        f"exhaustive step, {len(sample)} subsets timed on one core each: hmmlearn "
        f"{result['peer_per_subset_s']:.2f} s per subset, skhmmgmr "
        f"{result['ours_per_subset_s']:.2f} s; extrapolated to 1023 subsets on {n_jobs} "
        f"cores: hmmlearn {result['peer_exhaustive_s']:.0f} s "
        f"({result['peer_exhaustive_s'] / 60:.0f} min), skhmmgmr "
        f"{result['ours_exhaustive_extrapolated_s']:.0f} s"
    )
    return result


def _canonical(subset):
    # Runs of different versions may order the features of a subset differently.
    return tuple(sorted(subset))


def compare_selections(fast, reference):
    """Every selection of the two runs, side by side; returns a dict of differences."""
    keys = ["trade_off", "recording"]
    labels = list(fast.relevance.columns)
    fast, reference = (
        types.SimpleNamespace(
            **{
                **vars(report),
                "exhaustive": report.exhaustive.assign(
                    subset=report.exhaustive["subset"].map(_canonical)
                ),
                "forward_paths": report.forward_paths.assign(
                    subset=report.forward_paths["subset"].map(_canonical)
                ),
                "candidates": report.candidates.assign(
                    features=report.candidates["features"].map(_canonical)
                ),
            }
        )
        for report in (fast, reference)
    )
    best = {
        name: best_per_recording(
            rescore_table(report.exhaustive, "subset", labels), "subset", tie_breaker="n_features"
        ).set_index(keys)["subset"]
        for name, report in (("fast", fast), ("reference", reference))
    }
    joined = pd.concat(best, axis=1).dropna()
    same_best = float((joined["fast"] == joined["reference"]).mean())
    # Model by model: the same validation metrics mean that both engines reached the same fit.
    metrics = fast.exhaustive.merge(
        reference.exhaustive, on=["subset", "recording"], suffixes=("_fast", "_reference")
    )
    same_fit = ((metrics["accuracy_fast"] - metrics["accuracy_reference"]).abs() < 0.01) & (
        (metrics["smoothness_fast"] - metrics["smoothness_reference"]).abs() < 1e-3
    )
    same_models = float(same_fit.groupby(metrics["subset"]).all().mean())
    relevance_diff = (fast.relevance - reference.relevance).abs()
    candidates = fast.candidates.set_index("name")["features"]
    candidates_ref = reference.candidates.set_index("name")["features"]
    differing = [n for n in candidates.index if candidates[n] != candidates_ref.get(n)]
    paths = {}
    for name, report in (("fast", fast), ("reference", reference)):
        final = report.forward_paths[report.forward_paths["accepted"]]
        paths[name] = final.groupby(["trade_off", "path"])["subset"].last()
    forward = pd.concat(paths, axis=1).dropna()
    result = {
        "exhaustive_same_fit_share": same_models,
        "exhaustive_same_best_share": same_best,
        "forward_same_final_share": float((forward["fast"] == forward["reference"]).mean()),
        "relevance_max_count_difference": int(relevance_diff.to_numpy().max()),
        "candidates_differing": differing,
        "same_subset": _canonical(fast.features) == _canonical(reference.features),
        "same_n_states": fast.n_states == reference.n_states,
        "state_choices_fast": fast.state_choices[["trade_off", "n_states"]].to_dict("list"),
        "state_choices_reference": reference.state_choices[["trade_off", "n_states"]].to_dict(
            "list"
        ),
    }
    print(
        f"exhaustive models with the same validation metrics under both engines (accuracy "
        f"within 0.01 points, smoothness within 1e-3 Nm/s on every recording): "
        f"{same_models:.1%}"
    )
    print(
        f"selections, fast vs reference: per-recording best exhaustive subsets identical in "
        f"{same_best:.1%} of (trade-off, recording) pairs; final forward subsets identical in "
        f"{result['forward_same_final_share']:.1%} of paths; relevance counts differ by at "
        f"most {result['relevance_max_count_difference']}; candidates differing: "
        f"{differing or 'none'}; same subset: {result['same_subset']}; same K: "
        f"{result['same_n_states']}"
    )
    for name, report in (("fast", fast), ("reference", reference)):
        test = report.test_summary.set_index("model")
        print(
            f"  {name:<9} test accuracy final/baseline "
            f"{test.loc['final', 'accuracy']:.2f}/{test.loc['baseline', 'accuracy']:.2f} %, "
            f"smoothness {test.loc['final', 'smoothness']:.3f}/"
            f"{test.loc['baseline', 'smoothness']:.3f} Nm/s"
        )
    return result


def run(
    n_drivers=7,
    n_jobs=2,
    cache=DEFAULT_CACHE,
    reference=True,
    peer=True,
    duration=300.0,
    save=None,
    reference_tables=None,
):
    """All three parts; returns a dict of figures.

    ``save``: a folder for the selection tables of both paths. ``reference_tables``: the
    saved tables of an earlier reference run (``reference_path.joblib``) to compare with
    instead of running the reference path again; it does not depend on the fast engine.
    """
    data = load_protocol(n_drivers, cache, duration)
    fast, wall = run_framework(data, HMMGMRRegressor(random_state=0), n_jobs, "fast path", save)
    results = {
        "framework_wall_s": wall,
        "stages_s": fast.timings,
        "subset": fast.features,
        "n_states": fast.n_states,
    }
    if peer:
        top = list(fast.filter.loc[fast.filter["selected"], "feature"])
        results["peer"] = peer_exhaustive(data, top, n_jobs)
        results["peer"]["ours_exhaustive_measured_s"] = fast.timings["exhaustive"]
    if reference_tables:
        slow, slow_wall = load_tables(reference_tables)
        print(
            f"reference path: tables of an earlier run ({slow_wall:.0f} s wall) from "
            f"{reference_tables}"
        )
        results["reference_wall_s"] = slow_wall
        results["reference_tables"] = reference_tables
        results["comparison"] = compare_selections(fast, slow)
    elif reference:
        slow, slow_wall = run_framework(
            data, ReferenceHMMGMR(random_state=0), n_jobs, "reference path", save
        )
        results["reference_wall_s"] = slow_wall
        results["comparison"] = compare_selections(fast, slow)
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drivers", type=int, default=7)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--duration", type=float, default=300.0, help="seconds per section")
    parser.add_argument("--cache", default=DEFAULT_CACHE, help="simulator cache directory")
    parser.add_argument("--skip-reference", action="store_true")
    parser.add_argument("--skip-peer", action="store_true")
    parser.add_argument("--save", default=None, help="directory for the selection tables")
    parser.add_argument(
        "--reference-tables",
        default=None,
        help="compare with the saved tables of an earlier reference run instead of running it",
    )
    args = parser.parse_args(argv)
    return run(
        args.drivers,
        n_jobs=args.n_jobs,
        cache=args.cache,
        reference=not args.skip_reference,
        peer=not args.skip_peer,
        duration=args.duration,
        save=args.save,
        reference_tables=args.reference_tables,
    )


if __name__ == "__main__":
    main()
