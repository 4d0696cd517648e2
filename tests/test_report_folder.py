"""The report folder: written whole or not at all, and re-rendered only when consistent."""

import json
import os
import stat

import pandas as pd
import pytest

from skhmmgmr.cli import main
from skhmmgmr.cli._report import render_html, write_report

plt = pytest.importorskip("matplotlib.pyplot")


def _write(folder, value, **kwargs):
    tables = {
        "test_summary": pd.DataFrame({"model": ["final"], "rmse": [value]}),
        "states": pd.DataFrame({"n_states": [1, 2, 3], "rmse": [value, 2.0, 3.0]}),
        "bic": pd.DataFrame({"n_states": [1, 2], "bic": [value, 5.0]}),
    }
    fig, ax = plt.subplots()
    ax.plot([0, value])
    meta = {"title": f"run {value}", "text": ["t"], "details": {"value": value}}
    return write_report(folder, tables=tables, figures={"estimate": fig}, meta=meta, **kwargs)


@pytest.fixture
def report(tmp_path):
    folder = tmp_path / "report"
    _write(folder, 1.0)
    return folder


def _contents(folder):
    return {path.name: path.read_bytes() for path in folder.iterdir()}


def _manifest(folder):
    return json.loads((folder / "manifest.json").read_text())


def _report_error(folder, capsys):
    assert main(["report", str(folder)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def test_an_interrupted_write_leaves_the_previous_report(report, monkeypatch):
    before = _contents(report)
    original, calls = pd.DataFrame.to_csv, []

    def interrupted(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return original(self, *args, **kwargs)

    monkeypatch.setattr(pd.DataFrame, "to_csv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _write(report, 2.0)
    assert _contents(report) == before
    assert [p.name for p in report.parent.iterdir()] == ["report"]  # no partial folder left
    monkeypatch.undo()
    _write(report, 2.0)
    assert _manifest(report)["title"] == "run 2.0"


def test_the_manifest_records_what_it_lists(report):
    manifest = _manifest(report)
    states = next(t for t in manifest["tables"] if t["name"] == "states")
    assert states["rows"] == 3 and len(states["sha256"]) == 64
    assert len(manifest["figures"][0]["sha256"]) == 64
    assert main(["report", str(report), "--quiet"]) == 0
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(report.stat().st_mode) == 0o777 & ~umask  # not a private temp folder


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda f: (f / "states.csv").unlink(), "states.csv is listed in"),
        (lambda f: (f / "bic.csv").write_text("n_states,bic\n1,3.0\n2,4.0\n"), "bic.csv (2 rows"),
        (
            lambda f: (f / "states.csv").write_text("n_states\n1\n"),
            "(1 rows; the manifest records 3)",
        ),
        (lambda f: (f / "estimate.png").write_bytes(b"other png"), "estimate.png is not the file"),
    ],
)
def test_report_refuses_a_folder_whose_files_disagree_with_the_manifest(
    report, capsys, damage, message
):
    damage(report)
    assert message in _report_error(report, capsys)


def test_report_refuses_a_manifest_without_checksums(report, capsys):
    manifest = _manifest(report)
    for entry in manifest["tables"]:
        entry.pop("sha256")
    (report / "manifest.json").write_text(json.dumps(manifest))
    assert "records no checksum of test_summary.csv" in _report_error(report, capsys)


@pytest.mark.parametrize(
    "text, message",
    [
        ("{not json", "manifest.json is not valid JSON"),
        ('{"figures": []}', "manifest.json lacks the key 'tables'"),
        ('{"tables": {}, "figures": []}', "manifest.json has no list under 'tables'"),
        ('{"tables": [{"name": "x"}], "figures": []}', "entry 0 of 'tables' lacks ['file'"),
        ("[]", "must hold a JSON object"),
    ],
)
def test_a_damaged_manifest_is_named(report, capsys, text, message):
    (report / "manifest.json").write_text(text)
    assert message in _report_error(report, capsys)


@pytest.mark.parametrize("where", ["../secret.png", "absolute", "sub/../estimate.png", "link"])
def test_report_embeds_only_files_of_its_folder(report, capsys, where):
    secret = report.parent / "secret.png"
    secret.write_bytes(b"private bytes")
    if where == "link":
        (report / "link").symlink_to(secret)
    name = str(secret) if where == "absolute" else where
    manifest = _manifest(report)
    manifest["figures"][0]["file"] = name
    (report / "manifest.json").write_text(json.dumps(manifest))
    page = (report / "index.html").read_text()
    err = _report_error(report, capsys)
    assert f"the file {name!r} is not a file of the report folder" in err
    assert (report / "index.html").read_text() == page


def test_write_report_replaces_only_reports_unless_overwrite(tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match=r"not a skhmmgmr report folder \(it holds notes\.txt\)"):
        _write(folder, 1.0)
    assert _contents(folder) == {"notes.txt": b"mine"}
    (tmp_path / "file").write_text("mine")
    with pytest.raises(ValueError, match="is not a folder"):
        _write(tmp_path / "file", 1.0)
    _write(folder, 1.0, overwrite=True)
    assert "notes.txt" not in _contents(folder)
    render_html(folder)
