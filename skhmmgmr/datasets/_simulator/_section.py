"""A section of the simulator: which one (the nine arguments :func:`make_lane_keeping`,
:func:`drive` and :func:`torque_ahead` share, checked once in :class:`SectionSpec`) and the
section drawn from them before anyone drives it (:class:`Section`: its road, manoeuvres, the
human's parameters and noises), with the tidy frame of what was driven on it.
"""

import math
from dataclasses import InitVar, asdict, dataclass, field, fields
from numbers import Integral, Real

import numpy as np
from sklearn.utils import check_random_state

from ..._core._compat import (
    FiniteInterval,
    Interval,
    StrOptions,
    validate_parameter_constraints,
)
from ..._core._schema import (
    CROSSING_TIME,
    DRIVER,
    FEATURE_NAMES,
    MANOEUVRE,
    RECORDING,
    SETTING,
    SPLIT,
    STEERING_PERTURBATION,
    TARGET,
    TIME,
)
from .._frame import tidy_frame
from ._closed_loop import LOG_COLUMNS, simulate
from ._driver import check_driver, draw_remnants, sample_driver
from ._perturbation import multisine, multisine_frequencies, perturbation_stream
from ._road import SETTINGS, make_road, manoeuvre_of, manoeuvre_offsets
from ._sensors import SENSOR_NOISE_LEVELS, check_sensor_noise
from ._vehicle import VehicleParameters, check_vehicle

SCENARIOS = ("highway", "sharp_corners", "lane_change", "evasive", "wide_lane")
INTERNAL_RATE = 200.0  # [Hz] minimum integration rate
MIN_SPEED_KMH = 5.0  # below it, the constant-speed single-track model's slip angles lose meaning
# What one section may ask for: integration steps (the noises of every step are held, as arrays
# and lists of floats, about 100 bytes a step: 7 hours at 100 Hz) and road (about 1 kB a metre).
MAX_STEPS = 5_000_000
MAX_ROAD = 1_000_000.0  # [m]
PREVIEW_DISTANCES = (10.0, 30.0)  # [m] road sensors ahead of the front axle


def _checked(*constraints):
    """A field of :class:`SectionSpec` and what it must be (scikit-learn's constraints)."""
    return field(metadata={"constraints": list(constraints)})


@dataclass(frozen=True)
class SectionSpec:
    """The section to simulate: the arguments the simulator's functions share, checked once.

    Built from a public function's arguments (:meth:`of`) and checked on construction, every
    error naming the argument (or the number of samples); frozen, so that what was checked is
    what is simulated. ``sensor_noise`` holds the scale of the sensor errors (``None``: the
    true states), ``vehicle`` the :class:`VehicleParameters` and ``perturbation`` the RMS of
    the perturbation experiment (``None``: none); the numbers are floats.
    See :func:`make_lane_keeping` for their meaning.
    """

    duration: float = _checked(FiniteInterval(Real, 0, None, closed="neither"))
    setting: int = _checked(Interval(Integral, min(SETTINGS), max(SETTINGS), closed="both"))
    speed_kmh: float = _checked(FiniteInterval(Real, MIN_SPEED_KMH, None, closed="left"))
    sampling_rate: float = _checked(FiniteInterval(Real, 0, None, closed="neither"))
    scenario: str = _checked(StrOptions(set(SCENARIOS)))
    random_state: object = _checked("random_state")
    road_random_state: object = _checked("random_state")
    sensor_noise: object = _checked(
        StrOptions({"none", *SENSOR_NOISE_LEVELS}),
        FiniteInterval(Real, 0, None, closed="left"),
        None,
    )
    vehicle: object = _checked(
        None,
        StrOptions({"default"}),
        Interval(Integral, 0, 2**32 - 1, closed="both"),
        dict,
        VehicleParameters,
    )
    perturbation: object = field(
        default=None,
        metadata={"constraints": [FiniteInterval(Real, 0, None, closed="left"), None]},
    )
    caller: InitVar[str] = "SectionSpec"

    def __post_init__(self, caller):
        validate_parameter_constraints(
            self.constraints(),
            {f.name: getattr(self, f.name) for f in fields(self)},
            caller_name=caller,
        )
        for name in ("duration", "speed_kmh", "sampling_rate"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "setting", int(self.setting))
        object.__setattr__(self, "sensor_noise", check_sensor_noise(self.sensor_noise))
        object.__setattr__(self, "vehicle", check_vehicle(self.vehicle))
        if self.perturbation is not None:
            object.__setattr__(self, "perturbation", float(self.perturbation))
        self._check_size()
        if self.perturbation:  # the multisine's periods must fit in the section
            multisine_frequencies(self.n_samples / self.sampling_rate)

    @classmethod
    def constraints(cls, *names):
        """scikit-learn's constraints of the fields (those of ``names``, or all), for the
        ``validate_params`` of a public function that takes them."""
        return {
            f.name: f.metadata["constraints"] for f in fields(cls) if f.name in names or not names
        }

    @classmethod
    def of(cls, arguments, caller, **given):
        """The spec of a call: its fields picked by name from ``arguments`` (a public
        function's ``locals()`` on entry), ``given`` first; ``caller`` names the function in
        errors."""
        arguments = {**arguments, **given}
        return cls(**{f.name: arguments[f.name] for f in fields(cls)}, caller=caller)

    def _check_size(self):
        rows = self.duration * self.sampling_rate  # a float: inf beyond the largest one
        if math.isfinite(rows) and int(round(rows)) < 1:
            raise ValueError(
                f"duration={self.duration} s holds no sample at sampling_rate={self.sampling_rate}."
            )
        per_row = INTERNAL_RATE / self.sampling_rate
        steps = rows * (math.ceil(per_row) if 1.0 < per_row < math.inf else max(1.0, per_row))
        if not steps <= MAX_STEPS:
            raise ValueError(
                f"duration={self.duration:g} s at sampling_rate={self.sampling_rate:g} Hz is "
                f"{rows:.4g} samples ({steps:.4g} integration steps at {INTERNAL_RATE:g} Hz or "
                f"more); a section takes at most {MAX_STEPS:,} steps (about "
                f"{MAX_STEPS / (2 * INTERNAL_RATE * 3600):.0f} h at 100 Hz): simulate shorter "
                "sections."
            )
        if not self.speed * self.duration <= MAX_ROAD:
            raise ValueError(
                f"speed_kmh={self.speed_kmh:g} for duration={self.duration:g} s is a road of "
                f"{self.speed * self.duration / 1000:.4g} km; a section is at most "
                f"{MAX_ROAD / 1000:g} km: simulate shorter sections."
            )

    @property
    def speed(self):
        """The forward speed [m/s]."""
        return self.speed_kmh / 3.6

    @property
    def n_samples(self):
        """Samples of the section."""
        return int(round(self.duration * self.sampling_rate))

    @property
    def n_sub(self):
        """Integration steps per sample (at least :data:`INTERNAL_RATE`)."""
        return max(1, math.ceil(INTERNAL_RATE / self.sampling_rate))

    @property
    def dt(self):
        """The integration step [s]."""
        return 1.0 / (self.sampling_rate * self.n_sub)

    @property
    def sensor_scale(self):
        """Scale of the sensor errors: ``sensor_noise``'s times the car's (None: clean)."""
        return None if self.sensor_noise is None else self.sensor_noise * self.vehicle.sensor_noise

    @property
    def seeded(self):
        """Whether the seeds are ints (or the road's None), so that the section can be cached."""
        return isinstance(self.random_state, Integral) and (
            self.road_random_state is None or isinstance(self.road_random_state, Integral)
        )

    def recording_of(self, driver):
        """The default recording id of ``driver`` (a name) on this section."""
        return f"{driver}-{self.scenario}-s{self.setting}"


class Section:
    """One simulated section before anyone drives it: the road and manoeuvres of ``spec``'s
    seeds, the human's parameters (drawn around ``driver``'s) and noises, in the order
    :func:`make_lane_keeping` draws them."""

    def __init__(self, spec, driver):
        rng = check_random_state(spec.random_state)
        road_rng = (
            rng if spec.road_random_state is None else check_random_state(spec.road_random_state)
        )
        self.spec, self.rng = spec, rng
        self.parameters = sample_driver(check_driver(driver), rng)
        self.vehicle, self.speed = spec.vehicle, spec.speed
        self.sampling_rate = spec.sampling_rate
        self.n_samples, self.n_sub, self.dt = spec.n_samples, spec.n_sub, spec.dt
        margin = 300.0 + self.speed * self.parameters.preview_time * 2.0
        length = self.speed * spec.duration * 1.05 + margin
        self.road = make_road(
            length, setting=spec.setting, scenario=spec.scenario, random_state=road_rng
        )
        self.offsets = manoeuvre_offsets(self.road, spec.scenario, road_rng)
        self.remnants = draw_remnants(
            self.parameters, self.n_samples * self.n_sub, self.dt, self.rng
        )
        # the perturbation experiment's torque at every integration step (None: none)
        self.perturbation = None
        if spec.perturbation:
            self.perturbation = multisine(
                spec.perturbation,
                self.n_samples / self.sampling_rate,
                self.dt,
                self.n_samples * self.n_sub,
                perturbation_stream(spec.random_state, rng),
            )

    def simulate(self, torque_source=None, column_log=None, lost=None, law_log=None, law_keeps=()):
        """The logged states of the closed loop over the section (see :func:`simulate`)."""
        return simulate(
            self,
            self.n_samples,
            torque_source,
            column_log=column_log,
            perturbation=self.perturbation,
            lost=lost,
            law_log=law_log,
            law_keeps=law_keeps,
        )

    def logged_perturbation(self, n_rows):
        """The perturbation [Nm] at the first ``n_rows`` logged samples, or None when the
        section has no perturbation experiment (``perturbation=0`` logs zeros)."""
        if self.spec.perturbation is None:
            return None
        if self.perturbation is None:
            return np.zeros(n_rows)
        return self.perturbation[:: self.n_sub][:n_rows]

    def features(self, log):
        """The candidate features of Table B.2 (clean) and the torque of the logged states."""
        columns = dict(zip(LOG_COLUMNS, log.T, strict=True))
        theta, v, s, e_y, e_psi = (columns[name] for name in ("theta", "v", "s", "e_y", "e_psi"))
        road, lf = self.road, self.vehicle.front_distance
        s_front = s + lf * np.cos(e_psi)
        vehicle_heading = road.at(road.heading, s) + e_psi
        features = {
            "steering_wheel_angle": theta,
            "steering_wheel_velocity": columns["theta_d"],
            "steering_wheel_acceleration": columns["theta_dd"],
            "lateral_velocity": v,
            "lateral_acceleration": columns["a_y"],
            "slip_angle": np.arctan2(v, self.speed),
            "yaw_rate": columns["r"],
            "yaw_acceleration": columns["r_d"],
            "roll_angle": columns["phi"],
            "roll_velocity": columns["phi_d"],
            "roll_acceleration": columns["phi_dd"],
            "lateral_deviation_0m": e_y + lf * np.sin(e_psi),
            "heading_deviation_0m": vehicle_heading - road.at(road.heading, s_front),
            "road_curvature_0m": road.at(road.curvature, s_front),
        }
        for distance in PREVIEW_DISTANCES:
            ahead = s_front + distance
            features[f"heading_deviation_{distance:.0f}m"] = vehicle_heading - road.at(
                road.heading, ahead
            )
            features[f"road_curvature_{distance:.0f}m"] = road.at(road.curvature, ahead)
        return {name: features[name] for name in FEATURE_NAMES}, columns["torque"]

    def sensed(self, sensors, row, states):
        """The sensed features of logged row ``row``, in the order of :data:`FEATURE_NAMES`,
        from the states a torque source of :func:`simulate` gets (``sensors``: the
        section's :class:`SensorStream`)."""
        features, _ = self.features(np.array([(*states, 0.0)]))
        return sensors.features(row, {k: float(v[0]) for k, v in features.items()})

    def frame(self, log, features, torque, *, recording, driver, split):
        """The tidy frame of the measured ``features`` and ``torque``, with the manoeuvre
        under way and its lane crossing, from the logged states ``log``."""
        manoeuvre, crossing = self.manoeuvres(log)
        perturbation = self.logged_perturbation(len(torque))
        return tidy_frame(
            {
                RECORDING: recording,
                DRIVER: driver,
                SETTING: self.spec.setting,
                SPLIT: split,
                TIME: np.arange(len(torque)) / self.sampling_rate,
                MANOEUVRE: manoeuvre,
                CROSSING_TIME: crossing,
                **features,
                TARGET: torque,
                **({} if perturbation is None else {STEERING_PERTURBATION: perturbation}),
            },
            attrs={
                "scenario": self.spec.scenario,
                "speed": self.speed,
                "sensor_noise": self.spec.sensor_scale,
                "lane_width": self.road.lane_width,
                "vehicle": asdict(self.vehicle),
            },
        )

    def manoeuvres(self, log):
        """The manoeuvre of every logged row (by the car's arc length) and, on the rows of a
        manoeuvre, the time [s] its car's centre first crosses a marking of the centre lane
        (NaN if it does not)."""
        s, lateral = log[:, LOG_COLUMNS.index("s")], log[:, LOG_COLUMNS.index("e_y")]
        labels = manoeuvre_of(self.road, s)
        crossing = np.full(len(s), np.nan)
        half = self.road.lane_width / 2.0
        for start, stop, _ in self.road.manoeuvres:
            rows = np.flatnonzero((s >= start) & (s < stop))
            if rows.size < 2:
                continue
            side = np.sign(lateral[rows, None] - np.array([half, -half]))
            changed = np.flatnonzero((side[1:] != side[:-1]).any(axis=1))
            if changed.size:
                crossing[rows] = rows[changed[0] + 1] / self.sampling_rate
        return labels, crossing
