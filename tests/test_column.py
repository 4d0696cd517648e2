"""Tests of the steering column's torsion bar: the rigid limit, the static twist, stability."""

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest
from test_vehicles import drive_weaving

from skhmmgmr.datasets import (
    VEHICLE_RANGES,
    VehicleParameters,
    draw_vehicle,
    drive,
    make_lane_keeping,
)
from skhmmgmr.datasets._simulator._section import INTERNAL_RATE

# The stiffest corner of the ranges: the stiffest torsion bar on the lightest wheel, with the
# strongest assist (which multiplies the bar's stiffness at the lower column), the narrowest
# friction band and the most damping.
STIFF_COLUMN = {
    "column_stiffness": VEHICLE_RANGES["column_stiffness"][1],
    "column_damping": VEHICLE_RANGES["column_damping"][1],
    "wheel_inertia": VEHICLE_RANGES["wheel_inertia"][0],
    "assist_gain": VEHICLE_RANGES["assist_gain"][1],
    "assist_gain_slope": VEHICLE_RANGES["assist_gain_slope"][1],
    "assist_max": VEHICLE_RANGES["assist_max"][1],
    "wheel_friction": VEHICLE_RANGES["wheel_friction"][1],
    "friction_velocity": VEHICLE_RANGES["friction_velocity"][0],
    "wheel_damping": VEHICLE_RANGES["wheel_damping"][1],
}


def relative_rms(frame, reference, column):
    return np.sqrt(np.mean((frame[column] - reference[column]) ** 2)) / reference[column].std()


# Drawn cars have a torsion bar: the 30 drawn cars of tests/test_vehicles.py (a human at the
# wheel, and a model) test its stability over the ranges at 20 and 100 Hz.


def test_the_reference_car_has_a_rigid_column_and_drawn_cars_a_torsion_bar():
    assert VehicleParameters().column_stiffness == math.inf
    low, high, unit, _ = VEHICLE_RANGES["column_stiffness"]
    # typical torsion bars: 1 to 3 Nm/deg
    assert (low * math.radians(1.0), high * math.radians(1.0), unit) == pytest.approx(
        (1.0, 3.0, "Nm/rad")
    )
    for seed in range(10):
        assert low <= draw_vehicle(seed).column_stiffness <= high


def test_a_stiffer_torsion_bar_converges_to_the_rigid_column():
    # With (almost) all the inertia below the bar, the bar's torque is the driver's torque
    # at the wheel in the rigid limit; what is left is the time step of the two schemes.
    car = replace(draw_vehicle(0), steering_wheel_share=1e-3)
    kwargs = dict(sampling_rate=100.0, random_state=0, sensor_noise=None)
    rigid = make_lane_keeping(20.0, vehicle=replace(car, column_stiffness=math.inf), **kwargs)
    columns = ("driver_torque", "steering_wheel_angle", "lateral_deviation_0m", "yaw_rate")
    errors = []
    for stiffness in (100.0, 1e3, 1e5):
        frame = make_lane_keeping(20.0, vehicle=replace(car, column_stiffness=stiffness), **kwargs)
        errors.append([relative_rms(frame, rigid, column) for column in columns])
    errors = np.array(errors)
    assert (errors[1] < errors[0]).all() and (errors[2] <= errors[1] * 1.2).all()
    assert errors[0].max() > 0.03  # a soft bar (1.7 Nm/deg) moves the drive
    assert errors[2].max() < 0.01  # a bar 1,000 times stiffer than that is rigid


@pytest.mark.parametrize("stiffness", [60.0, 150.0])
def test_a_constant_torque_twists_the_torsion_bar_by_torque_over_stiffness(stiffness):
    # A constant torque at the wheel in steady state: the steering wheel's inertia balances
    # the torque and the bar (the sensor reads the torque), and the lower column balances
    # the boosted bar torque against the aligning torque as a rigid column would. The
    # compliant wheel is therefore turned further than the rigid one by the twist T / k.
    torque = 0.5
    runs = []
    for car in ({"column_stiffness": stiffness}, None):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # the car turns off the road
            runs.append(
                drive(
                    lambda row: torque,
                    duration=5.5,
                    sampling_rate=100.0,
                    random_state=0,
                    vehicle=car,
                    sensor_noise=None,
                )
            )
    compliant, rigid = (run.iloc[500] for run in runs)  # 5 s in
    twist = compliant["steering_wheel_angle"] - rigid["steering_wheel_angle"]
    assert twist == pytest.approx(torque / stiffness, rel=1e-6)
    assert compliant["driver_torque"] == pytest.approx(torque, rel=1e-6)
    assert abs(compliant["steering_wheel_velocity"]) < 1e-8


@pytest.mark.parametrize("rate", [20.0, 100.0])
def test_the_stiffest_column_is_stable_with_a_human_and_with_a_model(rate):
    # The column's natural frequency, sqrt(k (1 / J_up + (1 + gain) / J_low)), reaches
    # 235 rad/s here without the arms at a gain of 2: omega dt = 1.2 at the internal step.
    car = replace(VehicleParameters(), **STIFF_COLUMN)
    j_up = car.steering_wheel_share * car.wheel_inertia
    j_low = car.wheel_inertia - j_up
    omega = math.sqrt(car.column_stiffness * (1.0 / j_up + 3.0 / j_low))
    assert omega / (math.ceil(INTERNAL_RATE / rate) * rate) > 1.0
    rigid = replace(car, column_stiffness=math.inf)
    for driver in ("novice", "aggressive"):
        frames = [
            make_lane_keeping(
                20.0,
                sampling_rate=rate,
                driver=driver,
                random_state=1,
                vehicle=v,
                sensor_noise=None,
            )
            for v in (car, rigid)
        ]
        values = frames[0].drop(columns="crossing_time").select_dtypes(float).to_numpy()
        assert np.isfinite(values).all()
        compliant, reference = (f["steering_wheel_acceleration"].std() for f in frames)
        assert compliant < 1.5 * reference + 0.5, driver
        assert abs(frames[0]["lateral_deviation_0m"]).max() < 1.75
    runs = [drive_weaving(rate, v) for v in (car, rigid)]
    assert np.isfinite(runs[0].select_dtypes(float).drop(columns="crossing_time")).all().all()
    compliant, reference = (run["steering_wheel_acceleration"].std() for run in runs)
    assert compliant < 1.5 * reference + 0.5


@pytest.mark.parametrize(
    "parameters, message",
    [
        ({"column_stiffness": 0.0}, "column_stiffness=0.0"),
        ({"column_stiffness": -60.0}, "column_stiffness=-60.0"),
        ({"column_stiffness": float("nan")}, "column_stiffness=nan"),
        ({"column_damping": -0.1}, "column_damping=-0.1"),
        ({"column_damping": math.inf}, "column_damping=inf"),
        ({"steering_wheel_share": 1.0}, "steering_wheel_share=1.0"),
        ({"steering_wheel_share": 0.0}, "steering_wheel_share=0.0"),
    ],
)
def test_a_bad_column_names_the_parameter(parameters, message):
    for simulate in (
        lambda: make_lane_keeping(1.0, random_state=0, vehicle=parameters),
        lambda: drive(lambda row: 0.0, duration=1.0, random_state=0, vehicle=parameters),
    ):
        with pytest.raises(ValueError, match="vehicle parameter") as error:
            simulate()
        assert message in str(error.value)
