"""Torque ahead: accuracy and smoothness of estimates of the driver torque ``h`` seconds ahead.

Simulated drivers (``make_driving_protocol`` with short sections at 20 Hz), a few features
including the road preview (heading deviation and curvature 30 m ahead). For every horizon
``h`` in {0, 0.25, 0.5, 1.0} s the target is the torque ``h`` s ahead within every recording
(``skhmmgmr.datasets.shift_target``; the last ``h`` s of a recording have no target and are
left out), and five estimators are compared on the test recordings:

- ``hold``: the current HMM-GMR estimate (``predict``), held as the forecast;
- ``ahead marginal``: ``predict_ahead(steps, state_output="marginal")`` of the same model
  (``alpha_t A^h`` mixing the state output means, the HMM's own forecast);
- ``ahead conditional``: ``predict_ahead(steps, state_output="conditional")`` (the state
  conditional means given the current inputs);
- ``HMM-GMR shifted``: an HMM-GMR fitted on the shifted target;
- ``RidgeCV shifted``: a linear model of the shifted target on the current features.

Run with::

    python benchmarks/bench_ahead.py                # about 30 s on 2 cores
    python benchmarks/bench_ahead.py --duration 60  # quicker
"""

import argparse
import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import RidgeCV

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_driving_protocol, shift_target
from skhmmgmr.metrics import accuracy_score, smoothness_score

FEATURES = [
    "steering_wheel_angle",
    "yaw_rate",
    "lateral_deviation_0m",
    "heading_deviation_30m",
    "road_curvature_30m",
]
HORIZONS = (0.0, 0.25, 0.5, 1.0)
RATE = 20.0


def split(data, name):
    part = data[data["split"] == name]
    return part[FEATURES].to_numpy(), part["driver_torque"].to_numpy(), part["recording"].to_numpy()


def scores(y_true, y_pred, groups):
    accuracy = accuracy_score(y_true, y_pred, groups=groups)
    return accuracy, smoothness_score(y_pred, sampling_period=1.0 / RATE, groups=groups)


def run(drivers, duration, n_states, seed):
    # Per driver: one training section per setting 1-6, two test sections on setting 7.
    sections = {"n_train_per_setting": 1, "n_validation": 0, "n_test": 2}
    data = make_driving_protocol(
        drivers, duration=duration, sampling_rate=RATE, random_state=seed, **sections
    )
    X_train, y_train, g_train = split(data, "train")
    X_test, y_test, g_test = split(data, "test")
    model = HMMGMRRegressor(n_states=n_states, random_state=seed)
    model.fit(X_train, y_train, groups=g_train)
    now = model.predict(X_test, groups=g_test)
    rows = []
    for horizon in HORIZONS:
        steps = int(round(horizon * RATE))
        target = shift_target(y_test, steps, groups=g_test)
        keep = ~np.isnan(target)
        train_target = shift_target(y_train, steps, groups=g_train)
        train_keep = ~np.isnan(train_target)
        shifted = HMMGMRRegressor(n_states=n_states, random_state=seed).fit(
            X_train[train_keep], train_target[train_keep], groups=g_train[train_keep]
        )
        ridge = RidgeCV(alphas=np.logspace(-3, 3, 13)).fit(
            X_train[train_keep], train_target[train_keep]
        )
        estimates = {
            "hold": now,
            "ahead marginal": model.predict_ahead(X_test, steps, groups=g_test),
            "ahead conditional": model.predict_ahead(
                X_test, steps, groups=g_test, state_output="conditional"
            ),
            "HMM-GMR shifted": shifted.predict(X_test, groups=g_test),
            "RidgeCV shifted": ridge.predict(X_test),
        }
        for name, estimate in estimates.items():
            accuracy, smoothness = scores(target[keep], estimate[keep], g_test[keep])
            rows.append((horizon, name, accuracy, smoothness))
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drivers", nargs="+", default=["defensive", "aggressive", "novice"])
    parser.add_argument("--duration", type=float, default=120.0, help="seconds per section")
    parser.add_argument("--n-states", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        rows = run(tuple(args.drivers), args.duration, args.n_states, args.seed)
    print(f"{'h [s]':>6}  {'estimator':<18} {'accuracy [%]':>12} {'smoothness [Nm/s]':>18}")
    for horizon, name, accuracy, smoothness in rows:
        print(f"{horizon:>6.2f}  {name:<18} {accuracy:>12.1f} {smoothness:>18.2f}")


if __name__ == "__main__":
    main()
