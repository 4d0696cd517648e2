"""Adapting a generic model to a new driver: ``HMMGMRRegressor.adapt`` against its peers.

A generic HMM-GMR is fitted on the training sections of two simulated drivers; a third driver
gives a few minutes of adaptation data (its first training sections) and its test sections.
On the new driver's test sections the table compares the generic model, its MAP adaptations
(means; means, covariances and transitions; several relevance factors) and a model fitted
from scratch on the adaptation data alone. Run with::

    python benchmarks/bench_adapt.py               # about a minute on 2 cores
    python benchmarks/bench_adapt.py --minutes 1 2 4
"""

import argparse
import copy
import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import make_driving_protocol
from skhmmgmr.metrics import accuracy_score, smoothness_score

FEATURES = ["steering_wheel_angle", "yaw_rate", "heading_deviation_30m", "road_curvature_30m"]
RATE = 20.0
SECTION = 60.0  # seconds per simulated section


def arrays(frame):
    return (
        frame[FEATURES].to_numpy(),
        frame["driver_torque"].to_numpy(),
        frame["recording"].to_numpy(),
    )


def table_row(name, model, test):
    X, y, groups = test
    estimate = model.predict(X, groups=groups)
    accuracy = accuracy_score(y, estimate, groups=groups)
    smoothness = smoothness_score(estimate, sampling_period=1.0 / RATE, groups=groups)
    print(f"{name:<34} {accuracy:>12.1f} {smoothness:>18.2f}")


def run(generic_drivers, new_driver, minutes, n_states, seed):
    sections = {"n_train_per_setting": 1, "n_validation": 0, "n_test": 3}
    data = make_driving_protocol(
        (*generic_drivers, new_driver),
        duration=SECTION,
        sampling_rate=RATE,
        random_state=seed,
        **sections,
    )
    train = data[data["split"] == "train"]
    new = data[data["driver"] == new_driver]
    generic = HMMGMRRegressor(n_states=n_states, random_state=seed)
    generic.fit(*arrays(train[train["driver"] != new_driver]))
    test = arrays(new[new["split"] == "test"])
    new_train = new[new["split"] == "train"]
    recordings = list(dict.fromkeys(new_train["recording"]))
    print(f"{'model':<34} {'accuracy [%]':>12} {'smoothness [Nm/s]':>18}")
    table_row("generic (no adaptation)", generic, test)
    for n_minutes in minutes:
        kept = recordings[: max(1, int(round(n_minutes * 60.0 / SECTION)))]
        adaptation = arrays(new_train[new_train["recording"].isin(kept)])
        label = f"{len(kept) * SECTION / 60:.0f} min"
        for parameters in ("m", "mvt"):
            for relevance in (4.0, 16.0, 64.0):
                model = copy.deepcopy(generic).adapt(
                    *adaptation, relevance=relevance, parameters=parameters
                )
                table_row(f"{label}: adapt {parameters!r}, r={relevance:g}", model, test)
        scratch = HMMGMRRegressor(n_states=n_states, random_state=seed).fit(*adaptation)
        table_row(f"{label}: fitted from scratch", scratch, test)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generic", nargs="+", default=["defensive", "aggressive"])
    parser.add_argument("--new-driver", default="novice")
    parser.add_argument("--minutes", nargs="+", type=float, default=[1.0, 3.0])
    parser.add_argument("--n-states", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        np.seterr(all="ignore")
        run(tuple(args.generic), args.new_driver, args.minutes, args.n_states, args.seed)


if __name__ == "__main__":
    main()
