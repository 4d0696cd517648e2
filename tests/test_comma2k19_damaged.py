"""The comma2k19 segment loader on damaged segments: every error names the file and segment."""

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from _comma2k19_data import SEGMENT

from skhmmgmr.datasets import fetch_comma2k19, load_comma2k19_segment

CAN = Path("processed_log", "CAN")


@pytest.fixture
def copy(tmp_path):
    """A copy of the CAN folder of the example segment, which is all the loader reads."""
    folder = tmp_path / "b0c9d2329ad1606b--2018-08-02--08-34-47" / "40"
    shutil.copytree(SEGMENT / CAN, folder / CAN)
    return folder


def _rewrite(folder, name, change):
    file = folder / CAN / name
    array = np.load(file)
    with open(file, "wb") as f:
        np.save(f, change(array))


def _named(folder, name):
    """Pattern of an error message naming the file ``name`` of the segment ``folder``."""
    return f"{re.escape(str(Path(CAN, name)))}.*{re.escape(str(folder))}"


def test_copy_loads(copy):
    assert len(load_comma2k19_segment(copy)) == 1200


@pytest.mark.parametrize("name", ["raw_can/t", "speed/t"])
def test_shuffled_times_are_refused_not_resorted(copy, name):
    rng = np.random.default_rng(0)
    _rewrite(copy, name, rng.permutation)
    with pytest.raises(ValueError, match=_named(copy, name) + ".*go back"):
        load_comma2k19_segment(copy)


@pytest.mark.parametrize("name", ["raw_can/t", "speed/t"])
def test_non_finite_times_are_refused(copy, name):
    _rewrite(copy, name, lambda t: np.where(np.arange(t.size) == 7, np.nan, t))
    with pytest.raises(ValueError, match=_named(copy, name) + ".*finite"):
        load_comma2k19_segment(copy)


@pytest.mark.parametrize(
    "name", ["raw_can/t", "raw_can/address", "raw_can/src", "raw_can/data", "speed/value"]
)
def test_truncated_file_is_named(copy, name):
    file = copy / CAN / name
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=_named(copy, name) + ".*not a readable NumPy array"):
        load_comma2k19_segment(copy)


def test_file_that_is_not_numpy_is_named(copy):
    (copy / CAN / "raw_can" / "src").write_bytes(b"garbage")
    with pytest.raises(ValueError, match=_named(copy, "raw_can/src")):
        load_comma2k19_segment(copy)


@pytest.mark.parametrize(
    "name, change, match",
    [
        ("raw_can/address", lambda a: a[:-5], "29793 values.*raw_can/t has 29798"),
        ("raw_can/data", lambda a: a[1:], "29797 values.*raw_can/t has 29798"),
        ("speed/value", lambda a: a[:-1], "4973 values.*speed/t has 4974"),
        ("speed/value", lambda a: np.hstack([a, a]), r"shape \(4974, 2\)"),
        ("raw_can/t", lambda t: t.reshape(-1, 2), r"shape \(14899, 2\)"),
        ("raw_can/src", lambda a: a.astype(float), "float64"),
        ("raw_can/data", lambda a: a.astype("S9"), "S9"),
        ("speed/t", lambda t: t.astype(str), "<U"),
    ],
)
def test_wrong_length_shape_or_dtype_is_named(copy, name, change, match):
    _rewrite(copy, name, change)
    with pytest.raises(ValueError, match=_named(copy, name) + ".*" + match):
        load_comma2k19_segment(copy)


@pytest.mark.parametrize("rate", [1e5, 1000.5])
def test_sampling_rate_is_bounded(rate, tmp_path):
    with pytest.raises(ValueError, match=r"sampling_rate.*1000 Hz.*50 to 83 Hz"):
        load_comma2k19_segment(tmp_path, sampling_rate=rate)
    with pytest.raises(ValueError, match=r"sampling_rate.*1000 Hz"):
        fetch_comma2k19(data_home=tmp_path, sampling_rate=rate, download_if_missing=False)


def test_highest_sampling_rate_works(copy):
    frame = load_comma2k19_segment(copy, sampling_rate=1000)
    np.testing.assert_allclose(np.diff(frame["time"]), 1e-3, atol=1e-9)
