"""The demo's page says what its tables hold, marks the K of the 1 % rules, and its saved
models predict what it reports (the tiny demo of ``conftest.demo_dir``)."""

import html
import json
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from skhmmgmr import portable
from skhmmgmr.datasets import make_driving_protocol
from skhmmgmr.metrics import evaluate_recordings
from skhmmgmr.state_selection import state_choices

pytest.importorskip("matplotlib")


def _manifest(folder):
    return json.loads((folder / "manifest.json").read_text())


def _answer(manifest, start):
    """The answer whose question starts with ``start``, as one text."""
    for item in manifest["answers"]:
        if item["question"].startswith(start):
            answer = item["answer"]
            return answer if isinstance(answer, str) else " ".join(answer)
    raise AssertionError(f"no answer to {start!r}: {[a['question'] for a in manifest['answers']]}")


@pytest.fixture(scope="module")
def test_rows():
    """The tiny demo's test recordings, simulated again as the demo did (seed 0)."""
    data = make_driving_protocol(
        drivers=("defensive", "novice"), duration=6.0, sampling_rate=10.0, random_state=0
    )
    return data[data["split"] == "test"].sort_values(["recording", "time"], kind="stable")


def test_the_page_answers_first_with_every_part(demo_dir):
    manifest = _manifest(demo_dir)
    page = (demo_dir / "index.html").read_text()
    questions = [item["question"] for item in manifest["answers"]]
    assert questions[:3] == [
        "What was selected, and why?",
        "What does it gain and cost against the baseline?",
        "What to use for what?",
    ]
    assert "Can the driver model drive?" in questions
    # the answers come before any figure or table, in the words the manifest holds
    assert page.index("In short") < page.index("<img") and page.index("In short") < page.index(
        "<table"
    )
    for item in manifest["answers"]:
        assert html.escape(item["question"]) in page
    models = pd.read_csv(demo_dir / "models.csv")
    expected = ["selected_model", "baseline", "torque_pipeline", "gradient_boosting"]
    assert list(models["model"]) == [*expected, "driver_model"]
    assert manifest["notes"] == [] or all("FMU" in note for note in manifest["notes"])


def test_the_plain_words_give_the_numbers_of_the_tables(demo_dir):
    manifest = _manifest(demo_dir)
    models = pd.read_csv(demo_dir / "models.csv").set_index("model")
    # the models table is the mean of its per-recording table
    per_recording = pd.read_csv(demo_dir / "models_test.csv")
    means = per_recording.groupby("model")[["rmse", "accuracy", "smoothness"]].mean()
    pd.testing.assert_frame_equal(
        means.loc[models.index], models[["rmse", "accuracy", "smoothness"]], check_names=False
    )
    # the selected model and the baseline score what the framework's own test table says
    framework = pd.read_csv(demo_dir / "test_summary.csv").set_index("model")
    for key, name in (("selected_model", "final"), ("baseline", "baseline")):
        for metric in ("rmse", "accuracy", "smoothness"):
            assert models.loc[key, metric] == pytest.approx(framework.loc[name, metric], rel=1e-9)
    cost = _answer(manifest, "What does it gain")
    for key in ("selected_model", "baseline"):
        assert f"{models.loc[key, 'accuracy']:.1f} %" in cost
        assert f"{models.loc[key, 'smoothness']:.2f}" in cost
    gap = models.loc["selected_model", "accuracy"] - models.loc["baseline", "accuracy"]
    assert f"{abs(gap):.1f} points {'less' if gap < 0 else 'more'} accurate" in cost
    uses = _answer(manifest, "What to use for what")
    for row in models.itertuples():
        assert f"{row.label}: {row.use}. Accuracy {row.accuracy:.1f} %" in uses
    best = models["accuracy"].idxmax()
    assert f"the most accurate is the {models.loc[best, 'label']}" in uses
    drive = _answer(manifest, "Can the driver model drive")
    lane_keeping = pd.read_csv(demo_dir / "lane_keeping.csv")
    assert lane_keeping["driver"].iloc[0] == "human (defensive)"
    for row in lane_keeping.itertuples():
        assert f"{row.driver}: lateral deviation {row.lateral_deviation_rms:.2f} m rms" in drive


def _rule_by_hand(scores, tol=0.01):
    """The 1 % rule in a plain loop: K grows while one more state gains more than ``tol``."""
    k = 0
    while k + 1 < len(scores) and (scores[k] - scores[k + 1]) / scores[k] > tol:
        k += 1
    return k + 1


def test_the_state_selection_figure_marks_the_k_of_the_selector(demo_dir):
    manifest = _manifest(demo_dir)
    trade_off = manifest["details"]["trade-off"]
    states = pd.read_csv(demo_dir / "states.csv")
    states = states[states["trade_off"] == trade_off]
    choices = state_choices(states[["n_states", "recording", "performance_score"]])
    choice = {k: int(choices[k].iloc[0]) for k in ("n_states_average", "n_states_per_recording")}
    means = states.groupby("n_states")["performance_score"].mean().to_numpy()
    assert choice["n_states_average"] == _rule_by_hand(means)
    kept = min(choice.values())
    assert manifest["details"]["selected number of states K"] == kept
    caption = {f["name"]: f["caption"] for f in manifest["figures"]}["state_selection"]
    assert f"average rule stops at K={choice['n_states_average']}" in caption
    assert f"per-recording rule at K={choice['n_states_per_recording']}" in caption
    assert f"the smaller, K={kept}, is kept" in caption
    selected = _answer(manifest, "What was selected")
    assert f"average rule stops at K = {choice['n_states_average']}" in selected
    assert f"per-recording rule at K = {choice['n_states_per_recording']}" in selected


def test_every_saved_model_loads_and_predicts_what_the_page_reports(demo_dir, test_rows):
    manifest = _manifest(demo_dir)
    models = pd.read_csv(demo_dir / "models.csv").set_index("model")
    saved = [f for f in manifest["files"] if f["kind"] == "portable JSON"]
    assert {f["model"] for f in saved} == {"selected_model", "torque_pipeline", "driver_model"}
    y, groups = test_rows["driver_torque"].to_numpy(), test_rows["recording"].to_numpy()
    for entry in saved:
        assert f'portable.load("{entry["file"]}")' in entry["code"]
        model, training = portable.load(demo_dir / entry["file"], return_training=True)
        inputs = list(model.feature_names_in_)
        estimate = model.predict(test_rows[inputs], groups=groups)
        table = evaluate_recordings(y, estimate, groups=groups, sampling_period=0.1)
        for metric in ("rmse", "accuracy", "smoothness"):
            assert table[metric].mean() == pytest.approx(
                models.loc[entry["model"], metric], rel=1e-12
            ), (entry["file"], metric)


@pytest.mark.skipif(shutil.which("cc") is None, reason="needs the system C compiler")
def test_the_saved_c_sources_compile(demo_dir, tmp_path):
    sources = [f["file"] for f in _manifest(demo_dir)["files"] if f["kind"] == "C source"]
    sources = [name for name in sources if name.endswith(".c")]
    assert len(sources) == 3
    for name in sources:
        command = ["cc", "-std=c99", "-Wall", "-Werror", "-c", str(demo_dir / name)]
        subprocess.run([*command, "-o", str(tmp_path / "x.o")], check=True)


def test_the_saved_fmu_runs_the_selected_model(demo_dir, test_rows, tmp_path):
    fmpy = pytest.importorskip("fmpy")
    model = portable.load(demo_dir / "selected_model.json")
    inputs = list(model.feature_names_in_)
    first = test_rows[test_rows["recording"] == test_rows["recording"].iloc[0]]
    signal = np.zeros(len(first), dtype=[("time", float)] + [(n, float) for n in inputs])
    signal["time"] = np.arange(len(first)) * 0.1
    for name in inputs:
        signal[name] = first[name].to_numpy()
    result = fmpy.simulate_fmu(
        str(demo_dir / "selected_model.fmu"),
        input=signal,
        stop_time=len(first) * 0.1,
        output_interval=0.1,
        output=["driver_torque"],
    )
    # the outputs after the step from t to t + h are those of the sample at t
    estimate = model.predict(first[inputs])
    np.testing.assert_allclose(result["driver_torque"][1:], estimate, rtol=1e-9, atol=1e-9)


def test_a_missing_fmpy_skips_the_fmu_with_a_line(monkeypatch, tmp_path):
    import builtins

    from skhmmgmr.cli._saved_models import save_models
    from skhmmgmr.cli._showcase import Candidate
    from skhmmgmr.estimator import HMMGMRRegressor

    real_import = builtins.__import__

    def no_fmpy(name, *args, **kwargs):
        if name == "fmpy" or name.startswith("fmpy."):
            raise ImportError("No module named 'fmpy'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_fmpy)
    X = pd.DataFrame(np.cumsum(np.random.default_rng(0).normal(size=(200, 2)), axis=0))
    X.columns = ["a", "b"]
    fitted = HMMGMRRegressor(n_states=2, n_iter=5, random_state=0).fit(X, X["a"])
    candidate = Candidate("m", "a model", "a test", fitted, ["a", "b"], saved=True)
    notes = []
    entries = save_models([candidate], tmp_path, sampling_period=0.1, notes=notes)
    assert [e["kind"] for e in entries] == ["portable JSON", "C source", "C source"]
    assert notes == [
        "The FMUs are not written: FMPy is not installed (pip install 'skhmmgmr[fmu]')."
    ]
    assert not list(tmp_path.glob("*.fmu"))


def test_the_driver_model_is_fitted_on_the_perturbation_experiment(demo_dir, test_rows):
    # by hand: the demo's training sections, a third of them driven again with a 0.2 Nm RMS
    # perturbation, and make_driver_model's defaults fitted on them
    from skhmmgmr import make_driver_model
    from skhmmgmr.datasets import DRIVER_MODEL_FEATURES

    experiment = make_driving_protocol(
        drivers=("defensive", "novice"),
        duration=6.0,
        sampling_rate=10.0,
        random_state=0,
        n_validation=0,
        n_test=0,
        perturbation=0.2,
        perturbed_share=1 / 3,
    ).sort_values(["recording", "time"], kind="stable")
    perturbed = experiment.groupby("recording")["steering_perturbation"].apply(
        lambda p: bool(p.abs().max() > 0)
    )
    assert perturbed.sum() * 3 == perturbed.size  # a third of the training recordings
    features = list(DRIVER_MODEL_FEATURES)
    by_hand = make_driver_model(sampling_period=0.1, random_state=0).fit(
        experiment[features],
        experiment["driver_torque"],
        groups=experiment["recording"],
        perturbation=experiment["steering_perturbation"],
    )
    saved = portable.load(demo_dir / "driver_model.json")
    assert type(saved).__name__ == "DriverModel"
    assert saved.perturbed_share_ == pytest.approx(1 / 3, rel=1e-12)
    rows = experiment["recording"].map(perturbed).to_numpy()
    rms = np.sqrt(np.mean(experiment["steering_perturbation"].to_numpy()[rows] ** 2))
    assert saved.perturbation_rms_ == pytest.approx(rms, rel=1e-12)
    assert rms == pytest.approx(0.2, rel=0.01)  # the multisine's RMS over 6-s sections
    groups = test_rows["recording"]
    np.testing.assert_allclose(
        saved.predict(test_rows[features], groups=groups),
        by_hand.predict(test_rows[features], groups=groups),
        rtol=1e-9,
        atol=1e-9,
    )
    # and the page says what it was fitted on
    use = pd.read_csv(demo_dir / "models.csv").set_index("model").loc["driver_model", "use"]
    assert "perturbation" in use and "0.2 Nm" in use
