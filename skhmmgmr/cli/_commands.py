"""Command line: ``skhmmgmr demo | select | report | fit | predict | export-c`` (``python -m
skhmmgmr``).

Errors the user can fix (a missing file or column, unreadable data, an output that would
overwrite a file) are printed without a traceback and end with exit code 2. Reading inputs and
guarding outputs is :mod:`._files`' job.
"""

import argparse
import inspect
import sys
import time
from pathlib import Path

import pandas as pd

from .._core._schema import META_COLUMNS
from ..datasets import RECORDING, SPLIT, TARGET, TIME
from ._cluster import add_scheduler_option, scheduler_context
from ._files import (
    NO_TIME,
    CommandError,
    assign_splits,
    check_columns,
    check_output,
    check_time_column,
    in_time_order,
    load_model,
    read_data,
    write_output,
)


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's help ends with its default, unless it states it (as options whose
    default is None, decided at run time, do)."""

    def _get_help_string(self, action):
        if action.default is None or "(default" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


def _framework_defaults():
    """Defaults of :func:`~skhmmgmr.select_parameters`: ``select`` uses and shows them."""
    from ..selection import select_parameters

    parameters = inspect.signature(select_parameters).parameters
    return {name: parameter.default for name, parameter in parameters.items()}


def _log(args, message):
    if not getattr(args, "quiet", False):
        print(message, flush=True)


def _feature_columns(frame, args):
    if args.features:
        return list(args.features)
    excluded = {args.target, args.recording, args.time, TIME, *META_COLUMNS}
    return [
        c for c in frame.columns if c not in excluded and pd.api.types.is_numeric_dtype(frame[c])
    ]


DEMO_SCALES = {
    # section length [s], features kept by the filter, largest K, trade-off step [%]
    "default": dict(duration=20.0, n_top=6, k_max=8, trade_off_step=25),
    "full": dict(duration=300.0, n_top=10, k_max=20, trade_off_step=10),
}


def _demo_default(name):
    default, full = DEMO_SCALES["default"][name], DEMO_SCALES["full"][name]
    return f"(default: {default:g}; --full: {full:g})"


def _progress(args, total, desc):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, disable=getattr(args, "quiet", False), leave=False)


def _per_driver(test, drivers):
    table = test.assign(driver=test["recording"].map(drivers).fillna("unknown"))
    return (
        table.groupby(["driver", "model"], sort=False)[["rmse", "accuracy", "smoothness"]]
        .mean()
        .reset_index()
    )


def _run_framework(args, data, meta):
    """select_parameters + figures + report folder; shared by ``demo`` and ``select``."""
    from ..metrics import trade_offs
    from ..selection import select_parameters
    from ._report import report_figures, report_tables, versions, write_report

    try:
        relevance_trade_offs = trade_offs(args.trade_off_step)
    except ValueError as exc:
        raise CommandError(f"--trade-off-step: {exc}") from exc
    period = float(data.groupby(RECORDING)[TIME].diff().median())
    started = time.perf_counter()
    bar = _progress(args, 3, "skhmmgmr")
    bar.set_postfix_str("parameter selection")
    try:
        with scheduler_context(args):
            report = select_parameters(
                data,
                candidate_features=args.features,
                n_top=args.n_top,
                k_max=args.k_max,
                trade_off=args.trade_off,
                relevance_trade_offs=relevance_trade_offs,
                sampling_period=period,
                n_jobs=args.n_jobs,
                progress=not args.quiet,
                random_state=args.seed,
                screening_tol=args.screening_tol,
            )
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    bar.update()
    bar.set_postfix_str("figures")
    per_driver = _per_driver(report.test, dict(zip(data[RECORDING], data["driver"], strict=False)))
    figures = report_figures(report, data, sampling_period=period)
    bar.update()
    bar.set_postfix_str("report")
    timings = {**meta.pop("timings", {}), **report.timings}
    timings["total"] = (
        sum(timings.values()) + time.perf_counter() - started - sum(report.timings.values())
    )
    details = {
        **meta.pop("details", {}),
        "selected features": ", ".join(report.features),
        "selected number of states K": report.n_states,
        "trade-off": report.trade_off,
        "filter / K range": f"top {args.n_top} features, K = 1..{args.k_max}",
        "relevance trade-offs": ", ".join(relevance_trade_offs),
        "empty candidate subsets": ", ".join(report.empty_candidates) or "none",
        "seed": args.seed,
        "n_jobs": args.n_jobs,
        "scheduler": args.scheduler or "joblib on this machine",
        **{f"time: {k} [s]": f"{v:.1f}" for k, v in timings.items()},
    }
    try:
        page = write_report(
            args.output,
            tables=report_tables(report, per_driver),
            figures=figures,
            meta={**meta, "details": details, "timings": timings, "versions": versions()},
            overwrite=args.overwrite,
        )
    except (ValueError, OSError) as exc:
        raise CommandError(f"cannot write the report {args.output}: {exc}") from exc
    bar.update()
    bar.close()
    columns = ["rmse", "accuracy", "smoothness", "performance_score", "n_features", "n_states"]
    print(f"selected features: {', '.join(report.features)}; K = {report.n_states}")
    if report.empty_candidates:
        print(f"empty candidate subsets (not compared): {', '.join(report.empty_candidates)}")
    print(report.test_summary.set_index("model")[columns].round(3).to_string())
    print(per_driver.set_index(["driver", "model"]).round(3).to_string())
    _log(args, f"Wrote {page} ({timings['total']:.1f} s)")
    return 0


def command_demo(args):
    """Simulate several drivers, run the whole framework, compare with the baseline on test."""
    from ..datasets import make_driving_protocol

    check_output(args.output, overwrite=args.overwrite, report=True)
    scale = DEMO_SCALES["full" if args.full else "default"]
    for name, value in scale.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    _log(
        args,
        f"Simulating drivers {', '.join(args.drivers)}: 12 training, 6 validation and 6 test "
        f"sections of {args.duration:.0f} s at {args.sampling_rate:g} Hz each",
    )
    started = time.perf_counter()
    bar = _progress(args, 1, "simulation")
    try:
        data = make_driving_protocol(
            drivers=tuple(args.drivers),
            duration=args.duration,
            sampling_rate=args.sampling_rate,
            random_state=args.seed,
            n_jobs=args.n_jobs,
        )
    except ValueError as exc:
        raise CommandError(str(exc)) from exc
    bar.update()
    bar.close()
    text = [
        "skhmmgmr demo: the thesis' driving protocol simulated for the virtual drivers "
        f"{', '.join(args.drivers)} (12 training sections on settings 1-6, 6 validation and 6 "
        f"test sections on setting 7, {args.duration:.0f} s each at {args.sampling_rate:g} Hz, "
        "100 km/h). The parameter selection framework (Spearman filter, exhaustive and "
        "forward wrappers, feature relevance, Strict/Mild/Liberal candidates, state selection "
        "with the 1% rule) chose the feature subset and K on the validation sections; the "
        "final model and the all-feature baseline with the same K were trained on the "
        "training sections and compared on the test sections.",
    ]
    details = {
        "drivers": ", ".join(args.drivers),
        "scale": "thesis (--full)" if args.full else "reduced (default)",
        "section length [s]": args.duration,
        "sampling rate [Hz]": args.sampling_rate,
        "recordings": data[RECORDING].nunique(),
    }
    meta = {
        "title": "skhmmgmr demo: driver steering-torque models",
        "command": "demo",
        "text": text,
        "details": details,
        "timings": {"simulation": time.perf_counter() - started},
    }
    return _run_framework(args, data, meta)


def command_select(args):
    """The framework on the user's recordings."""
    from ..datasets import load_recordings

    path = Path(args.data)
    if not path.exists():
        raise CommandError(f"data file not found: {path}")
    check_output(args.output, overwrite=args.overwrite, inputs=[path], report=True)
    source = path
    if path.is_file():
        source = read_data(path, args.recording, args.split)
        check_columns(source, [args.recording, args.target], path)
        check_time_column(source, args.time, path, file_order=False)
        if args.split in source.columns and args.split != SPLIT:
            source = source.drop(columns=SPLIT, errors="ignore").rename(columns={args.split: SPLIT})
        if args.features:
            check_columns(source, args.features, path)
    try:
        data = load_recordings(
            source,
            recording=args.recording,
            time=args.time,
            target=args.target,
            features=args.features,
            sampling_rate=args.sampling_rate,
            max_gap=args.max_gap,
        )
    except ValueError as exc:
        raise CommandError(f"{path}: {exc}") from exc
    splits = set(data[SPLIT])
    if splits <= {"train", "validation", "test"} and len(splits) == 3:
        rule = f"the '{args.split}' column"
    elif splits == {"unknown"}:
        data[SPLIT] = assign_splits(data, args)
        rule = (
            f"recordings drawn at random (seed {args.seed}): {args.validation_fraction:.0%} "
            f"validation, {args.test_fraction:.0%} test, the rest training"
        )
    else:
        raise CommandError(
            f"{path}: the '{args.split}' column must hold 'train', 'validation' and 'test' "
            f"(found {sorted(map(str, splits))}); drop it to split by recording"
        )
    counts = data.groupby(SPLIT)[RECORDING].nunique().to_dict()
    meta = {
        "title": f"skhmmgmr select: {path.name}",
        "command": "select",
        "text": [
            f"skhmmgmr select on {path}: the parameter selection framework on the user's "
            f"recordings, target '{args.target}', split by {rule}."
        ],
        "details": {
            "data": str(path),
            "recordings (train/validation/test)": "/".join(
                str(counts.get(s, 0)) for s in ("train", "validation", "test")
            ),
            "split": rule,
        },
    }
    return _run_framework(args, data, meta)


def command_report(args):
    from ._report import render_html

    try:
        page = render_html(args.result_dir)
    except (ValueError, OSError) as exc:
        raise CommandError(str(exc)) from exc
    _log(args, f"Wrote {page}")
    return 0


def _ordered_data(args):
    """The data of ``fit``/``predict``, rows gathered by recording and sorted by time (in file
    order with ``--time none``)."""
    frame = read_data(args.data, args.recording)
    check_columns(frame, [args.recording], args.data)
    check_time_column(frame, args.time, args.data, file_order=True)
    time = None if args.time == NO_TIME else args.time
    if time is None:
        _log(args, f"--time {NO_TIME}: the rows of {args.data} are taken in file order")
    return in_time_order(frame, args.data, recording=args.recording, time=time)


# --pipeline: the models fit can write
PIPELINES = ("hmmgmr", "torque")
# Options of --pipeline torque, the parameters of make_torque_pipeline they set.
TORQUE_OPTIONS = {
    "friction_velocity": "steering-wheel velocity [rad/s] over which friction changes sign "
    "('auto': chosen on the training recordings; 'none': no friction input)",
    "friction_column": "column of the steering-wheel velocity",
    "load_columns": "columns whose signed powers are appended (the option alone: none)",
    "powers": "powers >= 2 appended for every load column",
    "velocity_filter": "time constant [s] of a causal low-pass filter on the velocity before "
    "the friction input, restarted at every recording ('auto': none or one chosen on the "
    "training recordings, given the sampling period; 'none': no filter)",
    "output_smoothing": "time constant [rows] of the causal first-order read-out of the "
    "estimate ('auto': the weakest whose estimate is no rougher than the measured target on "
    "the training recordings; 'none': the filter's estimate itself)",
}


def _torque_defaults():
    """Defaults of :func:`~skhmmgmr.make_torque_pipeline` (and of ``SteeringFeatures``):
    ``fit --pipeline torque`` uses and shows them."""
    from ..torque_pipeline import SteeringFeatures, make_torque_pipeline

    defaults = {}
    for function in (SteeringFeatures, make_torque_pipeline):
        for name, parameter in inspect.signature(function).parameters.items():
            if name in TORQUE_OPTIONS:
                defaults[name] = parameter.default
    return defaults


def _option(name):
    return f"--{name.replace('_', '-')}"


def _sampling_period(frame, args):
    """Seconds between two rows: ``--sampling-period``, else the median time step of the
    recordings (``None`` without a time column)."""
    if args.sampling_period is not None:
        if not args.sampling_period > 0:
            raise CommandError(f"--sampling-period must be positive, got {args.sampling_period}")
        return args.sampling_period
    if args.time == NO_TIME:
        return None
    step = frame.groupby(args.recording, sort=False)[args.time].diff().median()
    return None if pd.isna(step) else float(step)


def _model_to_fit(args, period):
    """The unfitted model of ``--pipeline`` with the options that reach it."""
    from ..estimator import HMMGMRRegressor
    from ..torque_pipeline import make_torque_pipeline

    common = dict(random_state=args.seed, n_init=args.n_init)
    # absent options are absent from args (SUPPRESS): "none" may be given explicitly
    given = {n: getattr(args, n) for n in TORQUE_OPTIONS if hasattr(args, n)}
    if args.pipeline != "torque":
        if given:
            options = ", ".join(map(_option, given))
            raise CommandError(f"{options}: for --pipeline torque only")
        return HMMGMRRegressor(n_states=args.n_states, **common)
    options = _torque_defaults()
    options.update(given)
    for name in ("load_columns", "powers"):
        options[name] = tuple(options[name])
    if options["velocity_filter"] not in (None, "auto") and period is None:
        raise CommandError(
            f"--velocity-filter needs the sampling period: give --sampling-period, or a time "
            f"column (--time, now {args.time!r})"
        )
    friction_column = options.pop("friction_column")
    pipe = make_torque_pipeline(args.n_states, sampling_period=period, **options, **common)
    pipe.set_params(steering_features__friction_column=friction_column)
    return pipe


def _inputs(frame, features, args):
    """The feature columns, indexed by the time column when there is one: a velocity filter
    checks its sampling period against it in every recording."""
    X = frame[features]
    if args.time == NO_TIME:
        return X
    return X.set_axis(pd.Index(frame[args.time].to_numpy(dtype=float), name=TIME))


def command_fit(args):
    from ..portable import save

    check_output(args.output, overwrite=args.overwrite, inputs=[args.data])
    frame = _ordered_data(args)
    check_columns(frame, [args.target], args.data)
    features = _feature_columns(frame, args)
    check_columns(frame, features, args.data)
    period = _sampling_period(frame, args)
    model = _model_to_fit(args, period)
    try:
        model.fit(
            _inputs(frame, features, args),
            frame[args.target],
            groups=frame[args.recording].to_numpy(),
        )
    except ValueError as exc:
        raise CommandError(f"{args.data}: {exc}") from exc
    write_output(
        args.output,
        lambda path: save(model, path, output_names=[args.target], sampling_period=period),
    )
    derived = ""
    if args.pipeline == "torque":
        names = list(model[0].get_feature_names_out())[len(features) :]
        derived = f"; derived by the torque pipeline: {', '.join(names) or 'none'}"
        if model[0].friction_velocity is not None:
            derived += (
                f" (friction_velocity {model[0].friction_velocity_:g}, velocity_filter "
                f"{model[0].velocity_filter_ or 'none'})"
            )
        derived += f"; read-out time constant {model[-1].output_smoothing_:g} rows"
    _log(
        args,
        f"Fitted K={args.n_states} on {len(features)} input(s): {', '.join(features)}"
        f"{derived}; wrote {args.output}",
    )
    return 0


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
    check_output(output, overwrite=args.overwrite, inputs=[args.data, args.model])
    if args.metrics is not None:
        check_output(args.metrics, overwrite=args.overwrite, inputs=[args.data, args.model])
        if Path(args.metrics).resolve() == output.resolve():
            raise CommandError(f"--metrics {args.metrics} is also the predictions' --output")
    model, training = load_model(args.model, return_training=True)
    frame = _ordered_data(args)
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
    inputs = _inputs(frame, features, args)
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
    _log(args, f"Wrote {output} ({len(result)} rows)")
    if table is not None:
        _print_metrics(table, args)
    if args.metrics is not None:
        write_output(args.metrics, lambda partial: table.to_csv(partial, index=False))
        _log(args, f"Wrote {args.metrics} ({len(table)} recordings)")
    return 0


def command_export_c(args):
    """The C code of a model file written by ``fit`` (:func:`skhmmgmr.export.write_c`)."""
    from ..export import write_c
    from ..export._model import check_name

    model = load_model(args.model)
    folder = Path(args.directory)
    if folder.exists() and not folder.is_dir():
        raise CommandError(f"{folder} exists and is not a folder")
    folder.mkdir(parents=True, exist_ok=True)
    try:
        name = check_name(args.name)
    except ValueError as exc:
        raise CommandError(f"--name: {exc}") from exc
    for suffix in (".h", ".c"):
        check_output(folder / f"{name}{suffix}", overwrite=args.overwrite, inputs=[args.model])
    try:
        header, source = write_c(
            model, folder, name=name, dtype=args.dtype, overwrite=args.overwrite
        )
    except ValueError as exc:
        raise CommandError(f"{args.model}: {exc}") from exc
    _log(args, f"Wrote {header} and {source} ({args.dtype})")
    return 0


def _add_data_options(parser, *, file_order=False):
    parser.add_argument("--target", default=TARGET, help="target column")
    parser.add_argument("--recording", default=RECORDING, help="recording-id column")
    text = "time column [s]: rows are sorted by it within each recording; never an input"
    if file_order:
        text += f" ('{NO_TIME}': no time column, the rows are taken in file order)"
    parser.add_argument("--time", default=TIME, help=text)


def _add_output_options(parser, default, text):
    parser.add_argument("--output", default=default, help=text)
    text = "replace an existing output that is not a skhmmgmr report (never an input)"
    parser.add_argument("--overwrite", action="store_true", help=text)


def _none_or_float(text):
    return None if text.lower() == "none" else float(text)


def _setting(text):
    """A derived input's setting: a number, 'none' or 'auto' (chosen in fit)."""
    return "auto" if text.lower() == "auto" else _none_or_float(text)


def _add_torque_options(parser):
    """Options of ``fit --pipeline torque``, the parameters of ``make_torque_pipeline``."""
    defaults = _torque_defaults()

    def shown(name):
        value = defaults[name]
        value = " ".join(map(str, value)) if isinstance(value, tuple) else value
        value = "none" if value is None else value
        return f"{TORQUE_OPTIONS[name]}; --pipeline torque only (default: {value})"

    kinds = {
        "friction_velocity": dict(type=_setting),
        "friction_column": {},
        "load_columns": dict(nargs="*"),
        "powers": dict(nargs="*", type=int),
        "velocity_filter": dict(type=_setting),
        "output_smoothing": dict(type=_setting),
    }
    for name, kind in kinds.items():
        parser.add_argument(_option(name), default=argparse.SUPPRESS, help=shown(name), **kind)


def _add_framework_options(parser, defaults=None):
    """Options of ``demo`` and ``select``; ``defaults=None``: the demo's scale decides."""
    framework = _framework_defaults()
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument(
        "--n-jobs", type=int, default=-1, help="parallel fits with joblib; -1: all cores"
    )
    add_scheduler_option(parser)
    _add_output_options(parser, "skhmmgmr_report", "report folder")
    text = "accuracy/smoothness weights of every choice"
    parser.add_argument("--trade-off", default=framework["trade_off"], help=text)
    text = (
        "EM tolerance of the models that only screen features (the exhaustive and forward "
        "wrappers), e.g. 1e-3; the state sweep and the final model keep the strict one "
        "(default: the strict one everywhere)"
    )
    parser.add_argument("--screening-tol", type=float, default=None, help=text)
    helps = {
        "n_top": "features kept by the filter",
        "k_max": "largest number of states",
        "trade_off_step": "step of the trade-offs mapped by the relevance [%%]",
    }
    for name, text in helps.items():
        if defaults is None:
            default, text = None, f"{text} {_demo_default(name)}"
        else:
            default = defaults[name]
        parser.add_argument(f"--{name.replace('_', '-')}", type=int, default=default, help=text)


def build_parser():
    description = "HMM-GMR driver steering-torque models."
    parser = argparse.ArgumentParser(
        "skhmmgmr", description=description, formatter_class=_HelpFormatter
    )
    parser.add_argument("--quiet", action="store_true", help="print results only")
    sub = parser.add_subparsers(dest="command", required=True)
    quiet = argparse.ArgumentParser(add_help=False)
    # SUPPRESS keeps a --quiet given before the sub-command
    text = "print results only (default: False)"
    quiet.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS, help=text)
    common = dict(parents=[quiet], formatter_class=_HelpFormatter)

    demo = sub.add_parser(
        "demo",
        help="run the whole framework on simulated drivers and write a report",
        description="Simulate the thesis' protocol for several virtual drivers, select the "
        "features and K, compare the final model with the all-feature baseline on the test "
        "sections, and write an HTML report with its tables and figures.",
        **common,
    )
    demo.add_argument(
        "--full", action="store_true", help="thesis scale: 5-minute sections, top 10, K<=20"
    )
    drivers = ["defensive", "aggressive", "novice"]
    demo.add_argument("--drivers", nargs="+", default=drivers, help="driver styles")
    demo.add_argument(
        "--duration", type=float, help=f"section length [s] {_demo_default('duration')}"
    )
    demo.add_argument("--sampling-rate", type=float, default=20.0, help="logging rate [Hz]")
    demo.add_argument("--features", nargs="+", help="candidate features (default: all 18)")
    _add_framework_options(demo)
    demo.set_defaults(handler=command_demo)

    select = sub.add_parser(
        "select",
        help="run the whole framework on your recordings and write a report",
        description="Parameter selection on CSV/Parquet recordings (a file, or a folder with "
        "one file per recording). Rows are sorted by time within each recording. Recordings are "
        "split by the --split column (values train, validation, test); without it they are "
        "drawn at random by recording with --validation-fraction and --test-fraction.",
        **common,
    )
    select.add_argument("data", help="CSV or Parquet file, or a folder of them")
    _add_data_options(select)
    select.add_argument("--split", default=SPLIT, help="split column")
    select.add_argument("--features", nargs="+", help="candidate features (default: all numeric)")
    text = "check that every recording is sampled at this rate [Hz], or with --max-gap resample"
    select.add_argument("--sampling-rate", type=float, help=text + " to it (default: neither)")
    text = "gaps up to this many seconds are interpolated, a longer one splits its recording"
    select.add_argument("--max-gap", type=float, help=text + " (default: no resampling)")
    for part in ("validation", "test"):
        help_text = f"share of the recordings drawn for {part} when there is no split column"
        select.add_argument(f"--{part}-fraction", type=float, default=0.25, help=help_text)
    framework = _framework_defaults()
    # relevance_trade_offs=None of select_parameters maps the trade-offs in 10% steps
    _add_framework_options(
        select, {"n_top": framework["n_top"], "k_max": framework["k_max"], "trade_off_step": 10}
    )
    select.set_defaults(handler=command_select)

    report = sub.add_parser(
        "report",
        help="re-render the HTML page of a report folder from its saved tables",
        description="Rebuild index.html from manifest.json, the CSV tables and the PNG figures.",
        **common,
    )
    report.add_argument("result_dir", help="folder written by 'skhmmgmr demo' or 'select'")
    report.set_defaults(handler=command_report)

    fit = sub.add_parser(
        "fit",
        help="fit a model on CSV/Parquet recordings",
        description="Fit HMMGMRRegressor, or with --pipeline torque the recommended torque "
        "pipeline (make_torque_pipeline: friction and steering-load inputs derived in front of "
        "it), and save it as one portable JSON model file.",
        **common,
    )
    fit.add_argument("data", help="CSV or Parquet file, one row per sample")
    _add_data_options(fit, file_order=True)
    fit.add_argument("--features", nargs="+", help="feature columns (default: all numeric)")
    fit.add_argument("--n-states", type=int, default=5, help="number of hidden states K")
    fit.add_argument("--n-init", type=int, default=1, help="EM restarts, the best one is kept")
    fit.add_argument("--seed", type=int, default=0, help="random seed")
    text = (
        "model to fit: 'hmmgmr', HMMGMRRegressor on the features; 'torque', the torque "
        "pipeline (the package's most accurate model; its columns must be among the features)"
    )
    fit.add_argument("--pipeline", choices=PIPELINES, default="hmmgmr", help=text)
    _add_torque_options(fit)
    text = (
        "seconds between two rows, for --velocity-filter and the smoothness predict reports "
        "(default: the median time step of the recordings, none with --time none)"
    )
    fit.add_argument("--sampling-period", type=float, help=text)
    _add_output_options(fit, "model.json", "model file to write (portable JSON)")
    fit.set_defaults(handler=command_fit)

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
    _add_data_options(predict, file_order=True)
    _add_output_options(predict, None, "output file (default: DATA_predicted.EXT)")
    text = "CSV file for the metrics of every recording (needs the target column)"
    predict.add_argument("--metrics", help=text + " (default: printed only)")
    predict.add_argument(
        "--prefix",
        default="",
        help="written before the names of the columns predict adds (estimate, estimate_std, "
        "state_0, ...), when the data already has columns of those names",
    )
    predict.set_defaults(handler=command_predict)

    export = sub.add_parser(
        "export-c",
        help="write a model's causal filter as C99 source (<name>.h, <name>.c)",
        description="Write the causal filter of a model file as C99 code for embedded targets: "
        "static parameters, a caller-owned state, no heap; see the user guide, 'C code of a "
        "fitted model'.",
        **common,
    )
    export.add_argument("model", help="model file (portable JSON) written by 'skhmmgmr fit'")
    export.add_argument("directory", help="folder the two files are written to (made if absent)")
    export.add_argument("--name", default="skhmmgmr_model", help="C prefix of files and names")
    export.add_argument(
        "--float32",
        dest="dtype",
        action="store_const",
        const="float32",
        default="float64",
        help="single-precision arithmetic (default: double)",
    )
    export.add_argument(
        "--overwrite", action="store_true", help="replace existing files of that name"
    )
    export.set_defaults(handler=command_export_c)
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
