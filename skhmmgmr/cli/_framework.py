"""The framework and its report: ``skhmmgmr demo``, ``select`` and ``report``.

``demo`` simulates the thesis' protocol for several virtual drivers, ``select`` reads the
user's recordings; both run :func:`~skhmmgmr.select_parameters` (on this machine or a dask
cluster, :mod:`._cluster`) and write the report folder (:mod:`._report`), which ``report``
renders again from its saved tables.
"""

import inspect
from pathlib import Path

from ..datasets import RECORDING, SPLIT, TIME
from ._cluster import add_scheduler_option, scheduler_context
from ._files import (
    CommandError,
    assign_splits,
    check_columns,
    check_output,
    check_time_column,
    read_data,
)
from ._options import (
    add_data_options,
    add_output_options,
    finite_float,
    log,
    option_name,
)
from ._saved_models import save_models
from ._showcase import DRIVER_EXPERIMENT, models_table
from ._stages import Stages


def _framework_defaults():
    """Defaults of :func:`~skhmmgmr.select_parameters`: ``select`` uses and shows them."""
    from ..selection import select_parameters

    parameters = inspect.signature(select_parameters).parameters
    return {name: parameter.default for name, parameter in parameters.items()}


DEMO_SCALES = {
    # section length [s], features kept by the filter, largest K, trade-off step [%]
    "default": dict(duration=20.0, n_top=6, k_max=8, trade_off_step=25),
    "full": dict(duration=300.0, n_top=10, k_max=20, trade_off_step=10),
}


def _demo_default(name):
    default, full = DEMO_SCALES["default"][name], DEMO_SCALES["full"][name]
    return f"(default: {default:g}; --full: {full:g})"


def _per_driver(test, drivers):
    table = test.assign(driver=test["recording"].map(drivers).fillna("unknown"))
    return (
        table.groupby(["driver", "model"], sort=False)[["rmse", "accuracy", "smoothness"]]
        .mean()
        .reset_index()
    )


def _run_framework(args, data, meta, stages, human=None, experiment=None):
    """select_parameters, the other models, figures and report folder; shared by ``demo``
    and ``select``. ``human``: the simulator's driver style that drives the held-out road
    beside the driver model (``demo`` only); ``experiment``: the perturbation experiment
    the driver model is fitted on (``demo`` only)."""
    from ..metrics import trade_offs
    from ..selection import select_parameters
    from ._report import report_tables, versions, write_report

    try:
        relevance_trade_offs = trade_offs(args.trade_off_step)
    except ValueError as exc:
        raise CommandError(f"--trade-off-step: {exc}") from exc
    period = float(data.groupby(RECORDING)[TIME].diff().median())
    with stages.stage("parameter selection"):
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
                    search=args.search,
                )
        except ValueError as exc:
            raise CommandError(str(exc)) from exc
    showcase = _other_models(args, report, data, period, stages, human, experiment)
    with stages.stage("figures", total=1) as bar:
        per_driver = _per_driver(
            report.test, dict(zip(data[RECORDING], data["driver"], strict=False))
        )
        figures = _figures(report, data, showcase, period)
        bar.update()
    models = models_table(showcase)
    tables = {
        "models": models,
        "lane_keeping": showcase.lane_keeping,
        **report_tables(report, per_driver),
        "models_test": showcase.test,
    }
    tables = {name: table for name, table in tables.items() if table is not None}
    notes = list(showcase.notes.values())
    saved = []

    def save(folder):
        saved[:] = save_models(
            showcase.candidates.values(), folder, sampling_period=period, notes=notes
        )
        meta["answers"] = _answers(report, data, models, showcase, saved, notes)
        return saved

    # the page shows the stages before its own, which ends once the page is written
    timings = {name: value["wall"] for name, value in stages.timings.items()}
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
        **{f"time: framework, {k} [s]": f"{v:.1f}" for k, v in report.timings.items()},
    }
    # the stages' wall and CPU seconds (this process only: not joblib's workers)
    meta.update(details=details, timings=stages.timings, notes=notes, versions=versions())
    with stages.stage("report and saved models", total=1) as bar:
        try:
            page = write_report(
                args.output,
                tables=tables,
                figures=figures,
                meta=meta,
                files=save,
                overwrite=args.overwrite,
            )
        except (ValueError, OSError) as exc:
            raise CommandError(f"cannot write the report {args.output}: {exc}") from exc
        bar.update()
    total = sum(value["wall"] for value in stages.timings.values())
    print(f"selected features: {', '.join(report.features)}; K = {report.n_states}")
    if report.empty_candidates:
        print(f"empty candidate subsets (not compared): {', '.join(report.empty_candidates)}")
    columns = ["label", "accuracy", "smoothness", "rmse"]
    print(models.set_index("model")[columns].round(3).to_string())
    for note in notes:
        print(note)
    log(args, f"Wrote {page} ({total:.1f} s)")
    return 0


def _other_models(args, report, data, period, stages, human, experiment):
    """The torque pipeline, gradient boosting and the driver model on the framework's split,
    and with ``human`` the driver model at the wheel of a held-out road."""
    from ._showcase import closed_loop, run_showcase

    with stages.stage("other models"):
        showcase = run_showcase(
            report, data, sampling_period=period, seed=args.seed, experiment=experiment
        )
    if human is not None and "driver_model" in showcase.candidates:
        with stages.stage("closed loop", total=1) as bar:
            showcase.drives, showcase.lane_keeping = closed_loop(
                showcase.candidates,
                human,
                sampling_rate=1.0 / period,
                seed=args.seed,
            )
            bar.update()
    return showcase


def _figures(report, data, showcase, period):
    """The framework's figures and the showcase's, in the page's order."""
    from ._report import report_figures

    figures = report_figures(report, data, sampling_period=period)
    if not figures:
        return figures
    from ._showcase_figures import (
        closed_loop_figure,
        models_estimate_figure,
        state_selection_figure,
        trade_off_figure,
    )

    models = models_table(showcase)
    figures["models_estimate"] = models_estimate_figure(showcase.first, models)
    figures["state_selection"] = state_selection_figure(report)
    figures["trade_off"] = trade_off_figure(report.candidates, models)
    if showcase.drives:
        figures["closed_loop"] = closed_loop_figure(showcase.drives, showcase.lane_keeping)
    order = ["estimate", "models_estimate", "state_selection", "trade_off", "closed_loop"]
    order += ["drivers", "relevance"]
    return {name: figures[name] for name in order if name in figures}


def _answers(report, data, models, showcase, saved, notes):
    """The page's first section, from the tables the report saves."""
    from . import _answers as answers
    from ._showcase import CLOSED_LOOP_ROAD

    n_validation = data.loc[data[SPLIT] == "validation", RECORDING].nunique()
    found = [
        (
            "What was selected, and why?",
            answers.selected_answer(
                models,
                report.state_choices,
                trade_off=report.trade_off,
                features=list(report.features),
                n_states=report.n_states,
                n_validation=n_validation,
            ),
        ),
        (
            "What does it gain and cost against the baseline?",
            answers.trade_off_answer(models, trade_off=report.trade_off),
        ),
        ("What to use for what?", answers.uses_answer(models)),
    ]
    if showcase.lane_keeping is not None:
        road = (
            f"setting {CLOSED_LOOP_ROAD['setting']}, {CLOSED_LOOP_ROAD['duration']:.0f} s at "
            "100 km/h"
        )
        found.append(
            ("Can the driver model drive?", answers.drive_answer(showcase.lane_keeping, road=road))
        )
    if saved:
        found.append(("How do I use a model outside Python?", answers.files_answer(saved)))
    return [{"question": q, "answer": a} for q, a in found]


def command_demo(args):
    """Simulate several drivers, run the whole framework, compare with the baseline on test."""
    from ..datasets import make_driving_protocol

    check_output(args.output, option="--output", overwrite=args.overwrite, report=True)
    scale = DEMO_SCALES["full" if args.full else "default"]
    for name, value in scale.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    log(
        args,
        f"Simulating drivers {', '.join(args.drivers)}: 12 training, 6 validation and 6 test "
        f"sections of {args.duration:.0f} s at {args.sampling_rate:g} Hz each",
    )
    stages = Stages(quiet=args.quiet)
    with stages.stage("simulation", total=1) as bar:
        try:
            protocol = dict(
                drivers=tuple(args.drivers),
                duration=args.duration,
                sampling_rate=args.sampling_rate,
                random_state=args.seed,
                n_jobs=args.n_jobs,
            )
            data = make_driving_protocol(**protocol)
            # the driver model's training: the same training sections, a third of them driven
            # again with a torque on the wheel the driver does not know (the others are
            # bit-identical to the framework's)
            experiment = make_driving_protocol(
                **protocol, n_validation=0, n_test=0, **DRIVER_EXPERIMENT
            )
        except ValueError as exc:
            raise CommandError(str(exc)) from exc
        bar.update()
    text = [
        "skhmmgmr demo: the thesis' driving protocol simulated for the virtual drivers "
        f"{', '.join(args.drivers)} (12 training sections on settings 1-6, 6 validation and 6 "
        f"test sections on setting 7, {args.duration:.0f} s each at {args.sampling_rate:g} Hz, "
        "100 km/h). The parameter selection framework (Spearman filter, exhaustive and "
        "forward wrappers, feature relevance, Strict/Mild/Liberal candidates, state selection "
        "with the 1% rule) chose the feature subset and K on the validation sections; the "
        "final model and the all-feature baseline with the same K were trained on the "
        "training sections and compared on the test sections. The driver model was trained "
        "on the same training sections, a third of them driven again with a 0.2 Nm RMS torque "
        "on the steering wheel that the driver did not know (a perturbation experiment), and "
        "scored on the same test sections.",
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
    }
    return _run_framework(args, data, meta, stages, human=args.drivers[0], experiment=experiment)


def command_select(args):
    """The framework on the user's recordings."""
    from ..datasets import load_recordings

    path = Path(args.data)
    if not path.exists():
        raise CommandError(f"data file not found: {path}")
    check_output(
        args.output, option="--output", overwrite=args.overwrite, inputs=[path], report=True
    )
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
    return _run_framework(args, data, meta, Stages(quiet=args.quiet))


def command_report(args):
    from ._report import render_html

    if Path(args.result_dir).is_file():
        raise CommandError(
            f"{args.result_dir} is a file: 'report' re-renders a report folder; to write the "
            f"report of recordings, run 'skhmmgmr select {args.result_dir}' (with --target, "
            "--recording and --time naming its columns)"
        )
    try:
        page = render_html(args.result_dir)
    except (ValueError, OSError) as exc:
        raise CommandError(str(exc)) from exc
    log(args, f"Wrote {page}")
    return 0


def _add_framework_options(parser, defaults=None):
    """Options of ``demo`` and ``select``; ``defaults=None``: the demo's scale decides."""
    framework = _framework_defaults()
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument(
        "--n-jobs", type=int, default=-1, help="parallel fits with joblib; -1: all cores"
    )
    add_scheduler_option(parser)
    add_output_options(parser, "skhmmgmr_report", "report folder")
    text = "accuracy/smoothness weights of every choice"
    parser.add_argument("--trade-off", default=framework["trade_off"], help=text)
    text = (
        "EM tolerance of the models that only screen features (the exhaustive and forward "
        "wrappers), e.g. 1e-3; the state sweep and the final model keep the strict one "
        "(default: the strict one everywhere)"
    )
    parser.add_argument("--screening-tol", type=finite_float, default=None, help=text)
    text = (
        "how the wrappers and the state sweep fit their models: full (each from its own "
        "start until EM converges) or fast (subsets scored as a joint model's marginal, the K "
        "grown by splitting a state; the K the rule reads and the compared candidates "
        "fitted in full)"
    )
    parser.add_argument(
        "--search", choices=("full", "fast"), default=framework["search"], help=text
    )
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
        parser.add_argument(option_name(name), type=int, default=default, help=text)


def add_demo(sub, common):
    """The ``demo`` sub-command and its options."""
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
        "--duration", type=finite_float, help=f"section length [s] {_demo_default('duration')}"
    )
    demo.add_argument("--sampling-rate", type=finite_float, default=20.0, help="logging rate [Hz]")
    demo.add_argument("--features", nargs="+", help="candidate features (default: all 18)")
    _add_framework_options(demo)
    demo.set_defaults(handler=command_demo)
    return demo


def add_select(sub, common):
    """The ``select`` sub-command and its options."""
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
    add_data_options(select)
    select.add_argument("--split", default=SPLIT, help="split column")
    select.add_argument("--features", nargs="+", help="candidate features (default: all numeric)")
    text = "check that every recording is sampled at this rate [Hz], or with --max-gap resample"
    text += " to it (default: neither)"
    select.add_argument("--sampling-rate", type=finite_float, help=text)
    text = "gaps up to this many seconds are interpolated, a longer one splits its recording"
    select.add_argument("--max-gap", type=finite_float, help=text + " (default: no resampling)")
    for part in ("validation", "test"):
        help_text = f"share of the recordings drawn for {part} when there is no split column"
        select.add_argument(f"--{part}-fraction", type=finite_float, default=0.25, help=help_text)
    framework = _framework_defaults()
    # relevance_trade_offs=None of select_parameters maps the trade-offs in 10% steps
    _add_framework_options(
        select, {"n_top": framework["n_top"], "k_max": framework["k_max"], "trade_off_step": 10}
    )
    select.set_defaults(handler=command_select)
    return select


def add_report(sub, common):
    """The ``report`` sub-command."""
    report = sub.add_parser(
        "report",
        help="re-render the HTML page of a report folder from its saved tables",
        description="Rebuild index.html from manifest.json, the CSV tables and the PNG figures.",
        **common,
    )
    report.add_argument("result_dir", help="folder written by 'skhmmgmr demo' or 'select'")
    report.set_defaults(handler=command_report)
    return report
