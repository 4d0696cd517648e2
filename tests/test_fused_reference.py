"""The fused reference of ``benchmarks/_fused.py`` computes the engine's log-likelihoods."""

import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from skhmmgmr._core._sequences import Recordings
from skhmmgmr._hmm._em import baum_welch, initialize_parameters

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def fused():
    sys.path.insert(0, str(BENCHMARKS))
    try:
        import _fused
    finally:
        sys.path.remove(str(BENCHMARKS))
    return _fused


@pytest.mark.parametrize("n_dims, n_states", [(3, 2), (3, 6), (5, 10)])
def test_fused_reference_matches_engine(fused, n_dims, n_states):
    rng = np.random.default_rng(n_states)
    n_rows = 3000
    drive = np.cumsum(rng.normal(scale=0.05, size=(n_rows, 2)), axis=0)
    X = np.sin(drive) @ rng.normal(size=(2, n_dims)) + 0.3 * rng.normal(size=(n_rows, n_dims))
    bounds = np.array([0, 700, 1500, 1501, 2200, n_rows])
    recordings = Recordings(ids=np.arange(5), starts=bounds[:-1], stops=bounds[1:])
    start = initialize_parameters(
        X, recordings, n_states, "k-means++", 1e-6, np.random.RandomState(0)
    )
    ours = baum_welch(X, recordings, start, n_iter=4, tol=0.0, reg_covar=1e-6)
    history, _ = fused.fused_baum_welch(X, bounds, start, n_iter=4, reg_covar=1e-6)
    assert_allclose(history, ours.history[:4], rtol=1e-10)
