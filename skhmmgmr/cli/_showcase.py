"""The package beyond the framework, on the framework's split: what to use for what.

Beside the framework's selected model and its all-feature baseline (:mod:`._framework`), the
report fits, on the same training recordings, and scores on the same test recordings:

- the torque pipeline (:func:`~skhmmgmr.make_torque_pipeline`), the package's most accurate
  estimate of the recorded torque, and gradient boosting (scikit-learn's
  ``HistGradientBoostingRegressor``, defaults) on the same features, the usual yardstick;
- the driver model, the model meant to drive (:func:`driver_model`);

and, on the simulator only, puts the driver model at the wheel of a road none of the
recordings drove, beside the human
(:func:`~skhmmgmr.datasets.drive`). A part whose columns the data lack is left out, and the
report says which columns it needs.
"""

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from sklearn.base import clone
from threadpoolctl import threadpool_limits

from .._core._progress import progress_bar
from .._core._schema import (
    DRIVER_MODEL_FEATURES,
    RECORDING,
    SPLIT,
    STEERING_PERTURBATION,
    TARGET,
    TIME,
)
from ._answers import counted

#: The road of the closed loop: a seed none of the protocol's sections draws (they draw theirs
#: from the run's seed), the evaluation setting, one minute.
CLOSED_LOOP_ROAD = dict(setting=7, duration=60.0)
CLOSED_LOOP_SEED = 90_001
#: Columns the torque pipeline's derived inputs read (its steering load and friction).
TORQUE_PIPELINE_COLUMNS = (
    "steering_wheel_angle",
    "steering_wheel_velocity",
    "lateral_acceleration",
)
TORQUE_PIPELINE_STATES = 5


@dataclass
class Candidate:
    """One model of the report, fitted on the training recordings.

    ``key`` names its files and table rows; ``estimate``/``std`` are its outputs on the test
    rows (``std`` None for a model without one).
    """

    key: str
    label: str
    use: str
    model: object
    features: list
    saved: bool
    estimate: np.ndarray = field(repr=False, default=None)
    std: np.ndarray = field(repr=False, default=None)
    #: rows it is fitted on when they are not the framework's training rows
    training: pd.DataFrame = field(repr=False, default=None)


@dataclass
class Showcase:
    """The report's models, their test table and closed loop, and the parts left out."""

    candidates: dict
    test: pd.DataFrame
    notes: dict = field(default_factory=dict)
    #: the first test recording: ``time``, the measured torque and every model's estimate
    first: pd.DataFrame = None
    drives: dict = field(default_factory=dict)
    lane_keeping: pd.DataFrame = None


#: The demo's perturbation experiment for the driver model: the default experiment of
#: :func:`~skhmmgmr.make_driver_model` (0.2 Nm RMS in a third of the training recordings).
DRIVER_EXPERIMENT = dict(perturbation=0.2, perturbed_share=1 / 3)


def driver_model(seed, *, sampling_period):
    """The model meant to drive: ``(label, estimator, features, how it is made)``."""
    from ..torque_pipeline import make_driver_model

    label = "driver model (torque pipeline fitted on a perturbation experiment, K=1)"
    made = (
        "make_driver_model() on the sensed features but the wheel's acceleration, fitted on "
        "the training sections of which a third carried a 0.2 Nm RMS torque on the wheel "
        "that the driver did not know (make_driving_protocol(perturbation=0.2, "
        "perturbed_share=1/3)), so that it leans less on the wheel's own response"
    )
    model = make_driver_model(sampling_period=sampling_period, random_state=seed)
    return label, model, list(DRIVER_MODEL_FEATURES), made


def _missing(columns, available):
    return [c for c in columns if c not in available]


def _fit(candidate, train, groups=True):
    if candidate.training is not None:
        train = candidate.training
    X = train[candidate.features]
    if candidate.key == "driver_model":
        candidate.model.fit(
            X, train[TARGET], groups=train[RECORDING], perturbation=train[STEERING_PERTURBATION]
        )
    elif groups:
        candidate.model.fit(X, train[TARGET], groups=train[RECORDING])
    else:
        with threadpool_limits(limits=1):  # OpenMP threads on a small fit only spin
            candidate.model.fit(X, train[TARGET])
    return candidate


def _predict(candidate, test):
    X = test[candidate.features]
    if candidate.key == "gradient_boosting":
        candidate.estimate = candidate.model.predict(X)
        return candidate
    candidate.estimate, candidate.std = candidate.model.predict(
        X, groups=test[RECORDING], return_std=True
    )
    return candidate


def framework_candidates(report, train, test):
    """The selected model (refitted on named columns, so that its files carry the feature
    names; the same fit as the framework's) and the baseline."""
    selected = Candidate(
        "selected_model",
        f"selected model ({counted(len(report.features), 'feature')}, K={report.n_states})",
        "the thesis' model: few sensors, a smooth estimate, states to read",
        clone(report.final_model),
        list(report.features),
        saved=True,
    )
    baseline = list(report.candidates.loc[report.candidates["name"] == "Baseline", "features"])[0]
    base = Candidate(
        "baseline",
        f"all-feature baseline ({counted(len(baseline), 'feature')}, K={report.n_states})",
        "the reference the selection is measured against",
        report.baseline_model,
        list(baseline),
        saved=False,
    )
    _predict(_fit(selected, train), test)
    base.estimate, base.std = report.baseline_model.predict(
        test[base.features].to_numpy(dtype=float), groups=test[RECORDING], return_std=True
    )
    return selected, base


def other_candidates(features, columns, *, sampling_period, seed, experiment=None):
    """The torque pipeline, gradient boosting and the driver model (unfitted), and a note
    for each left out for want of columns. ``experiment``: the training rows of a
    perturbation experiment, which the driver model is fitted on (left out without)."""
    from sklearn.ensemble import HistGradientBoostingRegressor

    from ..torque_pipeline import make_torque_pipeline

    found, notes = [], {}
    missing = _missing(TORQUE_PIPELINE_COLUMNS, features)
    if missing:
        notes["torque_pipeline"] = (
            f"The torque pipeline is left out: its derived inputs (steering load and friction) "
            f"read the columns {list(TORQUE_PIPELINE_COLUMNS)}; the candidate features lack "
            f"{missing}."
        )
    else:
        pipeline = make_torque_pipeline(
            TORQUE_PIPELINE_STATES, sampling_period=sampling_period, random_state=seed
        )
        found.append(
            Candidate(
                "torque_pipeline",
                f"torque pipeline ({counted(len(features), 'feature')} + derived steering inputs, "
                f"K={TORQUE_PIPELINE_STATES})",
                "the most accurate estimate of the recorded torque, for assistance and observers "
                "(it estimates; it is no driver: at the wheel it does not keep a lane)",
                pipeline,
                list(features),
                saved=True,
            )
        )
    found.append(
        Candidate(
            "gradient_boosting",
            f"gradient boosting ({counted(len(features), 'feature')})",
            "the usual yardstick (scikit-learn's HistGradientBoostingRegressor, defaults)",
            HistGradientBoostingRegressor(random_state=seed),
            list(features),
            saved=False,
        )
    )
    label, model, inputs, made = driver_model(seed, sampling_period=sampling_period)
    missing = _missing(inputs, columns)
    if missing:
        notes["driver_model"] = (
            f"The driver model is left out: it reads the columns {inputs}; the data lack {missing}."
        )
    elif experiment is None:
        notes["driver_model"] = (
            "The driver model is left out: it is fitted on recordings of a perturbation "
            f"experiment (a column {STEERING_PERTURBATION!r}, the torque in Nm that the "
            "experiment put on the steering wheel, 0 where there was none; "
            "skhmmgmr.datasets.make_driving_protocol(perturbation=...) simulates one), and the "
            "training recordings have none."
        )
    else:
        found.append(
            Candidate(
                "driver_model",
                label,
                "a driver at the wheel of a simulator: " + made,
                model,
                inputs,
                saved=True,
                training=experiment,
            )
        )
    return found, notes


def score_on_test(candidates, test, *, sampling_period):
    """Per-recording rmse, accuracy and smoothness of every model on the test recordings,
    from the estimates of the models the report holds (and saves)."""
    from ..metrics import evaluate_recordings

    frames = []
    for candidate in candidates.values():
        table = evaluate_recordings(
            test[TARGET].to_numpy(dtype=float),
            candidate.estimate,
            groups=test[RECORDING].to_numpy(),
            sampling_period=sampling_period,
        )
        frames.append(table.assign(model=candidate.key))
    table = pd.concat(frames, ignore_index=True)
    return table[["model", "recording", "n_samples", "rmse", "accuracy", "smoothness"]]


def models_table(showcase):
    """Mean test metrics of every model, in the report's order, with what each is for."""
    grouped = showcase.test.groupby("model", sort=False)
    means = grouped[["rmse", "accuracy", "smoothness"]].mean()
    rows = []
    for key, candidate in showcase.candidates.items():
        rows.append(
            {
                "model": key,
                "label": candidate.label,
                "use": candidate.use,
                "n_inputs": len(candidate.features),
                "n_recordings": grouped.size().loc[key],
                **means.loc[key].to_dict(),
            }
        )
    return pd.DataFrame(rows)


def run_showcase(report, data, *, sampling_period, seed, experiment=None):
    """Every model of the report fitted on the training rows and scored on the test rows.

    The driver model is fitted on the training rows of ``experiment`` (a perturbation
    experiment: the demo simulates one on the same training sections), else on those of
    ``data`` when they carry the perturbation's column, else left out with a note. The
    models beyond the framework's count as the steps of the caller's progress stage
    (:func:`~skhmmgmr._core._progress.progress_bar`).
    """
    train, test = split_rows(data)
    if experiment is not None:
        experiment = split_rows(experiment)[0]
    elif STEERING_PERTURBATION in data.columns:
        experiment = train
    selected, baseline = framework_candidates(report, train, test)
    others, notes = other_candidates(
        list(baseline.features),
        data.columns,
        sampling_period=sampling_period,
        seed=seed,
        experiment=experiment,
    )
    candidates = {c.key: c for c in (selected, baseline)}
    for candidate in progress_bar(others, total=len(others), desc="models"):
        groups = candidate.key != "gradient_boosting"
        _predict(_fit(candidate, train, groups=groups), test)
        candidates[candidate.key] = candidate
    table = score_on_test(candidates, test, sampling_period=sampling_period)
    # the recording of the framework's estimate figure: the first test recording of the data
    rows = (test[RECORDING] == data.loc[data[SPLIT] == "test", RECORDING].iloc[0]).to_numpy()
    first = pd.DataFrame(
        {
            "recording": test[RECORDING].to_numpy()[rows],
            "time": np.arange(rows.sum()) * sampling_period
            if TIME not in test
            else test[TIME].to_numpy()[rows],
            "measured": test[TARGET].to_numpy()[rows],
            **{key: c.estimate[rows] for key, c in candidates.items()},
        }
    )
    return Showcase(candidates=candidates, test=table, notes=notes, first=first)


def closed_loop(candidates, human, *, sampling_rate, seed):
    """The driver model at the wheel of a held-out road, beside the human style ``human``:
    the drives and their lane-keeping metrics.

    Only the model meant to drive is put at the wheel: a regression of the recorded torque on
    the car's own states (the torque pipeline, the selected model) estimates well and steers
    badly (the user guide's "The driver model at the wheel").
    """
    from ..datasets import drive
    from ..metrics import lane_keeping_metrics

    road = dict(CLOSED_LOOP_ROAD, sampling_rate=sampling_rate, random_state=CLOSED_LOOP_SEED + seed)
    drives = {f"human ({human})": drive(human, **road)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a model that leaves the road: in the table
        drives[candidates["driver_model"].label] = drive(candidates["driver_model"].model, **road)
    rows = []
    for name, frame in drives.items():
        metrics = lane_keeping_metrics(frame)
        lost = frame.attrs.get("lost_control")
        rows.append({"driver": name, **metrics.to_dict(), "lost_control_at": lost})
    return drives, pd.DataFrame(rows)


def split_rows(data):
    """The training and test rows of the tidy table, each recording's rows in time order."""
    train = data[data[SPLIT] == "train"]
    test = data[data[SPLIT] == "test"]
    if TIME in data.columns:
        train = train.sort_values([RECORDING, TIME], kind="stable")
        test = test.sort_values([RECORDING, TIME], kind="stable")
    return train, test
