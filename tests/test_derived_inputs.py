"""The derived inputs chosen by the data: ``friction_velocity="auto"`` and
``velocity_filter="auto"`` of :class:`SteeringFeatures` (the defaults of
``make_torque_pipeline``), the friction basis (#53), and the chosen values in the stream, the
model file, the C filter and the command line."""

import json
import math
import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest
import sklearn
from test_pipeline_stream import _plain_play

from skhmmgmr import SteeringFeatures, make_torque_pipeline, portable
from skhmmgmr.datasets import FEATURE_NAMES, make_lane_keeping, to_panel
from skhmmgmr.torque_pipeline import (
    FILTER_CANDIDATES,
    SLOW_FILTER_CANDIDATES,
    WIDTH_GRID,
    low_pass,
)
from skhmmgmr.torque_pipeline._friction_search import LADDER_QUANTILES, velocity_ladder

COLUMNS = ["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration"]
PERIOD = 0.01
BAND = 0.05  # the friction band of the data
LEAD = 0.02  # the lead of the plays of the pipeline fixture [s]
SLOW = 0.1  # the slow velocity filter of the pipeline fixture [s]


def _recordings(
    friction=((0.4, BAND),),
    n_recordings=6,
    seconds=20.0,
    noise=0.06,
    seed=0,
    plays=(),
    angle_noise=1e-3,
    lag=None,
):
    """Smooth steering with a friction torque ``sum(h * tanh(v / w))`` over the ``(h, w)`` of
    ``friction`` and a hysteresis torque ``sum(h * play_r(angle))`` over the ``(h, r)`` of
    ``plays``, the velocity measured with white noise of std ``noise``, the angle with
    ``angle_noise``: the torque reads the true velocity and angle, the inputs the measured
    ones. With ``lag`` [s], the friction reads the true velocity through a first-order filter
    of that time constant (a column whose friction lags the wheel)."""
    rng = np.random.default_rng(seed)
    frames = []
    t = np.arange(0.0, seconds, PERIOD)
    for number in range(n_recordings):
        frequencies = rng.uniform(0.1, 0.8, 4)
        phases = rng.uniform(0, 2 * np.pi, 4)
        amplitudes = rng.uniform(0.01, 0.05, 4)
        angle = sum(
            a * np.sin(2 * np.pi * f * t + p)
            for a, f, p in zip(amplitudes, frequencies, phases, strict=True)
        )
        velocity = sum(
            a * 2 * np.pi * f * np.cos(2 * np.pi * f * t + p)
            for a, f, p in zip(amplitudes, frequencies, phases, strict=True)
        )
        torque = 8.0 * angle + rng.normal(0, 0.01, len(t))
        slowed = velocity if lag is None else low_pass(velocity, math.exp(-PERIOD / lag))
        torque += sum(height * np.tanh(slowed / width) for height, width in friction)
        torque += sum(height * _plain_play(angle, radius) for height, radius in plays)
        frames.append(
            pd.DataFrame(
                {
                    "recording": f"r{number}",
                    "steering_wheel_angle": angle + rng.normal(0, angle_noise, len(t)),
                    "steering_wheel_velocity": velocity + rng.normal(0, noise, len(t)),
                    "lateral_acceleration": 60.0 * angle + rng.normal(0, 0.5, len(t)),
                    "driver_torque": torque,
                }
            )
        )
    return pd.concat(frames, ignore_index=True)


@pytest.fixture(scope="module")
def data():
    return _recordings()


def _auto(**params):
    return SteeringFeatures(friction_velocity="auto", velocity_filter="auto", **params)


def _filtered(velocity, groups, time_constant):
    """The velocity through the filter, recording by recording (``low_pass``)."""
    if time_constant is None:
        return velocity
    decay = math.exp(-PERIOD / time_constant)
    return np.concatenate([low_pass(velocity[groups == g], decay) for g in pd.unique(groups)])


def _plain_rmse(data, widths, time_constant):
    """The held-out RMSE of one candidate by a plain loop: every third recording held out in
    turn, least squares (``numpy.linalg.lstsq``) on the inputs, the load inputs and the
    friction basis ``tanh(v / w)`` of ``widths`` (none for None)."""
    groups = data["recording"].to_numpy()
    y = data["driver_torque"].to_numpy()
    derived = SteeringFeatures(friction_velocity=None).fit_transform(data[COLUMNS]).to_numpy()
    velocity = _filtered(data["steering_wheel_velocity"].to_numpy(), groups, time_constant)
    basis = [np.tanh(velocity / width) for width in widths or ()]
    inputs = np.column_stack([np.ones(len(y)), derived, *basis])
    fold = {g: i % 3 for i, g in enumerate(pd.unique(groups))}
    folds = np.array([fold[g] for g in groups])
    squares = 0.0
    for k in range(3):
        held = folds == k
        coef = np.linalg.lstsq(inputs[~held], y[~held], rcond=None)[0]
        squares += np.sum((inputs[held] @ coef - y[held]) ** 2)
    return math.sqrt(squares / len(y))


def _choice(friction, noise):
    data = _recordings(friction, noise=noise)
    step = _auto(sampling_period=PERIOD)
    return step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])


@pytest.mark.parametrize(
    "friction, widths",
    [
        (((0.4, 0.05),), (0.05,)),  # one band of the grid: that band alone
        (((0.4, 0.2),), (0.2,)),
        ((), None),  # no friction: no friction input
    ],
)
def test_auto_finds_a_known_band_and_no_friction_where_there_is_none(friction, widths):
    """Clean velocities (noise 1 mrad/s): the friction the torque holds is the answer."""
    step = _choice(friction, noise=0.001)
    assert step.friction_velocity_ == widths
    if widths is None:
        assert step.velocity_filter_ is None
        assert not any(n.startswith("steering_friction") for n in step.get_feature_names_out())


@pytest.mark.parametrize(
    "friction, plays, widths, radii",
    [
        ((), ((0.4, 0.004),), None, (0.004,)),  # a play alone: that play
        (((0.3, 0.05),), ((0.3, 0.004),), (0.05,), (0.004,)),  # both
        (((0.4, 0.05),), (), (0.05,), None),  # a band alone: no play
        ((), (), None, None),  # neither
    ],
)
def test_auto_finds_a_known_play_beside_the_band(friction, plays, widths, radii):
    """Exact angles, clean velocities: the hysteresis the torque holds (a play of half-width
    4 mrad on the angle) is found with the friction band, or not at all where there is none."""
    data = _recordings(friction, plays=plays, noise=0.001, angle_noise=0.0)
    step = _auto(sampling_period=PERIOD, friction_angle="auto")
    step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    assert (step.friction_velocity_, step.friction_angle_) == (widths, radii)
    names = list(step.get_feature_names_out())
    assert ("steering_hysteresis_0.004" in names) == (radii is not None)


def test_sharp_friction_gets_narrow_widths_and_two_bands_a_basis():
    """A band of 5 mrad/s, below the grid's 6.25: a basis from the narrowest width the
    velocity resolves; a friction curve of two bands (5 and 100 mrad/s): a basis spanning
    both, more accurate than any single band."""
    sharp = _choice(((0.4, 0.005),), noise=0.001)
    widths = sharp.friction_velocity_
    velocity_resolved = velocity_ladder(_recordings(((0.4, 0.005),), noise=0.001)[COLUMNS[1]])
    assert widths[0] == velocity_resolved[0] <= 0.00625 and len(widths) >= 2
    assert widths == WIDTH_GRID[WIDTH_GRID.index(widths[0]) :][: len(widths)]  # consecutive
    double = _choice(((0.2, 0.005), (0.2, 0.1)), noise=0.001)
    widths = double.friction_velocity_
    assert widths[0] <= 0.00625 and widths[-1] >= 0.1
    table = double.friction_search_
    single = table[table["n_friction_inputs"] == 1]["validation_rmse"].min()
    assert table[table["chosen"]]["validation_rmse"].iloc[0] < 0.5 * single


def _simulated(vehicle, sensor_noise="typical"):
    """Six 40-second recordings of the simulator at 50 Hz (three driver styles) in the
    reference car with ``vehicle``'s parameters, the friction inputs chosen on them."""
    frames = [
        make_lane_keeping(
            40.0,
            driver=style,
            sampling_rate=50.0,
            random_state=seed,
            vehicle=vehicle,
            sensor_noise=sensor_noise,
            recording=f"{style}-{seed}",
        )
        for seed, style in enumerate(["defensive", "aggressive", "novice"] * 2)
    ]
    data = pd.concat(frames, ignore_index=True)
    step = SteeringFeatures(friction_velocity="auto")
    step.fit(data[list(FEATURE_NAMES)], data["driver_torque"], groups=data["recording"])
    return step.friction_velocity_


def test_a_simulated_car_gets_the_widths_of_its_friction():
    """The simulator's column: a sharp band (3 mrad/s) gets a basis from a narrow width, a
    smooth one (0.3 rad/s) wide bands only, a column without friction no friction input. With
    the sensors' true values the narrowest width is the band's; measured (the angle in steps of
    0.1 deg: 87 mrad/s at 50 Hz), the velocity resolves less, and the sharp band's narrowest
    width is still a sixteenth of the smooth one's at most."""
    sharp = _simulated({"friction_velocity": 0.003}, sensor_noise=None)
    smooth = _simulated({"friction_velocity": 0.3}, sensor_noise=None)
    assert sharp[0] <= 0.0032 and min(smooth) >= 0.025
    sharp = _simulated({"friction_velocity": 0.003})
    smooth = _simulated({"friction_velocity": 0.3})
    assert sharp[0] <= smooth[0] / 16
    assert _simulated({"wheel_friction": 0.0}) is None


def test_the_ladder_reads_the_velocitys_scale_through_each_filter():
    """The ladder of every filter candidate runs from the narrowest band whose transition
    ``|v| < 2 w`` holds the low quantile of the (filtered) velocity's sizes to the widest at
    most its high quantile; on a velocity noisier than the steering (0.5 rad/s), the filter,
    which takes noise out, lets narrower bands in."""
    data = _recordings(noise=0.5)
    step = _auto(sampling_period=PERIOD)
    step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    table = step.friction_search_
    groups = data["recording"].to_numpy()
    ladders = {}
    for time_constant in FILTER_CANDIDATES:
        velocity = _filtered(data[COLUMNS[1]].to_numpy(), groups, time_constant)
        size = np.abs(velocity[velocity != 0])
        low, high = np.quantile(size, LADDER_QUANTILES)
        expected = tuple(w for w in WIDTH_GRID if 2 * w >= low and w <= high)
        rows = table[table["velocity_filter"].map(lambda v, tc=time_constant: v == tc)]
        longest = max((w for w in rows["friction_velocity"] if w is not None), key=len)
        assert longest == expected
        # every window of consecutive widths, and no friction input
        n = len(expected)
        assert len(rows) == 1 + n * (n + 1) // 2
        ladders[time_constant] = expected
    assert ladders[0.05][0] < ladders[None][0]


def test_the_basis_is_the_hand_built_design_matrix(data):
    """A basis of widths (the issue's 3 to 50 mrad/s) is the columns ``numpy.tanh(v / w)``,
    with the velocity filter a plain loop's, then the load inputs; named by their widths,
    unit 1."""
    widths = (0.003, 0.006, 0.012, 0.025, 0.05)
    X, groups = data[COLUMNS], data["recording"].to_numpy()
    X = X.copy()
    X.attrs["units"] = {"steering_wheel_velocity": "rad/s"}
    for time_constant in (None, 0.02):
        step = SteeringFeatures(
            friction_velocity=widths, velocity_filter=time_constant, sampling_period=PERIOD
        )
        out = step.fit_transform(X, groups=groups)
        velocity = X[COLUMNS[1]].to_numpy()
        if time_constant is not None:
            velocity = np.concatenate(
                [
                    _plain_filter(velocity[groups == g], math.exp(-PERIOD / time_constant))
                    for g in pd.unique(groups)
                ]
            )
        angle, acceleration = X[COLUMNS[0]].to_numpy(), X[COLUMNS[2]].to_numpy()
        expected = np.column_stack(
            [
                X.to_numpy(),
                *[np.tanh(velocity / w) for w in widths],
                angle * np.abs(angle),
                angle**3,
                acceleration * np.abs(acceleration),
                acceleration**3,
            ]
        )
        np.testing.assert_allclose(out.to_numpy(), expected, rtol=1e-12, atol=0)
        names = ["0.003", "0.006", "0.012", "0.025", "0.05"]
        assert list(out.columns[3:8]) == [f"steering_friction_{n}" for n in names]
        assert all(out.attrs["units"][name] == "1" for name in out.columns[3:8])
    # a list is a basis too; an array in, an array out, the same numbers
    array = SteeringFeatures(friction_velocity=list(widths), friction_column=1, load_columns=(0, 2))
    named = SteeringFeatures(friction_velocity=widths).fit_transform(X)
    np.testing.assert_array_equal(array.fit_transform(X.to_numpy()), named.to_numpy())
    assert array.friction_velocity_ == widths


def _plain_filter(values, decay):
    out, state = [], None
    for value in values:
        state = value if state is None else decay * state + (1.0 - decay) * value
        out.append(state)
    return np.array(out)


@pytest.mark.parametrize(
    "widths, message",
    [
        ((), "holds no width"),
        ((0.01, -0.02), "widths > 0"),
        ((0.01, float("nan")), "widths > 0"),
        ((0.01, True), "widths > 0"),
        ((0.01, 0.0100001), "repeats a width"),
    ],
)
def test_a_bad_basis_is_refused_naming_it(data, widths, message):
    with pytest.raises(ValueError, match=message):
        SteeringFeatures(friction_velocity=widths).fit(data[COLUMNS])


@pytest.mark.parametrize(
    "widths, time_constant", [(None, None), ((0.025,), None), ((0.05, 0.1), 0.02)]
)
def test_the_validation_rmse_is_that_of_a_plain_loop(data, widths, time_constant):
    step = _auto(sampling_period=PERIOD)
    step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    table = step.friction_search_
    row = table[
        (table["friction_velocity"].map(lambda w: w == widths))
        & table["velocity_filter"].map(lambda v: v == time_constant)
    ]
    assert len(row) == 1
    expected = _plain_rmse(data, widths, time_constant)
    assert row["validation_rmse"].iloc[0] == pytest.approx(expected, rel=1e-7)


def test_the_rule_takes_the_fewest_inputs_near_the_least_error(data):
    step = _auto(sampling_period=PERIOD)
    step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    table = step.friction_search_
    assert table["chosen"].sum() == 1
    chosen = table[table["chosen"]].iloc[0]
    least = table["validation_rmse"].min()
    assert chosen["validation_rmse"] <= least * 1.002
    fewer = table[table["n_friction_inputs"] < chosen["n_friction_inputs"]]
    assert (fewer["validation_rmse"] > least * 1.002).all()
    assert step.friction_velocity_ == chosen["friction_velocity"]
    assert step.velocity_filter_ == chosen["velocity_filter"]
    # the transform uses the chosen values
    out = step.transform(data[COLUMNS], groups=data["recording"])
    fixed = SteeringFeatures(
        friction_velocity=step.friction_velocity_,
        velocity_filter=step.velocity_filter_,
        sampling_period=PERIOD,
    ).fit_transform(data[COLUMNS], groups=data["recording"])
    pd.testing.assert_frame_equal(out, fixed)


def test_the_candidates_follow_the_settings(data):
    X, y, groups = data[COLUMNS], data["driver_torque"], data["recording"]
    # no sampling period: no filter to compare
    step = _auto().fit(X, y, groups=groups)
    assert set(step.friction_search_["velocity_filter"]) == {None}
    assert step.velocity_filter_ is None
    # a fixed band: the filters only, the band kept as it is
    step = SteeringFeatures(velocity_filter="auto", sampling_period=PERIOD).fit(X, y, groups=groups)
    assert list(step.friction_search_["friction_velocity"]) == [0.1] * len(FILTER_CANDIDATES)
    assert step.friction_velocity_ == 0.1
    assert "steering_friction" in step.get_feature_names_out()
    # a fixed basis: the filters only
    step = SteeringFeatures(
        friction_velocity=(0.05, 0.1), velocity_filter="auto", sampling_period=PERIOD
    )
    step.fit(X, y, groups=groups)
    assert list(step.friction_search_["friction_velocity"]) == [(0.05, 0.1)] * len(
        FILTER_CANDIDATES
    )
    assert step.friction_velocity_ == (0.05, 0.1)
    # no friction input: nothing to choose
    step = SteeringFeatures(friction_velocity=None, velocity_filter="auto").fit(X)
    assert step.friction_search_ is None and step.velocity_filter_ is None
    assert "steering_friction" not in step.get_feature_names_out()
    # fixed values: no search, and no target needed
    step = SteeringFeatures(friction_velocity=0.2).fit(X)
    assert step.friction_search_ is None and step.friction_velocity_ == 0.2


def test_one_recording_is_cut_in_consecutive_folds(data):
    """Without recordings, the folds are three blocks of consecutive rows: the RMSE is that of
    the plain loop over those blocks."""
    X, y = data[COLUMNS].iloc[:3000], data["driver_torque"].iloc[:3000]
    step = SteeringFeatures(friction_velocity="auto").fit(X, y)
    blocks = pd.Series(np.repeat(["b0", "b1", "b2"], 1000))
    frame = pd.concat([X, y], axis=1).assign(recording=blocks.to_numpy())
    table = step.friction_search_
    for widths in (None, (0.025,), (0.025, 0.05, 0.1)):
        got = table[table["friction_velocity"].map(lambda w, ws=widths: w == ws)]
        assert len(got) == 1
        expected = _plain_rmse(frame, widths, None)
        assert got["validation_rmse"].iloc[0] == pytest.approx(expected, rel=1e-7)


def test_auto_needs_the_target(data):
    with pytest.raises(ValueError, match="fit needs y"):
        _auto().fit(data[COLUMNS])
    with pytest.raises(ValueError, match="at least 2 parts"):
        _auto().fit(data[COLUMNS].iloc[:5], data["driver_torque"].iloc[:5])


def test_the_choice_is_deterministic_and_ignores_the_row_order_in_the_pipeline(data):
    X, y, groups = data[COLUMNS], data["driver_torque"], data["recording"].to_numpy()
    first = make_torque_pipeline(2, sampling_period=PERIOD, n_iter=3, random_state=0)
    first.fit(X, y, groups=groups)
    order = np.random.default_rng(1).permutation(pd.unique(groups))
    rows = np.concatenate([np.flatnonzero(groups == g) for g in order])
    again = make_torque_pipeline(2, sampling_period=PERIOD, n_iter=3, random_state=0)
    again.fit(X.iloc[rows], y.iloc[rows], groups=groups[rows])
    pd.testing.assert_frame_equal(first[0].friction_search_, again[0].friction_search_)


@pytest.fixture(scope="module")
def pipeline(data):
    """The torque pipeline with its defaults, the plays led on the velocity and a slow
    velocity: the friction basis and the filter chosen in fit."""
    model = make_torque_pipeline(
        3,
        sampling_period=PERIOD,
        n_iter=10,
        random_state=0,
        angle_lead=LEAD,
        slow_velocity_filter=SLOW,
    )
    model.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    assert model[0].velocity_filter_ is not None  # the stream must follow a chosen filter
    assert len(model[0].friction_velocity_) >= 2  # a basis
    assert model[0].friction_angle_ is not None  # and plays
    assert model[0].angle_lead_ == LEAD  # led on the velocity
    assert model[0].slow_velocity_filter_ == SLOW  # and the friction basis of a slow velocity
    return model


def test_the_stream_follows_the_chosen_settings(pipeline, data):
    X, groups = data[COLUMNS], data["recording"].to_numpy()
    settings = pipeline[0].stream_settings()
    assert settings["friction_velocity"] == list(pipeline[0].friction_velocity_)
    assert settings["friction_angle"] == list(pipeline[0].friction_angle_)
    assert (settings["angle_lead"], settings["lead_position"]) == (LEAD, 1)
    assert settings["filter_decay"] == math.exp(-PERIOD / pipeline[0].velocity_filter_)
    assert settings["slow_filter_decay"] == math.exp(-PERIOD / SLOW)
    stream = pipeline.filter_stream()
    estimates = []
    for recording in pd.unique(groups):
        stream.reset()
        estimates += [stream.update(row) for row in X.to_numpy()[groups == recording]]
    expected = pipeline.predict(X, groups=groups)
    np.testing.assert_allclose(estimates, expected, rtol=0, atol=1e-12)


def test_the_model_file_holds_the_chosen_values(pipeline, data, tmp_path):
    path = tmp_path / "pipe.json"
    portable.save(pipeline, path, output_names=["driver_torque"])
    document = json.loads(path.read_text())
    params = document["steps"][0]["params"]
    assert params["friction_velocity"] == list(pipeline[0].friction_velocity_)
    assert params["friction_angle"] == list(pipeline[0].friction_angle_)
    assert params["angle_column"] == "steering_wheel_angle"
    assert params["angle_lead"] == LEAD
    assert params["slow_velocity_filter"] == SLOW
    assert params["velocity_filter"] == pipeline[0].velocity_filter_
    # a basis needs no new format version (older readers refuse it, never misread it)
    assert document["format_version"] == document["steps"][-1]["model"]["format_version"]
    restored = portable.load(path)
    assert restored[0].friction_velocity_ == pipeline[0].friction_velocity_
    assert restored[0].friction_angle_ == pipeline[0].friction_angle_
    assert restored[0].angle_lead_ == LEAD
    assert restored[0].slow_velocity_filter_ == SLOW
    X, groups = data[COLUMNS], data["recording"]
    np.testing.assert_array_equal(
        restored.predict(X, groups=groups), pipeline.predict(X, groups=groups)
    )
    np.testing.assert_array_equal(
        restored[0].transform(X, groups=groups), pipeline[0].transform(X, groups=groups)
    )
    # a file cannot hold a setting still to choose, nor a basis fit would refuse
    velocity, angle = "friction_velocity", "friction_angle"
    for key, value, message in [
        (
            velocity,
            "auto",
            "'steps[0].params.friction_velocity' must be a number or null or a list",
        ),
        (velocity, [0.01, -1.0], "'steps[0].params.friction_velocity[1]' must be greater than 0"),
        (velocity, [], "'steps[0].params.friction_velocity' must be a non-empty list"),
        (velocity, [0.01, 0.01], "'steps[0].params.friction_velocity' holds [0.01] more than once"),
        (velocity, [0.01, 0.0100001], "repeats a width"),
        (angle, "auto", "'steps[0].params.friction_angle' must be a list"),
        (angle, 0.004, "'steps[0].params.friction_angle' must be a list"),
        (angle, [0.004, 0.0], "'steps[0].params.friction_angle[1]' must be greater than 0"),
        (angle, [0.004, 0.0040001], "friction_angle=(0.004, 0.0040001) repeats a width"),
        ("angle_lead", "auto", "'steps[0].params.angle_lead' must be a number"),
        ("slow_velocity_filter", "auto", "'steps[0].params.slow_velocity_filter' must be a"),
        ("slow_velocity_filter", 0.0, "'steps[0].params.slow_velocity_filter' must be greater"),
    ]:
        bad = json.loads(json.dumps(document))
        bad["steps"][0]["params"][key] = value
        path.write_text(json.dumps(bad))
        with pytest.raises(ValueError, match=re.escape(message)):
            portable.load(path)
    document["steps"][0]["params"]["velocity_filter"] = "auto"
    path.write_text(json.dumps(document))
    with pytest.raises(ValueError, match="'steps.0..params.velocity_filter' must be a number or"):
        portable.load(path)


def test_a_step_without_plays_writes_the_keys_of_before(data, tmp_path):
    """The keys of the hysteresis inputs are written only with them: the file of a step
    without them is one an older reader reads."""
    X, y, groups = data[COLUMNS], data["driver_torque"], data["recording"]
    pipeline = make_torque_pipeline(1, friction_angle=None, velocity_filter=None)
    portable.save(pipeline.fit(X, y, groups=groups), tmp_path / "pipe.json")
    params = json.loads((tmp_path / "pipe.json").read_text())["steps"][0]["params"]
    old = ["friction_velocity", "friction_column", "load_columns", "powers", "velocity_filter"]
    assert list(params) == [*old, "sampling_period"]
    assert portable.load(tmp_path / "pipe.json")[0].friction_angle_ is None


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler (cc) on this machine")
def test_the_c_filter_follows_the_chosen_settings(pipeline, data, tmp_path):
    """Double precision to 1e-12 of predict; single precision throughout (built with
    -Wdouble-promotion -Werror, no double-precision libm function) within the C tests'
    float tolerance."""
    from test_export_c import (
        CC,
        DOUBLE_LIBM,
        FLOAT32_FLAGS,
        FLOAT32_RTOL,
        Compiled,
        _close,
        _undefined_symbols,
    )

    X, groups = data[COLUMNS], data["recording"]
    expected = pipeline.predict(X, groups=groups)
    scale = pipeline[-1].model_.standardization.output_scale
    compiled = Compiled(pipeline, tmp_path, name="auto")
    assert "friction_widths" in compiled.paths[1].read_text()
    assert "slow_low_pass(state, inputs[1])" in compiled.paths[1].read_text()
    estimates, _, codes = compiled.run(X, groups)
    assert not codes.any()
    np.testing.assert_allclose(estimates[:, 0], expected, rtol=0, atol=1e-12)
    single = Compiled(pipeline, tmp_path, name="single", dtype="float32")
    estimates, _, codes = single.run(X, groups)
    assert not codes.any()
    _close(estimates[:, 0], expected, scale, FLOAT32_RTOL)
    obj = tmp_path / "single.o"
    build = [CC, *FLOAT32_FLAGS, "-c", str(single.paths[1]), "-o", str(obj)]
    subprocess.run(build, check=True, capture_output=True)
    undefined = _undefined_symbols("nm", obj)
    assert not undefined & DOUBLE_LIBM and "tanhf" in undefined, undefined


def test_the_command_line_chooses_and_reports_the_settings(data, tmp_path, capsys):
    from skhmmgmr.cli import main

    frame = data.assign(time=data.groupby("recording").cumcount() * PERIOD)
    csv, model = tmp_path / "runs.csv", tmp_path / "pipe.json"
    frame.iloc[::2].to_csv(csv, index=False)  # every other row: 50 Hz
    argv = ["fit", str(csv), "--target", "driver_torque", "--features", *COLUMNS]
    argv += ["--n-states", "2", "--pipeline", "torque", "--output", str(model)]
    argv += ["--friction-velocity", "auto", "--velocity-filter", "auto"]
    assert main([*argv, "--slow-velocity-filter", str(SLOW)]) == 0
    fitted = portable.load(model)
    widths, time_constant = fitted[0].friction_velocity, fitted[0].velocity_filter
    assert set(widths) <= set(WIDTH_GRID) and time_constant in FILTER_CANDIDATES
    assert fitted[0].sampling_period == pytest.approx(2 * PERIOD)
    assert fitted[0].slow_velocity_filter_ == SLOW
    listed = ", ".join(f"{w:g}" for w in widths)
    out = capsys.readouterr().out
    assert f"friction_velocity {listed}, velocity_filter" in out
    assert f"slow_velocity_filter {SLOW:g}" in out


def test_the_recordings_reach_the_choice_by_every_path(data):
    """groups with metadata routing off or on, or a panel's index: the same folds, the same
    table."""

    def table(X, y, **groups):
        model = make_torque_pipeline(2, sampling_period=PERIOD, n_iter=2, random_state=0)
        return model.fit(X, y, **groups)[0].friction_search_

    X, y, groups = data[COLUMNS], data["driver_torque"], data["recording"].to_numpy()
    expected = table(X, y, groups=groups)
    with sklearn.config_context(enable_metadata_routing=True):
        pd.testing.assert_frame_equal(table(X, y, groups=groups), expected)
    panel = to_panel(data.assign(time=data.groupby("recording").cumcount() * PERIOD))
    pd.testing.assert_frame_equal(table(panel[COLUMNS], panel["driver_torque"]), expected)
    # one recording: other folds, another table
    assert not np.allclose(
        table(X, y)["validation_rmse"].to_numpy(), expected["validation_rmse"].to_numpy()
    )


def test_the_sampling_period_is_read_from_a_panels_time_index(data):
    """#51 item 13: fitted on a panel whose time index says 0.01 s, the pipeline never
    considered the velocity filter (the command line infers the period)."""
    panel = to_panel(data.assign(time=data.groupby("recording").cumcount() * PERIOD))
    X, y = panel[COLUMNS], panel["driver_torque"]
    pipe = make_torque_pipeline(2, n_iter=2, random_state=0).fit(X, y)
    assert pipe[0].sampling_period_ == pytest.approx(PERIOD, rel=1e-12)
    assert pipe[0].sampling_period is None  # the parameter stays as given
    considered = set(pipe[0].friction_search_["velocity_filter"])
    assert considered == set(FILTER_CANDIDATES)
    # the same choice as with the period given, and a fixed filter needs no more
    given = _auto(
        sampling_period=PERIOD,
        friction_angle="auto",
        angle_lead="auto",
        slow_velocity_filter="auto",
    ).fit(X, y)
    pd.testing.assert_frame_equal(pipe[0].friction_search_, given.friction_search_)
    fixed = SteeringFeatures(velocity_filter=0.02).fit(X)
    assert fixed.sampling_period_ == pytest.approx(PERIOD, rel=1e-12)
    assert fixed.stream_settings()["filter_decay"] == pytest.approx(math.exp(-PERIOD / 0.02))
    # without a time level there is nothing to read: no filter considered, a fixed one refused
    plain = _auto().fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    assert plain.sampling_period_ is None
    assert set(plain.friction_search_["velocity_filter"]) == {None}
    with pytest.raises(ValueError, match="needs sampling_period.*'time' index level"):
        SteeringFeatures(velocity_filter=0.02).fit(data[COLUMNS])


def test_the_model_file_keeps_the_period_read_from_the_index(data, tmp_path):
    panel = to_panel(data.assign(time=data.groupby("recording").cumcount() * PERIOD))
    X, y = panel[COLUMNS], panel["driver_torque"]
    step = SteeringFeatures(velocity_filter=0.02)
    pipe = make_torque_pipeline(2, velocity_filter=0.02, n_iter=2, random_state=0).fit(X, y)
    portable.save(pipe, tmp_path / "pipe.json")
    loaded = portable.load(tmp_path / "pipe.json")
    assert loaded[0].sampling_period == pytest.approx(PERIOD)
    np.testing.assert_allclose(loaded.predict(X), pipe.predict(X), rtol=0, atol=1e-12)
    assert step.get_params()["sampling_period"] is None
    # the FMU runs at the period the filter was made for, refusing another
    from skhmmgmr.export import write_fmu

    write_fmu(pipe, tmp_path / "driver.fmu", binary=False)
    with pytest.raises(ValueError, match="not the period"):
        write_fmu(pipe, tmp_path / "other.fmu", binary=False, sampling_period=2 * PERIOD)


def test_a_target_of_other_rows_is_refused_naming_both_lengths(data):
    """#51 item 22: y one row short gave "cannot reshape array of size 599"; one shared
    check (in_filter_order) names the lengths wherever the pipeline reads per-row
    arguments."""
    X, y = data[COLUMNS].iloc[:600], data["driver_torque"].iloc[:600]
    short = y.to_numpy()[:-1]
    with pytest.raises(ValueError, match="X has 600, y has 599"):
        _auto().fit(X, short)
    pipe = make_torque_pipeline(2, n_iter=2, random_state=0)
    with pytest.raises(ValueError, match="X has 600, y has 599"):
        pipe.fit(X, short)
    pipe.fit(X, y)
    with pytest.raises(ValueError, match="X has 600, y has 599"):
        pipe.score(X, short)
    with pytest.raises(ValueError, match="X has 600, sample_weight has 599"):
        pipe.score(X, y, sample_weight=np.ones(599))
    with pytest.raises(ValueError, match="X has 600, y has 599"):
        pipe.adapt(X, short)
    with pytest.raises(ValueError, match="X has 600, time has 599"):
        pipe.predict(X, time=np.arange(599) * PERIOD)


def test_the_plays_read_the_angle_led_on_the_velocity():
    """``angle_lead``: every hysteresis input is the plain loop's play of ``angle + lead *
    velocity``, restarted at each recording; a missing velocity is a missing led angle."""
    data = _recordings(n_recordings=2, seconds=2.0, plays=((0.3, 0.004),))
    data.loc[[5, 250], "steering_wheel_velocity"] = np.nan
    radii, lead = (0.002, 0.008), 0.03
    step = SteeringFeatures(friction_velocity=None, load_columns=(), friction_angle=radii)
    derived = step.set_params(angle_lead=lead).fit_transform(
        data[COLUMNS], groups=data["recording"]
    )
    for recording in pd.unique(data["recording"]):
        rows = (data["recording"] == recording).to_numpy()
        led = data.loc[rows, COLUMNS[0]] + lead * data.loc[rows, COLUMNS[1]]
        for r in radii:
            expected = _plain_play(led.to_numpy(), r)
            np.testing.assert_array_equal(
                derived.loc[rows, f"steering_hysteresis_{r:.3g}"], expected
            )
    assert np.isnan(derived.loc[[5, 250], "steering_hysteresis_0.002"]).all()
    unled = step.set_params(angle_lead=0.0).fit_transform(data[COLUMNS], groups=data["recording"])
    assert step.angle_lead_ is None  # a lead of 0 is the angle itself
    expected = _plain_play(data[COLUMNS[0]].to_numpy()[:200], 0.002)
    np.testing.assert_array_equal(unled["steering_hysteresis_0.002"].to_numpy()[:200], expected)


@pytest.mark.parametrize("late_rows, lead", [(0, None), (5, 0.05)])
def test_auto_leads_an_angle_sensor_that_is_late(late_rows, lead):
    """The torque follows a play of the true angle; an angle sensor ``late_rows`` rows (50
    ms) late reads ``angle(t - 0.05) ~ angle(t) - 0.05 velocity``: ``"auto"`` leads the plays
    by those 50 ms on the (exact) velocity, and by nothing when the angle is on time."""
    data = _recordings((), plays=((0.4, 0.004),), noise=0.001, angle_noise=0.0)
    if late_rows:
        angle = data.groupby("recording")[COLUMNS[0]].shift(late_rows)
        data = data.assign(steering_wheel_angle=angle).dropna()
    step = _auto(sampling_period=PERIOD, friction_angle="auto", angle_lead="auto")
    step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    assert step.friction_angle_ is not None
    assert step.angle_lead_ == lead
    table = step.friction_search_
    assert set(table["angle_lead"].dropna()) == {0.02, 0.05}
    assert table.loc[table["friction_angle"].isna(), "angle_lead"].isna().all()


@pytest.mark.parametrize(
    "name",
    [
        "friction_velocity",
        "velocity_filter",
        "sampling_period",
        "angle_lead",
        "slow_velocity_filter",
    ],
)
def test_an_infinite_setting_is_refused(data, name):
    """Refused naming the parameter: by its constraint where scikit-learn's intervals exclude
    infinity, by the step's own check on the oldest versions, whose intervals let it in."""
    params = {"friction_angle": 0.004, "sampling_period": PERIOD, name: math.inf}
    with pytest.raises(ValueError, match=f"{name}' parameter .* Got inf|{name} must be finite"):
        SteeringFeatures(**params).fit(data[COLUMNS])


def _plain_low_pass(values, decay):
    """The first-order filter by a plain loop: started at the first observed value, ``y =
    decay y + (1 - decay) x``; after ``g`` missing values ``decay^(g + 1)`` in place of
    ``decay``; NaN where the value is missing."""
    out, last, lapse = [], None, decay
    for x in values:
        if math.isnan(x):
            out.append(math.nan)
            lapse *= decay
            continue
        last = x if last is None else lapse * last + (1.0 - lapse) * x
        out.append(last)
        lapse = decay
    return np.array(out)


def test_the_slow_velocity_is_a_plain_loops_first_order_filter():
    """``slow_velocity_filter``: the friction inputs of the velocity through its own filter,
    restarted at each recording, after the unchanged friction inputs of the measured one."""
    data = _recordings(n_recordings=2, seconds=2.0)
    data.loc[[5, 6, 250], "steering_wheel_velocity"] = np.nan
    widths, groups = (0.01, 0.05), data["recording"]
    plain = SteeringFeatures(friction_velocity=widths, load_columns=(), sampling_period=PERIOD)
    step = plain.set_params(slow_velocity_filter=SLOW)
    derived = step.fit_transform(data[COLUMNS], groups=groups)
    fast = ["steering_friction_0.01", "steering_friction_0.05"]
    slow = ["steering_friction_slow_0.01", "steering_friction_slow_0.05"]
    assert list(derived.columns[3:]) == fast + slow
    unslowed = SteeringFeatures(friction_velocity=widths, load_columns=()).fit_transform(
        data[COLUMNS], groups=groups
    )
    pd.testing.assert_frame_equal(derived[fast], unslowed[fast])
    for recording in pd.unique(groups):
        rows = (groups == recording).to_numpy()
        velocity = data.loc[rows, "steering_wheel_velocity"].to_numpy()
        slowed = _plain_low_pass(velocity, math.exp(-PERIOD / SLOW))
        for name, width in zip(slow, widths, strict=True):
            expected = np.tanh(slowed / width)
            np.testing.assert_allclose(derived.loc[rows, name], expected, rtol=1e-12, atol=1e-15)
    assert np.isnan(derived.loc[[5, 6, 250], slow]).all().all()
    with pytest.raises(ValueError, match="slow_velocity_filter=0.1 needs sampling_period"):
        step.set_params(sampling_period=None).fit(data[COLUMNS])
    with pytest.raises(ValueError, match="'slow_velocity_filter' parameter"):
        step.set_params(slow_velocity_filter=-0.1).fit(data[COLUMNS])


@pytest.mark.parametrize("lag", [None, 0.1, 0.2])
def test_auto_slows_the_velocity_of_a_friction_that_lags(lag):
    """The friction torque reads the true velocity through a filter of ``lag`` seconds:
    ``"auto"`` takes the slow velocity of that time constant, and none when the friction reads
    the velocity itself (measured with little noise: no filter needed to see it)."""
    data = _recordings(noise=0.001, lag=lag, n_recordings=3, seconds=10.0)
    step = _auto(sampling_period=PERIOD, slow_velocity_filter="auto")
    step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    assert step.slow_velocity_filter_ == lag
    assert set(step.friction_search_["slow_velocity_filter"]) == set(SLOW_FILTER_CANDIDATES)
