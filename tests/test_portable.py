"""Portable model file: round trip, the plain-NumPy reference filter, malformed files."""

import copy
import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import skhmmgmr
from skhmmgmr import FittedHMMGMR, HMMGMRRegressor, portable

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "plot_portable_filter.py"


def file_dict(model, folder, **options):
    """The dict of the model file ``portable.save`` writes for ``model``."""
    path = Path(folder) / "saved.json"
    portable.save(model, path, **options)
    return json.loads(path.read_text())


def load_dict(data, folder):
    """``portable.load`` of a file holding the dict ``data`` (as written by any writer)."""
    path = Path(folder) / "edited.json"
    path.write_text(json.dumps(data))
    return portable.load(path)


def load_reference_filter():
    """``portable_filter`` from the gallery example (its demonstration is not run)."""
    spec = importlib.util.spec_from_file_location("plot_portable_filter", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.portable_filter


def make_data(n_outputs=1, seed=0):
    rng = np.random.default_rng(seed)
    X = np.cumsum(rng.normal(scale=0.25, size=(450, 3)), axis=0) + [30.0, 0.0, -5.0]
    torque = 2.0 * np.tanh(X[:, 1]) - 0.5 * X[:, 2] + 0.1 * np.sin(X[:, 0])
    y = torque + rng.normal(scale=0.05, size=450)
    if n_outputs == 2:
        y = np.column_stack([y, torque**2])
    frame = pd.DataFrame(X, columns=["speed", "steering_wheel_angle", "yaw_rate"])
    return frame, y, np.repeat(["a", "b", "c"], 150)


@pytest.fixture(scope="module")
def data():
    return make_data()


@pytest.fixture(scope="module")
def model(data):
    X, y, groups = data
    return HMMGMRRegressor(n_states=5, random_state=0).fit(X, y, groups=groups)


@pytest.fixture
def exported(model, tmp_path):
    path = tmp_path / "model.json"
    portable.save(model, path, output_names=["steering_torque"])
    return path


def test_round_trip_predicts_identically(data, model, exported, tmp_path):
    X, _, groups = data
    restored = portable.load(exported)
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    got, got_std = restored.predict(X, groups=groups, return_std=True)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got_std, expected_std)
    assert restored.get_params() == model.get_params()
    np.testing.assert_array_equal(restored.feature_names_in_, model.feature_names_in_)
    for name in [
        "startprob_",
        "transmat_",
        "means_",
        "covars_",
        "log_likelihood_history_",
        "penalized_log_likelihood_history_",
    ]:
        np.testing.assert_array_equal(getattr(restored, name), getattr(model, name))
    assert restored.log_likelihood_ == model.log_likelihood_
    assert restored.penalized_log_likelihood_ == model.penalized_log_likelihood_
    assert restored.n_iter_ == model.n_iter_ and restored.converged_ == model.converged_
    assert file_dict(restored, tmp_path) == json.loads(exported.read_text())


def test_file_is_strict_json_with_documented_keys(model, exported, tmp_path):
    def reject(token):
        raise AssertionError(f"non-finite token {token}")

    data = json.loads(exported.read_text(), parse_constant=reject)
    assert data["format"] == "skhmmgmr-hmm-gmr" and data["format_version"] == 2
    assert data["model_type"] == "HMMGMRRegressor"
    assert data["training"] == {"longest_recording": 150}
    assert data["package_version"] == skhmmgmr.__version__
    assert data["feature_names"] == ["speed", "steering_wheel_angle", "yaw_rate"]
    assert data["output_names"] == ["steering_torque"]
    assert (data["n_states"], data["n_inputs"], data["n_outputs"]) == (5, 3, 1)
    chol = np.array(data["filter"]["input_precision_cholesky"])
    np.testing.assert_array_equal(chol, np.triu(chol))
    assert file_dict(model, tmp_path)["output_names"] == ["output_0"]


@pytest.mark.parametrize("n_outputs", [1, 2])
def test_reference_filter_matches_predict(tmp_path, n_outputs):
    X, y, groups = make_data(n_outputs=n_outputs, seed=n_outputs)
    model = HMMGMRRegressor(n_states=4, random_state=0).fit(X, y, groups=groups)
    path = tmp_path / "model.json"
    portable.save(model, path)
    portable_filter = load_reference_filter()
    for recording in ["a", "c"]:
        rows = X[groups == recording]
        expected, expected_std = model.predict(rows, return_std=True)
        got, got_std = portable_filter(path, rows.to_numpy())
        np.testing.assert_allclose(got.reshape(expected.shape), expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got_std.reshape(expected.shape), expected_std, atol=1e-12)


def test_unnamed_multi_output_round_trip(tmp_path):
    X, y, groups = make_data(n_outputs=2)
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(X.to_numpy(), y, groups=groups)
    restored = load_dict(file_dict(model, tmp_path), tmp_path)
    assert not hasattr(restored, "feature_names_in_")
    assert file_dict(restored, tmp_path)["feature_names"] == ["x0", "x1", "x2"]
    np.testing.assert_array_equal(restored.predict(X.to_numpy()), model.predict(X.to_numpy()))
    assert restored.predict(X.to_numpy()).shape == (450, 2)


def test_output_names_must_match_outputs(model, tmp_path):
    with pytest.raises(ValueError, match="2 names for 1 output"):
        portable.save(model, tmp_path / "model.json", output_names=["a", "b"])
    assert not (tmp_path / "model.json").exists()


def test_unfitted_model_cannot_export(tmp_path):
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        portable.save(HMMGMRRegressor(), tmp_path / "model.json")


def edited(data, key, value):
    """Copy of ``data`` with the dotted ``key`` set to ``value`` (deleted when ``...``);
    ``name[i]`` in ``key`` is item ``i`` of the list ``name``."""
    data = copy.deepcopy(data)
    *parents, last = key.replace("[", ".").replace("]", "").split(".")
    target = data
    for parent in parents:
        target = target[int(parent)] if isinstance(target, list) else target[parent]
    if value is ...:
        del target[last]
    else:
        target[last] = value
    return data


@pytest.mark.parametrize(
    "key",
    [
        "format_version",
        "n_states",
        "feature_names",
        "standardization.output_scale",
        "filter.input_means",
        "filter.transition_matrix",
        "joint.covariances",
        "estimator_params",
    ],
)
def test_missing_key_is_named(model, key, tmp_path):
    with pytest.raises(ValueError, match=f"lacks the key '{key}'"):
        load_dict(edited(file_dict(model, tmp_path), key, ...), tmp_path)


@pytest.mark.parametrize(
    "key, value, message",
    [
        ("filter.input_means", [[0.0, 1.0]] * 5, r"'filter.input_means' has shape \(5, 2\)"),
        ("filter.transition_matrix", [[1.0]], "'filter.transition_matrix' has shape"),
        ("joint.means", [[1e300, "a"]] * 5, r"'joint.means\[0\]\[1\]' must be a number, got 'a'"),
        ("filter.regression_intercepts", [["a"]] * 5, "'filter.regression_intercepts[0][0]' m"),
        ("filter.start_probabilities", [0.5, 0.6, 0, 0, -0.1], "start_probabilities' must"),
        ("standardization.input_scale", [1.0, 0.0, 1.0], "input_scale' must be positive"),
        ("format_version", 4, "'format_version' is 4: the file was written by a newer"),
        ("format_version", 0, "'format_version' is 0; format versions are whole numbers"),
        ("model_type", "TorquePipeline", "the model file lacks the key 'steps'"),
        ("training", {"longest_recording": 0}, "'training.longest_recording' must be at le"),
        ("format", "onnx", "'format' is 'onnx'"),
        ("n_inputs", 0, "'n_inputs' must be a positive integer, got 0"),
        ("feature_names", ["a", "b"], "'feature_names' must be a list of 3"),
        ("feature_names", "abc", "'feature_names' must be a list of distinct names, got 'abc'"),
        ("target_ndim", 3, "'target_ndim' is 3"),
        ("estimator_params", {"n_stats": 2}, "'estimator_params' holds an unknown"),
        # #35: values fit refuses were loaded (and NaN inputs marginalised)
        (
            "estimator_params",
            {"missing_values": "bogus"},
            "'estimator_params' holds a value fit refuses: The 'missing_values' parameter",
        ),
        ("estimator_params", {"missing_values": ["a"]}, "'missing_values' parameter"),
        ("estimator_params", {"missing_values": {"a": 1}}, "'estimator_params.missing_values'"),
        ("estimator_params", {"reg_covar": -1.0}, "'reg_covar' parameter"),
        ("feature_names", ["a", "b", "a"], r"'feature_names' holds \['a'\] more than once"),
        ("fit_info", {"log_likelihood_history": [1.0, [2.0, 3.0]]}, "'fit_info.log_likel"),
    ],
)
def test_malformed_content_is_named(model, key, value, message, tmp_path):
    with pytest.raises(ValueError, match=message if "\\" in message else re.escape(message)):
        load_dict(edited(file_dict(model, tmp_path), key, value), tmp_path)


def test_edited_filter_parameters_are_refused(model, tmp_path):
    data = file_dict(model, tmp_path)
    data["filter"]["regression_coefficients"][2][0][1] += 0.01
    with pytest.raises(ValueError, match="'filter.regression_coefficients' does not match"):
        load_dict(data, tmp_path)


@pytest.mark.parametrize(
    "text, message",
    [
        ("[1, 2, 3]", "must be a JSON object, got list"),
        ('{"format": ', "is not a valid JSON file"),
        ('{"format": NaN}', "NaN is not valid JSON"),
        ('{"format": "skhmmgmr-hmm-gmr", "format_version": 1}', "lacks the key 'n_states'"),
    ],
)
def test_bad_files(tmp_path, text, message):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        portable.load(path)


@pytest.mark.parametrize(
    "content, message",
    [
        ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
        ('{"n_states": ' + "9" * 5000 + "}", "is not a valid model file"),
        ("\ufeff{}".encode("utf-16"), r"is not a JSON text file \(UTF-8\)"),
        (bytes(range(256)), r"is not a JSON text file \(UTF-8\)"),
    ],
)
def test_files_python_cannot_read_name_the_file(tmp_path, content, message):
    """#35: RecursionError, ValueError, UnicodeDecodeError named neither file nor key."""
    path = tmp_path / "odd.json"
    if isinstance(content, str):
        path.write_text(content)
    else:
        path.write_bytes(content)
    with pytest.raises(ValueError, match=re.escape(str(path)) + ".*" + message):
        portable.load(path)


@pytest.fixture(scope="module")
def carrying(data):
    X, y, groups = data
    X = X.copy()
    X.iloc[::7, 0] = np.nan
    params = {"n_states": 2, "random_state": 0, "missing_values": "carry_forward"}
    return HMMGMRRegressor(**params).fit(X, y, groups=groups)


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda s: s["lags"].__setitem__(3, 8.9), r"'stale_inputs.lags\[3\]' must be a whole"),
        (lambda s: s["lags"].__setitem__(3, True), r"'stale_inputs.lags\[3\]' must be a whole"),
        (lambda s: s["lags"].__setitem__(3, 10**30), r"'stale_inputs.lags' must lie in \[1, "),
        (lambda s: s["variances"][0].__setitem__(0, 1e-320), "must be at least 1e-12"),
        (lambda s: s["variances"][0].__setitem__(0, -1.0), "must be at least 1e-12"),
        (lambda s: s["variances"].__setitem__(0, [1.0]), "'stale_inputs.variances' must hold"),
        (lambda s: s.pop("lags"), "lacks the key 'stale_inputs.lags'"),
    ],
)
def test_stale_inputs_of_a_model_file_are_checked(carrying, change, message, tmp_path):
    """#35: a lag of 8.9 loaded as 8; variances of 1e-320 passed and gave NaN estimates."""
    data = file_dict(carrying, tmp_path)
    change(data["stale_inputs"])
    with pytest.raises(ValueError, match=message):
        load_dict(data, tmp_path)


def test_restored_model_streams(data, exported):
    X, _, groups = data
    restored = portable.load(exported)
    rows = X[groups == "b"]
    got = restored.filter_stream().update_batch(rows)
    np.testing.assert_allclose(got, restored.predict(rows), rtol=0, atol=1e-12)


# -- covariances that would give NaN standard deviations --------------------------------------


def consistent_file(model, covariances, path):
    """A model file whose joint covariances are ``covariances`` (data units) and whose filter
    block is derived from them, as a writer that does not check them would produce."""
    from skhmmgmr._hmm._emissions import make_emissions
    from skhmmgmr._hmm._portable import export_json, to_dict

    fitted = model.model_
    emissions = make_emissions("full", fitted.data_emissions.means, covariances)
    edited = FittedHMMGMR(
        fitted.startprob, fitted.transmat, emissions, fitted.standardization, scalar_output=True
    )
    export_json(to_dict(edited, estimator_params=model.get_params()), path)
    return path


def test_asymmetric_joint_covariance_is_refused(data, model, tmp_path):
    # Only the lower triangle is factorised, but the regression reads the upper one of the
    # input block: this file used to load and give a NaN std on every row.
    covariances = model.covars_.copy()
    covariances[1, 0, 1] = 0.0
    path = consistent_file(model, covariances, tmp_path / "edited.json")
    with pytest.raises(
        ValueError,
        match=r"edited\.json: 'joint\.covariances\[1\]' \(state 1\) is not symmetric: entry "
        r"\[0, 1\] is 0\.0",
    ):
        portable.load(path)


def test_indefinite_joint_covariance_is_refused(model, tmp_path):
    data = file_dict(model, tmp_path)
    covariance = np.array(data["joint"]["covariances"][2])
    covariance[1, 3] = covariance[3, 1] = 2 * np.sqrt(covariance[1, 1] * covariance[3, 3])
    data["joint"]["covariances"][2] = covariance.tolist()
    with pytest.raises(ValueError, match=r"'joint.covariances\[2\]' \(state 2\) is not positive"):
        load_dict(data, tmp_path)
    data["joint"]["covariances"][2][3][3] = -1.0
    with pytest.raises(ValueError, match=r"\(state 2\) has the non-positive variance -1.0"):
        load_dict(data, tmp_path)


def test_conditional_covariance_singular_to_round_off_is_refused(model, tmp_path):
    # A rank-2 joint covariance plus 1e-16 I factorises, but the variance of the output given
    # the inputs comes out zero or negative in floating point for some draws.
    rng = np.random.default_rng(0)
    covariances = model.covars_.copy()
    for _ in range(1000):
        B = rng.normal(size=(4, 3))
        covariances[3] = B @ B.T + 1e-16 * np.eye(4)
        try:
            path = consistent_file(model, covariances, tmp_path / "singular.json")
        except ValueError:  # not factorised
            continue
        data = json.loads(path.read_text())
        if data["filter"]["conditional_covariances"][3][0][0] <= 0:
            break
    else:
        pytest.skip("no draw is singular to round-off with this LAPACK")
    with pytest.raises(
        ValueError, match=r"'filter.conditional_covariances\[3\]' \(state 3\).* not positive"
    ):
        portable.load(path)
