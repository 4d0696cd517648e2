"""HierarchicalHMMGMRRegressor: the flat filter is the two-level filter, labels fix the fit."""

import dataclasses

import numpy as np
import pytest
from scipy.stats import multivariate_normal
from sklearn import config_context
from sklearn.model_selection import GroupKFold, cross_validate
from test_portable import file_dict, load_dict

from skhmmgmr import HierarchicalHMMGMRRegressor, portable
from skhmmgmr.export import write_c


def two_manoeuvres(n_recordings=4, rows=60, seed=0):
    """Recordings alternating "keep" (x in [-3, -1], y = 3 x) and "change" (x in [1, 3],
    y = -x) in runs of ``rows``: the labels fix which rows each block sees."""
    rng = np.random.default_rng(seed)
    X, y, labels, groups = [], [], [], []
    for r in range(n_recordings):
        for run in range(4):
            keep = (run + r) % 2 == 0
            x = rng.uniform(-3, -1, rows) if keep else rng.uniform(1, 3, rows)
            X.append(np.column_stack([x, rng.normal(0, 1, rows)]))
            y.append((3.0 * x if keep else -x) + rng.normal(0, 0.01, rows))
            labels += ["keep" if keep else "change"] * rows
            groups += [r] * rows
    return np.vstack(X), np.concatenate(y), np.asarray(labels), np.asarray(groups)


@pytest.fixture(scope="module")
def fitted():
    X, y, labels, groups = two_manoeuvres()
    model = HierarchicalHMMGMRRegressor(
        manoeuvres=["keep", "change"], n_states={"keep": 1, "change": 2}, random_state=0
    )
    return model.fit(X, y, groups=groups, manoeuvre=labels), X, y, labels, groups


def two_level_filter(X, startprob, within, exit, chain, entry, blocks, means, covs, n_in):
    """Causal GMR of a manoeuvre chain over per-manoeuvre HMMs, as plain loops over the pairs
    (manoeuvre, state): stay in the manoeuvre with ``1 - exit`` and move by its own matrix,
    or leave with ``exit``, pick the next manoeuvre by ``chain`` and its state by ``entry``."""
    pairs = [(m, i) for m, size in enumerate(blocks) for i in range(size)]
    estimates, manoeuvre_proba = [], []
    alpha = None
    for t, x in enumerate(X):
        prior = np.zeros(len(pairs))
        for b, (n, j) in enumerate(pairs):
            if t == 0:
                prior[b] = startprob[b]
                continue
            for a, (m, i) in enumerate(pairs):
                if n == m:
                    step = (1 - exit[m][i]) * within[m][i][j]
                else:
                    step = exit[m][i] * chain[m][n] * entry[n][j]
                prior[b] += alpha[a] * step
        density = [
            multivariate_normal(means[b][:n_in], covs[b][:n_in, :n_in]).pdf(x)
            for b in range(len(pairs))
        ]
        alpha = prior * np.asarray(density)
        alpha /= alpha.sum()
        conditional = [
            means[b][n_in]
            + covs[b][n_in, :n_in] @ np.linalg.solve(covs[b][:n_in, :n_in], x - means[b][:n_in])
            for b in range(len(pairs))
        ]
        estimates.append(float(alpha @ np.asarray(conditional)))
        manoeuvre_proba.append(
            [sum(alpha[b] for b, (m, _) in enumerate(pairs) if m == k) for k in range(len(blocks))]
        )
    return np.asarray(estimates), np.asarray(manoeuvre_proba)


def test_flattened_filter_is_the_two_level_filter(fitted):
    model, X, *_ = fitted
    rng = np.random.default_rng(1)
    blocks = [1, 2]
    # hand-made parts, far from any fit: the flat matrix is composed by the estimator's code
    within = [np.array([[1.0]]), np.array([[0.7, 0.3], [0.4, 0.6]])]
    exit = [np.array([0.2]), np.array([0.05, 0.5])]
    chain = [[0.0, 1.0], [1.0, 0.0]]
    entry = [np.array([1.0]), np.array([0.25, 0.75])]
    startprob = np.array([0.5, 0.2, 0.3])
    flat = np.zeros((3, 3))
    index = [(0, 0), (1, 0), (1, 1)]
    for a, (m, i) in enumerate(index):
        for b, (n, j) in enumerate(index):
            flat[a, b] = (1 - exit[m][i]) * within[m][i, j] if m == n else exit[m][i] * entry[n][j]
    structured = model._hierarchy().compose(
        dataclasses.replace(
            model._parts(),
            within=np.array([[1.0, 0, 0], [0, 0.7, 0.3], [0, 0.4, 0.6]]),
            exit=np.array([0.2, 0.05, 0.5]),
            chain=np.array([[0.0, 1.0], [1.0, 0.0]]),
            entry=np.array([1.0, 0.25, 0.75]),
        )
    )
    np.testing.assert_allclose(structured, flat, rtol=0, atol=1e-15)
    fitted_model = dataclasses.replace(model.model_, startprob=startprob, transmat=structured)
    estimator = HierarchicalHMMGMRRegressor.from_fitted_model(
        fitted_model, manoeuvres=["keep", "change"], n_states=[1, 2]
    )
    rows = X[rng.choice(len(X), 40)]  # jumping between manoeuvres: every transition counts
    expected, expected_proba = two_level_filter(
        rows, startprob, within, exit, chain, entry, blocks,
        estimator.means_, estimator.covars_, n_in=2,
    )  # fmt: skip
    np.testing.assert_allclose(estimator.predict(rows), expected, rtol=0, atol=1e-10)
    proba = estimator.predict_manoeuvre_proba(rows)
    np.testing.assert_allclose(proba, expected_proba, rtol=0, atol=1e-10)
    np.testing.assert_allclose(estimator.exit_proba_, [0.2, 0.05, 0.5], atol=1e-12)
    np.testing.assert_allclose(estimator.entry_proba_, [1.0, 0.25, 0.75], atol=1e-12)


def test_labels_fix_each_manoeuvres_slope_and_the_chain():
    X, y, labels, groups = two_manoeuvres()
    model = HierarchicalHMMGMRRegressor(
        manoeuvres=["keep", "change"], n_states=1, refine_iter=0, random_state=0
    ).fit(X, y, groups=groups, manoeuvre=labels)
    covars = model.covars_
    slopes = covars[:, 2, 0] / covars[:, 0, 0]
    np.testing.assert_allclose(slopes, [3.0, -1.0], atol=0.01)
    # 4 recordings of 4 runs: every run but the last of a recording hands over; each
    # manoeuvre holds 8 runs of 60 rows, 6 of which hand over
    np.testing.assert_allclose(model.exit_proba_, (6 + 0.5) / (480 + 1.0), rtol=1e-9)
    np.testing.assert_allclose(model.manoeuvre_transmat_, [[0, 1], [1, 0]], atol=1e-15)
    # two recordings start in each manoeuvre
    np.testing.assert_allclose(model.manoeuvre_startprob_, [0.5, 0.5], rtol=1e-12)
    # refined jointly the labels' answer stands
    refined = HierarchicalHMMGMRRegressor(
        manoeuvres=["keep", "change"], n_states=1, random_state=0
    ).fit(X, y, groups=groups, manoeuvre=labels)
    covars = refined.covars_
    np.testing.assert_allclose(covars[:, 2, 0] / covars[:, 0, 0], [3.0, -1.0], atol=0.01)
    proba = refined.predict_manoeuvre_proba(X, groups=groups)
    assert np.mean(proba.argmax(axis=1) == (labels == "change")) > 0.99


def test_refinement_keeps_the_blocks_and_raises_the_objective(fitted):
    model, X, y, labels, groups = fitted
    history = model.penalized_log_likelihood_history_
    assert np.all(np.diff(history) >= -1e-9 * np.abs(history[:-1]))
    transmat = model.transmat_
    m_of, entry, exit = model.state_manoeuvre_, model.entry_proba_, model.exit_proba_
    chain = model.manoeuvre_transmat_
    for a in range(3):
        for b in range(3):
            if m_of[a] != m_of[b]:  # only through the chain and the entry distribution
                expected = exit[a] * chain[m_of[a], m_of[b]] * entry[b]
                assert transmat[a, b] == pytest.approx(expected, rel=1e-9, abs=1e-300)
    np.testing.assert_allclose(transmat.sum(axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.diag(chain), 0.0)


def test_manoeuvre_probabilities_are_the_blocks_of_the_state_probabilities(fitted):
    model, X, _, _, groups = fitted
    proba = model.predict_manoeuvre_proba(X, groups=groups)
    states = model.predict_state_proba(X, groups=groups)
    assert proba.shape == (len(X), 2)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(proba, [[s[0], s[1] + s[2]] for s in states], rtol=1e-12)
    assert list(model.manoeuvres_) == ["keep", "change"]
    assert list(model.states_per_manoeuvre_) == [1, 2]
    assert list(model.state_manoeuvre_) == [0, 1, 1]
    assert model.transmat_.shape == (3, 3)


def test_states_per_manoeuvre_forms_and_unlabelled_fit():
    X, y, labels, groups = two_manoeuvres(n_recordings=2)
    by_list = HierarchicalHMMGMRRegressor(manoeuvres=None, n_states=[2, 1], random_state=0)
    by_list.fit(X, y, groups=groups, manoeuvre=labels)
    assert list(by_list.manoeuvres_) == ["change", "keep"]  # sorted labels
    assert list(by_list.state_manoeuvre_) == [0, 0, 1]
    unlabelled = HierarchicalHMMGMRRegressor(manoeuvres=2, n_states=1, random_state=0)
    unlabelled.fit(X, y, groups=groups)
    assert list(unlabelled.manoeuvres_) == [0, 1]
    # k-means finds the two manoeuvres, whatever it calls them
    found = unlabelled.predict_manoeuvre_proba(X, groups=groups).argmax(axis=1)
    agreement = np.mean(found == (labels == "change"))
    assert max(agreement, 1 - agreement) > 0.99
    assert unlabelled.score(X, y, groups=groups) > 0.99


@pytest.mark.parametrize(
    "params, fit_labels, message",
    [
        ({"manoeuvres": ["keep", "change"]}, "other", r"label\(s\) \['other'\]"),
        ({"manoeuvres": ["keep", "change"]}, "short", "manoeuvre has 10 labels, X has"),
        ({"manoeuvres": None}, None, "manoeuvres=None takes the manoeuvres from the labels"),
        ({"manoeuvres": ["keep", "change"], "n_states": {"keep": 1}}, "ok", r"misses \['change'"),
        ({"manoeuvres": ["keep", "change"], "n_states": [1, 2, 3]}, "ok", "3 values for 2"),
        ({"manoeuvres": ["keep", "keep"]}, None, r"names \['keep'\] more than once"),
        ({"manoeuvres": ["keep", "change", "evade"]}, "ok", "'evade' has 0 row"),
    ],
)
def test_clear_errors(params, fit_labels, message):
    X, y, labels, groups = two_manoeuvres(n_recordings=1)
    if fit_labels == "other":
        labels = labels.copy()
        labels[5] = "other"
    elif fit_labels == "short":
        labels = labels[:10]
    elif fit_labels is None:
        labels = None
    model = HierarchicalHMMGMRRegressor(**{"n_states": 1, **params})
    with pytest.raises(ValueError, match=message):
        model.fit(X, y, groups=groups, manoeuvre=labels)


def test_model_file_stream_and_c_export_reproduce_predict(fitted, tmp_path):
    model, X, _, _, groups = fitted
    rows = X[groups == 1]
    path = tmp_path / "hierarchy.json"
    portable.save(model, path)
    restored = portable.load(path)
    assert type(restored) is HierarchicalHMMGMRRegressor
    np.testing.assert_allclose(restored.predict(rows), model.predict(rows), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        restored.predict_manoeuvre_proba(rows), model.predict_manoeuvre_proba(rows), atol=1e-12
    )
    assert list(restored.manoeuvres_) == ["keep", "change"]
    stream = model.filter_stream()
    streamed, std = zip(*(stream.update(row, return_std=True) for row in rows), strict=True)
    expected, expected_std = model.predict(rows, return_std=True)
    np.testing.assert_allclose(streamed, expected, rtol=0, atol=1e-10)
    np.testing.assert_allclose(std, expected_std, rtol=0, atol=1e-10)
    manoeuvre_of_state = model.state_manoeuvre_
    last = np.bincount(manoeuvre_of_state, weights=stream.state_proba_, minlength=2)
    np.testing.assert_allclose(last, model.predict_manoeuvre_proba(rows)[-1], atol=1e-10)
    (tmp_path / "c").mkdir()
    written = write_c(model, tmp_path / "c")
    assert written


def test_manoeuvre_labels_are_routed_as_metadata():
    X, y, labels, groups = two_manoeuvres(n_recordings=3)
    model = HierarchicalHMMGMRRegressor(manoeuvres=["keep", "change"], n_states=1, random_state=0)
    with config_context(enable_metadata_routing=True):
        scores = cross_validate(
            model,
            X,
            y,
            cv=GroupKFold(3),
            params={"groups": groups, "manoeuvre": labels},
            return_estimator=True,
        )
    assert np.all(scores["test_score"] > 0.9)
    # a fold fitted on its own labels: both manoeuvres were labelled in it
    assert all(list(e.manoeuvres_) == ["keep", "change"] for e in scores["estimator"])


def test_a_start_from_the_flat_model_keeps_its_states_and_names_them_by_the_labels():
    from skhmmgmr import HMMGMRRegressor

    X, y, labels, groups = two_manoeuvres()
    flat = HMMGMRRegressor(n_states=4, random_state=0).fit(X, y, groups=groups)
    model = HierarchicalHMMGMRRegressor(
        manoeuvres=["keep", "change"],
        n_states=[3, 1],
        start="flat",
        refine_iter=0,
        random_state=0,
    ).fit(X, y, groups=groups, manoeuvre=labels)
    # the flat model's states, reordered by manoeuvre: "keep" has x < 0, "change" x > 0
    order = np.argsort(flat.means_[:, 0])
    np.testing.assert_allclose(np.sort(model.means_[:, 0]), flat.means_[order, 0])
    assert model.states_per_manoeuvre_.sum() == 4
    keep = model.state_manoeuvre_ == 0
    assert np.all(model.means_[keep, 0] < 0) and np.all(model.means_[~keep, 0] > 0)
    assert list(model.states_per_manoeuvre_) == [
        int(np.sum(flat.means_[:, 0] < 0)),
        int(np.sum(flat.means_[:, 0] > 0)),
    ]
    np.testing.assert_allclose(model.transmat_.sum(axis=1), 1.0)
    refined = HierarchicalHMMGMRRegressor(
        manoeuvres=["keep", "change"], n_states=[3, 1], start="flat", random_state=0
    ).fit(X, y, groups=groups, manoeuvre=labels)
    proba = refined.predict_manoeuvre_proba(X, groups=groups)
    assert np.mean(proba.argmax(axis=1) == (labels == "change")) > 0.95


def test_a_start_from_the_flat_model_gives_every_manoeuvre_a_state():
    # one manoeuvre only on few rows: the flat model gives it no state of its own
    X, y, labels, groups = two_manoeuvres()
    labels = labels.copy()
    labels[::97] = "rare"
    model = HierarchicalHMMGMRRegressor(
        manoeuvres=["keep", "change", "rare"], n_states=[1, 1, 1], start="flat", random_state=0
    ).fit(X, y, groups=groups, manoeuvre=labels)
    assert np.all(model.states_per_manoeuvre_ >= 1)
    assert model.states_per_manoeuvre_.sum() == 3


# --- labels and manoeuvres refused naming the label, its row and its recording (#51) ----------


def _recording_1_first():
    """Two recordings, recording 1's rows first: fit reads them in the order of the ids, so
    a row's place in X differs from its place in the fit."""
    X, y, labels, groups = two_manoeuvres(n_recordings=2)
    order = np.concatenate([np.flatnonzero(groups == 1), np.flatnonzero(groups == 0)])
    return X[order], y[order], labels[order].astype(object), groups[order]


@pytest.mark.parametrize("missing", [np.nan, None, ["keep"]])
@pytest.mark.parametrize("manoeuvres", [None, ["keep", "change"]])
def test_a_row_without_a_manoeuvre_label_is_refused_naming_it(missing, manoeuvres):
    """#51: with manoeuvres=None a NaN label gave "manoeuvre 1.0 has 0 row(s)", None a
    numpy TypeError."""
    X, y, labels, groups = _recording_1_first()
    labels[10] = missing
    model = HierarchicalHMMGMRRegressor(manoeuvres=manoeuvres, n_states=1, n_iter=2)
    with pytest.raises(ValueError, match=r"holds .* at row 10 of X \(recording 1\)") as error:
        model.fit(X, y, groups=groups, manoeuvre=labels)
    assert repr(missing) in str(error.value)


def test_a_label_out_of_the_manoeuvres_is_named_with_its_first_row():
    X, y, labels, groups = _recording_1_first()
    labels[[200, 300]] = "overtake"  # recording 1, then recording 0
    model = HierarchicalHMMGMRRegressor(manoeuvres=["keep", "change"], n_states=1, n_iter=2)
    with pytest.raises(ValueError, match=r"\['overtake'\].*first is at row 300 of X \(recor"):
        model.fit(X, y, groups=groups, manoeuvre=labels)  # the first in the fit's order


@pytest.mark.parametrize("manoeuvres", [{"keep": 1, "change": 2}, {"keep", "change"}])
def test_manoeuvres_given_as_a_dict_or_a_set_is_refused_naming_it(manoeuvres):
    """#51: a dict gave "unhashable type: 'dict'", and from a model file "unknown
    parameter"."""
    X, y, labels, groups = two_manoeuvres(n_recordings=2)
    model = HierarchicalHMMGMRRegressor(manoeuvres=manoeuvres, n_states=1, n_iter=2)
    with pytest.raises(ValueError, match="'manoeuvres' parameter .* n_states, which takes a"):
        model.fit(X, y, groups=groups, manoeuvre=labels)


def test_a_model_file_with_manoeuvres_as_a_dict_names_the_key(fitted, tmp_path):
    model = fitted[0]
    data = file_dict(model, tmp_path)
    data["estimator_params"]["manoeuvres"] = {"keep": 1, "change": 2}
    with pytest.raises(ValueError, match="'estimator_params.manoeuvres' must be a param") as error:
        load_dict(data, tmp_path)
    assert "unknown parameter" not in str(error.value)


def test_labels_of_texts_and_numbers_without_manoeuvres_are_refused():
    X, y, labels, groups = two_manoeuvres(n_recordings=2)
    labels = labels.astype(object)
    labels[labels == "change"] = 1
    model = HierarchicalHMMGMRRegressor(manoeuvres=None, n_states=1, n_iter=2)
    with pytest.raises(ValueError, match=r"types \['int', 'str'\].*give manoeuvres="):
        model.fit(X, y, groups=groups, manoeuvre=labels)
    # named in the order of their blocks, they fit
    named = HierarchicalHMMGMRRegressor(manoeuvres=["keep", 1], n_states=1, n_iter=2)
    named.fit(X, y, groups=groups, manoeuvre=labels)
    assert list(named.manoeuvres_) == ["keep", 1]
