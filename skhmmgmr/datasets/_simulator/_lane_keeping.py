"""Closed-loop lane-keeping simulator: road, virtual driver, steering system and vehicle."""

import math
import numbers
import os
from dataclasses import asdict

import numpy as np
from sklearn.utils import check_random_state

from ..._core._schema import (
    CROSSING_TIME,
    DRIVER,
    FEATURE_NAMES,
    MANOEUVRE,
    RECORDING,
    SETTING,
    SPLIT,
    TARGET,
    TIME,
)
from .._frame import tidy_frame
from ._driver import check_driver, coloured_noise, sample_driver
from ._road import LANE_WIDTH, SETTINGS, make_road, manoeuvre_of, manoeuvre_offsets
from ._sensors import check_sensor_noise, measure
from ._vehicle import check_vehicle

SCENARIOS = ("highway", "sharp_corners", "lane_change", "evasive", "wide_lane")
INTERNAL_RATE = 200.0  # [Hz] minimum integration rate
PREVIEW_DISTANCES = (10.0, 30.0)  # [m] road sensors ahead of the front axle
LOST_CONTROL = 10.0  # [m] lateral deviation at which the simulation stops
CORNER_CUT_RADIUS = 300.0  # [m] radius at which the corner cut is corner_cutting * tolerance
LINE_LIMIT = 0.8  # [m] largest intended offset from the centre of a 3.5 m lane (car 1.8 m wide)
STIFF_STEP = 0.5  # dt * (velocity slope) / inertia of the steering above which it steps implicitly


def _check_positive(value, name):
    if not isinstance(value, numbers.Real) or isinstance(value, bool) or not value > 0:
        raise ValueError(f"{name} must be a positive number, got {name}={value!r}.")
    return float(value)


def _check_setting(setting):
    if (
        isinstance(setting, bool)
        or not isinstance(setting, numbers.Integral)
        or setting not in SETTINGS
    ):
        raise ValueError(
            f"setting must be an integer from 1 to 7 (Table B.1), got setting={setting!r}."
        )
    return int(setting)


def _check_scenario(scenario):
    if scenario not in SCENARIOS:
        raise ValueError(f"Unknown scenario={scenario!r}; expected one of {SCENARIOS}.")
    return scenario


def checked_section_arguments(
    duration, sampling_rate, speed_kmh, setting, scenario, sensor_noise, vehicle
):
    """The arguments every simulation of a section shares, checked (a ValueError names the
    argument): ``(duration, sampling_rate, speed_kmh, setting, scenario, vehicle)``, the
    sensor noise checked too. The section must hold at least one sample."""
    duration = _check_positive(duration, "duration")
    sampling_rate = _check_positive(sampling_rate, "sampling_rate")
    speed_kmh = _check_positive(speed_kmh, "speed_kmh")
    setting = _check_setting(setting)
    scenario = _check_scenario(scenario)
    check_sensor_noise(sensor_noise)
    vehicle = check_vehicle(vehicle)
    if int(round(duration * sampling_rate)) < 1:
        raise ValueError(f"duration={duration} s holds no sample at sampling_rate={sampling_rate}.")
    return duration, sampling_rate, speed_kmh, setting, scenario, vehicle


def draw_remnants(driver, n_steps, dt, rng):
    """The human driver's coloured noises over ``n_steps`` integration steps: on the desired
    angle, on the torque, and the lane wander (drawn for every driver, so that the sensor
    errors drawn next are the same whoever drives)."""
    return (
        coloured_noise(n_steps, dt, driver.angle_remnant_time, driver.angle_remnant, rng),
        coloured_noise(n_steps, dt, 0.1, driver.torque_remnant, rng),
        coloured_noise(n_steps, dt, driver.lane_wander_time, driver.lane_wander, rng),
    )


def _simulate(
    road,
    offsets,
    vehicle,
    driver,
    speed,
    n_samples,
    n_sub,
    dt,
    remnants,
    torque_source=None,
    initial=None,
    column_log=None,
):
    """Integrate the closed loop with semi-implicit Euler; return logged states (n_samples, 14).

    ``torque_source``: another driver than the human of ``driver``, called at every logged
    sample as ``torque_source(row, states)`` with the states of the logged columns but the
    torque (the steering-wheel acceleration of the integration step before); its torque acts
    at the steering wheel until the next sample. It may lose control: the log then ends at the
    sample where the lateral deviation first exceeds :data:`LOST_CONTROL`.

    ``initial`` (with a ``torque_source`` only): start from a logged state instead of rest,
    ``(theta, theta_d, theta_dd, v, r, phi, phi_d, s, e_y, e_psi, t_driver)`` with the driver
    torque of the integration step before (which sets the power assist's gain), followed, with
    a torsion bar, by the lower column's ``(theta_c, theta_c_d)`` at that sample (from
    ``column_log``); without them the lower column starts at the bar's static twist under that
    torque, turning with the wheel (exact at rest only).
    ``column_log``: an array (n_samples, 2) that receives ``(theta_c, theta_c_d)`` at every
    logged sample (with a torsion bar; the rigid column writes the wheel's angle and velocity).
    The logged torque is the torque sensor's: the driver's (the human's, or the torque
    source's) with a rigid column; the torsion bar's ``k_c (theta - theta_c) + c_c (theta' -
    theta_c')`` at the sample with a ``column_stiffness``, ``theta_c`` being the lower
    column's angle (see :mod:`._vehicle`).
    """
    n_steps = n_samples * n_sub
    u = speed
    m, iz, lf, lr = vehicle.mass, vehicle.yaw_inertia, vehicle.front_distance, vehicle.rear_distance
    cf, cr = vehicle.front_cornering_stiffness, vehicle.rear_cornering_stiffness
    f_max = vehicle.friction_coefficient * vehicle.front_load
    r_max = vehicle.friction_coefficient * vehicle.rear_load
    ms_h = vehicle.sprung_mass * vehicle.roll_arm
    ix, c_roll = vehicle.roll_inertia, vehicle.roll_damping
    k_roll = vehicle.roll_stiffness - ms_h * 9.81
    ratio = vehicle.steering_ratio
    t_mech, t_pneu, slip_t = (
        vehicle.mechanical_trail,
        vehicle.pneumatic_trail,
        vehicle.pneumatic_trail_slip,
    )
    b_sw, fric, fric_v = vehicle.wheel_damping, vehicle.wheel_friction, vehicle.friction_velocity
    g0, g1, a_max = vehicle.assist_gain, vehicle.assist_gain_slope, vehicle.assist_max
    # driver constants (a torque source has no arm impedance of its own)
    j_arm, b_arm, k_arm = driver.arm_inertia, driver.arm_damping, driver.arm_stiffness
    if torque_source is not None:
        j_arm = b_arm = 0.0
    j_sw = vehicle.wheel_inertia
    # torsion bar: a finite column stiffness splits the steering into two inertias (see
    # _vehicle); the rigid column (column_stiffness=inf) keeps the one-inertia step below
    compliant = math.isfinite(vehicle.column_stiffness)
    k_col, c_col = vehicle.column_stiffness, vehicle.column_damping
    j_up = vehicle.steering_wheel_share * j_sw
    j_low = j_sw - j_up
    # explicit Euler on the steering's velocity terms is stable for dt * slope / inertia < 2;
    # a car past STIFF_STEP (stiff damping, narrow friction band, light wheel) steps them
    # implicitly (the reference car, at 0.41 for 200 Hz, does not)
    stiff = dt * (b_sw + fric / fric_v) / j_sw > STIFF_STEP
    act_lag = dt / (driver.activation_time + dt)
    look = speed * driver.preview_time
    far_gain = 2.0 / (look * look)
    lead = driver.lead_time
    # A wider lane leaves the driver more room: the tolerated band, the corner cut and the
    # deviation at which the correction grows scale with the lane's width.
    lane_scale = road.lane_width / LANE_WIDTH
    line_limit = LINE_LIMIT + (road.lane_width - LANE_WIDTH) / 2.0
    near_gain, tol = driver.near_gain, driver.lane_tolerance * lane_scale
    edge = driver.edge_deviation * lane_scale
    inv_edge = 1.0 / edge if edge > 0 else 0.0
    angle_gain = driver.vehicle_model_gain * vehicle.steering_angle_for_curvature(speed)
    feel = driver.feel_gain * vehicle.aligning_stiffness(speed)
    fb0, fb1 = 1.0 + g0, g1
    n_delay = max(1, int(round(driver.reaction_time / dt)))
    n_hold = int(round(driver.hold_time / dt))
    # Lane target (manoeuvre offset + corner cut) and the far point on the road, tabulated.
    grid = road.s
    cut = driver.corner_cutting * tol * np.clip(road.curvature * CORNER_CUT_RADIUS, -1.5, 1.5)
    far = road.lateral_offset(grid, look) + road.at(offsets, grid + look)
    curv, near, far = road.curvature.tolist(), offsets.tolist(), far.tolist()
    cut_near, cut_far = cut.tolist(), road.at(cut, grid + look).tolist()
    inv_ds = 1.0 / (grid[1] - grid[0])
    angle_noise, torque_noise, wander = (noise.tolist() for noise in remnants)
    effort = driver.torque_remnant_effort

    tanh, sin, cos, sqrt = math.tanh, math.sin, math.cos, math.sqrt
    s = e_y = e_psi = s_d = e_y_d = e_psi_d = 0.0
    theta = theta_d = theta_dd = v = r = phi = phi_d = 0.0
    theta_c = theta_c_d = 0.0  # lower column (below the torsion bar), in steering-wheel angle
    t_muscle = t_driver = theta_des = 0.0
    if initial is not None:
        if torque_source is None:
            raise ValueError("initial needs a torque_source (a human starts at rest)")
        values = tuple(map(float, initial))
        theta, theta_d, theta_dd, v, r, phi, phi_d, s, e_y, e_psi, t_driver = values[:11]
        if compliant and len(values) == 13:
            theta_c, theta_c_d = values[11:]
        elif compliant:
            # No lower-column state given: the torsion bar's static twist under the logged
            # torque, turning with the wheel (exact at rest only).
            theta_c, theta_c_d = theta - t_driver / k_col, theta_d
    delay_line = [0.0] * n_delay
    log = np.empty((n_samples, 14))
    row = 0
    for k in range(n_steps):
        sample = k % n_sub == 0
        if sample and abs(e_y) > LOST_CONTROL:
            if torque_source is not None:
                return log[:row]
            raise RuntimeError(
                f"The driver lost control {k * dt:.1f} s into the recording "
                f"(lateral deviation {e_y:.1f} m); driver parameters: {driver}."
            )
        if torque_source is None:
            x = s * inv_ds
            i = int(x)
            f = x - i
            # the intended line (corner cut + wander) stays within LINE_LIMIT of the lane centre
            line = cut_near[i] + f * (cut_near[i + 1] - cut_near[i]) + wander[k]
            lane = near[i] + f * (near[i + 1] - near[i]) + max(-line_limit, min(line_limit, line))
            line = cut_far[i] + f * (cut_far[i + 1] - cut_far[i]) + wander[k]
            aim = far[i] + f * (far[i + 1] - far[i]) + max(-line_limit, min(line_limit, line))

            # visual layer, acting after the reaction delay; the lead acts on the far-point drift
            e_far = aim - e_y - look * e_psi
            e_far += lead * ((far[i + 1] - far[i]) * inv_ds * s_d - e_y_d - look * e_psi_d)
            e_near = e_y - lane
            outside = e_near - tol * tanh(e_near / tol)
            outside *= 1.0 + (e_near * inv_edge) ** 2
            theta_vis = angle_gain * (far_gain * e_far - near_gain * outside) + angle_noise[k]
            j = k % n_delay
            delayed = delay_line[j]
            delay_line[j] = theta_vis
            if n_hold == 0 or k % n_hold == 0:
                theta_des = delayed

            # neuromuscular layer: the activation lag acts on the command (expected steering
            # feel plus the equilibrium point of the arm stiffness), the arm impedance at once
            load = feel * theta_des
            t_ff = math.copysign(
                (sqrt(fb0 * fb0 + 4.0 * fb1 * abs(load)) - fb0) / (2.0 * fb1), load
            )
            t_muscle += act_lag * (t_ff + k_arm * theta_des - t_muscle)
            t_hand = t_muscle - k_arm * theta
            t_hand += (1.0 + effort * abs(t_hand)) * torque_noise[k]
        x = s * inv_ds
        i = int(x)
        kappa = curv[i] + (x - i) * (curv[i + 1] - curv[i])

        # tyres, aligning torque, vehicle (none of which depends on this step's torque)
        alpha_f = (theta_c if compliant else theta) / ratio - (v + lf * r) / u
        alpha_r = (lr * r - v) / u
        force_f = f_max * tanh(cf * alpha_f / f_max)
        force_r = r_max * tanh(cr * alpha_r / r_max)
        trail = t_mech + t_pneu * max(0.0, 1.0 - abs(alpha_f) / slip_t)
        v_d = (force_f + force_r) / m - u * r
        r_d = (lf * force_f - lr * force_r) / iz
        a_y = v_d + u * r
        phi_dd = (ms_h * a_y - k_roll * phi - c_roll * phi_d) / ix
        s_d = (u * cos(e_psi) - v * sin(e_psi)) / (1.0 - kappa * e_y)
        e_y_d = u * sin(e_psi) + v * cos(e_psi)
        if compliant:  # the torque sensor reads the torsion bar
            t_driver = k_col * (theta - theta_c) + c_col * (theta_d - theta_c_d)
        if column_log is not None and sample:  # the lower column with the logged states
            column_log[row] = (theta_c, theta_c_d) if compliant else (theta, theta_d)
        if torque_source is not None and sample:
            states = (theta, theta_d, theta_dd, v, a_y, r, r_d, phi, phi_d, phi_dd, s, e_y, e_psi)
            t_hand = torque_source(row, states)
            log[row] = (*states, t_driver if compliant else t_hand)
            row += 1

        # power assist (sensing last step's driver torque, or this step's torsion bar torque).
        # The boost gain is frozen at last step's torque, which makes the rigid-column balance
        # J_sw theta'' = (1 + gain) T_d - loads, with T_d = T_hand - B theta' - J_arm theta'',
        # linear in theta'' (a lagged assist would feed back the arm inertia and oscillate).
        gain = g0 + g1 * abs(t_driver)
        if gain * abs(t_driver) > a_max:
            gain = a_max / abs(t_driver)
        if compliant:
            # Two-inertia column (see _vehicle), the assist boosting the torsion bar torque:
            #   (J_up + J_arm) theta'' = T_hand - B theta' - T_bar
            #   J_low theta_c'' = (1 + gain) T_bar - aligning - b_sw theta_c' - T_fric
            # stepped by linearised backward Euler on the torsion bar and the velocity terms
            # (stable whatever the column's natural frequency against dt): T_bar at the step's
            # end is t_next + k_e (theta'' - theta_c'').
            sticking = tanh(theta_c_d / fric_v)
            k_e = (k_col * dt + c_col) * dt
            t_next = t_driver + k_col * dt * (theta_d - theta_c_d)
            r_up = t_hand - b_arm * theta_d - t_next
            r_low = (1.0 + gain) * t_next - force_f * trail / ratio - b_sw * theta_c_d
            r_low -= fric * sticking
            m_up = j_up + j_arm + b_arm * dt + k_e
            m_low = j_low + (1.0 + gain) * k_e + dt * (b_sw + fric / fric_v * (1.0 - sticking**2))
            det = m_up * m_low - (1.0 + gain) * k_e * k_e
            theta_dd = (m_low * r_up + k_e * r_low) / det
            theta_c_d += dt * (m_up * r_low + (1.0 + gain) * k_e * r_up) / det
            theta_c += dt * theta_c_d
        else:
            t_arm = t_hand - b_arm * theta_d
            sticking = tanh(theta_d / fric_v)
            loads = force_f * trail / ratio + b_sw * theta_d + fric * sticking
            if stiff:
                # linearised backward Euler on the velocity terms (damping, friction): stable
                # whatever the friction's slope fric / fric_v against the inertia
                slope = b_sw + (1.0 + gain) * b_arm + fric / fric_v * (1.0 - sticking * sticking)
                theta_dd = ((1.0 + gain) * t_arm - loads) / (
                    j_sw + (1.0 + gain) * j_arm + dt * slope
                )
            else:
                theta_dd = ((1.0 + gain) * t_arm - loads) / (j_sw + (1.0 + gain) * j_arm)
            t_driver = t_arm - j_arm * theta_dd

        if torque_source is None and sample:
            log[row] = (
                theta,
                theta_d,
                theta_dd,
                v,
                a_y,
                r,
                r_d,
                phi,
                phi_d,
                phi_dd,
                s,
                e_y,
                e_psi,
                t_driver,
            )
            row += 1

        theta_d += dt * theta_dd
        theta += dt * theta_d
        v += dt * v_d
        r += dt * r_d
        phi_d += dt * phi_dd
        phi += dt * phi_d
        s += dt * s_d
        e_y += dt * e_y_d
        e_psi_d = r - kappa * s_d
        e_psi += dt * e_psi_d
    return log


def _features(log, road, vehicle, speed):
    """Candidate features of Table B.2 from the logged states and the road sensors."""
    (theta, theta_d, theta_dd, v, a_y, r, r_d, phi, phi_d, phi_dd, s, e_y, e_psi, torque) = log.T
    lf = vehicle.front_distance
    s_front = s + lf * np.cos(e_psi)
    vehicle_heading = road.at(road.heading, s) + e_psi
    columns = {
        "steering_wheel_angle": theta,
        "steering_wheel_velocity": theta_d,
        "steering_wheel_acceleration": theta_dd,
        "lateral_velocity": v,
        "lateral_acceleration": a_y,
        "slip_angle": np.arctan2(v, speed),
        "yaw_rate": r,
        "yaw_acceleration": r_d,
        "roll_angle": phi,
        "roll_velocity": phi_d,
        "roll_acceleration": phi_dd,
        "lateral_deviation_0m": e_y + lf * np.sin(e_psi),
        "heading_deviation_0m": vehicle_heading - road.at(road.heading, s_front),
        "road_curvature_0m": road.at(road.curvature, s_front),
    }
    for distance in PREVIEW_DISTANCES:
        ahead = s_front + distance
        columns[f"heading_deviation_{distance:.0f}m"] = vehicle_heading - road.at(
            road.heading, ahead
        )
        columns[f"road_curvature_{distance:.0f}m"] = road.at(road.curvature, ahead)
    return {name: columns[name] for name in FEATURE_NAMES}, torque


class Section:
    """One simulated section before anyone drives it: the seeds' road, manoeuvres, the
    human's parameters and remnants, in the order :func:`make_lane_keeping` draws them."""

    def __init__(
        self,
        duration,
        setting,
        driver,
        speed_kmh,
        sampling_rate,
        scenario,
        random_state,
        road_random_state,
        vehicle=None,
    ):
        rng = check_random_state(random_state)
        road_rng = rng if road_random_state is None else check_random_state(road_random_state)
        self.rng = rng
        self.parameters = sample_driver(check_driver(driver), rng)
        self.vehicle = check_vehicle(vehicle)
        self.speed = speed_kmh / 3.6
        self.sampling_rate, self.setting, self.scenario = sampling_rate, setting, scenario
        self.n_samples = int(round(duration * sampling_rate))
        self.n_sub = max(1, math.ceil(INTERNAL_RATE / sampling_rate))
        self.dt = 1.0 / (sampling_rate * self.n_sub)
        margin = 300.0 + self.speed * self.parameters.preview_time * 2.0
        length = self.speed * duration * 1.05 + margin
        self.road = make_road(length, setting=setting, scenario=scenario, random_state=road_rng)
        self.offsets = manoeuvre_offsets(self.road, scenario, road_rng)
        self.remnants = draw_remnants(
            self.parameters, self.n_samples * self.n_sub, self.dt, self.rng
        )

    def simulate(self, torque_source=None, column_log=None):
        """The logged states of the closed loop (see :func:`_simulate`)."""
        return _simulate(
            self.road,
            self.offsets,
            self.vehicle,
            self.parameters,
            self.speed,
            self.n_samples,
            self.n_sub,
            self.dt,
            self.remnants,
            torque_source,
            column_log=column_log,
        )

    def sensor_scale(self, sensor_noise):
        """Scale of the sensor errors: ``sensor_noise``'s times the car's (None: clean)."""
        scale = check_sensor_noise(sensor_noise)
        return None if scale is None else scale * self.vehicle.sensor_noise

    def frame(self, log, features, torque, *, recording, driver, split, scale):
        """The tidy frame of the measured ``features`` and ``torque``, with the manoeuvre
        under way and its lane crossing, from the logged states ``log``."""
        manoeuvre, crossing = self.manoeuvres(log)
        return tidy_frame(
            {
                RECORDING: recording,
                DRIVER: driver,
                SETTING: self.setting,
                SPLIT: split,
                TIME: np.arange(len(torque)) / self.sampling_rate,
                MANOEUVRE: manoeuvre,
                CROSSING_TIME: crossing,
                **features,
                TARGET: torque,
            },
            attrs={
                "scenario": self.scenario,
                "speed": self.speed,
                "sensor_noise": scale,
                "lane_width": self.road.lane_width,
                "vehicle": asdict(self.vehicle),
            },
        )

    def manoeuvres(self, log):
        """The manoeuvre of every logged row (by the car's arc length) and, on the rows of a
        manoeuvre, the time [s] its car's centre first crosses a marking of the centre lane
        (NaN if it does not)."""
        s, lateral = log[:, 10], log[:, 11]
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


def _make_lane_keeping(
    duration,
    setting,
    driver,
    speed_kmh,
    sampling_rate,
    scenario,
    random_state,
    road_random_state,
    recording,
    split,
    sensor_noise=None,
    vehicle=None,
):
    section = Section(
        duration,
        setting,
        driver,
        speed_kmh,
        sampling_rate,
        scenario,
        random_state,
        road_random_state,
        vehicle,
    )
    log = section.simulate()
    features, torque = _features(log, section.road, section.vehicle, section.speed)
    # sensors: drawn after the closed loop, which therefore does not depend on sensor_noise
    scale = section.sensor_scale(sensor_noise)
    features, torque = measure(
        features, torque, 1.0 / sampling_rate, section.speed, scale, section.rng
    )
    style = driver if isinstance(driver, str) else "custom"
    if recording is None:
        recording = f"{style}-{scenario}-s{setting}"
    return section.frame(
        log, features, torque, recording=recording, driver=style, split=split, scale=scale
    )


def make_lane_keeping(
    duration=300.0,
    *,
    setting=7,
    driver="defensive",
    speed_kmh=100.0,
    sampling_rate=100.0,
    scenario="highway",
    random_state=None,
    road_random_state=None,
    recording=None,
    split="train",
    sensor_noise="typical",
    vehicle=None,
    cache=None,
):
    """Simulate a driver keeping the centre lane of a pseudo-random highway section.

    A closed-loop simulation (thesis Appendices B and C.1) of a virtual driver that steers with
    torque (preview, reaction delay, internal model of the steering feel, neuromuscular lag,
    coloured remnant), a steering system with power assist and self-aligning torque, and a
    single-track vehicle with tyre saturation and roll, on a road of straights and circular
    arcs joined by clothoids (Table B.1), three lanes of 3.5 m, at constant speed.

    Parameters
    ----------
    duration : float, default=300.0
        Length of the recording [s].
    setting : int, default=7
        Radius setting of Table B.1: 1 S (300-600 m), 2 M (600-900), 3 L (900-1200),
        4 SM (300-900), 5 ML (600-1200), 6 SL (300-600 and 900-1200), 7 SML (300-1200).
    driver : str or DriverParameters, default="defensive"
        A key of :data:`DRIVER_STYLES` ("defensive", "aggressive", "novice") or parameters.
        Each recording draws its own parameters around the style's (per-recording variability).
    speed_kmh : float, default=100.0
        Constant forward speed [km/h] (the thesis drives at 100 km/h).
    sampling_rate : float, default=100.0
        Logging rate [Hz]. The model is integrated at a multiple of it, at least 200 Hz.
    scenario : {"highway", "sharp_corners", "lane_change", "evasive", "wide_lane"}, \
default="highway"
        "highway" is the thesis' protocol. Stress scenarios (thesis Appendix E.4):
        "sharp_corners" uses radii of 175-300 m (25 m grid) instead of the setting's;
        "lane_change" moves to a neighbouring lane and back every 300-800 m; "evasive" adds
        sudden 2.5-3.5 m double lane changes over 30-40 m; "wide_lane" is one 5 m lane of
        straights (300-800 m) alternating with sinusoidal segments (1-4 m amplitude, tightest
        radius 300-600 m; the setting is not used), where the driver's tolerated band and
        corner cut grow with the lane. The lateral deviation stays measured from the centre
        lane.
    random_state : int, RandomState instance or None, default=None
        Seeds the road, the driver parameters and the remnant noise. Same int, same DataFrame.
    road_random_state : int, RandomState instance or None, default=None
        Seeds the road (and the manoeuvres) separately, so that several drivers can drive the
        same section; by default the road is drawn from ``random_state``.
    recording : str, default=None
        Recording id; defaults to ``"{driver}-{scenario}-s{setting}"``.
    split : str, default="train"
        Value of the ``split`` column.
    sensor_noise : {"typical", "none"}, float or None, default="typical"
        Measurement of the logged signals (see Sensors below). "typical": realistic sensor
        errors, derivatives computed from the measured signals, as a vehicle logs them. None or
        "none": the true states of the simulation. A float scales every error (noise, drift,
        resolution; "typical" is 1.0), times the car's ``sensor_noise``. The closed loop always
        runs on the true states.
    vehicle : None, "default", int, dict or VehicleParameters, default=None
        The car and its steering system (friction, power assist, column damping, inertia,
        steering ratio, trails, sensor set). None or "default": the reference car of
        :class:`VehicleParameters`; an int: the car :func:`draw_vehicle` draws from that seed,
        within :data:`VEHICLE_RANGES`; a dict: the reference car with these parameters
        replaced (``{"wheel_friction": 0.6}``). The car is drawn apart from ``random_state``:
        the same seeds give the same road, driver and noises in every car. The driver knows
        the car (its internal model is the car's).
    cache : str, path or joblib.Memory, default=None
        Cache the simulation on disk (only used when ``random_state`` is an int and
        ``road_random_state`` an int or None).

    Returns
    -------
    frame : pandas.DataFrame
        One row per sample: ``recording, driver, setting, split, time``, ``manoeuvre`` (what
        the driver is doing: ``"lane_keeping"``, ``"lane_change_left"``,
        ``"lane_change_right"`` or ``"evasive"``, by the car's position on the road) and
        ``crossing_time`` (on the rows of a manoeuvre, the time [s] at which the car's centre
        crosses a marking of the centre lane; NaN elsewhere or if it never does), then the 18
        candidate features :data:`FEATURE_NAMES` (Table B.2) then ``driver_torque``. SI units,
        listed in ``frame.attrs["units"]``; ``frame.attrs["lane_width"]`` is the lane's width,
        ``frame.attrs["vehicle"]`` the car's parameters (a dict of :class:`VehicleParameters`).
        Signs: y and yaw to the left; roll positive when the body leans right (outwards in a
        left turn); deviations are vehicle minus road (lateral at the front axle, heading at
        the road sensors at 0, 10 and 30 m ahead of the front axle);
        curvature positive in left turns.

    Notes
    -----
    Calibration. Over one 5-minute setting-7 section, every style stays within these bands
    (:data:`CALIBRATION_BANDS`, checked by the tests; thesis Table C.2 in brackets): RMS torque
    1-2.5 Nm (1.64-1.67), max torque 2.5-8 Nm (4.1-4.3), RMS lateral deviation 0.05-0.6 m
    (0.41-0.47), max lateral deviation below 1.75 m (1.1-1.5; the vehicle centre never leaves
    the lane), RMS lateral acceleration 0.5-1.5 m/s^2 (0.97-1.0), RMS steering-wheel angle
    4-12 deg (6.9-7.1), max 10-40 deg (22.8-24.7). Use :func:`calibration_table` to compute them.
    The bands hold for the true states and for the measured signals, in the reference car.

    Sensors (``sensor_noise="typical"``). The driver sees the world, the logger measures it:
    the sensor errors are drawn after the simulation and do not change the closed loop. Each
    measured signal gets white noise (per sample, at the logging rate), a slowly varying error
    (first-order Gauss-Markov: bias, attitude drift, camera tracking error) and a quantisation.
    Magnitudes typical of the sensor type (RMS; 1 deg = 0.01745 rad):

    ===============================  ======================  ==========  ===============  =========
    signal                           sensor type             white       drift (time)     step
    ===============================  ======================  ==========  ===============  =========
    steering wheel angle             steering angle sensor   0.02 deg    -                0.1 deg
    lateral velocity (slip angle)    GNSS/INS or optical     0.03 m/s    -                -
    lateral acceleration             MEMS accelerometer      0.05 m/s^2  0.02 m/s^2 (60)  -
    yaw rate                         MEMS gyro               0.1 deg/s   0.03 deg/s (60)  -
    roll angle                       INS attitude            0.01 deg    0.05 deg (20 s)  -
    lateral deviation 0 m            lane camera             0.01 m      0.03 m (0.2 s)   -
    heading deviation 0 / 10 / 30 m  lane camera             3/4/6e-4    1/1.5/3e-3 rad   -
                                                             rad         (0.2 s)
    road curvature 0 / 10 / 30 m     lane camera             3/4/6e-5    1/1.5/3e-4 1/m   -
                                                             1/m         (0.3 s)
    driver torque (target)           EPS torque sensor       0.03 Nm     -                0.01 Nm
    ===============================  ======================  ==========  ===============  =========

    The slip angle is ``arctan(measured lateral velocity / speed)``. The derivatives are not
    measured but computed as an ECU would, causally: backward difference of the measured signal
    then a first-order low-pass of time constant 20 ms (steering-wheel velocity, from the angle)
    or 40 ms (steering-wheel acceleration from the filtered velocity, yaw acceleration from the
    yaw rate, roll velocity from the roll angle, roll acceleration from the filtered roll
    velocity). At 100 Hz on a setting-7 section, the RMS error (noise and filter lag) is about
    a quarter of the signal RMS for the steering-wheel velocity, half for the roll velocity,
    equal for the yaw acceleration and 3 times for the roll acceleration; the steering-wheel
    acceleration of the model has most of its power above the 4 Hz of the filter, so its
    measured version keeps mainly the low-frequency part (correlation about 0.4).

    Examples
    --------
    >>> from skhmmgmr.datasets import make_lane_keeping
    >>> frame = make_lane_keeping(duration=10.0, driver="aggressive", random_state=0)
    >>> frame.shape
    (1000, 26)
    >>> frame.attrs["units"]["driver_torque"]
    'Nm'
    """
    duration, sampling_rate, speed_kmh, setting, scenario, vehicle = checked_section_arguments(
        duration, sampling_rate, speed_kmh, setting, scenario, sensor_noise, vehicle
    )
    check_driver(driver)
    args = (duration, setting, driver, speed_kmh, sampling_rate, scenario, random_state)
    args += (road_random_state, recording, split, sensor_noise, vehicle)
    seeded = isinstance(random_state, numbers.Integral) and (
        road_random_state is None or isinstance(road_random_state, numbers.Integral)
    )
    if cache is not None and seeded:
        return _cached(cache)(*args)
    return _make_lane_keeping(*args)


def _cached(cache):
    from joblib import Memory

    if isinstance(cache, (str, os.PathLike)):
        cache = Memory(os.fspath(cache), verbose=0)
    if not hasattr(cache, "cache"):
        raise ValueError(f"cache must be a directory or a joblib.Memory, got cache={cache!r}.")
    return cache.cache(_make_lane_keeping)
