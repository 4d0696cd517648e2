"""The command line, run in-process: demo/select reports, report re-render, fit/predict, errors."""

import argparse
import functools
import inspect
import json

import numpy as np
import pandas as pd
import pytest

from skhmmgmr.cli import build_parser, main

pytest.importorskip("matplotlib")


def make_recordings(n_recordings=6, length=80, seed=0, split=True):
    """A tidy CSV-like table: the torque follows f0 and f1."""
    rng = np.random.default_rng(seed)
    frames = []
    for r in range(n_recordings):
        x = np.cumsum(rng.normal(scale=0.2, size=(length, 3)), axis=0)
        frame = pd.DataFrame(x, columns=["f0", "f1", "f2"])
        frame.insert(0, "run", f"r{r}")
        frame.insert(1, "t", np.arange(length) * 0.05)
        frame["torque"] = np.tanh(x[:, 0]) + 0.5 * x[:, 1] + rng.normal(scale=0.05, size=length)
        if split:
            frame["split"] = ["train", "train", "train", "train", "validation", "test"][r % 6]
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def test_demo_writes_report(demo_dir, capsys):
    names = {p.name for p in demo_dir.iterdir()}
    figures = ("estimate", "models_estimate", "state_selection", "trade_off", "closed_loop")
    figures += ("drivers", "relevance")
    for figure in figures:
        assert f"{figure}.png" in names
        assert (demo_dir / f"{figure}.png").stat().st_size > 5_000
    for table in ("test_summary", "per_driver", "candidates", "relevance", "states", "bic"):
        assert f"{table}.csv" in names
    manifest = json.loads((demo_dir / "manifest.json").read_text())
    assert manifest["command"] == "demo"
    assert {"skhmmgmr", "scikit-learn", "numpy"} <= set(manifest["versions"])
    assert manifest["details"]["seed"] == 0
    assert "simulation" in manifest["timings"]
    page = (demo_dir / "index.html").read_text()
    assert page.count("data:image/png;base64,") == len(figures)
    assert page.count("<table") >= 8
    assert "Test set per driver" in page and "defensive" in page and "novice" in page
    per_driver = pd.read_csv(demo_dir / "per_driver.csv")
    assert set(per_driver["driver"]) == {"defensive", "novice"}
    assert set(per_driver["model"]) == {"final", "baseline"}


def test_report_rerenders_from_saved_tables(demo_dir, tmp_path):
    copy = tmp_path / "copy"
    copy.mkdir()
    for path in demo_dir.iterdir():
        if path.name != "index.html":
            (copy / path.name).write_bytes(path.read_bytes())
    assert main(["report", str(copy), "--quiet"]) == 0
    page = (copy / "index.html").read_text()
    assert page == (demo_dir / "index.html").read_text()


def test_report_errors(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "manifest.json" in capsys.readouterr().err
    recordings = tmp_path / "runs.csv"
    make_recordings().to_csv(recordings, index=False)
    assert main(["report", str(recordings)]) == 2
    assert f"skhmmgmr select {recordings}" in capsys.readouterr().err


def test_select_on_csv_without_split(tmp_path, capsys):
    data = make_recordings(n_recordings=6, split=False)
    path = tmp_path / "runs.csv"
    data.to_csv(path, index=False)
    output = tmp_path / "out"
    argv = ["select", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    argv += ["--n-top", "2", "--k-max", "2", "--trade-off-step", "50", "--quiet"]
    assert main([*argv, "--output", str(output)]) == 0
    out = capsys.readouterr().out
    assert "selected features" in out
    manifest = json.loads((output / "manifest.json").read_text())
    assert "drawn at random" in manifest["details"]["split"]
    assert (
        manifest["details"]["recordings (train/validation/test)"] == "3/2/1"
        or sum(map(int, manifest["details"]["recordings (train/validation/test)"].split("/"))) == 6
    )
    assert (output / "index.html").is_file()
    # the same page as the demo's: the parts whose columns the recordings lack are named
    models = pd.read_csv(output / "models.csv")
    assert list(models["model"]) == ["selected_model", "baseline", "gradient_boosting"]
    torque_pipeline, driver_model = manifest["notes"][:2]
    assert "torque pipeline is left out" in torque_pipeline and "steering_wheel_velocity" in (
        torque_pipeline
    )
    assert "driver model is left out" in driver_model and "lateral_deviation_0m" in driver_model
    assert (output / "selected_model.json").is_file()
    assert "What to use for what?" in (output / "index.html").read_text()


def test_select_errors(tmp_path, capsys):
    assert main(["select", str(tmp_path / "nope.csv")]) == 2
    assert "not found" in capsys.readouterr().err
    path = tmp_path / "runs.csv"
    make_recordings().to_csv(path, index=False)
    assert main(["select", str(path), "--target", "torque", "--recording", "run"]) == 2
    assert "missing the time column 'time'; name yours with --time." in capsys.readouterr().err
    bad = make_recordings().assign(split="holdout")
    bad.to_csv(path, index=False)
    argv = ["select", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    assert main(argv) == 2
    assert "'train', 'validation' and 'test'" in capsys.readouterr().err


def test_fit_predict_round_trip(tmp_path):
    data = make_recordings()
    path = tmp_path / "runs.csv"
    data.to_csv(path, index=False)
    model = tmp_path / "model.json"
    argv = ["fit", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    assert main([*argv, "--features", "f0", "f1", "--n-states", "2", "--output", str(model)]) == 0
    assert (
        main(["--quiet", "predict", str(model), str(path), "--recording", "run", "--time", "t"])
        == 0
    )
    result = pd.read_csv(tmp_path / "runs_predicted.csv")
    assert len(result) == len(data)
    assert {"estimate", "estimate_std", "state_0", "state_1"} <= set(result.columns)
    assert np.allclose(result[["state_0", "state_1"]].sum(axis=1), 1.0)
    assert (result["estimate_std"] > 0).all()
    assert np.corrcoef(result["estimate"], result["torque"])[0, 1] > 0.8


def test_export_c_writes_the_c_filter_of_a_fitted_model(tmp_path, capsys):
    path, model = tmp_path / "runs.csv", tmp_path / "model.json"
    make_recordings().to_csv(path, index=False)
    argv = ["fit", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    assert main([*argv, "--features", "f0", "f1", "--n-states", "2", "--output", str(model)]) == 0
    folder = tmp_path / "c"
    folder.mkdir()
    assert main(["--quiet", "export-c", str(model), str(folder), "--name", "torque"]) == 0
    header = (folder / "torque.h").read_text()
    assert "double alpha[2]" in header and "int         torque_update(" in header
    assert "f0, f1" in header and (folder / "torque.c").is_file()
    assert main(["--quiet", "export-c", str(model), str(folder), "--name", "torque"]) == 2
    assert "torque.h exists; pass --overwrite" in capsys.readouterr().err
    argv = ["--quiet", "export-c", str(model), str(folder), "--name", "torque", "--overwrite"]
    assert main([*argv, "--float32"]) == 0
    assert "float alpha[2]" in (folder / "torque.h").read_text()
    assert main(["export-c", str(model), str(folder), "--name", "2fast"]) == 2
    assert "--name: name must be a C identifier" in capsys.readouterr().err
    assert main(["--quiet", "export-c", str(model), str(tmp_path / "new" / "c")]) == 0
    assert (tmp_path / "new" / "c" / "skhmmgmr_model.h").is_file()  # the folder is made
    (tmp_path / "file").write_text("")
    assert main(["export-c", str(model), str(tmp_path / "file")]) == 2
    assert "file exists and is not a folder" in capsys.readouterr().err
    assert main(["export-c", str(tmp_path / "none.json"), str(folder)]) == 2
    assert "model file not found" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["fit", "{tmp}/missing.csv"], "data file not found"),
        (["fit", "{tmp}/garbage.parquet"], "Cannot read"),
        (
            ["fit", "{tmp}/runs.csv", "--target", "nope", "--recording", "run", "--time", "t"],
            "missing column",
        ),
        (["predict", "{tmp}/missing.joblib", "{tmp}/runs.csv"], "model file not found"),
    ],
)
def test_error_exit_codes(tmp_path, capsys, argv, message):
    make_recordings().to_csv(tmp_path / "runs.csv", index=False)
    (tmp_path / "garbage.parquet").write_bytes(b"not parquet at all")
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_unknown_driver_style(capsys):
    assert main(["demo", "--drivers", "reckless", "--quiet"]) == 2
    assert "reckless" in capsys.readouterr().err


@pytest.mark.parametrize(
    "command", ["demo", "select", "report", "fit", "predict", "export-c", "export-fmu"]
)
def test_help_of_every_sub_command(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: skhmmgmr {command}")


def test_parser_lists_sub_commands():
    text = build_parser().format_help()
    for command in ("demo", "select", "report", "fit", "predict"):
        assert command in text


def test_select_defaults_are_those_of_select_parameters():
    from skhmmgmr.selection import select_parameters

    defaults = inspect.signature(select_parameters).parameters
    args = build_parser().parse_args(["select", "runs.csv"])
    for name in ("n_top", "k_max", "trade_off", "screening_tol", "search"):
        assert getattr(args, name) == defaults[name].default
    assert args.trade_off_step == 10  # relevance_trade_offs=None maps 10% steps


def test_select_hands_the_screening_tolerance_to_the_framework(tmp_path, capsys, monkeypatch):
    import skhmmgmr.selection

    given = {}

    @functools.wraps(skhmmgmr.selection.select_parameters)  # the defaults the options show
    def recorded(*args, **kwargs):
        given.update(kwargs)
        raise ValueError("stopped after the call")

    monkeypatch.setattr(skhmmgmr.selection, "select_parameters", recorded)
    path = tmp_path / "runs.csv"
    make_recordings().to_csv(path, index=False)
    argv = ["select", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    argv += ["--screening-tol", "1e-3", "--search", "fast", "--output", str(tmp_path / "out")]
    assert main(argv) == 2
    assert given["screening_tol"] == 1e-3
    assert given["search"] == "fast"
    assert "stopped after the call" in capsys.readouterr().err


def _sub_parsers():
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {"skhmmgmr": parser, **action.choices}


@pytest.mark.parametrize(
    "command", ["skhmmgmr", "demo", "select", "report", "fit", "predict", "export-c", "export-fmu"]
)
def test_help_shows_every_default(command):
    parser = _sub_parsers()[command]
    formatter = parser._get_formatter()
    for action in parser._actions:
        if action.option_strings and action.dest not in ("help", "version"):
            assert "(default: " in formatter._expand_help(action), action.option_strings


def test_select_help_text_states_the_defaults(capsys):
    from skhmmgmr.selection import select_parameters

    defaults = inspect.signature(select_parameters).parameters
    with pytest.raises(SystemExit):
        main(["select", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"largest number of states (default: {defaults['k_max'].default})" in text
    assert f"features kept by the filter (default: {defaults['n_top'].default})" in text
    assert f"(default: {defaults['trade_off'].default})" in text
    assert "(default: 0.25)" in text and "(default: skhmmgmr_report)" in text


def test_select_reports_an_empty_candidate(tmp_path, capsys, monkeypatch):
    import skhmmgmr.selection

    original = skhmmgmr.selection.candidate_subsets

    def with_empty_strict_2(*args, **kwargs):
        candidates = original(*args, **kwargs)
        row = candidates.index[candidates["name"] == "Strict 2"][0]
        candidates.at[row, "features"] = ()
        candidates.loc[row, ["n_features", "empty"]] = [0, True]
        return candidates

    monkeypatch.setattr(skhmmgmr.selection._framework, "candidate_subsets", with_empty_strict_2)
    path = tmp_path / "runs.csv"
    make_recordings().to_csv(path, index=False)
    output = tmp_path / "out"
    argv = ["select", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    argv += ["--n-top", "2", "--k-max", "2", "--trade-off-step", "50", "--n-jobs", "1"]
    with pytest.warns(UserWarning, match="Strict 2"):
        assert main([*argv, "--quiet", "--output", str(output)]) == 0
    assert "empty candidate subsets (not compared): Strict 2" in capsys.readouterr().out
    manifest = json.loads((output / "manifest.json").read_text())
    assert manifest["details"]["empty candidate subsets"] == "Strict 2"
    candidates = pd.read_csv(output / "candidates.csv").set_index("name")
    assert candidates.loc["Strict 2", "features"] == "(empty)"
    assert "(empty)" in (output / "index.html").read_text()


def test_select_resamples_recordings_with_gaps_on_request(tmp_path, capsys):
    data = make_recordings(n_recordings=6, split=False)
    data["t"] += np.random.default_rng(1).uniform(-0.002, 0.002, len(data))  # jitter
    data = data.drop(index=[10, 11, 100]).reset_index(drop=True)  # r0: 0.15 s gap, r1: 0.1 s
    data.loc[data["run"] == "r2", "t"] += np.where(data.loc[data["run"] == "r2", "t"] > 2, 5, 0)
    path = tmp_path / "runs.csv"
    data.to_csv(path, index=False)
    argv = ["select", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    argv += ["--n-top", "2", "--k-max", "2", "--trade-off-step", "50", "--quiet"]
    assert main([*argv, "--sampling-rate", "20", "--output", str(tmp_path / "a")]) == 2
    assert "is not sampled at 20.0 Hz" in capsys.readouterr().err
    assert main([*argv, "--max-gap", "0.2", "--output", str(tmp_path / "a")]) == 2
    assert "max_gap needs sampling_rate" in capsys.readouterr().err
    resample = ["--sampling-rate", "20", "--max-gap", "0.2", "--output", str(tmp_path / "b")]
    assert main([*argv, *resample]) == 0
    manifest = json.loads((tmp_path / "b" / "manifest.json").read_text())
    counts = manifest["details"]["recordings (train/validation/test)"].split("/")
    assert sum(map(int, counts)) == 7  # r2 split at its 5-s gap; the short gaps interpolated


# --- one rule for the time column, and outputs that never replace the user's columns (#35) ---


@pytest.mark.parametrize("command", ["fit", "predict", "select"])
def test_every_command_needs_the_time_column_or_an_explicit_file_order(tmp_path, capsys, command):
    """#35: fit took the rows in file order and then used the file's time column 't' as an
    input ("fitted on 19 features"), while select refused the same file."""
    path = tmp_path / "runs.csv"
    make_recordings().to_csv(path, index=False)
    model = tmp_path / "model.json"
    argv = ["fit", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    assert main(["--quiet", *argv, "--n-states", "2", "--output", str(model)]) == 0
    given = {"fit": ["fit", str(path)], "predict": ["predict", str(model), str(path)]}
    given["select"] = ["select", str(path)]
    options = ["--target", "torque", "--recording", "run"]
    assert main([*given[command], *options]) == 2
    err = capsys.readouterr().err
    assert "missing the time column 'time'; name yours with --time" in err
    assert ("--time none" in err) == (command != "select")
    if command == "select":
        assert main([*given[command], *options, "--time", "none"]) == 2
        assert "needs a time column" in capsys.readouterr().err


def test_fit_names_its_inputs_and_never_takes_the_time_column(tmp_path, capsys):
    path = tmp_path / "runs.csv"
    make_recordings().rename(columns={"t": "time"}).to_csv(path, index=False)
    argv = ["fit", str(path), "--target", "torque", "--recording", "run", "--n-states", "2"]
    assert main([*argv, "--output", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    inputs = out.split("input(s): ")[1].split(";")[0].split(", ")
    assert "time" not in inputs and inputs == ["f0", "f1", "f2"]
    # --time none: file order, and a column 'time' is still never an input
    assert main([*argv, "--time", "none", "--output", str(tmp_path / "n.json")]) == 0
    assert "in file order" in capsys.readouterr().out


def test_predict_never_replaces_the_users_columns(tmp_path, capsys):
    """#35: predict replaced the values of the user's columns named estimate or state_0."""
    data = make_recordings().assign(estimate=7.0)
    path = tmp_path / "runs.csv"
    data.to_csv(path, index=False)
    model = tmp_path / "model.json"
    fit = ["fit", str(path), "--target", "torque", "--recording", "run", "--time", "t"]
    assert (
        main(["--quiet", *fit, "--features", "f0", "--n-states", "2", "--output", str(model)]) == 0
    )
    predict = ["predict", str(model), str(path), "--recording", "run", "--time", "t"]
    assert main(predict) == 2
    assert "already has the column(s) ['estimate']" in capsys.readouterr().err
    assert not (tmp_path / "runs_predicted.csv").exists()
    assert main(["--quiet", *predict, "--prefix", "hmm_"]) == 0
    result = pd.read_csv(tmp_path / "runs_predicted.csv")
    assert (result["estimate"] == 7.0).all()
    assert {"hmm_estimate", "hmm_estimate_std", "hmm_state_0", "hmm_state_1"} <= set(result)


def test_every_stage_has_one_line_and_the_loops_inside_count_into_it():
    import io

    from skhmmgmr._core._progress import progress_bar
    from skhmmgmr.cli._stages import Stages

    stream = io.StringIO()  # not a terminal: one line per stage, when it ends
    stages = Stages(stream=stream)
    with stages.stage("parameter selection"):
        assert list(progress_bar(range(3), total=3, desc="subsets")) == [0, 1, 2]
        assert list(progress_bar("ab", total=2, desc="states")) == ["a", "b"]
    with stages.stage("figures", total=1) as bar:
        bar.update()
    lines = stream.getvalue().splitlines()
    assert [line.split(" (")[0] for line in lines] == [
        "parameter selection: done, 5/5 steps",
        "figures: done, 1/1 steps",
    ]
    assert set(stages.timings) == {"parameter selection", "figures"}
    # outside a stage a loop keeps a bar of its own; --quiet shows nothing
    quiet = io.StringIO()
    with Stages(quiet=True, stream=quiet).stage("simulation", total=1) as bar:
        bar.update()
    assert quiet.getvalue() == ""
