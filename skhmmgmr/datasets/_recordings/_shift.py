"""Targets shifted ahead within every recording, for models that estimate the future."""

from numbers import Integral

import numpy as np
import pandas as pd

from ..._core._compat import Interval, validate_params
from ..._core._panel import read_layout


@validate_params(
    {
        "y": ["array-like"],
        "horizon_rows": [Interval(Integral, 0, None, closed="left")],
        "groups": ["array-like", None],
    },
    prefer_skip_nested_validation=True,
)
def shift_target(y, horizon_rows, groups=None):
    """The target ``horizon_rows`` rows ahead, within every recording.

    Row ``t`` of the result holds ``y`` at row ``t + horizon_rows`` of the same recording; the
    last ``horizon_rows`` rows of every recording, whose future lies outside the recording,
    hold NaN (never a value of the next recording). Drop them before fitting, e.g.
    ``keep = ~np.isnan(shifted)``.

    Parameters
    ----------
    y : array-like of shape (n_samples,) or (n_samples, n_outputs)
        The target, rows of a recording contiguous and in time order, or a pandas Series or
        DataFrame whose index has a ``recording`` (and ``time``) level, rows in any order;
        pandas input keeps its index and columns.
    horizon_rows : int
        How many rows ahead (``seconds * sampling_rate``), >= 0.
    groups : array-like of shape (n_samples,), default=None
        Recording id of every row; ``None`` means the ``recording`` level of a pandas index,
        or else one recording.

    Returns
    -------
    shifted : ndarray, pandas Series or DataFrame of the shape of ``y``, float

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr.datasets import shift_target
    >>> shift_target(np.arange(6.0), 2, groups=["a", "a", "a", "b", "b", "b"])
    array([ 2., nan, nan,  5., nan, nan])
    """
    horizon_rows = int(horizon_rows)
    values = np.asarray(y, dtype=float)
    if values.ndim not in (1, 2):
        raise ValueError(f"y must be 1-D or 2-D, got {values.ndim} dimensions")
    # A pandas index with recordings (and time) may hold the rows in any order.
    rows = read_layout(y, groups)
    values = rows.to_filter_order(values)
    recordings = rows.recordings(values.shape[0])
    shifted = np.full_like(values, np.nan)
    for start, stop in zip(recordings.starts, recordings.stops, strict=True):
        if stop - start > horizon_rows:
            shifted[start : stop - horizon_rows] = values[start + horizon_rows : stop]
    shifted = rows.to_caller_order(shifted)
    if isinstance(y, pd.Series):
        return pd.Series(shifted, index=y.index, name=y.name)
    if isinstance(y, pd.DataFrame):
        return pd.DataFrame(shifted, index=y.index, columns=y.columns)
    return shifted
