"""Scorers of :mod:`skhmmgmr.metrics`: per-recording prediction and metadata routing."""

import inspect
import warnings
from functools import partial

import numpy as np
from sklearn.utils.metadata_routing import UNCHANGED, MetadataRequest, get_routing_for_object

from .._core._compat import (
    _MetadataRequester,
    _routing_enabled,
    validate_parameter_constraints,
    validate_params,
)
from .._core._docstrings import fill_shared_parameters
from .._core._panel import in_filter_order, recordings_of
from .._core._pickled import PickleVersionMixin
from ._table import (
    PREDICT_MODE,
    SAMPLING_PERIOD,
    SCALE,
    TRADE_OFFS,
    WEIGHT,
    average,
    check_some_weight,
    parse_trade_offs,
    performance_per_recording,
    recording_metrics,
)

TIME_COLUMN = [str, None]


class UngroupedScoringWarning(UserWarning):
    """A scorer received no ``groups`` and scored the whole fold as one recording."""


class _RecordingScorer(PickleVersionMixin, _MetadataRequester):
    """Base of the per-recording scorers: prediction per recording and metadata routing.

    Subclasses define ``_score_predictions(y_true, y_pred, groups, sampling_period, time)``
    and add the constraints of their own parameters to ``_parameter_constraints``.
    """

    _sign = 1
    _needs_sampling = True
    _parameter_constraints: dict = {"predict_mode": PREDICT_MODE}

    # -- scikit-learn parameter protocol (so that clone, repr and set_params work) ------------
    @classmethod
    def _get_param_names(cls):
        signature = inspect.signature(cls.__init__)
        return [p.name for p in signature.parameters.values() if p.name != "self"]

    def get_params(self, deep=True):
        """Get the parameters of this scorer (``deep`` is ignored)."""
        return {name: getattr(self, name) for name in self._get_param_names()}

    def set_params(self, **params):
        """Set the parameters of this scorer."""
        valid = self._get_param_names()
        for name, value in params.items():
            if name not in valid:
                raise ValueError(f"invalid parameter {name!r} for {type(self).__name__}")
            setattr(self, name, value)
        self._check_params()
        return self

    def __repr__(self):
        defaults = {
            p.name: p.default
            for p in inspect.signature(type(self).__init__).parameters.values()
            if p.name != "self"
        }
        changed = [
            f"{name}={value!r}"
            for name, value in self.get_params().items()
            if not (value is defaults[name] or _equal(value, defaults[name]))
        ]
        return f"{type(self).__name__}({', '.join(changed)})"

    def _routing_repr(self):
        return repr(self)

    # -- metadata routing ---------------------------------------------------------------------
    def _get_metadata_request(self):
        if hasattr(self, "_metadata_request"):
            return get_routing_for_object(self._metadata_request)
        requests = MetadataRequest(owner=self)
        # groups are requested by default (like GroupKFold.split): scoring a fold of several
        # recordings as one sequence would silently give a wrong score.
        requests.score.add_request(param="groups", alias=True)
        return requests

    def set_score_request(self, *, groups=UNCHANGED):
        """Request (or not) the ``groups`` metadata for scoring.

        Only available with ``sklearn.set_config(enable_metadata_routing=True)``. The scorer
        requests ``groups`` by default, so this is only needed to switch it off
        (``groups=False``) or to take it under another name (``groups="recording_id"``).

        Parameters
        ----------
        groups : bool, str or None, default=sklearn.utils.metadata_routing.UNCHANGED
            ``True``: receive ``groups``; ``False``: do not; ``None``: error if given; a
            string: receive the metadata of that name as ``groups``.

        Returns
        -------
        self : object
        """
        if not _routing_enabled():
            raise RuntimeError(
                "set_score_request is only available when metadata routing is enabled; use "
                "sklearn.set_config(enable_metadata_routing=True) or sklearn.config_context"
            )
        requests = self._get_metadata_request()
        if groups is not UNCHANGED:
            requests.score.add_request(param="groups", alias=groups)
        self._metadata_request = requests
        return self

    def _accept_sample_weight(self):
        # scikit-learn's multi-metric scorer asks this when sample_weight is passed without
        # routing; the thesis' metrics have no sample weights.
        return False

    # -- scoring ------------------------------------------------------------------------------
    def _check_params(self):
        validate_parameter_constraints(
            self._parameter_constraints, self.get_params(), caller_name=type(self).__name__
        )
        if self.sampling_period is not None and self.time_column is not None:
            raise ValueError("give either sampling_period or time_column, not both")

    def __call__(self, estimator, X, y_true, groups=None, **kwargs):
        """Score a fitted estimator on ``X`` (greater is better).

        Parameters
        ----------
        estimator : object
            Fitted regressor with ``predict``.
        X : array-like or pandas.DataFrame of shape (n_samples, n_features)
            Input rows; the rows of a recording must be contiguous and in time order, unless
            the index of ``X`` holds the recordings (and the time): see
            :func:`skhmmgmr.datasets.to_panel`.
        y_true : array-like of shape (n_samples,) or (n_samples, n_outputs)
            Observed target.
        groups : array-like of shape (n_samples,), default=None
            Recording id of every row, passed directly or routed by scikit-learn's metadata
            routing. If None, the ``"recording"`` level of the index of ``X``; without one,
            the whole of ``X`` is scored as one recording and an
            :class:`UngroupedScoringWarning` is emitted.

        Returns
        -------
        score : float
        """
        if kwargs:
            raise TypeError(
                f"{type(self).__name__} got unexpected metadata {sorted(kwargs)}; it only "
                "takes groups"
            )
        self._check_params()
        # Read once and handed to predict and the metrics. Recordings in the index are
        # scored in filter order, whatever order the caller (a resampling search, a
        # permutation) put the rows in.
        run = partial(self._score_in_filter_order, estimator)
        return in_filter_order(run, X, groups, rows={"y_true": y_true})

    def _score_in_filter_order(self, estimator, layout, X, y_true):
        """The score of the rows ``X`` and ``y_true`` in filter order, their ``layout`` read."""
        groups, index_time = layout.handed_down(), layout.time
        sampling_period, time = None, None
        if self._needs_sampling:
            sampling_period, time = self.sampling_period, self._time_of(X)
            if sampling_period is None and time is None:
                time = index_time
            if sampling_period is None and time is None:
                raise ValueError(
                    f"{type(self).__name__} needs the time step of the rows for the "
                    "smoothness: set sampling_period (seconds) or time_column, or give X a "
                    "'time' index level"
                )
        y_pred = self._predict(estimator, X, groups)
        return self._sign * self._score_predictions(y_true, y_pred, groups, sampling_period, time)

    def _time_of(self, X):
        if self.time_column is None:
            return None
        if not hasattr(X, "columns"):
            raise ValueError(
                f"time_column={self.time_column!r} needs X to be a pandas DataFrame, got "
                f"{type(X).__name__}"
            )
        if self.time_column not in X.columns:
            raise ValueError(f"X has no column {self.time_column!r} (time_column)")
        return np.asarray(X[self.time_column], dtype=float)

    def _predict(self, estimator, X, groups):
        if groups is None:
            warnings.warn(
                f"{type(self).__name__} received no groups and scores the fold as ONE "
                "recording, so a fold of several recordings is filtered and scored as one "
                "sequence. Enable metadata routing (sklearn.set_config("
                "enable_metadata_routing=True)) and pass groups to fit, or use a splitter "
                "whose test folds are single recordings (LeaveOneGroupOut).",
                UngroupedScoringWarning,
                stacklevel=3,
            )
            return estimator.predict(X)
        mode = self.predict_mode
        if mode == "auto":
            mode = "groups" if _predict_takes_groups(estimator) else "per_recording"
        if mode == "groups":
            return estimator.predict(X, groups=groups)
        recordings = recordings_of(groups, _n_rows(X))
        parts = [estimator.predict(_take_rows(X, rows)) for _, rows in recordings.slices()]
        return np.concatenate([np.asarray(p) for p in parts], axis=0)


def _predict_takes_groups(estimator):
    """Whether ``estimator.predict`` takes ``groups``: as a parameter of its own, or, with
    metadata routing on, as metadata it routes to a step that requests it (a Pipeline)."""
    if _routing_enabled() and hasattr(estimator, "get_metadata_routing"):
        try:
            if "groups" in get_routing_for_object(estimator).consumes("predict", ["groups"]):
                return True
        except (AttributeError, TypeError, ValueError):
            pass
    try:
        parameters = inspect.signature(estimator.predict).parameters
    except (TypeError, ValueError):
        return False
    groups = parameters.get("groups")
    return groups is not None and groups.kind in (
        inspect.Parameter.POSITIONAL_OR_KEYWORD,
        inspect.Parameter.KEYWORD_ONLY,
    )


def _n_rows(X):
    return X.shape[0] if hasattr(X, "shape") else len(X)


def _take_rows(X, rows):
    if hasattr(X, "iloc"):
        return X.iloc[rows]
    return X[rows]


def _equal(a, b):
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


@fill_shared_parameters
class PerformanceScore(_RecordingScorer):
    """Scorer returning the negative performance score ``-PS`` (greater is better).

    Usable as ``scoring=`` in :class:`~sklearn.model_selection.GridSearchCV`,
    :func:`~sklearn.model_selection.cross_validate` or
    :class:`~sklearn.feature_selection.SequentialFeatureSelector`. Each recording of the test
    fold is predicted separately (the filter restarts), scored, and the per-recording scores
    are averaged; see :func:`performance_score`.

    The recording ids reach the scorer as ``groups`` through metadata routing: with
    ``sklearn.set_config(enable_metadata_routing=True)``, the ``groups`` given to ``fit`` of
    the search are sliced per fold and passed to the scorer, which requests them by default.
    Without routing the scorer gets no groups, scores each fold as one recording and warns
    (:class:`UngroupedScoringWarning`); that is right only when each test fold is one
    recording (``LeaveOneGroupOut``).

    Parameters
    ----------
    {accuracy_weight, smoothness_weight}
    accuracy_scale, smoothness_scale : float or mapping, default=None
        Reference scales dividing each term; see :func:`performance_score`.
    {sampling_period}
    {time_column}
    {predict_mode}

    See Also
    --------
    performance_score : The metric on arrays.
    make_performance_scorers : Several trade-offs and the two metrics for multi-metric scoring.

    Notes
    -----
    Recipe for a grid search over recordings (``groups`` holds one recording id per row)::

        import sklearn
        from sklearn.model_selection import GridSearchCV, GroupKFold

        with sklearn.config_context(enable_metadata_routing=True):
            search = GridSearchCV(
                estimator,  # its fit may need .set_fit_request(groups=True)
                param_grid,
                cv=GroupKFold(n_splits=5),
                scoring={"ps": PerformanceScore(sampling_period=0.01)},
                refit="ps",
            ).fit(X, y, groups=groups)

    With ``cross_validate`` pass ``params={"groups": groups}``. A scorer called by hand takes
    ``groups`` directly: ``scorer(estimator, X, y, groups=groups)``. Call
    ``set_score_request(groups=False)`` to stop the scorer from receiving groups.

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.linear_model import LinearRegression
    >>> from skhmmgmr.metrics import PerformanceScore
    >>> X = np.arange(8.0).reshape(-1, 1)
    >>> y = np.array([0.0, 1.0, 2.0, 3.5, 4.0, 5.0, 6.5, 7.0])
    >>> groups = [0, 0, 0, 0, 1, 1, 1, 1]
    >>> model = LinearRegression().fit(X, y)
    >>> scorer = PerformanceScore(sampling_period=0.1)
    >>> scorer
    PerformanceScore(sampling_period=0.1)
    >>> round(scorer(model, X, y, groups=groups), 3)
    -8.45
    """

    _sign = -1
    _parameter_constraints = {
        **_RecordingScorer._parameter_constraints,
        "accuracy_weight": WEIGHT,
        "smoothness_weight": WEIGHT,
        "sampling_period": SAMPLING_PERIOD,
        "time_column": TIME_COLUMN,
        "accuracy_scale": SCALE,
        "smoothness_scale": SCALE,
    }

    def __init__(
        self,
        accuracy_weight=0.5,
        smoothness_weight=0.5,
        *,
        sampling_period=None,
        time_column=None,
        accuracy_scale=None,
        smoothness_scale=None,
        predict_mode="auto",
    ):
        self.accuracy_weight = accuracy_weight
        self.smoothness_weight = smoothness_weight
        self.sampling_period = sampling_period
        self.time_column = time_column
        self.accuracy_scale = accuracy_scale
        self.smoothness_scale = smoothness_scale
        self.predict_mode = predict_mode
        self._check_params()

    @property
    def _needs_sampling(self):
        return self.smoothness_weight > 0

    def _check_params(self):
        super()._check_params()
        check_some_weight(self.accuracy_weight, self.smoothness_weight)

    def _score_predictions(self, y_true, y_pred, groups, sampling_period, time):
        metrics = recording_metrics(
            y_true,
            y_pred,
            groups=groups,
            sampling_period=sampling_period,
            time=time,
            accuracy=self.accuracy_weight > 0,
            smoothness=self.smoothness_weight > 0,
        )
        per_recording = performance_per_recording(
            metrics,
            self.accuracy_weight,
            self.smoothness_weight,
            self.accuracy_scale,
            self.smoothness_scale,
        )
        return average(per_recording, "uniform_average")


@fill_shared_parameters
class AccuracyScore(_RecordingScorer):
    """Scorer returning the mean per-recording accuracy in percent (greater is better).

    See :class:`PerformanceScore` for how ``groups`` reach the scorer.

    Parameters
    ----------
    {predict_mode}

    Examples
    --------
    >>> from skhmmgmr.metrics import AccuracyScore
    >>> AccuracyScore()
    AccuracyScore()
    """

    _needs_sampling = False
    sampling_period = None
    time_column = None

    def __init__(self, *, predict_mode="auto"):
        self.predict_mode = predict_mode
        self._check_params()

    def _score_predictions(self, y_true, y_pred, groups, sampling_period, time):
        metrics = recording_metrics(y_true, y_pred, groups=groups, smoothness=False)
        return average(metrics.accuracy, "uniform_average")


@fill_shared_parameters
class SmoothnessScore(_RecordingScorer):
    """Scorer returning the negative mean per-recording smoothness ``-SM`` (greater is better).

    See :class:`PerformanceScore` for how ``groups`` reach the scorer.

    Parameters
    ----------
    {sampling_period}
    {time_column}
    {predict_mode}

    Examples
    --------
    >>> from skhmmgmr.metrics import SmoothnessScore
    >>> SmoothnessScore(sampling_period=0.01)
    SmoothnessScore(sampling_period=0.01)
    """

    _sign = -1
    _parameter_constraints = {
        **_RecordingScorer._parameter_constraints,
        "sampling_period": SAMPLING_PERIOD,
        "time_column": TIME_COLUMN,
    }

    def __init__(self, *, sampling_period=None, time_column=None, predict_mode="auto"):
        self.sampling_period = sampling_period
        self.time_column = time_column
        self.predict_mode = predict_mode
        self._check_params()

    def _score_predictions(self, y_true, y_pred, groups, sampling_period, time):
        metrics = recording_metrics(
            None, y_pred, groups=groups, sampling_period=sampling_period, time=time, accuracy=False
        )
        return average(metrics.smoothness, "uniform_average")


@validate_params(
    {
        "trade_offs": TRADE_OFFS,
        "sampling_period": SAMPLING_PERIOD,
        "time_column": TIME_COLUMN,
        "accuracy_scale": SCALE,
        "smoothness_scale": SCALE,
        "metrics": ["boolean"],
        "predict_mode": PREDICT_MODE,
    },
    prefer_skip_nested_validation=True,
)
@fill_shared_parameters
def make_performance_scorers(
    trade_offs=("100/0", "50/50", "0/100"),
    *,
    sampling_period=None,
    time_column=None,
    accuracy_scale=None,
    smoothness_scale=None,
    metrics=True,
    predict_mode="auto",
):
    """Scorers for multi-metric scoring: one :class:`PerformanceScore` per trade-off.

    Parameters
    ----------
    trade_offs : str, pair or list of those, default=("100/0", "50/50", "0/100")
        Trade-offs as in :func:`normalize_performance`.
    {sampling_period}
    {time_column}
    accuracy_scale, smoothness_scale : float or mapping, default=None
        Reference scales passed to every scorer; see :class:`PerformanceScore`.
    metrics : bool, default=True
        Also add ``"accuracy"`` (:class:`AccuracyScore`) and ``"neg_smoothness"``
        (:class:`SmoothnessScore`).
    {predict_mode}

    Returns
    -------
    scorers : dict
        ``{"neg_performance_<trade-off>": PerformanceScore, ...}`` (plus the two metric
        scorers), usable as ``scoring=`` of ``cross_validate`` or ``GridSearchCV``.

    Examples
    --------
    >>> from skhmmgmr.metrics import make_performance_scorers
    >>> sorted(make_performance_scorers(["50/50"], sampling_period=0.01))
    ['accuracy', 'neg_performance_50/50', 'neg_smoothness']
    """
    scorers = {
        f"neg_performance_{label}": PerformanceScore(
            w1,
            w2,
            sampling_period=sampling_period,
            time_column=time_column,
            accuracy_scale=accuracy_scale,
            smoothness_scale=smoothness_scale,
            predict_mode=predict_mode,
        )
        for label, w1, w2 in parse_trade_offs(trade_offs)
    }
    if metrics:
        scorers["accuracy"] = AccuracyScore(predict_mode=predict_mode)
        scorers["neg_smoothness"] = SmoothnessScore(
            sampling_period=sampling_period, time_column=time_column, predict_mode=predict_mode
        )
    return scorers
