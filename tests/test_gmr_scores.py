"""The causal GMR estimate scored in one compiled pass, against predict and the metrics."""

import numpy as np
import pytest

from skhmmgmr import HMMGMRRegressor
from skhmmgmr._core._sequences import as_recordings
from skhmmgmr._hmm._gmr_scores import error_sums
from skhmmgmr.metrics import evaluate_recordings


@pytest.fixture(scope="module")
def fitted():
    rng = np.random.default_rng(0)
    X = np.cumsum(rng.normal(scale=0.2, size=(1200, 4)), axis=0)
    y = np.tanh(X[:, 0]) + 0.3 * X[:, 2] + 0.05 * rng.normal(size=1200)
    groups = np.repeat(np.arange(6), 200)
    model = HMMGMRRegressor(n_states=3, random_state=0).fit(X[:, [2, 0]], y, groups=groups)
    return X, y, groups, model


@pytest.mark.parametrize("layout", ["C", "F"])
def test_the_sums_are_those_of_predict(fitted, layout):
    X, y, groups, model = fitted
    scaling = model.model_.standardization
    standardized = np.zeros_like(X)
    standardized[:, [2, 0]] = scaling.inputs(X[:, [2, 0]])
    standardized = np.asarray(standardized, order=layout)
    recordings = as_recordings(groups, len(groups))
    sums = error_sums(
        standardized,
        [2, 0],  # the model's inputs, read in place among other columns
        recordings,
        model.model_.gmr,
        y,
        scaling.output_center[0],
        scaling.output_scale[0],
    )
    estimate = model.predict(X[:, [2, 0]], groups=groups)
    for r, (_, rows) in enumerate(recordings.slices()):
        steps = np.diff(estimate[rows])
        expected = [np.sum((estimate[rows] - y[rows]) ** 2), steps.sum(), np.sum(steps**2)]
        np.testing.assert_allclose(sums[r], expected, rtol=1e-9, atol=1e-12)
    # the metrics read from them are evaluate_recordings' (RMSE, accuracy, smoothness)
    table = evaluate_recordings(y, estimate, groups=groups, sampling_period=0.05)
    n = recordings.lengths
    rmse = np.sqrt(sums[:, 0] / n)
    np.testing.assert_allclose(rmse, table["rmse"], rtol=1e-9)
    spread = np.array([np.std(y[rows]) for _, rows in recordings.slices()])
    np.testing.assert_allclose((1 - rmse / spread) * 100, table["accuracy"], rtol=1e-9)
    mean = sums[:, 1] / (n - 1)
    smoothness = np.sqrt(sums[:, 2] / (n - 1) - mean**2) / 0.05
    np.testing.assert_allclose(smoothness, table["smoothness"], rtol=1e-7)


def test_an_extreme_row_is_read_as_predict_reads_it(fitted):
    X, y, groups, model = fitted
    scaling = model.model_.standardization
    standardized = scaling.inputs(X[:, [2, 0]])
    standardized[300] = 1e3  # far from every state: densities below exp(-700)
    recordings = as_recordings(groups, len(groups))
    sums = error_sums(
        standardized,
        [0, 1],
        recordings,
        model.model_.gmr,
        y,
        scaling.output_center[0],
        scaling.output_scale[0],
    )
    assert np.all(np.isfinite(sums))
    raw = scaling.input_center + scaling.input_scale * standardized
    estimate = model.predict(raw, groups=groups)
    rows = slice(200, 400)
    np.testing.assert_allclose(sums[1, 0], np.sum((estimate[rows] - y[rows]) ** 2), rtol=1e-9)


def test_more_than_one_output_is_refused(fitted):
    X, y, groups, _ = fitted
    model = HMMGMRRegressor(n_states=2, random_state=0).fit(X[:, :2], X[:, 2:], groups=groups)
    with pytest.raises(ValueError, match="one output"):
        error_sums(X[:, :2], [0, 1], as_recordings(groups, len(groups)), model.model_.gmr, y, 0, 1)
