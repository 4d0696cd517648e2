"""The fitted model: one immutable object that predict, FilterStream and the JSON format read."""

from dataclasses import dataclass, field, replace

import numpy as np

from .._core._pickled import PickleVersionMixin
from ._em import HMMParameters
from ._gmr import causal_filter, condition_on_inputs, gmr_estimates
from ._readout import smooth_outputs


def _frozen(array):
    array = np.array(array, dtype=float)
    array.flags.writeable = False
    return array


@dataclass(frozen=True)
class Standardization:
    """Centre and scale of the joint columns ``[inputs, outputs]``.

    The model works on standardised columns ``z = (x - center) / scale``; every conversion
    between the data's units and the model's is a method of this object.

    Parameters
    ----------
    center, scale : array-like of shape (n_inputs + n_outputs,)
        ``scale`` must be positive.
    n_inputs : int
        The first ``n_inputs`` columns are inputs, the others outputs.

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr import Standardization
    >>> scaling = Standardization(center=[1.0, 0.0], scale=[2.0, 0.5], n_inputs=1)
    >>> scaling.joint(np.array([[3.0]]), np.array([[1.0]]))
    array([[1., 2.]])
    >>> scaling.outputs(np.array([[2.0]]))
    array([[1.]])
    """

    center: np.ndarray
    scale: np.ndarray
    n_inputs: int

    def __post_init__(self):
        center, scale = _frozen(self.center), _frozen(self.scale)
        if center.ndim != 1 or center.shape != scale.shape:
            raise ValueError("center and scale must be 1-D arrays of the same length")
        if not (np.all(np.isfinite(center)) and np.all(np.isfinite(scale)) and np.all(scale > 0)):
            raise ValueError("center must be finite and scale finite and positive")
        if not 0 < self.n_inputs < center.shape[0]:
            raise ValueError(f"n_inputs={self.n_inputs} must be in [1, {center.shape[0] - 1}]")
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "scale", scale)

    @property
    def n_outputs(self):
        return self.center.shape[0] - self.n_inputs

    @property
    def input_center(self):
        return self.center[: self.n_inputs]

    @property
    def input_scale(self):
        return self.scale[: self.n_inputs]

    @property
    def output_center(self):
        return self.center[self.n_inputs :]

    @property
    def output_scale(self):
        return self.scale[self.n_inputs :]

    def inputs(self, X):
        """Standardised inputs of ``X`` (n_samples, n_inputs)."""
        return (X - self.input_center) / self.input_scale

    def joint(self, X, Y):
        """Standardised joint columns of inputs ``X`` and outputs ``Y`` (2-D)."""
        return (np.hstack([X, Y]) - self.center) / self.scale

    def outputs(self, T):
        """Outputs in the data's units from standardised outputs ``T`` (n_samples, n_outputs)."""
        return T * self.output_scale + self.output_center

    def output_std(self, S):
        """Standard deviations in the data's units from standardised ones."""
        return S * self.output_scale

    def log_jacobian(self, n_rows):
        """``log |dz/dx|`` of ``n_rows`` rows: a density in the data's units is the density of
        the standardised rows minus this (in log). With missing values, ``n_rows`` holds the
        number of observed values of every column."""
        if np.ndim(n_rows):
            return -float(np.dot(n_rows, np.log(self.scale)))
        return -n_rows * float(np.sum(np.log(self.scale)))


@dataclass(frozen=True)
class FittedHMMGMR(PickleVersionMixin):
    """A fitted HMM-GMR model (immutable): the HMM over standardised ``[inputs, outputs]``,
    its standardisation and the output shape.

    :class:`~skhmmgmr.HMMGMRRegressor` stores one as ``model_``; :class:`~skhmmgmr.FilterStream`
    and the portable JSON format read it. Build an estimator from one with
    :meth:`HMMGMRRegressor.from_fitted_model <skhmmgmr.HMMGMRRegressor.from_fitted_model>`.

    Parameters
    ----------
    startprob : ndarray of shape (n_states,)
    transmat : ndarray of shape (n_states, n_states)
        Row ``j`` holds the probabilities of leaving state ``j``.
    data_emissions : GaussianEmissions
        State densities over the joint columns in the data's units
        (:mod:`skhmmgmr._hmm._emissions`). The model keeps read-only copies.
    standardization : Standardization
    scalar_output : bool, default=True
        Whether predictions are 1-D (the model was fitted on a 1-D target).
    feature_names : tuple of str, default=None
        Input names, when the model was fitted on named columns.
    stale_noise : StaleInputNoise, default=None
        The inputs' variograms in standardised units, by which a model fitted with
        ``missing_values="carry_forward"`` reads a missing input through its last observed
        value (:mod:`skhmmgmr._hmm._stale_inputs`); None otherwise.
    output_decay : array-like of shape (n_outputs,), default=None
        Decay ``a`` in [0, 1) of the causal first-order read-out of every output: the
        estimate is ``a * (previous estimate) + (1 - a) * (GMR estimate)``, the first of a
        recording the GMR estimate (:mod:`skhmmgmr._hmm._readout`). None: zeros, the GMR
        estimate itself.

    Attributes
    ----------
    emissions : GaussianEmissions
        The state densities over the standardised joint columns, derived from
        ``data_emissions``: the model that is exported and restored is the data-unit one, so
        a restored model predicts bit for bit as the original.
    gmr : GMRParameters
        The causal GMR read-out (standardised units).

    Examples
    --------
    >>> from skhmmgmr import HMMGMRRegressor
    >>> from skhmmgmr.datasets import make_lane_keeping
    >>> data = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
    >>> X, y = data[["steering_wheel_angle", "yaw_rate"]], data["driver_torque"]
    >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y).model_
    >>> model.n_states, model.n_inputs, model.covariance_type, model.feature_names
    (2, 2, 'full', ('steering_wheel_angle', 'yaw_rate'))
    >>> model.transmat.flags.writeable
    False
    >>> HMMGMRRegressor.from_fitted_model(model).predict(X).shape
    (600,)
    """

    startprob: np.ndarray
    transmat: np.ndarray
    data_emissions: object
    standardization: Standardization
    scalar_output: bool = True
    feature_names: tuple = None
    stale_noise: object = None
    output_decay: np.ndarray = None
    emissions: object = field(init=False, repr=False, compare=False)
    gmr: object = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        startprob, transmat = _frozen(self.startprob), _frozen(self.transmat)
        n_states, n_dims = self.data_emissions.n_states, self.data_emissions.n_dims
        if startprob.shape != (n_states,) or transmat.shape != (n_states, n_states):
            raise ValueError(
                f"startprob and transmat must have shapes ({n_states},) and "
                f"({n_states}, {n_states}) for {n_states} states"
            )
        if self.standardization.center.shape != (n_dims,):
            raise ValueError(
                f"the standardisation covers {self.standardization.center.shape[0]} columns, "
                f"the emission {n_dims}"
            )
        if self.scalar_output and self.standardization.n_outputs != 1:
            raise ValueError("scalar_output needs exactly one output")
        if self.feature_names is not None:
            names = tuple(str(name) for name in self.feature_names)
            if len(names) != self.n_inputs:
                raise ValueError(f"{len(names)} feature names for {self.n_inputs} inputs")
            object.__setattr__(self, "feature_names", names)
        if self.stale_noise is not None:
            object.__setattr__(self, "stale_noise", self.stale_noise.frozen(self.n_inputs))
        n_outputs = self.standardization.n_outputs
        decay = _frozen(np.zeros(n_outputs) if self.output_decay is None else self.output_decay)
        if decay.shape != (n_outputs,) or not np.all((decay >= 0) & (decay < 1)):
            raise ValueError(
                f"output_decay must hold {n_outputs} number(s) in [0, 1), one per output; "
                f"got {self.output_decay!r}"
            )
        object.__setattr__(self, "output_decay", decay)
        # The model owns read-only copies: nobody can change it after the fact.
        data_emissions = self.data_emissions.frozen()
        scaling = self.standardization
        emissions = data_emissions.standardized(scaling.center, scaling.scale).frozen()
        object.__setattr__(self, "data_emissions", data_emissions)
        object.__setattr__(self, "emissions", emissions)
        object.__setattr__(self, "startprob", startprob)
        object.__setattr__(self, "transmat", transmat)
        gmr = condition_on_inputs(startprob, transmat, emissions, self.n_inputs)
        object.__setattr__(self, "gmr", gmr)

    def __setstate__(self, state):
        """Unpickle; a model pickled before the read-out had none (zero decays)."""
        super().__setstate__(state)
        if "output_decay" not in state:
            object.__setattr__(self, "output_decay", _frozen(np.zeros(self.n_outputs)))

    @classmethod
    def from_standardized(cls, startprob, transmat, emissions, standardization, **kwargs):
        """The model of an HMM whose ``emissions`` are over the standardised columns."""
        scaling = standardization
        data_emissions = emissions.rescaled(scaling.center, scaling.scale)
        return cls(startprob, transmat, data_emissions, scaling, **kwargs)

    @property
    def n_states(self):
        return self.emissions.n_states

    @property
    def n_inputs(self):
        return self.standardization.n_inputs

    @property
    def n_outputs(self):
        return self.standardization.n_outputs

    @property
    def covariance_type(self):
        return self.emissions.covariance_type

    @property
    def smoothed(self):
        """Whether the read-out smooths an output (a decay above 0)."""
        return bool(np.any(self.output_decay > 0))

    def with_output_decay(self, output_decay):
        """The same model with another read-out decay (see ``output_decay``)."""
        return replace(self, output_decay=output_decay)

    def hmm_parameters(self):
        """The HMM in standardised units, as the EM engine takes it."""
        return HMMParameters(self.startprob, self.transmat, self.emissions)

    def n_parameters(self):
        """Free parameters: start and transition probabilities and the state densities."""
        n_states = self.n_states
        return int((n_states - 1) + n_states * (n_states - 1) + self.emissions.n_parameters())

    def predict_outputs(
        self, standardized, recordings, *, missing=None, min_log_density=None, return_std=False
    ):
        """The causal estimates of the outputs, as ``predict`` gives them, in filter order.

        Parameters
        ----------
        standardized : ndarray of shape (n_samples, n_inputs)
            Standardised inputs, in filter order.
        recordings : Recordings
        missing : MissingRows, default=None
            The rows that miss an input (:func:`~skhmmgmr._hmm._gmr.read_missing`).
        min_log_density : float, default=None
            The outlier policy's threshold (:mod:`skhmmgmr._hmm._holds`): held rows show the
            estimate and std of the last accepted row of their recording, the prior
            mixture's (:meth:`prior_output`) before any.
        return_std : bool, default=False

        Returns
        -------
        estimate, std : ndarray of shape (n_samples, n_outputs)
            In the data's units, the estimate through the read-out (``output_decay``); std
            None unless ``return_std``.
        alpha : ndarray of shape (n_samples, n_states)
            The filtered state probabilities.
        """
        gmr = self.gmr
        alpha, holds = causal_filter(
            standardized, recordings, gmr, missing=missing, min_log_density=min_log_density
        )
        estimate, std = gmr_estimates(standardized, alpha, gmr, return_std, missing=missing)
        estimate = self.standardization.outputs(estimate)
        estimate = smooth_outputs(estimate, recordings, self.output_decay, holds)
        if return_std:
            std = self.standardization.output_std(std)
        if holds is not None:
            prior_mean, prior_std = self.prior_output()
            estimate = holds.carry(estimate, prior_mean)
            std = None if std is None else holds.carry(std, prior_std)
        return estimate, std, alpha

    def prior_output(self):
        """Output mean and std under the start probabilities (before any input is seen), in
        the data's units, shape (n_outputs,) each."""
        n_inputs = self.n_inputs
        means = self.emissions.means[:, n_inputs:]
        variances = self.emissions.state_variances()[:, n_inputs:]
        mean = self.startprob @ means
        std = np.sqrt(np.maximum(self.startprob @ (variances + (means - mean) ** 2), 0.0))
        return self.standardization.outputs(mean), self.standardization.output_std(std)
