"""Plots of estimates, feature relevance, state selection and per-driver results.

Needs the ``plot`` extra (matplotlib), imported only when a plot is drawn. The arguments are
checked before it is, against the constraints of every function (scikit-learn's
``validate_params``).
"""

from numbers import Integral

import numpy as np
import pandas as pd

from ._core._compat import HasMethods, Interval, validate_params

__all__ = [
    "driver_table",
    "plot_driver_comparison",
    "plot_estimate",
    "plot_relevance",
    "plot_state_selection",
]


# matplotlib's figure size in inches: a pair of numbers
FIGSIZE = [tuple, list]
AXES = [HasMethods(["imshow", "plot"]), None]
# A recording id -> driver mapping or function
DRIVERS = [dict, callable, None]


def _pyplot():
    try:
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "skhmmgmr.plotting needs matplotlib: pip install 'skhmmgmr[plot]'"
        ) from exc
    return plt


@validate_params(
    {
        "time": ["array-like"],
        "measured": ["array-like"],
        "estimate": ["array-like"],
        "std": ["array-like", None],
        "state_proba": ["array-like", None],
        "torque_unit": [str],
        "title": [str, None],
        "figsize": FIGSIZE,
    },
    prefer_skip_nested_validation=True,
)
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


def _relevance_block(relevance, source):
    if isinstance(relevance.index, pd.MultiIndex):
        sources = relevance.index.get_level_values(0).unique()
        if source not in sources:
            raise ValueError(f"source={source!r} is not in the relevance table: {list(sources)}")
        return relevance.xs(source, level=0)
    return relevance


@validate_params(
    {
        "relevance": [pd.DataFrame],
        "source": [str],
        "n_recordings": [Interval(Integral, 1, None, closed="left"), None],
        "ax": AXES,
        "cmap": [str, callable],
    },
    prefer_skip_nested_validation=True,
)
def plot_relevance(relevance, *, source="combined", n_recordings=None, ax=None, cmap="viridis"):
    """Feature relevance over the accuracy/smoothness trade-offs as a heat map (thesis Fig. 4).

    Parameters
    ----------
    relevance : pandas.DataFrame
        Counts, one row per feature and one column per trade-off, as returned by
        :func:`~skhmmgmr.selection.feature_relevance`, or the ``relevance`` table of a
        :class:`~skhmmgmr.selection.SelectionReport` (rows ``(source, feature)``).
    source : str, default="combined"
        Block of a ``(source, feature)`` table to draw: "exhaustive", "forward" or "combined".
    n_recordings : int, default=None
        Upper end of the colour scale; default ``relevance.attrs["n_recordings"]`` (doubled for
        "combined"), else the largest count.
    ax : matplotlib.axes.Axes, default=None
        Axes to draw on; a new figure when None.
    cmap : str, default="viridis"

    Returns
    -------
    fig : matplotlib.figure.Figure
    ax : matplotlib.axes.Axes

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.plotting import plot_relevance
    >>> counts = pd.DataFrame({"100/0": [3, 1], "0/100": [0, 2]}, index=["swa", "yaw_rate"])
    >>> fig, ax = plot_relevance(counts)
    >>> len(ax.get_images())
    1
    """
    plt = _pyplot()
    block = _relevance_block(relevance, source)
    counts = block.to_numpy(dtype=float)
    if n_recordings is None:
        n_recordings = relevance.attrs.get("n_recordings")
        if n_recordings is not None and source == "combined" and block is not relevance:
            n_recordings = 2 * n_recordings
    vmax = n_recordings or max(counts.max(), 1.0)
    if ax is None:
        fig, ax = plt.subplots(figsize=(4.0 + 0.5 * counts.shape[1], 1.5 + 0.28 * len(block)))
    else:
        fig = ax.figure
    image = ax.imshow(counts, aspect="auto", cmap=cmap, vmin=0, vmax=vmax)
    ax.set_xticks(range(counts.shape[1]), [str(c) for c in block.columns], rotation=45)
    ax.set_yticks(range(len(block)), [str(f) for f in block.index])
    ax.set_xlabel("accuracy/smoothness trade-off [%]")
    ax.set_title(f"feature relevance ({source})" if block is not relevance else "feature relevance")
    fig.colorbar(image, ax=ax, label="count over validation recordings")
    fig.tight_layout()
    return fig, ax


@validate_params(
    {
        "states": [pd.DataFrame],
        "bic": [pd.DataFrame, None],
        "n_states": [Interval(Integral, 1, None, closed="left"), None],
        "figsize": FIGSIZE,
    },
    prefer_skip_nested_validation=True,
)
def plot_state_selection(states, *, bic=None, n_states=None, figsize=(9, 6)):
    """Accuracy, smoothness and performance score against K, with BIC (thesis Fig. 8).

    Parameters
    ----------
    states : pandas.DataFrame
        One row per (K, validation recording) with columns ``n_states``, ``accuracy``,
        ``smoothness`` and ``performance_score``: the ``states`` table of a
        :class:`~skhmmgmr.selection.SelectionReport`. Means over recordings are drawn.
    bic : pandas.DataFrame, default=None
        Columns ``n_states`` and ``bic`` (the report's ``bic`` table); adds a fourth panel.
    n_states : int, default=None
        Chosen K, marked by a vertical dashed line on every panel.
    figsize : tuple, default=(9, 6)

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of matplotlib.axes.Axes
        Three panels, four with ``bic``.

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.plotting import plot_state_selection
    >>> states = pd.DataFrame({
    ...     "n_states": [1, 2, 3], "accuracy": [80.0, 88.0, 89.0],
    ...     "smoothness": [2.0, 2.5, 2.6], "performance_score": [0.4, 0.3, 0.31],
    ... })
    >>> fig, axes = plot_state_selection(states, n_states=2)
    >>> len(axes)
    3
    """
    plt = _pyplot()
    panels = [
        ("accuracy", "accuracy [%]"),
        ("smoothness", "smoothness [Nm/s]"),
        ("performance_score", "performance score\n(lower is better)"),
    ]
    if bic is not None:
        panels.append(("bic", "BIC (training)"))
    fig, axes = plt.subplots(2, 2, sharex=True, figsize=figsize, squeeze=False)
    axes = axes.ravel()
    means = states.groupby("n_states")[[c for c, _ in panels[:3]]].mean()
    for ax, (column, label) in zip(axes, panels, strict=False):
        table = bic.set_index("n_states")["bic"] if column == "bic" else means[column]
        ax.plot(table.index, table.to_numpy(), marker="o", color="tab:blue", label=label)
        ax.set_ylabel(label)
        if n_states is not None:
            ax.axvline(n_states, color="tab:red", ls="--", lw=1, label=f"chosen K={n_states}")
        ax.grid(alpha=0.3)
    if bic is None:
        axes[3].remove()
        axes = axes[:3]
    for ax in axes[-2:]:
        ax.set_xlabel("number of states K")
        ax.xaxis.set_tick_params(labelbottom=True)
    axes[0].legend(loc="lower right", fontsize="small")
    fig.suptitle("state selection (means over validation recordings)")
    fig.tight_layout()
    return fig, axes


@validate_params(
    {
        "test": [pd.DataFrame],
        "drivers": DRIVERS,
        "models": [tuple, list],
        "labels": [dict, None],
        "figsize": FIGSIZE,
    },
    prefer_skip_nested_validation=True,
)
def plot_driver_comparison(
    test, *, drivers=None, models=("final", "baseline"), labels=None, figsize=(9, 4)
):
    """Per-driver accuracy and smoothness of the final model against the baseline (Fig. 9).

    Parameters
    ----------
    test : pandas.DataFrame
        One row per (model, test recording) with columns ``model``, ``recording``,
        ``accuracy`` and ``smoothness`` (the ``test`` table of a
        :class:`~skhmmgmr.selection.SelectionReport`), and optionally ``driver``.
    drivers : dict or callable, default=None
        Recording id -> driver; default: the ``driver`` column, else the recording id up to its
        first "-" (the simulator's ``"defensive-test-s7-0"`` naming).
    models : sequence of str, default=("final", "baseline")
        Models to draw, one bar per driver and model.
    labels : dict, default=None
        Model -> legend label.
    figsize : tuple, default=(9, 4)

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of matplotlib.axes.Axes
        Accuracy and smoothness panels; bars are means over the driver's test recordings with
        their standard deviation as error bars.

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.plotting import plot_driver_comparison
    >>> test = pd.DataFrame({
    ...     "model": ["final", "baseline"] * 2, "recording": ["a-1", "a-1", "b-1", "b-1"],
    ...     "accuracy": [90.0, 91.0, 88.0, 89.0], "smoothness": [2.0, 3.0, 2.5, 3.5],
    ... })
    >>> fig, axes = plot_driver_comparison(test)
    >>> len(axes[0].patches)
    4
    """
    plt = _pyplot()
    table = driver_table(test, drivers=drivers)
    table = table[table["model"].isin(models)]
    names = list(dict.fromkeys(table["driver"]))
    stats = table.groupby(["driver", "model"])[["accuracy", "smoothness"]].agg(["mean", "std"])
    labels = {**{m: m for m in models}, **(labels or {})}
    fig, axes = plt.subplots(1, 2, figsize=figsize)
    width = 0.8 / len(models)
    positions = np.arange(len(names))
    for ax, (metric, unit) in zip(axes, (("accuracy", "%"), ("smoothness", "Nm/s")), strict=True):
        for m, model in enumerate(models):
            rows = [(d, model) for d in names]
            mean = stats[(metric, "mean")].reindex(rows).to_numpy()
            std = stats[(metric, "std")].reindex(rows).fillna(0.0).to_numpy()
            ax.bar(
                positions + (m - (len(models) - 1) / 2) * width,
                mean,
                width,
                yerr=std,
                capsize=3,
                label=labels[model],
            )
        ax.set_xticks(positions, names)
        ax.set_ylabel(f"{metric} [{unit}]")
        ax.set_title(f"test {metric} per driver")
        ax.grid(axis="y", alpha=0.3)
    accuracy = table["accuracy"]
    if len(accuracy) and accuracy.min() > 50:
        # accuracies sit near 90 %; a zero-based axis hides the differences
        axes[0].set_ylim(max(accuracy.min() - 5, 0), min(accuracy.max() + 3, 100))
    axes[0].legend(loc="lower right", fontsize="small")
    fig.tight_layout()
    return fig, axes


@validate_params({"test": [pd.DataFrame], "drivers": DRIVERS}, prefer_skip_nested_validation=True)
def driver_table(test, *, drivers=None):
    """The test table with a ``driver`` column (see :func:`plot_driver_comparison`).

    Examples
    --------
    >>> import pandas as pd
    >>> from skhmmgmr.plotting import driver_table
    >>> driver_table(pd.DataFrame({"recording": ["novice-test-s7-0"]}))["driver"].tolist()
    ['novice']
    """
    table = test.copy()
    if drivers is not None:
        mapper = drivers.get if isinstance(drivers, dict) else drivers
        table["driver"] = [mapper(r) for r in table["recording"]]
    elif "driver" not in table.columns:
        table["driver"] = [str(r).split("-")[0] for r in table["recording"]]
    return table
