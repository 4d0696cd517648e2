"""How well a drive kept its lane: the closed-loop metrics of a recording.

Computed on the logged columns of the tidy frame (:func:`skhmmgmr.datasets.drive`,
:func:`skhmmgmr.datasets.make_lane_keeping`), per recording:

- ``lateral_deviation_rms``, ``lateral_deviation_max`` [m]: RMS and largest absolute value of
  ``lateral_deviation_0m`` (the lateral deviation of the front axle from the lane centre);
- ``departures`` [-]: times a wheel leaves the lane, i.e. the deviation's absolute value rises
  above ``(lane_width - vehicle_width) / 2`` (0.85 m for a 1.8 m wide car in a 3.5 m lane); a
  departure ends when the deviation is back inside by ``hysteresis`` (0.1 m), so that sensor
  noise on the line does not count one departure as many;
- ``time_out_of_lane`` [s]: time spent with a wheel out of the lane (rows beyond the limit
  times the sampling period);
- ``heading_error_rms`` [rad]: RMS of ``heading_deviation_0m``;
- ``torque_rms`` [Nm]: RMS of ``driver_torque``;
- ``torque_roughness`` [Nm/s]: the package's smoothness of the torque, the standard deviation
  of its first difference over the time step;
- ``steering_reversal_rate`` [1/min]: reversals of the steering-wheel angle per minute, a
  reversal being a change of direction by at least ``reversal_gap`` (2 deg) from the last
  extreme (the gap method of Östlund et al., 2005, on the angle as logged).

Rows of a manoeuvre (a ``manoeuvre`` column other than ``"lane_keeping"`` or missing: an
intended lane change) leave the departures and the time out of the lane alone.
"""

import math
import numbers

import numpy as np
import pandas as pd

from .._core._compat import FiniteInterval, validate_parameter_constraints, validate_params
from .._core._panel import read_layout
from .._core._schema import MANOEUVRE, RECORDING, TARGET, TIME

LANE_KEEPING_METRICS = (
    "lateral_deviation_rms",
    "lateral_deviation_max",
    "departures",
    "time_out_of_lane",
    "heading_error_rms",
    "torque_rms",
    "torque_roughness",
    "steering_reversal_rate",
)
_COLUMNS = ("lateral_deviation_0m", "heading_deviation_0m", "steering_wheel_angle", TARGET)
DEFAULT_LANE_WIDTH = 3.5


# A width, a distance or an angle: positive and finite.
POSITIVE = [FiniteInterval(numbers.Real, 0, None, closed="neither")]


@validate_params(
    {
        "frame": [pd.DataFrame],
        "lane_width": [*POSITIVE, None],
        "vehicle_width": POSITIVE,
        "hysteresis": POSITIVE,
        "reversal_gap": POSITIVE,
    },
    prefer_skip_nested_validation=True,
)
def lane_keeping_metrics(
    frame,
    *,
    lane_width=None,
    vehicle_width=1.8,
    hysteresis=0.1,
    reversal_gap=math.radians(2.0),
):
    """Lane-keeping metrics of every recording of a drive.

    Parameters
    ----------
    frame : pandas.DataFrame
        Tidy frame of one or several recordings (columns ``recording`` and ``time``, or a
        panel with them in its index), with ``lateral_deviation_0m``,
        ``heading_deviation_0m``, ``steering_wheel_angle`` and ``driver_torque``; optionally
        ``manoeuvre``.
    lane_width : float, default=None
        Width of the lane [m]; by default ``frame.attrs["lane_width"]`` (the simulator's
        frames say it: 5 m in the ``"wide_lane"`` scenario), else 3.5.
    vehicle_width : float, default=1.8
        Width of the car [m]; a wheel leaves the lane when the lateral deviation exceeds
        ``(lane_width - vehicle_width) / 2``.
    hysteresis : float, default=0.1
        How far back inside the lane [m] the deviation must come to end a departure.
    reversal_gap : float, default=radians(2)
        Smallest change of direction of the steering-wheel angle [rad] counted as a reversal.

    Returns
    -------
    metrics : pandas.Series or pandas.DataFrame
        The metrics of the module's docstring (:data:`LANE_KEEPING_METRICS`): a Series for one
        recording, else a DataFrame with one row per recording (index ``recording``, in order
        of appearance).

    Examples
    --------
    >>> from skhmmgmr.datasets import make_lane_keeping
    >>> from skhmmgmr.metrics import lane_keeping_metrics
    >>> drive = make_lane_keeping(30.0, sampling_rate=20.0, random_state=0)
    >>> metrics = lane_keeping_metrics(drive)
    >>> list(metrics.index[:3])
    ['lateral_deviation_rms', 'lateral_deviation_max', 'departures']
    >>> bool(metrics["lateral_deviation_max"] < 1.75)
    True
    """
    if lane_width is None:
        lane_width = frame.attrs.get("lane_width", DEFAULT_LANE_WIDTH)
        validate_parameter_constraints(
            {"lane_width": POSITIVE},
            {"lane_width": lane_width},
            caller_name="lane_keeping_metrics (read from frame.attrs)",
        )
    lane_width, vehicle_width = float(lane_width), float(vehicle_width)
    reversal_gap, hysteresis = float(reversal_gap), float(hysteresis)
    if vehicle_width >= lane_width:
        raise ValueError(
            f"vehicle_width={vehicle_width} must be smaller than lane_width={lane_width}."
        )
    missing = [c for c in _COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(
            f"frame lacks the column(s) {missing}; its columns are {list(frame.columns)}."
        )
    groups = frame[RECORDING].to_numpy() if RECORDING in frame.columns else None
    time = frame[TIME].to_numpy(dtype=float) if TIME in frame.columns else None
    layout = read_layout(frame, groups, time)
    if layout.time is None:
        raise ValueError(f"frame has no {TIME!r} column or index level: the metrics need the time.")
    ordered = layout.to_filter_order(frame)
    recordings = layout.recordings(len(ordered), min_length=2)
    limit = (lane_width - vehicle_width) / 2.0
    rows = []
    for rec, part in recordings.slices():
        values = {c: ordered[c].to_numpy(dtype=float)[part] for c in _COLUMNS}
        for column, v in values.items():
            if not np.isfinite(v).all():
                raise ValueError(f"{column} holds NaN or infinity in recording {rec!r}.")
        period = float(np.median(np.diff(layout.time[part])))
        keeping = np.ones(len(values[TARGET]), dtype=bool)
        if MANOEUVRE in ordered.columns:
            manoeuvre = ordered[MANOEUVRE].to_numpy()[part]
            keeping = pd.isna(manoeuvre) | (manoeuvre == "lane_keeping")
        deviation = values["lateral_deviation_0m"]
        out = (np.abs(deviation) > limit) & keeping
        torque = values[TARGET]
        rows.append(
            {
                "lateral_deviation_rms": _rms(deviation),
                "lateral_deviation_max": float(np.abs(deviation).max()),
                "departures": departures(np.abs(deviation), keeping, limit, hysteresis),
                "time_out_of_lane": float(np.count_nonzero(out) * period),
                "heading_error_rms": _rms(values["heading_deviation_0m"]),
                "torque_rms": _rms(torque),
                "torque_roughness": float(np.std(np.diff(torque) / period)),
                "steering_reversal_rate": steering_reversals(
                    values["steering_wheel_angle"], reversal_gap
                )
                / (len(torque) * period / 60.0),
            }
        )
    table = pd.DataFrame(rows, index=pd.Index(recordings.ids, name=RECORDING))
    table = table[list(LANE_KEEPING_METRICS)]
    return table.iloc[0].rename(recordings.ids[0]) if len(table) == 1 else table


def _rms(values):
    return float(np.sqrt(np.mean(np.square(values))))


def departures(deviation, keeping, limit, hysteresis):
    """Number of departures: ``deviation`` rising above ``limit`` on a lane-keeping row, each
    ending once ``deviation`` is below ``limit - hysteresis``."""
    count, out = 0, False
    for value, counted in zip(deviation, keeping, strict=True):
        if not out and value > limit and counted:
            count, out = count + 1, True
        elif out and value < limit - hysteresis:
            out = False
    return count


def steering_reversals(angle, gap):
    """Number of reversals of ``angle`` by at least ``gap``: the direction is set by the
    first move of ``gap`` from the start; a reversal is a move of ``gap`` back from the
    extreme reached since the last one."""
    count, direction = 0, 0
    extreme = start = float(angle[0])
    for value in angle[1:]:
        if direction == 0:
            if abs(value - start) >= gap:
                direction, extreme = (1 if value > start else -1), value
            continue
        if (value - extreme) * direction > 0:
            extreme = value
        elif (extreme - value) * direction >= gap:
            count += 1
            direction, extreme = -direction, value
    return count
