"""Emission models: everything that depends on the form of the state densities.

The EM engine (:mod:`skhmmgmr._hmm._em`), the GMR filter (:mod:`skhmmgmr._hmm._gmr`),
:class:`~skhmmgmr.FilterStream`, the portable JSON format and the estimator ask an emission
object; none of them does Gaussian algebra itself. An emission model provides

- the emission likelihoods of a block of rows, scaled to a maximum of one per row
  (:meth:`GaussianEmissions.density`), also over a subset of the columns
  (:meth:`GaussianEmissions.marginal`);
- the M-step from the sufficient statistics (:class:`MomentStatistics`: weighted moments of
  the columns, accumulated chunk by chunk and merged by addition), with a prior
  (:class:`CovariancePrior`) whose log-density EM adds to the log-likelihood;
- the initialisation from hard or soft responsibilities (:meth:`GaussianEmissions.from_moments`);
- the number of free parameters (information criteria);
- the GMR read-out: the gating density on the inputs and the conditional mean and covariance of
  the outputs given the inputs (:meth:`GaussianEmissions.condition`);
- MAP adaptation with the model as the prior (:meth:`GaussianEmissions.map_adapted`, after
  Reynolds, Quatieri and Dunn, 2000) and the same model over other means
  (:meth:`GaussianEmissions.with_means`, the stream's adapted model);
- what conditioning on the observed columns of a row needs (missing inputs): the precision
  matrices, their product with deviations from the means, the squared Mahalanobis distances
  and ``1/2 log det`` of the precisions, and the whitening matrices the portable filter block
  stores;
- every state's covariance matrix or variances (the read-outs that mix them, ``covars_``);
- its change of units (:meth:`GaussianEmissions.rescaled`) and its exchange forms: the
  ``joint`` block of the portable JSON file (:meth:`GaussianEmissions.portable_joint`,
  :meth:`GaussianEmissions.from_state_covariances`) and hmmlearn's ``covars_``
  (:meth:`GaussianEmissions.hmmlearn_covars`).

No other module compares ``covariance_type`` with a family's name or reads the covariance or
precision fields (``tests/test_package_boundaries.py`` checks it): a new family changes this
module only.

Two families are implemented: ``"full"`` (one full covariance per state) and ``"tied"`` (one
full covariance shared by all states, as in :class:`sklearn.mixture.GaussianMixture`: the
regression slope is shared and the intercepts differ by state). ``"diag"`` and ``"spherical"``
are refused (:data:`REFUSED_COVARIANCE_TYPES`).
"""

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from scipy import linalg

from ._gaussian import (
    augmented_columns,
    compute_precision_cholesky,
    gaussians_from_moments,
    log_det_cholesky,
    stack_gaussians,
)
from ._kernels import scaled_densities

# A state whose expected number of rows falls below this keeps its previous emission
# parameters: less than one row of posterior mass cannot define a Gaussian, and keeping the
# state's parameters (instead of re-seeding it) keeps the objective non-decreasing.
MIN_STATE_WEIGHT = 1.0

REFUSED_COVARIANCE_TYPES = {
    "diag": "within a state the outputs would not depend on the inputs",
    "spherical": "within a state the outputs would not depend on the inputs",
}


@dataclass
class MomentStatistics:
    """Sufficient statistics of the Gaussian family: weighted moments about ``shift``.

    ``weights[k] = sum_t r_tk``, ``first[k] = sum_t r_tk (x_t - shift)`` and
    ``second[k] = sum_t r_tk (x_t - shift)(x_t - shift)^T``. Statistics of disjoint sets of
    rows (other chunks, other workers) about the same shift add up (:meth:`merge`).
    """

    weights: np.ndarray
    first: np.ndarray
    second: np.ndarray
    shift: np.ndarray

    def merge(self, other):
        """Statistics of the rows of both (same shift)."""
        if not np.array_equal(self.shift, other.shift):
            raise ValueError("statistics about different shift points cannot be merged")
        return MomentStatistics(
            self.weights + other.weights,
            self.first + other.first,
            self.second + other.second,
            self.shift,
        )

    def scatter_about(self, means):
        """``sum_t r_tk (x_t - m_k)(x_t - m_k)^T`` about given means (absolute units)."""
        offsets = means - self.shift
        cross = self.first[:, :, np.newaxis] * offsets[:, np.newaxis, :]
        outer = offsets[:, :, np.newaxis] * offsets[:, np.newaxis, :]
        scatter = self.second - cross - cross.transpose(0, 2, 1)
        scatter += self.weights[:, np.newaxis, np.newaxis] * outer
        return 0.5 * (scatter + scatter.transpose(0, 2, 1))


@dataclass(frozen=True)
class CovariancePrior:
    """Prior ``p(S) ∝ exp(-scale / 2 tr(S^-1))`` on every covariance matrix of an emission.

    The M-step is its exact maximiser, ``S = (scatter + scale I) / weight``; ``scale=0`` gives
    maximum likelihood. It is the M-step's prior hook: another prior provides the same two
    methods (see :meth:`GaussianEmissions.maximize`).
    """

    scale: float

    def covariance(self, scatter, weight):
        """The maximiser of ``-weight / 2 log det S - 1/2 tr((scatter + scale I) S^-1)``."""
        covariance = scatter / weight
        covariance.flat[:: covariance.shape[0] + 1] += self.scale / weight
        return covariance

    def log_density(self, precisions_chol):
        """``-scale / 2 sum tr(S^-1)`` over the given precision Cholesky factors (improper
        prior: no normalising constant)."""
        if self.scale == 0:
            return 0.0
        return -0.5 * self.scale * float(np.sum(np.square(precisions_chol)))


class GaussianDensity:
    """Emission likelihoods of augmented columns under every state (see
    :func:`~skhmmgmr._hmm._gaussian.stack_gaussians`)."""

    def __init__(self, means, precisions_chol, shift=None):
        self.n_states = means.shape[0]
        self.factors, self.norms = stack_gaussians(means, precisions_chol, shift)

    def frames(self, columns, frames, top):
        """Write the likelihoods of ``columns`` (augmented, one chunk) scaled to a maximum of
        one per row into ``frames`` (n_rows, n_states) and the logarithms of the scales into
        ``top`` (n_rows,)."""
        scaled_densities(self.factors @ columns, self.norms[:, 0], frames, top)

    def log_prob(self, X):
        """Log-densities of the rows of ``X``, shape (n_rows, n_states)."""
        projected = self.factors @ augmented_columns(np.asarray(X, dtype=float))
        np.square(projected, out=projected)
        half = projected.reshape(self.n_states, -1, projected.shape[1]).sum(axis=1)
        return (self.norms - half).T


class GaussianEmissions(ABC):
    """Gaussian state densities over ``n_dims`` columns; the base of both families.

    Parameters
    ----------
    means : ndarray of shape (n_states, n_dims)
    covariances : ndarray
        In the family's own shape (:attr:`covariance_shape`): (n_states, n_dims, n_dims)
        for "full", (n_dims, n_dims) for "tied".

    Attributes
    ----------
    means : ndarray of shape (n_states, n_dims)
    covariances : ndarray
        In the family's own shape.
    full_covariances : ndarray of shape (n_states, n_dims, n_dims)
        Every state's covariance (tied: the shared one, repeated).
    precisions_chol : ndarray of shape (n_states, n_dims, n_dims)
        Precision Cholesky factor of every state's covariance.
    """

    covariance_type = None

    def __init__(self, means, covariances):
        self.means = np.asarray(means, dtype=float)
        self.covariances = np.asarray(covariances, dtype=float)
        n_states, n_dims = self.means.shape
        if self.covariances.shape != self.covariance_shape(n_states, n_dims):
            raise ValueError(
                f"{self.covariance_type!r} covariances of {n_states} states over {n_dims} "
                f"columns have shape {self.covariance_shape(n_states, n_dims)}, got "
                f"{self.covariances.shape}"
            )
        self.full_covariances = self._expand(self.covariances, n_states)
        self.precisions_chol = self._precisions_chol()

    @property
    def n_states(self):
        return self.means.shape[0]

    @property
    def n_dims(self):
        return self.means.shape[1]

    # -- family-specific parts ---------------------------------------------------------------
    @staticmethod
    @abstractmethod
    def covariance_shape(n_states, n_dims):
        """Shape of the family's own covariance array."""

    @staticmethod
    @abstractmethod
    def _expand(covariances, n_states):
        """Every state's full covariance from the family's own array."""

    def _precisions_chol(self):
        return compute_precision_cholesky(self.full_covariances)

    @abstractmethod
    def n_parameters(self):
        """Free parameters of the state densities (means and covariances)."""

    @classmethod
    @abstractmethod
    def prior_for(cls, reg_covar, n_samples, n_states):
        """The covariance prior of ``reg_covar``: the scatter of ``n_samples`` divided over
        the covariance matrices (an average share) rows of variance ``reg_covar``."""

    @abstractmethod
    def maximize(self, statistics, prior):
        """M-step: the maximiser of the expected complete-data log-likelihood plus the log
        prior, from ``statistics`` (:class:`MomentStatistics`).

        A state with less than :data:`MIN_STATE_WEIGHT` rows of posterior mass keeps its
        parameters (``self`` is the previous emission): its terms are then unchanged while
        the others are maximised (a generalised EM step).
        """

    @classmethod
    @abstractmethod
    def from_moments(cls, statistics, reg_covar, pooled=None):
        """Initial emission from the moments of initial responsibilities, ``reg_covar`` on
        the diagonal; ``pooled`` (moments of all rows, one state) stands in for states with
        too few rows for a covariance."""

    @abstractmethod
    def _with(self, means, full_covariances):
        """The same family over other means and (full) covariances."""

    @abstractmethod
    def _map_covariances(self, scatter, means, weights, relevance):
        """The MAP covariances (family shape, before symmetrising) of :meth:`map_adapted`."""

    @classmethod
    @abstractmethod
    def from_state_covariances(cls, means, covariances):
        """The family over ``means`` and every state's covariance (n_states, n_dims, n_dims),
        as the portable ``joint`` block and hmmlearn's ``covars_`` give them.

        Raises
        ------
        ValueError
            If the covariances do not have the family's form (tied: not all equal), with a
            message that reads after the name of the covariances.
        """

    # -- shared parts ------------------------------------------------------------------------
    def log_prior(self, prior):
        """Log-density of the prior at these parameters (each covariance matrix once)."""
        return prior.log_density(self._distinct_precisions_chol())

    def _distinct_precisions_chol(self):
        return self.precisions_chol

    def reordered(self, order):
        """The same emission with the states in ``order`` (a tied covariance stays shared)."""
        return self._with(self.means[order], self.full_covariances[order])

    @staticmethod
    def stacked(blocks, weights):
        """One emission of the states of every emission in ``blocks`` (same family), in
        order; a tied family shares the ``weights``-weighted mean of the blocks'
        covariances."""
        weights = np.asarray(weights, dtype=float) / np.sum(weights)
        means = np.vstack([block.means for block in blocks])
        full = np.concatenate([block.full_covariances for block in blocks])
        if isinstance(blocks[0], TiedCovariance):
            shared = sum(w * b.covariances for w, b in zip(weights, blocks, strict=True))
            return TiedCovariance(means, shared)
        return blocks[0]._with(means, full)

    def with_means(self, means):
        """The same covariances about other state ``means`` (n_states, n_dims)."""
        return type(self)(means, self.covariances)

    def frozen(self):
        """A copy whose means and covariances are read-only."""
        means, covariances = np.array(self.means), np.array(self.covariances)
        means.flags.writeable = covariances.flags.writeable = False
        return type(self)(means, covariances)

    def map_adapted(self, statistics, means, relevance, reg_covar=0.0):
        """MAP adaptation of the covariances with these parameters as the prior.

        GMM-UBM speaker adaptation (Reynolds, Quatieri and Dunn, 2000): with the E-step's
        ``statistics`` (:class:`MomentStatistics` of the new rows), the adapted state
        ``means`` and the relevance factor ``r``, every covariance moves from its prior value
        ``S0`` to ``S' = (scatter(mu') + r (S0 + (mu0 - mu')(mu0 - mu')^T)) / (n + r)`` (per
        state; tied: the scatters of all states plus ``r S0`` over ``N + r``), then
        ``reg_covar`` is added to its diagonal as fit's M-step does.

        Returns
        -------
        emissions : GaussianEmissions
            The same family over ``means`` and the adapted covariances.
        """
        scatter = statistics.scatter_about(means)
        covariances = self._map_covariances(scatter, means, statistics.weights, relevance)
        covariances = 0.5 * (covariances + np.swapaxes(covariances, -1, -2))
        diagonal = np.einsum("...ii->...i", covariances)  # a writeable view
        diagonal += reg_covar
        return type(self)(means, covariances)

    def state_covariances(self):
        """Every state's covariance matrix, shape (n_states, n_dims, n_dims) (tied: the
        shared one, repeated)."""
        return self.full_covariances

    def state_variances(self):
        """Every state's variances (the diagonals of its covariance), (n_states, n_dims)."""
        return np.diagonal(self.full_covariances, axis1=1, axis2=2)

    def whitening(self):
        """Every state's whitening matrix ``U_k`` (n_states, n_dims, n_dims): upper
        triangular, ``inv(S_k) = U_k U_k^T``, so that ``(x - mu_k) @ U_k`` has the identity
        covariance (the precision Cholesky factor the portable filter block stores)."""
        return self.precisions_chol

    def precisions(self):
        """Every state's precision matrix ``L_k = inv(S_k)``, (n_states, n_dims, n_dims)."""
        factors = self.precisions_chol
        return factors @ factors.transpose(0, 2, 1)

    def precision_times(self, deviations):
        """``L_k d`` of deviations ``d`` (n_states, n_rows, n_dims) from every state's mean:
        two batched products with the whitening matrices."""
        factors = self.precisions_chol
        return (deviations @ factors) @ factors.transpose(0, 2, 1)

    def mahalanobis(self, deviations):
        """Squared Mahalanobis distances ``d^T L_k d`` of deviations ``d`` (n_states,
        n_rows, n_dims) from every state's mean, shape (n_states, n_rows)."""
        return np.square(deviations @ self.precisions_chol).sum(axis=2)

    def half_log_det_precision(self):
        """``1/2 log det L_k = -1/2 log det S_k`` of every state, shape (n_states,)."""
        return np.log(np.diagonal(self.precisions_chol, axis1=1, axis2=2)).sum(axis=1)

    def portable_joint(self):
        """The ``joint`` block of the portable model file (:mod:`skhmmgmr.portable`):
        ``covariance_type``, ``means`` and every state's covariance (tied: repeated)."""
        return {
            "covariance_type": self.covariance_type,
            "means": self.means,
            "covariances": self.full_covariances,
        }

    def hmmlearn_covars(self):
        """The covariances as ``hmmlearn.hmm.GaussianHMM`` stores them (what its
        ``covars_`` setter takes): the family's own shape, a copy."""
        return np.array(self.covariances)

    def density(self, shift=None):
        """Evaluator of the scaled emission likelihoods (:class:`GaussianDensity`) of columns
        about ``shift``."""
        return GaussianDensity(self.means, self.precisions_chol, shift)

    def log_prob(self, X):
        """Log-density of every row of ``X`` (n_rows, n_dims) under every state."""
        return self.density().log_prob(X)

    def marginal(self, dims):
        """The densities of the columns ``dims`` alone (same family)."""
        dims = np.asarray(dims)
        return self._with(self.means[:, dims], self.full_covariances[:, dims][:, :, dims])

    def split(self, state, offset):
        """The densities with ``state`` split in two halves at ``mean -/+ offset`` (shape
        (n_dims,)), the new one last; a full covariance loses ``offset offset^T`` (an equal
        mixture of the halves keeps the state's moments; ``offset`` must keep it positive
        definite), the other families keep theirs."""
        offset = np.asarray(offset, dtype=float)
        means = np.vstack([self.means, self.means[state] + offset])
        means[state] = self.means[state] - offset
        full = np.concatenate([self.full_covariances, self.full_covariances[state : state + 1]])
        return self._with(means, self._split_covariances(full, state, offset))

    @staticmethod
    def _split_covariances(full, state, offset):
        """Covariances (n_states + 1, n_dims, n_dims) of :meth:`split` (``state``'s last)."""
        return full

    def rescaled(self, center, scale):
        """The densities of ``center + scale * x`` (a change of units of every column)."""
        return self._with(
            self.means * scale + center, self.full_covariances * np.outer(scale, scale)
        )

    def standardized(self, center, scale):
        """The densities of ``(x - center) / scale`` (inverse of :meth:`rescaled`)."""
        return self._with(
            (self.means - center) / scale, self.full_covariances / np.outer(scale, scale)
        )

    def condition(self, n_inputs):
        """GMR read-out: the first ``n_inputs`` columns are inputs, the others outputs.

        Returns
        -------
        gating : GaussianEmissions
            The input marginal (same family).
        coef : ndarray of shape (n_states, n_outputs, n_inputs)
        intercept : ndarray of shape (n_states, n_outputs)
            The conditional mean of the outputs is ``coef_k @ x + intercept_k``.
        conditional_covariances : ndarray of shape (n_states, n_outputs, n_outputs)
        """
        covariances = self.full_covariances
        n_outputs = self.n_dims - n_inputs
        coef = np.empty((self.n_states, n_outputs, n_inputs))
        conditional = np.empty((self.n_states, n_outputs, n_outputs))
        for k in range(self.n_states):
            s_ff = covariances[k, :n_inputs, :n_inputs]
            s_tf = covariances[k, n_inputs:, :n_inputs]
            coef[k] = linalg.solve(s_ff, s_tf.T, assume_a="pos").T
            conditional[k] = covariances[k, n_inputs:, n_inputs:] - coef[k] @ s_tf.T
            conditional[k] = 0.5 * (conditional[k] + conditional[k].T)
        intercept = self.means[:, n_inputs:] - np.einsum(
            "kof,kf->ko", coef, self.means[:, :n_inputs]
        )
        return self.marginal(np.arange(n_inputs)), coef, intercept, conditional

    def log_normalizers(self):
        """``log det(P_k) - n_dims / 2 log(2 pi)`` of every state."""
        return log_det_cholesky(self.precisions_chol) - 0.5 * self.n_dims * np.log(2 * np.pi)


class FullCovariance(GaussianEmissions):
    """One full covariance matrix per state (the thesis' model)."""

    covariance_type = "full"

    @staticmethod
    def covariance_shape(n_states, n_dims):
        return (n_states, n_dims, n_dims)

    @staticmethod
    def _expand(covariances, n_states):
        return covariances

    def n_parameters(self):
        n_states, n_dims = self.means.shape
        return n_states * n_dims + n_states * n_dims * (n_dims + 1) // 2

    @classmethod
    def prior_for(cls, reg_covar, n_samples, n_states):
        return CovariancePrior(float(reg_covar) * n_samples / n_states)

    def maximize(self, statistics, prior):
        weights = statistics.weights
        alive = weights >= MIN_STATE_WEIGHT
        means, covariances = self.means.copy(), self.covariances.copy()
        safe = np.where(alive, weights, 1.0)
        new_means = statistics.shift + statistics.first / safe[:, np.newaxis]
        scatter = statistics.scatter_about(new_means)
        for k in np.flatnonzero(alive):
            means[k] = new_means[k]
            covariances[k] = prior.covariance(scatter[k], weights[k])
        return FullCovariance(means, covariances)

    @classmethod
    def from_moments(cls, statistics, reg_covar, pooled=None):
        weights = statistics.weights
        means, covariances = gaussians_from_moments(
            np.maximum(weights, 1e-12),
            statistics.first,
            statistics.second,
            reg_covar,
            statistics.shift,
        )
        # A state with too few rows for a full covariance (or none at all) takes the pooled
        # covariance instead, so that EM starts from usable Gaussians.
        small = weights < statistics.first.shape[1] + 1
        if np.any(small) and pooled is not None:
            pooled_mean, pooled_covariance = gaussians_from_moments(
                pooled.weights, pooled.first, pooled.second, reg_covar, pooled.shift
            )
            covariances[small] = pooled_covariance[0]
            means[small & (weights < 1e-12)] = pooled_mean[0]
        return cls(means, covariances)

    def _with(self, means, full_covariances):
        return FullCovariance(means, full_covariances)

    @staticmethod
    def _split_covariances(full, state, offset):
        shrunk = full[state] - np.outer(offset, offset)
        full[state] = full[-1] = shrunk
        return full

    def _map_covariances(self, scatter, means, weights, relevance):
        moved = self.means - means
        prior_scatter = self.full_covariances + moved[:, :, np.newaxis] * moved[:, np.newaxis, :]
        return (scatter + relevance * prior_scatter) / (weights + relevance)[
            :, np.newaxis, np.newaxis
        ]

    @classmethod
    def from_state_covariances(cls, means, covariances):
        return cls(means, covariances)


class TiedCovariance(GaussianEmissions):
    """One full covariance matrix shared by all states."""

    covariance_type = "tied"

    @staticmethod
    def covariance_shape(n_states, n_dims):
        return (n_dims, n_dims)

    @staticmethod
    def _expand(covariances, n_states):
        return np.broadcast_to(covariances, (n_states, *covariances.shape))

    def _precisions_chol(self):
        shared = compute_precision_cholesky(self.covariances[np.newaxis])
        return np.broadcast_to(shared, (self.n_states, *self.covariances.shape))

    def _distinct_precisions_chol(self):
        return self.precisions_chol[:1]

    def n_parameters(self):
        n_states, n_dims = self.means.shape
        return n_states * n_dims + n_dims * (n_dims + 1) // 2

    @classmethod
    def prior_for(cls, reg_covar, n_samples, n_states):
        return CovariancePrior(float(reg_covar) * n_samples)

    def maximize(self, statistics, prior):
        weights = statistics.weights
        alive = weights >= MIN_STATE_WEIGHT
        safe = np.where(alive, weights, 1.0)
        means = np.where(
            alive[:, np.newaxis],
            statistics.shift + statistics.first / safe[:, np.newaxis],
            self.means,
        )
        # The shared covariance given every state's mean (a kept state about its kept mean).
        scatter = statistics.scatter_about(means).sum(axis=0)
        return TiedCovariance(means, prior.covariance(scatter, weights.sum()))

    @classmethod
    def from_moments(cls, statistics, reg_covar, pooled=None):
        weights = statistics.weights
        safe = np.maximum(weights, 1e-12)
        means = statistics.shift + statistics.first / safe[:, np.newaxis]
        if pooled is not None:
            means[weights < 1e-12] = pooled.shift + pooled.first[0] / pooled.weights[0]
        scatter = statistics.scatter_about(means).sum(axis=0)
        covariance = scatter / weights.sum()
        covariance.flat[:: covariance.shape[0] + 1] += reg_covar
        return cls(means, covariance)

    def _with(self, means, full_covariances):
        return TiedCovariance(means, full_covariances[0])

    def _map_covariances(self, scatter, means, weights, relevance):
        total = scatter.sum(axis=0) + relevance * self.covariances
        return total / (weights.sum() + relevance)

    @classmethod
    def from_state_covariances(cls, means, covariances):
        covariances = np.asarray(covariances, dtype=float)
        if not np.allclose(covariances, covariances[0], rtol=1e-12, atol=0):
            raise ValueError("must all be equal for covariance_type 'tied'")
        return cls(means, covariances[0])


EMISSION_FAMILIES = {"full": FullCovariance, "tied": TiedCovariance}


def emission_family(covariance_type):
    """The emission class of ``covariance_type``, or an error that says why not."""
    if covariance_type in REFUSED_COVARIANCE_TYPES:
        raise ValueError(
            f"covariance_type={covariance_type!r} is not supported: "
            f"{REFUSED_COVARIANCE_TYPES[covariance_type]}, so GMR would predict the state "
            "means only; use 'full' or 'tied'"
        )
    try:
        return EMISSION_FAMILIES[covariance_type]
    except KeyError:
        raise ValueError(
            f"covariance_type must be one of {sorted(EMISSION_FAMILIES)}, got {covariance_type!r}"
        ) from None


def make_emissions(covariance_type, means, covariances):
    """Emission of the family ``covariance_type`` (covariances in the family's shape)."""
    return emission_family(covariance_type)(means, covariances)
