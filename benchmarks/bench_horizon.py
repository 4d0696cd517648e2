"""The torque over a horizon, the thesis' way (Appendix E.3), against three simpler forecasts.

A preview model (``HMMGMRRegressor(n_states=5)`` on ``PREVIEW_FEATURES``) is fitted on a
driver style's protocol training recordings (``make_driving_protocol``, measured sensors).
On held-out setting-7 roads driven by the same style, the torque ``h`` seconds after every
sample ``t`` (h = 0.25, 0.5, 1 and 2 s; 0 for reference) is estimated from what is known at
``t`` by:

- ``rollout``: ``skhmmgmr.datasets.torque_ahead``, the simulator's vehicle integrated from
  the state at ``t`` with the model's torque, the model streamed on the rollout's features
  (the road ahead is known);
- ``hold``: the last measured torque, at ``t``;
- ``now``: the model's filtered estimate at ``t``, held;
- ``ahead_marginal`` and ``ahead_conditional``: ``predict_ahead(X, h rows)`` of the preview
  model, with its two read-outs (the states' output means; their conditional means given the
  inputs at ``t``);
- ``shifted``: a preview model fitted on the target ``h`` ahead (``shift_target``), its
  filtered estimate at ``t``.

Printed per horizon and forecast: the accuracy (``skhmmgmr.metrics.accuracy_score`` against
the measured torque at ``t + h``, per road, averaged) and the roughness (the package's
smoothness score of the forecast as a series over ``t``, Nm/s; the measured torque's own is
printed as ``measured``), averaged over the roads, with the worst road's accuracy.

Run with::

    python benchmarks/bench_horizon.py                 # defensive, 3 roads of 60 s
    python benchmarks/bench_horizon.py --quick         # 1 road of 20 s
"""

import argparse
import time

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import (
    PREVIEW_FEATURES,
    make_driving_protocol,
    make_lane_keeping,
    shift_target,
    torque_ahead,
)
from skhmmgmr.metrics import accuracy_score, smoothness_score

PREVIEW = list(PREVIEW_FEATURES)
HORIZONS = (0.0, 0.25, 0.5, 1.0, 2.0)


def _parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--style", default="defensive")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--duration", type=float, default=60.0, help="test road length [s]")
    parser.add_argument("--train-duration", type=float, default=60.0, help="protocol sections [s]")
    parser.add_argument("--rate", type=float, default=100.0, help="sampling rate [Hz]")
    parser.add_argument("--quick", action="store_true", help="1 road of 20 s")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.duration = args.seeds[:1], 20.0
    return args


def fit_models(train, rate):
    """The preview model, and one preview model of the target ``h`` ahead per horizon."""
    X, y, groups = train[PREVIEW], train["driver_torque"], train["recording"]
    hmm = dict(n_states=5, random_state=0)
    model = HMMGMRRegressor(**hmm).fit(X, y, groups=groups)
    shifted = {}
    for horizon in HORIZONS:
        ahead = shift_target(y.to_numpy(), int(round(horizon * rate)), groups=groups.to_numpy())
        keep = ~np.isnan(ahead)
        shifted[horizon] = HMMGMRRegressor(**hmm).fit(
            X[keep], ahead[keep], groups=groups.to_numpy()[keep]
        )
    return model, shifted


def forecasts(model, shifted, args, seed):
    """Per horizon, the forecasts of the module docstring at every start time of one road."""
    road = dict(
        driver=args.style,
        setting=7,
        duration=args.duration,
        sampling_rate=args.rate,
        random_state=20_000 + seed,
    )
    recorded = make_lane_keeping(**road)
    X, torque = recorded[PREVIEW], recorded["driver_torque"].to_numpy()
    groups = recorded["recording"].to_numpy()
    start = time.perf_counter()
    rolled = torque_ahead(model, horizons=HORIZONS, **road)
    elapsed = time.perf_counter() - start
    now = model.predict(X)
    per_horizon = []
    for horizon in HORIZONS:
        rows = int(round(horizon * args.rate))
        at = rolled[rolled["horizon"] == horizon]
        starts = np.round(at["time"].to_numpy() * args.rate).astype(int)
        target = torque[starts + rows]
        assert np.array_equal(target, at["driver_torque"].to_numpy())
        per_horizon.append(
            (
                horizon,
                target,
                {
                    "rollout": at["estimate"].to_numpy(),
                    "hold": torque[starts],
                    "now": now[starts],
                    "ahead_marginal": model.predict_ahead(X, rows)[starts],
                    "ahead_conditional": model.predict_ahead(X, rows, state_output="conditional")[
                        starts
                    ],
                    "shifted": shifted[horizon].predict(X, groups=groups)[starts],
                    "measured": target,
                },
                int(at["lost_control"].sum()),
            )
        )
    return per_horizon, elapsed


def main(argv=None):
    args = _parse(argv)
    threadpool_limits(1)
    start = time.perf_counter()
    data = make_driving_protocol(
        (args.style,), duration=args.train_duration, sampling_rate=args.rate, random_state=0
    )
    model, shifted = fit_models(data[data["split"] == "train"], args.rate)
    print(f"{args.style}: fitted 1 + {len(shifted)} models in {time.perf_counter() - start:.0f} s")
    rows = []
    for seed in args.seeds:
        per_horizon, elapsed = forecasts(model, shifted, args, seed)
        for horizon, target, estimates, lost in per_horizon:
            for name, estimate in estimates.items():
                rows.append(
                    {
                        "horizon": horizon,
                        "forecast": name,
                        "seed": seed,
                        "accuracy": accuracy_score(target, estimate),
                        "roughness": smoothness_score(estimate, sampling_period=1.0 / args.rate),
                        "lost": lost if name == "rollout" else 0,
                    }
                )
        print(f"road {seed}: rollouts of {args.duration:g} s in {elapsed:.0f} s")
    table = pd.DataFrame(rows)
    summary = table.groupby(["horizon", "forecast"], sort=False).agg(
        accuracy=("accuracy", "mean"),
        worst_accuracy=("accuracy", "min"),
        roughness=("roughness", "mean"),
        lost=("lost", "sum"),
    )
    with pd.option_context("display.width", 200, "display.max_rows", 100):
        print(summary.round(2).to_string())
    print(f"total {time.perf_counter() - start:.0f} s")
    return table


if __name__ == "__main__":
    main()
