"""Plots render to files and return their matplotlib objects."""

import numpy as np
import pytest

plt = pytest.importorskip("matplotlib.pyplot")

from skhmmgmr.plotting import plot_estimate  # noqa: E402


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
