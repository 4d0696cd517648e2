"""Tests of the simulator's perturbation experiment: a multisine torque on the steering wheel
that the driver does not know (``perturbation=``)."""

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from skhmmgmr.datasets import (
    DRIVER_STYLES,
    FEATURE_NAMES,
    TARGET,
    drive,
    load_recordings,
    make_driving_protocol,
    make_lane_keeping,
)
from skhmmgmr.datasets._simulator._protocol import _perturbed
from skhmmgmr.datasets._simulator._section import Section, SectionSpec

PERTURBATION = "steering_perturbation"


@pytest.mark.parametrize("rate", [20.0, 100.0])
def test_the_multisine_has_the_rms_asked_for_and_nothing_outside_its_band(rate):
    frame = make_lane_keeping(60.0, sampling_rate=rate, random_state=1, perturbation=0.3)
    assert list(frame.columns[-2:]) == [TARGET, PERTURBATION]
    assert frame.attrs["units"][PERTURBATION] == "Nm"
    torque = frame[PERTURBATION].to_numpy()
    assert_allclose(np.sqrt(np.mean(torque**2)), 0.3, rtol=1e-12)
    power = np.abs(np.fft.rfft(torque)) ** 2
    frequency = np.fft.rfftfreq(len(torque), 1.0 / rate)
    inside = (frequency >= 0.05 - 1e-9) & (frequency <= 5.0 + 1e-9)
    assert power[~inside].sum() < 1e-20 * power.sum()
    lines = frequency[power > 1e-6 * power.max()]
    assert 20 <= len(lines) <= 24 and lines.min() == pytest.approx(0.05)
    assert lines.max() == pytest.approx(5.0)
    assert np.all(np.diff(np.log(lines)) > 0.1)  # spread on a log scale, none repeated


def test_without_perturbation_no_column_and_zero_is_the_unperturbed_run():
    plain = make_lane_keeping(10.0, sampling_rate=20.0, random_state=2)
    assert PERTURBATION not in plain.columns
    zero = make_lane_keeping(10.0, sampling_rate=20.0, random_state=2, perturbation=0.0)
    assert (zero[PERTURBATION] == 0.0).all()
    assert zero.drop(columns=PERTURBATION).equals(plain)


@pytest.mark.parametrize("random_state", [4, np.random.RandomState(4)])
def test_the_perturbation_draws_from_its_own_stream(random_state):
    # the road, the driver, its noises and the sensor errors are those of the run without it
    def section(perturbation):
        seed = random_state if isinstance(random_state, int) else np.random.RandomState(4)
        spec = SectionSpec(10.0, 3, 100.0, 20.0, "highway", seed, None, "typical", None)
        return Section(dataclasses.replace(spec, perturbation=perturbation), "novice")

    plain, perturbed = section(None), section(0.2)
    assert plain.perturbation is None and perturbed.perturbation.shape == (2000,)
    assert plain.parameters == perturbed.parameters
    assert_array_equal(plain.road.curvature, perturbed.road.curvature)
    for a, b in zip(plain.remnants, perturbed.remnants, strict=True):
        assert_array_equal(a, b)
    if isinstance(random_state, int):  # a RandomState instance gives the perturbation a seed
        assert_array_equal(plain.rng.random_sample(5), perturbed.rng.random_sample(5))
    again = section(0.2)
    assert_array_equal(again.perturbation, perturbed.perturbation)


def test_the_driver_does_not_know_the_perturbation():
    # A driver without arm impedance feels the wheel only through its eyes: until its
    # reaction time has passed, its torque is the same with and without the perturbation,
    # while the wheel already turns by it. After it, the driver answers the car's motion.
    driver = dataclasses.replace(
        DRIVER_STYLES["defensive"],
        arm_stiffness=0.0,
        arm_damping=0.0,
        arm_inertia=0.0,
        reaction_time=0.5,
        variability=0.0,
    )
    run = dict(driver=driver, sampling_rate=100.0, random_state=0, sensor_noise=None)
    plain = make_lane_keeping(5.0, **run)
    perturbed = make_lane_keeping(5.0, **run, perturbation=0.5)
    before = plain["time"] < 0.5 - 1e-9
    assert_allclose(perturbed[TARGET][before], plain[TARGET][before], rtol=0, atol=1e-12)
    turned = np.abs(perturbed["steering_wheel_angle"] - plain["steering_wheel_angle"])
    assert turned[before].max() > 1e-4
    assert np.abs(perturbed[TARGET] - plain[TARGET])[~before].max() > 1e-2


@pytest.mark.parametrize("vehicle", [None, {"column_stiffness": 150.0}])
def test_the_perturbation_is_a_torque_at_the_wheel_logged_apart_from_the_drivers(vehicle):
    # At 200 Hz (one integration step a sample) a driver that adds the perturbation to its own
    # torque moves the car exactly as the perturbation experiment does; the experiment logs
    # the driver's share, the other run the sum.
    road = dict(duration=8.0, sampling_rate=200.0, random_state=3, sensor_noise=None)
    road["vehicle"] = vehicle
    perturbed = drive(lambda row: -2.0 * row[0], **road, perturbation=0.4)
    added = iter(perturbed[PERTURBATION].tolist())
    summed = drive(lambda row: -2.0 * row[0] + next(added), **road)
    features = list(FEATURE_NAMES)
    pd.testing.assert_frame_equal(perturbed[features], summed[features], rtol=0, atol=1e-12)
    assert_allclose(perturbed[TARGET] + perturbed[PERTURBATION], summed[TARGET], rtol=0, atol=1e-12)
    if vehicle is None:  # a rigid column logs the model's own torque
        assert_allclose(perturbed[TARGET], -2.0 * perturbed["steering_wheel_angle"], atol=1e-12)


def test_a_human_drive_with_perturbation_is_its_lane_keeping_run():
    road = dict(duration=10.0, sampling_rate=20.0, random_state=5, perturbation=0.2)
    assert drive("aggressive", **road).equals(
        make_lane_keeping(driver="aggressive", split="test", **road)
    )


def test_the_protocol_perturbs_a_share_of_its_training_recordings():
    sizes = dict(n_train_per_setting=2, n_validation=1, n_test=1, duration=4.0, sampling_rate=20.0)
    plain = make_driving_protocol(("defensive",), random_state=0, **sizes)
    data = make_driving_protocol(
        ("defensive",), random_state=0, perturbation=0.2, perturbed_share=1 / 3, **sizes
    )
    rms = data.groupby("recording", sort=False)[PERTURBATION].apply(
        lambda p: float(np.sqrt(np.mean(p**2)))
    )
    perturbed = sorted(rms.index[rms > 0])
    assert perturbed == [
        "defensive-train-s2-0",
        "defensive-train-s3-1",
        "defensive-train-s5-0",
        "defensive-train-s6-1",
    ]
    assert_allclose(rms[perturbed], 0.2, rtol=1e-12)
    # the others are the recordings of the protocol without perturbation, bit for bit
    same = ~data["recording"].isin(perturbed)
    assert data.loc[same].drop(columns=PERTURBATION).equals(plain.loc[same])
    everything = make_driving_protocol(("defensive",), random_state=0, perturbation=0.2, **sizes)
    perturbed = everything.groupby("recording")[PERTURBATION].apply(lambda p: bool(p.any()))
    assert perturbed.to_dict() == {r: "-train-" in r for r in perturbed.index}


@pytest.mark.parametrize("n_train", [12, 10, 7])
@pytest.mark.parametrize("share", [0.0, 0.05, 0.3, 1 / 3, 0.5, 0.99, 1.0])
def test_the_number_of_perturbed_recordings_is_rounded_down(n_train, share):
    sections = [("train", 1, k) for k in range(n_train)] + [("validation", 7, 0), ("test", 7, 0)]
    flags = _perturbed(sections, share)
    expected = {(12, 0.3): 3, (12, 0.99): 11, (10, 0.99): 9, (7, 0.5): 3, (7, 0.3): 2}
    assert sum(flags) == expected.get((n_train, share), math.floor(share * n_train + 1e-9))
    assert flags[-2:] == [False, False]  # never the validation or test recordings
    # spread evenly: between two perturbed recordings, about 1 / share of them
    where = np.flatnonzero(flags)
    if where.size > 1:
        assert np.ptp(np.diff(where)) <= 1


def test_the_perturbation_is_a_label_not_a_feature_of_a_loaded_file(tmp_path):
    simulated = make_lane_keeping(4.0, sampling_rate=20.0, random_state=0, perturbation=0.2)
    simulated.to_csv(tmp_path / "perturbed.csv", index=False)
    loaded = load_recordings(tmp_path / "perturbed.csv")
    assert list(loaded.columns) == list(simulated.columns)
    assert loaded.attrs["units"][PERTURBATION] == "Nm"
    # through CSV text: pandas 2.0's default float parser is not round-trip exact (1e-16 Nm)
    assert_allclose(loaded[PERTURBATION], simulated[PERTURBATION], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: make_lane_keeping(2.0, perturbation=-0.1), "'perturbation' parameter"),
        (lambda: drive(lambda r: 0.0, duration=2.0, perturbation=np.inf), "'perturbation'"),
        (lambda: make_lane_keeping(0.1, perturbation=0.2), "at least 0.2 s"),
        (lambda: make_driving_protocol(duration=2.0, perturbed_share=1.5), "perturbed_share"),
    ],
)
def test_bad_perturbations_are_refused_naming_the_parameter(call, words):
    with pytest.raises(ValueError, match=words):
        call()
