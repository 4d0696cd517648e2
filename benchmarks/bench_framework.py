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
3. **Fast and full search side by side** (``--searches``): the framework with
   ``search="full"`` (every model from its own k-means start until EM converges) and
   ``search="fast"`` on the same data, per seed, one after the other in one run: wall time per
   stage and their ratio, the EM fits of every stage (full fits, and screened models with
   their few EM iterations), and every selection compared (subset, K, the candidate subsets
   of every trade-off, the K of every trade-off, test accuracy and smoothness).
4. **Scale** (``--scale``): both searches side by side as the data and the candidates grow:
   the whole framework on the drivers of ``--drivers`` and on ``--scale-factor`` times as
   many (rows), and the exhaustive stage alone (K=2, the Spearman filter's top ``n``) for
   every ``n`` of ``--n-tops`` (candidate features): wall time and EM fits of both paths.
5. **Slow reference path**: the same framework with :class:`_reference.ReferenceHMMGMR`, an EM
   built from sklearn.mixture's densities and hmmlearn's recursions (k-means on all rows), and
   a comparison of every selection: per-recording best subsets, relevance, candidates, the
   chosen subset and K.

Run::

    python benchmarks/bench_framework.py                   # all three, about 45 minutes
    python benchmarks/bench_framework.py --skip-reference  # fast path and peer, ~10 minutes
    python benchmarks/bench_framework.py --searches --seeds 0 1 2   # search="fast" vs "full"
    python benchmarks/bench_framework.py --searches --drivers 3 --duration 60   # a quick look
    python benchmarks/bench_framework.py --scale --scale-factor 4 --n-tops 10 12 14   # growth
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
from sklearn.model_selection import PredefinedSplit
from threadpoolctl import threadpool_limits

from skhmmgmr import HMMGMRRegressor, select_parameters
from skhmmgmr._core._schema import TARGET
from skhmmgmr.feature_selection import ExhaustiveFeatureSelector, SpearmanSelector
from skhmmgmr.metrics import evaluate_recordings
from skhmmgmr.selection import candidate_subsets
from skhmmgmr.selection._framework_data import sampling_period_of, split_recordings_table
from skhmmgmr.selection._search import _screening
from skhmmgmr.selection._search._score_tables import best_per_recording, rescore_table
from skhmmgmr.selection._sources import source_tables

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


def run_framework(data, estimator, n_jobs, label, save=None, search="full"):
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        report = select_parameters(
            data,
            n_top=10,
            k_max=20,
            n_jobs=n_jobs,
            progress=False,
            estimator=estimator,
            search=search,
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


def _fits(table, keys, refitted=None):
    """``(full fits, screened models)`` of a stage's table: one model per ``keys`` and
    split, screened when the fast search marked it so; ``refitted`` keeps the models (by
    their first key) the stage fitted itself (not read from another stage)."""
    models = table.drop_duplicates([*keys, "fold"])
    if refitted is not None:
        models = models[models[keys[0]].map(_canonical).isin(refitted)]
    if "screened" not in models:
        return len(models), 0
    screened = models["screened"].astype(bool)
    return int((~screened).sum()), int(screened.sum())


def em_fits(report):
    """EM fits per stage of a framework run: ``{stage: (full fits, screened models)}``.

    The exhaustive wrapper's models are in its table; the forward wrapper refits only the
    subsets the exhaustive one did not evaluate; the fast search adds, per split, one joint
    model over all the forward wrapper's columns when that subset is not on its paths (the
    exhaustive wrapper's joint model is its all-top subset); the state sweep fits every K;
    the candidates, the final and the baseline model are fitted in full by both paths.
    """
    tables = report.source_tables
    exhaustive, forward = tables["exhaustive_results"], tables["forward_results"]
    seen = set(exhaustive["subset"].map(_canonical))
    new = set(forward["subset"].map(_canonical)) - seen
    counts = {
        "exhaustive": _fits(exhaustive, ["subset"]),
        "forward": _fits(forward, ["subset"], refitted=new),
        "states": _fits(report.states, ["n_states"]),
    }
    n_folds = forward["fold"].nunique()
    everything = _canonical(report.filter["feature"])
    if "screened" in forward and everything not in set(forward["subset"].map(_canonical)):
        full, screened = counts["forward"]
        counts["forward"] = (full + n_folds, screened)
    candidates = report.candidates[~report.candidates["empty"].astype(bool)]
    counts["candidates, final, baseline"] = (len(candidates) * n_folds + 2, 0)
    return counts


def _candidates_per_trade_off(report):
    """The candidate subsets of every trade-off (not only the framework's): ``{(trade-off,
    name): features}`` from the report's relevance counts."""
    n_recordings = report.states["recording"].nunique()
    sources = [s for s in report.relevance.index.unique(0) if s != "combined"]
    subsets = {}
    for label in report.relevance.columns:
        relevance = {}
        for source in sources:
            relevance[source] = report.relevance.loc[source]
            relevance[source].attrs["n_recordings"] = n_recordings
        table = candidate_subsets(relevance, label)
        for name, features in zip(table["name"], table["features"], strict=True):
            subsets[label, name] = _canonical(features)
    return subsets


def compare_searches(full, fast):
    """The answers of the two searches side by side; returns a dict of differences."""
    subsets = _candidates_per_trade_off(full), _candidates_per_trade_off(fast)
    differing = {
        key: sorted(set(subsets[0][key]) ^ set(subsets[1][key]))
        for key in subsets[0]
        if subsets[0][key] != subsets[1].get(key)
    }
    choices = [r.state_choices.set_index("trade_off")["n_states"] for r in (full, fast)]
    k_differing = {t: (int(choices[0][t]), int(choices[1][t])) for t in choices[0].index}
    k_differing = {t: ks for t, ks in k_differing.items() if ks[0] != ks[1]}
    tests = [r.test_summary.set_index("model").loc["final"] for r in (full, fast)]
    accuracy_gap = float(tests[1]["accuracy"] - tests[0]["accuracy"])
    smoothness_gap = float(tests[1]["smoothness"] / tests[0]["smoothness"] - 1.0)
    result = {
        "same_subset": _canonical(full.features) == _canonical(fast.features),
        "same_n_states": int(full.n_states) == int(fast.n_states),
        "subset_full": tuple(full.features),
        "subset_fast": tuple(fast.features),
        "n_states": (int(full.n_states), int(fast.n_states)),
        "candidates_differing": differing,
        "n_candidates": len(subsets[0]),
        "k_differing": k_differing,
        "test_accuracy": (float(tests[0]["accuracy"]), float(tests[1]["accuracy"])),
        "test_smoothness": (float(tests[0]["smoothness"]), float(tests[1]["smoothness"])),
        "accuracy_gap_points": accuracy_gap,
        "smoothness_gap_share": smoothness_gap,
        "within_tolerance": abs(accuracy_gap) <= 0.1 and abs(smoothness_gap) <= 0.01,
    }
    print(
        f"  same subset: {result['same_subset']}; K full/fast {result['n_states']}; candidate "
        f"subsets differing: {len(differing)} of {len(subsets[0])} (trade-off x candidate); "
        f"K per trade-off differing: {k_differing or 'none'}"
    )
    if not result["same_subset"]:
        print(f"    full: {', '.join(full.features)}")
        print(f"    fast: {', '.join(fast.features)}")
    for key, features in differing.items():
        print(f"    {key[0]} {key[1]}: {', '.join(features)} in one path only")
    print(
        f"  test, final model: accuracy full/fast {tests[0]['accuracy']:.2f}/"
        f"{tests[1]['accuracy']:.2f} % ({accuracy_gap:+.2f} pt), smoothness "
        f"{tests[0]['smoothness']:.3f}/{tests[1]['smoothness']:.3f} Nm/s "
        f"({smoothness_gap:+.1%}); within 0.1 pt / 1 %: {result['within_tolerance']}"
    )
    return result


def run_searches(seeds, *, n_drivers, duration, n_jobs, cache, save=None, full_tables=None):
    """``search="full"`` and ``search="fast"`` side by side on the data of every seed;
    ``full_tables``: a folder of an earlier run's saved tables (``--save``), whose full
    search (``full_search_seed_<seed>.joblib``) is read instead of run again (the full path
    does not depend on the fast one; its times are those of that run)."""
    results = {}
    for seed in seeds:
        data = thesis_protocol(n_drivers, duration=duration, seed=seed, cache=cache)
        print(f"seed {seed}: {n_drivers} drivers (seeds {data.attrs['seeds']}), {len(data):,} rows")
        reports, walls = {}, {}
        for search in ("full", "fast"):
            label = f"{search} search seed {seed}"
            if search == "full" and full_tables:
                path = os.path.join(full_tables, f"full_search_seed_{seed}.joblib")
                reports[search], walls[search] = load_tables(path)
                print(f"{label}: tables of an earlier run ({walls[search]:.0f} s wall), {path}")
                continue
            estimator = HMMGMRRegressor(random_state=0)
            reports[search], walls[search] = run_framework(
                data, estimator, n_jobs, label, save, search=search
            )
        full, fast = reports["full"], reports["fast"]
        print(f"  ratio full/fast: {walls['full'] / walls['fast']:.2f}x")
        for stage in full.timings:
            print(
                f"    {stage:<26} full {full.timings[stage]:6.0f} s  fast "
                f"{fast.timings[stage]:6.0f} s  ratio "
                f"{full.timings[stage] / max(fast.timings[stage], 1e-9):5.2f}x"
            )
        fits = {search: em_fits(report) for search, report in reports.items()}
        print(
            f"  EM fits per stage, full fits + screened models (screened: "
            f"{_screening.EXHAUSTIVE_ITERATIONS} EM iterations per exhaustive subset, "
            f"{_screening.SUBSET_ITERATIONS} per forward subset, "
            f"{_screening.STATE_ITERATIONS} after each split of a state), and the ratio of "
            "the full fits:"
        )
        for stage in fits["full"]:
            (a, b), (c, d) = fits["full"][stage], fits["fast"][stage]
            print(
                f"    {stage:<26} full {a:5d} + {b:4d}   fast {c:5d} + {d:4d}   "
                f"{a / max(c, 1):6.1f}x"
            )
        results[seed] = {
            "wall_s": walls,
            "ratio": walls["full"] / walls["fast"],
            "stages_s": {search: report.timings for search, report in reports.items()},
            "em_fits": fits,
            "comparison": compare_searches(full, fast),
        }
    return results


def exhaustive_stage(data, n_top, n_jobs, search):
    """The exhaustive stage alone, as the framework runs it (K=2 on the Spearman filter's top
    ``n_top`` features of the training recordings, validated on the validation ones): wall
    seconds and ``(full fits, screened models)``."""
    X, y, groups, split = split_recordings_table(data, None, None, TARGET)
    train, searched = split == "train", np.isin(split, ["train", "validation"])
    top = SpearmanSelector(k=n_top).fit(X[train], y[train], groups[train]).get_support()
    X_s = X.loc[searched, X.columns[top]].reset_index(drop=True)
    cv = PredefinedSplit(np.where(split[searched] == "validation", 0, -1))
    selector = ExhaustiveFeatureSelector(
        HMMGMRRegressor(n_states=2, random_state=0),
        cv=cv,
        sampling_period=sampling_period_of(data, None),
        n_jobs=n_jobs,
        search=search,
    )
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        selector.fit(X_s, y[searched], groups=groups[searched])
    return time.perf_counter() - start, _fits(selector.results_, ["subset"])


def run_scale(*, n_drivers, duration, factor, n_tops, n_jobs, cache, seed=0, parts=None):
    """How the time of both searches grows with the rows (the framework on ``n_drivers`` and
    on ``factor`` times as many drivers) and with the candidate features (the exhaustive
    stage on the top ``n`` of every ``n_tops``): a table with one row per run."""
    parts = parts or ("rows", "features")
    rows = []

    def report(row):
        rows.append(row)
        print(
            f"  {row['part']:<8} {row['drivers']:3d} drivers {row['rows']:>10,} rows "
            f"{row['candidates']:3d} candidates  {row['search']:<4}  {row['seconds']:7.0f} s  "
            f"EM fits {row['full_fits']} + {row['screened']} screened",
            flush=True,
        )

    base = thesis_protocol(n_drivers, duration=duration, seed=seed, cache=cache)
    for search in ("fast", "full"):  # compiled (numba's cache) and workers started, untimed
        exhaustive_stage(base, 3, n_jobs, search)
    if "features" in parts:
        print(f"exhaustive stage alone, {n_drivers} drivers, {len(base):,} rows:")
        for n_top in n_tops:
            for search in ("fast", "full"):
                seconds, (full, screened) = exhaustive_stage(base, n_top, n_jobs, search)
                report(
                    {
                        "part": "features",
                        "drivers": n_drivers,
                        "rows": len(base),
                        "candidates": n_top,
                        "search": search,
                        "seconds": seconds,
                        "full_fits": full,
                        "screened": screened,
                    }
                )
    if "rows" in parts:
        print("the framework (top 10, forward over all candidates, K = 1..20):")
        for drivers in (n_drivers, factor * n_drivers):
            data = base if drivers == n_drivers else None
            if data is None:
                data = thesis_protocol(drivers, duration=duration, seed=seed, cache=cache)
            for search in ("fast", "full"):
                label = f"{search} search, {drivers} drivers"
                report_, wall = run_framework(
                    data, HMMGMRRegressor(random_state=0), n_jobs, label, search=search
                )
                fits = em_fits(report_)
                report(
                    {
                        "part": "rows",
                        "drivers": drivers,
                        "rows": len(data),
                        "candidates": int(report_.filter.shape[0]),
                        "search": search,
                        "seconds": wall,
                        "full_fits": sum(f for f, _ in fits.values()),
                        "screened": sum(s for _, s in fits.values()),
                    }
                )
    table = pd.DataFrame(rows)
    print(table.to_string(index=False))
    return table


def load_tables(path):
    """The tables of a run saved with ``--save`` (e.g. ``reference_path.joblib``), as a
    report-like namespace, and that run's wall time."""
    tables = joblib.load(path)
    wall = tables.pop("wall_s", None)
    if wall is None:
        wall = sum(tables["timings"].values())
    if "sources" in tables:  # the report's properties, from the fitted sources
        source = {}
        for name, selector in tables["sources"].items():
            source.update(source_tables(name, selector))
        tables.setdefault("source_tables", source)
        tables.setdefault("exhaustive", source.get("exhaustive_results"))
        tables.setdefault("forward_paths", source.get("forward_paths"))
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
    parser.add_argument(
        "--searches",
        action="store_true",
        help='only search="full" against search="fast", side by side per seed',
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="with --searches")
    parser.add_argument(
        "--scale",
        action="store_true",
        help="only both searches as the rows and the candidate features grow",
    )
    parser.add_argument("--scale-factor", type=int, default=4, help="with --scale: x drivers")
    parser.add_argument("--n-tops", type=int, nargs="+", default=[10, 12, 14], help="with --scale")
    parser.add_argument(
        "--scale-parts", nargs="+", choices=["rows", "features"], default=None, help="with --scale"
    )
    parser.add_argument(
        "--full-tables",
        default=None,
        help="with --searches: read the full search of an earlier --save folder, not run it",
    )
    parser.add_argument(
        "--screening-error",
        type=float,
        default=None,
        help="the bound of a screened score's relative error (e.g. 0.0025) under which the "
        "fast search fits in full what can change a relevance decision (default: off)",
    )
    parser.add_argument(
        "--exhaustive-iterations",
        type=int,
        default=None,
        help="EM iterations of a feature subset the exhaustive wrapper screens from the joint "
        f"model's marginal (default: {_screening.EXHAUSTIVE_ITERATIONS}; 0: the marginal "
        "scored as it is)",
    )
    parser.add_argument(
        "--subset-iterations",
        type=int,
        default=None,
        help="the same for the forward wrapper's subsets "
        f"(default: {_screening.SUBSET_ITERATIONS})",
    )
    parser.add_argument("--skip-reference", action="store_true")
    parser.add_argument("--skip-peer", action="store_true")
    parser.add_argument("--save", default=None, help="directory for the selection tables")
    parser.add_argument(
        "--reference-tables",
        default=None,
        help="compare with the saved tables of an earlier reference run instead of running it",
    )
    args = parser.parse_args(argv)
    _screening.SCREENING_ERROR = args.screening_error
    if args.exhaustive_iterations is not None:
        _screening.EXHAUSTIVE_ITERATIONS = args.exhaustive_iterations
    if args.subset_iterations is not None:
        _screening.SUBSET_ITERATIONS = args.subset_iterations
    if args.scale:
        return run_scale(
            n_drivers=args.drivers,
            duration=args.duration,
            factor=args.scale_factor,
            n_tops=args.n_tops,
            n_jobs=args.n_jobs,
            cache=args.cache,
            seed=args.seeds[0],
            parts=args.scale_parts,
        )
    if args.searches:
        return run_searches(
            args.seeds,
            n_drivers=args.drivers,
            duration=args.duration,
            n_jobs=args.n_jobs,
            cache=args.cache,
            save=args.save,
            full_tables=args.full_tables,
        )
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
