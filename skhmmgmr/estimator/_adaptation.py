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

import warnings
from dataclasses import replace

import numpy as np
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils.validation import check_is_fitted

from .._core._validation import (
    check_adaptation_params,
)
from .._hmm._em import HMMParameters, e_step
from .._hmm._em_data import Columns, EStepData
from .._hmm._fitted import FittedHMMGMR
from .._hmm._gaussian import NotPositiveDefiniteError
from .._hmm._gmr import causal_filter, gmr_estimates, mix_estimates, read_missing
from .._hmm._missing import observed_counts
from .._hmm._readout import ahead_weights, smooth_outputs
from .._hmm._stale_inputs import stale_noise_for
from ._adaptation_choice import (
    AUTO,
    candidates,
    check_strength,
    choose,
    chunk_ids,
    confirm_fresh_fit,
    recording_folds,
    time_folds,
)
from ._prediction_inputs import read_inputs, read_joint_inputs


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
    With no ``parameters`` or ``relevance=inf`` nothing moves: ``prior`` itself, after no
    iteration.
    """
    engine = EStepData(columns, recordings, prior.n_states)
    if not parameters or relevance == np.inf:  # nothing moves: one E-step for the likelihood
        return prior, [e_step(engine, prior).log_likelihood], 0, True
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

    def adapt(
        self, X, y, groups=None, *, relevance="auto", parameters="auto", n_iter=10, time=None
    ):
        """Adapt the fitted model to new recordings by maximum a posteriori (MAP) EM.

        The fitted parameters are the prior, as in GMM-UBM speaker adaptation (Reynolds et
        al., 2000): the E-step statistics of the new recordings (soft counts ``n_k`` and
        moments per state, in the fitted model's standardised units, the original
        standardisation kept) move a state's mean to ``(n_k E_k[x] + r mu_k) / (n_k + r)``,
        so that a state seen in fewer than about ``r`` rows stays near its fitted value.
        Covariances ("v") and transitions ("t") adapt by the analogous rules (see
        :doc:`/user_guide/adaptation`); the other parameters keep their fitted values.

        By default (``relevance="auto"``, ``parameters="auto"``) the new recordings choose how
        far the model moves. Every recording is cut in time into eight blocks; the model is
        adapted to seven of them and estimates the eighth, in turn, for "do not adapt"
        (``relevance=inf``), for the means and covariances ("mv") at a relevance of 4096,
        1024, 256, 64, 16 and 4, and for a fresh fit of the estimator on the recordings
        alone (``relevance=0``). A candidate's held-out error is the root mean squared error
        of its estimate in every tenth of a held-out block, averaged. Among the candidates
        that keep the fitted model as a prior, the strongest within two standard errors of
        the best score is chosen (the one-standard-error rule, towards the fitted model). The
        fresh fit replaces it only on clear evidence: ahead of it by half a standard error
        of their paired differences on the blocks, and not behind it by more than one with
        each recording held out in turn (with a single recording: a score a tenth lower).
        The choice then adapts to all the rows; ``adaptation_`` keeps the table. A driver
        like the fitted model's keeps it as it is; one far from it moves it as far as the
        held-out rows support, up to a model of its own. The choice costs about 55 single
        adaptations (8 folds of 6 MAP EM runs and a fit, each followed by a prediction; two
        per recording more when the fresh fit leads): 1-4 s for 1-5 minutes at 20 Hz, K=5, 5
        inputs (see :doc:`/user_guide/adaptation`).

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
        relevance : float or "auto", default="auto"
            Relevance factor ``r``: rows of evidence at which a state moves halfway from its
            fitted parameters to those of the new data (256 rows: about 13 s at 20 Hz).
            ``inf`` does not adapt; ``0`` fits the estimator anew on the new recordings alone
            (every parameter, the fitted model not a prior; ``parameters`` "mvt" or "auto").
            Small values approach plain (maximum likelihood) EM from the fitted parameters;
            ``r > 0`` keeps every adapted covariance positive definite (``r S0`` is added to
            the scatter), even for a state the new recordings never visit; the estimator's
            ``reg_covar`` is added to its diagonal as in :meth:`fit`, so that this holds in
            floating point too when ``r`` is so small that ``r S0`` vanishes beside the
            scatter. "auto": chosen from the new recordings, as above. Set a number when the
            adaptation must be quick (a few rows of a stream, a batch of many drivers) or
            the same for every driver, or when the new recordings are not of the kind the
            model will see (the choice scores the model on them).
        parameters : str or "auto", default="auto"
            Which parameters adapt: any of "m" (means), "v" (covariances) and "t" (start and
            transition probabilities), as hmmlearn's ``params``; "" adapts nothing. "auto":
            "mv" (drivers differ in the slopes of the torque on the signals, which live in
            the covariances; the means alone and the transitions added nothing in
            ``benchmarks/bench_adapt_defaults.py``), or a fresh fit when ``relevance`` is
            "auto" too.
        n_iter : int, default=10
            Maximum number of MAP EM iterations; the estimator's ``tol`` stops them earlier.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        self : HMMGMRRegressor
            With a new ``model_`` (the previous one is not modified; when nothing adapts,
            the same ``model_``), and ``n_iter_``, ``converged_``, ``log_likelihood_`` and
            ``log_likelihood_history_`` of the adaptation (the log-likelihood of the new
            recordings), and ``adaptation_``: the table of the "auto" choice, one row per
            candidate with ``parameters``, ``relevance`` (``inf``: not adapted; ``0``: a
            fresh fit), ``validation_rmse`` (the error on held-out time blocks, in units of
            the output's standard deviation at fit), ``validation_se`` (its standard
            error), ``recordings_rmse`` (the error on held-out recordings, for the fresh fit
            and the choice it was checked against; else NaN) and ``chosen``; None when
            neither is "auto". After a fresh fit the
            likelihood attributes are the fit's (``penalized_log_likelihood_`` among them).

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
        >>> choice = model.adapt(X[:200], y[:200] + 0.5).adaptation_  # how far: "auto"
        >>> choice.columns.tolist()
        ['parameters', 'relevance', 'validation_rmse', 'validation_se', 'recordings_rmse', 'chosen']
        """
        check_is_fitted(self)
        relevance, parameters = check_strength(relevance, parameters)
        check_adaptation_params("adapt", n_iter=n_iter)
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
        self.adaptation_ = None
        if AUTO in (relevance, parameters):
            pairs = candidates(relevance, parameters, fresh_fit=self._fits_anew)
            self.adaptation_ = self._choose_adaptation(X, Y, recordings, pairs, int(n_iter))
            chosen = self.adaptation_[self.adaptation_["chosen"]].iloc[0]
            relevance, parameters = chosen["relevance"], chosen["parameters"]
        if relevance == 0:
            return self._fit_anew(X, Y, recordings)
        model, prior = self.model_, self.model_.hmm_parameters()
        params, history, n_done, converged = self._map_em(
            X, Y, recordings, prior, relevance, parameters, int(n_iter)
        )
        if params is not prior:
            self.model_ = _with_parameters(model, params)
        jacobian = model.standardization.log_jacobian(observed_counts(X, Y))
        self.n_iter_, self.converged_ = n_done, converged
        self.log_likelihood_history_ = np.asarray(history) + jacobian
        self.log_likelihood_ = float(self.log_likelihood_history_[-1])
        # The penalised objective of fit does not apply to the adapted model.
        self.penalized_log_likelihood_ = self.penalized_log_likelihood_history_ = None
        return self

    #: Whether ``relevance=0`` (a fresh fit on the adaptation recordings alone) is possible.
    _fits_anew = True

    def _fit_anew(self, X, Y, recordings):
        """``adapt`` with ``relevance=0``: the model of a fresh fit with this estimator's
        parameters on the rows, and the fit's attributes."""
        if not self._fits_anew:
            raise ValueError(
                f"relevance=0 fits the model anew, which {type(self).__name__}.adapt cannot: "
                "call fit; adapt takes relevance > 0."
            )
        fresh = self._fresh_fit(X, Y, recordings)
        self.model_ = replace(fresh.model_, feature_names=self.model_.feature_names)
        for name in FIT_ATTRIBUTES:
            setattr(self, name, getattr(fresh, name))
        return self

    def _fresh_fit(self, X, Y, recordings, quiet=False):
        """A clone of this estimator fitted on the rows ``X, Y`` of ``recordings``; ``quiet``:
        without its convergence warning and messages (a candidate of the "auto" choice)."""
        fresh = clone(self)
        if quiet:
            fresh.set_params(verbose=0)
        with warnings.catch_warnings():
            if quiet:
                warnings.simplefilter("ignore", ConvergenceWarning)
            y = Y[:, 0] if self.model_.scalar_output else Y
            return fresh.fit(X, y, groups=recordings.row_ids())

    def _map_em(self, X, Y, recordings, prior, relevance, parameters, n_iter):
        """:func:`adapt_parameters` from ``prior`` on the rows ``X, Y`` of ``recordings``."""
        return adapt_parameters(
            Columns.from_rows(self.model_.standardization.joint(X, Y)),
            recordings,
            prior,
            relevance=float(relevance),
            parameters=set(parameters),
            n_iter=n_iter,
            tol=self.tol,
            reg_covar=self.reg_covar,
        )

    def _candidate(self, X, Y, recordings, prior, relevance, parameters, n_iter):
        """The fitted model of one candidate of the "auto" choice on the rows ``X, Y``."""
        if relevance == 0:
            return self._fresh_fit(X, Y, recordings, quiet=True).model_
        params = self._map_em(X, Y, recordings, prior, relevance, parameters, n_iter)[0]
        return self.model_ if params is prior else _with_parameters(self.model_, params)

    def _choose_adaptation(self, X, Y, recordings, pairs, n_iter):
        """The table of the "auto" choice among ``pairs`` on the rows ``X, Y`` of
        ``recordings`` (the rule of :meth:`adapt`'s "auto"): every candidate on
        the time folds, then the choice and the fresh fit on held-out recordings when the
        fresh fit leads on the time folds."""
        errors, counts = self._held_out_errors(X, Y, time_folds(recordings), pairs, n_iter)
        table, confirm = choose(pairs, errors, counts)
        if not confirm:
            return table
        folds = recording_folds(recordings)
        if not folds:
            return confirm_fresh_fit(table)
        chosen = pairs[int(np.flatnonzero(table["chosen"])[0])]
        errors, counts = self._held_out_errors(X, Y, folds, [chosen, pairs[-1]], n_iter)
        return confirm_fresh_fit(table, errors, counts)

    def _held_out_errors(self, X, Y, folds, pairs, n_iter):
        """The sums of squared errors (n_pairs, n_chunks) of every candidate of ``pairs``
        adapted on each fold's rows, per chunk of its held-out rows (NaN where a candidate
        could not adapt), and the entries of every chunk; in units of the fitted model's
        standardised outputs, rows whose target is missing left out."""
        model = self.model_
        prior = model.hmm_parameters()
        errors, counts = [np.zeros((len(pairs), 0))], [np.zeros(0, dtype=int)]
        for adapt_rows, adapt_recordings, held_rows, held_recordings in folds:
            held_X, held_Y, chunks = X[held_rows], Y[held_rows], chunk_ids(held_recordings)
            observed = ~np.isnan(held_Y)
            counts.append(np.bincount(chunks, observed.sum(axis=1)))
            fold = np.full((len(pairs), counts[-1].size), np.nan)
            for i, (parameters, relevance) in enumerate(pairs):
                try:
                    candidate = self._candidate(
                        X[adapt_rows],
                        Y[adapt_rows],
                        adapt_recordings,
                        prior,
                        relevance,
                        parameters,
                        n_iter,
                    )
                except ValueError:  # too few rows, a covariance not positive definite: no score
                    continue
                # A fresh fit has a standardisation of its own: each candidate reads the rows
                # as predict does, the errors in units of the fitted model's outputs.
                standardized = candidate.standardization.inputs(held_X)
                noise = stale_noise_for(candidate, self.missing_values)
                missing = read_missing(standardized, held_recordings, noise)
                estimate = candidate.predict_outputs(
                    standardized,
                    held_recordings,
                    missing=missing,
                    min_log_density=self.min_log_density,
                )[0]
                error = (estimate - held_Y) / model.standardization.output_scale
                fold[i] = np.bincount(chunks, np.sum(np.where(observed, error, 0.0) ** 2, axis=1))
            errors.append(fold)
        return np.hstack(errors), np.concatenate(counts)

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


# The attributes a fit sets beside ``model_``, which a fresh fit (``relevance=0``) hands on.
FIT_ATTRIBUTES = (
    "n_iter_",
    "converged_",
    "log_likelihood_",
    "log_likelihood_history_",
    "penalized_log_likelihood_",
    "penalized_log_likelihood_history_",
)


def _n_rows(values):
    """Number of rows of an array-like, 0 for None."""
    return 0 if values is None else len(values)


def _with_parameters(model, params):
    """``model`` (a :class:`FittedHMMGMR`) with the HMM ``params`` (standardised units)."""
    return FittedHMMGMR.from_standardized(
        params.startprob,
        params.transmat,
        params.emissions,
        model.standardization,
        scalar_output=model.scalar_output,
        feature_names=model.feature_names,
        stale_noise=model.stale_noise,
        output_decay=model.output_decay,
    )


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
