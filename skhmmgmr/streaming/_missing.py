"""One sample of a :class:`~skhmmgmr.FilterStream` whose NaN inputs are missing values: the
densities and the state output means given its observed inputs (and the carried values of
the missing ones, ``missing_values="carry_forward"``), as ``predict`` reads such a row
(:func:`~skhmmgmr._hmm._missing.gmr_given_observed`)."""

import numpy as np

from .._hmm._holds import MAX_STANDARDISED
from .._hmm._missing import gmr_given_observed


def observed_frames(params, z, threshold, stale=None):
    """``(frames, state_means, added)`` of the standardised sample ``z`` (n_inputs,), NaN
    where missing: the input densities of its observed inputs relative to the best state's
    (n_states,), every state's output means given them and the variances they add to the
    conditional ones (both (n_states, n_outputs)); None when the outlier policy holds the
    sample (:mod:`skhmmgmr._hmm._holds`: observed inputs out of range, or all log-densities
    below ``threshold``; never a sample with no input observed). ``stale``: the carried
    values, from :meth:`~skhmmgmr._hmm._stale_inputs.CarriedInputs.read`."""
    missing = np.isnan(z)
    observed = np.where(missing, 0.0, z)[np.newaxis]
    if not np.sum(np.abs(observed)) < MAX_STANDARDISED:
        return None
    log_prob, state_means, added = gmr_given_observed(params, observed, missing[np.newaxis], stale)
    log_prob = log_prob[0]
    top = log_prob.max()
    in_range = top > -np.inf and not np.isnan(log_prob).any()
    if not (missing.all() or top >= threshold and in_range):
        return None
    return np.exp(log_prob - top), state_means[0], added[0]
