"""Online MAP adaptation of the state means in FilterStream (``relevance=``, ``target=``)."""

import pickle

import numpy as np
import pytest
from test_portable import file_dict, load_dict

from skhmmgmr import FilterStream, HMMGMRRegressor


def _data(n_samples, seed, offset=0.0, n_outputs=1):
    rng = np.random.default_rng(seed)
    X = np.cumsum(rng.normal(scale=0.25, size=(n_samples, 3)), axis=0)
    y = 2.0 * np.tanh(X[:, 0]) - 0.5 * X[:, 1] + offset + rng.normal(scale=0.05, size=n_samples)
    if n_outputs == 2:
        y = np.column_stack([y, 0.5 * y + rng.normal(scale=0.05, size=n_samples)])
    return X, y


@pytest.fixture(scope="module")
def model():
    X, y = _data(600, 0)
    return HMMGMRRegressor(n_states=3, random_state=0).fit(X, y)


def _stream(stream, X, y=None, return_std=False):
    out = [
        stream.update(row, return_std=return_std, target=None if y is None else y[i])
        for i, row in enumerate(X)
    ]
    return np.array(out)


def test_without_targets_an_adapting_stream_is_the_plain_stream_exactly(model):
    X, _ = _data(150, 1)
    plain = _stream(model.filter_stream(), X, return_std=True)
    adapting = _stream(model.filter_stream(relevance=8.0, forgetting=0.99), X, return_std=True)
    assert np.array_equal(adapting, plain)
    batch = model.filter_stream(relevance=8.0).update_batch(X, return_std=True)
    assert np.array_equal(np.column_stack(batch), plain)
    assert np.array_equal(plain[:, 0], model.filter_stream(relevance=None).update_batch(X))


def test_forgetting_what_was_learned_gives_the_plain_stream_back_exactly(model):
    X, y = _data(150, 2, offset=1.0)
    stream = model.filter_stream(relevance=8.0)
    stream.update_batch(X, y=y)
    assert stream.adapted_model() is not model.model_
    stream.reset_adaptation().reset()
    assert stream.adapted_model() is model.model_
    assert stream.update(X[0], return_std=True) == model.filter_stream().update(
        X[0], return_std=True
    )
    assert np.array_equal(stream.update_batch(X[1:]), model.filter_stream().update_batch(X)[1:])


def test_recursive_statistics_equal_a_plain_loop(model):
    """mu_k = (sum_t lambda^(T-t) alpha_tk x_t + r mu0_k) / (sum_t lambda^(T-t) alpha_tk + r)
    with the stream's own filtered probabilities, in standardised units."""
    X, y = _data(300, 3, offset=0.7)
    relevance, forgetting = 20.0, 0.98
    stream = model.filter_stream(relevance=relevance, forgetting=forgetting)
    alphas = []
    for row, target in zip(X, y, strict=True):
        stream.update(row, target=target)
        alphas.append(stream.state_proba_)
    scaling = model.model_.standardization
    joint = scaling.joint(X, y[:, np.newaxis])
    prior = model.model_.emissions.means
    counts, sums = np.zeros(len(prior)), np.zeros_like(prior)
    for alpha, row in zip(alphas, joint, strict=True):
        counts = forgetting * counts + alpha
        sums = forgetting * sums + np.outer(alpha, row)
    expected = (sums + relevance * prior) / (counts + relevance)[:, np.newaxis]
    adapted = stream.adapted_model()
    np.testing.assert_allclose(adapted.emissions.means, expected, rtol=0, atol=1e-10)
    np.testing.assert_allclose(
        adapted.emissions.covariances, model.model_.emissions.covariances, rtol=0, atol=1e-10
    )
    np.testing.assert_array_equal(adapted.transmat, model.model_.transmat)


@pytest.mark.parametrize("missing", [False, True])
def test_the_adapted_stream_reads_out_the_adapted_model(model, missing):
    """Only the weights' constant row follows the means: the stream after learning predicts as
    a fresh stream of its adapted model (missing inputs: the conditioned read-out too)."""
    X, y = _data(300, 4, offset=-0.8)
    options = {"missing_values": "marginalize"} if missing else {}
    stream = model.filter_stream(relevance=10.0, **options)
    stream.update_batch(X[:200], y=y[:200])
    test = X[200:].copy()
    if missing:
        test[::7, 1] = np.nan
        test[::11] = np.nan
    stream.reset()
    fresh = FilterStream(stream.adapted_model(), **options)
    np.testing.assert_allclose(
        _stream(stream, test, return_std=True),
        _stream(fresh, test, return_std=True),
        rtol=0,
        atol=1e-10,
    )
    assert fresh.update(np.full(3, np.inf)) == pytest.approx(stream.update(np.full(3, np.inf)))


def _adapt_both(model, offset):
    """Online (one pass, filtered input posteriors) and batch MAP ("m", smoothed joint
    posteriors) adaptation to the training inputs with the torque shifted by ``offset``."""
    X, y = _data(600, 0, offset=offset)
    stream = model.filter_stream(relevance=16.0)
    counts = np.zeros(model.n_states)
    for row, target in zip(X, y, strict=True):
        stream.update(row, target=target)
        counts += stream.state_proba_
    batch = pickle.loads(pickle.dumps(model)).adapt(X, y, relevance=16.0, parameters="m")
    return stream.adapted_model().emissions.means, batch.model_.emissions.means, counts


def test_online_and_batch_adaptation_answer_a_torque_offset_alike(model):
    """A driver who applies more torque in the same situations. The filtered probabilities
    depend on the inputs only, so the online means answer an offset ``c`` (standardised)
    exactly by ``c n_k / (n_k + r)`` on the output and not at all on the inputs: the MAP rule's
    evidence weighting. Batch EM (whose posteriors also see the torque) answers nearly alike."""
    online_0, batch_0, counts = _adapt_both(model, 0.0)
    online_c, batch_c, _ = _adapt_both(model, 0.1)
    c = 0.1 / model.model_.standardization.output_scale[0]
    online, batch = online_c - online_0, batch_c - batch_0
    np.testing.assert_allclose(online[:, -1], c * counts / (counts + 16.0), rtol=1e-10)
    np.testing.assert_array_equal(online[:, :-1], 0.0)
    assert np.all((batch[:, -1] > 0) & (batch[:, -1] < c))
    np.testing.assert_allclose(batch[:, -1], online[:, -1], rtol=0.1)


def test_a_huge_relevance_keeps_the_fitted_model(model):
    X, y = _data(200, 7, offset=2.0)
    plain = model.filter_stream().update_batch(X)
    adapting = model.filter_stream(relevance=1e12).update_batch(X, y=y)
    np.testing.assert_allclose(adapting, plain, rtol=0, atol=1e-8)


def test_held_samples_and_nan_targets_are_not_learned(model):
    X, y = _data(100, 8, offset=1.0)
    stream = model.filter_stream(relevance=4.0)
    stream.update(X[0], target=np.nan)
    stream.update(np.array([np.inf, 0.0, 0.0]), target=y[0])
    assert stream.adapted_model() is model.model_


def test_adapted_stream_models_round_trip_through_json_and_pickle(model, tmp_path):
    X, y = _data(200, 9, offset=0.5)
    stream = model.filter_stream(relevance=8.0)
    stream.update_batch(X, y=y)
    adapted = HMMGMRRegressor.from_fitted_model(stream.adapted_model())
    restored = load_dict(file_dict(adapted, tmp_path), tmp_path)
    assert np.array_equal(restored.predict(X), adapted.predict(X))
    assert np.array_equal(pickle.loads(pickle.dumps(adapted)).predict(X), adapted.predict(X))
    # A pickled stream carries what it learned.
    copy = pickle.loads(pickle.dumps(stream))
    assert np.array_equal(copy.update_batch(X[:20]), stream.update_batch(X[:20]))


def test_multi_output_streams_adapt():
    X, y = _data(400, 10, n_outputs=2)
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(X, y)
    stream = model.filter_stream(relevance=8.0)
    stream.update_batch(X, y=y + [0.5, -0.5])
    shift = stream.adapted_model().emissions.means[:, -2:] - model.model_.emissions.means[:, -2:]
    assert np.all(shift[:, 0] > 0) and np.all(shift[:, 1] < 0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"relevance": 0.0}, "relevance"),
        ({"relevance": 4.0, "forgetting": 0.0}, "forgetting"),
        ({"relevance": "auto"}, r"no relevance='auto'.*adapt\(\)"),
    ],
)
def test_bad_adaptation_arguments(model, kwargs, match):
    with pytest.raises(ValueError, match=match):
        model.filter_stream(**kwargs)


def test_a_target_needs_an_adapting_stream(model):
    X, y = _data(10, 11)
    stream = model.filter_stream()
    with pytest.raises(ValueError, match="relevance"):
        stream.update(X[0], target=y[0])
    assert stream.n_samples_ == 0  # refused before filtering
    with pytest.raises(ValueError, match="relevance"):
        stream.update_batch(X, y=y)
    with pytest.raises(ValueError, match="rows"):
        model.filter_stream(relevance=4.0).update_batch(X, y=y[:5])


@pytest.mark.parametrize("duplicate", ["pickle", "deepcopy"])
def test_a_copied_adapting_stream_goes_on_adapting_as_the_original(model, duplicate):
    """#35: the copy's updates must reach its own weights (its views linked again)."""
    import copy

    X, y = _data(300, 4, offset=1.5)
    stream = model.filter_stream(relevance=8.0, forgetting=0.995)
    stream.update_batch(X[:100], y=y[:100])
    twin = pickle.loads(pickle.dumps(stream)) if duplicate == "pickle" else copy.deepcopy(stream)
    expected = _stream(stream, X[100:], y[100:], return_std=True)
    got = _stream(twin, X[100:], y[100:], return_std=True)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    # and it did adapt: the plain stream from the same point differs
    plain = pickle.loads(pickle.dumps(stream))
    plain.reset_adaptation()
    assert np.abs(_stream(plain, X[100:], return_std=True) - expected).max() > 0.05
    np.testing.assert_allclose(
        twin.adapted_model().emissions.means, stream.adapted_model().emissions.means, atol=1e-12
    )


@pytest.mark.parametrize(
    "options, parameter",
    [
        ({"relevance": "16"}, "relevance"),
        ({"relevance": True}, "relevance"),
        ({"relevance": -1.0}, "relevance"),
        ({"relevance": 8.0, "forgetting": "0.9"}, "forgetting"),
        ({"relevance": 8.0, "forgetting": True}, "forgetting"),
        ({"relevance": 8.0, "forgetting": 0.0}, "forgetting"),
        ({"relevance": 8.0, "forgetting": 1.5}, "forgetting"),
    ],
)
def test_stream_parameters_are_checked_as_estimator_parameters(model, options, parameter):
    with pytest.raises(ValueError, match=rf"The '{parameter}' parameter of FilterStream must"):
        model.filter_stream(**options)


@pytest.mark.parametrize("target", ["abc", [1.0, 2.0], np.ones((1, 2)), True, None])
def test_a_bad_target_is_refused_before_the_sample_is_consumed(model, target):
    """#35: the row was filtered (n_samples_, state_proba_ changed) before the conversion
    error."""
    X, y = _data(20, 5)
    stream = model.filter_stream(relevance=8.0)
    stream.update_batch(X[:10], y=y[:10])
    before = (stream.n_samples_, stream.state_proba_.copy())
    if target is None:  # a 2-D y for a one-output model
        with pytest.raises(ValueError, match=r"y has shape \(10, 2\)"):
            stream.update_batch(X[10:], y=np.column_stack([y[10:], y[10:]]))
    else:
        with pytest.raises(ValueError, match="target must be the 1 measured output"):
            stream.update(X[10], target=target)
    assert stream.n_samples_ == before[0]
    np.testing.assert_array_equal(stream.state_proba_, before[1])
