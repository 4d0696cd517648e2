"""Do the thesis' qualitative findings hold on the simulator with realistic sensors?

Runs :func:`skhmmgmr.select_parameters` once per driver style and once on all drivers together
(generic model), on data measured with realistic sensor errors (``sensor_noise="typical"``), and
prints per run: the selected subset and K, test accuracy and smoothness of the final model
against the 18-feature baseline with the same K, how much smoother the final model is, the
accuracy and smoothness against K on the validation recordings (the thesis: more states raise
accuracy and lower smoothness, i.e. a rougher estimate) and the wall time.

Run: ``python benchmarks/thesis_findings.py`` (reduced scale: 1-minute sections, K up to 8; a
few minutes per run on 2 cores) or ``python benchmarks/thesis_findings.py --full`` (thesis
protocol: 5-minute sections, 12/6/6 sections per driver, 10 filtered features, K up to 20). Both
scales sample at 20 Hz (``sampling_rate`` in ``REDUCED`` and ``FULL``). ``--sensor-noise none``
runs on the clean simulator states for comparison.
"""

import argparse
import time

import pandas as pd

from skhmmgmr import select_parameters
from skhmmgmr.datasets import DRIVER_STYLES, make_driving_protocol

REDUCED = dict(n_train_per_setting=2, n_validation=6, n_test=6, duration=60.0, sampling_rate=20.0)
FULL = dict(n_train_per_setting=2, n_validation=6, n_test=6, duration=300.0, sampling_rate=20.0)
SHORT = {
    "steering_wheel_angle": "swa",
    "steering_wheel_velocity": "swv",
    "steering_wheel_acceleration": "swacc",
    "lateral_velocity": "vy",
    "lateral_acceleration": "ay",
    "slip_angle": "slip",
    "yaw_rate": "r",
    "yaw_acceleration": "racc",
    "roll_angle": "roll",
    "roll_velocity": "rollv",
    "roll_acceleration": "rollacc",
    "lateral_deviation_0m": "ey0",
    "heading_deviation_0m": "epsi0",
    "road_curvature_0m": "kappa0",
    "heading_deviation_10m": "epsi10",
    "road_curvature_10m": "kappa10",
    "heading_deviation_30m": "epsi30",
    "road_curvature_30m": "kappa30",
}


def _parse(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="thesis protocol scale")
    parser.add_argument("--drivers", nargs="+", default=list(DRIVER_STYLES))
    parser.add_argument("--runs", nargs="+", default=None, help="driver styles and/or 'generic'")
    parser.add_argument("--sensor-noise", default="typical", help="'typical', 'none' or a scale")
    parser.add_argument("--n-top", type=int, default=10)
    parser.add_argument("--k-max", type=int, default=None)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--random-state", type=int, default=0)
    parser.add_argument("--cache", default=None, help="joblib cache directory")
    args = parser.parse_args(argv)
    if args.sensor_noise not in ("typical", "none"):
        args.sensor_noise = float(args.sensor_noise)
    if args.k_max is None:
        args.k_max = 20 if args.full else 8
    if args.runs is None:
        args.runs = [*args.drivers, "generic"]
    return args


def _trend(report):
    """Mean validation accuracy and smoothness per K, with the correlations against K."""
    states = report.states
    per_k = states.groupby("n_states")[["accuracy", "smoothness"]].mean()
    return per_k, per_k.reset_index().corr(method="spearman").loc["n_states"]


def run(data, name, args):
    start = time.perf_counter()
    report = select_parameters(
        data,
        n_top=args.n_top,
        k_max=args.k_max,
        n_jobs=args.n_jobs,
        memory=args.cache,
        progress=False,
        random_state=args.random_state,
    )
    wall = time.perf_counter() - start
    summary = report.test_summary.set_index("model")
    final, baseline = summary.loc["final"], summary.loc["baseline"]
    per_k, rho = _trend(report)
    print(f"\n=== {name}: {wall:.0f} s ===", flush=True)
    print(report.summary())
    print("stage timings [s]:", {k: round(v, 1) for k, v in report.timings.items()})
    print("validation metrics against K (mean over recordings):")
    print(per_k.round(3).T.to_string())
    return {
        "run": name,
        "subset": "+".join(SHORT.get(f, f) for f in report.features),
        "K": report.n_states,
        "acc_final": final["accuracy"],
        "acc_base": baseline["accuracy"],
        "smooth_final": final["smoothness"],
        "smooth_base": baseline["smoothness"],
        "smoother_%": 100.0 * (1.0 - final["smoothness"] / baseline["smoothness"]),
        "rho_acc_K": rho["accuracy"],
        "rho_smooth_K": rho["smoothness"],
        "wall_s": wall,
    }


def main(argv=None):
    args = _parse(argv)
    scale = FULL if args.full else REDUCED
    print(
        f"protocol: {scale}, sensor_noise={args.sensor_noise!r}, n_top={args.n_top}, "
        f"k_max={args.k_max}, n_jobs={args.n_jobs}",
        flush=True,
    )
    start = time.perf_counter()
    data = make_driving_protocol(
        tuple(args.drivers),
        **scale,
        random_state=args.random_state,
        sensor_noise=args.sensor_noise,
        n_jobs=args.n_jobs,
        cache=args.cache,
    )
    print(
        f"simulated {data['recording'].nunique()} recordings in "
        f"{time.perf_counter() - start:.0f} s",
        flush=True,
    )
    rows = []
    for name in args.runs:
        subset = data if name == "generic" else data[data["driver"] == name]
        rows.append(run(subset.reset_index(drop=True), name, args))
    table = pd.DataFrame(rows).set_index("run")
    print("\n=== findings (test set; smoothness in Nm/s, lower is smoother) ===")
    with pd.option_context("display.width", 200, "display.max_colwidth", 60):
        print(table.round(3).to_string())
    return table


if __name__ == "__main__":
    main()
