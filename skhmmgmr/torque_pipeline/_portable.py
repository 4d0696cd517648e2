"""The model file of a fitted torque pipeline, or of its regressor alone: the whole file by its
``model_type`` (format in :mod:`skhmmgmr.portable`'s docstring, which writes and reads it).

The regressor's block (``_hmm/_portable.py``) is the file of a regressor and the last step of a
pipeline's; this module adds the ``SteeringFeatures`` steps before it (their parameters, the
values chosen in ``fit`` in place of ``"auto"``, their fitted facts), the file's header and
``training`` block, and refuses, naming the type or the step, what a model file cannot hold.
Reading restores every step and checks that each one's outputs are the next one's inputs.
"""

import math
import numbers

from sklearn.pipeline import Pipeline
from sklearn.utils.validation import check_is_fitted

from .._core._compat import InvalidParameterError
from .._hmm._portable import (
    FORMAT_NAME,
    HIERARCHICAL_TYPE,
    REGRESSOR_TYPE,
    REGRESSOR_TYPES,
    check_model_file,
    estimator_from_dict,
    estimator_to_dict,
    read_header,
    read_training,
)
from .._version import __version__
from ..estimator import HierarchicalHMMGMRRegressor, HMMGMRRegressor
from ._driver_model import DriverModel
from ._pipeline import TorquePipeline
from ._steering_features import SteeringFeatures, restore_steering_features

#: The classes a model file holds, by their ``model_type``.
MODEL_TYPES = {
    REGRESSOR_TYPE: HMMGMRRegressor,
    HIERARCHICAL_TYPE: HierarchicalHMMGMRRegressor,
    "TorquePipeline": TorquePipeline,
    "DriverModel": DriverModel,
    "Pipeline": Pipeline,
}
#: A driver model's block (``driver_model``): its trade-off, then the fitted facts of the
#: perturbation it was fitted on, by key and attribute.
DRIVER_MODEL_FACTS = {
    "perturbation_rms": "perturbation_rms_",
    "perturbed_share": "perturbed_share_",
    "penalty_scale": "penalty_scale_",
}
#: Without ``preview_columns`` and ``penalty_scale`` (files of the first driver model) the
#: block holds a penalty in multiples of the perturbation: ``preview_columns=None``, scale 1.
STEERING_TYPE = "SteeringFeatures"
STEERING_PARAMS = (
    "friction_velocity",
    "friction_column",
    "load_columns",
    "powers",
    "velocity_filter",
    "sampling_period",
)
#: The keys of a step's hysteresis inputs, written only by a step that has them.
HYSTERESIS_PARAMS = ("friction_angle", "angle_column")


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------


def _type_name(value):
    kind = type(value)
    return f"{kind.__module__}.{kind.__qualname__}"


def _is_regressor(value):
    """Whether ``value`` is exactly one of the regressor classes a model file holds."""
    return any(type(value) is MODEL_TYPES[name] for name in REGRESSOR_TYPES)


def model_to_dict(fitted, *, output_names, units, period):
    """The model file's dict of a fitted regressor or pipeline, or a TypeError naming what
    a model file cannot hold (the type, or the step)."""
    if _is_regressor(fitted):
        data = estimator_to_dict(fitted, output_names=output_names)
        names = [*data["feature_names"], *data["output_names"]]
        data["training"] = _training(data["training"], units, period, names)
        return data
    model_type = next((name for name, cls in MODEL_TYPES.items() if type(fitted) is cls), None)
    if model_type is None:
        raise TypeError(
            "a model file holds an HMMGMRRegressor, a HierarchicalHMMGMRRegressor, a "
            "TorquePipeline or a Pipeline of SteeringFeatures steps and one of the two "
            f"regressors; got {_type_name(fitted)}"
        )
    *transformers, (last_name, regressor) = fitted.steps
    steps = []
    for name, step in transformers:
        if type(step) is not SteeringFeatures:
            what = repr(step) if step is None or isinstance(step, str) else _type_name(step)
            raise TypeError(
                f"the pipeline's step {name!r} is {what}; a model file's pipeline holds "
                f"{STEERING_TYPE} steps followed by an HMMGMRRegressor"
            )
        check_is_fitted(step, "n_features_in_")
        steps.append(_steering_dict(name, step))
    if not _is_regressor(regressor):
        raise TypeError(
            f"the pipeline's last step {last_name!r} is {_type_name(regressor)}, not an "
            "HMMGMRRegressor or a HierarchicalHMMGMRRegressor"
        )
    model = estimator_to_dict(regressor, output_names=output_names)
    steps.append({"name": str(last_name), "type": model["model_type"], "model": model})
    if period is None:
        periods = [step.sampling_period_ for _, step in transformers]
        period = next((p for p in periods if p is not None), None)
    names = [*_inputs_of(steps[0]), *model["output_names"]]
    data = {
        "format": FORMAT_NAME,
        "format_version": model["format_version"],  # the lowest that holds the regressor
        "package_version": __version__,
        "model_type": model_type,
        "training": _training({}, units, period, names),
        "steps": steps,
    }
    if model_type == "DriverModel":
        preview = fitted.preview_columns
        data["driver_model"] = {
            "perturbation_penalty": float(fitted.perturbation_penalty),
            "preview_columns": None if preview is None else [str(name) for name in preview],
            **{key: float(getattr(fitted, name)) for key, name in DRIVER_MODEL_FACTS.items()},
        }
    return data


def _inputs_of(step):
    """Input names of a step's block (positional ``x0``... without names)."""
    if step["type"] in REGRESSOR_TYPES:
        return step["model"]["feature_names"]
    names = step["feature_names_in"]
    return names if names is not None else [f"x{i}" for i in range(step["n_features_in"])]


def _training(block, units, period, names):
    block = dict(block)
    if units is not None:
        block["units"] = {str(name): str(unit) for name, unit in dict(units).items()}
    if period is not None:
        block["sampling_period"] = float(period)
    read_training(block, names)
    return block


def _plain(value):
    """A parameter's value as JSON: lists for tuples, Python numbers for NumPy ones."""
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        if not math.isfinite(value):
            raise ValueError(f"cannot export the parameter value {value}")
        return float(value)
    raise TypeError(f"cannot export the parameter value {value!r} of type {_type_name(value)}")


def _fitted_param(step, key):
    """A parameter of a fitted ``SteeringFeatures``, the value chosen in place of ``"auto"``
    (or, for the sampling period, read from the training rows' time)."""
    if key in ("friction_velocity", "velocity_filter", "sampling_period", "friction_angle"):
        return getattr(step, f"{key}_")
    return getattr(step, key)


def _steering_dict(name, step):
    names = getattr(step, "feature_names_in_", None)
    params = {key: _plain(_fitted_param(step, key)) for key in STEERING_PARAMS}
    if step.friction_angle_ is not None:  # the keys of the hysteresis inputs, when there are
        params |= {key: _plain(_fitted_param(step, key)) for key in HYSTERESIS_PARAMS}
    if step.angle_lead_ is not None:  # and of their lead, when there is one
        params["angle_lead"] = _plain(step.angle_lead_)
    if step.slow_velocity_filter_ is not None:  # the slow velocity, when there is one
        params["slow_velocity_filter"] = _plain(step.slow_velocity_filter_)
    return {
        "name": str(name),
        "type": STEERING_TYPE,
        "params": params,
        "n_features_in": int(step.n_features_in_),
        "feature_names_in": None if names is None else [str(n) for n in names],
    }


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


def model_from_dict(data):
    """(fitted model, training facts) of a model file's dict."""
    if not isinstance(data, dict):
        raise ValueError(f"a model file must be a JSON object, got {type(data).__name__}")
    version = read_header(data)
    if version == 1:
        model_type = REGRESSOR_TYPE
    elif "model_type" not in data:
        raise ValueError("the model file lacks the key 'model_type'")
    else:
        model_type = data["model_type"]
    if model_type not in MODEL_TYPES:
        raise ValueError(
            f"'model_type' is {model_type!r:.100}; this version of skhmmgmr reads "
            f"{sorted(MODEL_TYPES)}"
        )
    check_model_file(data)
    if model_type in REGRESSOR_TYPES:
        model = estimator_from_dict(MODEL_TYPES[model_type], data, checked=True)
        names = [*data["feature_names"], *data["output_names"]]
        return model, read_training(data.get("training"), names)
    return _pipeline_from_dict(data, MODEL_TYPES[model_type])


def _pipeline_from_dict(data, cls):
    """The pipeline of a file that follows the schema: its steps in order (SteeringFeatures
    steps, then the regressor's), each fitting the next."""
    blocks = data["steps"]
    steps, previous = [], None
    for index, block in enumerate(blocks):
        where = f"steps[{index}]"
        name, kind = block["name"], block["type"]
        if name in {n for n, _ in steps}:
            raise ValueError(f"'{where}.name' {name!r} names two steps")
        last = index == len(blocks) - 1
        expected = REGRESSOR_TYPES if last else (STEERING_TYPE,)
        if kind not in expected:
            known = f"{STEERING_TYPE!r} steps followed by one of {list(REGRESSOR_TYPES)}"
            raise ValueError(
                f"'{where}.type' is {kind!r:.100}, expected one of {list(expected)}: a "
                f"pipeline's steps are {known}"
            )
        if last:
            step = _regressor_step(block["model"], where, kind)
        else:
            step = _steering_step(block, where)
        if previous is not None:
            _check_chain(previous, step, where)
        steps.append((name, step))
        previous = step
    first = steps[0][1]
    names = getattr(first, "feature_names_in_", None)
    names = list(names) if names is not None else [f"x{i}" for i in range(first.n_features_in_)]
    regressor = steps[-1][1]
    outputs = blocks[-1]["model"]["output_names"]
    training = read_training(data.get("training"), [*names, *outputs])
    longest = regressor.longest_recording_
    if longest is not None:
        training = {"longest_recording": longest, **training}
    if cls is not DriverModel:
        return cls(steps), training
    block = data["driver_model"]
    preview = block.get("preview_columns")
    model = DriverModel(
        steps,
        perturbation_penalty=block["perturbation_penalty"],
        preview_columns=None if preview is None else tuple(preview),
    )
    for key, name in DRIVER_MODEL_FACTS.items():
        setattr(model, name, block.get(key, 1.0))  # only penalty_scale may be absent
    return model, training


def _regressor_step(model, where, kind):
    try:
        return estimator_from_dict(MODEL_TYPES[kind], model, checked=True)
    except ValueError as exc:
        raise ValueError(f"in '{where}.model': {exc}") from exc


def _steering_step(block, where):
    values = {
        key: tuple(value) if isinstance(value, list) else value
        for key, value in block["params"].items()
    }
    try:
        return restore_steering_features(values, block["n_features_in"], block["feature_names_in"])
    except (InvalidParameterError, TypeError, ValueError) as exc:
        raise ValueError(f"'{where}' holds a SteeringFeatures that fit refuses: {exc}") from exc


def _check_chain(previous, step, where):
    """The outputs of ``previous`` must be the inputs of ``step``: as many, and the same
    names when both have names."""
    out = list(previous.get_feature_names_out())
    named = hasattr(previous, "feature_names_in_")
    if step.n_features_in_ != len(out):
        raise ValueError(
            f"'{where}' takes {step.n_features_in_} input(s), but the step before it gives "
            f"{len(out)}: {out}"
        )
    names = getattr(step, "feature_names_in_", None)
    if named and names is not None and list(names) != out:
        raise ValueError(
            f"'{where}' takes the inputs {list(names)}, but the step before it gives {out}"
        )
