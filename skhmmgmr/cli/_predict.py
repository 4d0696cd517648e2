"""``skhmmgmr predict``: the estimate, its standard deviation and the state probabilities of a
model file on the user's recordings, and their accuracy and smoothness when the target is
there.
"""

import sys
from pathlib import Path

import pandas as pd

from ._files import (
    CommandError,
    check_columns,
    check_output,
    load_model,
    model_inputs,
    ordered_data,
    write_output,
)
from ._options import NO_TIME, add_data_options, add_output_options, log


def _recording_metrics(frame, estimate, groups, args, training):
    """Per-recording RMSE, accuracy and smoothness of the estimate (``None`` without the
    target column); the smoothness needs the time column or the model's sampling period."""
    from ..metrics._table import recording_metrics

    if args.target not in frame.columns or estimate.ndim != 1:
        return None
    time = None if args.time == NO_TIME else frame[args.time].to_numpy(dtype=float)
    period = training.get("sampling_period") if time is None else None
    timed = time is not None or period is not None
    metrics = recording_metrics(
        frame[args.target].to_numpy(dtype=float),
        estimate,
        groups=groups,
        time=time,
        sampling_period=period,
        smoothness=timed,
    )
    return metrics.to_frame(keep_output=False)


def _print_metrics(table, args):
    columns = [c for c in ("rmse", "accuracy", "smoothness") if c in table]
    print(f"{args.target}: {', '.join(columns)} per recording (accuracy in %)")
    print(table.round(3).to_string(index=False))
    means = ", ".join(f"{c} {table[c].mean():.3f}" for c in columns)
    print(f"mean over {len(table)} recording(s): {means}")
    if "smoothness" not in table:
        print(
            "smoothness: not reported, the time step is unknown (no --time column and no "
            "sampling period in the model file)"
        )


def command_predict(args):
    from sklearn.pipeline import Pipeline

    data_path = Path(args.data)
    output = Path(
        args.output or data_path.with_name(f"{data_path.stem}_predicted{data_path.suffix}")
    )
    read = [args.data, args.model]
    check_output(output, option="--output", overwrite=args.overwrite, inputs=read)
    if args.metrics is not None:
        check_output(args.metrics, option="--metrics", overwrite=args.overwrite, inputs=read)
        if Path(args.metrics).resolve() == output.resolve():
            raise CommandError(f"--metrics {args.metrics} is also the predictions' --output")
    model, training = load_model(args.model, return_training=True)
    frame = ordered_data(args)
    features = list(model.feature_names_in_)
    check_columns(frame, features, args.data)
    regressor = model[-1] if isinstance(model, Pipeline) else model
    names = [f"{args.prefix}{n}" for n in ("estimate", "estimate_std")]
    names += [f"{args.prefix}state_{k}" for k in range(regressor.n_states)]
    taken = [name for name in names if name in frame.columns]
    if taken:
        raise CommandError(
            f"{args.data} already has the column(s) {taken}, which predict writes: rename "
            "them, or pass --prefix to write the predictions under other names"
        )
    groups = frame[args.recording].to_numpy()
    inputs = model_inputs(frame, features, args)
    try:
        # the recordings reach every step of a pipeline (the velocity filter restarts)
        for _, step in model.steps[:-1] if regressor is not model else []:
            inputs = step.transform(inputs, groups=groups)
        estimate, std = regressor.predict(inputs, groups=groups, return_std=True)
        proba = regressor.predict_state_proba(inputs, groups=groups)
    except ValueError as exc:
        raise CommandError(f"{args.data}: {exc}") from exc
    try:
        table = _recording_metrics(frame, estimate, groups, args, training)
    except ValueError as exc:
        if args.metrics is not None:
            raise CommandError(f"{args.data}: no accuracy: {exc}") from exc
        print(f"skhmmgmr predict: no accuracy reported: {exc}", file=sys.stderr)
        table = None
    if args.metrics is not None and table is None:
        raise CommandError(
            f"--metrics: {args.data} has no target column {args.target!r} to compare with "
            "(name it with --target)"
        )
    written = {
        f"{args.prefix}estimate": estimate,
        f"{args.prefix}estimate_std": std,
        **{f"{args.prefix}state_{k}": proba[:, k] for k in range(proba.shape[1])},
    }
    result = pd.concat([frame, pd.DataFrame(written, index=frame.index)], axis=1)
    if output.suffix in (".parquet", ".pq"):
        write_output(output, result.to_parquet)
    else:
        write_output(output, lambda partial: result.to_csv(partial, index=False))
    log(args, f"Wrote {output} ({len(result)} rows)")
    if table is not None:
        _print_metrics(table, args)
    if args.metrics is not None:
        write_output(args.metrics, lambda partial: table.to_csv(partial, index=False))
        log(args, f"Wrote {args.metrics} ({len(table)} recordings)")
    return 0


def add_predict(sub, common):
    """The ``predict`` sub-command and its options."""
    predict = sub.add_parser(
        "predict",
        help="write estimate, std and state probabilities; report accuracy with the target",
        description="Predict with a model file of 'skhmmgmr fit' (a regressor or a torque "
        "pipeline). When the data hold the target column, print the RMSE, the accuracy and "
        "the smoothness (the standard deviation of the estimate's time derivative, lower is "
        "smoother) of every recording (skhmmgmr.metrics), and with --metrics write them.",
        **common,
    )
    predict.add_argument("model", help="model file (portable JSON) written by 'skhmmgmr fit'")
    predict.add_argument("data", help="CSV or Parquet file")
    add_data_options(predict, file_order=True)
    add_output_options(predict, None, "output file (default: DATA_predicted.EXT)")
    text = "CSV file for the metrics of every recording (needs the target column)"
    predict.add_argument("--metrics", help=text + " (default: printed only)")
    predict.add_argument(
        "--prefix",
        default="",
        help="written before the names of the columns predict adds (estimate, estimate_std, "
        "state_0, ...), when the data already has columns of those names",
    )
    predict.set_defaults(handler=command_predict)
    return predict
