"""Vehicle and steering-system parameters of the simulator, and their steady-state relations.

The equations are integrated inline in :mod:`._simulator` (a tight loop over Python floats is an
order of magnitude faster than calling functions per step); this module holds the parameters and
the closed-form relations the virtual driver's internal model uses.

Vehicle: single-track (bicycle) model at constant forward speed ``u`` with lateral velocity ``v``
and yaw rate ``r`` at the centre of mass, front/rear tyre forces ``F = F_max tanh(C alpha / F_max)``
(linear for small slip, saturating at ``mu Fz``), and a roll degree of freedom of the sprung mass
driven by the lateral acceleration::

    m (dv/dt + u r) = F_f + F_r                     alpha_f = delta - (v + l_f r) / u
    I_z dr/dt = l_f F_f - l_r F_r                   alpha_r = -(v - l_r r) / u
    I_x d2phi/dt2 = m_s h a_y - (k_phi - m_s g h) phi - c_phi dphi/dt

Steering system: rigid column of ratio ``i_s`` (``delta = theta / i_s``), wheel inertia and
damping, Coulomb friction, an electric power assist ``T_a = T_d (g_0 + g_1 |T_d|)`` (boost
curve, capped; its bandwidth is far above the driver's, so it acts without lag) and the
self-aligning torque of the front tyres ``F_f (t_m + t_p(alpha_f))`` (mechanical plus pneumatic
trail, the latter fading with slip)::

    J_sw d2theta/dt2 = T_d + T_a - F_f (t_m + t_p) / i_s - b_sw dtheta/dt - T_fric
"""

import math
from dataclasses import dataclass

GRAVITY = 9.81


@dataclass(frozen=True)
class VehicleParameters:
    """Passenger-car parameters (mid-size sedan); SI units.

    The understeer gradient (about 2 deg/g) and the steering ratio give a steering-wheel angle
    of about 7 deg per m/s^2 of lateral acceleration at 100 km/h, as in the thesis' data.
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
