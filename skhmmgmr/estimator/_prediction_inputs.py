"""The inputs of a prediction: the rows in filter order, their recordings, the standardised
values, and the rows that miss a value (read once for the filter and the read-out)."""

import warnings

from sklearn.utils.validation import check_is_fitted, validate_data

from .._core._panel import read_row_order
from .._core._sequences import as_recordings
from .._core._validation import check_finite, column_names_of
from .._hmm._gmr import read_missing
from .._hmm._stale_inputs import stale_noise_for


def read_inputs(estimator, X, groups, time):
    """``(standardized, recordings, rows, missing)`` of the inputs ``X`` of a fitted
    :class:`~skhmmgmr.HMMGMRRegressor`: ``rows`` (:func:`~skhmmgmr._core._panel.read_row_order`)
    puts results back in the caller's order, ``missing`` is
    :func:`~skhmmgmr._hmm._gmr.read_missing` of the standardised rows."""
    check_is_fitted(estimator)
    rows = read_row_order(X, groups, time)
    X = validate_data(
        estimator, rows.to_filter_order(X), reset=False, ensure_all_finite=False, dtype=float
    )
    if rows.groups is None:
        warn_if_one_long_recording(estimator, X.shape[0])
    recordings = as_recordings(rows.groups, X.shape[0], time=rows.time)
    names = column_names_of(estimator, X.shape[1])
    allow_nan = estimator.missing_values != "error"
    check_finite(X, name="X", column_names=names, recordings=recordings, allow_nan=allow_nan)
    model = estimator.model_
    standardized = model.standardization.inputs(X)
    noise = stale_noise_for(model, estimator.missing_values)
    return standardized, recordings, rows, read_missing(standardized, recordings, noise)


def warn_if_one_long_recording(estimator, n_samples):
    """Warn when ``n_samples`` rows without recordings outnumber the longest training
    recording of ``estimator`` (its ``longest_recording_``)."""
    longest = getattr(estimator, "longest_recording_", None)
    if longest is not None and n_samples > longest:
        warnings.warn(
            f"{n_samples} rows without groups are filtered as ONE recording, longer than "
            f"the longest training recording ({longest} rows). If they hold several "
            "recordings, pass groups=<recording id per row>, or give X a pandas index with "
            "a 'recording' level (skhmmgmr.datasets.to_panel), so that the filter restarts "
            "at every recording.",
            UserWarning,
            stacklevel=3,
        )


# Rows a fit reads as one recording without a word: more is longer than any one drive of the
# thesis' protocol (5-minute sections at 100 Hz are 30,000 rows) by far.
ONE_RECORDING_ROWS = 50_000


def warn_if_fitted_as_one_recording(n_samples):
    """Warn when a fit gets ``n_samples`` rows, more than :data:`ONE_RECORDING_ROWS`, with
    neither ``groups`` nor a recording index: they are fitted as one recording."""
    if n_samples > ONE_RECORDING_ROWS:
        warnings.warn(
            f"{n_samples} rows without groups are fitted as ONE recording. If they hold "
            "several recordings, pass groups=<recording id per row>, or give X a pandas index "
            "with a 'recording' level (skhmmgmr.datasets.to_panel); if they are one "
            "recording, say so with groups=<the same id on every row>, which also lets "
            "predict warn about longer inputs.",
            UserWarning,
            stacklevel=3,
        )
