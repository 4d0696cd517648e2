"""The report folder of ``skhmmgmr demo | select``: tables, figures, manifest and HTML page.

The folder holds every table as CSV, every figure as PNG, a ``manifest.json`` describing them
(captions, what was run, seeds, timings, versions) and ``index.html``, a self-contained page
(figures embedded as base64 PNG). :func:`render_html` rebuilds the page from the folder alone,
which is what ``skhmmgmr report DIR`` runs.
"""

import base64
import hashlib
import html
import json
import os
import platform
import secrets
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from .._core._files import write_atomically
from .._version import __version__

MANIFEST = "manifest.json"
PAGE = "index.html"
MAX_ROWS = 25
# keys of every entry of the manifest's lists
TABLE_FIELDS = ("name", "file", "caption", "shown")
FIGURE_FIELDS = ("name", "file", "caption")
#: keys of every saved model file (portable JSON, C source and header, FMU)
FILE_FIELDS = ("name", "file", "caption")
#: the manifest's lists of files, with the keys of their entries; "files" is optional
#: (a report of skhmmgmr <= 0.2 saved no model)
LISTS = {"tables": TABLE_FIELDS, "figures": FIGURE_FIELDS, "files": FILE_FIELDS}

# name -> (caption, shown on the page); every table is saved, long ones are shown truncated
TABLES = {
    "models": (
        "What to use for what: every model on the same test recordings (means over them)",
        True,
    ),
    "lane_keeping": (
        "The driver model at the wheel of a held-out road, beside the human (closed loop)",
        True,
    ),
    "test_summary": ("Test set: final model against the all-feature baseline (means)", True),
    "per_driver": ("Test set per driver (means over the driver's test recordings)", True),
    "candidates": (
        "Candidate subsets (Strict/Mild/Liberal 1-3) on validation, K=2; an empty candidate is "
        "listed but not compared",
        True,
    ),
    "state_choices": ("Number of states chosen by both 1% rules, per trade-off", True),
    "filter": ("Spearman filter on the training recordings", True),
    "relevance": ("Feature relevance: counts in the per-recording best subsets", True),
    "anova": ("One-way ANOVAs in the thesis' scope (Appendix E.1.2-E.1.4)", True),
    "bic": ("BIC of every K on the training recordings", True),
    "states": ("State selection: every K on every validation recording", False),
    "test": ("Test set: every recording", True),
    "models_test": ("Every model on every test recording", False),
    "candidate_scores": ("Candidate subsets: every validation recording", False),
}

# Tables of every relevance source (SelectionReport.source_tables), by the end of their name.
SOURCE_TABLES = {
    "_results": "Relevance source {}: every evaluated subset on every validation recording",
    "_paths": "Relevance source {}: every step of every path",
    "_selected": "Relevance source {}: the selected features",
}


def table_caption(name):
    """Caption of a report table and whether the page shows it (else: CSV only)."""
    if name in TABLES:
        return TABLES[name]
    for end, caption in SOURCE_TABLES.items():
        if name.endswith(end):
            return caption.format(repr(name[: -len(end)])), False
    return name, True


#: name -> caption, in the page's order; a caption says what to see (the command may give a
#: figure a caption of its own, with the run's numbers)
FIGURES = {
    "estimate": "Estimated against measured torque on a test recording, with the +-2 std band "
    "and the filtered state probabilities (thesis Fig. C.2): the band should hold the measured "
    "torque, and the states switch where the manoeuvre does",
    "models_estimate": "Every model's estimate against the measured torque on one test recording",
    "state_selection": "State selection (thesis Fig. 8): mean validation metrics against K, "
    "the 1% rules drawn (the gain of each added state on the performance score), the chosen "
    "K dashed",
    "trade_off": "Accuracy against smoothness: the candidate subsets on the validation "
    "recordings (left) and every model on the test recordings (right); up and to the left is "
    "better",
    "closed_loop": "A driver model at the wheel of a held-out road beside the human: lateral "
    "deviation from the lane centre and steering torque",
    "drivers": "Final model against the baseline per driver on the test set (thesis Fig. 9): "
    "the gap between the bars is what the selection costs (accuracy) or gains (smoothness) "
    "for each driver; the whiskers: one standard deviation over the driver's test recordings",
    "relevance": "Feature relevance over the accuracy/smoothness trade-offs (thesis Fig. 4): "
    "how often a feature is in a validation recording's best subset; bright on the left "
    "(100/0) it serves accuracy, bright on the right (0/100) smoothness",
}

STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; font-size: 0.85em; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 2px 6px; text-align: right; }
th { background: #f0f0f0; }
img { max-width: 100%; }
.meta td { text-align: left; }
td.text, th.text { text-align: left; }
figure { margin: 1em 0 2em; }
figcaption { font-size: 0.9em; color: #444; }
.wide { overflow-x: auto; max-width: 100%; }
.answers li { margin: 0.2em 0; line-height: 1.4; }
.answers { background: #f6f8fa; border-left: 4px solid #2a6fb0; padding: 0.5em 1.2em; }
.answers h3 { margin-bottom: 0.2em; }
.answers p { margin-top: 0.2em; line-height: 1.45; }
pre { background: #f0f0f0; padding: 0.4em 0.8em; overflow-x: auto; }
.note { color: #8a4b00; }
"""


def versions():
    """Versions of the packages the report depends on."""
    import hmmlearn
    import scipy
    import sklearn

    found = {
        "skhmmgmr": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "scikit-learn": sklearn.__version__,
        "pandas": pd.__version__,
        "hmmlearn": hmmlearn.__version__,
    }
    try:
        import matplotlib

        found["matplotlib"] = matplotlib.__version__
    except ImportError:
        found["matplotlib"] = "not installed"
    return found


def report_tables(report, per_driver):
    """The tables of a :class:`~skhmmgmr.selection.SelectionReport` as flat DataFrames."""
    tables = {name: getattr(report, name) for name in TABLES if hasattr(report, name)}
    tables.update(report.source_tables)
    tables["relevance"] = report.relevance.reset_index()
    tables["per_driver"] = per_driver
    return tables


def report_figures(report, data, *, sampling_period):
    """The report's figures: estimate, relevance, state selection and per-driver bars.

    Returns a dict name -> matplotlib figure, empty (with a warning) without matplotlib.
    """
    try:
        import matplotlib.pyplot  # noqa: F401

        from .. import plotting
    except ImportError as exc:
        warnings.warn(f"no figures: {exc}", stacklevel=2)
        return {}
    figures = {}
    test = data[data["split"] == "test"]
    first = test["recording"].iloc[0]
    rows = test[test["recording"] == first]
    X = rows[list(report.features)].to_numpy(dtype=float)
    model = report.final_model
    estimate, std = model.predict(X, return_std=True)
    time = rows["time"].to_numpy() if "time" in rows else np.arange(len(rows)) * sampling_period
    figures["estimate"], _ = plotting.plot_estimate(
        time,
        rows["driver_torque"].to_numpy(),
        estimate,
        std=std,
        state_proba=model.predict_state_proba(X),
        title=f"final model ({len(report.features)} features, K={report.n_states}): {first}",
        figsize=(8, 4.5),
    )
    figures["relevance"], _ = plotting.plot_relevance(report.relevance, source="combined")
    figures["state_selection"], _ = plotting.plot_state_selection(
        report.states, bic=report.bic, n_states=report.n_states
    )
    n_features = report.test_summary.set_index("model")["n_features"]
    figures["drivers"], _ = plotting.plot_driver_comparison(
        report.test,
        drivers=dict(zip(data["recording"], data["driver"], strict=False)),
        labels={m: f"{m} ({n} features)" for m, n in n_features.items()},
    )
    return figures


def _cell(value):
    if isinstance(value, tuple):
        return ", ".join(map(str, value)) if value else "(empty)"
    return value


def write_report(output, *, tables, figures, meta, files=None, overwrite=False):
    """Write tables (CSV), figures (PNG), the manifest and the HTML page into ``output``.

    The report is written into a temporary folder beside ``output`` and swapped in once
    complete: an interrupted or failed write leaves the previous folder as it was, never a
    folder mixing two runs. The manifest records every file's SHA-256 (and a table's number of
    rows), which :func:`render_html` checks.

    Parameters
    ----------
    output : str or path
        Folder, created (with its parents) if needed, replaced if it is a report.
    tables : dict of str to DataFrame
    figures : dict of str to matplotlib.figure.Figure or (Figure, str)
        Saved at 110 dpi and closed; a pair gives the figure its caption (else the one of
        :data:`FIGURES`).
    meta : dict
        JSON-serialisable; keys ``title``, ``text`` (list of paragraphs), ``answers`` (list
        of ``{"question", "answer"}``, shown first), ``notes`` (parts left out),
        ``details`` (label -> value, shown as a table) are rendered, the rest is kept in the
        manifest.
    files : callable, default=None
        ``files(folder)`` writes more files into the report's folder (the saved models) and
        returns their entries (``name``, ``file``, ``caption`` and any more keys, such as
        ``code``: the lines that load it).
    overwrite : bool, default=False
        Also replace a file, or a folder holding files that are not of a report.

    Returns
    -------
    page : pathlib.Path
        The HTML page.

    Raises
    ------
    ValueError
        When ``output`` holds something else than a report and ``overwrite`` is False.
    """
    output = Path(os.path.abspath(output))  # "." has a name and a parent
    check_replaceable(output, overwrite=overwrite)
    output.parent.mkdir(parents=True, exist_ok=True)
    # not mkdtemp, whose folders only their owner may read
    staging = output.parent / f".{output.name}.{os.getpid()}-{secrets.token_hex(4)}.partial"
    staging.mkdir()
    try:
        # the files first: their callback may complete ``meta`` (what they are, what was skipped)
        files = [] if files is None else files(staging)
        manifest = {**meta, "tables": [], "figures": [], "files": []}
        for name, table in tables.items():
            file = f"{name}.csv"
            table.apply(lambda column: column.map(_cell)).to_csv(staging / file, index=False)
            caption, shown = table_caption(name)
            entry = {"name": name, "file": file, "caption": caption, "shown": shown}
            entry.update(rows=len(table), sha256=_sha256(staging / file))
            manifest["tables"].append(entry)
        for name, fig in figures.items():
            fig, caption = fig if isinstance(fig, tuple) else (fig, FIGURES.get(name, ""))
            file = f"{name}.png"
            fig.savefig(staging / file, dpi=110)
            entry = {"name": name, "file": file, "caption": caption}
            manifest["figures"].append({**entry, "sha256": _sha256(staging / file)})
        for entry in files:
            manifest["files"].append({**entry, "sha256": _sha256(staging / entry["file"])})
        (staging / MANIFEST).write_text(json.dumps(manifest, indent=2, default=str))
        render_html(staging)
        _swap(staging, output)
    finally:
        if figures:
            import matplotlib.pyplot as plt

            for fig in figures.values():
                plt.close(fig[0] if isinstance(fig, tuple) else fig)
        shutil.rmtree(staging, ignore_errors=True)
    return output / PAGE


def _swap(new, target):
    """Put the folder ``new`` at ``target``; what was there is deleted only once it is."""
    if not os.path.lexists(target):
        os.replace(new, target)
        return
    trash = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=target.parent))
    os.replace(target, trash / target.name)
    try:
        os.replace(new, target)
    except BaseException:
        os.replace(trash / target.name, target)
        trash.rmdir()
        raise
    shutil.rmtree(trash, ignore_errors=True)


def foreign_files(folder):
    """Sorted names of what ``folder`` holds besides a report: all of it if it is no report."""
    folder = Path(folder)
    present = {path.name for path in folder.iterdir()}
    try:
        manifest = read_manifest(folder)
    except (OSError, ValueError):
        return sorted(present)
    listed = {MANIFEST, PAGE, *(e["file"] for e in _entries(manifest))}
    return sorted(present - listed)


def check_replaceable(output, *, overwrite):
    """Refuse to replace ``output`` (ValueError) unless it is absent, an empty folder or a
    report folder, or ``overwrite`` is True."""
    output = Path(output)
    if overwrite or not os.path.lexists(output):
        return
    if not output.is_dir():
        raise ValueError(
            f"{output} exists and is not a folder; choose another report folder or pass "
            "--overwrite to replace the file"
        )
    foreign = foreign_files(output)
    if foreign:
        shown = ", ".join(foreign[:5]) + (
            f" and {len(foreign) - 5} more" if len(foreign) > 5 else ""
        )
        raise ValueError(
            f"{output} is not a skhmmgmr report folder (it holds {shown}); choose another "
            "report folder or pass --overwrite to replace it with all its content"
        )


def _sha256(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def read_manifest(folder):
    """The manifest of a report folder, checked: ValueError naming the file and the key."""
    path = Path(folder) / MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"{folder} holds no {MANIFEST}: not a skhmmgmr report folder")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is not valid JSON ({exc}); rerun the command") from None
    if not isinstance(manifest, dict):
        raise ValueError(f"{path} must hold a JSON object, not {type(manifest).__name__}")
    manifest.setdefault("files", [])
    for key, fields in LISTS.items():
        entries = manifest.get(key)
        if not isinstance(entries, list):
            found = "lacks the key" if key not in manifest else "has no list under"
            raise ValueError(f"{path} {found} {key!r}: not a complete report manifest")
        for k, entry in enumerate(entries):
            lacking = [f for f in fields if not isinstance(entry, dict) or f not in entry]
            if lacking:
                raise ValueError(f"{path}: entry {k} of {key!r} lacks {lacking}")
            _check_inside(folder, entry["file"], f"{path}: {key} entry {entry['name']!r}")
    return manifest


def _entries(manifest):
    """Every file entry of a checked manifest: tables, figures and saved models."""
    return [entry for key in LISTS for entry in manifest[key]]


def _check_inside(folder, name, where):
    plain = isinstance(name, str) and Path(name).name == name and name not in ("", ".", "..")
    if not plain or (Path(folder) / name).resolve().parent != Path(folder).resolve():
        raise ValueError(
            f"{where}: the file {name!r} is not a file of the report folder; a report only "
            "embeds files inside its folder"
        )


def check_files(folder, manifest):
    """ValueError naming the first file listed in the manifest that is missing or changed."""
    where = Path(folder) / MANIFEST
    for entry in _entries(manifest):
        file = Path(folder) / entry["file"]
        if not file.is_file():
            raise ValueError(f"{file} is listed in {where} but missing")
        if "sha256" not in entry:
            raise ValueError(
                f"{where} records no checksum of {entry['file']}, so the folder may mix two "
                "runs; rerun the command that wrote it"
            )
        if _sha256(file) == entry["sha256"]:
            continue
        rows = ""
        if "rows" in entry:
            found = _count_rows(file)
            rows = f" ({found} rows; the manifest records {entry['rows']})"
        raise ValueError(
            f"{file}{rows} is not the file {where} records: the folder mixes two runs or was "
            "edited; rerun the command that wrote it"
        )


def _count_rows(file):
    try:
        return len(pd.read_csv(file))
    except Exception:  # only decorates the error message
        return "unreadable"


def _table_html(table, file):
    note = ""
    if len(table) > MAX_ROWS:
        note = f"<p>First {MAX_ROWS} of {len(table)} rows; all in <code>{file}</code>.</p>"
        table = table.head(MAX_ROWS)
    body = table.to_html(index=False, float_format=lambda v: f"{v:.4g}", na_rep="", border=0)
    return body + note


def render_html(output):
    """(Re)build ``index.html`` of a report folder from its manifest, CSV tables and PNGs.

    Parameters
    ----------
    output : str or path
        A folder written by :func:`write_report`.

    Returns
    -------
    page : pathlib.Path

    Raises
    ------
    FileNotFoundError
        When the folder has no manifest.
    ValueError
        Naming the file, when the manifest is not valid JSON or lacks a key, lists a file
        outside the folder, or a listed file is missing or differs from the one it records
        (a folder mixing two runs).
    """
    output = Path(output)
    manifest = read_manifest(output)
    check_files(output, manifest)
    title = html.escape(manifest.get("title", "skhmmgmr report"))
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{title}</title>"]
    parts.append(f"<style>{STYLE}</style></head><body><h1>{title}</h1>")
    parts += _answers_html(manifest)
    tables = {t["name"]: t for t in manifest["tables"]}
    if "models" in tables:
        parts.append(_section(output, tables.pop("models"), level=2))
    if manifest["figures"]:
        parts.append("<h2>Figures</h2>")
    for figure in manifest["figures"]:
        data = base64.b64encode((output / figure["file"]).read_bytes()).decode("ascii")
        parts.append(
            f"<figure id='figure-{html.escape(figure['name'])}'>"
            f"<img alt='{html.escape(figure['name'])}' src='data:image/png;base64,{data}'>"
            f"<figcaption>{html.escape(figure['caption'])}</figcaption></figure>"
        )
    parts += _files_html(manifest["files"])
    for name in ("lane_keeping", "test_summary", "per_driver"):
        if name in tables:
            parts.append(_section(output, tables.pop(name), level=2))
    text = manifest.get("text", [])
    if text:
        parts.append("<h2>What was run</h2>")
        parts += [f"<p>{html.escape(p)}</p>" for p in text]
    parts.append("<h2>Tables</h2>")
    parts += [_section(output, table, level=3) for table in tables.values() if table["shown"]]
    hidden = [t["file"] for t in tables.values() if not t["shown"]]
    if hidden:
        parts.append(f"<p>Also saved: {', '.join(f'<code>{f}</code>' for f in hidden)}.</p>")
    details = manifest.get("details", {})
    if details:
        rows = "".join(
            f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>"
            for k, v in details.items()
        )
        parts.append(f"<h2>Run</h2><table class='meta'>{rows}</table>")
    versions_found = manifest.get("versions", {})
    if versions_found:
        text = ", ".join(f"{k} {v}" for k, v in versions_found.items())
        parts.append(f"<h2>Versions</h2><p>{html.escape(text)}</p>")
    parts.append("</body></html>")
    return write_atomically(output / PAGE, "\n".join(parts))


def _answers_html(manifest):
    """The page's first section: the run's answers in plain words, and what was left out."""
    answers, notes = manifest.get("answers", []), manifest.get("notes", [])
    if not answers and not notes:
        return []
    parts = ["<div class='answers' id='answers'><h2>In short</h2>"]
    for item in answers:
        parts.append(f"<h3>{html.escape(item['question'])}</h3>")
        answer = item["answer"]
        if isinstance(answer, str):
            parts.append(f"<p>{html.escape(answer)}</p>")
        else:
            first, *lines = answer
            items = "".join(f"<li>{html.escape(line)}</li>" for line in lines)
            parts.append(f"<p>{html.escape(first)}</p><ul>{items}</ul>")
    parts += [f"<p class='note'>{html.escape(note)}</p>" for note in notes]
    parts.append("</div>")
    return parts


def _files_html(files):
    """The saved models, one block per model: its inputs, then every file, what it is and
    the lines of code that load it."""
    if not files:
        return []
    parts = ["<h2 id='saved-models'>Saved models</h2>"]
    by_model = {}
    for entry in files:
        by_model.setdefault(entry.get("model", entry["name"]), []).append(entry)
    for entries in by_model.values():
        first = entries[0]
        parts.append(f"<h3>{html.escape(first.get('label', first['name']))}</h3>")
        if first.get("inputs"):
            inputs = ", ".join(first["inputs"])
            parts.append(f"<p>Inputs, in this order: {html.escape(inputs)}.</p>")
        parts.append("<table class='meta'>")
        for entry in entries:
            code = entry.get("code")
            shown = f"<pre>{html.escape(code)}</pre>" if code else ""
            parts.append(
                f"<tr><td><code>{html.escape(entry['file'])}</code></td>"
                f"<td class='text'>{html.escape(entry['caption'])}</td>"
                f"<td class='text'>{shown}</td></tr>"
            )
        parts.append("</table>")
    return parts


#: Tables of few rows and many columns, shown transposed (one column per row of the CSV).
TRANSPOSED = ("lane_keeping",)


def _section(output, entry, *, level):
    table = pd.read_csv(output / entry["file"])
    if entry["name"] in TRANSPOSED:
        first = table.columns[0]
        table = table.set_index(first).T.infer_objects()
        table.columns.name = None
        table = table.rename_axis("metric").reset_index()
    caption = html.escape(entry["caption"])
    body = _table_html(table, entry["file"])
    # text columns (labels, uses, feature lists) read from the left
    numeric = pd.api.types.is_numeric_dtype
    texts = [i + 1 for i, column in enumerate(table.columns) if not numeric(table[column])]
    rule = ", ".join(f"#{entry['name']}-table td:nth-child({i})" for i in texts)
    style = f"<style>{rule} {{ text-align: left; }}</style>" if texts else ""
    return (
        f"<h{level} id='{entry['name']}'>{caption}</h{level}>{style}"
        f"<div class='wide' id='{entry['name']}-table'>{body}</div>"
    )
