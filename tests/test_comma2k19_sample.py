"""The comma2k19 sample that ships with the package: the same minute as the original segment,
read without anything outside the installed package."""

import os
import re
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from _comma2k19_data import SEGMENT, SEGMENT_NAME

from skhmmgmr.datasets import TARGET, load_comma2k19_sample, load_comma2k19_segment
from skhmmgmr.datasets._comma2k19._sample import (
    KEPT_FILES,
    KEPT_FRAMES,
    reduce_segment,
    sample_path,
    write_sample,
)

ROOT = Path(__file__).resolve().parents[1]

# Column -> (mean, largest absolute value) of load_comma2k19_segment(engagement=True,
# eps_torque=True) on the original segment folder, all of its 135,468 CAN frames and every file
# (measured once, before the sample was cut from it): the sample must give the same minute.
FULL_SEGMENT = {
    "time": (29.975, 59.94999999999709),
    "steering_wheel_angle": (-0.003694733122476171, 0.08028514559173916),
    "steering_wheel_velocity": (-8.853502989429783e-05, 0.47044001012510683),
    "steering_wheel_acceleration": (0.0001439614248029318, 2.665143575293312),
    "lateral_acceleration": (0.07026770739303252, 0.8331004381110078),
    "yaw_rate": (-0.007282665532291692, 0.03958406743523141),
    "yaw_acceleration": (-7.3004629283468e-05, 0.1350616691234775),
    "speed": (16.731704006582312, 19.833946091064256),
    "eps_torque": (3.8522734331389543, 733.0256909584158),
    "cruise_active": (0.8491666666666666, 1.0),
    "openpilot_steer_request": (0.8475, 1.0),
    "openpilot_steer_command": (0.9216666666666666, 630.0),
    "eps_lka_active": (0.8458333333333333, 1.0),
    "steer_override": (0.0, 0.0),
    "brake_pressed": (0.0, 0.0),
    "gas_pressed": (0.14666666666666667, 1.0),
    "driver_torque": (-4.224832384550343, 147.3745249334446),
}


def test_sample_is_the_original_minute():
    pytest.importorskip("cantools")
    frame = load_comma2k19_sample(engagement=True, eps_torque=True)
    assert len(frame) == 1200
    assert (frame["recording"] == SEGMENT_NAME).all()
    for column, (mean, largest) in FULL_SEGMENT.items():
        values = frame[column].to_numpy()
        np.testing.assert_allclose(values.mean(), mean, rtol=1e-12, atol=1e-15, err_msg=column)
        np.testing.assert_allclose(np.abs(values).max(), largest, rtol=1e-12, err_msg=column)


def test_driver_spans_of_the_original_minute():
    pytest.importorskip("cantools")
    spans = load_comma2k19_sample(steering="driver", min_span=0, sampling_rate=100.0)
    # measured on the original segment: three spans of 904, 3 and 5 rows at 100 Hz
    sizes = spans["recording"].value_counts().sort_index()
    assert sizes.to_dict() == {f"{SEGMENT_NAME}/span{k}": n for k, n in enumerate((904, 3, 5))}
    np.testing.assert_allclose(spans[TARGET].sum(), 15844.835814330097, rtol=1e-12)


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"sampling_rate": 10.0, "recording": "r", "eps_torque": True},
        {"engagement": True},
        {"steering": "driver", "min_span": 0.5, "sampling_rate": 50.0},
    ],
)
def test_sample_reads_as_its_segment_folder(options):
    if options.get("engagement") or options.get("steering") == "driver":
        pytest.importorskip("cantools")
    sample = load_comma2k19_sample(**options)
    folder = load_comma2k19_segment(SEGMENT, **options)
    assert sample.equals(folder)
    assert sample.attrs == folder.attrs


def test_options_are_checked_and_named():
    with pytest.raises(ValueError, match="sampling_rate"):
        load_comma2k19_sample(sampling_rate=0)
    with pytest.raises(ValueError, match="steering"):
        load_comma2k19_sample(steering="openpilot")
    with pytest.raises(ValueError, match="min_span"):
        load_comma2k19_sample(min_span=-1.0)
    with pytest.raises(TypeError):
        load_comma2k19_sample(SEGMENT)  # the folder goes to load_comma2k19_segment


def test_archive_holds_only_what_the_loader_and_its_tests_read():
    with np.load(sample_path()) as archive:
        raw = {name: archive[f"processed_log/CAN/raw_can/{name}"] for name in ("src", "address")}
        names = set(archive.files)
    pairs = set(zip(raw["src"].tolist(), raw["address"].tolist(), strict=True))
    assert pairs == set(KEPT_FRAMES)
    assert names == {
        f"processed_log/CAN/raw_can/{n}" for n in ("t", "address", "src", "data")
    } | set(KEPT_FILES)


def test_archive_is_rebuilt_byte_for_byte(tmp_path):
    """write_sample on the segment folder of the sample gives the archive that ships."""
    rebuilt = tmp_path / "sample.npz"
    write_sample(SEGMENT, rebuilt)
    assert rebuilt.read_bytes() == sample_path().read_bytes()
    arrays = reduce_segment(SEGMENT)
    with np.load(sample_path()) as archive:
        for name, values in arrays.items():
            assert archive[name].dtype == values.dtype, name
            np.testing.assert_array_equal(archive[name], values, err_msg=name)


def test_licence_and_description_travel_with_the_sample():
    folder = sample_path().parent
    licence = folder.joinpath("LICENSE").read_text()
    assert "MIT License" in licence and "Copyright (c) 2018 comma.ai" in licence
    assert "LICENSE" in folder.joinpath("README.md").read_text()
    assert zipfile.is_zipfile(sample_path())
    # a few hundred kB: the wheel stays small
    assert sample_path().stat().st_size < 1_000_000


def _tracked_files():
    """The files of the checkout: git's list, or (a copy without .git, an sdist) every file
    but the hidden folders, the virtual environments and what builds write."""
    try:
        listed = subprocess.run(
            ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        skipped = {"build", "dist", "_build", "auto_examples", "generated", "__pycache__"}
        files = []
        for folder, subfolders, names in os.walk(ROOT):
            subfolders[:] = [d for d in subfolders if d not in skipped and not d.startswith(".")]
            files.extend(Path(folder, name) for name in names)
        return files
    return [ROOT / name for name in listed.decode().split("\0") if name]


# What reaches out of the checkout: the folder beside it, an environment variable naming a data
# folder, or a path climbed from a file to above the checkout's root.
_OUTSIDE = re.compile(
    r"\.\.[/\\]shared|shared/data|[\"']shared[\"']"
    r"|[\"']\.\.[\"'], [\"']\.\.[\"']|SKHMMGMR_COMMA2K19"
)
_CLIMB = re.compile(r"__file__\)\.resolve\(\)\.parents\[(\d+)\]")


def _outside(relative, line):
    """Whether ``line`` of the file ``relative`` (to the checkout) names a place outside it."""
    climbs = [int(n) for n in _CLIMB.findall(line)]
    return bool(_OUTSIDE.search(line)) or any(n >= len(relative.parts) for n in climbs)


def test_the_check_finds_what_the_checkout_used_to_read():
    # the lines by which the tests and the example found the segment before it shipped (the
    # folder's name is put together here, so that this file does not itself name it)
    folder = "sha" + "red"
    tests = Path("tests", "_comma2k19_data.py")
    assert _outside(tests, f'SHARED = Path(__file__).resolve().parents[2] / "{folder}"')
    assert _outside(tests, 'SHARED = os.path.join(os.path.dirname(__file__), "..", "..", "x")')
    assert _outside(Path("examples", "e.py"), 'return Path(os.environ["SKHMMGMR_COMMA2K19"])')
    assert _outside(Path("e.py"), f"segment beside the repository (``../{folder}/data/x``)")
    assert not _outside(tests, 'ROOT = Path(__file__).resolve().parents[1] / "docs"')
    assert not _outside(
        Path("skhmmgmr", "datasets", "x.py"), "x = Path(__file__).resolve().parents[2]"
    )


def test_nothing_refers_to_a_folder_outside_the_checkout():
    found = []
    for path in _tracked_files():
        if path == Path(__file__).resolve() or not path.is_file():
            continue
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        relative = path.relative_to(ROOT)
        for number, line in enumerate(text.splitlines(), 1):
            if _outside(relative, line):
                found.append(f"{relative}:{number}: {line.strip()}")
    assert not found, "refers to a folder outside the checkout:\n" + "\n".join(found)
