"""Portable model file: any fitted model of the package as plain JSON, readable without it.

The model file is the package's long-lived format: later releases of skhmmgmr read every
format version and predict from it bit for bit, and any language reads it without the package.
:func:`save` writes a fitted :class:`~skhmmgmr.HMMGMRRegressor` or
:class:`~skhmmgmr.HierarchicalHMMGMRRegressor`, or a fitted pipeline of
:class:`~skhmmgmr.SteeringFeatures` steps followed by one of them (the
:class:`~skhmmgmr.torque_pipeline.TorquePipeline` of :func:`~skhmmgmr.make_torque_pipeline`,
or a scikit-learn :class:`~sklearn.pipeline.Pipeline` of the same steps); :func:`load` reads it
back, predicting bit for bit as the saved object. They are the one way to save and load a
model; the older shortcuts (the estimators' ``export_json``, ``from_json``, ``to_dict`` and
``from_dict``, and this module's ``to_dict``, ``export_json``, ``load_json`` and
``read_model``) are deprecated aliases, removed in 0.3. A file is read as data, never run;
:func:`json_schema` returns the JSON Schema (draft 2020-12) of the format, shipped with the
package (``skhmmgmr/portable_schema.json``), against which :func:`load` checks every file and
:func:`save` every file it writes.

The file is one JSON object. Its header, for every kind of model:

``format``, ``format_version``, ``package_version``
    What the file is (``"skhmmgmr-hmm-gmr"``), the version of the format and which skhmmgmr
    wrote it. A file is written with the lowest version that holds its model: 3 for a model
    whose read-out smooths (``output_decay``), 2 otherwise; version 1, written by skhmmgmr
    0.1.0, held the regressor without ``model_type`` and ``training``, and still loads.
    Readers refuse newer format versions.
``model_type``
    ``"HMMGMRRegressor"``, ``"HierarchicalHMMGMRRegressor"``, ``"TorquePipeline"`` or
    ``"Pipeline"`` (absent in version 1: a regressor).
``training`` (optional)
    Facts about the training data that predictions read: ``longest_recording`` (rows of the
    longest training recording, or null: ``predict`` warns above it without recordings; the
    estimator's ``longest_recording_``), ``sampling_period`` (seconds between two rows, when
    known) and ``units`` (input or output name -> unit text, those known).

A regressor's file (``model_type`` ``"HMMGMRRegressor"``, or
``"HierarchicalHMMGMRRegressor"``: the same keys and the same filter over all its states,
the manoeuvres' probabilities being the sums of their states') holds next to the header:

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
    the estimator's ``means_`` and ``covars_``, from which :func:`read_model` restores it.
    ``covariance_type`` (optional, default ``"full"``): ``"tied"`` when every state shares
    one covariance (then all K covariances are equal).
``stale_inputs`` (optional; models fitted with ``missing_values="carry_forward"``)
    ``lags`` (L increasing sample counts) and ``variances`` (F x L, standardised units,
    ``null`` where unknown): every input's variogram, the variance of its value ``lag``
    samples earlier about its current one (:mod:`skhmmgmr._hmm._stale_inputs`).
``output_decay`` (O numbers in [0, 1); version 3 only)
    The causal first-order read-out of a model fitted with ``output_smoothing``: the estimate
    of every accepted sample is ``a * (previous estimate) + (1 - a) * (the filter's
    estimate)``, the first of a recording the filter's estimate (a held sample leaves it).
    The std is the filter's, not smoothed. Absent (version 2): ``a = 0``.
``estimator_params``, ``fit_info``
    Hyperparameters (``get_params()``; for a ``"HierarchicalHMMGMRRegressor"``,
    ``manoeuvres`` and ``n_states`` are the lists of the manoeuvres' names and of their
    states, whose blocks of consecutive states the filter's arrays follow) and, optionally,
    ``log_likelihood``, ``log_likelihood_history``, ``penalized_log_likelihood``,
    ``penalized_log_likelihood_history``, ``n_iter`` and ``converged``.

A pipeline's file (``model_type`` ``"TorquePipeline"`` or ``"Pipeline"``) holds next to the
header (its ``training``: the sampling period and the units of the raw inputs) ``steps``, the
steps in order, each an object with ``name`` (the step's name in the pipeline) and ``type``:

- ``"SteeringFeatures"`` steps, first: ``params`` (``friction_velocity``, ``friction_column``,
  ``load_columns``, ``powers``, ``velocity_filter``, ``sampling_period``: the transformer's
  parameters, with the values chosen in ``fit`` (``friction_velocity_``,
  ``velocity_filter_``) in place of ``"auto"``) and its fitted facts ``n_features_in`` and
  ``feature_names_in`` (the input columns, or null when fitted on an array). The step
  appends to its inputs, in this order:
  ``steering_friction = tanh(v / friction_velocity)`` (unless ``friction_velocity`` is null)
  with ``v`` the column ``friction_column`` (for an array of widths ``w_j``, a basis: one
  input ``steering_friction_<w_j> = tanh(v / w_j)`` per width, in the array's order, named by
  ``w_j`` to three significant digits), then (with ``friction_angle``, an array of
  half-widths ``r_j``: a key written only with them, with ``angle_column`` the angle's
  column) one input ``steering_hysteresis_<r_j> = (a - p_j) / r_j`` per half-width, ``a`` the
  angle (with ``angle_lead`` ``l``, a key written only with a lead, ``a`` is the angle plus
  ``l`` times the column ``friction_column``, unfiltered) and ``p_j`` its play
  ``p_t = min(max(p_(t-1), a_t - r_j), a_t + r_j)``, restarted at every recording at its
  first observed angle (a missing angle leaves it alone), and for
  every column ``x`` of ``load_columns``
  and every ``p`` of ``powers`` ``sign(x) |x|^p`` (named ``<x>_signed_square``, ``<x>_cube``,
  ``<x>_signed_power<p>``; columns are names, or positions when ``feature_names_in`` is
  null). With ``velocity_filter`` ``tau``, ``v`` is
  the velocity through ``y_t = d y_(t-1) + (1 - d) x_t``, ``d = exp(-sampling_period /
  tau)``, restarted at every recording at its first observed value; after ``g`` missing
  values the next one ``x`` enters as ``y = d^(g+1) y_last + (1 - d^(g+1)) x``.
- one ``"HMMGMRRegressor"`` (or ``"HierarchicalHMMGMRRegressor"``) step, last: ``model``, a
  regressor's file as above (its own header included, of the same ``model_type``), whose
  inputs are the outputs of the steps before it.

The filter (METHOD.md section 2): ``alpha_1 ∝ pi * b(z_1)``, ``alpha_t ∝ (alpha_{t-1} @ A) *
b(z_t)``, estimate ``sum_k alpha_t,k m_k(z_t)``, where ``b_k`` is the Gaussian density of the
input marginal; densities are taken relative to the largest one, and if every product
``prior * b`` is zero the recursion restarts from ``b`` alone. With
``estimator_params["missing_values"]`` equal to ``"marginalize"`` NaN inputs are missing
values: ``b_k`` is then the density of the observed inputs ``o`` alone (1 if none), and
``m_k`` the regression applied to ``z`` completed by ``z_m = mu_m - (P_mm)^-1 P_mo (z_o -
mu_o)``, with the input precision ``P = U_k U_k^T``; the conditional covariance gains
``coef_m (P_mm)^-1 coef_m^T``. With ``"carry_forward"`` a missing input whose last observed
value ``c`` in the recording is ``g`` samples old (``0 < g <= max(lags)``) is observed through
``c`` with noise variance ``v = variances`` interpolated linearly at ``g``: ``P_mm`` becomes
``P_mm + diag(1 / v)`` in the formulas above, ``z_m = mu_m + (P_mm + diag(1/v))^-1 (diag(1/v)
(c - mu_m) - P_mo (z_o - mu_o))``, and ``b_k`` gains the density of ``c`` given ``z_o``.
With ``estimator_params["min_log_density"]`` a number (absent or null: no sample is held), a
sample whose largest ``log b_k(z)`` is below it is held: the state probabilities, the
read-out and the estimate stay those of the last accepted sample of the recording (before
any: ``pi`` and the prior mixture's output); a sample with no input observed is never held.

Reading refuses, with a message naming the key (and the file): a format version that is not
a whole number from 1 to :data:`FORMAT_VERSION`, an unknown ``model_type``, then anything the
JSON Schema refuses (a missing or unknown key, a value of the wrong kind, a key of a newer
format version, such as ``output_decay`` in a block of version 2), a number that is not finite
(``1e400``), then what the schema cannot say: sizes across keys, inconsistent parts (a
``filter`` block that does not match ``joint``, a step whose outputs are not the next step's
inputs) and parameters the estimators refuse.
"""

import os
from numbers import Real

from ._core._compat import FiniteInterval, validate_params
from ._core._deprecation import deprecated_alias
from ._hmm import _portable
from ._hmm._portable import (
    FIT_INFO_KEYS,
    FORMAT_NAME,
    FORMAT_VERSION,
    PortableModel,
    check_model_file,
    model_file_schema,
)
from .torque_pipeline._portable import MODEL_TYPES, model_from_dict, model_to_dict

__all__ = [
    "FIT_INFO_KEYS",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MODEL_TYPES",
    "PortableModel",
    "export_json",
    "json_schema",
    "load",
    "load_json",
    "read_model",
    "save",
    "to_dict",
]


@validate_params(
    {
        "fitted": "no_validation",  # refused below, naming the type or the step
        "path": [str, os.PathLike],
        "output_names": ["array-like", None],
        "units": [dict, None],
        "sampling_period": [FiniteInterval(Real, 0, None, closed="neither"), None],
    },
    prefer_skip_nested_validation=True,
)
def save(fitted, path, *, output_names=None, units=None, sampling_period=None):
    """Write a fitted regressor or torque pipeline to one portable JSON file.

    The model file is the format meant to last: later releases of skhmmgmr read it and predict
    from it bit for bit (a pickle is for the same release only).

    Parameters
    ----------
    fitted : HMMGMRRegressor, HierarchicalHMMGMRRegressor, TorquePipeline or Pipeline
        Fitted. A pipeline's steps are :class:`~skhmmgmr.SteeringFeatures` steps followed by
        one :class:`~skhmmgmr.HMMGMRRegressor` (as :func:`~skhmmgmr.make_torque_pipeline`
        makes) or :class:`~skhmmgmr.HierarchicalHMMGMRRegressor`; anything else (subclasses
        included) is refused, naming the step or the type.
    path : str or path-like
        The file to write (strict JSON, UTF-8), replaced if it exists; it is written
        completely or not at all.
    output_names : list of str, default=None
        Distinct names of the outputs; None: those of ``y`` in ``fit`` (the regressor's
        ``output_names_``: a pandas Series' name, a DataFrame's columns), else ``output_0``,
        ...
    units : dict, default=None
        Unit text of inputs (the columns the model takes) or outputs, by name, stored in
        ``training.units``.
    sampling_period : float, default=None
        Seconds between two rows of the training recordings, stored in
        ``training.sampling_period``; ``None``: the ``sampling_period`` of a
        :class:`~skhmmgmr.SteeringFeatures` step if it has one, else unknown.

    Raises
    ------
    TypeError
        If ``fitted`` is not one of the models above; the message names the type or step.
    ValueError
        If the file would not be a valid model file (the same checks as :func:`load`'s, such
        as repeated ``output_names``), if a ``units`` name is not an input or output of the
        model, or a fitted value is not finite.

    See Also
    --------
    load : Read the file back.

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from skhmmgmr import make_torque_pipeline, portable
    >>> from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping
    >>> data = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
    >>> X, y = data[list(FEATURE_NAMES)], data["driver_torque"]
    >>> pipe = make_torque_pipeline(2, random_state=0).fit(X, y)
    >>> path = os.path.join(tempfile.mkdtemp(), "torque.json")
    >>> portable.save(pipe, path, units={"driver_torque": "N m"})
    >>> loaded, training = portable.load(path, return_training=True)
    >>> bool(np.array_equal(loaded.predict(X), pipe.predict(X)))
    True
    >>> training["units"]
    {'driver_torque': 'N m'}
    """
    data = model_to_dict(fitted, output_names=output_names, units=units, period=sampling_period)
    try:
        check_model_file(data)
    except ValueError as exc:
        raise ValueError(f"cannot save the model: {exc}") from None
    _portable.export_json(data, path)


@validate_params(
    {"path": [str, os.PathLike], "return_training": ["boolean"]},
    prefer_skip_nested_validation=True,
)
def load(path, *, return_training=False):
    """Read a model file written by :func:`save` (or by skhmmgmr 0.1.0 and later).

    Parameters
    ----------
    path : str or path-like
    return_training : bool, default=False
        Also return the file's facts about the training data.

    Returns
    -------
    model : HMMGMRRegressor, HierarchicalHMMGMRRegressor, TorquePipeline or Pipeline
        Fitted, of the saved class; predicts bit for bit as the saved model.
    training : dict
        With ``return_training``: ``longest_recording``, ``sampling_period`` and ``units``,
        those the file holds (none for a file of format version 1).

    Raises
    ------
    ValueError
        If the file is not valid JSON or not a valid model file: the message names the file
        and what is wrong (the key, the format version, the unknown type or step).

    Examples
    --------
    >>> import os, tempfile
    >>> import numpy as np
    >>> from skhmmgmr import HMMGMRRegressor, portable
    >>> X = np.cumsum(np.random.default_rng(0).normal(size=(200, 2)), axis=0)
    >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, X.sum(axis=1))
    >>> path = os.path.join(tempfile.mkdtemp(), "model.json")
    >>> portable.save(model, path)
    >>> restored, training = portable.load(path, return_training=True)
    >>> bool(np.array_equal(restored.predict(X), model.predict(X)))
    True
    >>> training
    {}
    """
    data = _portable.load_json(path)
    try:
        model, training = model_from_dict(data)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc
    return (model, training) if return_training else model


def json_schema():
    """The JSON Schema (draft 2020-12) of the portable model file, every format version.

    Returns
    -------
    schema : dict
        The schema shipped with the package (``skhmmgmr/portable_schema.json``): validate a
        file with any JSON Schema validator; :func:`load` checks every file against it. It
        checks the keys, their kinds and the structure; the equal sizes of arrays across
        keys and the numerical checks are :func:`load`'s.

    Examples
    --------
    >>> from skhmmgmr import portable
    >>> portable.json_schema()["$schema"]
    'https://json-schema.org/draft/2020-12/schema'
    """
    return model_file_schema()


# --------------------------------------------------------------------------------------------
# Deprecated aliases (removed in 0.3)
# --------------------------------------------------------------------------------------------

_ESTIMATOR = "HMMGMRRegressor.from_fitted_model(model, **params)"


@deprecated_alias(
    "skhmmgmr.portable.to_dict",
    f"write the model file with skhmmgmr.portable.save({_ESTIMATOR}, path)",
)
def to_dict(model, **kwargs):
    """The model file's dict of a :class:`~skhmmgmr.FittedHMMGMR`.

    .. deprecated:: 0.2
       ``to_dict`` will be removed in 0.3: write the file with
       ``save(HMMGMRRegressor.from_fitted_model(model, **params), path)``.

    Parameters
    ----------
    model : FittedHMMGMR
    **kwargs : dict
        ``estimator_params``, ``fit_info``, ``output_names``, ``training`` and
        ``model_type``, stored as given.

    Returns
    -------
    data : dict
    """
    return _portable.to_dict(model, **kwargs)


@deprecated_alias("skhmmgmr.portable.export_json", "write model files with skhmmgmr.portable.save")
def export_json(data, path):
    """Write a model file's dict to ``path`` as strict JSON.

    .. deprecated:: 0.2
       ``export_json`` will be removed in 0.3: write model files with :func:`save`.

    Parameters
    ----------
    data : dict
    path : str or path-like
    """
    _portable.export_json(data, path)


@deprecated_alias("skhmmgmr.portable.load_json", "read model files with skhmmgmr.portable.load")
def load_json(path):
    """Read a model file into a dict, refusing invalid JSON and NaN tokens.

    .. deprecated:: 0.2
       ``load_json`` will be removed in 0.3: read model files with :func:`load`.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    data : dict
    """
    return _portable.load_json(path)


@deprecated_alias(
    "skhmmgmr.portable.read_model",
    "read model files with skhmmgmr.portable.load (its model_ is the FittedHMMGMR)",
)
def read_model(data):
    """The :class:`PortableModel` of a regressor's model file dict, checked.

    .. deprecated:: 0.2
       ``read_model`` will be removed in 0.3: :func:`load` reads the file (the regressor's
       ``model_``, ``get_params()`` and fitted attributes are what this returns).

    Parameters
    ----------
    data : dict

    Returns
    -------
    portable : PortableModel
    """
    return _portable.read_model(data)
