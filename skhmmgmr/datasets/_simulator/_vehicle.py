"""Vehicle and steering-system parameters of the simulator, and their steady-state relations.

This module holds the parameters, the closed-form relations the virtual driver's internal model
uses, and the vehicle's equations of motion (:func:`single_track`); the steering system's step
is :mod:`._steering`'s, and :mod:`._closed_loop` integrates both with the driver. Every step
function works on Python floats with its constants bound once per simulation: a tight loop
over floats is an order of magnitude faster than NumPy on arrays of one element.

Vehicle: single-track (bicycle) model at constant forward speed ``u`` with lateral velocity ``v``
and yaw rate ``r`` at the centre of mass, front/rear tyre forces ``F = F_max tanh(C alpha / F_max)``
(linear for small slip, saturating at ``mu Fz``), and a roll degree of freedom of the sprung mass
driven by the lateral acceleration::

    m (dv/dt + u r) = F_f + F_r                     alpha_f = delta - (v + l_f r) / u
    I_z dr/dt = l_f F_f - l_r F_r                   alpha_r = -(v - l_r r) / u
    I_x d2phi/dt2 = m_s h a_y - (k_phi - m_s g h) phi - c_phi dphi/dt

Steering system: column of ratio ``i_s``, wheel inertia and damping, Coulomb friction
``T_fric = F_c tanh(omega / omega_c)``, an electric power assist ``T_a = T (g_0 + g_1 |T|)``
of the sensed torque ``T`` (boost curve, capped at ``T_a,max``; its bandwidth is far above the
driver's, so it acts without lag) and the self-aligning torque of the front tyres
``F_f (t_m + t_p(alpha_f))`` (mechanical plus pneumatic trail, the latter fading with slip).

The reference car's column is rigid (``column_stiffness=inf``): ``delta = theta / i_s`` and the
torque sensor reads the driver's torque at the wheel, ``T = T_d``::

    J_sw d2theta/dt2 = T_d + T_a - F_f (t_m + t_p) / i_s - b_sw dtheta/dt - T_fric

A finite ``column_stiffness`` ``k_c`` puts a torsion bar (damping ``c_c``) between the
steering wheel (angle ``theta``, the share ``s`` of ``J_sw`` above the bar) and the lower column
carrying the rack (angle ``theta_c`` in steering-wheel units, ``delta = theta_c / i_s``, the
rest of ``J_sw``), as in an electric power steering: the torque sensor reads the torsion bar,
``T = T_bar = k_c (theta - theta_c) + c_c (dtheta/dt - dtheta_c/dt)``, the assist boosts it at
the lower column, and the friction and the damping act there::

    s J_sw d2theta/dt2 = T_d - T_bar
    (1 - s) J_sw d2theta_c/dt2 = T_bar + T_a - F_f (t_m + t_p) / i_s - b_sw dtheta_c/dt - T_fric

``driver_torque`` is the torque sensor's reading, ``T_bar``: in steady state the driver's
torque, while the wheel accelerates the driver's torque minus ``s J_sw d2theta/dt2``. Held at
a constant torque, the bar twists by ``theta - theta_c = T_d / k_c``. The column's natural
frequency ``sqrt(k_c (1 / (s J_sw + J_arm) + (1 + gain) / ((1 - s) J_sw)))`` (the assist's
local gain, up to 2.6, stiffens the lower side) is 50 to 250 rad/s (8 to 40 Hz) over the
drawn ranges, above the driver's bandwidth, and ``omega dt`` reaches 1.25 at the internal rate
of 200 Hz: the simulator
steps the column by linearised backward Euler (stable at any step, damping the column's mode
somewhat more than its own ``c_c`` does). The driver's arms (and a model at the wheel,
:func:`drive`, which has none) act on the steering wheel.
"""

import math
import numbers
from dataclasses import asdict, dataclass, fields, replace

from sklearn.utils import check_random_state

from ..._core._compat import validate_params

GRAVITY = 9.81


@dataclass(frozen=True)
class VehicleParameters:
    """Parameters of the simulated car and its steering system, in SI units.

    The default is the simulator's reference car (a mid-size sedan): its understeer gradient
    (about 2 deg/g) and steering ratio give a steering-wheel angle of about 7 deg per m/s^2 of
    lateral acceleration at 100 km/h, as in the thesis' data. Pass one to the simulator with
    ``vehicle=`` (:func:`make_lane_keeping`, :func:`make_driving_protocol`, :func:`drive`);
    :func:`draw_vehicle` draws the steering system within :data:`VEHICLE_RANGES`, and a
    variant of the default is ``dataclasses.replace(VehicleParameters(), wheel_friction=0.5)``.
    The virtual driver knows the car it drives: its internal model of the steering gain, of the
    aligning torque and of the power assist is the vehicle's.

    The reference car's steering column is rigid (``column_stiffness=inf``: the torque sensor
    reads the driver's torque at the wheel); a finite ``column_stiffness`` is a torsion bar
    with ``column_damping``, with the share ``steering_wheel_share`` of ``wheel_inertia``
    above it and the rest (lower column, reflected rack) below it, the torque sensor reading
    the bar (the equations are in the module's documentation and in the user guide).
    ``wheel_damping`` is the steering's viscous damping and ``wheel_friction`` its Coulomb
    friction, smoothed over ``friction_velocity``, at the lower column with a torsion bar.
    ``sensor_noise`` scales the sensor errors of the simulator's ``sensor_noise`` argument
    (the car's sensor set: 1 is "typical"). The simulator refuses a parameter outside the
    range in which a car stays a car and its integration stays sound (a mass of 500 to
    5000 kg, a roll inertia of 100 to 3000 kg m^2...), naming the parameter and the range.

    Examples
    --------
    >>> from skhmmgmr.datasets import VehicleParameters
    >>> car = VehicleParameters()
    >>> car.steering_ratio, car.wheel_friction
    (16.0, 0.3)
    """

    mass: float = 1500.0  # [kg]
    yaw_inertia: float = 2500.0  # [kg m^2]
    front_distance: float = 1.1  # [m] centre of mass to front axle (l_f)
    rear_distance: float = 1.6  # [m] centre of mass to rear axle (l_r)
    front_cornering_stiffness: float = 110_000.0  # [N/rad] axle
    rear_cornering_stiffness: float = 150_000.0  # [N/rad] axle
    friction_coefficient: float = 1.0  # [-] tyre-road
    sprung_mass: float = 1350.0  # [kg]
    roll_arm: float = 0.5  # [m] centre of mass height above the roll axis
    roll_inertia: float = 500.0  # [kg m^2] sprung mass about the roll axis
    roll_stiffness: float = 90_000.0  # [Nm/rad]
    roll_damping: float = 6_000.0  # [Nms/rad]
    width: float = 1.8  # [m]
    # steering system
    steering_ratio: float = 16.0  # [-]
    wheel_inertia: float = 0.04  # [kg m^2] steering wheel + column + reflected rack
    wheel_damping: float = 0.25  # [Nms/rad]
    wheel_friction: float = 0.3  # [Nm] Coulomb friction at the wheel
    friction_velocity: float = 0.1  # [rad/s] smoothing of the friction sign
    mechanical_trail: float = 0.02  # [m]
    pneumatic_trail: float = 0.03  # [m] at zero slip
    pneumatic_trail_slip: float = 0.12  # [rad] slip angle at which the pneumatic trail vanishes
    assist_gain: float = 0.3  # [-] boost curve g_0
    assist_gain_slope: float = 0.15  # [1/Nm] boost curve g_1
    assist_max: float = 6.0  # [Nm] assist saturation (at the wheel)
    sensor_noise: float = 1.0  # [-] scale of the sensor errors of this car's sensor set
    column_stiffness: float = math.inf  # [Nm/rad] torsion bar (inf: rigid column)
    column_damping: float = 0.1  # [Nms/rad] torsion bar damping (with a finite stiffness)
    steering_wheel_share: float = 0.5  # [-] share of wheel_inertia above the torsion bar

    @property
    def wheelbase(self):
        return self.front_distance + self.rear_distance

    @property
    def front_load(self):
        """Static front axle load [N]."""
        return self.mass * GRAVITY * self.rear_distance / self.wheelbase

    @property
    def rear_load(self):
        return self.mass * GRAVITY * self.front_distance / self.wheelbase

    @property
    def understeer_gradient(self):
        """Understeer gradient K [rad/(m/s^2)]: ``delta = (L + K u^2) kappa``."""
        m, L = self.mass, self.wheelbase
        return (
            m
            / L
            * (
                self.rear_distance / self.front_cornering_stiffness
                - self.front_distance / self.rear_cornering_stiffness
            )
        )

    def steering_angle_for_curvature(self, speed):
        """Steady-state steering-wheel angle per path curvature [rad m] at ``speed`` [m/s]."""
        return self.steering_ratio * (self.wheelbase + self.understeer_gradient * speed**2)

    def aligning_stiffness(self, speed):
        """Steady-state self-aligning torque at the wheel per steering-wheel angle [Nm/rad]."""
        front_force = self.mass * self.rear_distance / self.wheelbase * speed**2
        trail = self.mechanical_trail + self.pneumatic_trail
        return trail * front_force / self.steering_ratio / self.steering_angle_for_curvature(speed)

    def driver_torque_for_load(self, load):
        """Driver torque that, with the boost curve, balances ``load`` Nm at the wheel.

        Inverse of ``T (1 + g_0 + g_1 |T|) = load`` (assist saturation ignored).
        """
        g0, g1 = 1.0 + self.assist_gain, self.assist_gain_slope
        magnitude = (math.sqrt(g0 * g0 + 4.0 * g1 * abs(load)) - g0) / (2.0 * g1)
        return math.copysign(magnitude, load)


def single_track(vehicle, speed):
    """The vehicle's equations of motion on the road at ``speed`` [m/s] (module docstring).

    Returns
    -------
    rates : callable
        ``rates(road_wheel, v, r, phi, phi_d, e_y, e_psi, kappa) -> (aligning, v_d, r_d, a_y,
        phi_dd, s_d, e_y_d)``: from the steering-wheel angle that steers the road wheels
        (``road_wheel``, the wheel's or the lower column's, divided by the steering ratio
        here), the lateral velocity, the yaw rate, the roll angle and velocity, the lateral
        and heading deviations from the road's centreline and its curvature ``kappa``, the
        front tyres' aligning torque at the steering wheel, the derivatives of the lateral
        velocity and the yaw rate, the lateral acceleration, the roll acceleration, and the
        speeds along and across the road.
    """
    u = speed
    m, iz, lf, lr = vehicle.mass, vehicle.yaw_inertia, vehicle.front_distance, vehicle.rear_distance
    cf, cr = vehicle.front_cornering_stiffness, vehicle.rear_cornering_stiffness
    f_max = vehicle.friction_coefficient * vehicle.front_load
    r_max = vehicle.friction_coefficient * vehicle.rear_load
    ms_h = vehicle.sprung_mass * vehicle.roll_arm
    ix, c_roll = vehicle.roll_inertia, vehicle.roll_damping
    k_roll = vehicle.roll_stiffness - ms_h * GRAVITY
    ratio = vehicle.steering_ratio
    t_mech, t_pneu = vehicle.mechanical_trail, vehicle.pneumatic_trail
    slip_t = vehicle.pneumatic_trail_slip
    tanh, sin, cos = math.tanh, math.sin, math.cos

    def rates(road_wheel, v, r, phi, phi_d, e_y, e_psi, kappa):
        # tyres (saturating), the aligning torque of the front ones, the body, the road
        alpha_f = road_wheel / ratio - (v + lf * r) / u
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
        return force_f * trail / ratio, v_d, r_d, a_y, phi_dd, s_d, e_y_d

    return rates


#: What :func:`draw_vehicle` draws within ``(low, high)``, uniformly (the parameters of
#: :data:`LOG_UNIFORM`: uniformly in their logarithm): parameter name of
#: :class:`VehicleParameters` -> ``(low, high, unit, meaning)``. Every range holds the default
#: car's value but ``column_stiffness`` (the default column is rigid, a drawn car has a
#: torsion bar). The other parameters (mass, tyres, roll...) stay the default car's.
VEHICLE_RANGES = {
    "wheel_friction": (0.1, 0.8, "Nm", "Coulomb friction of the steering system at the wheel"),
    "friction_velocity": (
        0.002,
        0.3,
        "rad/s",
        "steering-wheel velocity over which the friction changes sign (its band; from the "
        "sharp friction of a column that sticks to a smooth one)",
    ),
    "assist_gain": (0.1, 1.0, "-", "power-assist boost at zero torque (g_0)"),
    "assist_gain_slope": (0.05, 0.4, "1/Nm", "growth of the boost with the torque (g_1)"),
    "assist_max": (3.0, 10.0, "Nm", "largest assist torque"),
    "wheel_damping": (0.1, 0.6, "Nms/rad", "viscous damping of the column"),
    "wheel_inertia": (0.025, 0.07, "kg m^2", "steering wheel, column and reflected rack"),
    "steering_ratio": (13.0, 19.0, "-", "steering-wheel angle per road-wheel angle"),
    "mechanical_trail": (0.01, 0.035, "m", "caster trail of the front wheels"),
    "pneumatic_trail": (0.02, 0.045, "m", "pneumatic trail of the front tyres at zero slip"),
    "sensor_noise": (0.5, 2.0, "-", "scale of every sensor error (1: typical)"),
    # drawn last, so that the parameters above are those drawn before the column was compliant
    "column_stiffness": (
        1.0 / math.radians(1.0),
        3.0 / math.radians(1.0),
        "Nm/rad",
        "torsion bar stiffness (1-3 Nm/deg); the reference car's column is rigid (inf)",
    ),
    "column_damping": (0.05, 0.3, "Nms/rad", "damping of the torsion bar's twist"),
}
#: The parameters of :data:`VEHICLE_RANGES` drawn uniformly in their logarithm: a range over
#: two orders of magnitude, of which a uniform draw would nearly never give the low end (a
#: friction band of 5 mrad/s or less: one car in a hundred instead of about one in five).
LOG_UNIFORM = frozenset({"friction_velocity"})


@validate_params({"random_state": ["random_state"]}, prefer_skip_nested_validation=True)
def draw_vehicle(random_state=None):
    """Draw a car's steering system and sensors within :data:`VEHICLE_RANGES`.

    Every parameter of :data:`VEHICLE_RANGES` is drawn uniformly within its range (the
    friction band uniformly in its logarithm, :data:`LOG_UNIFORM`: 0.002 to 0.3 rad/s, a
    band of 5 mrad/s or less in one car of five), one draw each in the order of the
    mapping; the others are the default car's (:class:`VehicleParameters`).
    ``vehicle=seed`` in the simulator draws the car with ``draw_vehicle(seed)``.

    Parameters
    ----------
    random_state : int, RandomState instance or None, default=None
        Seeds the draw. Same int, same car.

    Returns
    -------
    vehicle : VehicleParameters

    Examples
    --------
    >>> from skhmmgmr.datasets import VEHICLE_RANGES, draw_vehicle
    >>> car = draw_vehicle(0)
    >>> low, high, unit, meaning = VEHICLE_RANGES["wheel_friction"]
    >>> bool(low <= car.wheel_friction <= high), unit
    (True, 'Nm')
    """
    rng = check_random_state(random_state)
    drawn = {}
    for name, (low, high, *_) in VEHICLE_RANGES.items():
        if name in LOG_UNIFORM:
            drawn[name] = float(math.exp(rng.uniform(math.log(low), math.log(high))))
        else:
            drawn[name] = float(rng.uniform(low, high))
    return replace(VehicleParameters(), **drawn)


def check_vehicle(vehicle):
    """The :class:`VehicleParameters` of the simulator's ``vehicle=`` argument.

    None or "default": the default car; an int: :func:`draw_vehicle` of it; a dict: the default
    car with these parameters replaced; a :class:`VehicleParameters`: its parameters (checked).
    """
    if vehicle is None or (isinstance(vehicle, str) and vehicle == "default"):
        return VehicleParameters()
    if isinstance(vehicle, numbers.Integral) and not isinstance(vehicle, bool):
        return draw_vehicle(int(vehicle))
    if isinstance(vehicle, dict):
        known = {f.name for f in fields(VehicleParameters)}
        unknown = sorted(str(key) for key in vehicle if key not in known)
        if unknown:
            raise ValueError(
                f"vehicle has unknown parameter(s) {unknown}; expected names of "
                f"VehicleParameters: {sorted(known)}."
            )
        vehicle = replace(VehicleParameters(), **vehicle)
    if not isinstance(vehicle, VehicleParameters):
        raise ValueError(
            "vehicle must be None, 'default', an int seed, a dict of VehicleParameters "
            f"fields or a VehicleParameters, got vehicle={vehicle!r}."
        )
    for name, value in asdict(vehicle).items():
        _check_parameter(name, value)
    _check_balance(vehicle)
    return vehicle


#: Where each parameter of :class:`VehicleParameters` keeps a car a car and the simulator's
#: integration (semi-implicit Euler at 200 Hz or faster) sound: ``(low, high, unit, why)``.
#: Every drawn range (:data:`VEHICLE_RANGES`) and the reference car lie inside; a low of 0 is
#: a part that may be absent (no friction, no assist, no trail, clean sensors, no damping).
VEHICLE_LIMITS = {
    "mass": (500.0, 5000.0, "kg", "a car, from a city car to a van"),
    "yaw_inertia": (200.0, 10_000.0, "kg m^2", "a car's, about mass times the axles' distances"),
    "front_distance": (0.5, 3.0, "m", "a car's axle from its centre of mass"),
    "rear_distance": (0.5, 3.0, "m", "a car's axle from its centre of mass"),
    "front_cornering_stiffness": (1e4, 5e5, "N/rad", "a car's axle"),
    "rear_cornering_stiffness": (1e4, 5e5, "N/rad", "a car's axle"),
    "friction_coefficient": (0.05, 1.5, "-", "from ice to a dry track"),
    "sprung_mass": (300.0, 5000.0, "kg", "at most the mass"),
    "roll_arm": (0.05, 1.5, "m", "a car's centre of mass above its roll axis"),
    "roll_inertia": (100.0, 3000.0, "kg m^2", "a car body's about its roll axis"),
    "roll_stiffness": (1e4, 5e5, "Nm/rad", "a car's suspension"),
    "roll_damping": (0.0, 2e4, "Nms/rad", "a car's suspension, stable when stepped at 200 Hz"),
    "width": (1.0, 3.0, "m", "a car's"),
    "steering_ratio": (5.0, 30.0, "-", "a car's steering"),
    "wheel_inertia": (0.005, 0.5, "kg m^2", "a steering wheel, column and reflected rack"),
    "wheel_damping": (0.0, 5.0, "Nms/rad", "a steering column's"),
    "wheel_friction": (0.0, 5.0, "Nm", "a steering system's"),
    "friction_velocity": (0.001, 10.0, "rad/s", "the friction's band"),
    "mechanical_trail": (0.0, 0.1, "m", "a car's caster trail"),
    "pneumatic_trail": (0.0, 0.1, "m", "a car tyre's"),
    "pneumatic_trail_slip": (0.01, 0.5, "rad", "a car tyre's"),
    "assist_gain": (0.0, 10.0, "-", "a power assist's boost"),
    "assist_gain_slope": (0.001, 5.0, "1/Nm", "a power assist's boost curve"),
    "assist_max": (0.1, 50.0, "Nm", "a power assist's largest torque"),
    "sensor_noise": (0.0, 10.0, "-", "1 is a typical sensor set"),
    "column_stiffness": (10.0, math.inf, "Nm/rad", "a torsion bar, or math.inf: a rigid column"),
    "column_damping": (0.0, 10.0, "Nms/rad", "a torsion bar's"),
    "steering_wheel_share": (
        0.001,
        0.999,
        "-",
        "of the inertia above the torsion bar: the wheel, the lower column and the rack keep some",
    ),
}


def _check_parameter(name, value):
    """Refuse a parameter that is not a real number within its :data:`VEHICLE_LIMITS`."""
    low, high, unit, why = VEHICLE_LIMITS[name]
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Real)
        or math.isnan(value)
        or (math.isinf(value) and not math.isinf(high))
    ):
        raise ValueError(f"vehicle parameter {name} must be a finite number, got {name}={value!r}.")
    if not low <= value <= high:
        raise ValueError(
            f"vehicle parameter {name} must be within [{low:g}, {high:g}] {unit} ({why}), got "
            f"{name}={value!r}."
        )


def _check_balance(vehicle):
    """Refuse parameters that are each within their limits but not together."""
    if vehicle.sprung_mass > vehicle.mass:
        raise ValueError(
            f"vehicle parameter sprung_mass={vehicle.sprung_mass!r} must be at most "
            f"mass={vehicle.mass!r} (the body is part of the car)."
        )
    tipping = vehicle.sprung_mass * vehicle.roll_arm * GRAVITY
    if not vehicle.roll_stiffness > 2.0 * tipping:
        raise ValueError(
            f"vehicle parameter roll_stiffness={vehicle.roll_stiffness!r} must be more than "
            f"twice sprung_mass * roll_arm * {GRAVITY} = {tipping:g} Nm/rad: with less the "
            "body leans more than a radian per g of lateral acceleration, or rolls over."
        )
