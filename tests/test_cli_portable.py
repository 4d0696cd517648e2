"""``skhmmgmr fit --pipeline torque`` and ``skhmmgmr predict`` of either kind of model file,
with the accuracy and smoothness of every recording when the data hold the target."""

import numpy as np
import pandas as pd
import pytest

from skhmmgmr import HMMGMRRegressor, make_torque_pipeline, portable
from skhmmgmr.cli import main
from skhmmgmr.datasets import make_lane_keeping
from skhmmgmr.metrics import evaluate_recordings
from skhmmgmr.torque_pipeline import WIDTH_GRID, TorquePipeline

pytest.importorskip("pyarrow")

INPUTS = ["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration", "yaw_rate"]
TARGET = "driver_torque"
FIT = ["fit", "--target", TARGET, "--n-states", "2", "--features", *INPUTS]


def recordings(sampling_rate=20.0, seeds=(0, 1, 2)):
    frames = [
        make_lane_keeping(15.0, sampling_rate=sampling_rate, random_state=s, recording=f"r{s}")
        for s in seeds
    ]
    return pd.concat(frames, ignore_index=True)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The recordings as CSV and Parquet, and the torque pipeline fitted from the CSV with a
    velocity filter (its sampling period read from the time column)."""
    folder = tmp_path_factory.mktemp("cli")
    data = recordings()
    csv, parquet = folder / "runs.csv", folder / "runs.parquet"
    data.to_csv(csv, index=False)
    data.to_parquet(parquet)
    model = folder / "pipe.json"
    argv = [*FIT, "--pipeline", "torque", "--velocity-filter", "0.1", "--friction-angle", "none"]
    argv += ["--output", str(model)]
    argv.insert(1, str(parquet))
    assert main(["--quiet", *argv]) == 0
    return dict(data=data, csv=csv, parquet=parquet, model=model, folder=folder)


def test_fit_writes_the_torque_pipeline_with_its_options(files):
    pipe, training = portable.load(files["model"], return_training=True)
    assert type(pipe) is TorquePipeline
    features = pipe[0]
    # the friction inputs are chosen in fit (the default "auto"); the file holds the chosen
    # widths, a run of the grid's
    assert features.velocity_filter == 0.1 and isinstance(features.friction_velocity, tuple)
    first = WIDTH_GRID.index(features.friction_velocity[0])
    assert features.friction_velocity == WIDTH_GRID[first : first + len(features.friction_velocity)]
    assert features.sampling_period == pytest.approx(0.05, rel=1e-12)
    assert training["sampling_period"] == features.sampling_period
    assert training["longest_recording"] == 300
    assert list(features.feature_names_in_) == INPUTS
    assert pipe[-1].n_states == 2


def test_predict_with_the_pipeline_file_equals_the_loaded_pipeline(files, capsys):
    output = files["folder"] / "predicted.parquet"
    argv = ["predict", str(files["model"]), str(files["parquet"]), "--target", TARGET]
    assert main([*argv, "--output", str(output)]) == 0
    result = pd.read_parquet(output)
    data = files["data"]
    pipe = portable.load(files["model"])
    expected, std = pipe.predict(data[INPUTS], groups=data["recording"], return_std=True)
    np.testing.assert_array_equal(result["estimate"], expected)
    np.testing.assert_array_equal(result["estimate_std"], std)
    assert np.allclose(result[["state_0", "state_1"]].sum(axis=1), 1.0)


def test_predict_reports_accuracy_and_smoothness_of_every_recording(files, capsys):
    predicted, table = files["folder"] / "p.csv", files["folder"] / "metrics.csv"
    argv = ["predict", str(files["model"]), str(files["csv"]), "--target", TARGET]
    assert main([*argv, "--output", str(predicted), "--metrics", str(table)]) == 0
    out = capsys.readouterr().out
    result = pd.read_csv(predicted)
    expected = evaluate_recordings(
        result[TARGET], result["estimate"], groups=result["recording"], time=result["time"]
    )
    got = pd.read_csv(table)
    assert list(got.columns) == ["recording", "n_samples", "rmse", "accuracy", "smoothness"]
    assert got["recording"].tolist() == ["r0", "r1", "r2"]
    pd.testing.assert_frame_equal(got, expected, check_exact=False, rtol=1e-12)
    for row in expected.round(3).itertuples():
        assert f"{row.accuracy:.3f}" in out and f"{row.smoothness:.3f}" in out
    assert f"accuracy {expected['accuracy'].mean():.3f}" in out


def test_without_a_time_column_the_smoothness_uses_the_models_sampling_period(files, capsys):
    data = files["data"].drop(columns="time")
    path = files["folder"] / "untimed.csv"
    data.to_csv(path, index=False)
    table = files["folder"] / "untimed_metrics.csv"
    argv = ["predict", str(files["model"]), str(path), "--target", TARGET, "--time", "none"]
    assert main(["--quiet", *argv, "--metrics", str(table)]) == 0
    result = pd.read_csv(files["folder"] / "untimed_predicted.csv")
    period = portable.load(files["model"])[0].sampling_period
    expected = evaluate_recordings(
        result[TARGET], result["estimate"], groups=result["recording"], sampling_period=period
    )
    got = pd.read_csv(table)
    pd.testing.assert_frame_equal(got, expected, check_exact=False, rtol=1e-12)


def test_fit_and_predict_of_the_regressor_keep_working(files, capsys):
    model = files["folder"] / "regressor.json"
    argv = [*FIT, "--output", str(model)]
    argv.insert(1, str(files["csv"]))
    assert main(["--quiet", *argv]) == 0
    assert type(portable.load(model)) is HMMGMRRegressor
    assert portable.load(model).longest_recording_ == 300
    # data without the target column: predictions, no metrics
    path = files["folder"] / "no_target.csv"
    files["data"].drop(columns=TARGET).to_csv(path, index=False)
    capsys.readouterr()
    assert main(["predict", str(model), str(path), "--target", TARGET]) == 0
    out = capsys.readouterr().out
    assert "accuracy" not in out and "Wrote" in out
    assert "estimate" in pd.read_csv(files["folder"] / "no_target_predicted.csv")


@pytest.mark.parametrize(
    "options, message",
    [
        (["--velocity-filter", "0.1"], "--velocity-filter: for --pipeline torque only"),
        (["--output-smoothing", "2"], "--output-smoothing: for --pipeline torque only"),
        (
            ["--pipeline", "torque", "--output-smoothing", "-1"],
            "'output_smoothing' parameter of HMMGMRRegressor must be",
        ),
        (
            ["--pipeline", "torque", "--velocity-filter", "0.1", "--time", "none"],
            "--velocity-filter needs the sampling period",
        ),
        (["--pipeline", "torque", "--load-columns", "speed"], "needs the column(s) ['speed']"),
        (
            ["--pipeline", "torque", "--velocity-filter", "0.1", "--sampling-period", "0.01"],
            "steps 0.05 s (median) in recording 'r0', but sampling_period=0.01",
        ),
    ],
)
def test_fit_refuses_torque_options_it_cannot_use(files, tmp_path, capsys, options, message):
    argv = [*FIT, *options, "--output", str(tmp_path / "m.json")]
    argv.insert(1, str(files["csv"]))
    try:
        code = main(argv)
    except SystemExit as refused:  # an option refused when parsed
        code = refused.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "m.json").exists()


def test_predict_refuses_recordings_at_another_rate_than_the_filters(files, tmp_path, capsys):
    path = tmp_path / "fast.csv"
    recordings(sampling_rate=40.0, seeds=(5,)).to_csv(path, index=False)
    assert main(["predict", str(files["model"]), str(path)]) == 2
    assert "steps 0.025 s (median) in recording 'r5'" in capsys.readouterr().err


def test_metrics_need_the_target_column(files, tmp_path, capsys):
    path = tmp_path / "no_target.csv"
    files["data"].drop(columns=TARGET).to_csv(path, index=False)
    argv = ["predict", str(files["model"]), str(path), "--metrics", str(tmp_path / "m.csv")]
    assert main(argv) == 2
    assert "has no target column 'driver_torque'" in capsys.readouterr().err
    assert not (tmp_path / "no_target_predicted.csv").exists()


@pytest.mark.parametrize("given, expected", [(None, "auto"), ("2.5", 2.5), ("none", None)])
def test_fit_takes_the_read_out_of_the_torque_pipeline(files, capsys, given, expected):
    model = files["folder"] / f"smoothed-{given}.json"
    argv = [*FIT, "--pipeline", "torque", "--output", str(model)]
    argv.insert(1, str(files["csv"]))
    if given is not None:
        argv += ["--output-smoothing", given]
    capsys.readouterr()
    assert main(argv) == 0
    pipe = portable.load(model)
    regressor = pipe[-1]
    assert regressor.output_smoothing == expected
    if expected == 2.5:
        assert regressor.output_smoothing_ == pytest.approx(2.5, rel=1e-12)
    elif expected is None:
        assert regressor.output_smoothing_ == 0.0
    out = capsys.readouterr().out
    assert f"read-out time constant {regressor.output_smoothing_:g} rows" in out


def test_fit_reads_the_plays_and_the_friction_from_renamed_columns(files, capsys):
    """A user's recordings name the wheel's angle and velocity their own way: --angle-column
    and --friction-column say which columns the plays and the friction read."""
    renames = {"steering_wheel_angle": "swa", "steering_wheel_velocity": "swv"}
    data = files["data"].rename(columns=renames)
    path = files["folder"] / "renamed.parquet"  # exact floats (pandas 2.0's CSV parser is not)
    data.to_parquet(path)
    model = files["folder"] / "renamed.json"
    inputs = [renames.get(name, name) for name in INPUTS]
    argv = ["fit", str(path), "--target", TARGET, "--n-states", "2", "--features", *inputs]
    argv += ["--pipeline", "torque", "--friction-angle", "0.01", "--angle-column", "swa"]
    argv += ["--friction-column", "swv", "--load-columns", "swa", "lateral_acceleration"]
    argv += ["--output", str(model)]
    assert main(["--quiet", *argv]) == 0
    pipe = portable.load(model)
    features = pipe[0]
    assert (features.angle_column, features.friction_column) == ("swa", "swv")
    names = list(features.get_feature_names_out())
    assert any(name.startswith("steering_friction") for name in names)
    assert "steering_hysteresis_0.01" in names
    original = files["data"]
    by_api = make_torque_pipeline(
        2, friction_angle=0.01, sampling_period=features.sampling_period, random_state=0
    ).fit(original[INPUTS], original[TARGET], groups=original["recording"])
    np.testing.assert_allclose(
        pipe.predict(data[inputs], groups=data["recording"]),
        by_api.predict(original[INPUTS], groups=original["recording"]),
        rtol=0,
        atol=1e-12,
    )
    argv[argv.index("--angle-column") + 1] = "wheel"
    argv[-1] = str(files["folder"] / "refused.json")
    assert main(["--quiet", *argv]) == 2
    assert "['wheel'] (friction_column / angle_column" in capsys.readouterr().err
