"""Model input and output of :class:`~skhmmgmr.HMMGMRRegressor`.

The estimator's own constructor from a :class:`~skhmmgmr.FittedHMMGMR` lives here; every
exporter lives with its owner and the estimator's method is one line that delegates: the
portable JSON format to :mod:`skhmmgmr._hmm._portable` (the regressor's block of the format of
:mod:`skhmmgmr.portable`), hmmlearn to :mod:`skhmmgmr._hmm._hmmlearn`, the stream to
:class:`~skhmmgmr.FilterStream`.
"""

import numpy as np

from .._core._compat import validate_parameter_constraints
from .._hmm._hmmlearn import estimator_from_hmmlearn, estimator_to_hmmlearn
from .._hmm._portable import (
    REGRESSOR_TYPE,
    estimator_from_dict,
    estimator_from_json,
    estimator_to_dict,
    export_json,
)
from ..streaming import FilterStream


class ModelIOMixin:
    """Builds an estimator around a :class:`~skhmmgmr.FittedHMMGMR` and reads it out."""

    # ``model_type`` of the estimator's portable model file
    _portable_type = REGRESSOR_TYPE

    @classmethod
    def from_fitted_model(cls, model, **params):
        """A fitted estimator around a :class:`~skhmmgmr.FittedHMMGMR`.

        Parameters
        ----------
        model : FittedHMMGMR
        **params : dict
            Estimator parameters (``get_params()`` keys); ``n_states`` and
            ``covariance_type`` are taken from the model.

        Returns
        -------
        estimator : HMMGMRRegressor
            Fitted: predicts, streams and exports as ``model`` does.

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import HMMGMRRegressor
        >>> X = np.cumsum(np.random.default_rng(0).normal(size=(200, 2)), axis=0)
        >>> fitted = HMMGMRRegressor(n_states=2, random_state=0).fit(X, X.sum(axis=1))
        >>> copy = HMMGMRRegressor.from_fitted_model(fitted.model_)
        >>> bool(np.array_equal(copy.predict(X), fitted.predict(X)))
        True
        """
        params = {**params, "n_states": model.n_states, "covariance_type": model.covariance_type}
        estimator = cls(**params)
        # as fit would: a model restored with a parameter fit refuses must be refused too
        validate_parameter_constraints(
            cls._parameter_constraints, estimator.get_params(deep=False), caller_name=cls.__name__
        )
        estimator.model_ = model
        estimator.n_features_in_ = model.n_inputs
        if model.feature_names is not None:
            estimator.feature_names_in_ = np.asarray(model.feature_names, dtype=object)
        estimator.n_outputs_ = model.n_outputs
        return estimator

    @classmethod
    def from_hmmlearn(cls, hmm, *, n_outputs=1, feature_names=None, **params):
        """A fitted estimator that reads out a fitted ``hmmlearn.hmm.GaussianHMM`` by causal GMR.

        The HMM must be over the joint columns ``[inputs, outputs]`` (outputs last), with
        ``covariance_type`` "full" or "tied".

        Parameters
        ----------
        hmm : hmmlearn.hmm.GaussianHMM
            Fitted.
        n_outputs : int, default=1
            Number of output columns (the last ones); with one output, predictions are 1-D.
        feature_names : list of str, default=None
            Names of the inputs (then ``predict`` takes a DataFrame with these columns).
        **params : dict
            Other estimator parameters.

        Returns
        -------
        estimator : HMMGMRRegressor

        Examples
        --------
        >>> import numpy as np
        >>> from hmmlearn.hmm import GaussianHMM
        >>> from skhmmgmr import HMMGMRRegressor
        >>> rng = np.random.default_rng(0)
        >>> X = np.cumsum(rng.normal(size=(300, 1)), axis=0) / 10
        >>> joint = np.column_stack([X, 2 * X[:, 0] + rng.normal(scale=0.1, size=300)])
        >>> hmm = GaussianHMM(2, covariance_type="full", random_state=0).fit(joint)
        >>> model = HMMGMRRegressor.from_hmmlearn(hmm, n_outputs=1)
        >>> model.predict(X).shape
        (300,)
        """
        return estimator_from_hmmlearn(
            cls, hmm, n_outputs=n_outputs, feature_names=feature_names, **params
        )

    def to_hmmlearn(self):
        """The fitted HMM as a fitted ``hmmlearn.hmm.GaussianHMM`` over ``[inputs, outputs]``.

        Same covariance type, data units: hmmlearn's ``score``, ``decode`` (Viterbi),
        ``predict_proba`` (smoothed posteriors) and ``sample`` then work on the joint columns.

        Returns
        -------
        hmm : hmmlearn.hmm.GaussianHMM

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import HMMGMRRegressor
        >>> X = np.cumsum(np.random.default_rng(0).normal(size=(200, 2)), axis=0)
        >>> y = X.sum(axis=1)
        >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y)
        >>> hmm = model.to_hmmlearn()
        >>> bool(np.isclose(hmm.score(np.column_stack([X, y])), model.log_likelihood(X, y)))
        True
        """
        return estimator_to_hmmlearn(self)

    def filter_stream(self, **kwargs):
        """Sample-by-sample causal filter for real-time use.

        Parameters
        ----------
        **kwargs : dict
            Passed to :class:`~skhmmgmr.FilterStream` (``relevance``, ``forgetting``...;
            ``missing_values`` and ``min_log_density``, the outlier policy, default to the
            estimator's, as ``predict`` follows them).

        Returns
        -------
        stream : FilterStream
            Call ``stream.update(sample)`` once per sample and ``stream.reset()`` at the start
            of every recording; the estimates equal those of :meth:`predict`.

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import HMMGMRRegressor
        >>> X = np.cumsum(np.random.default_rng(0).normal(size=(300, 2)), axis=0) / 10
        >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, X[:, 0] - X[:, 1])
        >>> stream = model.filter_stream()
        >>> bool(abs(stream.update(X[0]) - model.predict(X[:1])[0]) < 1e-12)
        True
        """
        return FilterStream(self, **kwargs)

    def to_dict(self, *, output_names=None):
        """The fitted model as a JSON-ready dict (the portable model format).

        The dict holds everything the causal filter needs (see :mod:`skhmmgmr.portable` for
        the keys and their units) and everything :meth:`from_dict` needs to restore the
        estimator.

        Parameters
        ----------
        output_names : list of str, default=None
            Names of the outputs; ``output_0``, ... when None.

        Returns
        -------
        data : dict
            Nested dicts, lists, strings and finite numbers only.

        Examples
        --------
        >>> import numpy as np
        >>> from skhmmgmr import HMMGMRRegressor
        >>> X = np.cumsum(np.random.default_rng(0).normal(size=(200, 2)), axis=0)
        >>> model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, X.sum(axis=1))
        >>> restored = HMMGMRRegressor.from_dict(model.to_dict(output_names=["torque"]))
        >>> bool(np.array_equal(restored.predict(X), model.predict(X)))
        True
        """
        return estimator_to_dict(self, model_type=self._portable_type, output_names=output_names)

    def export_json(self, path, *, output_names=None):
        """Write the portable model file (strict JSON) to ``path``.

        Parameters
        ----------
        path : str or path-like
        output_names : list of str, default=None
            Names of the outputs; ``output_0``, ... when None.

        See Also
        --------
        from_json : restore the estimator from the file.
        """
        export_json(self.to_dict(output_names=output_names), path)

    @classmethod
    def from_dict(cls, data):
        """Restore a fitted estimator from :meth:`to_dict` output.

        Parameters
        ----------
        data : dict

        Returns
        -------
        model : HMMGMRRegressor
            Fitted; predicts as the exported model did.

        Raises
        ------
        ValueError
            If ``data`` is not a dict, lacks a key, has a wrong shape, non-finite numbers or
            inconsistent parameters, or is of another format version; the message names the
            key.
        """
        return estimator_from_dict(cls, data, model_type=cls._portable_type)

    @classmethod
    def from_json(cls, path):
        """Restore a fitted estimator from a file written by :meth:`export_json`.

        Parameters
        ----------
        path : str or path-like

        Returns
        -------
        model : HMMGMRRegressor

        Raises
        ------
        ValueError
            If the file is not valid JSON or not a valid model file (see :meth:`from_dict`);
            the message names the file and the key.
        """
        return estimator_from_json(cls, path)
