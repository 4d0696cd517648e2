"""The regressor's block of the portable model file: a fitted HMM-GMR model as plain JSON.

The format, every key and its units, is specified in the docstring of :mod:`skhmmgmr.portable`,
which reads and writes whole files (the regressor, or a pipeline whose last step holds such a
block). This module writes and reads the regressor's dict: :func:`to_dict` of a
:class:`~skhmmgmr.FittedHMMGMR`, :func:`read_model` back, and those of an estimator
(:func:`estimator_to_dict`, :func:`estimator_from_dict`): the estimator's parameters, fit
information and training facts travel with the model. An estimator says what its file holds
by a protocol in the manner of scikit-learn's ``__sklearn_tags__``: its class attribute
``__skhmmgmr_model_type__`` (the file's ``model_type``) and its method
``__skhmmgmr_file_params__()`` (the parameters the file keeps, ``estimator_params``), so that
this module reads no private hook of a higher layer. Every file is checked against the
format's JSON Schema (``skhmmgmr/portable_schema.json``) by :func:`check_model_file` before
anything is read from it; what the schema cannot say (array sizes across keys, the numerical
checks) is checked here.
"""

import functools
import json
import math
from dataclasses import dataclass, field
from importlib.resources import files
from numbers import Integral

import numpy as np
from sklearn.utils.validation import check_is_fitted

from .._core._compat import InvalidParameterError
from .._core._files import write_atomically
from .._core._json_schema import check_document
from .._version import __version__
from ._emissions import emission_family
from ._fitted import FittedHMMGMR, Standardization
from ._gaussian import NotPositiveDefiniteError
from ._stale_inputs import MAX_LAG, StaleInputNoise

FORMAT_NAME = "skhmmgmr-hmm-gmr"
# 1: 0.1.0, the regressor only; 2: ``model_type`` (the regressor or a pipeline) and ``training``;
# 3: ``output_decay`` (a read-out that smooths). A file is written with the lowest version that
# holds its model, so that a model without the newer parts stays readable by older readers.
FORMAT_VERSION = 3
PLAIN_VERSION, SMOOTHED_VERSION = 2, 3
REGRESSOR_TYPE = "HMMGMRRegressor"
# The same file, whose states are the blocks of manoeuvres (``estimator_params`` name them)
HIERARCHICAL_TYPE = "HierarchicalHMMGMRRegressor"
REGRESSOR_TYPES = (REGRESSOR_TYPE, HIERARCHICAL_TYPE)
SCHEMA_FILE = "portable_schema.json"

_FILTER_SHAPES = {
    "start_probabilities": ("K",),
    "transition_matrix": ("K", "K"),
    "input_means": ("K", "F"),
    "input_precision_cholesky": ("K", "F", "F"),
    "regression_coefficients": ("K", "O", "F"),
    "regression_intercepts": ("K", "O"),
    "conditional_covariances": ("K", "O", "O"),
}
_STANDARDIZATION_SHAPES = {
    "input_center": ("F",),
    "input_scale": ("F",),
    "output_center": ("O",),
    "output_scale": ("O",),
}
_JOINT_SHAPES = {"means": ("K", "D"), "covariances": ("K", "D", "D")}
_SHAPES = {
    "standardization": _STANDARDIZATION_SHAPES,
    "filter": _FILTER_SHAPES,
    "joint": _JOINT_SHAPES,
}


def to_dict(
    model,
    *,
    estimator_params=None,
    fit_info=None,
    output_names=None,
    training=None,
    model_type=REGRESSOR_TYPE,
):
    """JSON-ready dict of a :class:`~skhmmgmr.FittedHMMGMR` (a regressor file of the format
    of :mod:`skhmmgmr.portable`).

    ``model_type`` is one of :data:`REGRESSOR_TYPES`; ``estimator_params`` (the estimator's
    ``get_params()``), ``fit_info`` (log-likelihood, histories, iterations) and ``training``
    (facts about the training data, see :func:`read_training`) are stored as given.
    """

    gmr, scaling = model.gmr, model.standardization
    n_inputs, n_outputs = model.n_inputs, model.n_outputs
    if output_names is None:
        output_names = default_output_names(n_outputs)
    output_names = [str(name) for name in output_names]
    if len(output_names) != n_outputs:
        raise ValueError(f"output_names has {len(output_names)} names for {n_outputs} output(s)")
    named = model.feature_names is not None
    feature_names = model.feature_names if named else [f"x{i}" for i in range(n_inputs)]
    estimator_params = dict(estimator_params or {})
    if not isinstance(estimator_params.get("random_state"), Integral | None):
        estimator_params["random_state"] = None
    data = {
        "format": FORMAT_NAME,
        "format_version": SMOOTHED_VERSION if model.smoothed else PLAIN_VERSION,
        "package_version": __version__,
        "model_type": model_type,
        "n_states": int(model.n_states),
        "n_inputs": int(n_inputs),
        "n_outputs": int(n_outputs),
        "feature_names": [str(name) for name in feature_names],
        "feature_names_from_fit": named,
        "output_names": output_names,
        "target_ndim": 1 if model.scalar_output else 2,
        "standardization": {
            "input_center": scaling.input_center,
            "input_scale": scaling.input_scale,
            "output_center": scaling.output_center,
            "output_scale": scaling.output_scale,
        },
        "filter": {
            "start_probabilities": model.startprob,
            "transition_matrix": model.transmat,
            "input_means": gmr.gating.means,
            "input_precision_cholesky": gmr.gating.whitening(),
            "regression_coefficients": gmr.coef,
            "regression_intercepts": gmr.intercept,
            "conditional_covariances": gmr.conditional_covariances,
        },
        "joint": model.data_emissions.portable_joint(),
        "estimator_params": estimator_params,
        "fit_info": dict(fit_info or {}),
        "training": dict(training or {}),
    }
    if model.smoothed:
        data["output_decay"] = model.output_decay
    if model.stale_noise is not None:
        variances = model.stale_noise.variances
        data["stale_inputs"] = {
            "lags": model.stale_noise.lags,
            "variances": np.where(np.isfinite(variances), variances, None),
        }
    return _to_plain(data, "")


def _to_plain(value, key):
    """NumPy arrays and scalars to lists and Python numbers; refuse non-finite numbers."""
    if isinstance(value, dict):
        return {name: _to_plain(item, f"{key}.{name}".lstrip(".")) for name, item in value.items()}
    if isinstance(value, np.ndarray | list | tuple):
        array = np.asarray(value)
        if array.dtype.kind == "f" and not np.isfinite(array).all():
            raise ValueError(f"cannot export {key!r}: it holds NaN or infinite values")
        return array.tolist()
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"cannot export {key!r}: it is {value}")
    return value


def export_json(data, path):
    """Write a model file's dict to ``path`` as strict JSON (no NaN tokens), atomically."""
    write_atomically(path, json.dumps(data, indent=1, allow_nan=False) + "\n")


def load_json(path):
    """Read a portable model file into a dict, rejecting invalid JSON and NaN tokens."""

    def reject(token):
        raise ValueError(f"{path}: the number {token} is not valid JSON (non-finite value)")

    try:
        with open(path, encoding="utf-8") as file:
            text = file.read()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path} is not a JSON text file (UTF-8): {exc}") from None
    try:
        return json.loads(text, parse_constant=reject)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not a valid JSON file: {exc}") from exc
    except RecursionError:
        raise ValueError(f"{path}: the JSON is nested too deeply for a model file") from None
    except ValueError as exc:  # such as an integer of thousands of digits
        raise ValueError(f"{path} is not a valid model file: {exc}") from None


@functools.cache
def _schema_text():
    return (files("skhmmgmr") / SCHEMA_FILE).read_text(encoding="utf-8")


def model_file_schema():
    """The JSON Schema of the model file, shipped with the package (a new dict)."""
    return json.loads(_schema_text())


@functools.cache
def _schema():
    return model_file_schema()  # read only, by check_document


def check_model_file(data):
    """Check a model file's dict: its header (a file of a newer format version is refused as
    such), the format's JSON Schema, the sizes of its arrays and lists across keys, then the
    repeated names (in linear time, after the sizes: a file of a huge list of names is refused
    by its sizes first). Returns the format version; ``ValueError`` names the key at fault."""
    if not isinstance(data, dict):
        raise ValueError(f"a model file must be a JSON object, got {type(data).__name__}")
    version = read_header(data)
    repeated = []
    check_document(data, _schema(), postponed=repeated)
    if "steps" in data:  # a pipeline's file: its steps, then the regressor's block
        for index, step in enumerate(data["steps"]):
            where = f"steps[{index}]."
            if "model" in step:
                _check_sizes(step["model"], where + "model.")
            elif step["feature_names_in"] is not None:
                names, count = step["feature_names_in"], step["n_features_in"]
                _check_length(names, count, where + "feature_names_in", "names")
    else:
        _check_sizes(data, "")
    for check in repeated:
        check()
    return version


def _check_length(values, length, where, what):
    if len(values) != length:
        raise ValueError(f"'{where}' must be a list of {length} {what}, got {len(values)}")


def _check_sizes(block, where):
    """The names and arrays of a regressor's block against its sizes ``K``, ``F``, ``O``."""
    dims = _dims(block)
    _check_length(block["feature_names"], dims["F"], where + "feature_names", "names")
    _check_length(block["output_names"], dims["O"], where + "output_names", "names")
    if "output_decay" in block:
        _check_length(block["output_decay"], dims["O"], where + "output_decay", "decays")
    for section, shapes in _SHAPES.items():
        _arrays(block, section, shapes, dims, where)


def _dims(block):
    dims = {"K": block["n_states"], "F": block["n_inputs"], "O": block["n_outputs"]}
    dims["D"] = dims["F"] + dims["O"]
    return dims


# Fit information the JSON format keeps, as the estimator's attributes (name + "_").
FIT_INFO_KEYS = (
    "log_likelihood",
    "log_likelihood_history",
    "penalized_log_likelihood",
    "penalized_log_likelihood_history",
    "n_iter",
    "converged",
)


_HISTORIES = ("log_likelihood_history", "penalized_log_likelihood_history")


def default_output_names(n_outputs):
    """The names a file gives outputs that have none: ``output_0``..."""
    return [f"output_{i}" for i in range(n_outputs)]


def estimator_to_dict(estimator, *, output_names=None, training=None):
    """:func:`to_dict` of a fitted estimator's ``model_``, of the estimator's ``model_type``,
    with the parameters its file keeps, its fit information (:data:`FIT_INFO_KEYS`, the
    attributes ``name + "_"``), its output names (``output_names``, else those of fit,
    ``output_names_``) and its longest training recording (``longest_recording_``) added to
    ``training``."""
    check_is_fitted(estimator)
    longest = getattr(estimator, "longest_recording_", None)
    if output_names is None:
        output_names = getattr(estimator, "output_names_", None)
    return to_dict(
        estimator.model_,
        model_type=estimator.__skhmmgmr_model_type__,
        estimator_params=estimator.__skhmmgmr_file_params__(),
        fit_info={key: getattr(estimator, key + "_", None) for key in FIT_INFO_KEYS},
        output_names=None if output_names is None else list(output_names),
        training={"longest_recording": longest, **(training or {})},
    )


def estimator_from_dict(cls, data, *, checked=False):
    """A fitted estimator of class ``cls`` restored from a regressor's file (``checked``:
    already checked by :func:`check_model_file`, as the block of a pipeline's file is): its
    ``from_fitted_model`` with the stored parameters, then the stored fit information."""
    portable = restore_model(data) if checked else read_model(data)
    kind = data.get("model_type", REGRESSOR_TYPE)
    expected = cls.__skhmmgmr_model_type__
    if kind != expected:
        raise ValueError(
            f"the file holds a {kind} (its 'model_type'), not a {expected}: read it "
            "with skhmmgmr.portable.load"
        )
    try:
        estimator = cls.from_fitted_model(portable.model, **portable.estimator_params)
    except InvalidParameterError as exc:
        raise ValueError(f"'estimator_params' holds a value fit refuses: {exc}") from exc
    except TypeError as exc:
        raise ValueError(f"'estimator_params' holds an unknown parameter: {exc}") from exc
    except ValueError as exc:  # a read-out the parameters and the model disagree on
        raise ValueError(f"'estimator_params' does not fit 'output_decay': {exc}") from exc
    for key, value in portable.fit_info.items():
        setattr(estimator, key + "_", np.asarray(value, float) if key in _HISTORIES else value)
    estimator.longest_recording_ = portable.training.get("longest_recording")
    output_names = data["output_names"]
    if output_names != default_output_names(len(output_names)):
        estimator.output_names_ = np.asarray(output_names, dtype=object)
    return estimator


def estimator_from_json(cls, path):
    """A fitted estimator of class ``cls`` restored from a model file; an error names the
    file."""
    data = load_json(path)
    try:
        return estimator_from_dict(cls, data)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc


@dataclass(frozen=True)
class PortableModel:
    """What a model file holds: the model, the estimator's parameters, its fit info and the
    facts about its training data (``training``: empty for a file of format version 1)."""

    model: FittedHMMGMR
    estimator_params: dict
    fit_info: dict
    training: dict = field(default_factory=dict)


def read_model(data):
    """:class:`PortableModel` of a regressor's file, checked (:func:`check_model_file`)."""
    version = read_header(data) if isinstance(data, dict) else None
    if version is not None and version >= 2:
        kind = _require(data, "model_type")
        if kind not in REGRESSOR_TYPES:
            raise ValueError(
                f"'model_type' is {kind!r:.100}, not one of {list(REGRESSOR_TYPES)}: a file of "
                "a pipeline is read by skhmmgmr.portable.load"
            )
    check_model_file(data)
    return restore_model(data)


def restore_model(data):
    """:class:`PortableModel` of a regressor's file that follows the schema
    (:func:`check_model_file`): the checks across keys and the numerical ones, then the
    model."""
    dims = _dims(data)
    scaling = _arrays(data, "standardization", _STANDARDIZATION_SHAPES, dims)
    filtering = _arrays(data, "filter", _FILTER_SHAPES, dims)
    joint = _arrays(data, "joint", _JOINT_SHAPES, dims)
    feature_names, output_names = data["feature_names"], data["output_names"]
    if data["target_ndim"] == 1 and dims["O"] != 1:
        raise ValueError(f"'target_ndim' is 1 (one output), but 'n_outputs' is {dims['O']}")
    for key in ("input_scale", "output_scale"):
        if np.any(scaling[key] <= 0):
            raise ValueError(f"'standardization.{key}' must be positive")
    _check_probabilities(filtering["start_probabilities"], "filter.start_probabilities")
    _check_probabilities(filtering["transition_matrix"], "filter.transition_matrix")
    standardization = Standardization(
        np.concatenate([scaling["input_center"], scaling["output_center"]]),
        np.concatenate([scaling["input_scale"], scaling["output_scale"]]),
        dims["F"],
    )
    _check_joint_covariances(joint["covariances"])
    emissions = _joint_emissions(data["joint"], joint)
    try:
        model = FittedHMMGMR(
            filtering["start_probabilities"],
            filtering["transition_matrix"],
            emissions,
            standardization,
            scalar_output=data["target_ndim"] == 1,
            feature_names=feature_names if data["feature_names_from_fit"] else None,
            stale_noise=_stale_noise(data.get("stale_inputs"), dims["F"]),
            output_decay=data.get("output_decay"),
        )
    except (NotPositiveDefiniteError, np.linalg.LinAlgError) as exc:
        raise ValueError(f"'joint.covariances' is not usable: {exc}") from exc
    _check_filter_matches_joint(filtering, model)
    _check_conditional_covariances(model)
    fit_info = data.get("fit_info", {})
    fit_info = {key: fit_info[key] for key in FIT_INFO_KEYS if fit_info.get(key) is not None}
    training = read_training(data.get("training"), [*feature_names, *output_names])
    return PortableModel(model, data["estimator_params"], fit_info, training)


def read_header(data):
    """The format version of a model file's dict, after checking its ``format``: a whole
    number from 1 to :data:`FORMAT_VERSION`, newer ones refused as written by a newer
    skhmmgmr."""
    if _require(data, "format") != FORMAT_NAME:
        raise ValueError(f"'format' is {data['format']!r:.100}, expected {FORMAT_NAME!r}")
    version = _require(data, "format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ValueError(
            f"'format_version' is {version!r:.100}; format versions are whole numbers from 1 "
            f"(this version of skhmmgmr reads 1 to {FORMAT_VERSION})"
        )
    if version > FORMAT_VERSION:
        raise ValueError(
            f"'format_version' is {version}: the file was written by a newer skhmmgmr; this "
            f"version reads format versions 1 to {FORMAT_VERSION} (upgrade skhmmgmr to read it)"
        )
    return version


TRAINING_KEYS = ("longest_recording", "sampling_period", "units")


def read_training(block, names, where="training"):
    """The facts of a ``training`` block that follows the schema, those known (not null),
    after checking that ``units`` names only inputs and outputs (``names``)."""
    if block is None:
        return {}
    strangers = sorted(set(block.get("units") or {}) - set(names))
    if strangers:
        raise ValueError(
            f"'{where}.units' names {strangers}, neither inputs nor outputs of the model "
            f"(those are {list(names)})"
        )
    return {key: block[key] for key in TRAINING_KEYS if block.get(key) is not None}


def _stale_noise(block, n_inputs):
    if block is None:
        return None
    lags = block["lags"]
    if not all(lag <= MAX_LAG for lag in lags):
        raise ValueError(f"'stale_inputs.lags' must lie in [1, {MAX_LAG}], got {lags!r:.200}")
    try:
        variances = np.array(block["variances"], dtype=float)  # null -> NaN
    except ValueError:
        raise ValueError("'stale_inputs.variances' must hold lists of equal length") from None
    noise = StaleInputNoise(
        np.array(lags, dtype=np.int64), np.where(np.isnan(variances), np.inf, variances)
    )
    try:
        return noise.frozen(n_inputs)
    except ValueError as exc:
        raise ValueError(f"'stale_inputs' is not usable: {exc}") from None


def _joint_emissions(block, joint):
    """The emission model of the ``joint`` block: its family checks that the covariances
    have its form."""
    try:
        family = emission_family(block.get("covariance_type", "full"))
    except ValueError as exc:
        raise ValueError(f"'joint.covariance_type': {exc}") from exc
    try:
        return family.from_state_covariances(joint["means"], joint["covariances"])
    except NotPositiveDefiniteError as exc:
        raise ValueError(f"'joint.covariances' is not usable: {exc}") from exc
    except ValueError as exc:
        raise ValueError(f"'joint.covariances' {exc}") from exc


def _check_joint_covariances(covariances):
    """Every state's joint covariance must be symmetric and positive definite: the filter
    reads parts of both triangles, and an asymmetric matrix can give negative variances."""
    for k, covariance in enumerate(covariances):
        name = f"'joint.covariances[{k}]' (state {k})"
        diagonal = np.diag(covariance)
        if np.any(diagonal <= 0):
            j = int(np.flatnonzero(diagonal <= 0)[0])
            raise ValueError(
                f"{name} has the non-positive variance {float(diagonal[j])!r} in column {j}"
            )
        tolerance = 1e-10 * np.sqrt(np.outer(diagonal, diagonal))
        asymmetric = np.abs(covariance - covariance.T) > tolerance
        if asymmetric.any():
            i, j = (int(v[0]) for v in np.nonzero(asymmetric))
            raise ValueError(
                f"{name} is not symmetric: entry [{i}, {j}] is {float(covariance[i, j])!r} "
                f"but entry [{j}, {i}] is {float(covariance[j, i])!r}"
            )
        try:
            np.linalg.cholesky(covariance)
        except np.linalg.LinAlgError:
            raise ValueError(f"{name} is not positive definite") from None


def _check_conditional_covariances(model):
    """The covariance of the outputs given the inputs (the predictive variance within a state)
    must be positive definite too; it is not when the joint one is singular to round-off."""
    for k, covariance in enumerate(model.gmr.conditional_covariances):
        try:
            np.linalg.cholesky(covariance)
        except np.linalg.LinAlgError:
            raise ValueError(
                f"'filter.conditional_covariances[{k}]' (state {k}), the covariance of the "
                "outputs given the inputs, is not positive definite: 'joint.covariances"
                f"[{k}]' is singular to round-off"
            ) from None


def _require(data, key, where=""):
    if key not in data:
        raise ValueError(f"the model file lacks the key {where + key!r}")
    return data[key]


def _arrays(data, section, shapes, dims, where=""):
    """The arrays of a block as float arrays of the shapes ``shapes`` gives in ``dims``."""
    arrays = {}
    for key, symbolic in shapes.items():
        name = f"{where}{section}.{key}"
        expected = tuple(dims[symbol] for symbol in symbolic)
        try:
            array = np.asarray(data[section][key], dtype=float)
        except ValueError:  # lists of unequal lengths
            raise ValueError(f"{name!r} holds lists of unequal lengths") from None
        if array.shape != expected:
            raise ValueError(f"{name!r} has shape {array.shape}, expected {expected}")
        arrays[key] = array
    return arrays


def _check_probabilities(array, name):
    if np.any(array < 0) or not np.allclose(array.sum(axis=-1), 1.0, rtol=0, atol=1e-8):
        raise ValueError(f"{name!r} must hold non-negative probabilities summing to 1")


def _check_filter_matches_joint(filtering, model):
    """The filter block is derived from the joint block: refuse files where they disagree."""
    gmr = model.gmr
    for key, value in [
        ("input_means", gmr.gating.means),
        ("input_precision_cholesky", gmr.gating.whitening()),
        ("regression_coefficients", gmr.coef),
        ("regression_intercepts", gmr.intercept),
        ("conditional_covariances", gmr.conditional_covariances),
    ]:
        if not np.allclose(filtering[key], value, rtol=1e-8, atol=1e-10):
            raise ValueError(
                f"'filter.{key}' does not match the one derived from 'joint' and "
                "'standardization'; the file was edited or corrupted"
            )
