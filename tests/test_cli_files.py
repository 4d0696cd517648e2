"""The command line's files: row order, recording ids, guarded outputs (checked before any
work, named by their option, written through files no one can plant), the model format."""

import json
import os
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_cli import make_recordings

from skhmmgmr import HMMGMRRegressor, __version__, portable
from skhmmgmr.cli import main
from skhmmgmr.cli._files import CommandError, read_data, write_output

DATA = ["--target", "torque", "--recording", "run", "--time", "t"]
FIT = ["--features", "f0", "f1", "--n-states", "2", "--quiet"]


def _shuffled_within_recordings(data, seed=0):
    rng = np.random.default_rng(seed)
    parts = [part.iloc[rng.permutation(len(part))] for _, part in data.groupby("run", sort=False)]
    return pd.concat(parts, ignore_index=True)


@pytest.fixture
def runs(tmp_path):
    path = tmp_path / "runs.csv"
    make_recordings().to_csv(path, index=False)
    return path


@pytest.fixture
def model(tmp_path, runs):
    path = tmp_path / "model.json"
    assert main(["fit", str(runs), *DATA, *FIT, "--output", str(path)]) == 0
    return path


def _error(capsys):
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def test_fit_and_predict_sort_rows_by_time_within_each_recording(tmp_path, runs, model):
    shuffled = tmp_path / "shuffled.csv"
    _shuffled_within_recordings(pd.read_csv(runs)).to_csv(shuffled, index=False)
    refit = tmp_path / "refit.json"
    assert main(["fit", str(shuffled), *DATA, *FIT, "--output", str(refit)]) == 0
    # Same data in the same order: the same model, up to the summation order of the kernels.
    _assert_same_numbers(json.loads(refit.read_text()), json.loads(model.read_text()))
    for path in (runs, shuffled):
        assert main(["predict", str(model), str(path), "--recording", "run", "--time", "t"]) == 0
    expected = pd.read_csv(tmp_path / "runs_predicted.csv")
    pd.testing.assert_frame_equal(
        pd.read_csv(tmp_path / "shuffled_predicted.csv"), expected, check_exact=False, rtol=1e-9
    )


def _assert_same_numbers(left, right, where="model"):
    if isinstance(left, dict):
        assert left.keys() == right.keys(), where
        for key in left:
            _assert_same_numbers(left[key], right[key], f"{where}.{key}")
    elif isinstance(left, list) and left and not isinstance(left[0], str):
        assert len(left) == len(right), where
        for i, (a, b) in enumerate(zip(left, right, strict=True)):
            _assert_same_numbers(a, b, f"{where}[{i}]")
    elif isinstance(left, float):
        assert left == pytest.approx(right, rel=1e-9, abs=1e-12), where
    else:
        assert left == right, where


def test_the_time_column_named_time_is_used_by_default(tmp_path, model):
    data = make_recordings().rename(columns={"t": "time"})
    path = tmp_path / "default.csv"
    _shuffled_within_recordings(data).to_csv(path, index=False)
    assert main(["predict", str(model), str(path), "--recording", "run", "--quiet"]) == 0
    result = pd.read_csv(tmp_path / "default_predicted.csv")
    assert (result.groupby("run", sort=False)["time"].diff().dropna() > 0).all()
    assert list(pd.unique(result["run"])) == list(pd.unique(data["run"]))


@pytest.mark.parametrize("command", ["fit", "predict", "select"])
def test_a_repeated_time_is_refused_naming_recording_and_time(tmp_path, model, capsys, command):
    data = make_recordings()
    data.loc[data.index[data["run"] == "r1"][5], "t"] = 0.5  # row 10 of r1 is at 0.5 s too
    path = tmp_path / "repeated.csv"
    _shuffled_within_recordings(data).to_csv(path, index=False)
    argv = {"fit": ["fit", str(path), *DATA, *FIT], "predict": ["predict", str(model), str(path)]}
    argv["select"] = ["select", str(path), *DATA, "--output", str(tmp_path / "report")]
    assert main([*argv[command], *DATA[2:]]) == 2
    err = _error(capsys)
    assert "'r1'" in err and "time 0.5" in err and "repeats the time" in err
    assert "repeated.csv" in err


def test_a_time_column_given_but_absent_is_named(runs, capsys):
    assert main(["fit", str(runs), "--target", "torque", "--recording", "run", "--time", "x"]) == 2
    assert "missing the time column 'x'" in _error(capsys)


@pytest.mark.parametrize("ids", [("7", "007"), ("1e3", "1000"), ("TRUE", "True")])
def test_recording_ids_stay_text_in_every_command(tmp_path, model, ids):
    data = make_recordings(n_recordings=2)
    data["run"] = data["run"].map({"r0": ids[0], "r1": ids[1]})
    path = tmp_path / "ids.csv"
    data.to_csv(path, index=False)
    assert main(["predict", str(model), str(path), *DATA[2:], "--quiet"]) == 0
    result = pd.read_csv(tmp_path / "ids_predicted.csv", dtype={"run": str})
    assert list(pd.unique(result["run"])) == list(ids)
    # the filter restarts at each recording: the first row of the second one is a first row
    first = result.groupby("run", sort=False).head(1)[["state_0", "state_1"]].to_numpy()
    alone = tmp_path / "alone.csv"
    data[data["run"] == ids[1]].to_csv(alone, index=False)
    assert main(["predict", str(model), str(alone), *DATA[2:], "--quiet"]) == 0
    restart = pd.read_csv(tmp_path / "alone_predicted.csv")[["state_0", "state_1"]].to_numpy()
    np.testing.assert_allclose(first[1], restart[0])
    assert list(pd.unique(read_data(path, "run")["run"])) == list(ids)


def test_fit_writes_the_portable_json_model(model):
    assert json.loads(model.read_text())["format"] == "skhmmgmr-hmm-gmr"


class _Payload:
    """Unpickling it writes a marker file: what a crafted model file could do."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return Path.write_text, (Path(self.marker), "code ran")


def test_predict_never_unpickles_a_model_file(tmp_path, runs, capsys):
    pickle.loads(pickle.dumps(_Payload(tmp_path / "proof")))
    assert (tmp_path / "proof").exists()  # the payload is live
    crafted = tmp_path / "model.joblib"
    crafted.write_bytes(pickle.dumps(_Payload(tmp_path / "marker")))
    assert main(["predict", str(crafted), str(runs), "--recording", "run"]) == 2
    assert not (tmp_path / "marker").exists()
    err = _error(capsys)
    assert str(crafted) in err and "pickle" in err


@pytest.mark.parametrize(
    "content", [b"\x00\xff garbage", b'{"format": "skhmmgmr-hmm-gmr", "n_st', b"[1, 2]", b"{}"]
)
def test_predict_names_an_unusable_model_file(tmp_path, runs, model, capsys, content):
    bad = tmp_path / "bad.json"
    bad.write_bytes(content)
    assert main(["predict", str(bad), str(runs), "--recording", "run"]) == 2
    assert f"cannot load the model file {bad}" in _error(capsys)
    truncated = tmp_path / "truncated.json"
    truncated.write_text(model.read_text()[: len(model.read_text()) // 2])
    assert main(["predict", str(truncated), str(runs), "--recording", "run"]) == 2
    assert str(truncated) in _error(capsys)


def test_fit_refuses_to_overwrite_a_file_without_overwrite(tmp_path, runs, capsys):
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    argv = ["fit", str(runs), *DATA, *FIT, "--output", str(notes)]
    assert main(argv) == 2
    assert "--overwrite" in _error(capsys) and notes.read_text() == "mine"
    assert main([*argv, "--overwrite"]) == 0
    assert json.loads(notes.read_text())["format"] == "skhmmgmr-hmm-gmr"


def test_predict_refuses_to_overwrite_its_default_output(tmp_path, runs, model, capsys):
    (tmp_path / "runs_predicted.csv").write_text("mine")
    argv = ["predict", str(model), str(runs), "--recording", "run", "--time", "t"]
    assert main(argv) == 2
    assert "--overwrite" in _error(capsys)
    assert (tmp_path / "runs_predicted.csv").read_text() == "mine"
    assert main([*argv, "--overwrite", "--quiet"]) == 0
    assert "estimate" in pd.read_csv(tmp_path / "runs_predicted.csv")


@pytest.mark.parametrize("input_name", ["runs.csv", "model.json"])
def test_an_input_is_never_overwritten(tmp_path, runs, model, capsys, input_name):
    before = (tmp_path / input_name).read_bytes()
    predict = ["predict", str(model), str(runs), "--recording", "run", "--overwrite"]
    assert main([*predict, "--output", str(tmp_path / input_name)]) == 2
    assert "would overwrite the input" in _error(capsys)
    fit = ["fit", str(runs), *DATA, *FIT, "--overwrite", "--output", str(runs)]
    assert main(fit) == 2
    assert (tmp_path / input_name).read_bytes() == before


@pytest.mark.parametrize("command", ["fit", "predict", "select"])
def test_a_missing_or_unusable_output_folder_is_named(tmp_path, runs, model, capsys, command):
    argv = {
        "fit": ["fit", str(runs), *DATA, *FIT],
        "predict": ["predict", str(model), str(runs), "--recording", "run"],
        "select": ["select", str(runs), *DATA],
    }[command]
    assert main([*argv, "--output", str(tmp_path / "nowhere" / "out")]) == 2
    assert f"the folder {tmp_path / 'nowhere'} does not exist" in _error(capsys)
    assert main([*argv, "--output", str(runs / "out")]) == 2
    assert "is not a folder" in _error(capsys)


def test_an_unwritable_output_folder_is_named(tmp_path, runs, capsys, monkeypatch):
    import skhmmgmr.cli._files

    monkeypatch.setattr(skhmmgmr.cli._files.os, "access", lambda *args: False)
    assert main(["fit", str(runs), *DATA, *FIT, "--output", str(tmp_path / "m.json")]) == 2
    assert f"the folder {tmp_path} is not writable" in _error(capsys)


def test_a_failed_write_keeps_the_previous_file(tmp_path):
    path = tmp_path / "out.csv"
    path.write_text("previous")

    def full_disk(partial):
        Path(partial).write_text("half")
        raise OSError(28, "No space left on device")

    with pytest.raises(CommandError, match=r"cannot write .*out\.csv: No space left"):
        write_output(path, full_disk)
    assert path.read_text() == "previous"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]


def test_select_checks_its_output_folder_before_the_run(tmp_path, runs, capsys, monkeypatch):
    import functools

    import skhmmgmr.selection

    @functools.wraps(skhmmgmr.selection.select_parameters)  # the CLI reads its defaults
    def never(*args, **kwargs):
        raise AssertionError("the selection ran")

    monkeypatch.setattr(skhmmgmr.selection, "select_parameters", never)
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "thesis.tex").write_text("mine")
    assert main(["select", str(runs), *DATA, "--output", str(folder)]) == 2
    err = _error(capsys)
    assert "not a skhmmgmr report folder" in err and "thesis.tex" in err
    assert (folder / "thesis.tex").read_text() == "mine"
    assert main(["select", str(runs), *DATA, "--output", str(tmp_path), "--overwrite"]) == 2
    assert "would overwrite the input" in _error(capsys)


# --- #51: options and outputs checked before any work, named in errors, written through files
# no one can plant -------------------------------------------------------------------------


@pytest.fixture
def victim(tmp_path):
    """A file outside the folders the commands write to."""
    outside = tmp_path / "outside"
    outside.mkdir()
    path = outside / "victim.txt"
    path.write_text("mine")
    return path


def _parse_error(argv, capsys):
    """The message of an option refused when parsed (argparse exits with code 2)."""
    with pytest.raises(SystemExit) as refused:
        main(argv)
    assert refused.value.code == 2
    return _error(capsys)


# --- item 3: no output is written through a predictable name ----------------------------------


def test_fit_and_predict_never_write_through_a_planted_link(tmp_path, runs, victim):
    """#51: the outputs were written to ``.partial-<pid>-<name>`` opened plainly, so that a
    link planted there overwrote a file outside the folder (and was then renamed over the
    output)."""
    work = tmp_path / "work"
    work.mkdir()
    names = ("model.json", "predicted.csv", "metrics.csv")
    for name in names:
        (work / f".partial-{os.getpid()}-{name}").symlink_to(victim)
    model = work / "model.json"
    assert main(["fit", str(runs), *DATA, *FIT, "--output", str(model)]) == 0
    predict = ["predict", str(model), str(runs), "--recording", "run", "--time", "t", "--quiet"]
    predict += ["--target", "torque", "--output", str(work / "predicted.csv")]
    assert main([*predict, "--metrics", str(work / "metrics.csv")]) == 0
    assert victim.read_text() == "mine"
    for name in names:
        assert (work / name).is_file() and not (work / name).is_symlink()
    assert portable.load(model).n_features_in_ == 2
    assert len(pd.read_csv(work / "predicted.csv")) == len(pd.read_csv(runs))
    assert len(pd.read_csv(work / "metrics.csv")) == 6  # one row per recording


def test_export_c_never_writes_through_a_planted_link(tmp_path, model, victim):
    folder = tmp_path / "c"
    folder.mkdir()
    for suffix in (".h", ".c"):
        (folder / f".torque{suffix}.partial").symlink_to(victim)
    assert main(["--quiet", "export-c", str(model), str(folder), "--name", "torque"]) == 0
    assert victim.read_text() == "mine"
    for suffix in (".h", ".c"):
        path = folder / f"torque{suffix}"
        assert path.is_file() and not path.is_symlink()
    assert "torque_update(" in (folder / "torque.h").read_text()


def test_report_never_writes_its_page_through_a_planted_link(tmp_path, victim):
    from skhmmgmr.cli._report import write_report

    folder = tmp_path / "report"
    table = pd.DataFrame({"model": ["final"], "rmse": [1.0]})
    write_report(folder, tables={"test_summary": table}, figures={}, meta={"title": "run"})
    (folder / ".index.html.partial").symlink_to(victim)
    assert main(["report", str(folder), "--quiet"]) == 0
    assert victim.read_text() == "mine"
    page = folder / "index.html"
    assert not page.is_symlink() and "<h1>run</h1>" in page.read_text()


# --- item 9: the target, the time and the recording ids are never features -------------------


@pytest.mark.parametrize(
    "columns, message",
    [
        (["torque"], "'torque' is the target (--target)"),
        (["t"], "'t' is the time column (--time), which is never an input"),
        (["run"], "'run' is the recording-id column (--recording)"),
        (["f1", "f1"], "--features names ['f1'] more than once"),
    ],
)
def test_fit_refuses_features_that_cannot_be_inputs(tmp_path, runs, capsys, columns, message):
    """#51: ``--features ... driver_torque`` fitted the target on itself, ``--features ...
    time`` took the time column as an input."""
    output = tmp_path / "m.json"
    argv = ["fit", str(runs), *DATA, "--features", "f0", *columns, "--output", str(output)]
    assert main(argv) == 2
    assert message in _error(capsys)
    assert not output.exists()


# --- item 11: export-c checks every argument before it makes a folder -------------------------


def test_export_c_refusing_a_name_leaves_no_folder_behind(tmp_path, model, capsys):
    target = tmp_path / "new" / "nested" / "dir"
    assert main(["export-c", str(model), str(target), "--name", "2fast"]) == 2
    assert "--name: name must be a C identifier" in _error(capsys)
    assert not (tmp_path / "new").exists()


def test_export_c_refusing_a_model_leaves_no_folder_behind(tmp_path, capsys):
    """A model the C filter cannot run (missing values marginalised) is refused by write_c;
    the folders made for it are removed."""
    data = make_recordings()
    fitted = HMMGMRRegressor(n_states=2, missing_values="marginalize", random_state=0)
    fitted.fit(data[["f0", "f1"]], data["torque"], groups=data["run"])
    path = tmp_path / "marginal.json"
    portable.save(fitted, path)
    target = tmp_path / "new" / "nested"
    assert main(["export-c", str(path), str(target)]) == 2
    assert "missing_values" in _error(capsys)
    assert not (tmp_path / "new").exists()


# --- item 17: numbers refused when the options are parsed, by the estimator's rule ------------


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("--output-smoothing", "1e300", "'output_smoothing' parameter of HMMGMRRegressor"),
        ("--output-smoothing", "1e400", "'output_smoothing' parameter of HMMGMRRegressor"),
        ("--output-smoothing", "1" + "0" * 400, "'output_smoothing' parameter of HMMGMRRegressor"),
        ("--output-smoothing", "2e6", "'output_smoothing' parameter of HMMGMRRegressor"),
        ("--sampling-period", "inf", "must be a finite number"),
        ("--sampling-period", "nan", "must be a finite number"),
        ("--sampling-period", "-0.05", "'sampling_period' parameter"),
    ],
)
def test_fit_refuses_unusable_numbers_when_it_parses_them(
    tmp_path, runs, capsys, option, value, message
):
    """#51: ``--output-smoothing 1e300`` was refused only after the whole fit, 10**400 with an
    OverflowError; ``--sampling-period inf`` passed the option check and printed a traceback
    after fitting."""
    output = tmp_path / "m.json"
    argv = ["fit", str(runs), *DATA, *FIT, "--pipeline", "torque", "--load-columns", "f1"]
    err = _parse_error([*argv, option, value, "--output", str(output)], capsys)
    assert f"argument {option}:" in err and message in err
    assert not output.exists()


# --- item 23: errors name the option; --version; one rule for export-c's files ---------------


def test_an_existing_metrics_file_is_named_by_its_option(tmp_path, runs, model, capsys):
    """#51: "--output X exists" was printed for the path of --metrics."""
    metrics = tmp_path / "metrics.csv"
    metrics.write_text("mine")
    argv = ["predict", str(model), str(runs), "--recording", "run", "--time", "t"]
    argv += ["--target", "torque", "--metrics", str(metrics)]
    assert main(argv) == 2
    err = _error(capsys)
    assert f"--metrics {metrics} exists; pass --overwrite" in err and "--output" not in err
    assert metrics.read_text() == "mine"


def test_export_c_names_its_own_options(tmp_path, model, capsys):
    """#51: export-c, which has no --output, said "--output X exists"."""
    folder = tmp_path / "c"
    assert main(["--quiet", "export-c", str(model), str(folder), "--name", "torque"]) == 0
    header = (folder / "torque.h").read_text()
    assert main(["export-c", str(model), str(folder), "--name", "torque", "--float32"]) == 2
    err = _error(capsys)
    assert f"--name torque: {folder / 'torque.h'} exists; pass --overwrite" in err
    assert "--output" not in err
    assert (folder / "torque.h").read_text() == header  # nothing replaced


def test_version(capsys):
    with pytest.raises(SystemExit) as shown:
        main(["--version"])
    assert shown.value.code == 0
    assert capsys.readouterr().out.strip() == f"skhmmgmr {__version__}"
