"""Driver models at the wheel: do models that fit recorded torque keep the lane?

For every driver style, models are fitted on the style's protocol training recordings
(``make_driving_protocol``, measured sensors) and then drive held-out roads of every setting
(``skhmmgmr.datasets.drive``: the simulator's closed loop, the model streamed sample by sample
on what the sensors log), side by side with the human they learned from on the same road, with
the same sensor errors:

- ``baseline``: ``HMMGMRRegressor(n_states=5)`` on the 18 features (the thesis' baseline);
- ``selected``: ``HMMGMRRegressor(n_states=5)`` on the steering-wheel angle and the yaw rate
  (the thesis' selected subset, "Strict 1", with its 5 states);
- ``pipeline``: ``make_torque_pipeline(5)`` (derived steering-system inputs, 18 features);
- ``preview``: ``HMMGMRRegressor(n_states=5)`` on ``PREVIEW_FEATURES`` (what the driver sees
  of the road: lane position, heading and curvature ahead);
- ``ridge``, ``boosting``: ``RidgeCV`` and ``HistGradientBoostingRegressor`` on the 18
  features.

Printed per style and model: the open-loop test accuracy and roughness (recorded torque of the
protocol's test recordings), then per held-out road (setting x seed) the lane-keeping metrics
(``skhmmgmr.metrics.lane_keeping_metrics``): how many drives lost control (beyond 10 m), the
departures, the RMS lateral deviation and the torque RMS relative to the human's on the same
road, and the torque roughness. The targets of the issue for the package's models: no
departure on any held-out road, RMS lateral deviation within 25 % of the human's, torque RMS
within 20 %.

``--scenarios`` prints instead the generalisation table of the thesis' Appendix E.4: models
trained on the standard protocol, tested per stress scenario (sharp corners, wide lane, lane
change, evasive), open loop (accuracy and smoothness on the human's recordings of the scenario)
and closed loop (the model at the wheel). ``--figure PATH`` draws the lateral deviation and the
torque of the human and of the models over one road.

Run with::

    python benchmarks/bench_closed_loop.py                  # 3 styles x 7 settings x 3 seeds
    python benchmarks/bench_closed_loop.py --quick          # 1 style, 3 settings, 1 seed
    python benchmarks/bench_closed_loop.py --scenarios
"""

import argparse
import time
import warnings

import numpy as np
import pandas as pd
from _roads import OneRow, road_seed
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.linear_model import RidgeCV
from threadpoolctl import threadpool_limits

from skhmmgmr import HMMGMRRegressor, make_torque_pipeline
from skhmmgmr.datasets import (
    DRIVER_STYLES,
    FEATURE_NAMES,
    PREVIEW_FEATURES,
    drive,
    make_driving_protocol,
    make_lane_keeping,
)
from skhmmgmr.metrics import accuracy_score, lane_keeping_metrics, smoothness_score

FEATURES = list(FEATURE_NAMES)
SELECTED = ["steering_wheel_angle", "yaw_rate"]
PACKAGE_MODELS = ("baseline", "selected", "pipeline", "preview")
SCENARIOS = ("highway", "sharp_corners", "wide_lane", "lane_change", "evasive")


def _parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--styles", nargs="+", default=list(DRIVER_STYLES))
    parser.add_argument("--settings", nargs="+", type=int, default=list(range(1, 8)))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--duration", type=float, default=120.0, help="drive length [s]")
    parser.add_argument("--train-duration", type=float, default=60.0, help="protocol sections [s]")
    parser.add_argument("--rate", type=float, default=100.0, help="sampling rate [Hz]")
    parser.add_argument("--quick", action="store_true", help="1 style, 3 settings, 1 seed")
    parser.add_argument("--scenarios", action="store_true", help="the generalisation table")
    parser.add_argument("--figure", default=None, help="PNG of one road, human and models")
    args = parser.parse_args(argv)
    if args.quick:
        args.styles, args.settings, args.seeds = args.styles[:1], [1, 4, 7], args.seeds[:1]
    return args


def fit_models(train):
    """The models of the module docstring, fitted on ``train``."""
    X, y, groups = train[FEATURES], train["driver_torque"], train["recording"]
    hmm = dict(n_states=5, random_state=0)
    models = {
        "baseline": HMMGMRRegressor(**hmm).fit(X, y, groups=groups),
        "selected": HMMGMRRegressor(**hmm).fit(train[SELECTED], y, groups=groups),
        "pipeline": make_torque_pipeline(5, random_state=0).fit(X, y, groups=groups),
        "preview": HMMGMRRegressor(**hmm).fit(train[list(PREVIEW_FEATURES)], y, groups=groups),
        "ridge": RidgeCV(alphas=np.logspace(-3, 3, 13)).fit(X.to_numpy(), y),
        "boosting": HistGradientBoostingRegressor(random_state=0).fit(X.to_numpy(), y),
    }
    return models


def as_driver(name, model):
    """What ``drive`` gets: the package's models as they are, the others one row at a time."""
    return OneRow(model) if name in ("ridge", "boosting") else model


def open_loop(model, name, frame):
    """Accuracy and roughness of ``model`` on the recorded torque of ``frame``."""
    groups = frame["recording"].to_numpy()
    if name in ("ridge", "boosting"):
        estimate = model.predict(frame[FEATURES].to_numpy())
    else:
        columns = list(getattr(model, "feature_names_in_", FEATURES))
        estimate = model.predict(frame[columns], groups=groups)
    y = frame["driver_torque"]
    return (
        accuracy_score(y, estimate, groups=groups),
        smoothness_score(estimate, time=frame["time"].to_numpy(), groups=groups),
    )


def closed_loop(args):
    rows = []
    for style in args.styles:
        data = make_driving_protocol(
            (style,), duration=args.train_duration, sampling_rate=args.rate, random_state=0
        )
        train, test = data[data["split"] == "train"], data[data["split"] == "test"]
        start = time.perf_counter()
        models = fit_models(train)
        print(f"{style}: fitted {len(models)} models in {time.perf_counter() - start:.0f} s")
        fit_quality = {name: open_loop(m, name, test) for name, m in models.items()}
        for setting in args.settings:
            for seed in args.seeds:
                road = dict(
                    setting=setting,
                    duration=args.duration,
                    sampling_rate=args.rate,
                    random_state=road_seed(style, setting, seed),
                )
                human = lane_keeping_metrics(drive(style, **road))
                for name, model in models.items():
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        frame = drive(as_driver(name, model), **road)
                    metrics = lane_keeping_metrics(frame)
                    lost = frame.attrs["lost_control"] is not None
                    rows.append(
                        {
                            "style": style,
                            "model": name,
                            "setting": setting,
                            "seed": seed,
                            "accuracy": fit_quality[name][0],
                            "roughness_open_loop": fit_quality[name][1],
                            "lost_control": lost,
                            "departures": metrics["departures"],
                            "human_departures": human["departures"],
                            "deviation_ratio": metrics["lateral_deviation_rms"]
                            / human["lateral_deviation_rms"],
                            "torque_ratio": metrics["torque_rms"] / human["torque_rms"],
                            "roughness": metrics["torque_roughness"],
                            "human_roughness": human["torque_roughness"],
                            "driven_s": len(frame) / args.rate,
                        }
                    )
    table = pd.DataFrame(rows)
    summary = table.groupby(["style", "model"], sort=False).agg(
        accuracy=("accuracy", "first"),
        rough_open=("roughness_open_loop", "first"),
        drives=("lost_control", "size"),
        lost=("lost_control", "sum"),
        driven_s=("driven_s", "mean"),
        departures=("departures", "sum"),
        human_departures=("human_departures", "sum"),
        deviation_ratio=("deviation_ratio", "mean"),
        worst_deviation_ratio=("deviation_ratio", "max"),
        torque_ratio=("torque_ratio", "mean"),
        roughness=("roughness", "mean"),
        human_roughness=("human_roughness", "mean"),
    )
    kept = summary["lost"] == 0
    summary["meets_target"] = (
        kept
        & (summary["departures"] == 0)
        & (summary["worst_deviation_ratio"] <= 1.25)
        & (
            table.groupby(["style", "model"], sort=False)["torque_ratio"].apply(
                lambda r: (abs(r - 1) <= 0.2).all()
            )
        )
    )
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        print(summary.round(3).to_string())
    return table


def scenario_table(args):
    """Thesis Appendix E.4: trained on the standard protocol, tested per stress scenario."""
    rows = []
    for style in args.styles:
        data = make_driving_protocol(
            (style,), duration=args.train_duration, sampling_rate=args.rate, random_state=0
        )
        models = fit_models(data[data["split"] == "train"])
        for scenario in SCENARIOS:
            for seed in args.seeds:
                road = dict(
                    scenario=scenario,
                    duration=args.duration,
                    sampling_rate=args.rate,
                    random_state=road_seed(style, 7, seed),
                )
                try:
                    recorded = make_lane_keeping(driver=style, **road)
                except RuntimeError:  # the human model itself loses control
                    continue
                human = lane_keeping_metrics(recorded)
                for name in ("baseline", "selected", "preview"):
                    accuracy, smoothness = open_loop(models[name], name, recorded)
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        frame = drive(models[name], **road)
                    metrics = lane_keeping_metrics(frame)
                    rows.append(
                        {
                            "scenario": scenario,
                            "model": name,
                            "style": style,
                            "accuracy": accuracy,
                            "smoothness": smoothness,
                            "lost_control": frame.attrs["lost_control"] is not None,
                            "departures": metrics["departures"],
                            "human_departures": human["departures"],
                            "deviation_ratio": metrics["lateral_deviation_rms"]
                            / human["lateral_deviation_rms"],
                        }
                    )
    table = pd.DataFrame(rows)
    summary = table.groupby(["scenario", "model"], sort=False).agg(
        accuracy=("accuracy", "mean"),
        smoothness=("smoothness", "mean"),
        drives=("lost_control", "size"),
        lost=("lost_control", "sum"),
        departures=("departures", "sum"),
        human_departures=("human_departures", "sum"),
        deviation_ratio=("deviation_ratio", "mean"),
    )
    with pd.option_context("display.width", 200, "display.max_columns", 30):
        print(summary.round(3).to_string())
    return table


def figure(args, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    style = args.styles[0]
    data = make_driving_protocol(
        (style,), duration=args.train_duration, sampling_rate=args.rate, random_state=0
    )
    models = fit_models(data[data["split"] == "train"])
    road = dict(
        setting=7, duration=60.0, sampling_rate=args.rate, random_state=road_seed(style, 7, 0)
    )
    runs = {f"human ({style})": drive(style, **road)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name in ("preview", "selected"):
            runs[f"{name} model"] = drive(models[name], **road)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    for label, frame in runs.items():
        top.plot(frame["time"], frame["lateral_deviation_0m"], label=label, lw=1)
        bottom.plot(frame["time"], frame["driver_torque"], label=label, lw=1)
    for limit in (-0.85, 0.85):
        top.axhline(limit, color="grey", ls=":", lw=1)
    top.set_ylim(-3, 3)
    bottom.set_ylim(-6, 6)
    top.set_ylabel("lateral deviation [m]")
    bottom.set_ylabel("driver torque [Nm]")
    bottom.set_xlabel("time [s]")
    top.legend(loc="upper right", fontsize=8)
    top.set_title("The same road, the same sensor errors: the human and two models at the wheel")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main(argv=None):
    args = _parse(argv)
    start = time.perf_counter()
    # one row at a time, a thread pool costs more than the prediction (10 ms a row)
    threadpool_limits(1)
    if args.figure:
        figure(args, args.figure)
    elif args.scenarios:
        scenario_table(args)
    else:
        closed_loop(args)
    print(f"total {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
