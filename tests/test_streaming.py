"""FilterStream: sample-by-sample parity with predict, state handling, held samples."""

import copy
import dataclasses
import math

import numpy as np
import pandas as pd
import pytest

import skhmmgmr
from skhmmgmr import FilterStream, HMMGMRRegressor

NAMES = ["steering_wheel_angle", "yaw_rate", "heading_deviation_10m"]


def make_recordings(n_recordings=3, length=200, n_outputs=1, seed=0):
    """Random-walk inputs and a torque that is a nonlinear function of them."""
    rng = np.random.default_rng(seed)
    X = np.cumsum(rng.normal(scale=0.25, size=(n_recordings * length, 3)), axis=0)
    torque = 2.0 * np.tanh(X[:, 0]) - 0.5 * X[:, 1] + 0.3 * np.sin(X[:, 2])
    y = torque + rng.normal(scale=0.05, size=len(torque))
    if n_outputs == 2:
        y = np.column_stack([y, np.abs(torque) + rng.normal(scale=0.05, size=len(torque))])
    groups = np.repeat([f"rec{r}" for r in range(n_recordings)], length)
    return X, y, groups


@pytest.fixture(scope="module")
def data():
    return make_recordings()


@pytest.fixture(scope="module")
def model(data):
    X, y, groups = data
    return HMMGMRRegressor(n_states=4, random_state=0).fit(X, y, groups=groups)


def stream_recordings(stream, X, groups):
    """Estimates, stds, state probabilities and flags of every row, streamed recording by
    recording after a reset."""
    results = []
    for rec in pd.unique(groups):
        stream.reset()
        for row in X[groups == rec]:
            estimate, std, flag = stream.update(row, return_std=True, return_flag=True)
            results.append((estimate, std, stream.state_proba_, flag))
    return tuple(np.array(column) for column in zip(*results, strict=True))


def test_stream_matches_predict_across_recordings(data, model):
    X, _, groups = data
    stream = model.filter_stream()
    estimates, stds, alphas, _ = stream_recordings(stream, X, groups)
    predicted, predicted_std = model.predict(X, groups=groups, return_std=True)
    np.testing.assert_allclose(estimates, predicted, rtol=0, atol=1e-12)
    np.testing.assert_allclose(stds, predicted_std, rtol=0, atol=1e-12)
    np.testing.assert_allclose(alphas, model.predict_state_proba(X, groups=groups), atol=1e-12)
    assert type(stream.update(X[0])) is float
    assert stream.last_flag_ == "ok" and not stream.held_
    assert stream.n_samples_ == np.sum(groups == groups[-1]) + 1


def test_reset_restarts_the_filter(data, model):
    X, _, _ = data
    stream = model.filter_stream()
    first = [stream.update(row) for row in X[:50]]
    stream.reset()
    np.testing.assert_array_equal(stream.state_proba_, model.startprob_)
    again = [stream.update(row) for row in X[:50]]
    np.testing.assert_array_equal(first, again)


def test_update_batch_mixed_with_update(data, model):
    X, _, groups = data
    rows = X[groups == "rec1"]
    stream = model.filter_stream()
    parts = [stream.update_batch(rows[:7]), [stream.update(rows[7])]]
    parts.append(stream.update_batch(rows[8:120]))
    parts.append([stream.update(row) for row in rows[120:130]])
    parts.append(stream.update_batch(rows[130:]))
    np.testing.assert_allclose(np.concatenate(parts), model.predict(rows), rtol=0, atol=1e-12)
    stream.reset()
    estimates, std, flags = stream.update_batch(rows, return_std=True, return_flag=True)
    _, predicted_std = model.predict(rows, return_std=True)
    np.testing.assert_allclose(std, predicted_std, rtol=0, atol=1e-12)
    assert estimates.shape == std.shape == flags.shape == (len(rows),)
    assert set(flags) == {"ok"}


def test_multi_output_returns_arrays():
    X, y, groups = make_recordings(n_outputs=2, length=150)
    model = HMMGMRRegressor(n_states=3, random_state=0).fit(X, y, groups=groups)
    rows = X[groups == "rec2"]
    stream = model.filter_stream()
    estimate, std = stream.update(rows[0], return_std=True)
    assert estimate.shape == std.shape == (2,)
    rest = stream.update_batch(rows[1:])
    assert rest.shape == (len(rows) - 1, 2)
    predicted = model.predict(rows)
    np.testing.assert_allclose(np.vstack([estimate, rest]), predicted, rtol=0, atol=1e-12)


def test_features_by_name():
    X, y, groups = make_recordings(length=120)
    frame = pd.DataFrame(X, columns=NAMES)
    model = HMMGMRRegressor(n_states=3, random_state=0).fit(frame, y, groups=groups)
    stream = model.filter_stream()
    expected = model.predict(frame.iloc[:20])
    got = [stream.update(dict(zip(NAMES[::-1], row[::-1], strict=True))) for row in X[:10]]
    got += [stream.update(frame.iloc[i]) for i in range(10, 15)]
    got += list(stream.update_batch(frame.iloc[15:20][NAMES[::-1]]))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(stream.feature_names_in_, NAMES)
    with pytest.raises(ValueError, match="yaw_rate"):
        stream.update({"steering_wheel_angle": 0.0, "heading_deviation_10m": 0.0})


def test_bad_input_shapes(model):
    stream = model.filter_stream()
    with pytest.raises(ValueError, match="use update_batch"):
        stream.update(np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        stream.update([0.0, 1.0])
    with pytest.raises(ValueError, match="without feature names"):
        stream.update({"x0": 0.0, "x1": 0.0, "x2": 0.0})
    with pytest.raises(ValueError, match="n_samples, 3"):
        stream.update_batch(np.zeros(3))
    assert stream.n_samples_ == 0


def test_unfitted_model_raises():
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        HMMGMRRegressor().filter_stream()


@pytest.mark.parametrize(
    "bad, flag, min_log_density",
    [
        ([np.nan, 0.0, 0.0], "non-finite", None),
        ([0.0, np.inf, 0.0], "non-finite", None),
        ([0.0, 0.0, -np.inf], "non-finite", None),
        ([1e4, -1e4, 1e4], "outlier", -1e3),  # far from every state, with the hold setting
        ([1e200, 1e200, -1e200], "outlier", None),  # out of the model's range
    ],
)
def test_held_sample_does_not_poison_the_filter(data, model, bad, flag, min_log_density):
    X, _, groups = data
    rows = X[groups == "rec0"]
    clean = model.filter_stream()
    expected = [clean.update(row) for row in rows[:60]]
    stream = model.filter_stream(min_log_density=min_log_density)
    got = [stream.update(row) for row in rows[:30]]
    alpha_before = stream.state_proba_
    held, held_std, got_flag = stream.update(np.array(bad), return_std=True, return_flag=True)
    assert got_flag == flag == stream.last_flag_ and stream.held_
    assert held == got[-1]
    _, std_before = clean.update_batch(rows[:30], return_std=True)
    assert held_std == pytest.approx(std_before[-1], abs=1e-12)
    np.testing.assert_array_equal(stream.state_proba_, alpha_before)
    got += [stream.update(row) for row in rows[30:60]]
    np.testing.assert_array_equal(got, expected)
    assert stream.last_flag_ == "ok" and not stream.held_


def test_held_first_sample_gives_prior_mixture(model):
    stream = model.filter_stream()
    estimate, std = stream.update([np.nan, 1.0, 2.0], return_std=True)
    means, variances = model.means_[:, -1], model.covars_[:, -1, -1]
    expected = model.startprob_ @ means
    assert estimate == pytest.approx(expected, abs=1e-12)
    assert std == pytest.approx(
        math.sqrt(model.startprob_ @ (variances + (means - expected) ** 2)), abs=1e-12
    )
    batch, flags = stream.reset().update_batch(
        np.array([[np.nan, 0, 0], [1e300, 0, 0]]), return_flag=True
    )
    assert np.all(np.isfinite(batch)) and list(flags) == ["non-finite", "outlier"]


def test_no_nan_comes_out_of_a_hostile_stream(data, model):
    X, _, _ = data
    rng = np.random.default_rng(3)
    rows = X[:300].copy()
    rows[rng.choice(300, 40, replace=False), rng.integers(0, 3, 40)] = np.nan
    rows[rng.choice(300, 20, replace=False)] *= 1e6
    rows[rng.choice(300, 5, replace=False), 0] = np.inf
    estimates, std = model.filter_stream().update_batch(rows, return_std=True)
    assert np.all(np.isfinite(estimates)) and np.all(np.isfinite(std))


def test_restart_when_transitions_rule_out_every_state(data, model):
    """A zero product ``prior * density`` restarts the filter, exactly as predict does."""
    X, _, _ = data
    rigid = HMMGMRRegressor.from_fitted_model(
        dataclasses.replace(model.model_, transmat=np.eye(4), startprob=np.eye(4)[0])
    )
    rows = X[:100].copy()
    # Far from state 0 (its relative density underflows) but close enough to state 2.
    rows[50] = 4.0 * rigid.means_[2, :3] - 3.0 * rigid.means_[0, :3]
    stream = rigid.filter_stream()
    estimates, flags = stream.update_batch(rows, return_flag=True)
    assert list(flags[49:52]) == ["ok", "restarted", "ok"]
    # With A = I the filter can leave state 0 only by restarting.
    assert stream.state_proba_[0] < 0.5
    np.testing.assert_allclose(estimates, rigid.predict(rows), rtol=0, atol=1e-12)


def test_stream_is_decoupled_from_later_refits(data, model):
    X, y, groups = data
    refit = copy.deepcopy(model)
    stream = refit.filter_stream()
    refit.fit(X[:300], -y[:300])
    np.testing.assert_allclose(
        stream.update_batch(X[:20]), model.predict(X[:20]), rtol=0, atol=1e-12
    )


def test_state_proba_is_a_copy(model, data):
    stream = model.filter_stream()
    stream.update(data[0][0])
    alpha = stream.state_proba_
    alpha[:] = 0.0
    assert stream.state_proba_.sum() == pytest.approx(1.0)


def test_public_export(model):
    assert "FilterStream" in skhmmgmr.__all__
    assert isinstance(model.filter_stream(), FilterStream)


def _outlying(X, rng, n=12):
    """``X`` with far samples: 50 to 1e4 times the data's spread, alone and in runs."""
    X = np.array(X, dtype=float)
    rows = rng.choice(np.arange(X.shape[0]), size=n, replace=False)
    X[rows] *= rng.choice([50.0, 1e3, 1e4], size=(n, 1))
    X[[0, 1]] *= 1e3  # at the start of a recording: before any accepted sample
    return X


def test_far_samples_are_filtered_as_predict_filters_them(data, model):
    """#51: the stream held every sample whose densities all underflowed (log-density below
    log(DBL_MIN)), where predict filtered it: the forward step is in log space now."""
    X, _, groups = data
    X = _outlying(X, np.random.default_rng(0))
    assert (model.input_log_density(X, groups=groups) < math.log(np.finfo(float).tiny)).any()
    estimates, stds, alphas, flags = stream_recordings(model.filter_stream(), X, groups)
    expected, expected_std = model.predict(X, groups=groups, return_std=True)
    assert set(flags) <= {"ok", "restarted"}
    # far samples extrapolate a state's regression to large estimates: round-off relative
    np.testing.assert_allclose(estimates, expected, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(stds, expected_std, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(alphas, model.predict_state_proba(X, groups=groups), atol=1e-12)


@pytest.mark.parametrize("n_outputs, smoothing", [(1, None), (1, 4.0), (2, 4.0)])
def test_predict_holds_the_samples_the_stream_holds(n_outputs, smoothing):
    """With min_log_density set, predict, predict_state_proba and predict_ahead(0) hold the
    rows below it as the stream does: the state, the read-out and the estimate of the last
    accepted row (the prior mixture before any)."""
    X, y, groups = make_recordings(n_outputs=n_outputs, length=150)
    model = HMMGMRRegressor(n_states=3, output_smoothing=smoothing, random_state=0)
    model.fit(X, y, groups=groups)
    X = _outlying(X, np.random.default_rng(1))
    threshold = -40.0
    expected_held = model.input_log_density(X, groups=groups) < threshold
    assert 5 <= expected_held.sum() < 40
    model.set_params(min_log_density=threshold)  # read at prediction time: no refit
    estimates, stds, alphas, flags = stream_recordings(model.filter_stream(), X, groups)
    np.testing.assert_array_equal(flags == "outlier", expected_held)
    predicted, predicted_std = model.predict(X, groups=groups, return_std=True)
    np.testing.assert_allclose(predicted, estimates, rtol=0, atol=1e-12)
    np.testing.assert_allclose(predicted_std, stds, rtol=0, atol=1e-12)
    np.testing.assert_allclose(model.predict_state_proba(X, groups=groups), alphas, atol=1e-12)
    ahead = model.predict_ahead(X, 0, groups=groups, return_std=True)
    np.testing.assert_allclose(ahead[0], predicted, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ahead[1], predicted_std, rtol=0, atol=1e-12)
    # a forecast from a held row is that of the last accepted row of its recording
    forecast = model.predict_ahead(X, 5, groups=groups)
    rows = np.flatnonzero(expected_held[1:] & (groups[1:] == groups[:-1])) + 1
    rows = rows[~expected_held[rows - 1]]
    np.testing.assert_array_equal(forecast[rows], forecast[rows - 1])
    # the first rows of a recording are held: the prior mixture
    prior = model.filter_stream().update(np.full(3, np.nan), return_std=True)
    np.testing.assert_allclose(predicted[0], prior[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(predicted_std[0], prior[1], rtol=0, atol=1e-12)
    assert model.set_params(min_log_density=None).predict(X[:1]).shape == predicted[:1].shape


def test_the_hold_setting_is_the_estimators_and_refused_when_not_a_number(model):
    """#51: min_log_density=nan was taken, and then every sample was held."""
    assert model.filter_stream().min_log_density is None
    assert FilterStream(model.model_).min_log_density is None
    assert model.filter_stream(min_log_density=-3).min_log_density == -3.0
    holding = HMMGMRRegressor.from_fitted_model(model.model_, min_log_density=-7.5)
    assert holding.filter_stream().min_log_density == -7.5
    for bad in (np.nan, np.inf, -np.inf, "low", True):
        with pytest.raises(ValueError, match="'min_log_density' parameter of FilterStream"):
            FilterStream(model, min_log_density=bad)
        with pytest.raises(ValueError, match="'min_log_density' parameter of HMMGMRRegressor"):
            HMMGMRRegressor(min_log_density=bad).fit(*make_recordings(length=40)[:2])


def test_the_model_file_keeps_the_hold_setting(data, model, tmp_path):
    from skhmmgmr import portable

    X, _, groups = data
    holding = HMMGMRRegressor.from_fitted_model(model.model_, min_log_density=-30.0)
    portable.save(holding, tmp_path / "holding.json")
    restored = portable.load(tmp_path / "holding.json")
    assert restored.min_log_density == -30.0
    far = _outlying(X, np.random.default_rng(2))
    np.testing.assert_array_equal(
        restored.predict(far, groups=groups), holding.predict(far, groups=groups)
    )
    portable.save(model, tmp_path / "plain.json")
    assert portable.load(tmp_path / "plain.json").min_log_density is None


def test_predict_refuses_inputs_out_of_the_models_range(model):
    X = np.zeros((4, 3))
    X[2, 1] = 1e200
    with pytest.raises(ValueError, match=r"out of the model's range in recording 0 \(row 2.*'x1'"):
        model.predict(X)
    stream = model.filter_stream()
    assert list(stream.update_batch(X, return_flag=True)[1]) == ["ok", "ok", "outlier", "ok"]


@pytest.mark.parametrize(
    "row, message",
    [
        (np.array(["1", "2", "3"]), "features must hold real numbers.*<U1"),
        (np.array([1.0, 2.0, 3j]), "features must hold real numbers.*complex128"),
        (np.array([1.0, "a", 2.0], dtype=object), "features must hold real numbers.*object"),
        ({"a": [1.0, 2.0], "b": 0.0, "c": 0.0}, r"features\['a'\] is \[1.0, 2.0\], not a number"),
        ({"a": "1.5", "b": 0.0, "c": 0.0}, r"features\['a'\] is '1.5', not a number"),
        (pd.Series([1.0, 2.0, 3.0, 4.0], index=["a", "b", "c", "a"]), r"label\(s\) \['a'\] more"),
    ],
)
def test_rows_that_are_not_real_numbers_are_refused_naming_the_input(row, message):
    X, y, groups = make_recordings(length=60)
    frame = pd.DataFrame(X, columns=["a", "b", "c"])
    stream = HMMGMRRegressor(n_states=2, n_iter=5, random_state=0).fit(frame, y).filter_stream()
    with pytest.raises(ValueError, match=message):
        stream.update(row)
    assert stream.n_samples_ == 0
    with pytest.raises(ValueError, match="X's column 'b' holds"):
        stream.update_batch(frame.assign(b="x"))
    with pytest.raises(ValueError, match="X must hold real numbers"):
        stream.update_batch(X.astype(complex))
    # numbers in an object array, and numpy scalars by name, are numbers
    assert (
        stream.update(np.array([0.1, 2, np.float32(3)], dtype=object), return_flag=True)[1] == "ok"
    )
    assert stream.update({"a": np.float64(0.1), "b": np.int64(2), "c": 3.0}) is not None
