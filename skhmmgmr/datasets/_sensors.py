"""Sensor measurement of the simulated states: what a data logger in a real car would record.

The closed loop runs on the true states (the driver sees the world); the logger measures them.
Every directly measured signal gets white noise, an optional slowly drifting error (first-order
Ornstein-Uhlenbeck noise: gyro and accelerometer bias, attitude drift, camera tracking error) and
an optional quantisation. The derivative signals are not measured: as an ECU would, they are
backward differences of the measured (noisy, quantised) signals, smoothed by a first-order
low-pass filter, so that sensor noise is amplified by the differentiation like in a real
recording. The slip angle is computed from the measured lateral velocity (the optical or
GNSS/INS sensor measuring one measures the other).

Magnitudes are typical of the sensor types, not of one product:

- steering angle sensors on the CAN bus (e.g. Bosch LWS, EPS column sensors) report the angle
  with a 0.1 deg resolution;
- automotive MEMS gyros (ESC yaw-rate sensors, IMUs) have a noise of about 0.05-0.2 deg/s RMS in
  a 50-100 Hz bandwidth and a bias instability of a few hundredths of deg/s;
- MEMS accelerometers 0.02-0.1 m/s^2 RMS;
- GNSS/INS and optical (Correvit-type) sensors measure the lateral velocity to about 0.02-0.05
  m/s (slip angle to about 0.1 deg) and the roll angle to a few hundredths of a degree;
- lane cameras measure the lateral offset to 0.02-0.05 m and the heading to about 1e-3 rad, with
  an error correlated over a few frames (tracking filter), growing with the look-ahead distance,
  and the curvature to 1e-4-1e-3 1/m, more uncertain further ahead;
- EPS torsion-bar torque sensors measure the driver torque to a few hundredths of Nm.
"""

import math
import numbers
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from ._driver import coloured_noise

SENSOR_NOISE_LEVELS = {"typical": 1.0}


@dataclass(frozen=True)
class Sensor:
    """Error model of a directly measured signal (SI units)."""

    white: float  # RMS white noise per sample
    drift: float = 0.0  # RMS of the slowly varying (Ornstein-Uhlenbeck) error
    drift_time: float = 1.0  # [s] correlation time of the drift
    resolution: float = 0.0  # quantisation step (0: none)
    kind: str = ""  # sensor type, for the documentation


_DEG = math.pi / 180.0

#: Error models of the directly measured signals, keyed by feature (and target) name.
SENSORS = {
    "steering_wheel_angle": Sensor(0.02 * _DEG, resolution=0.1 * _DEG, kind="steering angle"),
    "lateral_velocity": Sensor(0.03, kind="GNSS/INS or optical"),
    "lateral_acceleration": Sensor(0.05, 0.02, 60.0, kind="MEMS accelerometer"),
    "yaw_rate": Sensor(0.1 * _DEG, 0.03 * _DEG, 60.0, kind="MEMS gyro"),
    "roll_angle": Sensor(0.01 * _DEG, 0.05 * _DEG, 20.0, kind="INS attitude"),
    "lateral_deviation_0m": Sensor(0.01, 0.03, 0.2, kind="lane camera"),
    "heading_deviation_0m": Sensor(3e-4, 1e-3, 0.2, kind="lane camera"),
    "heading_deviation_10m": Sensor(4e-4, 1.5e-3, 0.2, kind="lane camera"),
    "heading_deviation_30m": Sensor(6e-4, 3e-3, 0.2, kind="lane camera"),
    "road_curvature_0m": Sensor(3e-5, 1e-4, 0.3, kind="lane camera"),
    "road_curvature_10m": Sensor(4e-5, 1.5e-4, 0.3, kind="lane camera"),
    "road_curvature_30m": Sensor(6e-5, 3e-4, 0.3, kind="lane camera"),
    "driver_torque": Sensor(0.03, resolution=0.01, kind="EPS torque sensor"),
}

#: Derived signals: (source signal, time constant [s] of the low-pass after the difference).
#: Second derivatives differentiate the already filtered first derivative.
DERIVATIVES = {
    "steering_wheel_velocity": ("steering_wheel_angle", 0.02),
    "steering_wheel_acceleration": ("steering_wheel_velocity", 0.04),
    "yaw_acceleration": ("yaw_rate", 0.04),
    "roll_velocity": ("roll_angle", 0.04),
    "roll_acceleration": ("roll_velocity", 0.04),
}


def check_sensor_noise(sensor_noise):
    """Scale factor of the sensor errors, or None for the clean states."""
    if sensor_noise is None or (isinstance(sensor_noise, str) and sensor_noise == "none"):
        return None
    if isinstance(sensor_noise, str) and sensor_noise in SENSOR_NOISE_LEVELS:
        return SENSOR_NOISE_LEVELS[sensor_noise]
    if (
        isinstance(sensor_noise, numbers.Real)
        and not isinstance(sensor_noise, bool)
        and math.isfinite(sensor_noise)
        and sensor_noise >= 0
    ):
        return float(sensor_noise)
    raise ValueError(
        "sensor_noise must be 'typical', 'none', None or a non-negative scale factor, got "
        f"sensor_noise={sensor_noise!r}."
    )


def ecu_derivative(x, dt, time_constant):
    """Causal derivative: backward difference then a first-order low-pass.

    The first sample's difference is zero (no earlier sample), and the filter starts at rest.

    Parameters
    ----------
    x : ndarray of shape (n_samples,)
        Measured signal.
    dt : float
        Sampling period [s].
    time_constant : float
        Time constant of the low-pass filter [s] (cut-off ``1 / (2 pi time_constant)``).

    Returns
    -------
    derivative : ndarray of shape (n_samples,)
    """
    difference = np.diff(x, prepend=x[:1]) / dt
    a = dt / (time_constant + dt)
    return lfilter([a], [1.0, a - 1.0], difference)


def measure_signal(x, sensor, dt, scale, rng):
    """Measure one signal: add white noise and drift, then quantise."""
    n = x.size
    white = rng.standard_normal(n) * (sensor.white * scale)
    drift = coloured_noise(n, dt, sensor.drift_time, sensor.drift * scale, rng)
    measured = x + white + drift
    step = sensor.resolution * scale
    if step > 0:
        measured = step * np.round(measured / step)
    return measured


def measure(columns, torque, dt, speed, scale, rng):
    """Measure the candidate features and the driver torque.

    Parameters
    ----------
    columns : dict of str to ndarray
        Clean candidate features (true states of the simulation).
    torque : ndarray
        Clean driver torque.
    dt : float
        Sampling period of the logger [s].
    speed : float
        Forward speed [m/s] (to compute the slip angle from the lateral velocity).
    scale : float or None
        Scale factor of every error (noise, drift and resolution); None returns the clean
        states unchanged.
    rng : numpy.random.RandomState
        Draws the sensor errors, in a fixed order (same seed, same measurement).

    Returns
    -------
    measured : dict of str to ndarray
        The features, in the order of ``columns``.
    torque : ndarray
    """
    if scale is None:
        return dict(columns), torque
    measured = {}
    for name, sensor in SENSORS.items():
        clean = torque if name == "driver_torque" else columns[name]
        measured[name] = measure_signal(np.asarray(clean, dtype=float), sensor, dt, scale, rng)
    for name, (source, time_constant) in DERIVATIVES.items():
        measured[name] = ecu_derivative(measured[source], dt, time_constant)
    measured["slip_angle"] = np.arctan2(measured["lateral_velocity"], speed)
    torque = measured.pop("driver_torque")
    return {name: measured[name] for name in columns}, torque
