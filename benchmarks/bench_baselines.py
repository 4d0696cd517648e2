"""What a user would pick instead: ridge, gradient boosting and the package's models, side by side.

On the simulator's protocol (``make_driving_protocol``: three driver styles, 36 training, 18
validation and 18 test recordings of 5 minutes, measured sensors), for every seed and sampling
rate asked for, every model is fitted on the training recordings and scored on the test
recordings:

- ``RidgeCV`` and ``HistGradientBoostingRegressor(max_iter=300)`` on the 18 features;
- ordinary least squares on the 18 features plus the friction basis
  ``tanh(steering_wheel_velocity / w)`` for w in 3, 6, 12, 25 and 50 mrad/s (``OLS + friction
  basis``: the linear model a vehicle engineer writes by hand, issue #53);
- gradient boosting with causal lags of the last second (every feature 0.1, 0.25, 0.5 and 1 s
  back, within its recording; the first rows repeat the first value);
- ``HMMGMRRegressor`` with 5 and 8 states on the 18 features (the thesis' model);
- ``make_torque_pipeline`` (the steering system's derived inputs, then HMM-GMR) with the number
  of states chosen on the validation recordings by mean accuracy (the friction band and the
  velocity filter chosen in ``fit``, the defaults), then, at that number, that filter or a
  fixed 20 ms one chosen the same way.

Printed per model: mean and worst-recording test accuracy (%), roughness (std of the estimate's
time derivative, Nm/s, the thesis' smoothness), the D.5-normalised performance score at the
thesis' 50/50 trade-off (lower is better; normalised over the models of the table), fit time,
predict throughput (rows/s on the test set) and per-sample streaming latency (median of 2,000
single-row calls: ``FilterStream.update`` for the HMM models, the pipeline's own stream of the
sensed rows for the pipeline; ``predict`` on a one-row array for the others). Then the same
accuracy and roughness per driver style, and the targets of the pipeline against the plain
boosting baseline and against the expert's linear model (mean and worst recording). Run
with::

    python benchmarks/bench_baselines.py                      # seeds 0 1 2, 20 and 100 Hz
    python benchmarks/bench_baselines.py --seeds 0 --rates 20  # one table, about 2 minutes
    python benchmarks/bench_baselines.py --quick               # 1-minute recordings

``--vehicles default 0 1 2`` runs the whole bench in every car given (``default``: the
simulator's reference car, rigid column; an int: the car ``draw_vehicle`` draws from it, the
steering system, torsion bar included, drawn within ``VEHICLE_RANGES``) and ends with the
spread over the cars: per rate and model, the mean accuracy and roughness in each car (over
the seeds), their lowest and highest, and the pipeline's margin over boosting in each car.

``--without-read-out`` adds the pipeline at the same settings with ``output_smoothing=None``
(no read-out: the estimate of the filter itself, rougher and without the read-out's lag) as a
row, and prints its margins over plain boosting per style (informative, not targets): the
price of the default read-out, which keeps the estimate no rougher than the measured torque.

``--output results.json`` saves every per-recording figure. ``--residuals`` prints instead
why the thesis' model loses: the mean test residual of ``HMMGMRRegressor`` (K=5, 18 features)
and of the pipeline (K=5) in bins of lateral acceleration and of steering-wheel velocity, and
the share of the rows and the lateral-acceleration range of each of the model's states (first
seed and rate).
"""

import argparse
import json
import math
import time
import warnings

import numpy as np
import pandas as pd
import sklearn
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.linear_model import LinearRegression, RidgeCV

from skhmmgmr import HMMGMRRegressor, make_torque_pipeline
from skhmmgmr.datasets import (
    FEATURE_NAMES,
    VehicleParameters,
    draw_vehicle,
    make_driving_protocol,
)
from skhmmgmr.metrics import normalize_performance
from skhmmgmr.metrics._table import recording_metrics

FEATURES = list(FEATURE_NAMES)
LAGS_S = (0.1, 0.25, 0.5, 1.0)
STYLES = ("defensive", "aggressive", "novice")
PIPELINE = "make_torque_pipeline"
EXPERT = "OLS + friction basis"
NO_READ_OUT = "no read-out"
#: The friction basis of the expert's linear model [rad/s] (issue #53).
EXPERT_WIDTHS = (0.003, 0.006, 0.012, 0.025, 0.05)


def add_lags(frame, rate):
    """Each feature ``LAGS_S`` seconds back, within its recording."""
    by_recording = frame.groupby("recording", sort=False)[FEATURES]
    first = by_recording.transform("first")
    lagged = {}
    for lag in LAGS_S:
        steps = round(lag * rate)
        shifted = by_recording.shift(steps).fillna(first)
        lagged.update({f"{c}_lag{lag}s": shifted[c] for c in FEATURES})
    return pd.concat([frame, pd.DataFrame(lagged, index=frame.index)], axis=1)


def add_basis(frame):
    """The expert's friction basis ``tanh(v / w)`` as columns ``friction_basis_<w>``."""
    velocity = frame["steering_wheel_velocity"]
    basis = {f"friction_basis_{w:g}": np.tanh(velocity / w) for w in EXPERT_WIDTHS}
    return pd.concat([frame, pd.DataFrame(basis, index=frame.index)], axis=1)


def score(y, pred, frame, rate):
    metrics = recording_metrics(
        y, pred, groups=frame["recording"].to_numpy(), sampling_period=1.0 / rate
    )
    styles = frame.groupby("recording", sort=False)["driver"].first().reindex(metrics.ids)
    return pd.DataFrame(
        {
            "recording": metrics.ids,
            "driver": styles.to_numpy(),
            "accuracy": metrics.accuracy[:, 0],
            "smoothness": metrics.smoothness[:, 0],
        }
    )


def median_latency_us(function, rows, n_calls=2000):
    for row in rows[:200]:
        function(row)
    elapsed = np.empty(n_calls)
    for i in range(n_calls):
        row = rows[i % len(rows)]
        start = time.perf_counter_ns()
        function(row)
        elapsed[i] = time.perf_counter_ns() - start
    return float(np.median(elapsed)) / 1000.0


def stream_latency(model, rows):
    return median_latency_us(model.filter_stream().update, rows)


def fit_predict(model, train, test, columns, grouped):
    """Fit and predict, the recordings routed to every step that asks for them."""
    fit_kw = {"groups": train["recording"].to_numpy()} if grouped else {}
    predict_kw = {"groups": test["recording"].to_numpy()} if grouped else {}
    with sklearn.config_context(enable_metadata_routing=True):
        start = time.perf_counter()
        model.fit(train[columns], train["driver_torque"].to_numpy(), **fit_kw)
        fit_s = time.perf_counter() - start
        start = time.perf_counter()
        pred = model.predict(test[columns], **predict_kw)
    return pred, fit_s, len(test) / (time.perf_counter() - start)


def evaluate(name, model, train, test, rate, columns, grouped):
    pred, fit_s, rows_per_s = fit_predict(model, train, test, columns, grouped)
    table = score(test["driver_torque"].to_numpy(), pred, test, rate)
    rows = test[columns].to_numpy()[:2000]
    if name.startswith(PIPELINE) or grouped:  # the pipeline's stream derives the sensed rows
        latency = stream_latency(model, rows)
    else:
        latency = median_latency_us(model.predict, rows[:, np.newaxis, :])
    table["model"] = name
    return table, {"model": name, "fit_s": fit_s, "rows_per_s": rows_per_s, "latency_us": latency}


def choose_pipeline(data, rate, states):
    """The pipeline's number of states, then its velocity filter (the one fit chooses, or
    20 ms), by mean validation accuracy."""
    train, validation = data[data["split"] == "train"], data[data["split"] == "validation"]

    def accuracy(**params):
        model = make_torque_pipeline(random_state=0, sampling_period=1.0 / rate, **params)
        pred = fit_predict(model, train, validation, FEATURES, True)[0]
        return score(validation["driver_torque"].to_numpy(), pred, validation, rate)[
            "accuracy"
        ].mean()

    by_states = {k: accuracy(n_states=k) for k in states}
    k = max(by_states, key=by_states.get)
    # the default ("auto": chosen in fit on the training recordings) against a fixed 20 ms
    by_filter = {"auto": by_states[k], 0.02: accuracy(n_states=k, velocity_filter=0.02)}
    return k, max(by_filter, key=by_filter.get), by_states, by_filter


def run(seed, rate, states, duration, cache, vehicle=None, without_read_out=False):
    data = make_driving_protocol(
        random_state=seed, sampling_rate=rate, duration=duration, cache=cache, vehicle=vehicle
    )
    k, velocity_filter, by_states, by_filter = choose_pipeline(data, rate, states)
    print(
        f"\nseed {seed}, {rate:g} Hz, car {car_name(vehicle)}: pipeline validation accuracy "
        + ", ".join(f"K={s}: {a:.2f}" for s, a in by_states.items())
        + f" -> K={k}; velocity filter "
        + ", ".join(f"{f}: {a:.2f}" for f, a in by_filter.items())
        + f" -> {velocity_filter}"
    )
    pipeline = make_torque_pipeline(
        n_states=k, random_state=0, velocity_filter=velocity_filter, sampling_period=1.0 / rate
    )
    lagged = add_basis(add_lags(data, rate))
    train, test = lagged[lagged["split"] == "train"], lagged[lagged["split"] == "test"]
    lag_columns = [c for c in lagged.columns if "_lag" in c]
    basis_columns = [c for c in lagged.columns if c.startswith("friction_basis_")]
    models = [
        ("RidgeCV", RidgeCV(), FEATURES, False),
        (EXPERT, LinearRegression(), FEATURES + basis_columns, False),
        (
            "HistGradientBoosting",
            HistGradientBoostingRegressor(max_iter=300, random_state=0),
            FEATURES,
            False,
        ),
        (
            "HistGradientBoosting + lags",
            HistGradientBoostingRegressor(max_iter=300, random_state=0),
            FEATURES + lag_columns,
            False,
        ),
        ("HMMGMRRegressor K=5", HMMGMRRegressor(n_states=5, random_state=0), FEATURES, True),
        ("HMMGMRRegressor K=8", HMMGMRRegressor(n_states=8, random_state=0), FEATURES, True),
        (f"{PIPELINE} K={k}", pipeline, FEATURES, True),
    ]
    if without_read_out:
        unsmoothed = make_torque_pipeline(
            n_states=k,
            random_state=0,
            velocity_filter=velocity_filter,
            sampling_period=1.0 / rate,
            output_smoothing=None,
        )
        models.append((f"{PIPELINE} K={k} {NO_READ_OUT}", unsmoothed, FEATURES, True))
    tables, costs = [], []
    for name, model, columns, grouped in models:
        table, cost = evaluate(name, model, train, test, rate, columns, grouped)
        tables.append(table)
        costs.append(cost)
    table = pd.concat(tables, ignore_index=True)
    ps = normalize_performance(table, weights="50/50")
    table = table.merge(ps[["model", "recording", "performance_score"]], on=["model", "recording"])
    table["seed"], table["rate"], table["vehicle"] = seed, rate, car_name(vehicle)
    summary = summarise(table, pd.DataFrame(costs))
    print(summary.to_string(float_format=lambda v: f"{v:.2f}"))
    return table, summary


def summarise(table, costs):
    by_model = table.groupby("model", sort=False)
    summary = pd.DataFrame(
        {
            "accuracy %": by_model["accuracy"].mean(),
            "worst %": by_model["accuracy"].min(),
            "roughness Nm/s": by_model["smoothness"].mean(),
            "PS 50/50": by_model["performance_score"].mean(),
        }
    )
    for style in STYLES:
        rows = table[table["driver"] == style].groupby("model", sort=False)
        summary[f"{style[:3]} acc"] = rows["accuracy"].mean()
        summary[f"{style[:3]} worst"] = rows["accuracy"].min()
        summary[f"{style[:3]} rough"] = rows["smoothness"].mean()
    costs = costs.set_index("model")
    summary["fit s"] = costs["fit_s"]
    summary["Mrows/s"] = costs["rows_per_s"] / 1e6
    summary["stream us"] = costs["latency_us"]
    return summary


def targets(summary):
    """The pipeline against plain boosting (mean, worst and roughness, overall and per style)
    and against the expert's linear model (mean and worst, overall)."""
    pipeline = next(m for m in summary.index if m.startswith(PIPELINE))
    return pipeline_targets(summary, pipeline)


def without_read_out(summary):
    """The margins over plain boosting of the pipeline without its read-out, if a row."""
    rows = [m for m in summary.index if m.startswith(PIPELINE) and m.endswith(NO_READ_OUT)]
    return pipeline_targets(summary, rows[0])[2:] if rows else []


def pipeline_targets(summary, pipeline):
    """The checks of :func:`targets` for the row ``pipeline``."""
    ours, boost = summary.loc[pipeline], summary.loc["HistGradientBoosting"]
    expert = summary.loc[EXPERT]
    checks = [
        (
            f"mean accuracy vs {EXPERT}",
            ours["accuracy %"] >= expert["accuracy %"],
            ours["accuracy %"],
            expert["accuracy %"],
        ),
        (
            f"worst recording vs {EXPERT}",
            ours["worst %"] >= expert["worst %"],
            ours["worst %"],
            expert["worst %"],
        ),
    ]
    for prefix in ("", *[f"{s[:3]} " for s in STYLES]):
        acc = "accuracy %" if not prefix else f"{prefix}acc"
        worst = "worst %" if not prefix else f"{prefix}worst"
        rough = "roughness Nm/s" if not prefix else f"{prefix}rough"
        checks += [
            (
                f"{prefix or 'all '}mean accuracy vs boosting",
                ours[acc] >= boost[acc],
                ours[acc],
                boost[acc],
            ),
            (
                f"{prefix or 'all '}worst recording vs boosting",
                ours[worst] >= boost[worst],
                ours[worst],
                boost[worst],
            ),
            (
                f"{prefix or 'all '}roughness vs boosting",
                ours[rough] <= boost[rough],
                ours[rough],
                boost[rough],
            ),
        ]
    return checks


def spread(table):
    """Per rate and model, the mean accuracy and roughness in every car, and their range."""
    for rate, rows in table.groupby("rate"):
        by_car = rows.groupby(["model", "vehicle"], sort=False)[["accuracy", "smoothness"]]
        means = by_car.mean().unstack("vehicle")
        accuracy, roughness = means["accuracy"], means["smoothness"]
        summary = pd.DataFrame(
            {
                "acc min %": accuracy.min(axis=1),
                "acc max %": accuracy.max(axis=1),
                "rough min": roughness.min(axis=1),
                "rough max": roughness.max(axis=1),
            }
        )
        worst = rows.groupby(["model", "vehicle"], sort=False)["accuracy"].min().unstack()
        summary["worst recording %"] = worst.min(axis=1)
        print(f"\n{rate:g} Hz: mean test accuracy % per car (over the seeds)")
        print(accuracy.to_string(float_format=lambda v: f"{v:.2f}"))
        print(f"\n{rate:g} Hz: spread over the cars")
        print(summary.to_string(float_format=lambda v: f"{v:.2f}"))
        pipeline = next(m for m in accuracy.index if m.startswith(PIPELINE))
        margin = accuracy.loc[pipeline] - accuracy.loc["HistGradientBoosting"]
        print(
            f"{rate:g} Hz: pipeline minus boosting per car (points): "
            + ", ".join(f"{car}: {m:+.2f}" for car, m in margin.items())
        )


def car_name(vehicle):
    return "default" if vehicle is None else str(vehicle)


def describe_cars(vehicles):
    for vehicle in vehicles:
        car = draw_vehicle(vehicle) if vehicle is not None else VehicleParameters()
        print(
            f"car {car_name(vehicle)}: friction {car.wheel_friction:.2f} Nm over "
            f"{car.friction_velocity:.2f} rad/s, assist {car.assist_gain:.2f} + "
            f"{car.assist_gain_slope:.2f}/Nm (max {car.assist_max:.1f} Nm), damping "
            f"{car.wheel_damping:.2f} Nms/rad, inertia {car.wheel_inertia:.3f} kg m^2, ratio "
            f"{car.steering_ratio:.1f}, trails {car.mechanical_trail * 1e3:.0f}+"
            f"{car.pneumatic_trail * 1e3:.0f} mm, sensor noise x{car.sensor_noise:.2f}, "
            + (
                f"torsion bar {math.radians(car.column_stiffness):.2f} Nm/deg "
                f"({car.column_damping:.2f} Nms/rad)"
                if math.isfinite(car.column_stiffness)
                else "rigid column"
            )
        )


def residuals(seed, rate, duration, cache):
    """Mean test residual per bin of the two inputs whose nonlinearity the states miss."""
    data = make_driving_protocol(
        random_state=seed, sampling_rate=rate, duration=duration, cache=cache
    )
    train, test = data[data["split"] == "train"], data[data["split"] == "test"]
    y, fit_groups = train["driver_torque"].to_numpy(), train["recording"].to_numpy()
    groups = test["recording"].to_numpy()
    thesis = HMMGMRRegressor(n_states=5, random_state=0).fit(train[FEATURES], y, groups=fit_groups)
    pipeline = make_torque_pipeline(n_states=5, random_state=0)
    pipeline.fit(train[FEATURES], y, hmmgmr__groups=fit_groups)
    residual = pd.DataFrame(
        {
            "HMMGMRRegressor K=5": test["driver_torque"]
            - thesis.predict(test[FEATURES], groups=groups),
            f"{PIPELINE} K=5": test["driver_torque"]
            - pipeline.predict(test[FEATURES], groups=groups),
        }
    )
    bins = {
        "lateral_acceleration": [-5, -3, -2, -1, -0.5, 0, 0.5, 1, 2, 3, 5],
        "steering_wheel_velocity": [-2, -0.5, -0.2, -0.1, -0.05, 0, 0.05, 0.1, 0.2, 0.5, 2],
    }
    for column, edges in bins.items():
        binned = pd.cut(test[column], edges)
        table = residual.groupby(binned, observed=True).mean()
        table["rows"] = binned.value_counts()
        print(f"\nmean residual (Nm) by {column}\n{table.to_string(float_format='{:.3f}'.format)}")
    print(f"\nRMS residual (Nm)\n{np.sqrt((residual**2).mean()).to_string()}")
    states = thesis.predict_state_proba(test[FEATURES], groups=groups).argmax(axis=1)
    acceleration = test["lateral_acceleration"].to_numpy()
    for k in range(thesis.n_states):
        low, high = np.percentile(acceleration[states == k], [5, 95])
        print(
            f"state {k}: {np.mean(states == k):.1%} of the rows, lateral acceleration "
            f"{low:.2f} to {high:.2f} m/s^2 (5-95 %)"
        )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--rates", type=float, nargs="+", default=[20.0, 100.0])
    parser.add_argument("--states", type=int, nargs="+", default=[3, 5, 8])
    parser.add_argument("--quick", action="store_true", help="1-minute recordings")
    parser.add_argument("--cache", default=None, help="folder caching the simulated data")
    parser.add_argument("--output", default=None, help="JSON file of every figure")
    parser.add_argument("--residuals", action="store_true", help="the residual analysis only")
    parser.add_argument(
        "--without-read-out",
        action="store_true",
        help="add the pipeline with output_smoothing=None (its margins printed, not targets)",
    )
    parser.add_argument(
        "--vehicles",
        nargs="+",
        default=["default"],
        help="cars: 'default' (the reference car) or int seeds of draw_vehicle",
    )
    args = parser.parse_args()
    warnings.filterwarnings("ignore", category=UserWarning)
    duration = 60.0 if args.quick else 300.0
    if args.residuals:
        residuals(args.seeds[0], args.rates[0], duration, args.cache)
        return
    vehicles = [None if v == "default" else int(v) for v in args.vehicles]
    describe_cars(vehicles)
    tables, missed = [], 0
    for vehicle in vehicles:
        for rate in args.rates:
            for seed in args.seeds:
                table, summary = run(
                    seed, rate, args.states, duration, args.cache, vehicle, args.without_read_out
                )
                tables.append(table)
                for what, ok, ours, theirs in targets(summary):
                    missed += not ok
                    print(f"  [{'ok' if ok else 'MISSED'}] {what}: {ours:.3f} vs {theirs:.3f}")
                for what, ok, ours, theirs in without_read_out(summary):
                    print(
                        f"  [{'ahead' if ok else 'behind'}, {NO_READ_OUT}] {what}: "
                        f"{ours:.3f} vs {theirs:.3f}"
                    )
    if len(vehicles) > 1:
        spread(pd.concat(tables, ignore_index=True))
    if args.output:
        with open(args.output, "w") as file:
            json.dump(pd.concat(tables).to_dict(orient="records"), file)
    print(f"\n{missed} target(s) missed")


if __name__ == "__main__":
    main()
