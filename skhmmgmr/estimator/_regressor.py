"""The HMM-GMR regressor: a Gaussian HMM over ``[inputs, outputs]`` read out by causal GMR."""

import warnings
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin, TransformerMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.metrics import r2_score
from sklearn.utils import metadata_routing
from sklearn.utils.validation import check_is_fitted

from .._core._compat import FiniteInterval, Interval, StrOptions, _fit_context
from .._core._panel import align_target
from .._core._pickled import PickleVersionMixin
from .._core._validation import (
    check_column_scales,
    check_enough_rows,
    check_target_finite,
)
from .._hmm._em import fit_hmm, score_hmm
from .._hmm._em_data import Columns
from .._hmm._em_init import INIT_METHODS
from .._hmm._emissions import EMISSION_FAMILIES, REFUSED_COVARIANCE_TYPES, emission_family
from .._hmm._fitted import FittedHMMGMR, Standardization
from .._hmm._gmr import filter_state_probabilities, read_missing, scaled_input_densities
from .._hmm._holds import MIN_LOG_DENSITY_CONSTRAINT
from .._hmm._missing import observed_counts
from .._hmm._readout import (
    MAX_TIME_CONSTANT,
    fixed_decay,
    time_constant_of,
    weakest_decay,
)
from .._hmm._stale_inputs import MISSING_VALUES, learn_stale_noise, stale_noise_for
from ._adaptation import AdaptMixin
from ._io import ModelIOMixin
from ._prediction_inputs import read_inputs, read_joint_inputs


class HMMGMRRegressor(
    PickleVersionMixin, AdaptMixin, ModelIOMixin, TransformerMixin, RegressorMixin, BaseEstimator
):
    """Hidden Markov Model + Gaussian Mixture Regression (HMM-GMR) regressor.

    A fully connected hidden Markov model with one Gaussian per state (a full covariance per
    state, or one shared by all states) is fitted by Baum-Welch (EM) on the joint vector
    ``[X, y]`` of every recording. Prediction is causal:
    the forward variable is computed on the inputs only, restarted at every recording, and
    weights the per-state Gaussian-conditional means of ``y`` given ``X`` (Gaussian Mixture
    Regression).

    Read more in the user guide and in METHOD.md sections 1-2.

    Parameters
    ----------
    n_states : int, default=5
        Number of hidden states ``K``.
    covariance_type : {"full", "tied"}, default="full"
        "full": one full covariance per state (the thesis' model). "tied": one full covariance
        shared by all states (far fewer parameters for many features and states; the
        regression slope of the outputs on the inputs is then shared and the intercepts differ
        by state). "diag" and "spherical" are refused: within a state the outputs would not
        depend on the inputs, and GMR would predict the state means only.
    n_iter : int, default=100
        Maximum number of EM iterations per initialisation.
    tol : float, default=1e-4
        Convergence threshold on the gain in log-likelihood per row between two EM iterations.
    n_init : int, default=1
        Number of initialisations; the fit with the highest log-likelihood is kept.
    init_params : {"kmeans", "k-means++", "random", "random_from_data"}, default="kmeans"
        How the state means and covariances are initialised (as in
        :class:`sklearn.mixture.GaussianMixture`); start probabilities start uniform and the
        transition rows are drawn from a flat Dirichlet distribution. The k-means starts
        ("kmeans", "k-means++", "random_from_data") cluster an evenly spaced sample of at most
        100,000 rows (every ``ceil(n_samples / 100000)``-th row from a random offset), then
        every row joins its nearest centre.
    reg_covar : float, default=1e-6
        Non-negative regularisation of the state covariances: a prior
        ``p(S_k) ∝ exp(-psi / 2 tr(S_k^-1))`` with ``psi = reg_covar * n_samples /
        n_states`` on every state covariance ``S_k``. The M-step is its exact maximiser,
        ``S_k = (scatter_k + psi I) / N_k``: a state holding an average share of the rows
        gets ``reg_covar`` on its diagonal, a lighter state more. EM maximises the penalised
        log-likelihood (``penalized_log_likelihood_history_``), which never falls. The engine
        works on standardised columns (zero mean, unit variance), so the value is relative to
        each column's variance: constant, collinear and badly scaled columns are all handled
        by the same regularisation. ``0`` gives maximum likelihood.
    missing_values : {"error", "marginalize", "carry_forward"}, default="error"
        What a NaN in ``X`` (or in ``y`` for ``fit``) means. "error": it is refused, naming
        its column and recording. "marginalize": a missing value; a row takes part through
        its observed columns only (missing-data EM: the states' marginal densities of those
        columns, and expected statistics of the missing ones; the k-means initialisation
        sees missing values as their column's mean), and prediction conditions on the
        observed inputs of each row (a row with none passes the state probabilities through
        the transition matrix). "carry_forward": fitted the same way, and ``fit`` also learns
        every input's variogram; prediction reads a missing input through its last observed
        value in the recording, as a noisy observation whose variance is the variogram at its
        age (marginalised when there is none, or older than 128 samples). Infinities are
        refused either way. See the user guide, "Missing inputs".
    output_smoothing : None, float in [0, 1e6] or "auto", default=None
        Time constant ``tau``, in rows, of a causal first-order read-out of the GMR estimate:
        ``estimate_t = a estimate_{t-1} + (1 - a) GMR_t`` with ``a = exp(-1 / tau)``,
        restarted at every recording (the first estimate is the GMR one). The same read-out
        runs in :class:`~skhmmgmr.FilterStream`, the model file and the generated C. "auto":
        ``fit`` chooses, per output, the weakest read-out whose estimate of the training
        recordings is no rougher than the measured output there (the thesis' smoothness,
        :func:`~skhmmgmr.metrics.smoothness_score`); none when the GMR estimate already is
        not, or when that read-out changes nothing that matters: the estimate's roughness by
        less than 1 % and no training recording's accuracy by 0.1 percentage point (a model
        without a read-out keeps model file format version 2). None or 0: the GMR estimate
        itself (the thesis' model). At most 1e6 rows, the longest "auto" considers (single
        precision, as in the C export's float32, could not tell a longer one's decay from
        one). ``return_std`` gives the model's predictive standard deviation either way. See
        the user guide, "Smooth by design".
    min_log_density : float or None, default=None
        The outlier policy, the same in ``predict``, :class:`~skhmmgmr.FilterStream` and the
        generated C code (:func:`skhmmgmr.export.write_c`). None: no sample is held; the
        filter works in log space, so that a sample far from every state is filtered as any
        other. A number: a sample whose input log-density (in the standardised units the
        model works in; the largest over the states) is below it is *held*: the estimate,
        its std and the state probabilities stay those of the last accepted sample of the
        recording (the prior mixture's before any), and the filter goes on as if the sample
        had not come. The training rows' own log-densities tell what is usual
        (:meth:`input_log_density`). Read at prediction time: ``set_params`` on a fitted
        model takes effect without a refit. Inputs whose standardised absolute values sum
        to 1e100 or more are out of the model's range either way: ``predict`` refuses them,
        the stream and the C code hold them. See the user guide, "Held samples".
    random_state : int, RandomState instance or None, default=None
        Seed of the initialisation, for reproducible fits.
    verbose : int, default=0
        Print the log-likelihood of every EM iteration when positive.

    Attributes
    ----------
    startprob_ : ndarray of shape (n_states,)
        Start probabilities ``pi``.
    transmat_ : ndarray of shape (n_states, n_states)
        Transition matrix; row ``j`` holds the probabilities of leaving state ``j``.
    means_ : ndarray of shape (n_states, n_dims)
        State means over the joint vector ``[inputs, outputs]``, in the data's units
        (``n_dims = n_features_in_ + n_outputs_``).
    covars_ : ndarray of shape (n_states, n_dims, n_dims)
        Every state's full covariance over the joint vector, in the data's units (with
        ``covariance_type="tied"`` the shared one, repeated; as hmmlearn's ``covars_``).
    model_ : FittedHMMGMR
        The fitted model as one immutable object: standardisation, HMM parameters, state
        densities and output shape. ``predict``, :class:`~skhmmgmr.FilterStream` and the
        portable JSON format read it; ``startprob_``, ``transmat_``, ``means_`` and
        ``covars_`` are views of it in the data's units.
    n_features_in_ : int
        Number of input features.
    feature_names_in_ : ndarray of shape (n_features,)
        Input names, when ``X`` has string column names.
    n_outputs_ : int
        Number of outputs (columns of ``y``).
    output_names_ : ndarray of shape (n_outputs,)
        Output names, when ``y`` has them: a pandas Series' name, a DataFrame's string
        column names. :func:`skhmmgmr.portable.save` writes them in the model file.
    n_iter_ : int
        EM iterations of the kept initialisation.
    converged_ : bool
        Whether the kept initialisation converged.
    log_likelihood_ : float
        Log-likelihood of the training recordings under the fitted parameters.
    output_smoothing_ : float or ndarray of shape (n_outputs,)
        Time constant in rows of the read-out of every output (``output_smoothing``, or the
        one "auto" chose; 0: none): a float for a 1-D target.
    log_likelihood_history_ : ndarray
        Log-likelihood before every M-step of the kept initialisation, then that of the
        fitted parameters. EM maximises the penalised log-likelihood, not this: it may fall
        slightly in an iteration when ``reg_covar > 0`` (never when ``reg_covar=0``).
    penalized_log_likelihood_ : float
        The objective EM maximises, for the fitted parameters: the log-likelihood plus the
        log covariance prior ``-psi / 2 sum_k tr(S_k^-1)`` (standardised units; see
        ``reg_covar``). The kept initialisation is the one with the highest value.
    penalized_log_likelihood_history_ : ndarray
        The same for every entry of ``log_likelihood_history_``; non-decreasing up to
        round-off (1e-9 relative).
    longest_recording_ : int or None
        Rows of the longest training recording (``None`` when fitted without recordings):
        ``predict`` warns when it gets more rows than that without recordings.

    Notes
    -----
    Recordings reach the model as ``groups`` (one recording id per row, routed by
    scikit-learn's metadata routing) or with the rows themselves: a pandas ``X`` whose index
    has a level ``"recording"`` (and optionally ``"time"``, see
    :func:`skhmmgmr.datasets.to_panel`). Tools that never pass ``groups`` on
    (``cross_val_predict``, built-in scorers, ``permutation_importance``, successive halving,
    conformal wrappers) keep the index, so their results are per recording. With a ``time``
    level the rows may come in any order: the filter runs in time order and the results come
    back in the caller's row order.
    ``fit`` takes the recordings of such an ``X`` in order of their ids (as text), so that any
    shuffle of the rows gives the same model.

    See Also
    --------
    skhmmgmr.PerformanceScore : the thesis' accuracy/smoothness scorer.

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr import HMMGMRRegressor
    >>> rng = np.random.default_rng(0)
    >>> X = np.cumsum(rng.normal(size=(400, 2)), axis=0) / 10
    >>> y = 2.0 * X[:, 0] - X[:, 1] + rng.normal(scale=0.05, size=400)
    >>> groups = np.repeat(["a", "b"], 200)
    >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y, groups=groups)
    >>> model.predict(X, groups=groups).shape
    (400,)
    >>> model.score(X, y, groups=groups) > 0.95
    True
    """

    _parameter_constraints = {
        "n_states": [Interval(Integral, 1, None, closed="left")],
        "covariance_type": [StrOptions({*EMISSION_FAMILIES, *REFUSED_COVARIANCE_TYPES})],
        "n_iter": [Interval(Integral, 1, None, closed="left")],
        "tol": [Interval(Real, 0, None, closed="left")],
        "n_init": [Interval(Integral, 1, None, closed="left")],
        "init_params": [StrOptions(set(INIT_METHODS))],
        "reg_covar": [Interval(Real, 0, None, closed="left")],
        "missing_values": [StrOptions(set(MISSING_VALUES))],
        "output_smoothing": [
            None,
            FiniteInterval(Real, 0, MAX_TIME_CONSTANT, closed="both"),
            StrOptions({"auto"}),
        ],
        "min_log_density": MIN_LOG_DENSITY_CONSTRAINT,
        "random_state": ["random_state"],
        "verbose": ["verbose"],
    }

    # Recording ids are what makes the data sequences: with metadata routing enabled they are
    # requested by default (as GroupKFold.split does), so that a search routes them to fit,
    # predict, transform and score without set_*_request calls.
    __metadata_request__fit = {"groups": True}
    __metadata_request__predict = {"groups": True, "return_std": metadata_routing.UNUSED}
    __metadata_request__transform = {"groups": True}
    __metadata_request__score = {"groups": True}

    def __init__(
        self,
        n_states=5,
        *,
        covariance_type="full",
        n_iter=100,
        tol=1e-4,
        n_init=1,
        init_params="kmeans",
        reg_covar=1e-6,
        missing_values="error",
        output_smoothing=None,
        min_log_density=None,
        random_state=None,
        verbose=0,
    ):
        self.n_states = n_states
        self.covariance_type = covariance_type
        self.n_iter = n_iter
        self.tol = tol
        self.n_init = n_init
        self.init_params = init_params
        self.reg_covar = reg_covar
        self.missing_values = missing_values
        self.output_smoothing = output_smoothing
        self.min_log_density = min_log_density
        self.random_state = random_state
        self.verbose = verbose

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y, groups=None, time=None):
        """Fit the HMM on the joint ``[X, y]`` of every recording by Baum-Welch.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            Input features, rows of a recording contiguous and in time order, or a DataFrame
            with the recordings (and the time) in its index (see Notes).
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Outputs (the driver torque).
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row; ``None`` means the recording level of the index of
            ``X``, or else one recording.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        self : HMMGMRRegressor
        """
        emission_family(self.covariance_type)  # refuses "diag" and "spherical", saying why
        # Recordings in order of their ids, whether from the index or from groups: the
        # initialization reads the rows in order, so neither a shuffle of a panel's rows (a
        # resampling search) nor the order of the recordings given as arrays may change it.
        inputs = read_joint_inputs(self, X, y, groups, time, fitting=True)
        standardized, scaling, stale_noise = self._standardized(inputs, self.n_states)
        result = self._baum_welch(standardized, inputs.recordings)
        if not result.converged:
            warnings.warn(
                f"EM did not converge in n_iter={self.n_iter} iterations (tol={self.tol}); "
                "increase n_iter or tol.",
                ConvergenceWarning,
                stacklevel=2,
            )
        self._set_fitted(result, inputs, scaling, stale_noise)
        return self

    def __setstate__(self, state):
        # an estimator pickled before ``output_smoothing`` or ``min_log_density`` existed had
        # neither
        super().__setstate__({"output_smoothing": None, "min_log_density": None, **state})

    def _standardized(self, inputs, n_states):
        """``(columns, (center, scale), stale_noise)`` of the joint ``inputs`` of a fit of
        ``n_states`` states, with the attributes read from the data (``n_outputs_``,
        ``longest_recording_``)."""
        X, Y, recordings = inputs.X, inputs.Y, inputs.recordings
        self.n_outputs_ = Y.shape[1]
        # Without recordings there is nothing to compare a later prediction's length with.
        self.longest_recording_ = int(recordings.lengths.max()) if inputs.grouped else None
        check_enough_rows(X.shape[0], n_states, X.shape[1] + Y.shape[1])
        # The engine's own layout, standardised in place: the only copy of the data it makes.
        standardized, center, scale = Columns.standardized(X, Y)
        check_column_scales(scale, [*inputs.input_names, *inputs.output_names])
        # The variograms need the missing values, which the engine overwrites.
        stale_noise = learn_stale_noise(self.missing_values, standardized, X.shape[1], recordings)
        return standardized, (center, scale), stale_noise

    def _set_fitted(self, result, inputs, scaling, stale_noise):
        """The fitted attributes from the EM ``result`` on the standardised columns of
        ``inputs`` (``scaling``: their centre and scale)."""
        center, scale = scaling
        params = result.parameters
        self.model_ = FittedHMMGMR.from_standardized(
            params.startprob,
            params.transmat,
            params.emissions,
            Standardization(center, scale, inputs.X.shape[1]),
            scalar_output=inputs.scalar_output,
            feature_names=getattr(self, "feature_names_in_", None),
            stale_noise=stale_noise,
        )
        if self.output_smoothing is not None:
            self.model_ = self.model_.with_output_decay(self._output_decay(inputs))
        jacobian = self.model_.standardization.log_jacobian(observed_counts(inputs.X, inputs.Y))
        self.n_iter_ = result.n_iter
        self.converged_ = result.converged
        self.log_likelihood_ = result.log_likelihood + jacobian
        self.log_likelihood_history_ = np.asarray(result.history) + jacobian
        self.penalized_log_likelihood_ = result.objective + jacobian
        self.penalized_log_likelihood_history_ = np.asarray(result.objective_history) + jacobian
        if self.verbose:
            for i, (value, objective) in enumerate(
                zip(
                    self.log_likelihood_history_,
                    self.penalized_log_likelihood_history_,
                    strict=True,
                )
            ):
                print(
                    f"EM iteration {i}: log-likelihood {value:.6f}, "
                    f"penalised log-likelihood {objective:.6f}"
                )

    def _output_decay(self, inputs):
        """Decay of the read-out of every output: of ``output_smoothing``, or for "auto" the
        weakest that makes the estimate of the training ``inputs`` no rougher than their
        outputs."""
        n_outputs = inputs.Y.shape[1]
        if self.output_smoothing != "auto":
            return np.full(n_outputs, fixed_decay(self.output_smoothing))
        model, recordings = self.model_, inputs.recordings
        standardized = model.standardization.inputs(inputs.X)
        noise = stale_noise_for(model, self.missing_values)
        missing = read_missing(standardized, recordings, noise)
        estimate, _, _ = model.predict_outputs(  # no read-out yet: the GMR estimate
            standardized, recordings, missing=missing, min_log_density=self.min_log_density
        )
        return weakest_decay(estimate, inputs.Y, recordings)

    def _baum_welch(self, columns, recordings):
        # The one place the EM engine is called (a reference engine can stand in for it).
        return fit_hmm(
            columns,
            recordings,
            self.n_states,
            n_init=self.n_init,
            init_params=self.init_params,
            n_iter=self.n_iter,
            tol=self.tol,
            reg_covar=self.reg_covar,
            random_state=self.random_state,
            covariance_type=self.covariance_type,
        )

    @property
    def startprob_(self):
        check_is_fitted(self)
        return self.model_.startprob

    @property
    def transmat_(self):
        check_is_fitted(self)
        return self.model_.transmat

    @property
    def means_(self):
        check_is_fitted(self)
        return self.model_.data_emissions.means

    @property
    def covars_(self):
        check_is_fitted(self)
        return np.array(self.model_.data_emissions.state_covariances())

    @property
    def output_smoothing_(self):
        check_is_fitted(self)
        constants = np.array([time_constant_of(a) for a in self.model_.output_decay.tolist()])
        return float(constants[0]) if self.model_.scalar_output else constants

    def input_log_density(self, X, groups=None, time=None):
        """The log-density of every row's inputs under its nearest state, as the outlier
        policy reads it (``min_log_density``).

        The largest over the states of the input log-density, in the standardised units the
        model works in (of the observed inputs of a row with missing ones; 0 for a row with
        none). On the training recordings it tells what is usual: a ``min_log_density``
        well below their smallest value holds only samples farther from every state than
        any of them.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row (read only for ``missing_values="carry_forward"``).
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        log_density : ndarray of shape (n_samples,)

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import HMMGMRRegressor
        >>> rng = np.random.default_rng(1)
        >>> X = np.cumsum(rng.normal(size=(400, 2)), axis=0) / 10
        >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, X.sum(axis=1))
        >>> usual = model.input_log_density(X).min()
        >>> held = model.set_params(min_log_density=usual - 20.0).filter_stream()
        >>> held.update(np.array([50.0, -50.0]), return_flag=True)[1]
        'outlier'
        """
        standardized, _, rows, missing = read_inputs(self, X, groups, time)
        _, top, _ = scaled_input_densities(standardized, self.model_.gmr, missing=missing)
        return rows.to_caller_order(top)

    def predict_state_proba(self, X, groups=None, time=None):
        """Filtered state probabilities ``alpha_t,k`` given the inputs up to each row.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row; the filter restarts at every recording.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.

        Returns
        -------
        alpha : ndarray of shape (n_samples, n_states)
            Rows sum to one.
        """
        standardized, recordings, rows, missing = read_inputs(self, X, groups, time)
        alpha = filter_state_probabilities(
            standardized,
            recordings,
            self.model_.gmr,
            missing=missing,
            min_log_density=self.min_log_density,
        )
        return rows.to_caller_order(alpha)

    def predict(self, X, groups=None, time=None, return_std=False):
        """Causal GMR estimate of the outputs, filtered recording by recording.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row; the filter restarts at every recording. Without it
            all rows are filtered as one recording.
        time : array-like of shape (n_samples,), default=None
            Optional time stamps, checked to increase within every recording.
        return_std : bool, default=False
            Also return the predictive standard deviation (law of total variance over the
            filtered mixture; not smoothed by ``output_smoothing``).

        Returns
        -------
        y_pred : ndarray of shape (n_samples,) or (n_samples, n_outputs)
        y_std : ndarray of the same shape, only when ``return_std`` is True
        """
        standardized, recordings, rows, missing = read_inputs(self, X, groups, time)
        model = self.model_
        estimate, std, _ = model.predict_outputs(
            standardized,
            recordings,
            missing=missing,
            min_log_density=self.min_log_density,
            return_std=return_std,
        )
        estimate = rows.to_caller_order(estimate[:, 0] if model.scalar_output else estimate)
        if not return_std:
            return estimate
        return estimate, rows.to_caller_order(std[:, 0] if model.scalar_output else std)

    def transform(self, X, groups=None, time=None):
        """Filtered state probabilities, as features (see :meth:`predict_state_proba`).

        With ``set_output(transform="pandas")`` the result is a DataFrame whose columns are
        ``get_feature_names_out()``.
        """
        return self.predict_state_proba(X, groups=groups, time=time)

    def fit_transform(self, X, y, groups=None, time=None):
        """Fit, then return the filtered state probabilities of the training recordings."""
        return self.fit(X, y, groups=groups, time=time).transform(X, groups=groups, time=time)

    def get_feature_names_out(self, input_features=None):
        """Names of the state-probability columns: ``state_0`` ... ``state_{K-1}``."""
        check_is_fitted(self)
        return np.asarray([f"state_{k}" for k in range(self.n_states)], dtype=object)

    def score(self, X, y, groups=None, sample_weight=None):
        """Coefficient of determination R^2 of the per-recording causal predictions.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row.
        sample_weight : array-like of shape (n_samples,), default=None

        Returns
        -------
        score : float
        """
        y = align_target(X, y)
        check_target_finite(y, None)  # names y's column and row, not "Input contains NaN"
        return r2_score(y, self.predict(X, groups=groups), sample_weight=sample_weight)

    def log_likelihood(self, X, y, groups=None):
        """Log-likelihood of the joint ``[X, y]`` recordings under the fitted HMM.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
        y : array-like of shape (n_samples,) or (n_samples, n_outputs)
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row; the forward pass restarts at every recording.

        Returns
        -------
        log_likelihood : float
        """
        check_is_fitted(self)
        inputs = read_joint_inputs(self, X, y, groups, None, fitting=False)
        X, Y, recordings = inputs.X, inputs.Y, inputs.recordings
        scaling = self.model_.standardization
        log_likelihood = score_hmm(scaling.joint(X, Y), recordings, self.model_.hmm_parameters())
        return log_likelihood + scaling.log_jacobian(observed_counts(X, Y))

    def n_parameters(self):
        """Number of free parameters of the fitted HMM (for information criteria)."""
        check_is_fitted(self)
        return self.model_.n_parameters()

    def bic(self, X, y, groups=None):
        """Bayesian information criterion of the recordings (lower is better).

        ``-2 log L + n_parameters * log(n_samples)``.
        """
        log_likelihood = self.log_likelihood(X, y, groups=groups)
        return -2.0 * log_likelihood + self.n_parameters() * np.log(len(X))

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.required = True
        tags.target_tags.multi_output = True
        tags.input_tags.allow_nan = self.missing_values != "error"
        return tags
