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


def draw_errors(n, dt, scale, rng):
    """The errors of every signal of :data:`SENSORS` over ``n`` samples, ``(white noise,
    drift)`` arrays, drawn in a fixed order (that of :func:`measure`)."""
    errors = {}
    for name, sensor in SENSORS.items():
        white = rng.standard_normal(n) * (sensor.white * scale)
        errors[name] = white, coloured_noise(n, dt, sensor.drift_time, sensor.drift * scale, rng)
    return errors


def with_errors(x, white, drift, sensor, scale):
    """A signal (array or number) as its sensor reads it: plus its errors, quantised."""
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
    errors = draw_errors(len(torque), dt, scale, rng)
    measured = {}
    for name, sensor in SENSORS.items():
        clean = torque if name == "driver_torque" else columns[name]
        clean = np.asarray(clean, dtype=float)
        measured[name] = with_errors(clean, *errors[name], sensor, scale)
    for name, (source, time_constant) in DERIVATIVES.items():
        measured[name] = ecu_derivative(measured[source], dt, time_constant)
    measured["slip_angle"] = np.arctan2(measured["lateral_velocity"], speed)
    torque = measured.pop("driver_torque")
    return {name: measured[name] for name in columns}, torque


class SensorStream:
    """The logger of :func:`measure`, one sample at a time: the same errors (drawn beforehand
    by :func:`draw_errors`), the same quantisation and the same causal ECU derivatives, so that
    a closed loop can feed a driver model what the logger would record.

    Parameters
    ----------
    names : sequence of str
        Output order of the measured features.
    errors : dict of str to ndarray, or None
        :func:`draw_errors`' output; ``None`` (with ``scale=None``) measures the clean states.
    dt, speed, scale : float
        As for :func:`measure`.
    """

    def __init__(self, names, errors, dt, speed, scale):
        self.names, self.errors, self.dt, self.speed, self.scale = names, errors, dt, speed, scale
        self._gains = {name: dt / (tc + dt) for name, (_, tc) in DERIVATIVES.items()}
        self._previous = {}  # last measured value of every differentiated source
        self._filtered = dict.fromkeys(DERIVATIVES, 0.0)

    def features(self, i, columns):
        """The measured features of sample ``i`` from the clean ``columns`` (a dict)."""
        if self.scale is None:
            return np.array([columns[name] for name in self.names])
        measured = {
            name: self._read(name, sensor, i, columns[name])
            for name, sensor in SENSORS.items()
            if name != "driver_torque"
        }
        for name, (source, _) in DERIVATIVES.items():
            value = measured[source]
            previous = self._previous.get(source, value)  # the first difference is zero
            self._previous[source] = value
            gain = self._gains[name]
            # lfilter([gain], [1, gain - 1]) of the backward difference, term by term
            self._filtered[name] = (
                gain * ((value - previous) / self.dt) - (gain - 1.0) * (self._filtered[name])
            )
            measured[name] = self._filtered[name]
        measured["slip_angle"] = math.atan2(measured["lateral_velocity"], self.speed)
        return np.array([measured[name] for name in self.names])

    def continue_from(self, row):
        """Go on after a sample the logger measured: the next sample's ECU derivatives
        difference from ``row``'s measured signals and filter on from its derivatives, as
        :func:`measure` does from one row to the next.

        Parameters
        ----------
        row : mapping of str to float
            The measured features of the sample before, by name (all the signals of
            :data:`DERIVATIVES` and their sources).

        Returns
        -------
        self : SensorStream
        """
        if self.scale is not None:
            for name, (source, _) in DERIVATIVES.items():
                self._previous[source] = float(row[source])
                self._filtered[name] = float(row[name])
        return self

    def torque(self, i, torque):
        """The driver torque of sample ``i`` as the torque sensor reads it."""
        if self.scale is None:
            return torque
        return self._read("driver_torque", SENSORS["driver_torque"], i, torque)

    def _read(self, name, sensor, i, value):
        white, drift = self.errors[name]
        return float(with_errors(value, white[i], drift[i], sensor, self.scale))
