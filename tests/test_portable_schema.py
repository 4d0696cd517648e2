"""The model file's rules are its JSON Schema's: the loader checks every file against the shipped
schema (``skhmmgmr/_core/_json_schema.py``, no ``jsonschema`` at run time) and refuses what the
schema refuses, naming the key; what the schema cannot say (sizes across keys) comes before the
repeated names, which are found in linear time."""

import copy
import json
import re

import numpy as np
import pandas as pd
import pytest
from test_portable import edited, file_dict

from skhmmgmr import HMMGMRRegressor, make_torque_pipeline, portable
from skhmmgmr._core._json_schema import KEYWORDS, check_document, is_valid

jsonschema = pytest.importorskip("jsonschema")


@pytest.fixture(scope="module")
def validator():
    return jsonschema.Draft202012Validator(portable.json_schema())


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(3)
    X = pd.DataFrame(
        np.cumsum(rng.normal(size=(300, 3)), axis=0) / 10,
        columns=["steering_wheel_angle", "steering_wheel_velocity", "lateral_acceleration"],
    )
    y = pd.Series(2 * X["steering_wheel_angle"] - X["lateral_acceleration"], name="driver_torque")
    y += rng.normal(scale=0.05, size=len(y))
    return X, y, np.repeat(["a", "b"], 150)


@pytest.fixture(scope="module")
def plain(data):
    X, y, groups = data
    return HMMGMRRegressor(n_states=2, random_state=0).fit(X, y, groups=groups)


@pytest.fixture(scope="module")
def smoothed_pipeline(data):
    X, y, groups = data
    pipe = make_torque_pipeline(2, output_smoothing=4.0, random_state=0)
    return pipe.fit(X, y, groups=groups)


def _schema_keywords(node):
    if isinstance(node, list):
        return set().union(*map(_schema_keywords, node)) if node else set()
    if not isinstance(node, dict):
        return set()
    found = set()
    for key, value in node.items():
        if key in ("properties", "$defs"):
            found |= {key} | set().union(*map(_schema_keywords, value.values()))
        elif key not in ("const", "enum", "default", "examples"):
            found |= {key} | _schema_keywords(value)
    return found


def test_the_reader_knows_every_keyword_of_the_shipped_schema():
    schema = portable.json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    assert _schema_keywords(schema) <= KEYWORDS, _schema_keywords(schema) - KEYWORDS


def _load(data, tmp_path, text=None):
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(data) if text is None else text)
    return portable.load(path)


def _with_inner(pipeline_dict, key, value):
    """The pipeline's file with ``key`` of its regressor's block set to ``value``."""
    return edited(pipeline_dict, f"steps[{len(pipeline_dict['steps']) - 1}].model.{key}", value)


def _cases(plain_dict, pipeline_dict):
    """Files the schema refuses: (name, file, the message the loader gives)."""
    assert pipeline_dict["steps"][-1]["model"]["output_decay"]
    version_2 = {**plain_dict, "output_decay": [0.5]}
    inner_2 = _with_inner(pipeline_dict, "format_version", 2)
    inner_1 = copy.deepcopy(inner_2)
    block = inner_1["steps"][-1]["model"]
    block["format_version"] = 1
    del block["model_type"], block["training"]
    return [
        ("version 2 with output_decay", version_2, "the file holds the unknown key(s) ['output"),
        (
            "a pipeline's block marked 2 with output_decay",
            inner_2,
            "'steps[1].model' holds the unknown key(s) ['output_decay']",
        ),
        (
            "a pipeline's block marked 1 with output_decay",
            inner_1,
            "'steps[1].model' holds the unknown key(s) ['output_decay']",
        ),
        (
            "an unknown top-level key",
            {**plain_dict, "comment": "edited"},
            "the file holds the unknown key(s) ['comment']",
        ),
        (
            "an unknown top-level key of a pipeline",
            {**pipeline_dict, "comment": "edited"},
            "the file holds the unknown key(s) ['comment']",
        ),
        (
            "a non-numeric fit_info value",
            edited(plain_dict, "fit_info.log_likelihood", "high"),
            "'fit_info.log_likelihood' must be a number or null, got 'high'",
        ),
        (
            "a non-numeric history entry",
            edited(plain_dict, "fit_info.penalized_log_likelihood_history", [1.0, True]),
            "'fit_info.penalized_log_likelihood_history[1]' must be a number, got True",
        ),
        (
            "an unknown fit_info key",
            edited(plain_dict, "fit_info.seconds", 2.0),
            "'fit_info' holds the unknown key(s) ['seconds']",
        ),
    ]


def test_the_loader_refuses_what_the_schema_refuses_naming_the_key(
    plain, smoothed_pipeline, validator, tmp_path
):
    """#51 item 5: these files loaded (a block of version 2 or 1 dropped its read-out, and
    predicted 0.86 Nm apart)."""
    plain_dict = file_dict(plain, tmp_path)
    pipeline_dict = file_dict(smoothed_pipeline, tmp_path)
    assert pipeline_dict["format_version"] == 3
    assert not list(validator.iter_errors(plain_dict))
    assert not list(validator.iter_errors(pipeline_dict))
    for name, data, message in _cases(plain_dict, pipeline_dict):
        assert list(validator.iter_errors(data)), name
        with pytest.raises(ValueError, match=re.escape(message)):
            _load(data, tmp_path)


@pytest.mark.parametrize(
    "key", ["fit_info.log_likelihood", "estimator_params.tol", "training.sampling_period"]
)
def test_a_number_beyond_a_float_is_refused_naming_the_key(plain, tmp_path, key):
    """#51 item 5: ``1e400`` in fit_info loaded as inf, and the model could not be saved
    again. JSON has no infinite number: the loader refuses it where the schema asks a
    number, and in the estimator's parameters."""
    text = json.dumps(edited(file_dict(plain, tmp_path), key, 12345.678)).replace(
        "12345.678", "1e400"
    )
    with pytest.raises(ValueError, match=re.escape(f"'{key}' is inf, not a finite number")):
        _load(None, tmp_path, text=text)


def test_sixty_thousand_names_are_refused_by_their_sizes(plain, tmp_path):
    """#51 item 2: the repeated names were sought in quadratic time before any size check (a
    0.6 MB file of 60,000 names took 23 s to refuse). The sizes come first now, and the
    repeated names are found in one pass."""
    data = file_dict(plain, tmp_path)
    names = [f"feature_{i:05d}" for i in range(60_000)]
    huge = {**data, "n_inputs": len(names), "feature_names": names[:-1] + [names[0]]}
    path = tmp_path / "huge.json"
    path.write_text(json.dumps(huge))
    assert 0.5e6 < path.stat().st_size < 2e6
    with pytest.raises(
        ValueError, match=r"'standardization.input_center' has shape \(3,\), expected \(60000,\)"
    ):
        portable.load(path)
    # names that fit the sizes: the repeated one is named
    repeated = {**data, "feature_names": ["steering_wheel_angle"] * 3}
    with pytest.raises(
        ValueError, match=r"'feature_names' holds \['steering_wheel_angle'\] more than once"
    ):
        _load(repeated, tmp_path)


def test_the_reader_is_schema_driven():
    """A rule is the schema's: the same checker applies any schema's rules, naming the key."""
    schema = {
        "type": "object",
        "required": ["a"],
        "properties": {
            "a": {"$ref": "#/$defs/count"},
            "b": {"type": "array", "items": {"type": "string"}, "uniqueItems": True},
        },
        "unevaluatedProperties": False,
        "$defs": {"count": {"title": "a positive integer", "type": "integer", "minimum": 1}},
    }
    check_document({"a": 2, "b": ["x", "y"]}, schema)
    for document, message in [
        ({}, "lacks the key 'a'"),
        ({"a": 0}, "'a' must be a positive integer, got 0"),
        ({"a": True}, "'a' must be a positive integer, got True"),
        ({"a": 1, "b": ["x", 1]}, "'b[1]' must be text, got 1"),
        ({"a": 1, "b": ["x", "x"]}, "'b' holds ['x'] more than once"),
        ({"a": 1, "c": 1}, "the file holds the unknown key(s) ['c']"),
        ({"a": float("nan")}, "'a' must be a positive integer, got nan"),
    ]:
        with pytest.raises(ValueError, match=re.escape(message)):
            check_document(document, schema)
        assert not is_valid(document, schema)
    # the uniqueness of items can be left for last
    postponed = []
    check_document({"a": 1, "b": ["x", "x"]}, schema, postponed=postponed)
    with pytest.raises(ValueError, match=re.escape("'b' holds ['x'] more than once")):
        postponed[0]()


def test_save_refuses_repeated_output_names_with_the_loaders_rule(data, tmp_path):
    """#51 item 8: the file was written, and ``load`` refused it."""
    X, y, groups = data
    two = HMMGMRRegressor(n_states=2, random_state=0)
    two.fit(X, np.column_stack([y, -y]), groups=groups)
    path = tmp_path / "model.json"
    with pytest.raises(
        ValueError,
        match=re.escape("cannot save the model: 'output_names' holds ['torque'] more than once"),
    ):
        portable.save(two, path, output_names=["torque", "torque"])
    assert not path.exists()
    portable.save(two, path, output_names=["torque", "minus_torque"])
    assert list(portable.load(path).output_names_) == ["torque", "minus_torque"]
