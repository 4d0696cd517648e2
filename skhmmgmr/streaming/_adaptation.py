"""Online MAP adaptation of the state means of a :class:`~skhmmgmr.FilterStream`.

The recursive form of the means rule of :meth:`HMMGMRRegressor.adapt
<skhmmgmr.HMMGMRRegressor.adapt>` (parameters "m"). Every sample whose target is known adds
its filtered state probabilities ``alpha_t`` (the stream's, from the inputs up to ``t``) and
its standardised joint row ``x_t = [z_t, y_t]`` to decayed sufficient statistics, with a
forgetting factor ``lambda`` in (0, 1]::

    n_k <- lambda n_k + alpha_tk
    c_k <- lambda c_k + alpha_tk (x_t - mu0_k)
    mu_k = mu0_k + c_k / (n_k + r)  =  (sum_t lambda^(T-t) alpha_tk x_t + r mu0_k) / (n_k + r)

about the fitted means ``mu0`` (the fixed prior) with the relevance factor ``r``. With
``lambda = 1`` this is the batch rule with filtered instead of smoothed (and input-only instead
of joint) state probabilities, in one pass; ``lambda < 1`` forgets old rows (memory of about
``1 / (1 - lambda)`` rows) so that the model follows a driver who changes.

The stream's read-out depends on the means only through the constant row of its stacked
weight matrix (the offsets ``-P_k^T mu_k^F`` of the gating density's quadratic terms and the
GMR intercepts ``mu_k^T - coef_k mu_k^F``): it is affine in the means, so an update rewrites
that row as its fitted value plus ``vec(mu - mu0) @ J`` with a Jacobian ``J`` precomputed at
construction. The cost per update is a few small NumPy calls, independent of the number of
samples seen; the covariances, hence the precision factors and regression slopes, stay fixed.
"""

import math

import numpy as np

from .._core._validation import check_adaptation_params
from .._hmm._fitted import FittedHMMGMR
from .._hmm._gmr import condition_on_inputs


def check_adaptation(relevance, forgetting):
    """Validated ``(relevance, forgetting)``; ``relevance=None`` disables adaptation."""
    if isinstance(relevance, str) and relevance == "auto":
        raise ValueError(
            "FilterStream takes no relevance='auto': adapt's choice scores every strength on "
            "later rows of the recordings, which a stream has not seen yet. Adapt the model to "
            "recorded minutes with adapt() (relevance='auto' by default) and stream the "
            "adapted model, or give the stream a number."
        )
    if relevance is None:
        check_adaptation_params("FilterStream", forgetting=forgetting)
    else:
        check_adaptation_params("FilterStream", relevance=relevance, forgetting=forgetting)
    return relevance, float(forgetting)


class OnlineMeans:
    """Decayed MAP statistics of the state means and the stream weight row they set.

    Parameters
    ----------
    model : FittedHMMGMR
        The fitted model (the prior).
    bias : ndarray of shape (n_weights,)
        The constant row of the stream's stacked weights (a view: rewritten in place).
    n_terms : int
        Number of gating-density columns at the start of that row.
    relevance : float
    forgetting : float
    """

    def __init__(self, model, bias, n_terms, relevance, forgetting):
        emissions, params = model.emissions, model.gmr
        self.model = model
        self.scalar = model.scalar_output
        self.center = float(model.standardization.output_center[0])
        self.scale = float(model.standardization.output_scale[0])
        self.relevance, self.forgetting = float(relevance), float(forgetting)
        self.prior_means = np.array(emissions.means)
        n_states, n_dims = self.prior_means.shape
        n_outputs, n_inputs = params.coef.shape[1:]
        self.n_inputs = n_inputs
        self.bias, self.fitted_bias = bias, bias.copy()
        # d(bias)/d(mu_k): gating offsets -P_k^T (linear part of the density factors) and
        # intercepts (identity on the output means, -coef_k on the input means).
        linear = params.gating.density().factors[:, :n_inputs]
        per_state = n_terms // n_states
        jacobian = np.zeros((n_states, n_dims, bias.shape[0]))
        for k in range(n_states):
            terms = slice(k * per_state, (k + 1) * per_state)
            outputs = slice(n_terms + k * n_outputs, n_terms + (k + 1) * n_outputs)
            jacobian[k, :n_inputs, terms] = -linear[terms].T
            jacobian[k, :n_inputs, outputs] = -params.coef[k].T
            jacobian[k, n_inputs:, outputs] = np.eye(n_outputs)
        self.jacobian = jacobian.reshape(n_states * n_dims, -1)
        self.counts = np.zeros(n_states)
        self.centred = np.zeros((n_states, n_dims))  # decayed sums of alpha_tk (x_t - mu0_k)
        self._row = np.empty(n_dims)
        self._moves = np.empty((n_states, n_dims))
        self._moves_flat = self._moves.reshape(-1)
        self._denominator = np.empty((n_states, 1))
        self.n_learned = 0

    def __setstate__(self, state):
        """Unpickle (or deep-copy), then link the flat view of the moves again: pickling copies
        a view into an array of its own, which the updates would then no longer reach. The
        owner links ``bias`` to its weights again."""
        self.__dict__.update(state)
        self._moves_flat = self._moves.reshape(-1)

    def learn_target(self, alpha, inputs, target):
        """Learn a sample from its measured outputs in data units (a NaN one is skipped)."""
        scaling = self.model.standardization
        if self.scalar and not isinstance(target, np.ndarray):
            outputs = (float(target) - self.center) / self.scale
            if math.isfinite(outputs):
                self.learn(alpha, inputs, outputs)
            return
        target = np.asarray(target, dtype=float).reshape(scaling.n_outputs)
        if np.isfinite(target).all():
            self.learn(alpha, inputs, (target - scaling.output_center) / scaling.output_scale)

    def learn(self, alpha, inputs, outputs):
        """Add one sample (state probabilities, standardised inputs and outputs)."""
        row, moves = self._row, self._moves
        row[: self.n_inputs] = inputs
        row[self.n_inputs :] = outputs
        np.subtract(row, self.prior_means, out=moves)
        moves *= alpha[:, np.newaxis]
        if self.forgetting != 1.0:
            self.counts *= self.forgetting
            self.centred *= self.forgetting
        self.counts += alpha
        self.centred += moves
        np.add(self.counts[:, np.newaxis], self.relevance, out=self._denominator)
        np.divide(self.centred, self._denominator, out=moves)
        np.dot(self._moves_flat, self.jacobian, out=self.bias)
        self.bias += self.fitted_bias
        self.n_learned += 1

    def means(self):
        """Adapted state means (standardised units), shape (n_states, n_dims)."""
        return self.prior_means + self.centred / (self.counts + self.relevance)[:, np.newaxis]

    def clear(self):
        """Forget every learned sample: the fitted means again."""
        self.counts[:] = 0.0
        self.centred[:] = 0.0
        self.bias[:] = self.fitted_bias
        self.n_learned = 0

    def fitted_model(self):
        """The adapted model as a :class:`~skhmmgmr.FittedHMMGMR` (the fitted one before any
        learned sample)."""
        model = self.model
        if self.n_learned == 0:
            return model
        return FittedHMMGMR.from_standardized(
            model.startprob,
            model.transmat,
            model.emissions.with_means(self.means()),
            model.standardization,
            scalar_output=model.scalar_output,
            feature_names=model.feature_names,
            stale_noise=model.stale_noise,
            output_decay=model.output_decay,
        )

    def gmr(self):
        """GMR read-out of the adapted means (standardised units), for samples with missing
        inputs."""
        model = self.model
        emissions = model.emissions.with_means(self.means())
        return condition_on_inputs(model.startprob, model.transmat, emissions, model.n_inputs)
