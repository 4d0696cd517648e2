"""Driving data: an embedded lane-keeping simulator and loaders for public and own recordings."""

from ._schema import (
    DRIVER,
    FEATURE_NAMES,
    FEATURE_UNITS,
    RECORDING,
    SETTING,
    SPLIT,
    TARGET,
    TIME,
)

__all__ = [
    "DRIVER",
    "FEATURE_NAMES",
    "FEATURE_UNITS",
    "RECORDING",
    "SETTING",
    "SPLIT",
    "TARGET",
    "TIME",
]
