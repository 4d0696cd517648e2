"""The embedded closed-loop lane-keeping simulator: a road section, a virtual driver (or a
model) at the wheel, the steering system and the vehicle, and the sensors that log them.

Private: the public names are re-exported by :mod:`skhmmgmr.datasets`.
"""

from ._calibration import CALIBRATION_BANDS, THESIS_TABLE_C2, calibration_table
from ._drive import drive
from ._driver import DRIVER_STYLES, DriverParameters
from ._horizon import torque_ahead
from ._lane_keeping import make_lane_keeping
from ._protocol import make_driving_protocol
from ._vehicle import VEHICLE_RANGES, VehicleParameters, draw_vehicle

__all__ = [
    "CALIBRATION_BANDS",
    "DRIVER_STYLES",
    "DriverParameters",
    "THESIS_TABLE_C2",
    "VEHICLE_RANGES",
    "VehicleParameters",
    "calibration_table",
    "draw_vehicle",
    "drive",
    "make_driving_protocol",
    "make_lane_keeping",
    "torque_ahead",
]
