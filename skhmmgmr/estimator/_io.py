"""Model input and output of :class:`~skhmmgmr.HMMGMRRegressor`.

The estimator's own constructor from a :class:`~skhmmgmr.FittedHMMGMR` lives here; every
exporter lives with its owner and the estimator's method is one line that delegates: the
portable JSON format to :mod:`skhmmgmr._hmm._portable` (the regressor's block of the format of
:mod:`skhmmgmr.portable`), hmmlearn to :mod:`skhmmgmr._hmm._hmmlearn`, the stream to
:class:`~skhmmgmr.FilterStream`. The model file is written and read by
:func:`skhmmgmr.portable.save` and :func:`~skhmmgmr.portable.load`; the estimator's JSON
methods (``to_dict``, ``from_dict``, ``export_json``, ``from_json``) are their deprecated
aliases, kept for one release. The mixin implements the model file's protocol (see
:mod:`skhmmgmr._hmm._portable`): what the file keeps of an estimator, its ``model_type``
(``__skhmmgmr_model_type__``) and its parameters (``__skhmmgmr_file_params__``).
"""

import numpy as np

from .._core._compat import validate_parameter_constraints
from .._core._deprecation import deprecated_alias
from .._hmm._hmmlearn import estimator_from_hmmlearn, estimator_to_hmmlearn
from .._hmm._portable import (
    REGRESSOR_TYPE,
    estimator_from_dict,
    estimator_from_json,
    estimator_to_dict,
    export_json,
)
from .._hmm._readout import fixed_decay, time_constant_of
from ..streaming import FilterStream

_SAVE = "write the model file with skhmmgmr.portable.save(model, path)"
_LOAD = "read the model file with skhmmgmr.portable.load(path)"
_AS_DICT = "(json.load of the file gives its dict)"


def with_read_out(model, output_smoothing):
    """``model`` with the read-out that ``output_smoothing`` gives (a fitted estimator's
    parameter): a time constant is applied to a model without a read-out and must agree with
    the read-out of a model that has one; None and "auto" (the read-out fit chose) keep the
    model's."""
    if output_smoothing is None or isinstance(output_smoothing, str):
        return model
    decay = fixed_decay(output_smoothing)
    if not model.smoothed:
        return model.with_output_decay(np.full(model.n_outputs, decay)) if decay else model
    if not np.allclose(model.output_decay, decay, rtol=1e-12, atol=0):
        held = [round(time_constant_of(a), 6) for a in model.output_decay.tolist()]
        raise ValueError(
            f"output_smoothing={output_smoothing!r} asks for a read-out of time constant "
            f"{output_smoothing!r} rows, but the model's read-out has the time constant(s) "
            f"{held}: give output_smoothing=None to keep the model's read-out"
        )
    return model


class ModelIOMixin:
    """Builds an estimator around a :class:`~skhmmgmr.FittedHMMGMR` and reads it out."""

    # ``model_type`` of the estimator's portable model file
    __skhmmgmr_model_type__ = REGRESSOR_TYPE

    @classmethod
    def from_fitted_model(cls, model, **params):
        """A fitted estimator around a :class:`~skhmmgmr.FittedHMMGMR`.

        Parameters
        ----------
        model : FittedHMMGMR
        **params : dict
            Estimator parameters (``get_params()`` keys); ``n_states`` and
            ``covariance_type`` are taken from the model. A time constant ``output_smoothing``
            gives a model without a read-out (``model.output_decay`` zero) that read-out, and
            must agree with the read-out of a model that has one; None and "auto" keep the
            model's.

        Returns
        -------
        estimator : HMMGMRRegressor
            Fitted: predicts, streams and exports as ``model`` does (with the read-out of
            ``output_smoothing``).

        Raises
        ------
        ValueError
            If ``output_smoothing`` is a time constant that differs from the model's read-out.

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
        estimator.model_ = with_read_out(model, estimator.output_smoothing)
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
            Other estimator parameters. A time constant ``output_smoothing`` gives the
            estimate its read-out; "auto", which chooses the read-out from the training
            recordings in ``fit``, is refused.

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

    def __skhmmgmr_file_params__(self):
        """The parameters the model file keeps (``estimator_params``)."""
        return self.get_params()

    @deprecated_alias("HMMGMRRegressor.to_dict", f"{_SAVE} {_AS_DICT}")
    def to_dict(self, *, output_names=None):
        """The fitted model as a JSON-ready dict (the portable model format).

        .. deprecated:: 0.2
           ``to_dict`` will be removed in 0.3: :func:`skhmmgmr.portable.save` writes the
           model file (``json.load`` of the file gives this dict).

        Parameters
        ----------
        output_names : list of str, default=None
            Names of the outputs; those of ``y`` in ``fit`` (``output_names_``), else
            ``output_0``, ... when None.

        Returns
        -------
        data : dict
            Nested dicts, lists, strings and finite numbers only.
        """
        return estimator_to_dict(self, output_names=output_names)

    @deprecated_alias("HMMGMRRegressor.export_json", _SAVE)
    def export_json(self, path, *, output_names=None):
        """Write the portable model file (strict JSON) to ``path``.

        .. deprecated:: 0.2
           ``export_json`` will be removed in 0.3: call
           ``skhmmgmr.portable.save(model, path, output_names=...)``, which writes the same
           file.

        Parameters
        ----------
        path : str or path-like
        output_names : list of str, default=None
            Names of the outputs; those of ``y`` in ``fit`` (``output_names_``), else
            ``output_0``, ... when None.
        """
        export_json(estimator_to_dict(self, output_names=output_names), path)

    @classmethod
    @deprecated_alias("HMMGMRRegressor.from_dict", f"{_LOAD} {_AS_DICT}")
    def from_dict(cls, data):
        """Restore a fitted estimator from the dict of a model file.

        .. deprecated:: 0.2
           ``from_dict`` will be removed in 0.3: read the file with
           :func:`skhmmgmr.portable.load`.

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
            If ``data`` is not a valid model file of this class; the message names the key.
        """
        return estimator_from_dict(cls, data)

    @classmethod
    @deprecated_alias("HMMGMRRegressor.from_json", _LOAD)
    def from_json(cls, path):
        """Restore a fitted estimator from a model file.

        .. deprecated:: 0.2
           ``from_json`` will be removed in 0.3: call ``skhmmgmr.portable.load(path)``,
           which reads every model file.

        Parameters
        ----------
        path : str or path-like

        Returns
        -------
        model : HMMGMRRegressor

        Raises
        ------
        ValueError
            If the file is not valid JSON or not a valid model file of this class; the
            message names the file and the key.
        """
        return estimator_from_json(cls, path)
