"""The report's figures beyond the framework's: the 1 % rules on the state selection, the
accuracy/smoothness trade-off of the candidates and models, the closed loop.

Each function returns ``(figure, caption)``, the caption saying what to see with the run's
numbers; matplotlib is imported by the caller's check (:func:`._report.report_figures`).
"""

import numpy as np

from ..selection._search._score_tables import relative_gain

#: The thesis' tolerance of the state selection: one more state must gain more than this.
TOL = 0.01


def rule_choice(choices, trade_off):
    """``(K of the average rule, K of the per-recording rule, their mean)`` at ``trade_off``."""
    row = choices.set_index("trade_off").loc[trade_off]
    return (
        int(row["n_states_average"]),
        int(row["n_states_per_recording"]),
        float(row["n_states_per_recording_mean"]),
    )


def state_selection_figure(report):
    """The thesis' Fig. 8 with the two 1 % rules drawn on the performance-score panel."""
    from .. import plotting

    states = report.states[report.states["trade_off"] == report.trade_off]
    fig, axes = plotting.plot_state_selection(
        states, bic=report.bic, n_states=report.n_states, figsize=(10, 6.5)
    )
    average, per_recording, mean = rule_choice(report.state_choices, report.trade_off)
    ax = axes[2]
    scores = states.groupby("n_states")["performance_score"].mean()
    ks, values = scores.index.to_numpy(), scores.to_numpy()
    for k0, k1, v0, v1 in zip(ks[:-1], ks[1:], values[:-1], values[1:], strict=True):
        gain = relative_gain(v0, v1)
        colour = "tab:green" if gain > TOL else "tab:gray"
        ax.annotate(
            f"{100 * gain:+.1f}%",
            xy=((k0 + k1) / 2, (v0 + v1) / 2),
            xytext=(0, 8),
            textcoords="offset points",
            ha="center",
            fontsize=7,
            color=colour,
        )
    ax.axvline(average, color="tab:orange", lw=2, alpha=0.6, label=f"average rule: K={average}")
    ax.axvline(
        per_recording,
        color="tab:purple",
        lw=2,
        alpha=0.6,
        ls=":",
        label=f"per-recording rule: K={per_recording}",
    )
    ax.legend(loc="upper right", fontsize="small")
    caption = (
        f"State selection (thesis Fig. 8), trade-off {report.trade_off}: mean validation "
        "metrics against K. On the performance-score panel each step is labelled with the "
        "gain of one more state (green above 1 %). The average rule stops at "
        f"K={average} (orange), the per-recording rule at K={per_recording} (purple, the "
        f"recordings' choices average {mean:.2f}); the smaller, K={report.n_states}, is kept "
        "(red dashed). Accuracy may still rise beyond it: the rule weighs each added state "
        "against 1 %."
    )
    return fig, caption


def trade_off_figure(candidates, models):
    """Accuracy against smoothness: candidate subsets (validation) and models (test)."""
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.5))
    shown = candidates[~candidates["empty"].astype(bool)]
    colours = plt.get_cmap("tab10").colors
    # neighbouring candidates sit on one another: a colour per strategy, a size per number of
    # features, and a label only for the chosen one and the baseline
    for i, (strategy, block) in enumerate(shown.groupby("strategy", sort=False)):
        left.scatter(
            block["smoothness"],
            block["accuracy"],
            s=12 + 6 * block["n_features"],
            color=colours[i % 10],
            alpha=0.75,
            label=strategy,
        )
    for row in shown.itertuples(index=False):
        if row.rank == 1 or row.strategy == "Baseline":
            chosen = " (selected)" if row.rank == 1 else ""
            # the baseline sits at the right edge (the roughest): its label goes to its left
            right_edge = row.strategy == "Baseline"
            left.annotate(
                f"{row.name}{chosen}: {row.n_features} features",
                (row.smoothness, row.accuracy),
                xytext=(-8, -12) if right_edge else (6, 4),
                textcoords="offset points",
                ha="right" if right_edge else "left",
                fontsize=8,
            )
    left.legend(fontsize=7, loc="lower right", title="strategy", title_fontsize=7)
    left.set_title("candidate subsets on validation (size: number of features)", fontsize="medium")
    for i, row in enumerate(models.itertuples(index=False)):
        right.scatter(row.smoothness, row.accuracy, color=colours[i % 10], s=60, label=row.label)
    right.set_title("models on the test recordings", fontsize="medium")
    right.legend(fontsize=7, loc="best")
    for ax in (left, right):
        ax.set_xlabel("smoothness [Nm/s] (lower is smoother)")
        ax.set_ylabel("accuracy [%]")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    best = models.loc[models["accuracy"].idxmax()]
    smoothest = models.loc[models["smoothness"].idxmin()]
    caption = (
        "Accuracy against smoothness; up is more accurate, left is smoother. Left: the "
        "candidate subsets the framework compared on the validation recordings (K=2). Right: "
        f"every model on the same test recordings; the most accurate is the {best['label']}, "
        f"the smoothest the {smoothest['label']}."
    )
    return fig, caption


def closed_loop_figure(drives, lane_keeping):
    """Lateral deviation and steering torque of every driver on the held-out road."""
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(10, 5.5))
    for name, frame in drives.items():
        time = frame["time"].to_numpy()
        top.plot(time, frame["lateral_deviation_0m"].to_numpy(), lw=1, label=name)
        bottom.plot(time, frame["driver_torque"].to_numpy(), lw=0.8, label=name)
    half_lane = 0.5 * float(next(iter(drives.values())).attrs.get("lane_width", np.nan))
    if np.isfinite(half_lane):
        for sign in (-1, 1):
            top.axhline(sign * half_lane, color="k", lw=0.6, ls="--")
        # a drive that leaves the road ends beyond 10 m: the lane stays readable
        low, high = top.get_ylim()
        top.set_ylim(max(low, -3 * half_lane), min(high, 3 * half_lane))
    top.set_ylabel("lateral deviation [m]")
    bottom.set_ylabel("steering torque [Nm]")
    bottom.set_xlabel("time [s]")
    top.legend(fontsize="small", loc="upper left")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    rows = lane_keeping.set_index("driver")["lateral_deviation_rms"]
    said = "; ".join(f"{name}: {value:.2f} m rms" for name, value in rows.items())
    caption = (
        "Closed loop on a road none of the recordings drove: the driver model steers the "
        "simulated car, beside the human (the simulator's driver) on the same road. Top: "
        "lateral deviation from the lane centre (dashed: the lane's edges); bottom: the torque "
        "each applied. "
        f"Lateral deviation {said}."
    )
    return fig, caption


def models_estimate_figure(first, models):
    """Every model's estimate against the measured torque on the first test recording."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 5))
    ax.plot(first["time"], first["measured"], color="k", lw=1.6, label="measured")
    for row in models.itertuples(index=False):
        if row.model in first:
            label = f"{row.label}: {row.accuracy:.1f} %"
            ax.plot(first["time"], first[row.model], lw=0.9, label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("driver torque [Nm]")
    ax.set_title(f"test recording {first['recording'].iloc[0]}", fontsize="medium")
    # below the axes: five lines over a torque trace leave no free corner
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    caption = (
        "Every model's estimate against the measured torque on the same test recording (in the "
        "legend: each model's mean accuracy over all test recordings): the closer a line "
        "follows the black one, the more accurate; the flatter its wiggles, the smoother."
    )
    return fig, caption
