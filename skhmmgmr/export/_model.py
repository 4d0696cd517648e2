"""What a generated filter computes: a fitted model read into flat arrays, or refused.

:func:`read_filter` takes a fitted :class:`~skhmmgmr.HMMGMRRegressor`, or a pipeline of
:class:`~skhmmgmr.SteeringFeatures` then the regressor, and returns an :class:`ExportedFilter`:
the raw inputs and how the derived ones are computed from them, the standardisation, and the
filter's parameters in the stacked form :class:`~skhmmgmr.FilterStream` multiplies (the gating
density's quadratic-form terms, :func:`~skhmmgmr._hmm._gaussian.stack_gaussians`):

- ``gating``: ``(n_states, n_inputs, n_inputs)``, row ``i`` of state ``k`` holds the weights of
  the standardised input ``z_i`` in the state's ``n_inputs`` terms; ``offsets``
  ``(n_states, n_inputs)`` the constant of every term; the log-density of state ``k`` is
  ``norms[k] - sum_j (z @ gating[k] + offsets[k])_j^2``. The whitening factors are upper
  triangular, so row ``i`` is zero before column ``i`` (``triangular``; checked, not assumed);
- ``coef`` ``(n_states, n_outputs, n_inputs)`` and ``intercept`` ``(n_states, n_outputs)``: the
  states' output means ``coef[k] @ z + intercept[k]``;
- ``shared_gating`` / ``shared_coef``: whether every state has the same ``gating`` rows or the same
  ``coef`` (a shared covariance, ``covariance_type="tied"``): the code then computes them once.

Everything the C filter does not reproduce is refused here, with the reason: missing inputs
read through the model (``missing_values`` other than "error"), steps other than
``SteeringFeatures``, unfitted models.
"""

import math
import numbers
from dataclasses import dataclass

import numpy as np
from sklearn.exceptions import NotFittedError
from sklearn.pipeline import Pipeline
from sklearn.utils.validation import check_is_fitted

from .._core._compat import InvalidParameterError
from .._hmm._holds import check_min_log_density
from ..estimator import HMMGMRRegressor
from ..torque_pipeline import SteeringFeatures
from ..torque_pipeline._derived_inputs import friction_widths


@dataclass(frozen=True)
class DerivedInputs:
    """The inputs :class:`~skhmmgmr.SteeringFeatures` appends, by raw-input position.

    ``friction``: ``(position, widths)`` or None, ``widths`` the tuple of the friction inputs'
    widths (one: a band, several: a basis); ``powers``: ``(position, power)`` of every signed
    power in the transformer's column order; ``velocity_decay``: the decay of the velocity's
    low-pass filter per sample, or None; ``hysteresis``: ``(position, radii)`` of the angle
    and the plays' half-widths, or None; ``angle_lead``: ``(position, lead)`` of the velocity
    and the time the plays read the angle ahead on it, or None (the angle itself);
    ``slow_decay``: the decay per sample of the slow filter on the (unfiltered) velocity whose
    friction inputs, of the same widths, follow the others, or None (no such inputs).
    """

    friction: tuple = None
    powers: tuple = ()
    velocity_decay: float = None
    hysteresis: tuple = None
    angle_lead: tuple = None
    slow_decay: float = None

    @property
    def n_derived(self):
        widths = () if self.friction is None else self.friction[1]
        radii = () if self.hysteresis is None else self.hysteresis[1]
        slow = () if self.slow_decay is None else widths
        return len(widths) + len(slow) + len(radii) + len(self.powers)


@dataclass(frozen=True)
class ExportedFilter:
    """A fitted model as the generated C filter reads it (see the module docstring)."""

    input_names: tuple
    derived: DerivedInputs
    input_center: np.ndarray
    input_scale: np.ndarray
    output_center: np.ndarray
    output_scale: np.ndarray
    prior_estimate: np.ndarray
    prior_std: np.ndarray
    startprob: np.ndarray
    transmat: np.ndarray
    gating: np.ndarray
    offsets: np.ndarray
    norms: np.ndarray
    coef: np.ndarray
    intercept: np.ndarray
    conditional_variances: np.ndarray
    min_log_density: object  # the outlier policy's threshold, None: none (_hmm._holds)
    output_decay: np.ndarray  # the first-order read-out (skhmmgmr._hmm._readout)

    @property
    def smoothed(self):
        return bool(np.any(self.output_decay > 0))

    @property
    def n_raw_inputs(self):
        return len(self.input_names)

    @property
    def n_inputs(self):
        return self.input_center.shape[0]

    @property
    def n_states(self):
        return self.startprob.shape[0]

    @property
    def n_outputs(self):
        return self.output_center.shape[0]

    @property
    def triangular(self):
        lower = np.tril(np.ones((self.n_inputs, self.n_inputs), dtype=bool), -1)
        return not np.any(self.gating[:, lower])

    @property
    def shared_gating(self):
        return bool(np.all(self.gating == self.gating[0]) and np.all(self.norms == self.norms[0]))

    @property
    def shared_coef(self):
        return bool(np.all(self.coef == self.coef[0]))


def _unfitted(what):
    return NotFittedError(
        f"write_c needs a fitted model; this {what} is not fitted yet: call its fit first."
    )


def _steps(fitted):
    """(SteeringFeatures or None, HMMGMRRegressor) of what ``write_c`` was given."""
    if isinstance(fitted, HMMGMRRegressor):
        return None, fitted
    if not isinstance(fitted, Pipeline):
        raise TypeError(
            "write_c exports a fitted HMMGMRRegressor or a Pipeline of SteeringFeatures then "
            f"HMMGMRRegressor (make_torque_pipeline); got {type(fitted).__name__}."
        )
    steps = [(name, step) for name, step in fitted.steps if step not in (None, "passthrough")]
    # the regressor may be a subclass (HierarchicalHMMGMRRegressor: its model_ is a flat
    # HMM-GMR over all its states, exported as any other)
    kinds = [
        HMMGMRRegressor if isinstance(step, HMMGMRRegressor) else type(step) for _, step in steps
    ]
    if kinds not in ([HMMGMRRegressor], [SteeringFeatures, HMMGMRRegressor]):
        unsupported = [
            f"{name!r} ({type(step).__name__})"
            for name, step in steps
            if not isinstance(step, (SteeringFeatures, HMMGMRRegressor))
        ]
        reason = (
            f"the step(s) {', '.join(unsupported)} have no C form"
            if unsupported
            else f"its steps are {[name for name, _ in steps]}"
        )
        raise ValueError(
            "write_c exports a Pipeline of SteeringFeatures then HMMGMRRegressor (or the "
            f"regressor alone); {reason}."
        )
    features = steps[0][1] if len(steps) == 2 else None
    return features, steps[-1][1]


def _derived_inputs(features, regressor):
    """The raw input names and the :class:`DerivedInputs` of a fitted ``SteeringFeatures``."""
    try:
        check_is_fitted(features, "n_features_in_")
    except NotFittedError:
        raise _unfitted("pipeline's SteeringFeatures") from None
    n_raw = features.n_features_in_
    names = getattr(features, "feature_names_in_", None)
    raw_names = tuple(str(n) for n in names) if names is not None else None
    sources = list(features.load_columns)
    if features.friction_velocity_ is not None:
        sources.append(features.friction_column)
    if features.friction_angle_ is not None:
        sources.append(features.angle_column)
    lead = getattr(features, "angle_lead_", None)
    if lead is not None:
        sources.append(features.friction_column)
    # fit checked that every source column exists
    positions = {
        column: (raw_names.index(column) if isinstance(column, str) else int(column))
        for column in sources
    }
    friction = None
    if features.friction_velocity_ is not None:
        widths = friction_widths(features.friction_velocity_)
        friction = (positions[features.friction_column], widths)
    powers = tuple(
        (positions[column], int(power))
        for column in features.load_columns
        for power in features.powers
    )
    decay = None
    if features.friction_velocity_ is not None and features.velocity_filter_ is not None:
        decay = math.exp(-features.sampling_period_ / features.velocity_filter_)
    slow = getattr(features, "slow_velocity_filter_", None)
    if features.friction_velocity_ is not None and slow is not None:
        slow = math.exp(-features.sampling_period_ / slow)
    hysteresis = None
    if features.friction_angle_ is not None:
        hysteresis = (positions[features.angle_column], tuple(features.friction_angle_))
    if lead is not None:
        lead = (positions[features.friction_column], float(lead))
    derived = DerivedInputs(friction, powers, decay, hysteresis, lead, slow)
    expected = list(features.get_feature_names_out())
    given = getattr(regressor, "feature_names_in_", None)
    if n_raw + derived.n_derived != regressor.n_features_in_ or (
        given is not None and list(map(str, given)) != list(map(str, expected))
    ):
        inputs = list(given) if given is not None else f"{regressor.n_features_in_} columns"
        raise ValueError(
            f"the regressor's inputs ({inputs}) are not the SteeringFeatures' output "
            f"{expected}: write_c computes the derived inputs in that order."
        )
    return raw_names or tuple(f"x{i}" for i in range(n_raw)), derived


def read_filter(fitted):
    """The :class:`ExportedFilter` of a fitted regressor or torque pipeline, or a clear error.

    Raises
    ------
    TypeError
        For anything but an ``HMMGMRRegressor`` or a ``Pipeline``.
    ValueError
        For a pipeline with other steps, or a model that reads missing inputs.
    sklearn.exceptions.NotFittedError
        For an unfitted model.
    """
    features, regressor = _steps(fitted)
    try:
        check_is_fitted(regressor)
    except NotFittedError:
        raise _unfitted(type(regressor).__name__) from None
    model = regressor.model_
    if regressor.missing_values != "error" or model.stale_noise is not None:
        raise ValueError(
            f"write_c exports models fitted with missing_values='error' only; this one has "
            f"missing_values={regressor.missing_values!r}. The C filter does not marginalise "
            "missing inputs nor carry them forward: it holds a sample with a NaN input (the "
            "update returns 1). Refit with missing_values='error' to export."
        )
    if features is None:
        names = model.feature_names or tuple(f"x{i}" for i in range(model.n_inputs))
        derived = DerivedInputs()
    else:
        names, derived = _derived_inputs(features, regressor)
    params, scaling = model.gmr, model.standardization
    n_states, n_inputs = model.n_states, model.n_inputs
    density = params.gating.density()
    # factors: (n_states * n_inputs, n_inputs + 1), row k * n_inputs + j = term j of state k
    factors = density.factors.reshape(n_states, n_inputs, n_inputs + 1)
    prior_estimate, prior_std = model.prior_output()
    exported = ExportedFilter(
        input_names=tuple(names),
        derived=derived,
        input_center=np.array(scaling.input_center),
        input_scale=np.array(scaling.input_scale),
        output_center=np.array(scaling.output_center),
        output_scale=np.array(scaling.output_scale),
        prior_estimate=np.array(prior_estimate),
        prior_std=np.array(prior_std),
        startprob=np.array(params.startprob),
        transmat=np.array(params.transmat),
        gating=np.ascontiguousarray(factors[:, :, :n_inputs].transpose(0, 2, 1)),
        offsets=np.array(factors[:, :, n_inputs]),
        norms=np.array(density.norms[:, 0]),
        coef=np.array(params.coef),
        intercept=np.array(params.intercept),
        conditional_variances=np.array(params.conditional_variances),
        min_log_density=_min_log_density(regressor),
        output_decay=np.array(model.output_decay),
    )
    for field in ("gating", "offsets", "norms", "coef", "intercept", "conditional_variances"):
        if not np.all(np.isfinite(getattr(exported, field))):
            raise ValueError(f"the model's {field} are not all finite: it cannot be exported.")
    return exported


# The headers of the C standard library (C99, C11, C23): a generated ``<name>.h`` of one of
# these names, in a folder on the include path, would hide it (also on a file system that
# ignores case).
STANDARD_HEADERS = frozenset(
    "assert complex ctype errno fenv float inttypes iso646 limits locale math setjmp signal "  # noqa: SIM905
    "stdalign stdarg stdatomic stdbit stdbool stdckdint stddef stdint stdio stdlib "
    "stdnoreturn string tgmath threads time uchar wchar wctype".split()
)


def _min_log_density(regressor):
    """The regressor's ``min_log_density``, checked. Its error is a plain ValueError: the
    exporter's ``validate_params`` would take an InvalidParameterError for one of its own
    arguments and name the exporter in place of the regressor."""
    try:
        return check_min_log_density(
            getattr(regressor, "min_log_density", None), type(regressor).__name__
        )
    except InvalidParameterError as exc:
        raise ValueError(f"{exc} The model cannot be exported.") from exc


def check_name(name):
    """``name`` if it is a C identifier that may prefix the generated names and name the
    files, else ValueError."""
    if (
        not isinstance(name, str)
        or not name
        or not (name[0].isascii() and name[0].isalpha())
        or not all(c.isascii() and (c.isalnum() or c == "_") for c in name)
    ):
        raise ValueError(
            f"name must be a C identifier (ASCII letters, digits and underscores, starting "
            f"with a letter), got {name!r:.100}."
        )
    if name.lower() in STANDARD_HEADERS:
        raise ValueError(
            f"name={name!r} would write {name}.h, which hides the C standard header "
            f"<{name.lower()}.h> wherever the folder is on the include path; choose another "
            "name."
        )
    return name


def check_dtype(dtype):
    """``"float64"`` or ``"float32"`` (also given as NumPy types), else ValueError."""
    try:
        kind = np.dtype(dtype).name if not isinstance(dtype, numbers.Number) else None
    except TypeError:
        kind = None
    if kind not in ("float64", "float32"):
        raise ValueError(f"dtype must be 'float64' or 'float32', got {dtype!r}.")
    return kind
