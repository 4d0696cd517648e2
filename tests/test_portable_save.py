"""One portable file for any fitted model: ``portable.save`` / ``portable.load`` of the
regressor and of the torque pipeline, the JSON Schema, files of older and newer versions, and
bad files refused naming what is wrong."""

import json
import re
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from sklearn.exceptions import NotFittedError
from sklearn.linear_model import LinearRegression
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from test_portable import edited, file_dict

from skhmmgmr import HMMGMRRegressor, SteeringFeatures, make_torque_pipeline, portable
from skhmmgmr.datasets import make_lane_keeping, to_panel
from skhmmgmr.torque_pipeline import TorquePipeline

jsonschema = pytest.importorskip("jsonschema")

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = Path(__file__).resolve().parent / "fixtures"
CASES = ("full", "tied", "marginalize", "carry_forward")
LEGACY = [FIXTURES / f"legacy_0_1_0_{case}.json" for case in CASES]
INPUTS = ["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration", "yaw_rate"]
PERIOD = 0.05


@pytest.fixture(scope="module")
def data():
    """Three recordings of 20 s at 20 Hz, as a tidy frame."""
    frames = [
        make_lane_keeping(20.0, sampling_rate=1 / PERIOD, random_state=seed, recording=f"r{seed}")
        for seed in range(3)
    ]
    return pd.concat(frames, ignore_index=True)


@pytest.fixture(scope="module")
def validator():
    schema = portable.json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def schema_errors(validator, path):
    return [error.message for error in validator.iter_errors(json.loads(Path(path).read_text()))]


def fitted_pipeline(data, kind, velocity_filter):
    """A fitted pipeline: ``kind`` "torque" (make_torque_pipeline, recordings as groups) or
    "plain" (a scikit-learn Pipeline, recordings in the index of a panel)."""
    period = PERIOD if velocity_filter else None
    if kind == "torque":
        pipe = make_torque_pipeline(
            2, velocity_filter=velocity_filter, sampling_period=period, random_state=0
        )
        return pipe.fit(data[INPUTS], data["driver_torque"], groups=data["recording"])
    pipe = Pipeline(
        [
            ("derived", SteeringFeatures(velocity_filter=velocity_filter, sampling_period=period)),
            ("model", HMMGMRRegressor(n_states=2, random_state=0)),
        ]
    )
    panel = to_panel(data)
    return pipe.fit(panel[INPUTS], panel["driver_torque"])


@pytest.mark.parametrize("kind", ["torque", "plain"])
@pytest.mark.parametrize("velocity_filter", [None, 0.1])
def test_a_pipeline_round_trip_predicts_bit_for_bit(
    data, tmp_path, validator, kind, velocity_filter
):
    pipe = fitted_pipeline(data, kind, velocity_filter)
    path = tmp_path / "pipe.json"
    portable.save(pipe, path, output_names=["driver_torque"])
    assert schema_errors(validator, path) == []
    restored, training = portable.load(path, return_training=True)
    assert type(restored) is type(pipe)
    assert [name for name, _ in restored.steps] == [name for name, _ in pipe.steps]
    assert restored.get_params(deep=True).keys() == pipe.get_params(deep=True).keys()
    # the file holds the values fit chose in place of "auto"
    chosen = {
        f"{pipe.steps[0][0]}__{name}": getattr(pipe[0], f"{name}_")
        for name in (
            "friction_velocity",
            "velocity_filter",
            "friction_angle",
            "angle_lead",
            "slow_velocity_filter",
        )
    }
    for key, value in pipe.get_params(deep=True).items():
        if key not in ("steps",) and not hasattr(value, "get_params"):
            assert restored.get_params(deep=True)[key] == chosen.get(key, value), key
    # with the recordings in a panel's index (both kinds), and as groups (the torque pipeline)
    panel = to_panel(data)[INPUTS]
    np.testing.assert_array_equal(restored.predict(panel), pipe.predict(panel))
    if kind == "torque":
        groups = data["recording"]
        expected, expected_std = pipe.predict(data[INPUTS], groups=groups, return_std=True)
        got, got_std = restored.predict(data[INPUTS], groups=groups, return_std=True)
        np.testing.assert_array_equal(got, expected)
        np.testing.assert_array_equal(got_std, expected_std)
    # the training facts: the longest recording, and the period of a velocity filter
    assert restored[-1].longest_recording_ == pipe[-1].longest_recording_ == 400
    expected_training = {"longest_recording": 400}
    if velocity_filter:
        expected_training["sampling_period"] = PERIOD
    assert training == expected_training
    np.testing.assert_array_equal(restored[0].feature_names_in_, INPUTS)
    assert restored[0].n_features_in_ == len(INPUTS)


def test_the_velocity_filter_restarts_at_every_recording_after_loading(data, tmp_path):
    """The loaded pipeline routes the recordings to its filter: without them the estimates of
    the later recordings change (the filter runs across recordings), with them they equal the
    original's."""
    pipe = fitted_pipeline(data, "torque", 0.5)
    path = tmp_path / "pipe.json"
    portable.save(pipe, path)
    restored = portable.load(path)
    groups = data["recording"]
    routed = restored.predict(data[INPUTS], groups=groups)
    np.testing.assert_array_equal(routed, pipe.predict(data[INPUTS], groups=groups))
    with pytest.warns(UserWarning, match="filtered as ONE recording"):
        unrouted = restored.predict(data[INPUTS])
    assert not np.array_equal(routed, unrouted)


def test_a_regressor_round_trip_and_its_deprecated_shortcuts_write_the_same_file(
    data, tmp_path, validator
):
    model = HMMGMRRegressor(n_states=3, random_state=0)
    model.fit(data[INPUTS], data["driver_torque"], groups=data["recording"])
    saved, exported = tmp_path / "saved.json", tmp_path / "exported.json"
    portable.save(model, saved)
    with pytest.warns(FutureWarning, match=r"export_json is deprecated .*portable\.save\("):
        model.export_json(exported)
    assert saved.read_bytes() == exported.read_bytes()
    assert schema_errors(validator, saved) == []
    with pytest.warns(FutureWarning, match=r"from_json is deprecated .*portable\.load\("):
        from_json = HMMGMRRegressor.from_json(saved)
    for restored in (portable.load(saved), from_json):
        assert type(restored) is HMMGMRRegressor
        assert restored.longest_recording_ == 400
        expected = model.predict(data[INPUTS], groups=data["recording"], return_std=True)
        got = restored.predict(data[INPUTS], groups=data["recording"], return_std=True)
        np.testing.assert_array_equal(got[0], expected[0])
        np.testing.assert_array_equal(got[1], expected[1])


def test_units_and_sampling_period_travel_in_the_training_block(data, tmp_path, validator):
    pipe = fitted_pipeline(data, "torque", None)
    path = tmp_path / "pipe.json"
    units = {"steering_wheel_angle": "rad", "driver_torque": "N m"}
    portable.save(pipe, path, output_names=["driver_torque"], units=units, sampling_period=0.05)
    assert schema_errors(validator, path) == []
    _, training = portable.load(path, return_training=True)
    assert training == {"longest_recording": 400, "sampling_period": 0.05, "units": units}
    with pytest.raises(ValueError, match=r"'training.units' names \['speed'\], neither inputs"):
        portable.save(pipe, tmp_path / "bad.json", units={"speed": "m/s"})


@pytest.mark.parametrize(
    "options",
    [dict(covariance_type="tied"), dict(missing_values="carry_forward")],
    ids=["tied", "carry_forward"],
)
def test_every_form_of_the_regressor_validates_against_the_schema(
    data, tmp_path, validator, options
):
    model = HMMGMRRegressor(n_states=2, random_state=0, **options)
    model.fit(data[INPUTS].to_numpy(), data["driver_torque"].to_numpy(), groups=data["recording"])
    path = tmp_path / "model.json"
    portable.save(model, path)
    assert schema_errors(validator, path) == []
    got = portable.load(path).predict(data[INPUTS].to_numpy(), groups=data["recording"])
    np.testing.assert_array_equal(
        got, model.predict(data[INPUTS].to_numpy(), groups=data["recording"])
    )


@pytest.mark.parametrize("path", LEGACY, ids=lambda p: p.stem)
def test_0_1_0_files_validate_and_load(path, validator):
    assert schema_errors(validator, path) == []
    loaded, training = portable.load(path, return_training=True)
    assert type(loaded) is HMMGMRRegressor and training == {}
    assert loaded.longest_recording_ is None
    assert not hasattr(loaded, "output_names_")  # 0.1.0 named outputs output_0...
    assert np.isfinite(loaded.predict(np.zeros((5, loaded.n_features_in_)))).all()


def test_the_schema_ships_with_the_package():
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"
    ]
    assert "portable_schema.json" in package_data["skhmmgmr"]
    text = (ROOT / "skhmmgmr" / "portable_schema.json").read_text()
    assert json.loads(text) == portable.json_schema()
    assert portable.json_schema()["$schema"] == "https://json-schema.org/draft/2020-12/schema"


@pytest.fixture(scope="module")
def pipeline_dict(data, tmp_path_factory):
    path = tmp_path_factory.mktemp("pipe") / "pipe.json"
    portable.save(fitted_pipeline(data, "torque", 0.1), path)
    return json.loads(path.read_text())


@pytest.mark.parametrize(
    "key, value, message",
    [
        ("model_type", ..., "lacks the key 'model_type'"),
        ("model_type", "RandomForest", "'model_type' is 'RandomForest'; this version of skhm"),
        ("format_version", 4, "'format_version' is 4: the file was written by a newer skhmm"),
        ("format_version", "2", "'format_version' is '2'; format versions are whole numbers"),
        ("format", "onnx", "'format' is 'onnx'"),
        ("steps", [], "'steps' must be a non-empty list"),
        ("steps", ..., "lacks the key 'steps'"),
        ("steps[0].type", "StandardScaler", "'steps[0].type' is 'StandardScaler', expected one"),
        ("steps[1].type", "SteeringFeatures", "'steps' must hold exactly 1 item that is a reg"),
        ("steps[0].type", "HMMGMRRegressor", "'steps' must hold exactly 1 item that is a regre"),
        ("steps[0].params.powers", ..., "lacks the key 'steps[0].params.powers'"),
        ("steps[0].params.gain", 2.0, "'steps[0].params' holds the unknown key(s) ['gain']"),
        ("steps[0].params.friction_velocity", -1.0, "friction_velocity' must be greater than 0"),
        ("steps[0].params.velocity_filter", "fast", "velocity_filter' must be a number or null"),
        ("steps[0].params.sampling_period", None, "velocity_filter=0.1 needs sampling_period"),
        ("steps[0].params.powers", [2, 2], "'steps[0].params.powers' holds [2] more than once"),
        ("steps[0].params.load_columns", ["speed"], "needs the column(s) ['speed']"),
        ("steps[0].params.powers", [2], "'steps[1]' takes"),  # 2 inputs more than given
        ("steps[0].feature_names_in", ["a"], "'steps[0].feature_names_in' must be a list of 4"),
        ("steps[0].n_features_in", 0, "'steps[0].n_features_in' must be a positive integer"),
        ("steps[0].name", "a__b", "'steps[0].name' must be a step name"),
        ("steps[1].name", "steering_features", "names two steps"),
        ("steps[1].model.filter.input_means", ..., "lacks the key 'steps[1].model.filter.input_m"),
        ("steps[1].model.model_type", "Pipeline", "'steps[1].model.model_type' is 'Pipeline', ex"),
        ("training.units", {"speed": "m/s"}, "'training.units' names ['speed']"),
        ("training.when", "today", "'training' holds the unknown key(s) ['when']"),
    ],
)
def test_bad_pipeline_files_are_refused_naming_the_problem(
    pipeline_dict, tmp_path, key, value, message
):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(edited(pipeline_dict, key, value)))
    with pytest.raises(ValueError, match=re.escape(f"{path}: ") + ".*" + re.escape(message)):
        portable.load(path)


def test_the_regressors_shortcut_refuses_a_pipeline_file(pipeline_dict, tmp_path):
    path = tmp_path / "pipe.json"
    path.write_text(json.dumps(pipeline_dict))
    with (
        pytest.warns(FutureWarning, match="from_json is deprecated"),
        pytest.raises(ValueError, match="a file of a pipeline is read by skhmmgmr.portable.lo"),
    ):
        HMMGMRRegressor.from_json(path)


def test_an_unknown_step_type_fails_the_schema_too(pipeline_dict, validator):
    assert list(validator.iter_errors(pipeline_dict)) == []
    assert list(validator.iter_errors(edited(pipeline_dict, "steps[0].type", "StandardScaler")))
    assert list(validator.iter_errors(edited(pipeline_dict, "format_version", 4)))


def test_an_older_version_loads_and_a_newer_one_is_refused(data, tmp_path):
    model = HMMGMRRegressor(n_states=2, random_state=0)
    model.fit(data[INPUTS], data["driver_torque"], groups=data["recording"])
    current = file_dict(model, tmp_path)
    assert current["format_version"] == 2 and portable.FORMAT_VERSION == 3
    # version 1: the same keys without model_type and training
    older = {k: v for k, v in current.items() if k not in ("model_type", "training")}
    path = tmp_path / "v1.json"
    path.write_text(json.dumps({**older, "format_version": 1}))
    loaded, training = portable.load(path, return_training=True)
    assert training == {} and loaded.longest_recording_ is None
    groups = data["recording"]
    np.testing.assert_array_equal(
        loaded.predict(data[INPUTS], groups=groups), model.predict(data[INPUTS], groups=groups)
    )
    path.write_text(json.dumps({**current, "format_version": 4}))
    with pytest.raises(ValueError, match="written by a newer skhmmgmr; this version reads forma"):
        portable.load(path)


def test_save_refuses_what_a_model_file_does_not_hold(data, tmp_path):
    path = tmp_path / "model.json"
    X, y = data[INPUTS], data["driver_torque"]
    with pytest.raises(NotFittedError):
        portable.save(HMMGMRRegressor(), path)
    with pytest.raises(NotFittedError):
        portable.save(make_torque_pipeline(2), path)
    with pytest.raises(TypeError, match="got sklearn.linear_model._base.LinearRegression"):
        portable.save(LinearRegression().fit(X, y), path)
    scaled = Pipeline([("scale", StandardScaler()), ("model", HMMGMRRegressor(2, random_state=0))])
    scaled.fit(X, y)
    with pytest.raises(TypeError, match="step 'scale' is sklearn.preprocessing.*StandardScaler"):
        portable.save(scaled, path)
    skipped = Pipeline([("none", "passthrough"), ("model", HMMGMRRegressor(2, random_state=0))])
    with pytest.raises(TypeError, match="step 'none' is 'passthrough'; a model file's pipeline"):
        portable.save(skipped.fit(X, y), path)
    last = Pipeline([("derived", SteeringFeatures()), ("model", LinearRegression())]).fit(X, y)
    with pytest.raises(TypeError, match="last step 'model' is sklearn.linear_model"):
        portable.save(last, path)

    class MyRegressor(HMMGMRRegressor):
        pass

    with pytest.raises(TypeError, match="MyRegressor"):
        portable.save(MyRegressor(2, random_state=0).fit(X, y), path)
    assert not path.exists()
    assert TorquePipeline is portable.MODEL_TYPES["TorquePipeline"]


def test_the_hierarchical_regressor_and_its_pipeline_round_trip(data, tmp_path, validator):
    """The subclass is saved as itself (its own ``model_type``), valid under the schema, and
    loads back as itself: the same estimates, manoeuvre probabilities and structure."""
    from skhmmgmr import HierarchicalHMMGMRRegressor

    labels = np.where(data["lateral_acceleration"] > 0, "left", "right")
    groups = data["recording"]
    model = HierarchicalHMMGMRRegressor(["left", "right"], n_states=[2, 1], random_state=0)
    model.fit(data[INPUTS], data["driver_torque"], groups=groups, manoeuvre=labels)
    path = tmp_path / "hierarchy.json"
    portable.save(model, path)
    assert schema_errors(validator, path) == []
    assert json.loads(path.read_text())["model_type"] == "HierarchicalHMMGMRRegressor"
    restored = portable.load(path)
    assert type(restored) is HierarchicalHMMGMRRegressor
    X = data[INPUTS]
    np.testing.assert_array_equal(
        restored.predict(X, groups=groups), model.predict(X, groups=groups)
    )
    np.testing.assert_array_equal(
        restored.predict_manoeuvre_proba(X, groups=groups),
        model.predict_manoeuvre_proba(X, groups=groups),
    )
    assert list(restored.manoeuvres_) == ["left", "right"]
    np.testing.assert_array_equal(restored.states_per_manoeuvre_, [2, 1])
    # the flat regressor does not read it as one of its own
    with (
        pytest.warns(FutureWarning, match="from_json is deprecated"),
        pytest.raises(ValueError, match="holds a HierarchicalHMMGMRRegressor"),
    ):
        HMMGMRRegressor.from_json(path)

    pipe = Pipeline(
        [
            ("derived", SteeringFeatures()),
            ("model", HierarchicalHMMGMRRegressor(["left", "right"], n_states=1, random_state=0)),
        ]
    )
    pipe.fit(X, data["driver_torque"], model__groups=groups, model__manoeuvre=labels)
    path = tmp_path / "pipe.json"
    portable.save(pipe, path)
    assert schema_errors(validator, path) == []
    restored = portable.load(path)
    assert type(restored[-1]) is HierarchicalHMMGMRRegressor
    np.testing.assert_array_equal(
        restored.predict(X, groups=groups), pipe.predict(X, groups=groups)
    )
    derived = pipe[0].transform(X)
    np.testing.assert_array_equal(
        restored[-1].predict_manoeuvre_proba(derived, groups=groups),
        pipe[-1].predict_manoeuvre_proba(derived, groups=groups),
    )


def test_the_older_shortcuts_are_deprecated_aliases_that_still_work(data, tmp_path):
    """One documented way to save and load (``portable.save``/``load``); the shortcuts of
    before stay one release and say what to call instead."""
    model = HMMGMRRegressor(n_states=2, random_state=0)
    model.fit(data[INPUTS], data["driver_torque"], groups=data["recording"])
    path = tmp_path / "model.json"
    portable.save(model, path)
    expected = json.loads(path.read_text())
    X, groups = data[INPUTS], data["recording"]

    def deprecated(name, instead):
        return pytest.warns(
            FutureWarning,
            match=rf"{re.escape(name)} is deprecated since skhmmgmr 0\.2 and "
            rf"will be removed in 0\.3; .*{re.escape(instead)}",
        )

    with deprecated("HMMGMRRegressor.to_dict", "portable.save(model, path)"):
        assert model.to_dict() == expected
    with deprecated("HMMGMRRegressor.from_dict", "portable.load(path)"):
        restored = HMMGMRRegressor.from_dict(expected)
    np.testing.assert_array_equal(
        restored.predict(X, groups=groups), model.predict(X, groups=groups)
    )
    with deprecated("skhmmgmr.portable.load_json", "skhmmgmr.portable.load"):
        assert portable.load_json(path) == expected
    with deprecated("skhmmgmr.portable.read_model", "skhmmgmr.portable.load"):
        read = portable.read_model(expected)
    assert read.estimator_params == model.get_params()
    np.testing.assert_array_equal(read.model.transmat, model.transmat_)
    with deprecated("skhmmgmr.portable.to_dict", "HMMGMRRegressor.from_fitted_model"):
        as_dict = portable.to_dict(model.model_, estimator_params=model.get_params())
    with deprecated("skhmmgmr.portable.export_json", "skhmmgmr.portable.save"):
        portable.export_json(as_dict, tmp_path / "low_level.json")
    assert portable.load(tmp_path / "low_level.json").get_params() == model.get_params()
