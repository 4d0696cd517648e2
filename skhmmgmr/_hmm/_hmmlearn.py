"""Conversions between :class:`~skhmmgmr.FittedHMMGMR` and hmmlearn's ``GaussianHMM``.

hmmlearn's model is an HMM over the joint columns ``[inputs, outputs]`` in the data's units;
ours keeps the same HMM over standardised columns, which changes neither the log-likelihood
(up to the constant Jacobian of the standardisation, which :class:`Standardization` applies)
nor the GMR read-out.

:class:`~skhmmgmr.HMMGMRRegressor`'s ``to_hmmlearn`` and ``from_hmmlearn`` delegate to
:func:`estimator_to_hmmlearn` and :func:`estimator_from_hmmlearn`.
"""

import numpy as np
from sklearn.utils.validation import check_is_fitted

from ._emissions import emission_family
from ._fitted import FittedHMMGMR, Standardization


def to_hmmlearn(model):
    """A fitted ``hmmlearn.hmm.GaussianHMM`` over the joint columns, in the data's units."""
    from hmmlearn.hmm import GaussianHMM

    emissions = model.data_emissions
    hmm = GaussianHMM(
        n_components=model.n_states, covariance_type=model.covariance_type, init_params=""
    )
    hmm.n_features = emissions.n_dims
    hmm.startprob_ = np.array(model.startprob)
    hmm.transmat_ = np.array(model.transmat)
    hmm.means_ = np.array(emissions.means)
    hmm.covars_ = emissions.hmmlearn_covars()
    return hmm


def _standardization_of(emissions, n_inputs):
    """Centre and scale of the equally weighted mixture of the states: any positive scale
    gives the same model, this one keeps the filter's numbers near one."""
    means = emissions.means
    center = means.mean(axis=0)
    variances = emissions.state_variances().mean(axis=0) + means.var(axis=0)
    return Standardization(center, np.sqrt(variances), n_inputs)


def from_hmmlearn(hmm, n_outputs=1, feature_names=None):
    """:class:`FittedHMMGMR` of a fitted ``GaussianHMM`` whose last ``n_outputs`` columns are
    the outputs.

    Raises
    ------
    ValueError
        If the model is not fitted, its covariance type is not "full" or "tied", or
        ``n_outputs`` leaves no input.
    """
    for name in ("startprob_", "transmat_", "means_"):
        if not hasattr(hmm, name):
            raise ValueError(f"the hmmlearn model is not fitted: it has no {name}")
    family = emission_family(getattr(hmm, "covariance_type", None))
    means = np.asarray(hmm.means_, dtype=float)
    n_dims = means.shape[1]
    if not isinstance(n_outputs, int | np.integer) or not 0 < n_outputs < n_dims:
        raise ValueError(
            f"n_outputs must be an integer in [1, {n_dims - 1}] for a model over {n_dims} "
            f"columns, got {n_outputs!r}"
        )
    # hmmlearn returns every state's covariance (K, D, D) whatever its covariance type
    emissions = family.from_state_covariances(means, np.asarray(hmm.covars_, dtype=float))
    n_inputs = n_dims - n_outputs
    return FittedHMMGMR(
        np.asarray(hmm.startprob_, dtype=float),
        np.asarray(hmm.transmat_, dtype=float),
        emissions,
        _standardization_of(emissions, n_inputs),
        scalar_output=n_outputs == 1,
        feature_names=None if feature_names is None else tuple(feature_names),
    )


def estimator_to_hmmlearn(estimator):
    """:func:`to_hmmlearn` of a fitted estimator's ``model_``."""
    check_is_fitted(estimator)
    return to_hmmlearn(estimator.model_)


def estimator_from_hmmlearn(cls, hmm, *, n_outputs=1, feature_names=None, **params):
    """A fitted estimator of class ``cls`` (its ``from_fitted_model`` with ``params``) that
    reads out ``hmm`` (:func:`from_hmmlearn`); ``output_smoothing="auto"``, which chooses the
    read-out from training recordings, is refused."""
    if isinstance(params.get("output_smoothing"), str):
        raise ValueError(
            f"output_smoothing={params['output_smoothing']!r}: 'auto' chooses the read-out in "
            "fit, from the training recordings, which an hmmlearn model does not bring; give "
            "a time constant in rows, or None"
        )
    model = from_hmmlearn(hmm, n_outputs=n_outputs, feature_names=feature_names)
    return cls.from_fitted_model(model, **params)
