"""Sample-by-sample causal GMR filter for real-time use (one update per control cycle).

The stream runs the same normalised forward recursion and Gaussian Mixture Regression as
:meth:`HMMGMRRegressor.predict <skhmmgmr.HMMGMRRegressor.predict>` (METHOD.md section 2), one
sample at a time, with the filter state carried between calls, and holds the samples the
outlier policy holds (:mod:`skhmmgmr._hmm._holds`, the one ``predict`` and the generated C
follow). Everything that does not depend on the sample is precomputed at construction and
every intermediate result lives in a preallocated buffer, so that an update is a handful of
small NumPy calls on fixed buffers: ``[z, 1]`` times one stacked matrix, then the squared
terms times a block-sum matrix (:mod:`skhmmgmr.streaming._products`).

The stream reads a :class:`~skhmmgmr.FittedHMMGMR` (an estimator's ``model_``): the gating
density, the regressions and the standardisation are that object's. A sample with missing
inputs (NaN, when they are marginalised) takes a slower path: the Gaussians of every state
conditioned on its observed inputs (:func:`~skhmmgmr._hmm._missing.gmr_given_observed`).

A fitted Pipeline of ``SteeringFeatures`` steps and the regressor streams the sensed rows: the
derived inputs are computed first, one scalar operation at a time, into a preallocated row
(:mod:`skhmmgmr.streaming._derived`), which then goes the regressor's way.
"""

import math

import numpy as np

from .._core._pickled import PickleVersionMixin
from .._hmm._holds import MAX_STANDARDISED
from .._hmm._stale_inputs import carried_inputs
from ._adaptation import OnlineMeans, check_adaptation
from ._batch import read_batch
from ._flags import (
    FLAG_MISSING,
    FLAG_NON_FINITE,
    FLAG_OK,
    FLAG_OUTLIER,
    FLAG_RESTARTED,
    HELD_FLAGS,
    LEARNED_FLAGS,
)
from ._inputs import as_row
from ._missing import observed_frames
from ._products import product_buffer, stacked_weights
from ._source import read_streamed
from ._targets import read_target, read_targets


class FilterStream(PickleVersionMixin):
    """Causal HMM-GMR filter of a fitted :class:`~skhmmgmr.HMMGMRRegressor`, one sample a call.

    Streaming a recording sample by sample gives the estimates of ``model.predict`` on the whole
    recording (up to round-off), held samples included: both follow one outlier policy (see
    Notes). The stream copies the model's parameters when it is created: refitting the model
    later does not change it.

    Parameters
    ----------
    model : FittedHMMGMR, HMMGMRRegressor or Pipeline
        A fitted model, or a fitted estimator (its ``model_`` is read), or a fitted Pipeline of
        :class:`~skhmmgmr.SteeringFeatures` steps ending in an ``HMMGMRRegressor``
        (:func:`~skhmmgmr.make_torque_pipeline`'s, or any scikit-learn ``Pipeline`` of those
        steps), which then takes the sensed rows (see Notes). Usually created with
        ``estimator.filter_stream()`` or ``pipeline.filter_stream()``.
    min_log_density : float, default=None
        The outlier policy's threshold (see Notes): a sample whose input log-density, in the
        standardised units the model works in, is below it in every state is held. ``None``:
        the estimator's ``min_log_density`` when ``model`` is an estimator (the regressor's,
        for a Pipeline), which ``predict`` and the generated C follow too; no sample is held
        by its density for a :class:`~skhmmgmr.FittedHMMGMR`. Give another value only to try
        one out: ``predict`` keeps the estimator's.
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
        ``None``: no adaptation, the stream is the fitted model's. Not "auto": ``adapt``
        chooses its strength on later rows of the recordings, which a stream has not seen
        yet; adapt on recorded minutes and stream the adapted model instead.
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
    The forward step works in log space (the densities relative to the best state's), so that a
    sample far from every state is filtered as ``predict`` filters it. Samples the filter
    cannot or should not use are *held*: the update returns the last accepted estimate (or,
    before any accepted sample, the prior-mixture estimate ``sum_k pi_k mu_k^T`` and its
    standard deviation), sets :attr:`held_`, and leaves the filter state unchanged, so the
    estimates that follow equal those of a stream that never saw the held sample. Two kinds
    of sample are held (the outlier policy of :mod:`skhmmgmr._hmm._holds`):

    - ``"non-finite"``: an infinite input (a derived input that overflows, as the cube of a
      load of 1e200, included), or a NaN one unless missing values are missing values
      (``missing_values="marginalize"`` or ``"carry_forward"``: the sample is then filtered
      on its observed inputs, and a sample with none passes the state probabilities through
      the transition matrix). ``predict`` refuses such a sample, naming it;
    - ``"outlier"``: finite inputs out of the model's range (standardised inputs whose
      absolute values sum to 1e100 or more, where the squares of the density terms would
      overflow), which ``predict`` refuses too; and, only when ``min_log_density`` is set,
      a sample whose input log-densities are all below it, which ``predict`` holds too.

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
        min_log_density=None,
        missing_values=None,
        relevance=None,
        forgetting=1.0,
    ):
        streamed = read_streamed(
            model, missing_values=missing_values, min_log_density=min_log_density
        )
        model, self._stages = streamed.model, streamed.stages
        self.min_log_density = streamed.min_log_density
        # the outlier policy's threshold: -inf holds no sample by its density
        self._threshold = -math.inf if self.min_log_density is None else self.min_log_density
        self.missing_values = streamed.missing_values
        self._marginalize = self.missing_values != "error"
        self.relevance, self.forgetting = check_adaptation(relevance, forgetting)
        self._model = model
        self._carried = carried_inputs(model, self.missing_values)
        params, scaling = model.gmr, model.standardization
        n_states, n_outputs, n_inputs = params.coef.shape
        self.n_features_in_, names = streamed.n_features, streamed.names
        if self._stages:
            # the sensed row followed by every step's derived inputs, as the regressor reads it
            self._derived_row = np.empty(n_inputs)
        self._row_shape = (self.n_features_in_,)
        if names is not None:
            self.feature_names_in_ = np.asarray(names, dtype=object)
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

        weights, self._block_sum, n_whitened = stacked_weights(params)
        self._weights = weights
        self._online = None
        if relevance is not None:  # rewrites the constant row of the weights in place
            self._online = OnlineMeans(model, weights[n_inputs], n_whitened, relevance, forgetting)

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
        shape = (self._n_states, self._n_outputs, self._scalar_output)
        return product_buffer(width, n_whitened, *shape, product)

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
        # a stream pickled before the outlier policy kept its own threshold
        self.__dict__.setdefault("_threshold", self.min_log_density)
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
        return self.last_flag_ in HELD_FLAGS

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
        if (
            type(features) is np.ndarray
            and features.shape == self._row_shape
            and features.dtype.kind == "f"
        ):
            row = features
        else:
            row = as_row(features, getattr(self, "feature_names_in_", None), self.n_features_in_)
        if target is not None:  # checked before the sample is consumed
            self._check_learns()
            target = read_target(target, self._n_outputs, self._scalar_output)
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
        if sum(map(abs, z_list)) < MAX_STANDARDISED:
            np.dot(self._z, self._weights, out=product)
            np.multiply(whitened, whitened, out=self._squares_head)
            log_prob = self._log_prob
            np.dot(self._squares, self._block_sum, out=log_prob)
            log_prob_list = log_prob.tolist()
            top = max(log_prob_list)
            # below the threshold, or out of range: no finite density (or a NaN one)
            if not (
                top >= self._threshold and top > -math.inf and not math.isnan(sum(log_prob_list))
            ):
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

    def _learn(self, target):
        """Learn the measured outputs of the last sample (see the Notes)."""
        if self.last_flag_ in LEARNED_FLAGS:
            self._online.learn_target(self._alpha, self._z_inputs, target)

    def _missing_frames(self, means):
        """Scaled input densities of a sample whose NaN inputs are missing, given its observed
        inputs (None when held); writes the state output means given them into ``means``
        and the variances they add to the conditional ones into ``self._added``."""
        params = self._gmr if self._online is None else self._online.gmr()
        stale = None
        if self._carried is not None:
            stale = self._carried.read(np.isnan(self._z_inputs), self.n_samples_)
        observed = observed_frames(params, self._z_inputs, self._threshold, stale)
        if observed is None:
            return None
        frames, state_means, self._added = observed
        means[:] = state_means[:, 0] if self._scalar_output else state_means
        return frames

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
        if y is not None:
            self._check_learns()
        batch = read_batch(
            X,
            y,
            names=getattr(self, "feature_names_in_", None),
            n_features=self.n_features_in_,
            stages=self._stages,
            current=self.recording_,
            read_targets=lambda y, n: read_targets(y, n, self._n_outputs, self._scalar_output),
        )
        X, y, restarts = batch.X, batch.y, batch.restarts
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
        result = (estimates, std, flags)
        result = tuple(batch.rows.to_caller_order(a) for a in result if a is not None)
        return result if len(result) > 1 else result[0]
