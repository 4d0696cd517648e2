"""MAP adaptation of a fitted HMM-GMR to new recordings, and forecasts of the outputs ahead.

Adaptation follows GMM-UBM speaker adaptation (Reynolds, Quatieri and Dunn, 2000): the fitted
parameters are a prior, and EM on the new recordings (in the fitted model's standardised
columns: the :class:`~skhmmgmr.Standardization` of the original fit is kept) maximises the
posterior. With the E-step's soft counts ``n_k``, moments about the state means and a
relevance factor ``r`` (rows of evidence a state needs before it moves halfway), the M-step is

- means: ``mu_k' = (n_k E_k[x] + r mu0_k) / (n_k + r)``;
- covariances: ``S_k' = (scatter_k(mu_k') + r (S0_k + (mu0_k - mu_k')(mu0_k - mu_k')^T))
  / (n_k + r)`` (tied: the scatters of all states plus ``r S0`` over ``N + r``);
- transitions: ``A_jk' = (xi_jk + r A0_jk) / (sum_k xi_jk + r)``, and the start probabilities
  alike with the expected starts;

always about the original parameters (``mu0, S0, A0``), which stay the fixed prior across the
EM iterations. A parameter not adapted keeps its original value.

The forecast ``h`` rows ahead propagates the filtered state probabilities through the
transition matrix, ``alpha_t A^h``, and mixes per-state outputs (see
:meth:`AdaptMixin.predict_ahead`).
"""

from dataclasses import replace

import numpy as np
from sklearn.utils.validation import check_is_fitted

from .._core._validation import (
    check_adaptation_params,
)
from .._hmm._em import HMMParameters, e_step
from .._hmm._em_data import Columns, EStepData
from .._hmm._fitted import FittedHMMGMR
from .._hmm._gaussian import NotPositiveDefiniteError
from .._hmm._gmr import causal_filter, gmr_estimates, mix_estimates
from .._hmm._missing import observed_counts
from .._hmm._readout import ahead_weights, smooth_outputs
from ._prediction_inputs import read_inputs, read_joint_inputs

ADAPTED_PARAMETERS = frozenset("mvt")


def check_parameters(parameters):
    """The set of adapted parameters of a string of "m", "v" and "t"."""
    if not isinstance(parameters, str) or not set(parameters) <= ADAPTED_PARAMETERS:
        raise ValueError(
            f"parameters must be a string of 'm' (means), 'v' (covariances) and 't' "
            f"(transitions), got {parameters!r}"
        )
    return set(parameters)


def map_step(stats, prior, relevance, parameters, reg_covar=0.0):
    """The MAP M-step of the adapted ``parameters`` with ``prior`` (HMMParameters) fixed;
    ``reg_covar`` is added to the diagonal of every adapted covariance, as fit's M-step does."""
    emission, old = stats.emission, prior.emissions
    weights = emission.weights
    means = old.means
    if "m" in parameters:
        sums = weights[:, np.newaxis] * emission.shift + emission.first
        means = (sums + relevance * old.means) / (weights + relevance)[:, np.newaxis]
    startprob, transmat = prior.startprob, prior.transmat
    if "t" in parameters:
        starts = stats.start_counts + relevance * prior.startprob
        startprob = starts / starts.sum()
        counts = stats.transition_counts + relevance * prior.transmat
        transmat = counts / counts.sum(axis=1, keepdims=True)
    try:
        if "v" in parameters:
            emissions = old.map_adapted(emission, means, relevance, reg_covar)
        else:
            emissions = old.with_means(means)
    except NotPositiveDefiniteError as exc:
        raise ValueError(
            f"adapt: {exc.args[0].split(';')[0]} after adaptation with relevance={relevance:g}: "
            "the state's rows are too few or too alike for its covariance and the prior's "
            "weight vanishes beside them in floating point; raise relevance or the estimator's "
            "reg_covar, or adapt the means only (parameters='m')."
        ) from None
    return HMMParameters(np.asarray(startprob), np.asarray(transmat), emissions)


def adapt_parameters(
    columns, recordings, prior, *, relevance, parameters, n_iter, tol, reg_covar=0.0
):
    """MAP EM from ``prior`` on standardised ``columns`` (:class:`Columns`).

    Returns ``(parameters, history, n_done, converged)``; ``history`` holds the log-likelihood
    (standardised units) of the parameters before every M-step, then of the returned ones.
    Converged: the log-likelihood changed by less than ``tol`` per row between two E-steps.
    """
    engine = EStepData(columns, recordings, prior.n_states)
    n_samples = columns.n_samples
    params, history, converged, n_done = prior, [], False, 0
    for _ in range(n_iter):
        n_done += 1
        stats = e_step(engine, params)
        converged = bool(history) and abs(stats.log_likelihood - history[-1]) < tol * n_samples
        history.append(stats.log_likelihood)
        if converged:
            break
        params = map_step(stats, prior, relevance, parameters, reg_covar)
    else:
        history.append(e_step(engine, params).log_likelihood)
    return params, history, n_done, converged


class AdaptMixin:
    """``adapt`` (MAP adaptation to new recordings) and ``predict_ahead`` (forecasts)."""

    def adapt(self, X, y, groups=None, *, relevance=256.0, parameters="mv", n_iter=10, time=None):
        """Adapt the fitted model to new recordings by maximum a posteriori (MAP) EM.

        The fitted parameters are the prior, as in GMM-UBM speaker adaptation (Reynolds et
        al., 2000): the E-step statistics of the new recordings (soft counts ``n_k`` and
        moments per state, in the fitted model's standardised units, the original
        standardisation kept) move a state's mean to ``(n_k E_k[x] + r mu_k) / (n_k + r)``,
        so that a state seen in fewer than about ``r`` rows stays near its fitted value.
        Covariances ("v") and transitions ("t") adapt by the analogous rules (see
        :doc:`/user_guide/adaptation`); the other parameters keep their fitted values.

        This is not ``partial_fit``: in scikit-learn ``partial_fit`` learns incrementally
        towards the fit of all the data seen so far, whereas ``adapt`` treats the fitted
        model as a prior and the new recordings as the data of interest (a driver's own
        model from a generic one). With no new rows the model is unchanged; with many rows
        (``n_k >> r``) it approaches EM on the new recordings started from the fitted
        parameters.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            Inputs of the new recordings (as in :meth:`fit`).
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        relevance : float, default=256.0
            Relevance factor ``r`` > 0: rows of evidence at which a state moves halfway from
            its fitted parameters to those of the new data (256 rows: about 13 s at 20 Hz).
            Small values approach plain (maximum likelihood) EM; ``r > 0`` keeps every
            adapted covariance positive definite (``r S0`` is added to the scatter), even
            for a state the new recordings never visit; the estimator's ``reg_covar`` is
            added to its diagonal as in :meth:`fit`, so that this holds in floating point
            too when ``r`` is so small that ``r S0`` vanishes beside the scatter.
        parameters : str, default="mv"
            Which parameters adapt: any of "m" (means), "v" (covariances) and "t" (start and
            transition probabilities), as hmmlearn's ``params``. The defaults ("mv", 256) won
            ``benchmarks/bench_adapt_defaults.py`` (a generic model of two driver styles
            adapted to 1, 2 and 5 minutes of the third, in the reference car and in drawn
            cars): drivers differ in the slopes of the torque on the signals, which live in
            the covariances; the transitions added nothing.
        n_iter : int, default=10
            Maximum number of MAP EM iterations; the estimator's ``tol`` stops them earlier.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        self : HMMGMRRegressor
            With a new ``model_`` (the previous one is not modified), and ``n_iter_``,
            ``converged_``, ``log_likelihood_`` and ``log_likelihood_history_`` of the
            adaptation (the log-likelihood of the new recordings).

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import HMMGMRRegressor
        >>> X = np.random.default_rng(1).normal(size=(300, 2)).cumsum(axis=0) / 10
        >>> y = X @ [2.0, -1.0]
        >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y)
        >>> fitted = model.model_
        >>> adapted = model.adapt(X[:100], y[:100] + 0.5, relevance=8.0)  # another driver
        >>> bool(adapted is model and model.model_ is not fitted)
        True
        """
        check_is_fitted(self)
        adapted = check_parameters(parameters)
        check_adaptation_params("adapt", relevance=relevance, n_iter=n_iter)
        if _n_rows(X) == 0:  # nothing to adapt to: the model and its fit attributes stay
            lengths = {"y": _n_rows(y), "groups": _n_rows(groups), "time": _n_rows(time)}
            extra = {name: n for name, n in lengths.items() if n}
            if extra:
                raise ValueError(
                    f"X has no rows but {', '.join(f'{k} has {n}' for k, n in extra.items())}: "
                    "they must describe the same rows."
                )
            return self
        inputs = read_joint_inputs(self, X, y, groups, time, fitting=False)
        X, Y, recordings = inputs.X, inputs.Y, inputs.recordings
        model = self.model_
        scaling = model.standardization
        columns = Columns.from_rows(scaling.joint(X, Y))
        params, history, n_done, converged = adapt_parameters(
            columns,
            recordings,
            model.hmm_parameters(),
            relevance=float(relevance),
            parameters=adapted,
            n_iter=int(n_iter),
            tol=self.tol,
            reg_covar=self.reg_covar,
        )
        self.model_ = FittedHMMGMR.from_standardized(
            params.startprob,
            params.transmat,
            params.emissions,
            scaling,
            scalar_output=model.scalar_output,
            feature_names=model.feature_names,
            stale_noise=model.stale_noise,
            output_decay=model.output_decay,
        )
        jacobian = scaling.log_jacobian(observed_counts(X, Y))
        self.n_iter_, self.converged_ = n_done, converged
        self.log_likelihood_history_ = np.asarray(history) + jacobian
        self.log_likelihood_ = float(self.log_likelihood_history_[-1])
        # The penalised objective of fit does not apply to the adapted model.
        self.penalized_log_likelihood_ = self.penalized_log_likelihood_history_ = None
        return self

    def predict_ahead(
        self, X, steps, groups=None, time=None, *, state_output="marginal", return_std=False
    ):
        """Forecast of the outputs ``steps`` rows ahead from the inputs known now.

        The filtered state probabilities of every row (:meth:`predict_state_proba`) are
        propagated through the transition matrix, ``alpha_t A^steps``, and mix per-state
        outputs. With ``steps=0`` this is :meth:`predict`. For ``steps > 0`` the future inputs
        are unknown, hence two read-outs:

        - ``state_output="marginal"``: each state's output mean ``mu_k^T`` (and its marginal
          covariance ``S_k^TT``). Under the HMM the outputs ``steps`` rows ahead depend on
          the past only through the state then, so this is the model's exact forecast.
        - ``state_output="conditional"``: each state's conditional mean given the current
          inputs, ``mu_k^T + S_k^TF (S_k^FF)^-1 (F_t - mu_k^F)`` (and conditional
          covariance): the approximation that the inputs hold still over the horizon, better
          for slowly varying inputs (and those that preview the road).

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        steps : int
            Horizon in rows (``seconds * sampling_rate``), from 0 to 1e9.
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row; the filter restarts at every recording.
        time : array-like of shape (n_samples,), default=None
        state_output : {"marginal", "conditional"}, default="marginal"
        return_std : bool, default=False
            Also return the predictive standard deviation (law of total variance).

        Returns
        -------
        y_pred : ndarray of shape (n_samples,) or (n_samples, n_outputs)
            The forecast at row ``t`` is that of the outputs at row ``t + steps``.
        y_std : ndarray of the same shape, only when ``return_std`` is True

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import HMMGMRRegressor
        >>> X = np.random.default_rng(2).normal(size=(300, 2)).cumsum(axis=0) / 10
        >>> groups = np.repeat(["a", "b"], 150)
        >>> model = HMMGMRRegressor(n_states=2, random_state=0)
        >>> model = model.fit(X, X.sum(axis=1), groups=groups)
        >>> now = model.predict_ahead(X, 0, groups=groups)
        >>> bool(np.allclose(now, model.predict(X, groups=groups)))
        True
        >>> ahead, std = model.predict_ahead(X, 20, groups=groups, return_std=True)
        >>> ahead.shape
        (300,)
        """
        if state_output not in ("marginal", "conditional"):
            raise ValueError(
                f"state_output must be 'marginal' or 'conditional', got {state_output!r}"
            )
        check_adaptation_params("predict_ahead", steps=steps)
        steps = int(steps)
        # The rows in filter order, read once (with their missing values) for both steps.
        standardized, recordings, rows, missing = read_inputs(self, X, groups, time)
        model = self.model_
        alpha, holds = causal_filter(
            standardized,
            recordings,
            model.gmr,
            missing=missing,
            min_log_density=self.min_log_density,
        )

        def mixed(weights, with_std):
            if steps == 0 or state_output == "conditional":
                return gmr_estimates(standardized, weights, model.gmr, with_std, missing)
            return marginal_estimates(weights, model, with_std)

        ahead = transition_power(model.transmat, steps)
        estimate, std = mixed(alpha @ ahead, return_std)
        estimate = model.standardization.outputs(estimate)
        if model.smoothed and steps == 0:  # the read-out now: predict's
            estimate = smooth_outputs(estimate, recordings, model.output_decay, holds)
        elif model.smoothed:
            estimate = self._read_out_ahead(
                estimate, alpha, mixed, standardized, recordings, steps, (missing, holds)
            )
        if return_std:
            std = model.standardization.output_std(std)
        if holds is not None:  # a held row: the forecast of the last accepted one
            estimate, std = _carry_forecasts(model, holds, ahead, steps, estimate, std)
        estimate = rows.to_caller_order(estimate[:, 0] if model.scalar_output else estimate)
        if not return_std:
            return estimate
        return estimate, rows.to_caller_order(std[:, 0] if model.scalar_output else std)

    def _read_out_ahead(self, estimate, alpha, mixed, standardized, recordings, steps, rows):
        """The forecast ``estimate`` of the GMR estimate, turned into that of the smoothed
        read-out (:func:`~skhmmgmr._hmm._readout.ahead_weights`), output by output;
        ``rows``: the rows that miss an input and the held ones."""
        model = self.model_
        missing, holds = rows
        now, _ = gmr_estimates(standardized, alpha, model.gmr, False, missing)
        now = smooth_outputs(
            model.standardization.outputs(now), recordings, model.output_decay, holds
        )
        estimate = np.array(estimate)
        for j, decay in enumerate(model.output_decay.tolist()):
            carried, weights = ahead_weights(model.transmat, decay, steps)
            if weights is not None:
                estimate[:, j] = model.standardization.outputs(mixed(alpha @ weights, False)[0])[
                    :, j
                ]
            estimate[:, j] = carried * now[:, j] + (1.0 - carried) * estimate[:, j]
        return estimate


def _n_rows(values):
    """Number of rows of an array-like, 0 for None."""
    return 0 if values is None else len(values)


def transition_power(transmat, steps):
    """``transmat ** steps`` by repeated squaring, every product put back on the rows' simplex
    (non-negative, rows summing to one) so that round-off cannot build up over the ~60
    squarings of a long horizon."""

    def stochastic(matrix):
        np.clip(matrix, 0.0, None, out=matrix)
        matrix /= matrix.sum(axis=1, keepdims=True)
        return matrix

    result = np.eye(transmat.shape[0])
    base = np.array(transmat, dtype=float)
    while steps:
        if steps & 1:
            result = stochastic(result @ base)
        steps >>= 1
        if steps:
            base = stochastic(base @ base)
    return result


def _carry_forecasts(model, holds, ahead, steps, estimate, std):
    """The forecasts (data units) with every held row showing that of the last accepted row
    of its recording; before any, that of the start probabilities: the prior mixture's output
    (``steps=0``, as ``predict``) or the states' outputs mixed by ``startprob A^steps``."""
    if steps == 0:
        before, before_std = model.prior_output()
    else:
        before, before_std = marginal_estimates(
            model.startprob[np.newaxis] @ ahead, model, std is not None
        )
        before = model.standardization.outputs(before)[0]
        if before_std is not None:
            before_std = model.standardization.output_std(before_std)[0]
    estimate = holds.carry(estimate, before)
    return estimate, None if std is None else holds.carry(std, before_std)


def marginal_estimates(ahead, model, return_std=False):
    """Mix every state's output mean and marginal covariance (standardised units) with the
    state probabilities ``ahead``."""
    n_inputs = model.n_inputs
    outputs = model.emissions.marginal(np.arange(n_inputs, model.emissions.n_dims))
    covariances = outputs.state_covariances()
    state_means = np.broadcast_to(outputs.means, (ahead.shape[0], *covariances.shape[:2]))
    params = replace(model.gmr, conditional_covariances=covariances)
    return mix_estimates(ahead, state_means, params, return_std=return_std)
