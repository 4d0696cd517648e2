"""Command line: ``skhmmgmr demo | fit | predict`` (also ``python -m skhmmgmr``)."""

import argparse
import sys
import time
from pathlib import Path

import joblib
import pandas as pd

from .datasets import RECORDING, SPLIT, TARGET, TIME
from .datasets._schema import FEATURE_NAMES, META_COLUMNS


class CommandError(Exception):
    """A user-facing error: printed without a traceback, exit code 2."""


def _log(args, message):
    if not getattr(args, "quiet", False):
        print(message, flush=True)


def _read_table(path):
    path = Path(path)
    if not path.exists():
        raise CommandError(f"data file not found: {path}")
    try:
        if path.suffix in (".parquet", ".pq"):
            return pd.read_parquet(path)
        return pd.read_csv(path)
    except Exception as exc:  # pandas raises many types for unreadable files
        raise CommandError(f"cannot read {path}: {exc}") from exc


def _check_columns(frame, columns, path):
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise CommandError(f"{path}: missing column(s) {missing}; available: {list(frame.columns)}")


def _feature_columns(frame, args):
    if args.features:
        return list(args.features)
    excluded = {args.target, args.recording, args.time, *META_COLUMNS}
    return [
        c for c in frame.columns if c not in excluded and pd.api.types.is_numeric_dtype(frame[c])
    ]


def _evaluation_table(model, frame, features, target, recording, sampling_period):
    from .metrics import evaluate_recordings

    groups = frame[recording].to_numpy()
    pred = model.predict(frame[features], groups=groups)
    return evaluate_recordings(
        frame[target].to_numpy(), pred, groups=groups, sampling_period=sampling_period
    )


def command_demo(args):
    """Simulate drivers, fit the all-feature model and a two-feature model, compare on test."""
    from .datasets import make_driving_protocol
    from .estimator import HMMGMRRegressor

    scale = dict(duration=300.0) if args.full else dict(duration=args.duration)
    started = time.perf_counter()
    _log(args, f"Simulating drivers {args.drivers} ({scale['duration']:.0f} s sections, 20 Hz)")
    data = make_driving_protocol(
        drivers=tuple(args.drivers),
        sampling_rate=20.0,
        random_state=args.seed,
        n_jobs=args.n_jobs,
        **scale,
    )
    train = data[data[SPLIT] == "train"]
    test = data[data[SPLIT] == "test"]
    subsets = {
        "baseline (18 features)": list(FEATURE_NAMES),
        "steering wheel angle + yaw rate": ["steering_wheel_angle", "yaw_rate"],
    }
    rows = []
    for name, features in subsets.items():
        _log(args, f"Fitting {name}, K={args.n_states}")
        model = HMMGMRRegressor(n_states=args.n_states, random_state=args.seed)
        model.fit(train[features], train[TARGET], groups=train[RECORDING].to_numpy())
        table = _evaluation_table(model, test, features, TARGET, RECORDING, 0.05)
        rows.append(
            {
                "model": name,
                "n_features": len(features),
                "accuracy [%]": table["accuracy"].mean(),
                "smoothness [Nm/s]": table["smoothness"].mean(),
                "rmse [Nm]": table["rmse"].mean(),
            }
        )
    summary = pd.DataFrame(rows).set_index("model")
    print(summary.round(3).to_string())
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    summary.to_csv(output / "test_comparison.csv")
    _log(args, f"Wrote {output / 'test_comparison.csv'} in {time.perf_counter() - started:.1f} s")
    return 0


def command_fit(args):
    from .estimator import HMMGMRRegressor

    frame = _read_table(args.data)
    _check_columns(frame, [args.target, args.recording], args.data)
    features = _feature_columns(frame, args)
    _check_columns(frame, features, args.data)
    model = HMMGMRRegressor(n_states=args.n_states, random_state=args.seed, n_init=args.n_init)
    try:
        model.fit(frame[features], frame[args.target], groups=frame[args.recording].to_numpy())
    except ValueError as exc:
        raise CommandError(f"{args.data}: {exc}") from exc
    joblib.dump(model, args.output)
    _log(args, f"Fitted K={args.n_states} on {len(features)} features; wrote {args.output}")
    return 0


def command_predict(args):
    model_path = Path(args.model)
    if not model_path.exists():
        raise CommandError(f"model file not found: {model_path}")
    model = joblib.load(model_path)
    frame = _read_table(args.data)
    features = list(model.feature_names_in_)
    _check_columns(frame, [*features, args.recording], args.data)
    groups = frame[args.recording].to_numpy()
    try:
        estimate, std = model.predict(frame[features], groups=groups, return_std=True)
        proba = model.predict_state_proba(frame[features], groups=groups)
    except ValueError as exc:
        raise CommandError(f"{args.data}: {exc}") from exc
    result = frame.copy()
    result["estimate"] = estimate
    result["estimate_std"] = std
    for k in range(proba.shape[1]):
        result[f"state_{k}"] = proba[:, k]
    data_path = Path(args.data)
    output = (
        Path(args.output)
        if args.output
        else data_path.with_name(f"{data_path.stem}_predicted{data_path.suffix}")
    )
    if output.suffix in (".parquet", ".pq"):
        result.to_parquet(output)
    else:
        result.to_csv(output, index=False)
    _log(args, f"Wrote {output} ({len(result)} rows)")
    return 0


def _add_data_options(parser):
    parser.add_argument("--target", default=TARGET, help="target column (default: %(default)s)")
    parser.add_argument(
        "--recording", default=RECORDING, help="recording-id column (default: %(default)s)"
    )
    parser.add_argument("--time", default=TIME, help="time column (default: %(default)s)")


def build_parser():
    parser = argparse.ArgumentParser(
        prog="skhmmgmr", description="HMM-GMR driver steering-torque models."
    )
    parser.add_argument("--quiet", action="store_true", help="print results only")
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="run the main job on the embedded simulator")
    demo.add_argument("--full", action="store_true", help="thesis scale: 5-minute sections")
    demo.add_argument("--duration", type=float, default=60.0, help="section length [s]")
    demo.add_argument(
        "--drivers", nargs="+", default=["defensive", "aggressive", "novice"], help="styles"
    )
    demo.add_argument("--n-states", type=int, default=5)
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--n-jobs", type=int, default=None)
    demo.add_argument("--output", default="skhmmgmr_report", help="report folder")
    demo.set_defaults(handler=command_demo)

    fit = sub.add_parser("fit", help="fit a model on CSV/Parquet recordings")
    fit.add_argument("data", help="CSV or Parquet file, one row per sample")
    _add_data_options(fit)
    fit.add_argument("--features", nargs="+", help="feature columns (default: all numeric)")
    fit.add_argument("--n-states", type=int, default=5)
    fit.add_argument("--n-init", type=int, default=1)
    fit.add_argument("--seed", type=int, default=0)
    fit.add_argument("--output", default="model.joblib", help="model file to write")
    fit.set_defaults(handler=command_fit)

    predict = sub.add_parser("predict", help="write estimate, std and state probabilities")
    predict.add_argument("model", help="model file written by 'skhmmgmr fit'")
    predict.add_argument("data", help="CSV or Parquet file")
    _add_data_options(predict)
    predict.add_argument("--output", help="output file (default: DATA_predicted.EXT)")
    predict.set_defaults(handler=command_predict)
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except CommandError as exc:
        print(f"skhmmgmr {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
