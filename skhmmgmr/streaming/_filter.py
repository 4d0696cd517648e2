"""Sample-by-sample causal GMR filter for real-time use (one update per control cycle).

The stream runs the same normalised forward recursion and Gaussian Mixture Regression as
:meth:`HMMGMRRegressor.predict <skhmmgmr.HMMGMRRegressor.predict>` (METHOD.md section 2), one
sample at a time, with the filter state carried between calls. Everything that does not depend
on the sample is precomputed at construction and every intermediate result lives in a
preallocated buffer, so that an update is a handful of small NumPy calls on fixed buffers:

- the standardised input ``z`` (with a trailing 1) times ONE stacked matrix gives at once the
  terms of the gating density's quadratic form of every state
  (:class:`~skhmmgmr._hmm._emissions.GaussianDensity`) and every per-state conditional mean;
- the squared terms times a block-indicator matrix (with the log-normalisers as its last row)
  give the log-densities of all states in one more product.

The stream reads a :class:`~skhmmgmr.FittedHMMGMR` (an estimator's ``model_``): the gating
density, the regressions and the standardisation are that object's. A sample with missing
inputs (NaN, when they are marginalised) takes a slower path: the Gaussians of every state
conditioned on its observed inputs (:func:`~skhmmgmr._hmm._missing.gmr_given_observed`).

A fitted Pipeline of ``SteeringFeatures`` steps and the regressor streams the sensed rows: the
derived inputs are computed first, one scalar operation at a time, into a preallocated row
(:mod:`skhmmgmr.streaming._derived`), which then goes the regressor's way.
"""

import math
import numbers

import numpy as np
from sklearn.utils.validation import check_is_fitted

from .._core._panel import align_target, read_layout, recordings_of
from .._core._pickled import PickleVersionMixin
from .._hmm._fitted import FittedHMMGMR
from .._hmm._missing import gmr_given_observed
from .._hmm._stale_inputs import MISSING_VALUES, carried_inputs
from ._adaptation import OnlineMeans, check_adaptation
from ._derived import check_final, read_pipeline
from ._inputs import as_batch, as_row

FLAG_OK = "ok"
FLAG_NON_FINITE = "non-finite"
FLAG_OUTLIER = "outlier"
FLAG_RESTARTED = "restarted"
FLAG_MISSING = "missing"
_HELD_FLAGS = (FLAG_NON_FINITE, FLAG_OUTLIER)
_LEARNED_FLAGS = (FLAG_OK, FLAG_RESTARTED)
_MAX_STANDARDISED = 1e100


class FilterStream(PickleVersionMixin):
    """Causal HMM-GMR filter of a fitted :class:`~skhmmgmr.HMMGMRRegressor`, one sample a call.

    Streaming a recording sample by sample gives the estimates of ``model.predict`` on the whole
    recording (up to round-off), as long as no sample is held (see Notes). The stream copies
    the model's parameters when it is created: refitting the model later does not change it.

    Parameters
    ----------
    model : FittedHMMGMR, HMMGMRRegressor or Pipeline
        A fitted model, or a fitted estimator (its ``model_`` is read), or a fitted Pipeline of
        :class:`~skhmmgmr.SteeringFeatures` steps ending in an ``HMMGMRRegressor``
        (:func:`~skhmmgmr.make_torque_pipeline`'s, or any scikit-learn ``Pipeline`` of those
        steps), which then takes the sensed rows (see Notes). Usually created with
        ``estimator.filter_stream()`` or ``pipeline.filter_stream()``.
    min_log_density : float, default=log(smallest normal double) ~ -708.4
        A sample whose input log-density, in the standardised units the model works in, is below
        this value in every state is an outlier (see Notes). The default flags exactly the
        samples whose densities all underflow to zero in double precision.
    missing_values : {"error", "marginalize", "carry_forward"}, default=None
        What a NaN input means. "error": the sample is held (flag ``"non-finite"``).
        "marginalize": the input is missing; the sample is filtered on its observed inputs,
        as ``predict`` of a model with ``missing_values="marginalize"`` does (flag
        ``"missing"``). "carry_forward": the same, with the missing inputs read through their
        last observed values in the recording (since :meth:`reset`), as ``predict`` of a
        model fitted with ``missing_values="carry_forward"`` does (the model must hold the
        inputs' variograms, ``stale_noise``). ``None``: the estimator's ``missing_values``
        when ``model`` is an estimator (the regressor's, for a Pipeline), "error" for a
        :class:`~skhmmgmr.FittedHMMGMR`.
    relevance : float, default=None
        Online adaptation of the state means (see Notes): the relevance factor ``r`` > 0 of
        the MAP rule of :meth:`HMMGMRRegressor.adapt <skhmmgmr.HMMGMRRegressor.adapt>`.
        ``None``: no adaptation, the stream is the fitted model's.
    forgetting : float, default=1.0
        Forgetting factor in (0, 1] of the adaptation statistics, applied at every learned
        sample (memory of about ``1 / (1 - forgetting)`` samples); 1 forgets nothing.

    Attributes
    ----------
    last_flag_ : str
        What happened at the last update: ``"ok"``, ``"restarted"`` (accepted; the transitions
        allowed no state that explains the sample, so the filter restarted from the input
        densities, as ``predict`` does), ``"missing"`` (accepted; some or all inputs were NaN
        and marginalised), ``"non-finite"`` or ``"outlier"`` (both held).
    n_samples_ : int
        Number of samples given since the last :meth:`reset`, held ones included.
    recording_ : object or None
        Recording of the last batch given with a ``"recording"`` index level (see
        :meth:`update_batch`); ``None`` after :meth:`reset` and for plain input.
    n_features_in_ : int
        Number of inputs of one sample (for a Pipeline: of one sensed row, before the derived
        inputs).
    feature_names_in_ : ndarray of str
        Input names, when the model (the Pipeline) was fitted on named columns.

    Notes
    -----
    Samples the filter cannot use are *held*: the update returns the last accepted estimate (or,
    before any accepted sample, the prior-mixture estimate ``sum_k pi_k mu_k^T`` and its
    standard deviation), sets :attr:`held_`, and leaves the filter state unchanged, so the
    estimates that follow equal those of a stream that never saw the held sample. Two kinds
    of sample are held:

    - ``"non-finite"``: an infinite input, or a NaN one unless missing values are
      missing values (``missing_values="marginalize"`` or ``"carry_forward"``: the sample is
      then filtered on its observed inputs, and a sample with none passes the state
      probabilities through the transition matrix);
    - ``"outlier"``: finite inputs so far from every state that all input log-densities are below
      ``min_log_density`` (or standardised inputs whose absolute values sum above 1e100, where
      the densities would overflow). ``predict`` would extrapolate the nearest state's linear
      regression there; the stream does not trust it, keeps the state probabilities, and flags
      the sample.

    No NaN or infinity ever comes out of :meth:`update`.

    A model whose read-out smooths (``output_smoothing`` of the regressor) gives the
    smoothed estimate, as ``predict`` does: ``a * (previous estimate) + (1 - a) * (GMR
    estimate)`` at every accepted sample, the GMR estimate at the first of a recording. A held
    sample leaves the read-out as it is; ``return_std`` gives the model's predictive standard
    deviation, not smoothed.

    Online adaptation (``relevance`` given): an update given the measured ``target`` returns
    the current model's estimate, then moves the state means by the MAP rule of ``adapt``
    (fitted means as the prior), recursively, from decayed statistics of the filtered state
    probabilities: a bounded cost per update (:mod:`skhmmgmr.streaming._adaptation`). Held
    samples and those with missing inputs do not learn. :meth:`reset` keeps what was
    learned, :meth:`reset_adaptation` forgets it, :meth:`adapted_model` returns it.

    A Pipeline (``SteeringFeatures`` steps, then the regressor) streams the sensed rows, in the
    Pipeline's input order or by name: every update computes the derived inputs of the row
    and filters the row they make with the regressor, so that the estimates equal
    ``pipeline.predict`` on the recording (up to round-off; ``update_batch`` on a panel
    equals it with the panel's recordings). The velocity filter of ``velocity_filter`` keeps
    its state between updates and restarts with the regressor's filter (:meth:`reset`, a new
    recording in :meth:`update_batch`); it follows the batch rule of ``SteeringFeatures``
    (it starts at the first observed velocity of the recording; a missing velocity gives a
    missing friction input and leaves its state alone). A held row still feeds its velocity
    to the velocity filter, as ``predict`` would, so that the derived inputs of the rows
    after it are ``predict``'s; only an infinite velocity is read as missing (``predict``
    refuses it). Missing values, ``target`` and the adaptation are the regressor's, as for the
    regressor's own stream.

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr import HMMGMRRegressor
    >>> rng = np.random.default_rng(0)
    >>> X = np.cumsum(rng.normal(size=(300, 2)), axis=0) / 10
    >>> y = np.tanh(X[:, 0]) - X[:, 1]
    >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y)
    >>> stream = model.filter_stream()
    >>> estimates = [stream.update(row) for row in X[:50]]
    >>> bool(np.allclose(estimates, model.predict(X[:50]), rtol=0, atol=1e-12))
    True
    >>> stream.update(np.array([np.nan, 0.0]), return_flag=True)[1]
    'non-finite'
    """

    def __init__(
        self,
        model,
        *,
        min_log_density=math.log(np.finfo(float).tiny),
        missing_values=None,
        relevance=None,
        forgetting=1.0,
    ):
        estimator = None if isinstance(model, FittedHMMGMR) else model
        self._stages = ()
        if estimator is not None and hasattr(estimator, "steps"):  # a Pipeline
            self._stages, (name, estimator) = read_pipeline(estimator)
        if estimator is not None:  # a fitted estimator first, as its other methods check
            check_is_fitted(estimator)
            model = getattr(estimator, "model_", None)
            if not isinstance(model, FittedHMMGMR):
                raise TypeError(
                    "FilterStream streams a fitted HMMGMRRegressor, a FittedHMMGMR or a fitted "
                    f"Pipeline ending in an HMMGMRRegressor; got {type(estimator).__name__}"
                    + (f" (the Pipeline's step {name!r})" if self._stages else "")
                )
        if missing_values is None:
            missing_values = getattr(estimator, "missing_values", "error")
        if missing_values not in MISSING_VALUES:
            raise ValueError(
                f"missing_values must be one of {MISSING_VALUES}, got {missing_values!r}"
            )
        self.missing_values = missing_values
        self._marginalize = missing_values != "error"
        self.relevance, self.forgetting = check_adaptation(relevance, forgetting)
        self._model = model
        self._carried = carried_inputs(model, missing_values)
        params, scaling = model.gmr, model.standardization
        n_states, n_outputs, n_inputs = params.coef.shape
        self.n_features_in_ = n_inputs
        names = model.feature_names
        if self._stages:
            check_final(self._stages, n_inputs, names)
            first = self._stages[0]
            self.n_features_in_, names = first.n_features_in, first.feature_names_in
            # the sensed row followed by every step's derived inputs, as the regressor reads it
            self._derived_row = np.empty(n_inputs)
        self._row_shape = (self.n_features_in_,)
        if names is not None:
            self.feature_names_in_ = np.asarray(names, dtype=object)
        self.min_log_density = float(min_log_density)
        self._n_states, self._n_outputs = n_states, n_outputs
        self._scalar_output = model.scalar_output
        self._input_center = np.array(scaling.input_center)
        self._input_scale = np.array(scaling.input_scale)
        self._output_center = np.array(scaling.output_center)
        self._output_scale = np.array(scaling.output_scale)
        self._center_0, self._scale_0 = float(self._output_center[0]), float(self._output_scale[0])
        # The causal first-order read-out of the GMR estimate (skhmmgmr._hmm._readout).
        self._smoothed = model.smoothed
        self._decay = np.array(model.output_decay)
        self._decay_0 = float(self._decay[0])
        self._startprob = np.array(params.startprob, dtype=float)
        # A^T @ alpha is a faster BLAS call than alpha @ A for these tiny sizes.
        self._transmat_t = np.ascontiguousarray(params.transmat.T, dtype=float)
        self._conditional_variances = np.ascontiguousarray(params.conditional_variances)
        # Samples with missing inputs: the read-out conditioned on their observed inputs.
        self._gmr, self._added = params, None

        # [z, 1] @ weights = [the gating density's quadratic-form terms of every state,
        # m_k(z) for every k]; log b_k(z) = norm_k - (sum of the squares of state k's terms).
        density = params.gating.density()
        n_terms = density.factors.shape[0]
        weights = np.empty((n_inputs + 1, n_terms + n_states * n_outputs))
        weights[:, :n_terms] = density.factors.T
        weights[:n_inputs, n_terms:] = np.hstack(list(params.coef.transpose(0, 2, 1)))
        weights[n_inputs, n_terms:] = params.intercept.ravel()
        self._weights = weights
        # [squared terms, 1] @ block_sum = log-densities.
        block_sum = np.zeros((n_terms + 1, n_states))
        block_sum[:n_terms] = -np.kron(np.eye(n_states), np.ones((n_terms // n_states, 1)))
        block_sum[n_terms] = density.norms[:, 0]
        self._block_sum = block_sum
        n_whitened = n_terms
        self._online = None
        if relevance is not None:  # rewrites the constant row of the weights in place
            self._online = OnlineMeans(model, weights[n_inputs], n_terms, relevance, forgetting)

        self._z = np.ones(n_inputs + 1)
        self._z_inputs = self._z[:n_inputs]
        self._squares = np.ones(n_whitened + 1)
        self._squares_head = self._squares[:n_whitened]
        self._log_prob = np.empty(n_states)
        self._prior = np.empty(n_states)
        self._alpha = np.empty(n_states)
        # Two product buffers: "work" receives the new sample, "accepted" holds the conditional
        # means of the last accepted sample (needed for the std of a held estimate).
        self._work = self._product_buffer(weights.shape[1], n_whitened)
        self._accepted = self._product_buffer(weights.shape[1], n_whitened)
        self._set_prior(model)
        self.reset()

    def _set_prior(self, model):
        """The estimate and std before any accepted sample: the prior mixture of ``model``."""
        mean, std = model.prior_output()
        if self._scalar_output:
            self._prior_estimate, self._prior_std = float(mean[0]), float(std[0])
        else:
            self._prior_estimate, self._prior_std = mean, std

    def _product_buffer(self, width, n_whitened, product=None):
        product = np.empty(width) if product is None else product
        means = product[n_whitened:].reshape(self._n_states, self._n_outputs)
        return product, product[:n_whitened], means[:, 0] if self._scalar_output else means

    def __setstate__(self, state):
        """Unpickle, then link the buffer views again (pickling copies every view)."""
        super().__setstate__(state)
        n_inputs, n_whitened = self._z.shape[0] - 1, self._squares.shape[0] - 1
        # a stream pickled before pipelines streamed reads the regressor's rows
        self.__dict__.setdefault("_stages", ())
        self.__dict__.setdefault("_row_shape", (n_inputs,))
        # a stream pickled before the smoothed read-out reads the GMR estimate
        self.__dict__.setdefault("_smoothed", False)
        self.__dict__.setdefault("_decay", np.zeros(self._output_center.shape[0]))
        self.__dict__.setdefault("_decay_0", 0.0)
        self._z_inputs, self._squares_head = self._z[:n_inputs], self._squares[:n_whitened]
        width = self._weights.shape[1]
        self._work = self._product_buffer(width, n_whitened, self._work[0])
        self._accepted = self._product_buffer(width, n_whitened, self._accepted[0])
        if self._online is not None:
            self._online.bias = self._weights[n_inputs]

    def reset(self):
        """Restart the filter at the beginning of a new recording.

        Returns
        -------
        self : FilterStream
        """
        if self._online is not None and self._online.n_learned:
            self._set_prior(self._online.fitted_model())
        self._prior[:] = self._startprob
        self._alpha[:] = self._startprob
        self._started = False
        self._last_estimate = self._prior_estimate
        self.last_flag_ = FLAG_OK
        self.n_samples_ = 0
        self.recording_ = None
        if self._carried is not None:
            self._carried.reset()
        for stage in self._stages:
            stage.reset()
        return self

    def reset_adaptation(self):
        """Forget the learned samples: the stream reads the fitted model again.

        Returns
        -------
        self : FilterStream
        """
        if self._online is not None and self._online.n_learned:
            self._online.clear()
            self._set_prior(self._model)
            if not self._started:
                self._last_estimate = self._prior_estimate
        return self

    def adapted_model(self):
        """The model with the adapted state means, a :class:`~skhmmgmr.FittedHMMGMR`.

        The fitted model when nothing was learned (or ``relevance=None``). Make an estimator
        of it with :meth:`HMMGMRRegressor.from_fitted_model
        <skhmmgmr.HMMGMRRegressor.from_fitted_model>`: it exports and pickles as any.
        """
        return self._model if self._online is None else self._online.fitted_model()

    @property
    def state_proba_(self):
        """Filtered state probabilities after the last accepted sample, shape (n_states,).

        Before any accepted sample of a recording they are the start probabilities.
        """
        return self._alpha.copy()

    @property
    def held_(self):
        """Whether the last update was held (non-finite or outlier sample)."""
        return self.last_flag_ in _HELD_FLAGS

    def update(self, features, return_std=False, return_flag=False, *, target=None):
        """Filter one sample and return the estimate of the outputs.

        Parameters
        ----------
        features : array-like of shape (n_features,) or mapping
            One sample (for a Pipeline: the sensed row, before the derived inputs). A dict or
            :class:`pandas.Series` keyed by feature name is accepted when the model was fitted
            on named columns.
        return_std : bool, default=False
            Also return the predictive standard deviation.
        return_flag : bool, default=False
            Also return :attr:`last_flag_`.
        target : float or array-like of shape (n_outputs,), default=None
            The measured outputs of this sample, learned after the estimate (only with
            ``relevance``; a NaN target is not learned).

        Returns
        -------
        estimate : float, or ndarray of shape (n_outputs,) for a multi-output model
        std : float or ndarray, only when ``return_std`` is True
        flag : str, only when ``return_flag`` is True
        """
        if type(features) is np.ndarray and features.shape == self._row_shape:
            row = features
        else:
            row = as_row(features, getattr(self, "feature_names_in_", None), self.n_features_in_)
        if target is not None:
            target = self._read_target(target)  # checked before the sample is consumed
        if self._stages:
            row = self._derive(row)
        np.subtract(row, self._input_center, out=self._z_inputs)
        np.divide(self._z_inputs, self._input_scale, out=self._z_inputs)
        estimate = self._step()
        if target is not None:
            self._learn(target)
        if not (return_std or return_flag):
            return estimate
        result = (estimate,)
        if return_std:
            result += (self._std(),)
        if return_flag:
            result += (self.last_flag_,)
        return result

    def _derive(self, row):
        """The sensed row followed by the derived inputs, in the preallocated row."""
        values = row.tolist()
        for stage in self._stages:
            stage.append(values)
        self._derived_row[:] = values
        return self._derived_row

    def _step(self):
        """Advance the filter with the standardised sample in ``self._z``."""
        self.n_samples_ += 1
        if self._carried is not None:
            self._carried.observe(self._z_inputs, self.n_samples_)
        z_list = self._z_inputs.tolist()
        product, whitened, means = self._work
        # NaN and infinity propagate into the sum; huge inputs would overflow the squares.
        if sum(map(abs, z_list)) < _MAX_STANDARDISED:
            np.dot(self._z, self._weights, out=product)
            np.multiply(whitened, whitened, out=self._squares_head)
            log_prob = self._log_prob
            np.dot(self._squares, self._block_sum, out=log_prob)
            log_prob_list = log_prob.tolist()
            top = max(log_prob_list)
            if not (top >= self.min_log_density and math.isfinite(sum(log_prob_list))):
                return self._hold(FLAG_OUTLIER)
            # Densities relative to the best state, as predict does: the largest is exactly 1.
            np.subtract(log_prob, top, out=log_prob)
            frames, flag, self._added = np.exp(log_prob, out=log_prob), FLAG_OK, None
        else:
            all_finite = all(map(math.isfinite, z_list))
            if all_finite or not self._marginalize or any(map(math.isinf, z_list)):
                return self._hold(FLAG_OUTLIER if all_finite else FLAG_NON_FINITE)
            frames, flag = self._missing_frames(means), FLAG_MISSING
            if frames is None:
                return self._hold(FLAG_OUTLIER)
        alpha = self._alpha
        np.multiply(self._prior, frames, out=alpha)
        total = sum(alpha.tolist())
        if total > 0.0:
            self.last_flag_ = flag
        else:
            alpha[:] = frames
            total = sum(frames.tolist())
            self.last_flag_ = FLAG_RESTARTED
        np.multiply(alpha, 1.0 / total, out=alpha)
        np.dot(self._transmat_t, alpha, out=self._prior)
        self._work, self._accepted = self._accepted, self._work
        smooth, self._started = self._smoothed and self._started, True
        if self._scalar_output:
            estimate = float(np.dot(alpha, means)) * self._scale_0 + self._center_0
            if smooth:
                decay = self._decay_0
                estimate = (1.0 - decay) * estimate + decay * self._last_estimate
            self._last_estimate = estimate
        else:
            estimate = np.dot(alpha, means) * self._output_scale + self._output_center
            if smooth:
                estimate = (1.0 - self._decay) * estimate + self._decay * self._last_estimate
            self._last_estimate = estimate.copy()
        return estimate

    def _check_learns(self):
        if self._online is None:
            raise ValueError("a target is learned only by a stream with relevance set")

    def _read_target(self, target):
        """The measured outputs of one sample as a float (one output) or an array of shape
        (n_outputs,); ValueError naming ``target`` for anything else."""
        self._check_learns()
        if (
            self._scalar_output
            and isinstance(target, numbers.Real)
            and not isinstance(target, (bool, np.bool_))
        ):
            return float(target)
        try:
            values = np.asarray(target, dtype=float)
        except (TypeError, ValueError):
            values = None
        if (
            values is None
            or values.ndim > 1
            or values.size != self._n_outputs
            or (isinstance(target, (bool, np.bool_)))
        ):
            raise ValueError(
                f"target must be the {self._n_outputs} measured output(s) of the sample "
                f"(NaN if unknown), got {target!r:.100}"
            )
        return float(values[0]) if self._scalar_output else values.reshape(self._n_outputs)

    def _read_targets(self, y, n_samples):
        """The measured outputs of a batch, shape (n_samples,) or (n_samples, n_outputs);
        ValueError naming ``y`` for anything else."""
        self._check_learns()
        try:
            values = np.asarray(y, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"y must hold numbers (NaN if unknown): {exc}") from None
        expected = (n_samples,) if self._scalar_output else (n_samples, self._n_outputs)
        if self._scalar_output and values.shape == (n_samples, 1):
            values = values[:, 0]
        if values.shape != expected:
            raise ValueError(
                f"y has shape {values.shape}; the batch of {n_samples} rows of a model with "
                f"{self._n_outputs} output(s) needs shape {expected}"
            )
        return values

    def _learn(self, target):
        """Learn the measured outputs of the last sample (see the Notes)."""
        if self.last_flag_ in _LEARNED_FLAGS:
            self._online.learn_target(self._alpha, self._z_inputs, target)

    def _missing_frames(self, means):
        """Scaled input densities of a sample whose NaN inputs are missing, given its observed
        inputs (None for an outlier); writes the state output means given them into ``means``
        and the variances they add to the conditional ones into ``self._added``."""
        missing = np.isnan(self._z_inputs)
        z = np.where(missing, 0.0, self._z_inputs)[np.newaxis]
        if not np.sum(np.abs(z)) < _MAX_STANDARDISED:
            return None
        params = self._gmr if self._online is None else self._online.gmr()
        stale = None if self._carried is None else self._carried.read(missing, self.n_samples_)
        log_prob, state_means, added = gmr_given_observed(params, z, missing[np.newaxis], stale)
        log_prob = log_prob[0]
        top = log_prob.max()
        if not (missing.all() or top >= self.min_log_density and np.isfinite(log_prob).all()):
            return None
        means[:] = state_means[0, :, 0] if self._scalar_output else state_means[0]
        self._added = added[0]
        return np.exp(log_prob - top)

    def _hold(self, flag):
        self.last_flag_ = flag
        estimate = self._last_estimate
        return estimate if self._scalar_output else estimate.copy()

    def _std(self):
        """Predictive std at the last accepted sample (law of total variance)."""
        if not self._started:
            std = self._prior_std
            return std if self._scalar_output else std.copy()
        means = self._accepted[2]
        if self._scalar_output:
            means = means[:, np.newaxis]
        alpha = self._alpha
        estimate = alpha @ means
        spread = means - estimate
        variance = alpha @ self._conditional_variances + alpha @ (spread * spread)
        if self._added is not None:
            variance += alpha @ self._added
        std = np.sqrt(variance) * self._output_scale
        return float(std[0]) if self._scalar_output else std

    def update_batch(self, X, return_std=False, return_flag=False, *, y=None):
        """Filter several consecutive samples, carrying the filter state on.

        Equivalent to calling :meth:`update` on every row in turn. A DataFrame whose index
        has a ``"recording"`` level (see :func:`skhmmgmr.datasets.to_panel`) restarts the
        filter (:meth:`reset`) wherever the recording changes, also from the last row of the
        previous batch (``recording_``), and is filtered in time order when the index has a
        ``"time"`` level; the results come back in the caller's row order.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            Consecutive samples (for a Pipeline: sensed rows); a DataFrame's columns are
            selected by feature name when the model was fitted on named columns.
        return_std : bool, default=False
            Also return the predictive standard deviations.
        return_flag : bool, default=False
            Also return the flag of every sample.
        y : array-like of shape (n_samples,) or (n_samples, n_outputs), default=None
            The measured outputs, learned after every estimate (only with ``relevance``).

        Returns
        -------
        estimates : ndarray of shape (n_samples,) or (n_samples, n_outputs)
        std : ndarray of the same shape, only when ``return_std`` is True
        flags : ndarray of str of shape (n_samples,), only when ``return_flag`` is True
        """
        rows = read_layout(X)
        y = align_target(X, y, rows)
        names = getattr(self, "feature_names_in_", None)
        X = as_batch(rows.to_filter_order(X), names, self.n_features_in_)
        if y is not None:
            y = self._read_targets(rows.to_filter_order(y), X.shape[0])
        for stage in self._stages:  # a time level at another period than the filter's
            stage.check_time(rows.time, rows.groups)
        restarts = self._recording_starts(rows.groups, X.shape[0])
        shape = (X.shape[0],) if self._scalar_output else (X.shape[0], self._n_outputs)
        estimates = np.empty(shape)
        std = np.empty(shape) if return_std else None
        flags = np.empty(X.shape[0], dtype=object) if return_flag else None
        z_inputs = self._z_inputs
        for i, row in enumerate(X):
            if i in restarts:
                self.reset().recording_ = restarts[i]
            if self._stages:
                row = self._derive(row)
            np.subtract(row, self._input_center, out=z_inputs)
            np.divide(z_inputs, self._input_scale, out=z_inputs)
            estimates[i] = self._step()
            if y is not None:
                self._learn(y[i])
            if return_std:
                std[i] = self._std()
            if return_flag:
                flags[i] = self.last_flag_
        result = tuple(rows.to_caller_order(a) for a in (estimates, std, flags) if a is not None)
        return result if len(result) > 1 else result[0]

    def _recording_starts(self, groups, n_samples):
        """{row: recording id} of the rows where a recording of an indexed batch begins."""
        if groups is None or n_samples == 0:
            return {}
        recordings = recordings_of(groups, n_samples)
        starts = {
            int(start): rec for rec, start in zip(recordings.ids, recordings.starts, strict=True)
        }
        if self.recording_ is not None and recordings.ids[0] == self.recording_:
            del starts[0]  # the batch goes on with the recording of the previous batch
        return starts
