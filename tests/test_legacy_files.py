"""Files written by skhmmgmr 0.1.0 still load: portable JSON to the last bits, pickles, skops.

The fixtures in ``tests/fixtures/`` were written by 0.1.0 (``make_legacy_fixtures.py``), before
the package moved from one flat folder into subpackages: portable model files, the predictions
0.1.0 made from them, a fitted regressor pickled and as a skops file, and every class path and
public name 0.1.0 defined.
"""

import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from skhmmgmr import FilterStream, HMMGMRRegressor
from skhmmgmr.portable import load_json, read_model

FIXTURES = Path(__file__).resolve().parent / "fixtures"
CASES = ("full", "tied", "marginalize", "carry_forward")


@pytest.fixture(scope="module")
def expected():
    with np.load(FIXTURES / "legacy_0_1_0_predictions.npz") as arrays:
        return dict(arrays)


def assert_same(actual, expected, key):
    """``actual`` equals ``expected[key]`` to the last bits of double precision.

    The code path is the same on every stack, but not the rounding: numpy chooses its SIMD loops
    by the processor it runs on (AVX2, AVX-512...) and another numpy brings its own OpenBLAS
    (the oldest supported one, 1.24.1, among them), and each sums and multiplies in its own
    order. The differences are 1e-16 to 1e-15 on values of order one, so the check is to 1e-14:
    a change of the model or of the read-out moves the estimates by orders of magnitude more.
    """
    np.testing.assert_allclose(actual, expected[key], rtol=0, atol=1e-14)


def _inputs(expected, case):
    return expected["X"] if case in ("full", "tied") else expected["X_gaps"]


@pytest.mark.parametrize("case", CASES)
def test_a_0_1_0_json_file_predicts_to_the_last_bits(expected, case):
    model = HMMGMRRegressor.from_json(FIXTURES / f"legacy_0_1_0_{case}.json")
    X, groups = _inputs(expected, case), expected["groups"]
    mean, std = model.predict(X, groups=groups, return_std=True)
    assert_same(mean, expected, f"{case}_mean")
    assert_same(std, expected, f"{case}_std")
    proba = model.predict_state_proba(X, groups=groups)
    assert_same(proba, expected, f"{case}_proba")


@pytest.mark.parametrize("case", CASES)
def test_a_0_1_0_json_file_streams_to_the_last_bits(expected, case):
    model = HMMGMRRegressor.from_json(FIXTURES / f"legacy_0_1_0_{case}.json")
    X, groups = _inputs(expected, case), expected["groups"]
    first = X[groups == groups[0]]
    mean, std = model.filter_stream().update_batch(first, return_std=True)
    assert_same(mean, expected, f"{case}_stream_mean")
    assert_same(std, expected, f"{case}_stream_std")
    # The file read without the estimator: the same fitted model, the same stream.
    portable = read_model(load_json(FIXTURES / f"legacy_0_1_0_{case}.json"))
    missing = portable.estimator_params["missing_values"]
    stream = FilterStream(portable.model, missing_values=missing)
    assert_same(stream.update_batch(first), expected, f"{case}_stream_mean")


def test_a_0_1_0_json_file_keeps_its_covariance_form_and_stale_inputs():
    tied = HMMGMRRegressor.from_json(FIXTURES / "legacy_0_1_0_tied.json")
    assert tied.covariance_type == "tied"
    carried = HMMGMRRegressor.from_json(FIXTURES / "legacy_0_1_0_carry_forward.json")
    assert carried.missing_values == "carry_forward"
    assert "stale_inputs" in load_json(FIXTURES / "legacy_0_1_0_carry_forward.json")


def _legacy_classes():
    # Private classes (one: the command line's argparse formatter) are never saved in a file.
    data = json.loads((FIXTURES / "legacy_0_1_0_classes.json").read_text())
    assert data["version"] == "0.1.0"
    return [tuple(pair) for pair in data["classes"] if not pair[1].startswith("_")]


@pytest.mark.parametrize("module, qualname", _legacy_classes())
def test_every_0_1_0_class_path_resolves_as_a_pickle_names_it(module, qualname):
    # A pickle or a skops file names a class by its module and qualified name; the crafted
    # pickle holds that reference alone, so the check needs no array written by numpy 2.
    reference = f"c{module}\n{qualname}\n.".encode()
    found = pickle.loads(reference)
    assert found.__name__ == qualname.rsplit(".", 1)[-1]
    assert found.__module__.startswith("skhmmgmr")


@pytest.mark.skipif(
    int(np.__version__.split(".")[0]) < 2,
    reason="the 0.1.0 pickle's arrays were written by numpy 2 (numpy._core)",
)
def test_a_0_1_0_pickle_loads_and_predicts_the_same(expected):
    with open(FIXTURES / "legacy_0_1_0_regressor.pkl", "rb") as file:
        saved = pickle.load(file)
    model, stream = saved["regressor"], saved["stream"]
    assert isinstance(model, HMMGMRRegressor)
    assert isinstance(stream, FilterStream)
    # 0.1.0 had no read-out: none, and the parameters are complete
    assert model.get_params()["output_smoothing"] is None and model.output_smoothing_ == 0.0
    X, groups = expected["X_gaps"], expected["groups"]
    mean, std = model.predict(X, groups=groups, return_std=True)
    assert_same(mean, expected, "carry_forward_direct_mean")
    assert_same(std, expected, "carry_forward_direct_std")
    first = X[groups == groups[0]]
    assert np.array_equal(stream.update_batch(first), model.filter_stream().update_batch(first))


def test_a_0_1_0_skops_file_loads_with_its_trusted_types_and_predicts_the_same(expected):
    sio = pytest.importorskip("skops.io")
    path = FIXTURES / "legacy_0_1_0_regressor.skops"
    untrusted = sio.get_untrusted_types(file=path)
    # The file names 0.1.0's private modules; they load as the modules of today.
    assert "skhmmgmr._fitted.FittedHMMGMR" in untrusted
    model = sio.load(path, trusted=untrusted)
    assert type(model) is HMMGMRRegressor
    X, groups = expected["X_gaps"], expected["groups"]
    mean, std = model.predict(X, groups=groups, return_std=True)
    assert_same(mean, expected, "carry_forward_direct_mean")
    assert_same(std, expected, "carry_forward_direct_std")
