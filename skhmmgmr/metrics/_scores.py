"""Per-recording metrics of the thesis, their D.5 normalisation, and scikit-learn scorers.

Every metric is computed on each recording separately and then averaged over the recordings
with equal weight (a short recording counts as much as a long one, as in the thesis, which
averages its validation recordings):

- RMSE (eq. 8), in the unit of the target (Nm for the steering torque);
- accuracy ``A = (1 - RMSE / SD(T)) * 100`` (eq. 9), in percent; 100 is a perfect estimate,
  0 is as good as predicting the recording's mean, and a bad model goes negative;
- smoothness ``SM = SD(dT_est/dt)`` (eq. 10), in target unit per second (Nm/s); lower is
  smoother. The derivative is the first difference divided by the time step and never crosses
  a recording boundary;
- performance score ``PS = w1 * |100 - A| + w2 * |SM|`` (eq. 7), lower is better.

Standard deviations are population ones (``ddof=0``), as in eq. D.4.

The raw PS adds percent to Nm/s. The thesis makes the two terms commensurate with the D.5
normalisation, which is a property of a table of compared models: see
:func:`normalize_performance`.

The scorers (:class:`PerformanceScore`, :class:`AccuracyScore`, :class:`SmoothnessScore`) follow
scikit-learn's convention that greater is better: :class:`PerformanceScore` returns ``-PS`` and
:class:`SmoothnessScore` returns ``-SM``, like ``neg_mean_squared_error``.
"""

from numbers import Integral

import numpy as np
import pandas as pd

from .._core._compat import Interval, validate_params
from .._core._docstrings import fill_shared_parameters
from ._table import (
    MULTIOUTPUT,
    SAMPLING_PERIOD,
    SCALE,
    TRADE_OFFS,
    WEIGHT,
    average,
    check_some_weight,
    parse_trade_offs,
    performance_per_recording,
    recording_metrics,
    share_of_sum,
)

# The arrays of a metric function: the target and estimate, the recordings and the time.
_ARRAYS = {
    "y_true": ["array-like"],
    "y_pred": ["array-like"],
    "groups": ["array-like", None],
    "time": ["array-like", None],
}


def arrays(*names):
    """The constraints of the arrays ``names`` of a metric function."""
    return {name: _ARRAYS[name] for name in names}


COLUMNS = {"model": [str], "recording": [str, list, tuple]}

# --------------------------------------------------------------------------------------------
# Metric functions
# --------------------------------------------------------------------------------------------


@validate_params(
    arrays("y_true", "y_pred", "groups") | {"multioutput": MULTIOUTPUT},
    prefer_skip_nested_validation=True,
)
@fill_shared_parameters
def accuracy_score(y_true, y_pred, *, groups=None, multioutput="uniform_average"):
    """Accuracy ``(1 - RMSE / SD(T)) * 100`` per recording, averaged over recordings.

    Parameters
    ----------
    {y_true, y_pred}
    {groups}
    {multioutput}

    Returns
    -------
    accuracy : float or ndarray of shape (n_outputs,)
        Mean accuracy over recordings, in percent. 100 is perfect; it is negative when the
        RMSE exceeds the standard deviation of the target.

    Raises
    ------
    ValueError
        If the target is constant in a recording (the accuracy is undefined there), or if an
        input holds NaN or infinity; the message names the recording.

    Examples
    --------
    >>> from skhmmgmr.metrics import accuracy_score
    >>> accuracy_score([0.0, 2.0, 0.0, 2.0], [0.0, 2.0, 1.0, 1.0])
    29.28...
    """
    metrics = recording_metrics(y_true, y_pred, groups=groups, smoothness=False)
    return average(metrics.accuracy, multioutput)


@validate_params(
    arrays("y_pred", "time", "groups")
    | {"sampling_period": SAMPLING_PERIOD, "multioutput": MULTIOUTPUT},
    prefer_skip_nested_validation=True,
)
@fill_shared_parameters
def smoothness_score(
    y_pred, *, sampling_period=None, time=None, groups=None, multioutput="uniform_average"
):
    """Smoothness ``SD(dT_est/dt)`` per recording, averaged over recordings (lower is smoother).

    Parameters
    ----------
    {y_pred}
    {sampling_period}
        Give this or ``time``.
    {time}
    {groups}
        The derivative is taken within each recording only, so every recording needs at least
        two rows.
    {multioutput}

    Returns
    -------
    smoothness : float or ndarray of shape (n_outputs,)
        Mean over recordings of the standard deviation of the estimate's time derivative, in
        target unit per second (Nm/s for torque).

    Examples
    --------
    >>> from skhmmgmr.metrics import smoothness_score
    >>> smoothness_score([0.0, 1.0, 1.0, 3.0], sampling_period=0.5)
    1.63...
    """
    metrics = recording_metrics(
        None,
        y_pred,
        groups=groups,
        sampling_period=sampling_period,
        time=time,
        accuracy=False,
    )
    return average(metrics.smoothness, multioutput)


@validate_params(
    arrays("y_true", "y_pred", "time", "groups")
    | {
        "accuracy_weight": WEIGHT,
        "smoothness_weight": WEIGHT,
        "sampling_period": SAMPLING_PERIOD,
        "accuracy_scale": SCALE,
        "smoothness_scale": SCALE,
        "multioutput": MULTIOUTPUT,
    },
    prefer_skip_nested_validation=True,
)
@fill_shared_parameters
def performance_score(
    y_true,
    y_pred,
    *,
    accuracy_weight=0.5,
    smoothness_weight=0.5,
    sampling_period=None,
    time=None,
    groups=None,
    accuracy_scale=None,
    smoothness_scale=None,
    multioutput="uniform_average",
):
    """Performance score ``w1 * |100 - A| / a + w2 * |SM| / s`` per recording, averaged.

    Lower is better. Without scales (``a = s = 1``) this is eq. 7 of the thesis, which adds
    percent to Nm/s; pass reference scales to make the terms commensurate. With ``a`` and ``s``
    set per recording to the sum of ``|100 - A|`` and ``|SM|`` over a set of compared models,
    this is the D.5 normalised score (:func:`normalize_performance` does that from a table).

    Parameters
    ----------
    {y_true, y_pred}
    {accuracy_weight, smoothness_weight}
    {sampling_period}
        Give this or ``time``, unless ``smoothness_weight`` is 0.
    {time}
    {groups}
    accuracy_scale, smoothness_scale : float or mapping, default=None
        Reference scale dividing each term: one positive number, or a mapping (dict or
        :class:`pandas.Series`) from recording id to a number. ``None`` means 1.
    {multioutput}

    Returns
    -------
    score : float or ndarray of shape (n_outputs,)
        Mean performance score over recordings.

    Examples
    --------
    >>> from skhmmgmr.metrics import performance_score
    >>> y_true = [0.0, 2.0, 0.0, 2.0]
    >>> y_pred = [0.0, 2.0, 1.0, 1.0]
    >>> performance_score(y_true, y_pred, sampling_period=0.5)  # 0.5*70.71 + 0.5*2.49
    36.60...
    >>> performance_score(y_true, y_pred, accuracy_weight=1.0, smoothness_weight=0.0)
    70.71...
    """
    check_some_weight(accuracy_weight, smoothness_weight)
    metrics = recording_metrics(
        y_true,
        y_pred,
        groups=groups,
        sampling_period=sampling_period,
        time=time,
        accuracy=accuracy_weight > 0,
        smoothness=smoothness_weight > 0,
    )
    per_recording = performance_per_recording(
        metrics, accuracy_weight, smoothness_weight, accuracy_scale, smoothness_scale
    )
    return average(per_recording, multioutput)


@validate_params(
    arrays("y_true", "y_pred", "groups", "time") | {"sampling_period": SAMPLING_PERIOD},
    prefer_skip_nested_validation=True,
)
@fill_shared_parameters
def evaluate_recordings(y_true, y_pred, *, groups=None, sampling_period=None, time=None):
    """Table of the metrics of every recording.

    Parameters
    ----------
    {y_true, y_pred}
    {groups}
    {sampling_period}
        Give this or ``time``.
    {time}

    Returns
    -------
    table : pandas.DataFrame
        One row per recording (in order of appearance), and per output when the target is
        2-D, with columns

        - ``recording``: the recording id;
        - ``output``: output index (only for 2-D targets);
        - ``n_samples``: rows of the recording;
        - ``rmse``: root-mean-square error, in target unit (Nm);
        - ``accuracy``: accuracy in percent;
        - ``smoothness``: SD of the estimate's derivative, in target unit per second (Nm/s).

        Add a ``model`` column and concatenate the tables of several models to get the input
        of :func:`normalize_performance`.

    Examples
    --------
    >>> from skhmmgmr.metrics import evaluate_recordings
    >>> evaluate_recordings(
    ...     [0.0, 2.0, 0.0, 2.0, 1.0, 3.0],
    ...     [0.0, 2.0, 1.0, 1.0, 1.0, 2.0],
    ...     groups=["a", "a", "a", "a", "b", "b"],
    ...     sampling_period=0.5,
    ... ).round(3)
      recording  n_samples   rmse  accuracy  smoothness
    0         a          4  0.707    29.289       2.494
    1         b          2  0.707    29.289       0.000
    """
    metrics = recording_metrics(
        y_true, y_pred, groups=groups, sampling_period=sampling_period, time=time
    )
    return metrics.to_frame(keep_output=np.ndim(y_pred) == 2)


# --------------------------------------------------------------------------------------------
# Tables of compared models: D.5 normalisation, trade-offs and ranking
# --------------------------------------------------------------------------------------------


@validate_params(
    {"step": [Interval(Integral, 1, 100, closed="both")]},
    prefer_skip_nested_validation=True,
)
def trade_offs(step=10):
    """Accuracy/smoothness trade-offs from "100/0" to "0/100" in steps of ``step`` percent.

    Parameters
    ----------
    step : int, default=10
        Step in percent; it must divide 100.

    Returns
    -------
    trade_offs : list of str

    Examples
    --------
    >>> from skhmmgmr.metrics import trade_offs
    >>> trade_offs(25)
    ['100/0', '75/25', '50/50', '25/75', '0/100']
    """
    if 100 % step:
        raise ValueError(f"step must be a step in percent that divides 100, got {step!r}")
    return [f"{a}/{100 - a}" for a in range(100, -1, -int(step))]


@validate_params(
    {
        "table": [pd.DataFrame],
        "weights": TRADE_OFFS,
        "accuracy": [str],
        "smoothness": [str],
    }
    | COLUMNS,
    prefer_skip_nested_validation=True,
)
def normalize_performance(
    table,
    *,
    weights="50/50",
    model="model",
    recording="recording",
    accuracy="accuracy",
    smoothness="smoothness",
):
    """D.5-normalised performance scores of a table of compared models x recordings.

    For every recording ``x`` and metric ``n``, the thesis scales each model's score by
    ``c_n^x = 1 / sum over the M compared models of Score_n`` (eq. D.5), so the two terms
    become shares of the models' total on that recording and can be added. The scores
    normalised are the ones that enter eq. 7, i.e. the accuracy loss ``|100 - A|`` and
    ``|SM|``; then ``PS = w1 * accuracy_term + w2 * smoothness_term``, lower is better.

    The normalised PS depends on which models are compared: add or remove a model and all
    scores change. Every model must therefore be evaluated on every recording. The terms do
    not depend on the weights, so any trade-off is re-scored from the same table without
    retraining.

    Parameters
    ----------
    table : pandas.DataFrame
        One row per (model, recording) with the raw metrics, e.g. concatenated outputs of
        :func:`evaluate_recordings` with a model column.
    weights : str, pair of float, or list of those, default="50/50"
        Trade-off(s): strings "accuracy/smoothness" in percent (see :func:`trade_offs`) or
        pairs ``(accuracy_weight, smoothness_weight)``.
    model : str, default="model"
        Column naming the model.
    recording : str or list of str, default="recording"
        Column(s) naming the recording; pass ``["recording", "output"]`` for 2-D targets.
    accuracy, smoothness : str, default="accuracy", "smoothness"
        Columns holding the accuracy (%) and smoothness (Nm/s).

    Returns
    -------
    scores : pandas.DataFrame
        One row per (trade-off, model, recording) with the key columns and ``trade_off``,
        ``accuracy_weight``, ``smoothness_weight``, ``accuracy_term``, ``smoothness_term`` and
        ``performance_score``. On each recording the ``accuracy_term`` (and the
        ``smoothness_term``) of the models sum to 1, or are all 0 when every model scores 0.

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.metrics import normalize_performance
    >>> table = pd.DataFrame({
    ...     "model": ["A", "B"], "recording": [1, 1],
    ...     "accuracy": [90.0, 70.0], "smoothness": [3.0, 1.0],
    ... })
    >>> normalize_performance(table, weights=["100/0", "50/50"])[
    ...     ["trade_off", "model", "performance_score"]]
      trade_off model  performance_score
    0     100/0     A               0.25
    1     100/0     B               0.75
    2     50/50     A               0.50
    3     50/50     B               0.50
    """
    parsed = parse_trade_offs(weights)
    keys = [recording] if isinstance(recording, str) else list(recording)
    columns = [model, *keys, accuracy, smoothness]
    missing = [c for c in columns if c not in table.columns]
    if missing:
        raise ValueError(f"table has no column(s) {missing}; it has {list(table.columns)}")
    data = table[columns].reset_index(drop=True)

    duplicated = data.duplicated([model, *keys])
    if duplicated.any():
        row = data.loc[duplicated.idxmax(), [model, *keys]].tolist()
        raise ValueError(f"table has several rows for (model, recording) {tuple(row)}")
    n_models = data[model].nunique()
    counts = data.groupby(keys, sort=False)[model].transform("size")
    if (counts != n_models).any():
        row = data.loc[(counts != n_models).idxmax(), keys].tolist()
        raise ValueError(
            f"recording {tuple(row) if len(row) > 1 else row[0]!r} is evaluated for "
            f"{int(counts[(counts != n_models).idxmax()])} of the {n_models} models; D.5 "
            "normalisation needs every model on every recording"
        )
    for column in (accuracy, smoothness):
        bad = ~np.isfinite(data[column].to_numpy(dtype=float))
        if bad.any():
            row = data.loc[np.flatnonzero(bad)[0], [model, *keys]].tolist()
            raise ValueError(f"{column} is NaN or infinite for (model, recording) {tuple(row)}")

    terms = data[[model, *keys]].copy()
    terms["accuracy_term"] = share_of_sum((100.0 - data[accuracy]).abs(), [data[k] for k in keys])
    terms["smoothness_term"] = share_of_sum(data[smoothness].abs(), [data[k] for k in keys])

    frames = []
    for label, w1, w2 in parsed:
        frame = terms.copy()
        frame.insert(0, "trade_off", label)
        frame.insert(len(frame.columns) - 2, "accuracy_weight", w1)
        frame.insert(len(frame.columns) - 2, "smoothness_weight", w2)
        frame["performance_score"] = w1 * frame["accuracy_term"] + w2 * frame["smoothness_term"]
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


@validate_params(
    {"scores": [pd.DataFrame], "average": ["boolean"], "score": [str], "trade_off": [str]}
    | COLUMNS,
    prefer_skip_nested_validation=True,
)
def rank_models(
    scores,
    *,
    average=False,
    score="performance_score",
    model="model",
    recording="recording",
    trade_off="trade_off",
):
    """Rank compared models per recording, or on the average over recordings (1 = best).

    Parameters
    ----------
    scores : pandas.DataFrame
        Output of :func:`normalize_performance` (or any table with a model, recording and
        score column; the ``trade_off`` column is optional).
    average : bool, default=False
        If False, rank the models on every recording (and trade-off). If True, average the
        score over recordings first and rank the averages.
    score : str, default="performance_score"
        Column to rank on; lower is better.
    model, recording, trade_off : str
        Column names; ``recording`` may be a list of columns.

    Returns
    -------
    ranking : pandas.DataFrame
        If ``average=False``: the input rows with an added ``rank`` column, sorted by
        trade-off, recording and rank. If ``average=True``: one row per (trade-off, model) with
        the mean ``score``, ``n_best`` (on how many recordings the model ranks first, the
        count the thesis uses for feature relevance) and ``rank``, sorted by rank. Ties share
        the best rank.

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.metrics import rank_models
    >>> scores = pd.DataFrame({
    ...     "model": ["A", "B", "A", "B"], "recording": [1, 1, 2, 2],
    ...     "performance_score": [0.2, 0.8, 0.6, 0.4],
    ... })
    >>> rank_models(scores, average=True)
      model  performance_score  n_best  rank
    0     A                0.4       1     1
    1     B                0.6       1     2
    """
    keys = [recording] if isinstance(recording, str) else list(recording)
    outer = [trade_off] if trade_off in scores.columns else []
    missing = [c for c in [model, *keys, score] if c not in scores.columns]
    if missing:
        raise ValueError(f"scores has no column(s) {missing}; it has {list(scores.columns)}")
    ranked = scores.copy()
    ranked["rank"] = (
        ranked.groupby([*outer, *keys], sort=False)[score].rank(method="min").astype(int)
    )
    if not average:
        order = _first_appearance_order(ranked, [*outer, *keys])
        return (
            ranked.assign(_order=order)
            .sort_values(["_order", "rank"], kind="stable")
            .drop(columns="_order")
            .reset_index(drop=True)
        )
    summary = ranked.groupby([*outer, model], sort=False).agg(
        **{score: (score, "mean"), "n_best": ("rank", lambda r: int((r == 1).sum()))}
    )
    summary = summary.reset_index()
    if outer:
        summary["rank"] = summary.groupby(outer, sort=False)[score].rank(method="min")
        order = _first_appearance_order(summary, outer)
    else:
        summary["rank"] = summary[score].rank(method="min")
        order = 0
    summary["rank"] = summary["rank"].astype(int)
    return (
        summary.assign(_order=order)
        .sort_values(["_order", "rank"], kind="stable")
        .drop(columns="_order")
        .reset_index(drop=True)
    )


def _first_appearance_order(frame, columns):
    return frame.groupby(columns, sort=False).ngroup()
