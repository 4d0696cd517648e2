"""The derived inputs chosen by the data: ``friction_velocity="auto"`` and
``velocity_filter="auto"`` of :class:`SteeringFeatures` (the defaults of
``make_torque_pipeline``), and the chosen values in the stream, the model file, the C filter
and the command line."""

import json
import math
import shutil

import numpy as np
import pandas as pd
import pytest
import sklearn

from skhmmgmr import SteeringFeatures, make_torque_pipeline, portable
from skhmmgmr.datasets import to_panel
from skhmmgmr.torque_pipeline import FILTER_CANDIDATES, FRICTION_CANDIDATES, low_pass

COLUMNS = ["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration"]
PERIOD = 0.01
BAND = 0.05  # the friction band of the data


def _recordings(n_recordings=6, seconds=20.0, noise=0.06, seed=0):
    """Smooth steering with a friction torque of band ``BAND``, the velocity measured with
    white noise: the torque reads the true velocity, the inputs the measured one."""
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
        torque = 8.0 * angle + 0.4 * np.tanh(velocity / BAND) + rng.normal(0, 0.01, len(t))
        frames.append(
            pd.DataFrame(
                {
                    "recording": f"r{number}",
                    "steering_wheel_angle": angle + rng.normal(0, 1e-3, len(t)),
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


def _plain_rmse(data, band, time_constant):
    """The held-out RMSE of one candidate by a plain loop: every third recording held out in
    turn, least squares (``numpy.linalg.lstsq``) on the inputs and the derived inputs."""
    groups = data["recording"].to_numpy()
    y = data["driver_torque"].to_numpy()
    derived = SteeringFeatures(friction_velocity=None).fit_transform(data[COLUMNS]).to_numpy()
    velocity = data["steering_wheel_velocity"].to_numpy()
    if time_constant is not None:
        decay = math.exp(-PERIOD / time_constant)
        velocity = np.concatenate(
            [low_pass(velocity[groups == g], decay) for g in pd.unique(groups)]
        )
    inputs = np.column_stack([derived, np.tanh(velocity / band)])
    fold = {g: i % 3 for i, g in enumerate(pd.unique(groups))}
    folds = np.array([fold[g] for g in groups])
    inputs = np.column_stack([np.ones(len(y)), inputs])
    squares = 0.0
    for k in range(3):
        held = folds == k
        coef = np.linalg.lstsq(inputs[~held], y[~held], rcond=None)[0]
        squares += np.sum((inputs[held] @ coef - y[held]) ** 2)
    return math.sqrt(squares / len(y))


def test_auto_chooses_the_band_and_a_velocity_filter_on_noisy_velocities(data):
    step = _auto(sampling_period=PERIOD)
    step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    table = step.friction_search_
    assert len(table) == len(FRICTION_CANDIDATES) * len(FILTER_CANDIDATES)
    assert table["chosen"].sum() == 1
    chosen = table[table["chosen"]].iloc[0]
    assert chosen["validation_rmse"] == table["validation_rmse"].min()
    assert step.friction_velocity_ == chosen["friction_velocity"] == BAND
    # the measured velocity is noisy at the scale of the band: a filter helps
    assert step.velocity_filter_ in FILTER_CANDIDATES and step.velocity_filter_ is not None
    # the transform uses the chosen values
    out = step.transform(data[COLUMNS], groups=data["recording"])
    fixed = SteeringFeatures(
        friction_velocity=BAND, velocity_filter=step.velocity_filter_, sampling_period=PERIOD
    ).fit_transform(data[COLUMNS], groups=data["recording"])
    pd.testing.assert_frame_equal(out, fixed)


@pytest.mark.parametrize("band, time_constant", [(0.025, None), (0.05, 0.02), (0.4, 0.05)])
def test_the_validation_rmse_is_that_of_a_plain_loop(data, band, time_constant):
    step = _auto(sampling_period=PERIOD)
    step.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    table = step.friction_search_
    row = table[
        (table["friction_velocity"] == band)
        & table["velocity_filter"].map(lambda v: v == time_constant)
    ]
    assert len(row) == 1
    expected = _plain_rmse(data, band, time_constant)
    assert row["validation_rmse"].iloc[0] == pytest.approx(expected, rel=1e-7)


def test_the_candidates_follow_the_settings(data):
    X, y, groups = data[COLUMNS], data["driver_torque"], data["recording"]
    # no sampling period: no filter to compare
    step = _auto().fit(X, y, groups=groups)
    assert list(step.friction_search_["velocity_filter"]) == [None] * len(FRICTION_CANDIDATES)
    assert step.velocity_filter_ is None
    # a fixed band: the filters only
    step = SteeringFeatures(velocity_filter="auto", sampling_period=PERIOD).fit(X, y, groups=groups)
    assert list(step.friction_search_["friction_velocity"]) == [0.1] * len(FILTER_CANDIDATES)
    assert step.friction_velocity_ == 0.1
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
    for band in (0.025, 0.1):
        got = step.friction_search_.set_index("friction_velocity")["validation_rmse"][band]
        assert got == pytest.approx(_plain_rmse(frame, band, None), rel=1e-7)


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
    """The torque pipeline with its defaults: the band and the filter chosen in fit."""
    model = make_torque_pipeline(3, sampling_period=PERIOD, n_iter=10, random_state=0)
    model.fit(data[COLUMNS], data["driver_torque"], groups=data["recording"])
    assert model[0].velocity_filter_ is not None  # the stream must follow a chosen filter
    return model


def test_the_stream_follows_the_chosen_settings(pipeline, data):
    X, groups = data[COLUMNS], data["recording"].to_numpy()
    settings = pipeline[0].stream_settings()
    assert settings["friction_velocity"] == pipeline[0].friction_velocity_
    assert settings["filter_decay"] == math.exp(-PERIOD / pipeline[0].velocity_filter_)
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
    params = json.loads(path.read_text())["steps"][0]["params"]
    assert params["friction_velocity"] == pipeline[0].friction_velocity_
    assert params["velocity_filter"] == pipeline[0].velocity_filter_
    restored = portable.load(path)
    assert restored[0].friction_velocity_ == pipeline[0].friction_velocity_
    X, groups = data[COLUMNS], data["recording"]
    np.testing.assert_array_equal(
        restored.predict(X, groups=groups), pipeline.predict(X, groups=groups)
    )
    # a file cannot hold a setting still to choose
    document = json.loads(path.read_text())
    document["steps"][0]["params"]["velocity_filter"] = "auto"
    path.write_text(json.dumps(document))
    with pytest.raises(ValueError, match="'steps.0..params.velocity_filter' must be a number or"):
        portable.load(path)


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler (cc) on this machine")
def test_the_c_filter_follows_the_chosen_settings(pipeline, data, tmp_path):
    from test_export_c import Compiled, _close

    compiled = Compiled(pipeline, tmp_path, name="auto")
    X, groups = data[COLUMNS], data["recording"]
    estimates, _, codes = compiled.run(X, groups)
    assert not codes.any()
    scale = pipeline[-1].model_.standardization.output_scale
    _close(estimates[:, 0], pipeline.predict(X, groups=groups), scale)


def test_the_command_line_chooses_and_reports_the_settings(data, tmp_path, capsys):
    from skhmmgmr.cli import main

    frame = data.assign(time=data.groupby("recording").cumcount() * PERIOD)
    csv, model = tmp_path / "runs.csv", tmp_path / "pipe.json"
    frame.iloc[::2].to_csv(csv, index=False)  # every other row: 50 Hz
    argv = ["fit", str(csv), "--target", "driver_torque", "--features", *COLUMNS]
    argv += ["--n-states", "2", "--pipeline", "torque", "--output", str(model)]
    argv += ["--friction-velocity", "auto", "--velocity-filter", "auto"]
    assert main(argv) == 0
    fitted = portable.load(model)
    band, time_constant = fitted[0].friction_velocity, fitted[0].velocity_filter
    assert band in FRICTION_CANDIDATES and time_constant in FILTER_CANDIDATES
    assert fitted[0].sampling_period == pytest.approx(2 * PERIOD)
    assert f"friction_velocity {band:g}" in capsys.readouterr().out


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
    given = _auto(sampling_period=PERIOD).fit(X, y)
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
