"""The fused E-step (``skhmmgmr/_hmm/_fused_estep.py``) computes what the staged E-step computes.

The staged path (densities by BLAS, the recursions of ``_kernels``, moments by
``MomentSums``) is the expectation: it is what the engine runs for rows with missing values,
and it has its own plain-loop tests in ``test_em_engine.py``.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from skhmmgmr._core._sequences import Recordings
from skhmmgmr._hmm import _em, _fused_estep
from skhmmgmr._hmm._em import HMMParameters, baum_welch, e_step, initialize_parameters, score_hmm
from skhmmgmr._hmm._em_data import EStepData
from skhmmgmr._hmm._fused_estep import applies, fused_pass


def _data(n_dims, n_states, covariance_type="full", seed=0):
    rng = np.random.default_rng(seed)
    n_rows = 2400
    drive = np.cumsum(rng.normal(scale=0.05, size=(n_rows, 2)), axis=0)
    X = np.sin(drive) @ rng.normal(size=(2, n_dims)) + 0.3 * rng.normal(size=(n_rows, n_dims))
    bounds = np.array([0, 1, 600, 1300, 1301, 1302, 2000, n_rows])  # rows of one recording too
    recordings = Recordings(ids=np.arange(len(bounds) - 1), starts=bounds[:-1], stops=bounds[1:])
    params = initialize_parameters(
        X,
        recordings,
        n_states,
        "k-means++",
        1e-6,
        np.random.RandomState(seed),
        covariance_type=covariance_type,
    )
    return X, recordings, params


@pytest.fixture(autouse=True)
def two_threads(monkeypatch):
    """The fused path needs more than one of numba's threads: two, whatever the machine."""
    monkeypatch.setattr(_fused_estep, "get_num_threads", lambda: 2)


def _staged(monkeypatch):
    monkeypatch.setattr(_em, "applies", lambda *_: False)


CASES = [(1, 1, "full"), (3, 2, "full"), (3, 5, "full"), (4, 7, "tied"), (9, 12, "full")]


@pytest.mark.parametrize("n_dims, n_states, covariance_type", CASES)
def test_statistics_equal_the_staged_e_step(monkeypatch, n_dims, n_states, covariance_type):
    X, recordings, params = _data(n_dims, n_states, covariance_type)
    engines = [EStepData(X, recordings, n_states, block_size=700) for _ in range(2)]
    assert applies(engines[0], params.emissions.density(engines[0].shift))
    fused = [e_step(engines[0], params) for _ in range(2)]  # the second with a remainder state
    with monkeypatch.context() as patch:
        _staged(patch)
        staged = [e_step(engines[1], params) for _ in range(2)]
    for ours, expected in zip(fused, staged, strict=True):
        assert ours.log_likelihood == pytest.approx(expected.log_likelihood, rel=1e-12)
        assert_allclose(ours.start_counts, expected.start_counts, rtol=1e-10, atol=1e-12)
        assert_allclose(ours.transition_counts, expected.transition_counts, rtol=1e-10, atol=1e-9)
        for name in ("weights", "first", "second"):
            assert_allclose(
                getattr(ours.emission, name),
                getattr(expected.emission, name),
                rtol=1e-10,
                atol=1e-8,
            )


@pytest.mark.parametrize("n_dims, n_states, covariance_type", CASES[1:])
def test_histories_equal_the_staged_engine(monkeypatch, n_dims, n_states, covariance_type):
    X, recordings, start = _data(n_dims, n_states, covariance_type, seed=1)

    def run():
        engine = EStepData(X, recordings, n_states, block_size=700)
        return baum_welch(X, recordings, start, n_iter=6, tol=0.0, reg_covar=1e-6, engine=engine)

    fused = run()
    _staged(monkeypatch)
    staged = run()
    assert_allclose(fused.history, staged.history, rtol=1e-10)
    assert_allclose(fused.parameters.means, staged.parameters.means, rtol=1e-8, atol=1e-10)
    assert score_hmm(X, recordings, fused.parameters) == pytest.approx(fused.history[-1])


def test_fused_result_does_not_depend_on_the_number_of_threads(monkeypatch):
    X, recordings, params = _data(3, 4)
    engine = EStepData(X, recordings, 4, block_size=500)
    density = params.emissions.density(engine.shift)
    results = []
    for n_threads in (1, 2, 3):
        monkeypatch.setattr(_fused_estep, "get_num_threads", lambda n=n_threads: n)
        results.append(fused_pass(engine, params, density, [0, 1, 2]))
    for other in results[1:]:
        assert other[0] == results[0][0]
        for ours, theirs in zip(other[1:], results[0][1:], strict=True):
            assert np.array_equal(ours, theirs)


def test_one_thread_or_one_block_takes_the_staged_path(monkeypatch):
    X, recordings, params = _data(3, 4)
    engine = EStepData(X, recordings, 4, block_size=500)
    density = params.emissions.density(engine.shift)
    assert applies(engine, density)
    assert not applies(EStepData(X, recordings, 4, block_size=10**6), density)  # one block
    monkeypatch.setattr(_fused_estep, "get_num_threads", lambda: 1)
    assert not applies(engine, density)


def test_an_impossible_recording_is_refused():
    # state 0 cannot follow itself into state 1, and row 5 lies where only state 1 has mass
    X = np.zeros((20, 1))
    X[15] = 60.0
    recordings = Recordings(ids=np.arange(2), starts=np.array([0, 10]), stops=np.array([10, 20]))
    params = HMMParameters.gaussian(
        np.array([1.0, 0.0]), np.eye(2), np.array([[0.0], [60.0]]), np.ones((2, 1, 1))
    )
    engine = EStepData(X, recordings, 2, block_size=10)
    assert applies(engine, params.emissions.density(engine.shift))
    with pytest.raises(FloatingPointError, match="impossible"):
        e_step(engine, params)
    with pytest.raises(FloatingPointError, match="impossible"):
        _em._score(engine, params)


def test_rows_with_missing_values_take_the_staged_path():
    X, recordings, params = _data(3, 3)
    X[10, 1] = np.nan
    engine = EStepData(X, recordings, 3)
    assert not applies(engine, params.emissions.density(engine.shift))
