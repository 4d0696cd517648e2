"""The report's first section: the run's answers in plain words, from its own tables.

An answer is a paragraph or a list of lines (a sentence, then one line per model). Every
number of the answers is read from a table the report saves (``models``,
``state_choices``, ``lane_keeping``), rounded as the text shows it, so that the words and the
tables cannot disagree; the tests read them back from the page and compare.
"""

import numpy as np

#: The thesis' stopping rule of the state selection, in the words of the answers.
RULE = (
    "states are added while one more improves the performance score by more than 1 %, on "
    "the average over the validation recordings and recording by recording (the mean of the "
    "recordings' choices, rounded half up); the thesis keeps the smaller K of the two"
)


def counted(n, noun):
    """``3 features``, ``1 feature``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _weights(trade_off):
    accuracy, smoothness = (float(part) for part in str(trade_off).split("/"))
    return accuracy, smoothness


def _row(models, key):
    return models.set_index("model").loc[key]


def selected_answer(models, choices, *, trade_off, features, n_states, n_validation):
    """What was selected and why: the features, K and the two 1 % rules."""
    accuracy, smoothness = _weights(trade_off)
    row = choices.set_index("trade_off").loc[trade_off]
    average, per_recording = int(row["n_states_average"]), int(row["n_states_per_recording"])
    kept = (
        "the two rules agree"
        if average == per_recording
        else f"the smaller, K = {n_states}, is kept"
    )
    return (
        f"The framework selected {counted(len(features), 'feature')} ({', '.join(features)}) and "
        f"K = {n_states} hidden states, weighting accuracy {accuracy:g} % and smoothness "
        f"{smoothness:g} % (trade-off {trade_off}). The features were chosen by the filter, the "
        f"wrappers and their relevance over the trade-offs; for K, {RULE}. On the "
        f"{n_validation} validation recordings the average rule stops at K = {average} and the "
        f"per-recording rule at K = {per_recording} (mean "
        f"{float(row['n_states_per_recording_mean']):.2f}): {kept}. More states can still "
        "score better on validation (see the state-selection figure); the rule stops where "
        "one more state gains less than 1 %."
    )


def trade_off_answer(models, *, trade_off):
    """What the selected model gains and costs against the all-feature baseline."""
    selected, baseline = _row(models, "selected_model"), _row(models, "baseline")
    d_accuracy = selected["accuracy"] - baseline["accuracy"]
    d_smoothness = 100 * (selected["smoothness"] / baseline["smoothness"] - 1)
    accuracy_words = (
        f"{abs(d_accuracy):.1f} points less accurate"
        if d_accuracy < 0
        else f"{d_accuracy:.1f} points more accurate"
    )
    smoothness_words = (
        f"{abs(d_smoothness):.0f} % smoother"
        if d_smoothness < 0
        else f"{d_smoothness:.0f} % rougher"
    )
    return (
        f"On the {int(selected['n_recordings'])} test recordings, against the baseline on all "
        f"{int(baseline['n_inputs'])} features with the same K: accuracy "
        f"{selected['accuracy']:.1f} % against {baseline['accuracy']:.1f} %, smoothness "
        f"{selected['smoothness']:.2f} against {baseline['smoothness']:.2f} Nm/s (lower is "
        f"smoother), rmse {selected['rmse']:.3f} against {baseline['rmse']:.3f} Nm. The "
        f"selected model is {accuracy_words} and {smoothness_words}, from "
        f"{counted(int(selected['n_inputs']), 'sensor')} instead of "
        f"{int(baseline['n_inputs'])}: that is the trade-off {trade_off} asks for (a smooth "
        "estimate from few sensors, its states readable as driving phases), not the most "
        "accurate estimate of the torque."
    )


def uses_answer(models):
    """What to use for what: a sentence, then one line per model with its test figures."""
    best = models.loc[models["accuracy"].idxmax()]
    lines = [
        f"All on the same test recordings; the most accurate is the {best['label']} "
        f"({best['accuracy']:.1f} %)."
    ]
    for row in models.itertuples(index=False):
        lines.append(
            f"{row.label}: {row.use}. Accuracy {row.accuracy:.1f} %, smoothness "
            f"{row.smoothness:.2f} Nm/s, rmse {row.rmse:.3f} Nm."
        )
    return lines


def _lost(value):
    """The time a drive lost control, or None (a missing value read back from CSV: NaN)."""
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return None
    return float(value)


def drive_answer(lane_keeping, *, road):
    """The driver model at the wheel of the held-out road, beside the human: a sentence, then
    one line per driver."""
    human, *models = lane_keeping.itertuples(index=False)
    verdicts = []
    for row in models:
        if _lost(row.lost_control_at) is not None:
            verdicts.append(f"the {row.driver} lost control")
        elif row.departures > human.departures:
            verdicts.append(
                f"the {row.driver} keeps the car on the road but leaves its lane "
                f"{counted(int(row.departures), 'time')} where the human left it "
                f"{counted(int(human.departures), 'time')}"
            )
        else:
            verdicts.append(
                f"the {row.driver} keeps its lane ({int(row.departures)} departures, the "
                f"human {int(human.departures)})"
            )
    lines = [
        f"In closed loop on a road none of the recordings drove ({road}), "
        + "; ".join(verdicts)
        + ":"
    ]
    for row in lane_keeping.itertuples(index=False):
        lost = _lost(row.lost_control_at)
        ending = f"; lost control at {lost:.1f} s" if lost is not None else ""
        lines.append(
            f"{row.driver}: lateral deviation {row.lateral_deviation_rms:.2f} m rms (largest "
            f"{row.lateral_deviation_max:.2f} m), {counted(int(row.departures), 'lane departure')} "
            f"({row.time_out_of_lane:.1f} s out of the lane), torque {row.torque_rms:.2f} Nm "
            f"rms{ending}."
        )
    return lines


def files_answer(files):
    """Where the saved models are and what reads them."""
    kinds = list(dict.fromkeys(entry["kind"] for entry in files))
    named = ", ".join(dict.fromkeys(entry["model"] for entry in files))
    return (
        f"The models {named} are saved in this report's folder as {', '.join(kinds)}; the "
        "table 'Saved models' below gives the lines that load each."
    )
