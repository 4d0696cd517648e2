"""``adapt(relevance="auto", parameters="auto")``: the strength chosen from the adaptation
recordings, checked against a hand-run of the same split with the public API."""

import copy

import numpy as np
import pytest
from sklearn.base import clone

from skhmmgmr import HierarchicalHMMGMRRegressor, HMMGMRRegressor
from skhmmgmr.estimator._adaptation_choice import candidates, choose, confirm_fresh_fit


def _driver(n_recordings, n_rows, seed, slopes=(2.0, -1.0), offset=0.0):
    """Recordings of a driver whose torque is ``slopes @ x + offset`` plus noise."""
    rng = np.random.default_rng(seed)
    X = np.cumsum(rng.normal(size=(n_recordings * n_rows, 2)), axis=0) / 10
    y = X @ np.asarray(slopes) + offset + rng.normal(scale=0.2, size=len(X))
    return X, y, np.repeat([f"r{i}" for i in range(n_recordings)], n_rows)


RELEVANCES = (4096.0, 1024.0, 256.0, 64.0, 16.0, 4.0)


@pytest.fixture(scope="module")
def generic():
    return HMMGMRRegressor(n_states=2, random_state=0).fit(*_driver(4, 150, 0))


def _errors(model, X, y, folds, pairs, n_chunks=10):
    """The root mean squared error of every candidate in every chunk of the held-out rows:
    each fold ``(adapt_parts, held_parts)`` (lists of row indices, each part a recording),
    the model adapted by ``adapt`` (or fitted anew by ``fit`` for relevance 0) to the first
    and scored by ``predict`` on the second, every held-out part cut into ``n_chunks``."""
    scale = model.model_.standardization.output_scale[0]
    sums = {pair: [] for pair in pairs}
    counts = []
    for adapt_parts, held_parts in folds:
        adapt_rows = np.concatenate(adapt_parts)
        adapt_groups = np.repeat(np.arange(len(adapt_parts)), [len(p) for p in adapt_parts])
        held_rows = np.concatenate(held_parts)
        held_groups = np.repeat(np.arange(len(held_parts)), [len(p) for p in held_parts])
        chunks = np.concatenate(
            [
                np.repeat(np.arange(n_chunks), [len(c) for c in np.array_split(p, n_chunks)])
                + n_chunks * k
                for k, p in enumerate(held_parts)
            ]
        )
        counts.append(np.bincount(chunks))
        for parameters, relevance in pairs:
            candidate = copy.deepcopy(model)
            if relevance == 0:
                candidate = clone(model).fit(X[adapt_rows], y[adapt_rows], groups=adapt_groups)
            elif relevance < np.inf:
                candidate.adapt(
                    X[adapt_rows],
                    y[adapt_rows],
                    groups=adapt_groups,
                    relevance=relevance,
                    parameters=parameters,
                )
            estimate = candidate.predict(X[held_rows], groups=held_groups)
            sums[parameters, relevance].append(
                np.bincount(chunks, ((estimate - y[held_rows]) / scale) ** 2)
            )
    counts = np.concatenate(counts)
    return np.sqrt(np.array([np.concatenate(sums[pair]) for pair in pairs]) / counts)


def _paired_t(rmse, than):
    """The mean of the paired differences over their standard error."""
    difference = rmse - than
    return difference.mean() / (np.std(difference, ddof=1) / np.sqrt(difference.size))


def _hand_run(model, X, y, groups, pairs, n_folds=8):
    """The rule of ``adapt``'s "auto", by hand: every recording in eight time blocks, every
    candidate adapted to seven of them (each block a recording) and scored on the eighth;
    the one-standard-error rule (two standard errors) among the candidates that keep the
    model as a prior; then the fresh fit (last) if it is ahead of that choice by half a
    standard error of their paired chunk differences and, with each recording held out in
    turn, not behind it by more than one (with a single recording: a score a tenth lower)."""
    recordings = [np.flatnonzero(groups == g) for g in dict.fromkeys(groups)]
    blocks = [np.array_split(rows, n_folds) for rows in recordings]
    folds = [
        (
            [part for parts in blocks for j, part in enumerate(parts) if j != i],
            [parts[i] for parts in blocks],
        )
        for i in range(n_folds)
    ]
    rmse = _errors(model, X, y, folds, pairs)
    score = rmse.mean(axis=1)
    se = np.std(rmse, axis=1, ddof=1) / np.sqrt(rmse.shape[1])
    best = np.argmin(score[:-1])
    chosen = next(k for k in range(len(pairs)) if score[k] <= score[best] + 2.0 * se[best])
    on_recordings = np.full(len(pairs), np.nan)
    if _paired_t(rmse[-1], rmse[chosen]) < -0.5:
        if len(recordings) == 1:
            fresh = score[-1] <= 0.9 * score[chosen]
        else:
            folds = [
                (recordings[:i] + recordings[i + 1 :], [recordings[i]])
                for i in range(len(recordings))
            ]
            held = _errors(model, X, y, folds, [pairs[chosen], pairs[-1]])
            on_recordings[[chosen, -1]] = held.mean(axis=1)
            fresh = _paired_t(held[1], held[0]) < 1.0
        chosen = len(pairs) - 1 if fresh else chosen
    return score, se, on_recordings, chosen


def test_the_choice_is_that_of_a_hand_run_of_the_same_split(generic):
    X, y, groups = _driver(2, 200, 1, slopes=(2.6, -0.6), offset=0.3)  # another driver
    model = copy.deepcopy(generic).adapt(X, y, groups=groups)
    table = model.adaptation_
    pairs = list(zip(table["parameters"], table["relevance"], strict=True))
    assert pairs[0] == ("", np.inf)
    assert pairs[1:-1] == [("mv", r) for r in RELEVANCES]
    assert pairs[-1] == ("mvt", 0.0)  # a fresh fit
    score, se, on_recordings, chosen = _hand_run(generic, X, y, groups, pairs)
    np.testing.assert_allclose(table["validation_rmse"], score, rtol=1e-9)
    np.testing.assert_allclose(table["validation_se"], se, rtol=1e-9)
    np.testing.assert_allclose(table["recordings_rmse"], on_recordings, rtol=1e-9)
    assert table["chosen"].tolist() == [k == chosen for k in range(len(pairs))]
    assert table["relevance"][chosen] < np.inf  # a driver this far moves the model
    assert np.isfinite(on_recordings).sum() == 2  # the fresh fit led: held-out recordings ran
    # then the chosen candidate adapts to all the rows
    parameters, relevance = pairs[chosen]
    reference = copy.deepcopy(generic).adapt(
        X, y, groups=groups, relevance=relevance, parameters=parameters
    )
    assert np.array_equal(model.predict(X, groups=groups), reference.predict(X, groups=groups))


def _sampled(fitted, n_recordings, n_rows, seed):
    """Recordings drawn from the fitted HMM itself (state path, then joint Gaussian rows)."""
    rng = np.random.default_rng(seed)
    means, covars = fitted.means_, fitted.covars_
    rows = []
    for _ in range(n_recordings):
        state = rng.choice(len(fitted.startprob_), p=fitted.startprob_)
        for _ in range(n_rows):
            rows.append(rng.multivariate_normal(means[state], covars[state]))
            state = rng.choice(len(fitted.startprob_), p=fitted.transmat_[state])
    rows = np.array(rows)
    return rows[:, :-1], rows[:, -1], np.repeat(np.arange(n_recordings), n_rows)


@pytest.mark.parametrize("data", ["training recordings", "sampled from the model"])
def test_the_models_own_data_do_not_adapt_it(generic, data):
    if data == "training recordings":
        X, y, groups = _driver(4, 150, 0)
    else:
        X, y, groups = _sampled(generic, 3, 200, 2)
    model = copy.deepcopy(generic)
    before = model.model_
    model.adapt(X, y, groups=groups)
    chosen = model.adaptation_[model.adaptation_["chosen"]]
    assert chosen["relevance"].tolist() == [np.inf] and chosen["parameters"].tolist() == [""]
    assert model.model_ is before
    assert model.n_iter_ == 0 and model.converged_
    np.testing.assert_allclose(model.log_likelihood_, generic.log_likelihood(X, y, groups))


def test_the_adapted_model_predicts_a_far_driver_better(generic):
    far = {"slopes": (3.0, -0.3), "offset": 0.5}
    X, y, groups = _driver(2, 200, 3, **far)
    X_new, y_new, groups_new = _driver(2, 200, 4, **far)
    model = copy.deepcopy(generic).adapt(X, y, groups=groups)
    assert model.score(X_new, y_new, groups_new) > generic.score(X_new, y_new, groups_new)


@pytest.mark.parametrize(
    "options, expected",
    [
        ({"relevance": "auto", "parameters": "mvt"}, [(r, "mvt") for r in RELEVANCES]),
        ({"relevance": 64.0, "parameters": "auto"}, [(64.0, "mv")]),
        ({"relevance": "auto", "parameters": ""}, []),
        ({"relevance": np.inf, "parameters": "auto"}, []),
        ({"relevance": 0.0, "parameters": "auto"}, [(0.0, "mvt")]),
    ],
)
def test_auto_compares_do_not_adapt_and_what_is_left_free(generic, options, expected):
    X, y, groups = _driver(2, 60, 5, offset=0.3)
    table = copy.deepcopy(generic).adapt(X, y, groups=groups, **options).adaptation_
    pairs = list(zip(table["relevance"], table["parameters"], strict=True))
    assert pairs == [(np.inf, ""), *expected]
    assert table["chosen"].sum() == 1


def test_fixed_settings_leave_no_choice_and_inf_adapts_nothing(generic):
    X, y, groups = _driver(2, 60, 6, offset=0.3)
    model = copy.deepcopy(generic)
    assert model.adapt(X, y, groups=groups, relevance=16.0, parameters="mv").adaptation_ is None
    before = model.model_
    model.adapt(X, y, groups=groups, relevance=np.inf, parameters="mv")
    assert model.model_ is before and model.n_iter_ == 0 and model.adaptation_ is None


def test_too_few_rows_to_choose_from_do_not_adapt(generic):
    X, y, _ = _driver(1, 1, 7, offset=1.0)
    model = copy.deepcopy(generic)
    before = model.model_
    model.adapt(X, y)
    assert model.model_ is before
    assert model.adaptation_["chosen"].tolist()[0]
    assert np.isnan(model.adaptation_["validation_rmse"]).all()


def test_missing_targets_do_not_count_in_the_choice():
    X, y, groups = _driver(2, 120, 8)
    generic = HMMGMRRegressor(n_states=2, missing_values="marginalize", random_state=0)
    generic.fit(X, y, groups=groups)
    X_new, y_new, groups_new = _driver(2, 120, 9, slopes=(2.6, -0.6), offset=0.3)
    y_missing = y_new.copy()
    y_missing[::5] = np.nan
    table = copy.deepcopy(generic).adapt(X_new, y_missing, groups=groups_new).adaptation_
    assert np.isfinite(table["validation_rmse"]).all()


def test_a_hierarchical_model_adapts_by_auto_and_keeps_its_structure():
    X, y, groups = _driver(4, 150, 10)
    manoeuvre = np.tile(np.repeat(["keep", "turn", "keep"], 50), 4)
    model = HierarchicalHMMGMRRegressor(manoeuvres=None, n_states=2, random_state=0)
    model.fit(X, y, groups=groups, manoeuvre=manoeuvre)
    chain, transmat = model.manoeuvre_transmat_, model.transmat_
    X_new, y_new, groups_new = _driver(2, 200, 11, slopes=(2.6, -0.6), offset=0.3)
    model.adapt(X_new, y_new, groups=groups_new)
    assert set(model.adaptation_["parameters"]) == {"", "mv"}  # never the transitions
    assert np.array_equal(model.transmat_, transmat)
    assert np.array_equal(model.manoeuvre_transmat_, chain)


def test_relevance_zero_fits_the_estimator_anew(generic):
    X, y, groups = _driver(2, 200, 12, slopes=(-1.0, 3.0))
    model = copy.deepcopy(generic).adapt(X, y, groups=groups, relevance=0.0, parameters="mvt")
    fresh = clone(generic).fit(X, y, groups=groups)
    assert np.array_equal(model.predict(X, groups=groups), fresh.predict(X, groups=groups))
    assert model.n_iter_ == fresh.n_iter_ and model.adaptation_ is None
    assert model.log_likelihood_ == fresh.log_likelihood_


def test_a_hierarchical_model_cannot_be_fitted_anew_by_adapt():
    X, y, groups = _driver(2, 150, 13)
    model = HierarchicalHMMGMRRegressor(manoeuvres=2, n_states=1, random_state=0)
    model.fit(X, y, groups=groups)
    with pytest.raises(ValueError, match="relevance=0 fits the model anew"):
        model.adapt(X, y, groups=groups, relevance=0.0, parameters="mvt")


def _fresh_fit_leading(fresh_ratio):
    """The table of :func:`choose` on 20 chunks where every candidate that keeps the model as
    a prior scores the same (so "do not adapt" is chosen) and the fresh fit scores
    ``fresh_ratio`` times as much in every chunk."""
    pairs = candidates("auto", "auto")
    base = 1.0 + 0.1 * np.sin(np.arange(20.0))
    rmse = np.vstack([np.tile(base, (len(pairs) - 1, 1)), fresh_ratio * base])
    table, confirm = choose(pairs, rmse**2, np.ones(20))
    assert table["chosen"].tolist()[0]
    return table, confirm


@pytest.mark.parametrize("ratio, chosen", [(0.91, False), (0.89, True)])
def test_with_one_recording_the_fresh_fit_needs_a_score_a_tenth_lower(ratio, chosen):
    table, confirm = _fresh_fit_leading(ratio)
    assert confirm  # ahead in every chunk: by far more than half a standard error
    table = confirm_fresh_fit(table)  # a single recording: nothing to hold out
    assert table["chosen"].tolist()[-1] == chosen and table["chosen"].sum() == 1


@pytest.mark.parametrize("behind, chosen", [(0.9, True), (1.1, False)])
def test_the_fresh_fit_must_not_trail_on_held_out_recordings(behind, chosen):
    table, _ = _fresh_fit_leading(0.5)
    # on held-out recordings the fresh fit trails the choice by `behind` standard errors
    # of the paired differences (+-0.1 around their mean, 20 chunks)
    spread = 0.1 * np.resize([1.0, -1.0], 20)
    se = np.std(spread, ddof=1) / np.sqrt(20)
    held = np.vstack([np.full(20, 1.0), 1.0 + behind * se + spread])
    table = confirm_fresh_fit(table, held**2, np.ones(20))
    assert table["chosen"].tolist()[-1] == chosen and table["chosen"].sum() == 1
    np.testing.assert_allclose(table["recordings_rmse"].iloc[[0, -1]], held.mean(axis=1))
    assert table["recordings_rmse"].iloc[1:-1].isna().all()


def test_a_fresh_fit_within_half_a_standard_error_is_not_considered():
    pairs = candidates("auto", "auto")
    base = 1.0 + 0.1 * np.sin(np.arange(20.0))
    spread = 0.1 * np.resize([1.0, -1.0], 20)
    se = np.std(spread, ddof=1) / np.sqrt(20)
    for lead, considered in [(0.4, False), (0.6, True)]:
        rmse = np.vstack([np.tile(base, (len(pairs) - 1, 1)), base - lead * se + spread])
        assert choose(pairs, rmse**2, np.ones(20))[1] == considered
