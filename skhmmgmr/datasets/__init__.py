"""Driving data: an embedded lane-keeping simulator and loaders for public and own recordings."""

from .._core._panel import to_panel
from .._core._schema import (
    DRIVER,
    FEATURE_NAMES,
    FEATURE_UNITS,
    PREVIEW_FEATURES,
    RECORDING,
    SETTING,
    SPLIT,
    TARGET,
    TIME,
)
from ._base import clear_data_home, get_data_home
from ._calibration import CALIBRATION_BANDS, THESIS_TABLE_C2, calibration_table
from ._comma2k19 import load_comma2k19_segment
from ._comma2k19_sample import load_comma2k19_sample
from ._comma2k19_scan import scan_comma2k19
from ._drive import drive
from ._driver import DRIVER_STYLES, DriverParameters
from ._fetch import COMMA2K19_URL, fetch_comma2k19
from ._horizon import torque_ahead
from ._protocol import make_driving_protocol
from ._recordings import load_recordings
from ._resample import resample_recordings
from ._shift import shift_target
from ._simulator import make_lane_keeping
from ._vehicle import VEHICLE_RANGES, VehicleParameters, draw_vehicle

__all__ = [
    "CALIBRATION_BANDS",
    "DRIVER_STYLES",
    "DriverParameters",
    "THESIS_TABLE_C2",
    "VEHICLE_RANGES",
    "VehicleParameters",
    "calibration_table",
    "drive",
    "draw_vehicle",
    "make_driving_protocol",
    "make_lane_keeping",
    "COMMA2K19_URL",
    "clear_data_home",
    "fetch_comma2k19",
    "get_data_home",
    "load_comma2k19_sample",
    "load_comma2k19_segment",
    "load_recordings",
    "resample_recordings",
    "scan_comma2k19",
    "shift_target",
    "torque_ahead",
    "to_panel",
    "DRIVER",
    "FEATURE_NAMES",
    "FEATURE_UNITS",
    "PREVIEW_FEATURES",
    "RECORDING",
    "SETTING",
    "SPLIT",
    "TARGET",
    "TIME",
]
