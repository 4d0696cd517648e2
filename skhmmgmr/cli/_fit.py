"""``skhmmgmr fit``: a model fitted on the user's recordings, saved as one model file.

The model is :class:`~skhmmgmr.HMMGMRRegressor` on the feature columns, or with ``--pipeline
torque`` the torque pipeline (:func:`~skhmmgmr.make_torque_pipeline`), whose options are the
pipeline's parameters, shown with their defaults and checked by their own rules. The file is
the portable JSON model file (:func:`skhmmgmr.portable.save`), with the sampling period.
"""

import argparse
import inspect

import pandas as pd

from .._core._schema import EXPERIMENT_COLUMNS, META_COLUMNS
from .._core._sequences import median_time_step
from ..datasets import TIME
from ._files import (
    CommandError,
    check_columns,
    check_output,
    model_inputs,
    ordered_data,
    write_output,
)
from ._options import (
    NO_TIME,
    add_data_options,
    add_output_options,
    checked_by,
    finite_float,
    log,
    option_name,
    setting,
)


def _feature_columns(frame, args):
    """The inputs: ``--features`` (never the target, the recording ids or the time), else
    every numeric column but those and the package's label columns."""
    roles = {
        args.target: "the target (--target)",
        args.recording: "the recording-id column (--recording)",
    }
    if args.time != NO_TIME:
        roles[args.time] = "the time column (--time), which is never an input"
    if args.features:
        for name in args.features:
            if name in roles:
                raise CommandError(f"--features: {name!r} is {roles[name]}; leave it out")
        repeated = sorted({name for name in args.features if args.features.count(name) > 1})
        if repeated:
            raise CommandError(f"--features names {repeated} more than once")
        return list(args.features)
    excluded = {*roles, TIME, *META_COLUMNS, *EXPERIMENT_COLUMNS}
    return [
        c for c in frame.columns if c not in excluded and pd.api.types.is_numeric_dtype(frame[c])
    ]


# --pipeline: the models fit can write
PIPELINES = ("hmmgmr", "torque")
# Options of --pipeline torque, the parameters of make_torque_pipeline they set.
TORQUE_OPTIONS = {
    "friction_velocity": "steering-wheel velocity [rad/s] over which friction changes sign "
    "('auto': no band, one band or a basis of several, their widths read from the velocity "
    "and chosen on the training recordings; 'none': no friction input)",
    "friction_column": "column of the steering-wheel velocity",
    "friction_angle": "half-width [rad] of a play on the steering-wheel angle, the hysteresis "
    "input of a column whose friction sticks ('auto': none or several chosen on the training "
    "recordings; 'none': no hysteresis input)",
    "angle_column": "column of the steering-wheel angle, the input of the plays",
    "angle_lead": "time [s] by which the plays read the angle ahead on the velocity, angle + "
    "lead * velocity ('auto': none, 0.02 or 0.05 s chosen on the training recordings; 'none': "
    "the angle itself)",
    "slow_velocity_filter": "time constant [s] of a second, slow low-pass filter on the "
    "velocity, whose friction inputs follow the others ('auto': none, 0.1 or 0.2 s chosen on "
    "the training recordings, given the sampling period; 'none': no such inputs)",
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


def _sampling_period(frame, args):
    """Seconds between two rows: ``--sampling-period``, else the median time step of the
    recordings, as the torque pipeline reads it from a time index (``None`` without a time
    column)."""
    if args.sampling_period is not None:  # checked when parsed
        return args.sampling_period
    if args.time == NO_TIME:
        return None
    return median_time_step(frame[args.time], frame[args.recording])


def _model_to_fit(args, period):
    """The unfitted model of ``--pipeline`` with the options that reach it."""
    from ..estimator import HMMGMRRegressor
    from ..torque_pipeline import make_torque_pipeline

    common = dict(random_state=args.seed, n_init=args.n_init)
    # absent options are absent from args (SUPPRESS): "none" may be given explicitly
    given = {n: getattr(args, n) for n in TORQUE_OPTIONS if hasattr(args, n)}
    if args.pipeline != "torque":
        if given:
            options = ", ".join(map(option_name, given))
            raise CommandError(f"{options}: for --pipeline torque only")
        return HMMGMRRegressor(n_states=args.n_states, **common)
    options = _torque_defaults()
    options.update(given)
    for name in ("load_columns", "powers"):
        options[name] = tuple(options[name])
    for name in ("velocity_filter", "slow_velocity_filter"):
        if options[name] not in (None, "auto") and period is None:
            raise CommandError(
                f"{option_name(name)} needs the sampling period: give --sampling-period, or a "
                f"time column (--time, now {args.time!r})"
            )
    columns = {name: options.pop(name) for name in ("friction_column", "angle_column")}
    pipe = make_torque_pipeline(args.n_states, sampling_period=period, **options, **common)
    pipe.set_params(**{f"steering_features__{name}": value for name, value in columns.items()})
    return pipe


def command_fit(args):
    from ..portable import save

    check_output(args.output, option="--output", overwrite=args.overwrite, inputs=[args.data])
    frame = ordered_data(args)
    check_columns(frame, [args.target], args.data)
    features = _feature_columns(frame, args)
    check_columns(frame, features, args.data)
    period = _sampling_period(frame, args)
    model = _model_to_fit(args, period)
    try:
        model.fit(
            model_inputs(frame, features, args),
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
        friction = model[0].friction_velocity_
        if friction is not None:
            widths = friction if isinstance(friction, tuple) else (friction,)
            derived += (
                f" (friction_velocity {', '.join(f'{w:g}' for w in widths)}, velocity_filter "
                f"{model[0].velocity_filter_ or 'none'}, slow_velocity_filter "
                f"{model[0].slow_velocity_filter_ or 'none'})"
            )
        radii = model[0].friction_angle_
        if radii is not None:
            derived += f" (friction_angle {', '.join(f'{r:g}' for r in radii)}"
            lead = model[0].angle_lead_
            derived += ")" if lead is None else f", angle_lead {lead:g})"
        derived += f"; read-out time constant {model[-1].output_smoothing_:g} rows"
    log(
        args,
        f"Fitted K={args.n_states} on {len(features)} input(s): {', '.join(features)}"
        f"{derived}; wrote {args.output}",
    )
    return 0


def _add_torque_options(parser):
    """Options of ``fit --pipeline torque``, the parameters of ``make_torque_pipeline``,
    checked when parsed by the rules of the parameters they set."""
    from ..estimator import HMMGMRRegressor
    from ..torque_pipeline import SteeringFeatures

    defaults = _torque_defaults()

    def shown(name):
        value = defaults[name]
        value = " ".join(map(str, value)) if isinstance(value, tuple) else value
        value = "none" if value is None else value
        return f"{TORQUE_OPTIONS[name]}; --pipeline torque only (default: {value})"

    kinds = {
        "friction_velocity": dict(type=checked_by(setting, SteeringFeatures, "friction_velocity")),
        "friction_column": {},
        "friction_angle": dict(type=checked_by(setting, SteeringFeatures, "friction_angle")),
        "angle_column": {},
        "angle_lead": dict(type=checked_by(setting, SteeringFeatures, "angle_lead")),
        "load_columns": dict(nargs="*"),
        "powers": dict(nargs="*", type=int),
        "velocity_filter": dict(type=checked_by(setting, SteeringFeatures, "velocity_filter")),
        "slow_velocity_filter": dict(
            type=checked_by(setting, SteeringFeatures, "slow_velocity_filter")
        ),
        "output_smoothing": dict(type=checked_by(setting, HMMGMRRegressor, "output_smoothing")),
    }
    for name, kind in kinds.items():
        parser.add_argument(option_name(name), default=argparse.SUPPRESS, help=shown(name), **kind)


def add_fit(sub, common):
    """The ``fit`` sub-command and its options."""
    from ..torque_pipeline import SteeringFeatures

    fit = sub.add_parser(
        "fit",
        help="fit a model on CSV/Parquet recordings",
        description="Fit HMMGMRRegressor, or with --pipeline torque the recommended torque "
        "pipeline (make_torque_pipeline: friction and steering-load inputs derived in front of "
        "it), and save it as one portable JSON model file.",
        **common,
    )
    fit.add_argument("data", help="CSV or Parquet file, one row per sample")
    add_data_options(fit, file_order=True)
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
    period = checked_by(finite_float, SteeringFeatures, "sampling_period")
    fit.add_argument("--sampling-period", type=period, help=text)
    add_output_options(fit, "model.json", "model file to write (portable JSON)")
    fit.set_defaults(handler=command_fit)
    return fit
