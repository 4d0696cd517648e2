"""Driving data: an embedded lane-keeping simulator and loaders for public and own recordings."""

from ._base import clear_data_home, get_data_home
from ._comma2k19 import load_comma2k19_segment
from ._fetch import COMMA2K19_URL, fetch_comma2k19
from ._recordings import load_recordings
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
    "COMMA2K19_URL",
    "clear_data_home",
    "fetch_comma2k19",
    "get_data_home",
    "load_comma2k19_segment",
    "load_recordings",
    "DRIVER",
    "FEATURE_NAMES",
    "FEATURE_UNITS",
    "RECORDING",
    "SETTING",
    "SPLIT",
    "TARGET",
    "TIME",
]
