"""Plots render to files and return their matplotlib objects."""

import numpy as np
import pandas as pd
import pytest

plt = pytest.importorskip("matplotlib.pyplot")

from skhmmgmr.plotting import (  # noqa: E402
    driver_table,
    plot_driver_comparison,
    plot_estimate,
    plot_relevance,
    plot_state_selection,
)


def test_plot_estimate_renders_band_and_states(tmp_path):
    t = np.arange(200) * 0.05
    proba = np.column_stack([np.linspace(0, 1, 200), np.linspace(1, 0, 200)])
    fig, axes = plot_estimate(
        t, np.sin(t), np.sin(t) + 0.05, std=np.full(200, 0.1), state_proba=proba, title="r1"
    )
    assert len(axes) == 2
    assert axes[0].get_title() == "r1"
    labels = [line.get_label() for line in axes[0].get_lines()]
    assert labels == ["measured", "HMM-GMR estimate"]
    assert len(axes[0].collections) == 1  # the +-2 std band
    assert len(axes[1].collections) == 2  # one stacked area per state
    path = tmp_path / "estimate.png"
    fig.savefig(path)
    assert path.stat().st_size > 10_000
    plt.close(fig)


def test_plot_estimate_without_extras():
    t = np.arange(10.0)
    fig, axes = plot_estimate(t, t, t)
    assert len(axes) == 1 and len(axes[0].collections) == 0
    plt.close(fig)


def make_selection_tables():
    features = ["steering_wheel_angle", "yaw_rate", "roll_angle"]
    labels = ["100/0", "50/50", "0/100"]
    blocks = {
        source: pd.DataFrame(
            np.arange(9).reshape(3, 3) % 4, index=features, columns=labels
        ).rename_axis(columns="trade_off")
        for source in ("exhaustive", "forward", "combined")
    }
    relevance = pd.concat(blocks, names=["source", "feature"])
    relevance.attrs["n_recordings"] = 3
    states = pd.DataFrame(
        {
            "n_states": np.repeat([1, 2, 3, 4], 2),
            "recording": ["a", "b"] * 4,
            "accuracy": [80, 82, 88, 89, 90, 90, 90.5, 90.2],
            "smoothness": [1.0, 1.1, 2.0, 2.1, 2.4, 2.5, 2.8, 2.9],
            "performance_score": [0.3, 0.3, 0.24, 0.25, 0.23, 0.24, 0.25, 0.26],
        }
    )
    bic = pd.DataFrame({"n_states": [1, 2, 3, 4], "bic": [100.0, 80.0, 75.0, 74.0]})
    test = pd.DataFrame(
        {
            "model": ["final", "baseline"] * 6,
            "recording": np.repeat(
                [f"{d}-test-s7-{i}" for d in ("defensive", "aggressive", "novice") for i in (0, 1)],
                2,
            ),
            "accuracy": np.linspace(88, 93, 12),
            "smoothness": np.linspace(1.5, 4.0, 12),
        }
    )
    return relevance, states, bic, test


def test_plot_relevance_heat_map(tmp_path):
    relevance, *_ = make_selection_tables()
    fig, ax = plot_relevance(relevance, source="forward")
    images = ax.get_images()
    assert len(images) == 1
    assert images[0].get_array().shape == (3, 3)
    assert images[0].get_clim() == (0, 3)
    assert [t.get_text() for t in ax.get_xticklabels()] == ["100/0", "50/50", "0/100"]
    assert [t.get_text() for t in ax.get_yticklabels()][1] == "yaw_rate"
    assert "forward" in ax.get_title()
    assert len(fig.axes) == 2  # heat map and colour bar
    fig.savefig(tmp_path / "relevance.png")
    assert (tmp_path / "relevance.png").stat().st_size > 5_000
    plt.close(fig)
    fig, ax = plot_relevance(relevance)
    assert ax.get_images()[0].get_clim() == (0, 6)  # combined: both wrappers' recordings
    plt.close(fig)
    with pytest.raises(ValueError, match="source="):
        plot_relevance(relevance, source="nope")


def test_plot_state_selection_marks_chosen_k(tmp_path):
    _, states, bic, _ = make_selection_tables()
    fig, axes = plot_state_selection(states, bic=bic, n_states=3)
    assert len(axes) == 4
    labels = [ax.get_ylabel() for ax in axes]
    assert labels[0] == "accuracy [%]" and labels[3] == "BIC (training)"
    for ax in axes:
        curve, marker = ax.get_lines()
        assert list(curve.get_xdata()) == [1, 2, 3, 4]
        assert list(marker.get_xdata()) == [3, 3]
    np.testing.assert_allclose(axes[0].get_lines()[0].get_ydata()[0], 81.0)
    assert axes[-1].get_xlabel() == "number of states K"
    fig.savefig(tmp_path / "states.png")
    assert (tmp_path / "states.png").stat().st_size > 10_000
    plt.close(fig)
    fig, axes = plot_state_selection(states)
    assert len(axes) == 3 and len(fig.axes) == 3
    assert all(len(ax.get_lines()) == 1 for ax in axes)
    plt.close(fig)


def test_plot_driver_comparison_grouped_bars(tmp_path):
    *_, test = make_selection_tables()
    fig, axes = plot_driver_comparison(test, labels={"final": "final (2 features)"})
    assert len(axes) == 2
    for ax in axes:
        assert len(ax.patches) == 6  # 3 drivers x 2 models
        assert [t.get_text() for t in ax.get_xticklabels()] == ["defensive", "aggressive", "novice"]
    assert axes[1].get_ylabel() == "smoothness [Nm/s]"
    handles, legend = axes[0].get_legend_handles_labels()
    assert legend == ["final (2 features)", "baseline"]
    heights = [p.get_height() for p in axes[1].patches]
    np.testing.assert_allclose(heights[0], test["smoothness"].iloc[[0, 2]].mean())
    fig.savefig(tmp_path / "drivers.png")
    assert (tmp_path / "drivers.png").stat().st_size > 5_000
    plt.close(fig)


def test_driver_table_mapping():
    *_, test = make_selection_tables()
    table = driver_table(test, drivers=lambda r: r[:3])
    assert set(table["driver"]) == {"def", "agg", "nov"}
