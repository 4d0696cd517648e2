"""Private helpers of :mod:`skhmmgmr.metrics`: input checks and the per-recording metric table."""

import numbers
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd
from sklearn.utils.validation import check_array

from .._core._compat import FiniteInterval, StrOptions
from .._core._panel import check_named_lengths, in_filter_order
from .._core._validation import binary_unit, check_sampling_period, constant_to_round_off

# Constraints of the parameters the metric functions, the scorers and the searches share
# (scikit-learn's validate_params and _parameter_constraints).
WEIGHT = [FiniteInterval(numbers.Real, 0, None, closed="left")]
SAMPLING_PERIOD = [FiniteInterval(numbers.Real, 0, None, closed="neither"), None]
SCALE = [FiniteInterval(numbers.Real, 0, None, closed="neither"), Mapping, pd.Series, None]
MULTIOUTPUT = [StrOptions({"raw_values", "uniform_average"}), "array-like"]
PREDICT_MODE = [StrOptions({"auto", "groups", "per_recording"})]
# One trade-off ("70/30" or a pair of weights) or a list of them.
TRADE_OFFS = [str, list, tuple]


def as_2d_target(y, name):
    """Validate a target/estimate array, allowing NaN (checked per recording later)."""
    y = check_array(
        y,
        ensure_2d=False,
        ensure_all_finite=False,
        dtype="numeric",
        input_name=name,
        ensure_min_samples=1,
    )
    if y.ndim == 1:
        return y.astype(float, copy=False).reshape(-1, 1)
    if y.ndim != 2:
        raise ValueError(f"{name} must be 1-D or 2-D, got {y.ndim} dimensions")
    return y.astype(float, copy=False)


def check_sampling(sampling_period, time, n_samples):
    """Return the validated sampling period or time array; exactly one must be given."""
    if sampling_period is None and time is None:
        raise ValueError(
            "smoothness needs the time step: give sampling_period (seconds between rows) "
            "or time (one time stamp in seconds per row)"
        )
    if sampling_period is not None and time is not None:
        raise ValueError("give either sampling_period or time, not both")
    if sampling_period is not None:
        return check_sampling_period(sampling_period), None
    time = np.asarray(time, dtype=float)
    if time.ndim != 1:
        raise ValueError(f"time must be 1-D (one time stamp per row), got shape {time.shape}")
    check_named_lengths(y_pred=np.empty(n_samples), time=time)
    return None, time


@dataclass
class RecordingMetrics:
    """Metrics of every recording (rows) and output (columns)."""

    ids: np.ndarray
    n_samples: np.ndarray
    rmse: np.ndarray | None
    accuracy: np.ndarray | None
    smoothness: np.ndarray | None

    def to_frame(self, keep_output):
        n_rec, n_out = next(
            m.shape for m in (self.rmse, self.accuracy, self.smoothness) if m is not None
        )
        frame = {"recording": np.repeat(self.ids, n_out)}
        if keep_output:
            frame["output"] = np.tile(np.arange(n_out), n_rec)
        frame["n_samples"] = np.repeat(self.n_samples, n_out)
        for name in ("rmse", "accuracy", "smoothness"):
            values = getattr(self, name)
            if values is not None:
                frame[name] = values.ravel()
        return pd.DataFrame(frame)


def recording_metrics(
    y_true,
    y_pred,
    *,
    groups=None,
    sampling_period=None,
    time=None,
    accuracy=True,
    smoothness=True,
):
    """Compute RMSE, accuracy and smoothness per recording and output.

    ``y_true`` may be None when only the smoothness is wanted. The recordings come from
    ``groups``, else from the ``recording`` level of the index of ``y_true`` (of ``y_pred``
    when ``y_true`` is no pandas object) as every scorer reads them: a panel
    (:func:`skhmmgmr.datasets.to_panel`), whose rows may come in any order, the other array
    paired by position; its ``time`` level gives the time steps when neither
    ``sampling_period`` nor ``time`` is given. The arrays are returned with shape
    (n_recordings, n_outputs), the recordings in order of first appearance.
    """
    check_named_lengths(y_true=y_true, y_pred=y_pred, groups=groups, time=time)
    rows = y_true if isinstance(y_true, pd.Series | pd.DataFrame) else y_pred

    def in_order(layout, _, y_true, y_pred):
        steps = layout.time if time is not None or sampling_period is None else None
        return _recording_metrics(
            y_true, y_pred, layout, sampling_period, steps, accuracy=accuracy, smoothness=smoothness
        )

    return in_filter_order(
        in_order, rows, groups, time=time, rows={"y_true": y_true, "y_pred": y_pred}
    )


def _recording_metrics(y_true, y_pred, layout, sampling_period, time, *, accuracy, smoothness):
    """:func:`recording_metrics` of rows in filter order, their ``layout`` read."""
    y_pred = as_2d_target(y_pred, "y_pred")
    n_samples, n_outputs = y_pred.shape
    if accuracy:
        y_true = as_2d_target(y_true, "y_true")
        if y_true.shape[1] != n_outputs:
            raise ValueError(f"y_true has {y_true.shape[1]} output(s) but y_pred has {n_outputs}")
    if smoothness:
        sampling_period, time = check_sampling(sampling_period, time, n_samples)
    recordings = layout.recordings(n_samples, min_length=2 if smoothness else 1)

    n_rec = len(recordings)
    rmse = np.empty((n_rec, n_outputs)) if accuracy else None
    acc = np.empty((n_rec, n_outputs)) if accuracy else None
    smooth = np.empty((n_rec, n_outputs)) if smoothness else None
    # Squares and standard deviations are taken in units of a power of two near the largest
    # value of each output (exact): no unit overflows or underflows them.
    for i, (rec_id, rows) in enumerate(recordings.slices()):
        pred = y_pred[rows]
        _check_finite(pred, "y_pred", rec_id)
        if accuracy:
            true = y_true[rows]
            _check_finite(true, "y_true", rec_id)
            true_magnitude = np.abs(true).max(axis=0)
            true_unit = binary_unit(true_magnitude)
            spread = (true / true_unit).std(axis=0)
            constant = constant_to_round_off(spread, true_magnitude / true_unit)
            spread *= true_unit
            if np.any(constant):
                raise ValueError(
                    f"y_true is constant in recording {rec_id!r} (standard deviation "
                    f"{spread[np.flatnonzero(constant)[0]]:.3g}, round-off for its values), "
                    "so its accuracy (1 - RMSE / SD) * 100 is undefined"
                )
            unit = binary_unit(np.maximum(true_magnitude, np.abs(pred).max(axis=0)))
            rmse[i] = np.sqrt(np.mean((pred / unit - true / unit) ** 2, axis=0)) * unit
            acc[i] = (1.0 - rmse[i] / spread) * 100.0
        if smoothness:
            steps = sampling_period if time is None else np.diff(time[rows])[:, None]
            unit = binary_unit(np.abs(pred).max(axis=0))
            smooth[i] = (np.diff(pred / unit, axis=0) / steps).std(axis=0) * unit
    return RecordingMetrics(
        ids=recordings.ids,
        n_samples=recordings.lengths,
        rmse=rmse,
        accuracy=acc,
        smoothness=smooth,
    )


def _check_finite(values, name, rec_id):
    bad = ~np.isfinite(values)
    if bad.any():
        raise ValueError(
            f"{name} contains {int(bad.sum())} NaN or infinite value(s) in recording {rec_id!r}"
        )


def average(values, multioutput):
    """Average (n_recordings, n_outputs) values over recordings, then over outputs."""
    per_output = values.mean(axis=0)
    if isinstance(multioutput, str):
        if multioutput == "raw_values":
            return per_output
        if multioutput == "uniform_average":
            return float(per_output.mean())
        raise ValueError(
            "multioutput must be 'raw_values', 'uniform_average' or an array of output "
            f"weights, got {multioutput!r}"
        )
    weights = np.asarray(multioutput, dtype=float)
    if weights.shape != per_output.shape:
        raise ValueError(
            f"multioutput has {weights.size} weight(s) but there are {per_output.size} outputs"
        )
    return float(np.average(per_output, weights=weights))


def recording_scale(scale, ids, name):
    """Broadcast a scalar or a mapping ``recording -> scale`` to one value per recording."""
    if scale is None:
        return np.ones(len(ids))
    if isinstance(scale, numbers.Real):
        values = np.full(len(ids), float(scale))
    else:
        mapping = scale.to_dict() if isinstance(scale, pd.Series) else dict(scale)
        missing = [rec for rec in ids if rec not in mapping]
        if missing:
            raise ValueError(f"{name} has no value for recording(s) {missing!r}")
        values = np.array([mapping[rec] for rec in ids], dtype=float)
    if not np.all(np.isfinite(values)) or np.any(values <= 0):
        raise ValueError(f"{name} must be positive and finite, got {scale!r}")
    return values


def parse_trade_off(trade_off):
    """Return ``(label, accuracy_weight, smoothness_weight)`` for "70/30" or (0.7, 0.3)."""
    if isinstance(trade_off, str):
        parts = trade_off.split("/")
        try:
            w1, w2 = (float(p) / 100.0 for p in parts)
        except ValueError:
            raise ValueError(
                f"a trade-off string reads 'accuracy/smoothness' in percent, e.g. '70/30'; "
                f"got {trade_off!r}"
            ) from None
        label = trade_off
    else:
        try:
            w1, w2 = (float(w) for w in trade_off)
        except (TypeError, ValueError):
            raise ValueError(
                "weights must be a trade-off string such as '70/30', a pair "
                f"(accuracy_weight, smoothness_weight) or a list of those; got {trade_off!r}"
            ) from None
        label = f"{round(100 * w1, 6):g}/{round(100 * w2, 6):g}"
    if min(w1, w2) < 0 or not np.isfinite([w1, w2]).all():
        raise ValueError(f"trade-off weights must be finite and non-negative, got {trade_off!r}")
    if w1 + w2 == 0:
        raise ValueError(
            f"trade-off {trade_off!r} gives both the accuracy and the smoothness weight 0, so "
            "every model would score 0; give one of them a weight"
        )
    return label, w1, w2


def parse_trade_offs(weights):
    """Accept one trade-off or a list of them; return a list of parsed trade-offs."""
    single = isinstance(weights, str) or (
        len(weights) == 2 and all(isinstance(w, numbers.Real) for w in weights)
    )
    parsed = [parse_trade_off(weights)] if single else [parse_trade_off(w) for w in weights]
    if not parsed:
        raise ValueError("weights holds no trade-off")
    return parsed


def share_of_sum(values, keys):
    """Divide every value by the sum over its ``keys`` block (D.5); 0 where the sum is 0."""
    totals = values.groupby(keys, sort=False, dropna=False).transform("sum")
    shares = values / totals.where(totals != 0)
    return shares.fillna(0.0)


def check_some_weight(accuracy_weight, smoothness_weight):
    """Refuse a trade-off whose two weights (each checked against :data:`WEIGHT`) are 0."""
    if accuracy_weight == 0 and smoothness_weight == 0:
        raise ValueError("accuracy_weight and smoothness_weight are both 0; give one a weight")


def performance_per_recording(
    metrics, accuracy_weight, smoothness_weight, accuracy_scale, smoothness_scale
):
    """Eq. 7 per recording and output, each term divided by its reference scale."""
    n_rec = len(metrics.ids)
    n_outputs = next(m.shape[1] for m in (metrics.accuracy, metrics.smoothness) if m is not None)
    score = np.zeros((n_rec, n_outputs))
    if accuracy_weight > 0:
        scale = recording_scale(accuracy_scale, metrics.ids, "accuracy_scale")[:, None]
        score += accuracy_weight * np.abs(100.0 - metrics.accuracy) / scale
    if smoothness_weight > 0:
        scale = recording_scale(smoothness_scale, metrics.ids, "smoothness_scale")[:, None]
        score += smoothness_weight * np.abs(metrics.smoothness) / scale
    return score
