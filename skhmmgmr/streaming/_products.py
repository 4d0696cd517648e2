"""The products of one update of a :class:`~skhmmgmr.FilterStream`, prepared once.

For the standardised inputs ``z`` of a sample (with a trailing 1):

- ``[z, 1] @ weights`` gives at once the terms of the gating density's quadratic form of every
  state (:class:`~skhmmgmr._hmm._emissions.GaussianDensity`: the whitened inputs) and every
  per-state conditional output mean ``m_k(z)``;
- ``[squared terms, 1] @ block_sum`` gives the log-densities of all states,
  ``log b_k(z) = norm_k - (sum of the squares of state k's terms)``.

Each update writes into preallocated buffers (:func:`product_buffer`): a product and its two
views, the terms and the state output means.
"""

import numpy as np


def stacked_weights(params):
    """``(weights, block_sum, n_terms)`` of a :class:`~skhmmgmr._hmm._gmr.GMRParameters`:
    ``weights`` (n_inputs + 1, n_terms + n_states * n_outputs), ``block_sum``
    (n_terms + 1, n_states)."""
    n_states, _, n_inputs = params.coef.shape
    density = params.gating.density()
    n_terms = density.factors.shape[0]
    weights = np.empty((n_inputs + 1, n_terms + params.coef.shape[0] * params.coef.shape[1]))
    weights[:, :n_terms] = density.factors.T
    weights[:n_inputs, n_terms:] = np.hstack(list(params.coef.transpose(0, 2, 1)))
    weights[n_inputs, n_terms:] = params.intercept.ravel()
    block_sum = np.zeros((n_terms + 1, n_states))
    block_sum[:n_terms] = -np.kron(np.eye(n_states), np.ones((n_terms // n_states, 1)))
    block_sum[n_terms] = density.norms[:, 0]
    return weights, block_sum, n_terms


def product_buffer(width, n_terms, n_states, n_outputs, scalar_output, product=None):
    """``(product, terms, means)``: a product buffer of ``width`` values (``product``, or a new
    one), its first ``n_terms`` values and the state output means after them, (n_states,)
    for a scalar output, (n_states, n_outputs) otherwise."""
    product = np.empty(width) if product is None else product
    means = product[n_terms:].reshape(n_states, n_outputs)
    return product, product[:n_terms], means[:, 0] if scalar_output else means
