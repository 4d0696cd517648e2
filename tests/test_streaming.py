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
    estimates, stds, alphas = [], [], []
    for rec in pd.unique(groups):
        stream.reset()
        for row in X[groups == rec]:
            estimate, std = stream.update(row, return_std=True)
            estimates.append(estimate)
            stds.append(std)
            alphas.append(stream.state_proba_)
    return np.array(estimates), np.array(stds), np.array(alphas)


def test_stream_matches_predict_across_recordings(data, model):
    X, _, groups = data
    stream = model.filter_stream()
    estimates, stds, alphas = stream_recordings(stream, X, groups)
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
    "bad, flag",
    [
        ([np.nan, 0.0, 0.0], "non-finite"),
        ([0.0, np.inf, 0.0], "non-finite"),
        ([0.0, 0.0, -np.inf], "non-finite"),
        ([1e4, -1e4, 1e4], "outlier"),
        ([1e200, 1e200, -1e200], "outlier"),
    ],
)
def test_held_sample_does_not_poison_the_filter(data, model, bad, flag):
    X, _, groups = data
    rows = X[groups == "rec0"]
    clean = model.filter_stream()
    expected = [clean.update(row) for row in rows[:60]]
    stream = model.filter_stream()
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
