"""Tests of the driver model (``make_driver_model``) and of the closed-loop scorer."""

import math
import warnings

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.model_selection import GridSearchCV, GroupKFold

from skhmmgmr import PerformanceScore, make_driver_model, make_torque_pipeline, portable
from skhmmgmr.datasets import (
    DRIVER_MODEL_FEATURES,
    FEATURE_NAMES,
    PREVIEW_FEATURES,
    drive,
    make_driving_protocol,
    torque_ahead,
)
from skhmmgmr.metrics import lane_keeping_metrics
from skhmmgmr.selection import ClosedLoopScorer, make_closed_loop_scorer
from skhmmgmr.torque_pipeline import DriverModel

FEATURES = list(DRIVER_MODEL_FEATURES)
SENSED = list(FEATURE_NAMES)  # what the simulator hands a driver
PERTURBATION = "steering_perturbation"
RATE = 20.0


@pytest.fixture(scope="module")
def protocol():
    """Six perturbed training sections and one test section of 30 s at 20 Hz."""
    return make_driving_protocol(
        ("defensive",),
        n_train_per_setting=1,
        n_validation=0,
        n_test=1,
        duration=30.0,
        sampling_rate=RATE,
        random_state=0,
        perturbation=0.1,
    )


@pytest.fixture(scope="module")
def train(protocol):
    return protocol[protocol["split"] == "train"]


def _fit(model, train, **kwargs):
    return model.fit(train[FEATURES], train["driver_torque"], groups=train["recording"], **kwargs)


@pytest.fixture(scope="module")
def model(train):
    driver = make_driver_model(sampling_period=1 / RATE, random_state=0)
    return _fit(driver, train, perturbation=train[PERTURBATION])


def test_the_penalty_is_the_least_squares_fit_of_the_shifted_target(train):
    # One state: the regression of y - penalty * p on the sensed and derived inputs, by
    # numpy's least squares (on well-conditioned columns, so that the regressor's covariance
    # regularisation is negligible).
    columns = [
        "steering_wheel_angle",
        "steering_wheel_velocity",
        "lateral_acceleration",
        "yaw_rate",
        "lateral_deviation_0m",
        "heading_deviation_10m",
    ]
    settings = dict(friction_velocity=0.1, velocity_filter=None, output_smoothing=None)
    # the penalty in multiples of the perturbation (preview_columns=None, the default)
    driver = make_driver_model(perturbation_penalty=2.5, reg_covar=1e-12, **settings)
    driver = driver.fit(
        train[columns],
        train["driver_torque"],
        groups=train["recording"],
        perturbation=train[PERTURBATION],
    )
    derived = np.asarray(driver[0].transform(train[columns]))
    design = np.column_stack([derived, np.ones(len(derived))])
    y, p = train["driver_torque"].to_numpy(), train[PERTURBATION].to_numpy()
    coef = np.linalg.lstsq(design, y - 2.5 * p, rcond=None)[0]
    estimate = driver.predict(train[columns], groups=train["recording"])
    assert_allclose(estimate, design @ coef, rtol=0, atol=1e-8)

    # the penalty form: the fit minimises sum (y - f)^2 + 2 * penalty * sum p f
    def objective(estimate):
        return np.sum((y - estimate) ** 2) + 2 * 2.5 * np.sum(p * estimate)

    plain = np.linalg.lstsq(design, y, rcond=None)[0]
    assert objective(design @ coef) < objective(design @ plain)
    assert driver.perturbed_share_ == 1.0
    assert driver.perturbation_rms_ == pytest.approx(0.1, rel=1e-12)


def test_without_perturbation_or_penalty_it_is_the_torque_pipeline(train):
    settings = dict(n_states=2, sampling_period=1 / RATE, random_state=0, powers=(2,))
    # the driver model keeps no plays on the angle and no slow velocity (it was measured at the
    # wheel without them)
    pipeline = make_torque_pipeline(**settings, friction_angle=None, slow_velocity_filter=None)
    pipeline = _fit(pipeline, train)
    expected = pipeline.predict(train[FEATURES], groups=train["recording"])
    for penalty, perturbation in [
        (1.0, None),
        (0.0, train[PERTURBATION]),
        (1.0, 0 * train[PERTURBATION]),
    ]:
        driver = make_driver_model(perturbation_penalty=penalty, **settings)
        driver = _fit(driver, train, perturbation=perturbation)
        assert_array_equal(driver.predict(train[FEATURES], groups=train["recording"]), expected)


def test_the_perturbation_penalises_a_pandas_or_2d_target_alike(train):
    p = train[PERTURBATION].to_numpy()
    driver = make_driver_model(perturbation_penalty=1.5, random_state=0)
    as_series = driver._penalised_target(train["driver_torque"], p)
    assert as_series.index.equals(train.index)
    assert_allclose(as_series, train["driver_torque"] - 1.5 * p)
    column = driver._penalised_target(train[["driver_torque"]].to_numpy(), p)
    assert column.shape == (len(train), 1)
    assert_allclose(column[:, 0], as_series)


def test_the_penalty_is_in_units_of_the_torque_perception_leaves_unexplained():
    # By hand: the least-squares fit of y on a constant and the preview column x is the mean
    # of y at x = 0 (1) and at x = 1 (4): e = (0, -1, 0, 1), sum e^2 = 2; sum p^2 = 0.5, so
    # the unit is 4 and penalty 0.5 shifts y by 0.5 * 4 * p = 2 p.
    X = pd.DataFrame({"x": [0.0, 1.0, 0.0, 1.0], "w": [1.0, -1.0, 1.0, -1.0]})
    y = np.array([1.0, 3.0, 1.0, 5.0])
    p = np.array([0.5, -0.5, 0.0, 0.0])
    driver = make_driver_model(perturbation_penalty=0.5, preview_columns=("x",))
    assert_allclose(driver._penalised_target(y, p, X), [0.0, 4.0, 1.0, 5.0], atol=1e-12)
    assert driver.penalty_scale_ == pytest.approx(4.0, rel=1e-12)
    assert driver.perturbed_share_ == 0.5
    # the perturbation twice as strong: a quarter of the unit, half the shift
    assert_allclose(driver._penalised_target(y, 2 * p, X), y - p, atol=1e-12)
    assert driver.penalty_scale_ == pytest.approx(1.0, rel=1e-12)


def test_scaling_the_torque_leaves_the_penalty_and_the_fit_in_proportion(train):
    # Torque and perturbation in other units (c times): the unit of the penalty is a ratio of
    # torques squared, so it stays, and the penalised target, the fit and its estimate are c
    # times the first (one state: a least-squares fit).
    X, y, p = train[FEATURES], train["driver_torque"], train[PERTURBATION].to_numpy()
    settings = dict(
        sampling_period=1 / RATE,
        output_smoothing=None,
        preview_columns=PREVIEW_FEATURES,
        perturbation_penalty=0.07,
        random_state=0,
    )
    first = make_driver_model(**settings).fit(X, y, groups=train["recording"], perturbation=p)
    target = first._penalised_target(y, p, X).to_numpy()
    c = 9.81
    other = make_driver_model(**settings)
    other = other.fit(X, c * y, groups=train["recording"], perturbation=c * p)
    assert other.penalty_scale_ == pytest.approx(first.penalty_scale_, rel=1e-9)
    assert first.penalty_scale_ > 1
    assert_allclose(other._penalised_target(c * y, c * p, X), c * target, rtol=1e-9)
    estimate = first.predict(X, groups=train["recording"])
    assert_allclose(other.predict(X, groups=train["recording"]), c * estimate, rtol=1e-6, atol=1e-9)


def test_the_penalty_needs_the_preview_columns_by_name(train):
    X, y, p = train[FEATURES], train["driver_torque"], train[PERTURBATION]
    sighted = make_driver_model(preview_columns=PREVIEW_FEATURES)
    with pytest.raises(ValueError, match=r"X has no column names; .*preview_columns="):
        sighted.fit(X.to_numpy(), y, perturbation=p)
    with pytest.raises(ValueError, match="X has no column 'road_curvature_30m'.*preview_col"):
        sighted.fit(X.drop(columns="road_curvature_30m"), y, perturbation=p)
    # with penalty 0, without a perturbation or in multiples of it, it needs no preview
    blind = X.drop(columns=list(PREVIEW_FEATURES))
    sighted.set_params(perturbation_penalty=0.0).fit(blind, y, perturbation=p)
    make_driver_model(preview_columns=PREVIEW_FEATURES).fit(blind, y)
    assert make_driver_model().fit(blind, y, perturbation=p).penalty_scale_ == 1.0


@pytest.mark.parametrize(
    "perturbation, words",
    [
        (np.zeros(5), r"perturbation has shape \(5,\); fit needs one torque"),
        ("nan", "perturbation is nan in row 3"),
    ],
)
def test_a_bad_perturbation_is_refused_naming_it(train, perturbation, words):
    if isinstance(perturbation, str):
        perturbation = train[PERTURBATION].to_numpy().copy()
        perturbation[3] = np.nan
    with pytest.raises(ValueError, match=words):
        _fit(make_driver_model(), train, perturbation=perturbation)
    with pytest.raises(ValueError, match="perturbation_penalty"):
        _fit(make_driver_model(perturbation_penalty=-1.0), train)
    with pytest.raises(TypeError, match="make_driver_model got unknown parameter"):
        make_driver_model(n_iterations=3)


def test_a_second_output_is_refused_with_a_perturbation(train):
    y = np.column_stack([train["driver_torque"], train["driver_torque"]])
    with pytest.raises(ValueError, match="y has 2 outputs"):
        make_driver_model().fit(train[FEATURES], y, perturbation=train[PERTURBATION])


def test_the_model_at_the_wheel_is_its_predict_on_what_it_sensed(model):
    # A plain loop of the same simulator: a driver that predicts, with the batch predict of
    # the model, the whole sensed history so far and applies its last estimate.
    road = dict(duration=4.0, sampling_rate=RATE, random_state=7, vehicle=2)
    history = []

    def plain(row):
        history.append(row.copy())
        return model.predict(pd.DataFrame(history, columns=SENSED)[FEATURES])[-1]

    streamed = drive(model, **road)
    looped = drive(plain, **road)
    pd.testing.assert_frame_equal(streamed[FEATURES], looped[FEATURES], rtol=0, atol=1e-9)
    assert_allclose(streamed["driver_torque"], looped["driver_torque"], rtol=0, atol=1e-9)
    # with a rigid column and clean sensors the sensor reads the model's own torque
    rigid = drive(model, **{**road, "duration": 3.0, "vehicle": None, "sensor_noise": None})
    assert len(rigid) == 60  # (kept control)
    assert_allclose(rigid["driver_torque"], model.predict(rigid[FEATURES]), rtol=0, atol=1e-12)


def test_stream_model_file_and_horizon_need_no_perturbation(model, protocol, tmp_path):
    test = protocol[protocol["split"] == "test"]
    expected, std = model.predict(test[FEATURES], groups=test["recording"], return_std=True)
    assert np.all(std > 0)
    y = test["driver_torque"].to_numpy()
    r2 = 1 - np.sum((y - expected) ** 2) / np.sum((y - y.mean()) ** 2)
    assert model.score(test[FEATURES], y, groups=test["recording"]) == pytest.approx(r2)
    stream = model.filter_stream()
    assert_allclose([stream.update(r) for r in test[FEATURES].to_numpy()], expected, atol=1e-12)
    portable.save(model, tmp_path / "driver.json")
    loaded = portable.load(tmp_path / "driver.json")
    assert type(loaded) is DriverModel
    assert loaded.get_params()["perturbation_penalty"] == model.perturbation_penalty
    assert loaded.get_params(deep=False).keys() == model.get_params(deep=False).keys()
    for key in ("perturbation_penalty", "preview_columns"):
        assert loaded.get_params()[key] == model.get_params()[key]
    facts = ("perturbation_rms_", "perturbed_share_", "penalty_scale_")
    assert [getattr(loaded, a) for a in facts] == [getattr(model, a) for a in facts]
    assert_array_equal(loaded.predict(test[FEATURES], groups=test["recording"]), expected)
    ahead = torque_ahead(
        model, horizons=(0.5,), duration=5.0, sampling_rate=RATE, random_state=1, start_every=25
    )
    assert ahead["estimate"].notna().all() and len(ahead) == 4


def test_the_file_keeps_the_unit_of_the_penalty(train, tmp_path):
    # in units of the preview's unexplained torque; a file without the unit (the first driver
    # model's) holds a penalty in multiples of the perturbation
    import json

    model = make_driver_model(
        perturbation_penalty=0.07, preview_columns=PREVIEW_FEATURES, random_state=0
    )
    model = _fit(model, train, perturbation=train[PERTURBATION])
    portable.save(model, tmp_path / "driver.json")
    loaded = portable.load(tmp_path / "driver.json")
    assert loaded.preview_columns == PREVIEW_FEATURES
    assert loaded.penalty_scale_ == model.penalty_scale_ > 1
    data = json.loads((tmp_path / "driver.json").read_text())
    del data["driver_model"]["preview_columns"], data["driver_model"]["penalty_scale"]
    (tmp_path / "first.json").write_text(json.dumps(data))
    loaded = portable.load(tmp_path / "first.json")
    assert loaded.preview_columns is None and loaded.penalty_scale_ == 1.0


def test_a_torque_pipelines_file_is_refused_as_a_driver_models(model, tmp_path):
    import json

    portable.save(model, tmp_path / "driver.json")
    data = json.loads((tmp_path / "driver.json").read_text())
    del data["driver_model"]
    (tmp_path / "bad.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match="driver_model"):
        portable.load(tmp_path / "bad.json")


# -- the closed-loop scorer ------------------------------------------------------------------


ROADS = [dict(setting=1, random_state=3), dict(setting=7, random_state=4)]
SHORT = dict(duration=8.0, sampling_rate=RATE)


def test_the_closed_loop_score_is_the_worst_log_ratio_to_the_human(model):
    scorer = make_closed_loop_scorer(ROADS, **SHORT)
    errors = []
    for road in ROADS:
        human = lane_keeping_metrics(drive("defensive", **road, **SHORT))
        driven = lane_keeping_metrics(drive(model, **road, **SHORT))
        ratio = driven["lateral_deviation_rms"] / human["lateral_deviation_rms"]
        errors.append(abs(math.log(ratio)))
    assert scorer(model, None, None) == pytest.approx(-max(errors), rel=1e-12)
    mean = make_closed_loop_scorer(ROADS, aggregate="mean", **SHORT)
    assert mean(model, None) == pytest.approx(-sum(errors) / 2, rel=1e-12)
    several = make_closed_loop_scorer(
        ROADS, metric=("lateral_deviation_rms", "torque_rms"), **SHORT
    )
    assert several(model, None) <= scorer(model, None)


def test_a_drive_that_loses_control_scores_ten_times_off():
    scorer = make_closed_loop_scorer(ROADS[:1], **SHORT)

    def weaving(row):  # the steering system's inverse and then some: a positive feedback
        return 60.0 * row[0]

    assert scorer(weaving, None) <= -math.log(10.0)
    assert len(scorer.human_) == 1


def test_the_closed_loop_scorer_ranks_candidates_in_a_grid_search(protocol, train):
    roads = make_closed_loop_scorer(1, **SHORT)
    search = GridSearchCV(
        make_driver_model(sampling_period=1 / RATE, random_state=0),
        {"perturbation_penalty": [0.0, 2.0]},
        scoring={"closed_loop": roads, "performance": PerformanceScore(sampling_period=0.05)},
        refit="closed_loop",
        cv=GroupKFold(n_splits=2),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ungrouped performance scoring
        search.fit(
            train[FEATURES],
            train["driver_torque"],
            groups=train["recording"],
            perturbation=train[PERTURBATION].to_numpy(),
        )
    scores = search.cv_results_["mean_test_closed_loop"]
    assert np.all(np.isfinite(scores)) and np.all(scores <= 0)
    assert search.best_params_["perturbation_penalty"] == [0.0, 2.0][int(np.argmax(scores))]
    assert isinstance(search.scorer_["closed_loop"], ClosedLoopScorer)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(roads=[dict(setting=1)]), r"roads\[0\] needs an int random_state"),
        (dict(roads=[dict(setting=1, random_state=0, duration=3.0)]), r"roads\[0\] must be"),
        (dict(roads=[]), "at least one road"),
        (dict(metric="departures"), "'metric' parameter"),
        (dict(metric=("torque_rms", "departures")), "metric must name"),
        (dict(aggregate="median"), "'aggregate' parameter"),
        (dict(roads=0), "'roads' parameter"),
    ],
)
def test_bad_scorer_arguments_are_refused_naming_them(kwargs, words):
    with pytest.raises(ValueError, match=words):
        make_closed_loop_scorer(**kwargs)


def test_a_preview_model_scores_without_the_other_sensed_features():
    # any driver drive takes: a regressor of the package on a subset of the sensed features
    from skhmmgmr import HMMGMRRegressor
    from skhmmgmr.datasets import make_lane_keeping

    human = make_lane_keeping(30.0, sampling_rate=RATE, random_state=0)
    preview = HMMGMRRegressor(n_states=2, random_state=0).fit(
        human[list(PREVIEW_FEATURES)], human["driver_torque"]
    )
    assert make_closed_loop_scorer(ROADS[:1], **SHORT)(preview, None) <= 0.0
