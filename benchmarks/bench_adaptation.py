"""Adapting a generic model to a new driver in minutes: ``HMMGMRRegressor.adapt`` benchmark.

Protocol (simulator, measured sensors, 20 Hz, sections of one minute):

- a population of simulated drivers: every driver draws its own parameters around one of the
  three styles (each :class:`~skhmmgmr.datasets.DriverParameters` field times a log-normal
  factor of spread ``--spread``, truncated at two spreads), and every recording draws its own
  around the driver's (the style's per-recording variability), so drivers of one style differ;
- a generic model is fitted on ``--generic-drivers`` drivers (styles in turn), six training
  minutes each (settings 1-6 of the thesis protocol);
- every held-out driver (``--held-out`` of them, styles in turn) drives 60 training minutes
  (settings 1-6 in turn) and three 2-minute test sections on setting 7. Adaptation data: its
  first 1, 2, 5 and 10 training minutes. Compared on its test sections: the generic model;
  the generic model adapted to those minutes; a model fitted from scratch on the same minutes;
  the generic model's FilterStream adapting its means online over those minutes; a
  driver-specific model fitted on all 60 minutes;
- the adaptation settings (which parameters, relevance factors) are chosen beforehand on two
  validation drivers (their own 2 adaptation minutes and 2-minute validation sections on
  setting 7), never on the test sections of the held-out drivers.

Reported per number of minutes: mean test accuracy over the held-out drivers (every driver's
accuracy is the mean over its test sections, :func:`skhmmgmr.metrics.accuracy_score`), the
worst driver's, and the mean roughness (:func:`skhmmgmr.metrics.smoothness_score`, Nm/s, lower
is smoother), and the goals at 2 minutes. Run with::

    nice python benchmarks/bench_adaptation.py --plot docs/_static/adaptation_minutes.png
    nice python benchmarks/bench_adaptation.py --quick  # smaller protocol, 1-2 minutes

The full run takes about 5 minutes on 2 cores (3 of them simulating 750 minutes of driving).
"""

import argparse
import copy
import math
import time
import warnings
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pandas as pd

# The five features of the torque-ahead benchmark: angle, yaw rate, lateral deviation and the
# road preview (heading deviation and curvature 30 m ahead).
from bench_ahead import FEATURES
from joblib import Parallel, delayed
from sklearn.exceptions import ConvergenceWarning

from skhmmgmr import HMMGMRRegressor
from skhmmgmr.datasets import DRIVER_STYLES, make_lane_keeping
from skhmmgmr.metrics import accuracy_score, smoothness_score

RATE = 20.0
SECTION = 60.0  # [s] one training section: one minute
TEST_SECTION = 120.0  # [s] test and validation sections
STYLES = ("defensive", "aggressive", "novice")
VALIDATION_STYLES = ("aggressive", "novice")
RELEVANCES = (4.0, 16.0, 64.0, 256.0, 1024.0)
CANDIDATES = [(p, r) for p in ("m", "mv", "mvt") for r in RELEVANCES]
PLOT = Path(__file__).resolve().parents[1] / "docs" / "_static" / "adaptation_minutes.png"


def draw_driver(style, spread, rng):
    """One driver of a style: every parameter but the per-recording variability times a
    log-normal factor of spread ``spread`` (truncated at 2 spreads); a draw that loses control
    of the car in three trial minutes (settings 1, 1 and 7) is drawn again."""
    base = DRIVER_STYLES[style]
    while True:
        changes = {
            field.name: getattr(base, field.name)
            * math.exp(spread * np.clip(rng.standard_normal(), -2.0, 2.0))
            for field in fields(base)
            if field.name != "variability"
        }
        parameters = replace(base, **changes)
        try:
            for setting in (1, 1, 7):
                seed = int(rng.integers(2**31 - 1))
                make_lane_keeping(
                    SECTION,
                    setting=setting,
                    driver=parameters,
                    sampling_rate=RATE,
                    random_state=seed,
                )
        except RuntimeError:  # lost control
            continue
        return parameters


def simulate(name, parameters, sections, seed, vehicle=None):
    """Recordings of one driver in ``vehicle`` (None: the reference car): ``sections`` is a
    list of (split, setting, duration)."""
    rng = np.random.default_rng(seed)
    frames = []
    for i, (split, setting, duration) in enumerate(sections):
        for attempt in range(10):  # a recording that loses control is driven again
            try:
                frame = make_lane_keeping(
                    duration,
                    setting=setting,
                    driver=parameters,
                    sampling_rate=RATE,
                    random_state=int(rng.integers(2**31 - 1)),
                    recording=f"{name}-{split}-{i:02d}",
                    split=split,
                    vehicle=vehicle,
                )
                break
            except RuntimeError:
                if attempt == 9:
                    raise
        frames.append(frame.assign(driver=name))
    return pd.concat(frames, ignore_index=True)


def training_sections(n_minutes):
    return [("train", 1 + i % 6, SECTION) for i in range(n_minutes)]


def arrays(frame):
    return (
        frame[FEATURES].to_numpy(),
        frame["driver_torque"].to_numpy(),
        frame["recording"].to_numpy(),
    )


def first_minutes(frame, n_minutes):
    train = frame[frame["split"] == "train"]
    kept = list(dict.fromkeys(train["recording"]))[:n_minutes]
    return arrays(train[train["recording"].isin(kept)])


def scores(model, test):
    X, y, groups = test
    estimate = model.predict(X, groups=groups)
    accuracy = accuracy_score(y, estimate, groups=groups)
    roughness = smoothness_score(estimate, sampling_period=1.0 / RATE, groups=groups)
    return accuracy, roughness


def fit(data, n_states, seed):
    return HMMGMRRegressor(n_states=n_states, random_state=seed).fit(*data)


def adapted(generic, data, parameters, relevance):
    return copy.deepcopy(generic).adapt(*data, parameters=parameters, relevance=relevance)


def online(generic, data, relevance):
    """The generic model's FilterStream adapting its means online over the recordings of
    ``data`` (restarting the filter at every recording), as a fitted estimator."""
    X, y, groups = data
    stream = generic.filter_stream(relevance=relevance)
    for recording in dict.fromkeys(groups):
        rows = groups == recording
        stream.reset().update_batch(X[rows], y=y[rows])
    return HMMGMRRegressor.from_fitted_model(stream.adapted_model())


def best(rows):
    """The settings of the best validation accuracy (to 0.1 point; ties: smoother)."""
    return min(rows, key=lambda row: (-round(row[-2], 1), row[-1]))[:-2]


def choose_settings(generic, validation, minutes):
    """Adaptation settings with the best mean validation accuracy (ties: smoother): the
    parameters and relevance of ``adapt``, and the relevance of online adaptation."""
    accuracy, roughness = np.mean([scores(generic, test) for _, test in validation], axis=0)
    print(f"  validation  generic             {accuracy:6.2f} %  {roughness:5.2f} Nm/s")
    rows = []
    for parameters, relevance in CANDIDATES:
        results = [
            scores(adapted(generic, first_minutes(frame, minutes), parameters, relevance), test)
            for frame, test in validation
        ]
        accuracy, roughness = np.mean(results, axis=0)
        rows.append((parameters, relevance, accuracy, roughness))
        print(
            f"  validation  adapt {parameters!r:<6} r={relevance:<6g} {accuracy:6.2f} %  "
            f"{roughness:5.2f} Nm/s"
        )
    online_rows = []
    for relevance in RELEVANCES:
        results = [
            scores(online(generic, first_minutes(frame, minutes), relevance), test)
            for frame, test in validation
        ]
        online_rows.append((relevance, *np.mean(results, axis=0)))
        print(
            f"  validation  online        r={relevance:<6g} {online_rows[-1][1]:6.2f} %  "
            f"{online_rows[-1][2]:5.2f} Nm/s"
        )
    return (*best(rows), *best(online_rows))


def held_out_driver(name, frame, generic, settings, minutes, n_states, seed):
    """Scores of every model on one held-out driver's test sections."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        test = arrays(frame[frame["split"] == "test"])
        rows = [(name, "generic", 0, *scores(generic, test))]
        specific = fit(first_minutes(frame, 10**6), n_states, seed)
        rows.append((name, "specific", 0, *scores(specific, test)))
        for n_minutes in minutes:
            data = first_minutes(frame, n_minutes)
            model = adapted(generic, data, *settings[:2])
            rows.append((name, "adapted", n_minutes, *scores(model, test)))
            model = online(generic, data, settings[2])
            rows.append((name, "online", n_minutes, *scores(model, test)))
            rows.append((name, "scratch", n_minutes, *scores(fit(data, n_states, seed), test)))
    return rows


def summary(results, minutes):
    """Per minutes: mean, worst-driver accuracy and mean roughness of every model."""
    per_driver = pd.DataFrame(
        results, columns=["driver", "model", "minutes", "accuracy", "roughness"]
    )
    table = []
    for n_minutes in minutes:
        for model in ("generic", "adapted", "online", "scratch", "specific"):
            at = per_driver["minutes"] == (0 if model in ("generic", "specific") else n_minutes)
            part = per_driver[(per_driver["model"] == model) & at]
            table.append(
                (
                    n_minutes,
                    model,
                    part["accuracy"].mean(),
                    part["accuracy"].min(),
                    part["roughness"].mean(),
                )
            )
    return per_driver, pd.DataFrame(
        table, columns=["minutes", "model", "accuracy", "worst", "roughness"]
    )


def goals(table, full_minutes, n_minutes=2):
    at = table[table["minutes"] == n_minutes].set_index("model")
    adapted_, scratch, specific = (at.loc[m] for m in ("adapted", "scratch", "specific"))
    checks = [
        (
            f"{n_minutes} min adapted within 1 point of the {full_minutes}-min specific model",
            adapted_["accuracy"] >= specific["accuracy"] - 1.0,
            f"{adapted_['accuracy']:.1f} vs {specific['accuracy']:.1f}",
        ),
        (
            f"{n_minutes} min adapted >= 3 points above from scratch on the same minutes",
            adapted_["accuracy"] >= scratch["accuracy"] + 3.0,
            f"{adapted_['accuracy']:.1f} vs {scratch['accuracy']:.1f}",
        ),
        (
            "not rougher than either",
            adapted_["roughness"] <= min(scratch["roughness"], specific["roughness"]),
            f"{adapted_['roughness']:.2f} vs {scratch['roughness']:.2f} (scratch), "
            f"{specific['roughness']:.2f} (specific) Nm/s",
        ),
    ]
    for text, met, values in checks:
        print(f"[{'ok' if met else 'MISSED'}] {text}: {values}")


def plot(table, path, full_minutes):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    lines = {  # model: colour, marker (None: a horizontal reference), label
        "adapted": ("C0", "o", "adapted generic model"),
        "online": ("C3", "^", "adapted online (FilterStream, means)"),
        "scratch": ("C1", "s", "fitted from scratch on the same minutes"),
        "generic": ("0.4", None, "generic model"),
        "specific": ("C2", None, f"driver-specific model, {full_minutes} min"),
    }
    for model, (color, marker, label) in lines.items():
        part = table[table["model"] == model]
        ls = "-" if marker else "--"
        ax.plot(part["minutes"], part["accuracy"], ls, color=color, marker=marker, label=label)
        ax.plot(
            part["minutes"],
            part["worst"],
            ":",
            color=color,
            marker=marker,
            markerfacecolor="none",
            linewidth=0.8,
        )
    ax.set_xscale("log")
    ax.minorticks_off()
    ax.set_xticks(sorted(table["minutes"].unique()))
    ax.set_xticklabels([f"{m:g}" for m in sorted(table["minutes"].unique())])
    ax.set_xlabel("minutes of the new driver")
    ax.set_ylabel("test accuracy [%]")
    ax.set_title("Mean over held-out drivers (dotted: worst driver)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"plot written to {path}")


def run(args):
    rng = np.random.default_rng(args.seed)
    seeds = iter(rng.integers(2**31 - 1, size=1000).tolist())
    jobs = []
    for i in range(args.generic_drivers):
        style = STYLES[i % len(STYLES)]
        parameters = draw_driver(style, args.spread, rng)
        jobs.append((f"generic{i:02d}-{style}", parameters, training_sections(6), next(seeds)))
    validation_names = []
    for i, style in enumerate(VALIDATION_STYLES):
        parameters = draw_driver(style, args.spread, rng)
        sections = training_sections(2) + [("test", 7, TEST_SECTION)] * 2
        validation_names.append(f"validation{i}-{style}")
        jobs.append((validation_names[-1], parameters, sections, next(seeds)))
    held_out_names = []
    for i in range(args.held_out):
        style = STYLES[i % len(STYLES)]
        parameters = draw_driver(style, args.spread, rng)
        sections = training_sections(args.full_minutes) + [("test", 7, TEST_SECTION)] * 3
        held_out_names.append(f"driver{i}-{style}")
        jobs.append((held_out_names[-1], parameters, sections, next(seeds)))
    start = time.perf_counter()
    frames = Parallel(n_jobs=args.n_jobs)(delayed(simulate)(*job) for job in jobs)
    frames = {job[0]: frame for job, frame in zip(jobs, frames, strict=True)}
    print(
        f"simulated {sum(len(f) for f in frames.values()) / RATE / 60:.0f} minutes of "
        f"{len(frames)} drivers in {time.perf_counter() - start:.0f} s"
    )

    start = time.perf_counter()
    generic_data = pd.concat(
        [frame for name, frame in frames.items() if name.startswith("generic")]
    )
    generic = fit(arrays(generic_data), args.n_states, args.seed)
    print(
        f"generic model: {len(generic_data) / RATE / 60:.0f} minutes of "
        f"{args.generic_drivers} drivers, fitted in {time.perf_counter() - start:.0f} s"
    )

    validation = []
    for name in validation_names:
        frame = frames[name]
        validation.append((frame, arrays(frame[frame["split"] == "test"])))
    settings = choose_settings(generic, validation, minutes=2)
    print(
        f"chosen on the validation drivers: adapt parameters={settings[0]!r}, "
        f"relevance={settings[1]:g}; online relevance={settings[2]:g}"
    )

    start = time.perf_counter()
    per_driver = Parallel(n_jobs=args.n_jobs)(
        delayed(held_out_driver)(
            name, frames[name], generic, settings, args.minutes, args.n_states, args.seed
        )
        for name in held_out_names
    )
    print(f"held-out drivers scored in {time.perf_counter() - start:.0f} s")
    per_driver, table = summary([row for rows in per_driver for row in rows], args.minutes)
    with pd.option_context(
        "display.width", 200, "display.max_columns", None, "display.float_format", "{:.2f}".format
    ):
        print("\nPer held-out driver (accuracy [%], roughness [Nm/s]):")
        print(
            per_driver.pivot_table(
                index=["model", "minutes"], columns="driver", values="accuracy"
            ).round(1)
        )
        print(
            f"\nMean over {args.held_out} held-out drivers (worst: the worst driver's "
            f"accuracy; specific: {args.full_minutes} min):"
        )
        print(table.round(2).to_string(index=False))
    print()
    goals(table, args.full_minutes)
    if args.plot:
        plot(table, args.plot, args.full_minutes)
    return table


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick",
        action="store_true",
        help="6 generic drivers, 20-minute specific models, 1-5 minutes",
    )
    parser.add_argument("--generic-drivers", type=int, default=24)
    parser.add_argument("--held-out", type=int, default=9)
    parser.add_argument("--full-minutes", type=int, default=60)
    parser.add_argument("--minutes", nargs="+", type=int, default=[1, 2, 5, 10])
    parser.add_argument(
        "--spread",
        type=float,
        default=0.2,
        help="log-normal spread of the driver parameters around the style",
    )
    parser.add_argument("--n-states", type=int, default=5)
    parser.add_argument("--n-jobs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--plot",
        type=Path,
        default=None,
        help=f"write the figure there (e.g. {PLOT.relative_to(PLOT.parents[2])})",
    )
    args = parser.parse_args()
    if args.quick:
        args.generic_drivers, args.held_out, args.full_minutes = 6, 5, 20
        args.minutes = [1, 2, 5]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        run(args)


if __name__ == "__main__":
    main()
