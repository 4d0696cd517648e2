"""``FilterStream``: the causal GMR filter one sample at a time, for a control loop."""

from ._filter import FilterStream
from ._flags import (
    FLAG_MISSING,
    FLAG_NON_FINITE,
    FLAG_OK,
    FLAG_OUTLIER,
    FLAG_RESTARTED,
)

__all__ = [
    "FLAG_MISSING",
    "FLAG_NON_FINITE",
    "FLAG_OK",
    "FLAG_OUTLIER",
    "FLAG_RESTARTED",
    "FilterStream",
]
