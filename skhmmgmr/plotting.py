"""Plots of estimates and filtered state probabilities (needs the ``plot`` extra: matplotlib)."""

import numpy as np


def _pyplot():
    try:
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "skhmmgmr.plotting needs matplotlib: pip install 'skhmmgmr[plot]'"
        ) from exc
    return plt


def plot_estimate(
    time,
    measured,
    estimate,
    *,
    std=None,
    state_proba=None,
    torque_unit="Nm",
    title=None,
    figsize=(8, 5),
):
    """Estimated against measured torque, with a +-2 std band and the state probabilities.

    Parameters
    ----------
    time : array-like of shape (n_samples,)
        Time [s] of every sample of one recording.
    measured, estimate : array-like of shape (n_samples,)
        Measured driver torque and its estimate.
    std : array-like of shape (n_samples,), default=None
        Predictive standard deviation; draws a +-2 std band when given.
    state_proba : array-like of shape (n_samples, n_states), default=None
        Filtered state probabilities; adds a stacked panel below (thesis Fig. C.2).
    torque_unit : str, default="Nm"
    title : str, default=None
    figsize : tuple, default=(8, 5)

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of matplotlib.axes.Axes
        One or two panels (torque, then state probabilities).

    Examples
    --------
    >>> import numpy as np
    >>> from skhmmgmr.plotting import plot_estimate
    >>> t = np.arange(100) * 0.05
    >>> fig, axes = plot_estimate(t, np.sin(t), np.sin(t) + 0.1, std=np.full(100, 0.1))
    >>> len(axes)
    1
    """
    plt = _pyplot()
    time = np.asarray(time, dtype=float)
    estimate = np.asarray(estimate, dtype=float)
    n_panels = 1 if state_proba is None else 2
    fig, axes = plt.subplots(
        n_panels,
        1,
        sharex=True,
        figsize=figsize,
        squeeze=False,
        gridspec_kw={"height_ratios": [2, 1][:n_panels]},
    )
    axes = axes[:, 0]
    ax = axes[0]
    ax.plot(time, measured, color="black", lw=1, label="measured")
    ax.plot(time, estimate, color="tab:blue", lw=1, label="HMM-GMR estimate")
    if std is not None:
        band = 2.0 * np.asarray(std, dtype=float)
        ax.fill_between(
            time, estimate - band, estimate + band, color="tab:blue", alpha=0.2, label="+-2 std"
        )
    ax.set_ylabel(f"driver torque [{torque_unit}]")
    ax.legend(loc="upper right", fontsize="small")
    if title:
        ax.set_title(title)
    if state_proba is not None:
        proba = np.asarray(state_proba, dtype=float)
        axes[1].stackplot(
            time, proba.T, labels=[f"state {k}" for k in range(proba.shape[1])], alpha=0.85
        )
        axes[1].set_ylim(0, 1)
        axes[1].set_ylabel("filtered state\nprobability")
        axes[1].legend(loc="upper right", fontsize="x-small", ncol=min(proba.shape[1], 5))
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    return fig, axes
