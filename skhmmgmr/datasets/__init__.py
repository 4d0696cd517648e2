"""Driving data: an embedded lane-keeping simulator and loaders for public and own recordings."""

from .._core._panel import to_panel
from .._core._schema import (
    DRIVER,
    DRIVER_MODEL_FEATURES,
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
from ._comma2k19 import (
    COMMA2K19_URL,
    fetch_comma2k19,
    load_comma2k19_sample,
    load_comma2k19_segment,
    scan_comma2k19,
)
from ._recordings import load_recordings, resample_recordings, shift_target
from ._simulator import (
    CALIBRATION_BANDS,
    DRIVER_STYLES,
    THESIS_TABLE_C2,
    VEHICLE_RANGES,
    DriverParameters,
    VehicleParameters,
    calibration_table,
    draw_vehicle,
    drive,
    make_driving_protocol,
    make_lane_keeping,
    torque_ahead,
)

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
    "DRIVER_MODEL_FEATURES",
    "FEATURE_NAMES",
    "FEATURE_UNITS",
    "PREVIEW_FEATURES",
    "RECORDING",
    "SETTING",
    "SPLIT",
    "TARGET",
    "TIME",
]
