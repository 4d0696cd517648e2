"""Files written by skhmmgmr 0.1.0 still load: portable JSON to the last bits, pickles and skops
files through the explicit loader of ``skhmmgmr.legacy``.

The fixtures in ``tests/fixtures/`` were written by 0.1.0 (``make_legacy_fixtures.py``), before
the package moved from one flat folder into subpackages: portable model files, the predictions
0.1.0 made from them, a fitted regressor pickled and as a skops file, and every class path and
public name 0.1.0 defined.
"""

import io
import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from skhmmgmr import FilterStream, HMMGMRRegressor, InconsistentVersionWarning, legacy, portable

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
    model = portable.load(FIXTURES / f"legacy_0_1_0_{case}.json")
    X, groups = _inputs(expected, case), expected["groups"]
    mean, std = model.predict(X, groups=groups, return_std=True)
    assert_same(mean, expected, f"{case}_mean")
    assert_same(std, expected, f"{case}_std")
    proba = model.predict_state_proba(X, groups=groups)
    assert_same(proba, expected, f"{case}_proba")


@pytest.mark.parametrize("case", CASES)
def test_a_0_1_0_json_file_streams_to_the_last_bits(expected, case):
    model = portable.load(FIXTURES / f"legacy_0_1_0_{case}.json")
    X, groups = _inputs(expected, case), expected["groups"]
    first = X[groups == groups[0]]
    mean, std = model.filter_stream().update_batch(first, return_std=True)
    assert_same(mean, expected, f"{case}_stream_mean")
    assert_same(std, expected, f"{case}_stream_std")
    # The stream of the fitted model alone: the same stream.
    stream = FilterStream(model.model_, missing_values=model.missing_values)
    assert_same(stream.update_batch(first), expected, f"{case}_stream_mean")


def test_a_0_1_0_json_file_keeps_its_covariance_form_and_stale_inputs():
    tied = portable.load(FIXTURES / "legacy_0_1_0_tied.json")
    assert tied.covariance_type == "tied"
    carried = portable.load(FIXTURES / "legacy_0_1_0_carry_forward.json")
    assert carried.missing_values == "carry_forward"
    assert carried.model_.stale_noise is not None
    assert "stale_inputs" in json.loads((FIXTURES / "legacy_0_1_0_carry_forward.json").read_text())


def _legacy_classes():
    # Private classes (one: the command line's argparse formatter) are never saved in a file.
    data = json.loads((FIXTURES / "legacy_0_1_0_classes.json").read_text())
    assert data["version"] == "0.1.0"
    return [tuple(pair) for pair in data["classes"] if not pair[1].startswith("_")]


@pytest.mark.parametrize("module, qualname", _legacy_classes())
def test_every_0_1_0_class_path_resolves_through_the_legacy_loader(module, qualname):
    # A pickle or a skops file names a class by its module and qualified name; the crafted
    # pickle holds that reference alone, so the check needs no array written by numpy 2.
    reference = f"c{module}\n{qualname}\n.".encode()
    found = legacy.load_pickle(io.BytesIO(reference))
    assert found.__name__ == qualname.rsplit(".", 1)[-1]
    assert found.__module__.startswith("skhmmgmr")


def test_the_old_private_modules_are_not_importable_by_their_old_names():
    # no import-time finder answers them: only the loader maps them
    with pytest.raises(ModuleNotFoundError):
        pickle.loads(b"cskhmmgmr._fitted\nFittedHMMGMR\n.")


@pytest.mark.skipif(
    int(np.__version__.split(".")[0]) < 2,
    reason="the 0.1.0 pickle's arrays were written by numpy 2 (numpy._core)",
)
def test_a_0_1_0_pickle_loads_and_predicts_the_same(expected):
    with pytest.warns(InconsistentVersionWarning, match="0.1.0 or earlier") as caught:
        saved = legacy.load_pickle(FIXTURES / "legacy_0_1_0_regressor.pkl")
    warned = {record.message.class_name for record in caught}
    assert {"HMMGMRRegressor", "FittedHMMGMR", "FilterStream"} <= warned
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


@pytest.mark.parametrize("names", ["current", "0.1.0"])
def test_a_0_1_0_skops_file_loads_with_its_trusted_types_and_predicts_the_same(expected, names):
    sio = pytest.importorskip("skops.io")
    path = FIXTURES / "legacy_0_1_0_regressor.skops"
    # The file names 0.1.0's private modules; the loader lists and loads them as today's.
    untrusted = legacy.untrusted_skops_types(path)
    assert "skhmmgmr._hmm._fitted.FittedHMMGMR" in untrusted
    old_names = sio.get_untrusted_types(file=path)
    assert "skhmmgmr._fitted.FittedHMMGMR" in old_names
    with pytest.warns(InconsistentVersionWarning):
        model = legacy.load_skops(path, trusted=untrusted if names == "current" else old_names)
    assert type(model) is HMMGMRRegressor
    X, groups = expected["X_gaps"], expected["groups"]
    mean, std = model.predict(X, groups=groups, return_std=True)
    assert_same(mean, expected, "carry_forward_direct_mean")
    assert_same(std, expected, "carry_forward_direct_std")


@pytest.mark.parametrize("file", [3, 2.5, None, ["a.pkl"]])
def test_the_legacy_loaders_refuse_what_names_no_file(file):
    # open(3) would read file descriptor 3
    from skhmmgmr.legacy import load_pickle, load_skops, untrusted_skops_types

    for loader in (load_pickle, load_skops, untrusted_skops_types):
        with pytest.raises(TypeError, match="file must be a path .* or a binary file object"):
            loader(file)
