"""The derived inputs chosen by the data against an expert's linear model and boosting, per car.

For every car (``--vehicles``: ``default``, the simulator's reference car, or an int seed of
``draw_vehicle``; cars 2 and 10 have sharp friction, bands of 2.3 and 2.2 mrad/s), sampling
rate and data seed, on the simulator's protocol (three driver styles; 36 training, 18
validation and 18 test recordings of ``--duration`` seconds, measured sensors), fitted on the
training recordings and scored on the test recordings:

- ``HistGradientBoostingRegressor(max_iter=300)`` on the 18 features (default boosting);
- ordinary least squares on the 18 features (``OLS``), and on the 18 features plus the
  friction basis ``tanh(steering_wheel_velocity / w)`` for w in 3, 6, 12, 25 and 50 mrad/s
  (``OLS + basis``: the model a vehicle engineer writes by hand, issue #53), and on the 18
  features plus the friction and hysteresis inputs the pipeline chose from the data
  (``OLS + chosen``: the same linear model on the data's own widths);
- ``make_torque_pipeline`` with its defaults (the friction inputs, the velocity filter and
  the read-out chosen in ``fit``), the number of states chosen among ``--states`` by mean
  validation accuracy; the chosen friction widths, filter and read-out are printed.

Printed per car, rate and seed: mean and worst-recording test accuracy (%) and roughness (std
of the estimate's time derivative, Nm/s) of every model and of the measured torque, and the
targets of issue #53 for the pipeline: mean and worst accuracy at least those of ``OLS +
basis`` and of boosting, roughness at most the measured torque's + 1 %. Run with::

    python benchmarks/bench_derived_inputs.py        # 5 cars, 20 and 100 Hz, seeds 0 1 2
    python benchmarks/bench_derived_inputs.py --vehicles 2 --rates 20 --seeds 0 --states 5
"""

import argparse
import itertools
import time
import warnings

import numpy as np
import pandas as pd
import sklearn
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.linear_model import LinearRegression
from threadpoolctl import threadpool_limits

from skhmmgmr import make_torque_pipeline
from skhmmgmr.datasets import FEATURE_NAMES, VehicleParameters, draw_vehicle, make_driving_protocol
from skhmmgmr.metrics._table import recording_metrics

FEATURES = list(FEATURE_NAMES)
#: The friction basis of the expert's linear model [rad/s] (issue #53).
EXPERT_WIDTHS = (0.003, 0.006, 0.012, 0.025, 0.05)
BOOSTING = "HistGradientBoosting"
OLS, OLS_BASIS, OLS_CHOSEN = "OLS", "OLS + basis", "OLS + chosen"
#: The roughness the pipeline may have above the measured torque's.
ROUGHNESS_MARGIN = 1.01


def scores(y, pred, groups, rate):
    """Mean and worst-recording accuracy (%) and mean roughness (Nm/s)."""
    metrics = recording_metrics(y, pred, groups=groups, sampling_period=1.0 / rate)
    accuracy = metrics.accuracy[:, 0]
    return accuracy.mean(), accuracy.min(), metrics.smoothness[:, 0].mean()


def with_basis(part):
    """The 18 features and the expert's friction basis."""
    velocity = part["steering_wheel_velocity"].to_numpy()
    basis = [np.tanh(velocity / width) for width in EXPERT_WIDTHS]
    return np.column_stack([part[FEATURES].to_numpy(), *basis])


def with_chosen(features, part):
    """The 18 features and the friction and hysteresis inputs ``features`` (the pipeline's
    fitted ``SteeringFeatures``) derives from them."""
    derived = features.transform(part[FEATURES], groups=part["recording"].to_numpy())
    chosen = [c for c in derived.columns if c.startswith(("steering_friction", "steering_hyst"))]
    return derived[FEATURES + chosen].to_numpy()


def predict(model, part, **kwargs):
    with sklearn.config_context(enable_metadata_routing=True):
        return model.predict(part[FEATURES], groups=part["recording"].to_numpy(), **kwargs)


def fit(model, part):
    with sklearn.config_context(enable_metadata_routing=True):
        return model.fit(
            part[FEATURES], part["driver_torque"].to_numpy(), groups=part["recording"].to_numpy()
        )


def choose_states(make, train, validation, rate, states):
    """The pipeline with the number of states of best mean validation accuracy."""
    best = None
    for k in states:
        model = fit(make(k), train)
        accuracy = scores(
            validation["driver_torque"].to_numpy(),
            predict(model, validation),
            validation["recording"].to_numpy(),
            rate,
        )[0]
        if best is None or accuracy > best[0]:
            best = (accuracy, k, model)
    return best[1], best[2]


def describe(features, readout, period):
    """The pipeline's chosen friction widths, velocity filter and read-out, in words."""
    widths = features.friction_velocity_
    if widths is None:
        friction = "no friction input"
    else:
        widths = widths if isinstance(widths, tuple) else (widths,)
        friction = "widths " + ", ".join(f"{w * 1000:.3g}" for w in widths) + " mrad/s"
    radii = features.friction_angle_
    if radii:
        friction += ", plays " + ", ".join(f"{r * 1000:.3g}" for r in radii) + " mrad"
        lead = getattr(features, "angle_lead_", None)
        if lead is not None:
            friction += f" led {lead * 1000:g} ms"
    tau = features.velocity_filter_
    velocity = "no filter" if tau is None else f"filter {tau * 1000:g} ms"
    slow = getattr(features, "slow_velocity_filter_", None)
    if slow is not None:
        velocity += f", slow velocity {slow * 1000:g} ms"
    return f"{friction}, {velocity}, read-out {readout * period * 1000:.1f} ms"


def run(vehicle, rate, seed, states, duration, cache):
    """The table of one car, rate and data seed, and the number of targets it misses."""
    data = make_driving_protocol(
        random_state=seed, sampling_rate=rate, duration=duration, cache=cache, vehicle=vehicle
    )
    train, validation, test = (data[data["split"] == s] for s in ("train", "validation", "test"))
    y, groups = test["driver_torque"].to_numpy(), test["recording"].to_numpy()
    target = train["driver_torque"].to_numpy()
    rows = {"measured torque": (np.nan, np.nan, scores(y, y, groups, rate)[2])}
    start = time.perf_counter()
    boosting = HistGradientBoostingRegressor(max_iter=300, random_state=0)
    boosting.fit(train[FEATURES], target)
    rows[BOOSTING] = scores(y, boosting.predict(test[FEATURES]), groups, rate)
    ols = LinearRegression().fit(train[FEATURES].to_numpy(), target)
    rows[OLS] = scores(y, ols.predict(test[FEATURES].to_numpy()), groups, rate)
    expert = LinearRegression().fit(with_basis(train), target)
    rows[OLS_BASIS] = scores(y, expert.predict(with_basis(test)), groups, rate)
    period = 1.0 / rate
    k, pipeline = choose_states(
        lambda k: make_torque_pipeline(k, sampling_period=period, random_state=0),
        train,
        validation,
        rate,
        states,
    )
    chosen = LinearRegression().fit(with_chosen(pipeline[0], train), target)
    rows[OLS_CHOSEN] = scores(y, chosen.predict(with_chosen(pipeline[0], test)), groups, rate)
    name = f"pipeline K={k}"
    rows[name] = scores(y, predict(pipeline, test), groups, rate)
    car = "default" if vehicle is None else str(vehicle)
    band = (VehicleParameters() if vehicle is None else draw_vehicle(vehicle)).friction_velocity
    print(
        f"\ncar {car} (friction band {band * 1000:.3g} mrad/s), {rate:g} Hz, seed {seed}: the "
        f"pipeline chose {describe(pipeline[0], pipeline[-1].output_smoothing_, period)}; "
        f"{time.perf_counter() - start:.0f} s"
    )
    table = pd.DataFrame(rows, index=["accuracy %", "worst %", "roughness Nm/s"]).T
    print(table.to_string(float_format=lambda v: f"{v:.2f}", na_rep=""))
    ours, measured = table.loc[name], table.loc["measured torque", "roughness Nm/s"]
    checks = []
    for other in (OLS_BASIS, BOOSTING):
        theirs = table.loc[other]
        checks += [
            (f"mean accuracy >= {other}'s", ours["accuracy %"] >= theirs["accuracy %"]),
            (f"worst recording >= {other}'s", ours["worst %"] >= theirs["worst %"]),
        ]
    limit = ROUGHNESS_MARGIN * measured
    checks.append(("roughness <= measured + 1 %", ours["roughness Nm/s"] <= limit))
    for what, ok in checks:
        print(f"  [{'ok' if ok else 'MISSED'}] pipeline: {what}")
    table["vehicle"], table["rate"], table["seed"], table["model"] = car, rate, seed, table.index
    table.loc[name, "model"] = "pipeline"
    table.loc[name, "chosen"] = describe(pipeline[0], pipeline[-1].output_smoothing_, period)
    table.loc[name, "K"] = k
    return table, sum(not ok for _, ok in checks)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", nargs="+", default=["default", "0", "2", "4", "10"])
    parser.add_argument("--rates", type=float, nargs="+", default=[20.0, 100.0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--states", type=int, nargs="+", default=[5, 8])
    parser.add_argument("--duration", type=float, default=120.0, help="seconds per recording")
    parser.add_argument("--cache", default=None, help="folder caching the simulated data")
    parser.add_argument("--output", default=None, help="CSV file of every table")
    args = parser.parse_args()
    warnings.filterwarnings("ignore", category=UserWarning)
    tables, missed = [], 0
    with threadpool_limits(1):
        for seed, rate, vehicle in itertools.product(args.seeds, args.rates, args.vehicles):
            car = None if vehicle == "default" else int(vehicle)
            table, misses = run(car, rate, seed, args.states, args.duration, args.cache)
            tables.append(table)
            missed += misses
            if args.output:  # every table so far, so that a long run keeps what it measured
                pd.concat(tables).to_csv(args.output)
    print(f"\n{missed} target(s) missed")


if __name__ == "__main__":
    main()
