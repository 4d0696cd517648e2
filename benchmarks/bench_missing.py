"""Missing inputs: the model's own marginalisation against imputation, side by side.

Simulated drivers (``make_driving_protocol``: the three driver styles, measured sensors,
20 Hz), five of the 18 candidate features, K=5. Missing values are made in the inputs of the
training AND the test recordings, in two scenarios:

(a) ``random``: 10 % of the input values missing at random, each value independently;
(b) ``outages``: in every 30 s of a recording one input (drawn at random) is missing for 2 s
    (at a random place within the 30 s).

Methods, all ``HMMGMRRegressor(n_states=5, random_state=0)`` fitted on the training recordings
and scored on the test recordings:

- ``complete``: the model on the complete data (no value missing: the reference);
- ``marginalize``: ``missing_values="marginalize"`` (the model conditions on the observed
  inputs of every row, in fit and predict);
- ``carry-forward``: ``missing_values="carry_forward"`` (fitted as ``marginalize``, and
  prediction reads a missing input through its last observed value, as a noisy observation
  whose variance is the input's variogram at that age);
- ``forward-fill``: every missing value replaced by the last observed value of its recording
  (a recording's leading gap by its first observed value);
- ``mean``: ``Pipeline(SimpleImputer(strategy="mean"), HMMGMRRegressor(...))``;
- ``iterative``: ``Pipeline(IterativeImputer(random_state=0), HMMGMRRegressor(...))``.

The pipelines receive the recording ids through metadata routing. Reported per scenario and
method: mean and worst-recording accuracy (``skhmmgmr.metrics``, per test recording) and the
wall time of ``fit`` (imputer included). Run with::

    python benchmarks/bench_missing.py           # thesis scale: 12/0/6 five-minute sections
                                                 # per driver (about 2 minutes on 2 cores)
    python benchmarks/bench_missing.py --quick   # 1-minute sections (about 1 minute)
"""

import argparse
import time
import warnings

import numpy as np
import pandas as pd
import sklearn
from sklearn.exceptions import ConvergenceWarning
from sklearn.experimental import enable_iterative_imputer  # noqa: F401
from sklearn.impute import IterativeImputer, SimpleImputer
from sklearn.pipeline import make_pipeline

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_driving_protocol
from skhmmgmr.metrics import evaluate_recordings

FEATURES = [
    "steering_wheel_angle",
    "yaw_rate",
    "heading_deviation_10m",
    "heading_deviation_30m",
    "lateral_velocity",
]
TARGET = "driver_torque"
SAMPLING_RATE = 20.0
N_STATES = 5


def _parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1-minute sections")
    parser.add_argument("--rate", type=float, default=0.10, help="scenario (a): missing share")
    parser.add_argument("--outage", type=float, default=2.0, help="scenario (b): seconds")
    parser.add_argument("--period", type=float, default=30.0, help="scenario (b): seconds")
    parser.add_argument("--random-state", type=int, default=0)
    parser.add_argument("--cache", default=None, help="simulator cache directory")
    return parser.parse_args(argv)


def load(args):
    frame = make_driving_protocol(
        n_validation=0,
        duration=60.0 if args.quick else 300.0,
        sampling_rate=SAMPLING_RATE,
        random_state=args.random_state,
        n_jobs=-1,
        cache=args.cache,
    )
    return {
        split: frame[frame["split"] == split].reset_index(drop=True) for split in ("train", "test")
    }


def random_gaps(X, groups, rng, args):
    return rng.random(X.shape) < args.rate


def outages(X, groups, rng, args):
    mask = np.zeros(X.shape, dtype=bool)
    period, length = int(args.period * SAMPLING_RATE), int(args.outage * SAMPLING_RATE)
    for recording in pd.unique(groups):
        rows = np.flatnonzero(groups == recording)
        for first in range(0, rows.size - length + 1, period):
            start = first + rng.integers(0, min(period, rows.size - first) - length + 1)
            mask[rows[start : start + length], rng.integers(X.shape[1])] = True
    return mask


SCENARIOS = {"random": random_gaps, "outages": outages}


def forward_filled(X, groups):
    frame = pd.DataFrame(X).groupby(groups, sort=False)
    return frame.ffill().groupby(groups, sort=False).bfill().to_numpy()


def model(**params):
    return HMMGMRRegressor(n_states=N_STATES, random_state=0, **params)


def methods():
    """name -> (estimator, how the inputs with missing values are given to it)."""
    return {
        "complete": (model(), "complete"),
        "marginalize": (model(missing_values="marginalize"), "missing"),
        "carry-forward": (model(missing_values="carry_forward"), "missing"),
        "forward-fill": (model(), "forward-fill"),
        "mean": (make_pipeline(SimpleImputer(strategy="mean"), model()), "missing"),
        "iterative": (make_pipeline(IterativeImputer(random_state=0), model()), "missing"),
    }


def run(data, scenario, rng, args):
    sets = {}
    for split, frame in data.items():
        X, groups = frame[FEATURES].to_numpy(), frame["recording"].to_numpy()
        mask = SCENARIOS[scenario](X, groups, rng, args)
        gappy = np.where(mask, np.nan, X)
        sets[split] = {
            "complete": X,
            "missing": gappy,
            "forward-fill": forward_filled(gappy, groups),
            "groups": groups,
            "y": frame[TARGET].to_numpy(),
            "share": mask.mean(),
        }
    train, test = sets["train"], sets["test"]
    rows = []
    for name, (estimator, inputs) in methods().items():
        start = time.perf_counter()
        with warnings.catch_warnings():
            # IterativeImputer's own stopping rule (max_iter=10) is not always reached
            warnings.filterwarnings("ignore", "\\[IterativeImputer\\]", ConvergenceWarning)
            estimator.fit(train[inputs], train["y"], groups=train["groups"])
        fit_time = time.perf_counter() - start
        pred = estimator.predict(test[inputs], groups=test["groups"])
        table = evaluate_recordings(
            test["y"], pred, groups=test["groups"], sampling_period=1 / SAMPLING_RATE
        )
        rows.append(
            {
                "scenario": scenario,
                "method": name,
                "mean accuracy [%]": table["accuracy"].mean(),
                "worst recording [%]": table["accuracy"].min(),
                "fit [s]": fit_time,
            }
        )
        print(f"  {scenario:<8} {name:<13} done in {fit_time:6.1f} s", flush=True)
    return pd.DataFrame(rows), train["share"], test["share"]


def main(argv=None):
    args = _parse(argv)
    sklearn.set_config(enable_metadata_routing=True)
    start = time.perf_counter()
    data = load(args)
    n_train, n_test = (data[s]["recording"].nunique() for s in ("train", "test"))
    print(
        f"{n_train} training and {n_test} test recordings, {len(data['train'])} and "
        f"{len(data['test'])} rows; features {', '.join(FEATURES)}; K={N_STATES}; "
        f"simulated in {time.perf_counter() - start:.0f} s"
    )
    rng = np.random.default_rng(args.random_state)
    tables = []
    for scenario in SCENARIOS:
        table, train_share, test_share = run(data, scenario, rng, args)
        print(
            f"  {scenario}: {100 * train_share:.1f} % of the training inputs and "
            f"{100 * test_share:.1f} % of the test inputs missing"
        )
        tables.append(table)
    table = pd.concat(tables, ignore_index=True)
    print()
    print(table.to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    print()
    model_methods = ["marginalize", "carry-forward"]
    for scenario, part in table.groupby("scenario", sort=False):
        scores = part.set_index("method")["mean accuracy [%]"]
        best_imputation = scores.drop(["complete", *model_methods]).idxmax()
        for method in model_methods:
            gap = scores["complete"] - scores[method]
            ahead = scores[method] - scores[best_imputation]
            print(
                f"{scenario}: {method} is {gap:.2f} points below the complete-data model "
                f"(target: at most 1) and {ahead:+.2f} points against the best imputation "
                f"({best_imputation}; target: ahead) -> "
                f"{'[ok]' if gap <= 1 and ahead > 0 else '[MISSED]'}"
            )
    return table


if __name__ == "__main__":
    main()
