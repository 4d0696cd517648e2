"""The framework's screening tolerance: time per stage and the selections, strict against screened.

:func:`skhmmgmr.select_parameters` fits thousands of K=2 models only to rank feature subsets
(the exhaustive and forward wrappers). ``screening_tol`` stops their EM at a looser tolerance
while the candidate comparison, the state sweep and the final model keep the estimator's own.
For each data seed this script runs the framework twice on the same data, strict
(``screening_tol=None``: ``tol=1e-4`` everywhere) and screened, and prints

- the wall time of every stage, side by side, and their ratio;
- whether every selection agrees: the chosen subset and K, the candidate subsets, the feature
  relevance, the number of states each trade-off's rule picks, the test scores.

Data: the benchmarks' thesis protocol (7 drivers, 12 training, 6 validation and 6 test
sections of 5 minutes per driver at 20 Hz; see ``_data.thesis_protocol``), one protocol per
seed. Run on an otherwise idle machine::

    python benchmarks/bench_screening.py                        # 3 seeds, about 30 minutes
    python benchmarks/bench_screening.py --drivers 3 --duration 60 --seeds 0   # a quick look
"""

import argparse
import os
import time
import warnings

import numpy as np
import pandas as pd
from _data import thesis_protocol
from sklearn.exceptions import ConvergenceWarning

from skhmmgmr import HMMGMRRegressor, select_parameters

DEFAULT_CACHE = os.path.join(os.path.expanduser("~"), ".cache", "skhmmgmr-benchmarks")


def run_path(data, screening_tol, n_jobs):
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        report = select_parameters(
            data,
            n_top=10,
            k_max=20,
            n_jobs=n_jobs,
            progress=False,
            estimator=HMMGMRRegressor(random_state=0),
            screening_tol=screening_tol,
        )
    return report, time.perf_counter() - start


def agreement(strict, screened):
    """Which selections of the two runs agree (bool per selection) and the largest
    difference of the feature relevance."""
    relevance_gap = float(
        np.nanmax(np.abs(strict.relevance.to_numpy() - screened.relevance.to_numpy()))
    )
    candidates = strict.candidates.set_index("name")["features"].map(tuple)
    other = screened.candidates.set_index("name")["features"].map(tuple)
    choices = strict.state_choices.set_index("trade_off")["n_states"]
    other_choices = screened.state_choices.set_index("trade_off")["n_states"]
    moved = choices[choices != other_choices.reindex(choices.index)]
    test_gap = (
        (strict.test_summary["performance_score"] - screened.test_summary["performance_score"])
        .abs()
        .max()
    )
    return {
        "subset": strict.features == screened.features,
        "K": strict.n_states == screened.n_states,
        "candidates": candidates.equals(other.reindex(candidates.index)),
        "relevance_max_gap": relevance_gap,
        "state_rule_moved": ", ".join(f"{t}: {choices[t]}->{other_choices[t]}" for t in moved.index)
        or "none",
        "test_score_gap": float(test_gap),
    }


def run(seeds, *, n_drivers, duration, screening_tol, n_jobs, cache):
    rows, checks = [], []
    for seed in seeds:
        data = thesis_protocol(n_drivers, duration=duration, seed=seed, cache=cache)
        strict, strict_wall = run_path(data, None, n_jobs)
        screened, screened_wall = run_path(data, screening_tol, n_jobs)
        for stage in strict.timings:
            rows.append(
                {
                    "seed": seed,
                    "stage": stage,
                    "strict_s": strict.timings[stage],
                    "screened_s": screened.timings[stage],
                }
            )
        rows.append(
            {"seed": seed, "stage": "wall", "strict_s": strict_wall, "screened_s": screened_wall}
        )
        seed_rows = pd.DataFrame(rows[-len(strict.timings) - 1 :])
        print(seed_rows.round(2).to_string(index=False), flush=True)  # kept if a later seed fails
        check = {"seed": seed, **agreement(strict, screened)}
        check["subset_K"] = f"{'+'.join(strict.features)} K={strict.n_states}"
        checks.append(check)
        print(
            f"seed {seed}: strict {strict_wall:.0f} s, screened {screened_wall:.0f} s; {check}",
            flush=True,
        )
    table = pd.DataFrame(rows)
    table["ratio"] = table["screened_s"] / table["strict_s"]
    with pd.option_context("display.width", 160, "display.max_colwidth", 80):
        print(f"\nTime per stage [s], strict (tol=1e-4) and screening_tol={screening_tol}")
        print(table.round(2).to_string(index=False))
        print("\nSelections, screened against strict")
        print(pd.DataFrame(checks).to_string(index=False))
    walls = table[table["stage"] == "wall"]
    print(
        f"\nwall: strict {walls['strict_s'].mean():.0f} s, screened "
        f"{walls['screened_s'].mean():.0f} s on average (target 300 s at the thesis' scale); "
        f"every selection equal on {np.mean([c['subset'] and c['K'] for c in checks]):.0%} "
        "of the seeds"
    )
    return table, pd.DataFrame(checks)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 100, 200])
    parser.add_argument("--drivers", type=int, default=7)
    parser.add_argument("--duration", type=float, default=300.0, help="seconds per section")
    parser.add_argument("--screening-tol", type=float, default=1e-3)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--cache", default=DEFAULT_CACHE, help="simulator cache directory")
    args = parser.parse_args(argv)
    return run(
        args.seeds,
        n_drivers=args.drivers,
        duration=args.duration,
        screening_tol=args.screening_tol,
        n_jobs=args.n_jobs,
        cache=args.cache,
    )


if __name__ == "__main__":
    main()
