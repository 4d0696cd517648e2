"""``FilterStream``: the causal GMR filter one sample at a time, for a control loop."""

from ._filter import (
    FLAG_MISSING,
    FLAG_NON_FINITE,
    FLAG_OK,
    FLAG_OUTLIER,
    FLAG_RESTARTED,
    FilterStream,
)

__all__ = [
    "FLAG_MISSING",
    "FLAG_NON_FINITE",
    "FLAG_OK",
    "FLAG_OUTLIER",
    "FLAG_RESTARTED",
    "FilterStream",
]
