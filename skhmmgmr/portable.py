"""Portable model file: a fitted HMM-GMR model as plain JSON, readable without skhmmgmr.

The file is one JSON object (format ``"skhmmgmr-hmm-gmr"``, ``format_version`` 1). Keys:

``format``, ``format_version``, ``package_version``
    What the file is and which skhmmgmr wrote it. Readers reject other format versions.
``n_states``, ``n_inputs``, ``n_outputs``
    ``K``, ``F`` and ``O``.
``feature_names`` (F strings), ``feature_names_from_fit`` (bool)
    Inputs in the order every array below uses; positional names ``x0``... when the model was
    fitted on an unnamed array (then ``feature_names_from_fit`` is false).
``output_names`` (O strings), ``target_ndim`` (1 or 2)
    Output names (``output_0``... unless given at export) and whether ``y`` was 1-D.
``standardization``
    ``input_center``, ``input_scale`` (F) and ``output_center``, ``output_scale`` (O). The
    filter runs on standardised inputs ``z = (x - input_center) / input_scale`` and returns
    standardised outputs: estimate ``= output_center + output_scale * t`` and
    std ``= output_scale * s``. Keeping the estimator's own units makes a reader reproduce
    ``predict`` to round-off.
``filter`` (all in standardised units)
    ``start_probabilities`` (K), ``transition_matrix`` (K x K, row ``j`` = from state ``j``),
    ``input_means`` (K x F), ``input_precision_cholesky`` (K x F x F: the upper-triangular
    ``U_k`` with ``inv(S_k^FF) = U_k U_k^T``, so that the squared Mahalanobis distance is
    ``||(z - mu_k) @ U_k||^2`` and ``log det S_k^FF = -2 sum(log diag U_k)``),
    ``regression_coefficients`` (K x O x F) and ``regression_intercepts`` (K x O) with the
    per-state conditional mean ``m_k(z) = coef_k @ z + intercept_k``, and
    ``conditional_covariances`` (K x O x O).
``joint`` (data units)
    ``means`` (K x (F+O)) and ``covariances`` (K x (F+O) x (F+O)) over ``[inputs, outputs]``:
    the estimator's ``means_`` and ``covars_``, from which :func:`from_dict` restores it.
``estimator_params``, ``fit_info``
    Hyperparameters (``get_params()``) and, optionally, ``log_likelihood``,
    ``log_likelihood_history``, ``penalized_log_likelihood``,
    ``penalized_log_likelihood_history``, ``n_iter`` and ``converged``.

The filter (METHOD.md section 2): ``alpha_1 ∝ pi * b(z_1)``, ``alpha_t ∝ (alpha_{t-1} @ A) *
b(z_t)``, estimate ``sum_k alpha_t,k m_k(z_t)``, where ``b_k`` is the Gaussian density of the
input marginal; densities are taken relative to the largest one, and if every product
``prior * b`` is zero the recursion restarts from ``b`` alone.
"""

import json
import math
from numbers import Integral

import numpy as np

from ._gaussian import NotPositiveDefiniteError
from ._gmr import condition_on_inputs

FORMAT_NAME = "skhmmgmr-hmm-gmr"
FORMAT_VERSION = 1

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


def to_dict(model, output_names=None):
    """JSON-ready dict of a fitted model; see the module docstring for the keys."""
    from . import __version__

    params = model._gmr_parameters()
    n_inputs, n_outputs = model.n_features_in_, model.n_outputs_
    if output_names is None:
        output_names = [f"output_{i}" for i in range(n_outputs)]
    output_names = [str(name) for name in output_names]
    if len(output_names) != n_outputs:
        raise ValueError(f"output_names has {len(output_names)} names for {n_outputs} output(s)")
    named = hasattr(model, "feature_names_in_")
    feature_names = model.feature_names_in_ if named else [f"x{i}" for i in range(n_inputs)]
    estimator_params = model.get_params()
    if not isinstance(estimator_params["random_state"], Integral | None):
        estimator_params["random_state"] = None
    data = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "package_version": __version__,
        "n_states": int(model.n_states),
        "n_inputs": int(n_inputs),
        "n_outputs": int(n_outputs),
        "feature_names": [str(name) for name in feature_names],
        "feature_names_from_fit": named,
        "output_names": output_names,
        "target_ndim": 1 if model._y_is_1d else 2,
        "standardization": {
            "input_center": model._center[:n_inputs],
            "input_scale": model._scale[:n_inputs],
            "output_center": model._center[n_inputs:],
            "output_scale": model._scale[n_inputs:],
        },
        "filter": {
            "start_probabilities": params.startprob,
            "transition_matrix": params.transmat,
            "input_means": params.input_means,
            "input_precision_cholesky": params.input_precisions_chol,
            "regression_coefficients": params.coef,
            "regression_intercepts": params.intercept,
            "conditional_covariances": params.conditional_covariances,
        },
        "joint": {"means": model.means_, "covariances": model.covars_},
        "estimator_params": estimator_params,
        "fit_info": {
            "log_likelihood": getattr(model, "log_likelihood_", None),
            "log_likelihood_history": getattr(model, "log_likelihood_history_", None),
            "penalized_log_likelihood": getattr(model, "penalized_log_likelihood_", None),
            "penalized_log_likelihood_history": getattr(
                model, "penalized_log_likelihood_history_", None
            ),
            "n_iter": getattr(model, "n_iter_", None),
            "converged": getattr(model, "converged_", None),
        },
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


def export_json(model, path, output_names=None):
    """Write :func:`to_dict` of ``model`` to ``path`` as strict JSON (no NaN tokens)."""
    text = json.dumps(to_dict(model, output_names=output_names), indent=1, allow_nan=False)
    with open(path, "w", encoding="utf-8") as file:
        file.write(text + "\n")


def load_json(path):
    """Read a portable model file into a dict, rejecting invalid JSON and NaN tokens."""

    def reject(token):
        raise ValueError(f"{path}: the number {token} is not valid JSON (non-finite value)")

    with open(path, encoding="utf-8") as file:
        text = file.read()
    try:
        return json.loads(text, parse_constant=reject)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not a valid JSON file: {exc}") from exc


def from_dict(data, estimator_class):
    """Fitted ``estimator_class`` instance restored from :func:`to_dict` output (validated)."""
    if not isinstance(data, dict):
        raise ValueError(
            f"a portable HMM-GMR model must be a JSON object, got {type(data).__name__}"
        )
    if _require(data, "format") != FORMAT_NAME:
        raise ValueError(f"'format' is {data['format']!r}, expected {FORMAT_NAME!r}")
    version = _require(data, "format_version")
    if version != FORMAT_VERSION:
        raise ValueError(
            f"'format_version' is {version!r}; this version of skhmmgmr reads format version "
            f"{FORMAT_VERSION} only"
        )
    dims = {"K": _count(data, "n_states"), "F": _count(data, "n_inputs")}
    dims["O"] = _count(data, "n_outputs")
    dims["D"] = dims["F"] + dims["O"]
    feature_names = _names(data, "feature_names", dims["F"])
    _names(data, "output_names", dims["O"])
    named = _require(data, "feature_names_from_fit")
    target_ndim = _require(data, "target_ndim")
    if not isinstance(named, bool):
        raise ValueError("'feature_names_from_fit' must be true or false")
    if target_ndim not in (1, 2) or (target_ndim == 1 and dims["O"] != 1):
        raise ValueError(f"'target_ndim' is {target_ndim!r}; it must be 1 (one output) or 2")
    scaling = _arrays(data, "standardization", _STANDARDIZATION_SHAPES, dims)
    filtering = _arrays(data, "filter", _FILTER_SHAPES, dims)
    joint = _arrays(data, "joint", _JOINT_SHAPES, dims)
    for key in ("input_scale", "output_scale"):
        if np.any(scaling[key] <= 0):
            raise ValueError(f"'standardization.{key}' must be positive")
    _check_probabilities(filtering["start_probabilities"], "filter.start_probabilities")
    _check_probabilities(filtering["transition_matrix"], "filter.transition_matrix")
    center = np.concatenate([scaling["input_center"], scaling["output_center"]])
    scale = np.concatenate([scaling["input_scale"], scaling["output_scale"]])
    _check_filter_matches_joint(filtering, joint, center, scale, dims["F"])

    params = _require(data, "estimator_params")
    if not isinstance(params, dict):
        raise ValueError("'estimator_params' must be a JSON object")
    params = {**params, "n_states": dims["K"]}
    try:
        model = estimator_class(**params)
    except TypeError as exc:
        raise ValueError(f"'estimator_params' holds an unknown parameter: {exc}") from exc
    model.startprob_ = filtering["start_probabilities"]
    model.transmat_ = filtering["transition_matrix"]
    model.means_ = joint["means"]
    model.covars_ = joint["covariances"]
    model.n_features_in_ = dims["F"]
    if named:
        model.feature_names_in_ = np.asarray(feature_names, dtype=object)
    model.n_outputs_ = dims["O"]
    model._y_is_1d = target_ndim == 1
    model._center, model._scale = center, scale
    fit_info = data.get("fit_info") or {}
    if not isinstance(fit_info, dict):
        raise ValueError("'fit_info' must be a JSON object")
    for key, attribute in [
        ("log_likelihood", "log_likelihood_"),
        ("penalized_log_likelihood", "penalized_log_likelihood_"),
        ("n_iter", "n_iter_"),
        ("converged", "converged_"),
    ]:
        if fit_info.get(key) is not None:
            setattr(model, attribute, fit_info[key])
    for key in ("log_likelihood_history", "penalized_log_likelihood_history"):
        if fit_info.get(key) is not None:
            setattr(model, key + "_", np.asarray(fit_info[key], float))
    return model


def _require(data, key, where=""):
    if key not in data:
        raise ValueError(f"the model file lacks the key {where + key!r}")
    return data[key]


def _count(data, key):
    value = _require(data, key)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{key!r} must be a positive integer, got {value!r}")
    return value


def _names(data, key, length):
    names = _require(data, key)
    if not isinstance(names, list) or len(names) != length:
        raise ValueError(f"{key!r} must be a list of {length} names")
    if not all(isinstance(name, str) for name in names):
        raise ValueError(f"{key!r} must hold strings only")
    return names


def _arrays(data, section, shapes, dims):
    block = _require(data, section)
    if not isinstance(block, dict):
        raise ValueError(f"{section!r} must be a JSON object")
    arrays = {}
    for key, symbolic in shapes.items():
        name = f"{section}.{key}"
        value = _require(block, key, where=f"{section}.")
        expected = tuple(dims[symbol] for symbol in symbolic)
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{name!r} is not a (nested) list of numbers") from exc
        if array.shape != expected:
            raise ValueError(f"{name!r} has shape {array.shape}, expected {expected}")
        if not np.isfinite(array).all():
            raise ValueError(f"{name!r} holds non-finite values")
        arrays[key] = array
    return arrays


def _check_probabilities(array, name):
    if np.any(array < 0) or not np.allclose(array.sum(axis=-1), 1.0, rtol=0, atol=1e-8):
        raise ValueError(f"{name!r} must hold non-negative probabilities summing to 1")


def _check_filter_matches_joint(filtering, joint, center, scale, n_inputs):
    """The filter block is derived from the joint block: refuse files where they disagree."""
    try:
        derived = condition_on_inputs(
            filtering["start_probabilities"],
            filtering["transition_matrix"],
            (joint["means"] - center) / scale,
            joint["covariances"] / np.outer(scale, scale),
            n_inputs,
        )
    except (NotPositiveDefiniteError, np.linalg.LinAlgError) as exc:
        raise ValueError(f"'joint.covariances' is not usable: {exc}") from exc
    for key, value in [
        ("input_means", derived.input_means),
        ("input_precision_cholesky", derived.input_precisions_chol),
        ("regression_coefficients", derived.coef),
        ("regression_intercepts", derived.intercept),
        ("conditional_covariances", derived.conditional_covariances),
    ]:
        if not np.allclose(filtering[key], value, rtol=1e-8, atol=1e-10):
            raise ValueError(
                f"'filter.{key}' does not match the one derived from 'joint' and "
                "'standardization'; the file was edited or corrupted"
            )
