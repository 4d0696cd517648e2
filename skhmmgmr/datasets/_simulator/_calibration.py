"""Driver statistics of the thesis' Table C.2, against which the simulator is calibrated."""

import numpy as np
import pandas as pd

from ..._core._compat import StrOptions, validate_params
from ..._core._schema import DRIVER, RECORDING, SETTING, TARGET

# Bands (around Table C.2 of the thesis) that a 5-minute setting-7 highway section meets for
# every driver style; checked by the test-suite. Angles in degrees.
CALIBRATION_BANDS = {
    "rms_torque": (1.0, 2.5),
    "max_torque": (2.5, 8.0),
    "rms_lateral_deviation": (0.05, 0.6),
    "max_lateral_deviation": (0.1, 1.75),
    "rms_lateral_acceleration": (0.5, 1.5),
    "rms_steering_wheel_angle": (4.0, 12.0),
    "max_steering_wheel_angle": (10.0, 40.0),
}

# Table C.2 of the thesis (IPG CarMaker virtual drivers, training data).
THESIS_TABLE_C2 = pd.DataFrame(
    {
        "defensive": [
            1.6705,
            4.2637,
            0.4131,
            1.1285,
            0.0626,
            0.9998,
            7.1144,
            24.7497,
            6.5095,
            68.0953,
        ],
        "aggressive": [
            1.6409,
            4.0869,
            0.4665,
            1.4975,
            0.0607,
            0.9653,
            6.8679,
            22.7767,
            6.1365,
            170.187,
        ],
    },
    index=[
        "rms_torque",
        "max_torque",
        "rms_lateral_deviation",
        "max_lateral_deviation",
        "rms_lateral_velocity",
        "rms_lateral_acceleration",
        "rms_steering_wheel_angle",
        "max_steering_wheel_angle",
        "rms_steering_wheel_velocity",
        "max_steering_wheel_velocity",
    ],
)


@validate_params(
    {"frame": [pd.DataFrame], "by": [StrOptions({RECORDING, DRIVER})]},
    prefer_skip_nested_validation=True,
)
def calibration_table(frame, by="recording"):
    """Driver statistics of Table C.2 (RMS and max of torque, deviation, angle...).

    Parameters
    ----------
    frame : pandas.DataFrame
        Output of :func:`make_lane_keeping` or :func:`make_driving_protocol`.
    by : {"recording", "driver"}, default="recording"
        Group the samples per recording or pool them per driver (as Table C.2 does).

    Returns
    -------
    table : pandas.DataFrame
        One row per group; torque in Nm, deviation in m, velocities in m/s, accelerations in
        m/s^2, steering-wheel angle in deg and its velocity in deg/s. Compare with
        :data:`THESIS_TABLE_C2` and :data:`CALIBRATION_BANDS`.

    Examples
    --------
    >>> from skhmmgmr.datasets import calibration_table, make_lane_keeping
    >>> table = calibration_table(make_lane_keeping(duration=20.0, random_state=0))
    >>> list(table.columns[:2])
    ['driver', 'setting']
    """

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x))))

    def peak(x):
        return float(np.max(np.abs(x)))

    rows = {}
    for key, group in frame.groupby(by, sort=False):
        angle = np.degrees(group["steering_wheel_angle"].to_numpy())
        rate = np.degrees(group["steering_wheel_velocity"].to_numpy())
        deviation = group["lateral_deviation_0m"].to_numpy()
        torque = group[TARGET].to_numpy()
        rows[key] = {
            DRIVER: group[DRIVER].iloc[0] if by == RECORDING else key,
            SETTING: group[SETTING].iloc[0] if by == RECORDING else "all",
            "rms_torque": rms(torque),
            "max_torque": peak(torque),
            "rms_lateral_deviation": rms(deviation),
            "max_lateral_deviation": peak(deviation),
            "rms_lateral_velocity": rms(group["lateral_velocity"]),
            "rms_lateral_acceleration": rms(group["lateral_acceleration"]),
            "rms_steering_wheel_angle": rms(angle),
            "max_steering_wheel_angle": peak(angle),
            "rms_steering_wheel_velocity": rms(rate),
            "max_steering_wheel_velocity": peak(rate),
        }
    table = pd.DataFrame.from_dict(rows, orient="index")
    table.index.name = by
    return table
