"""The chunked EM and filter numerics against plain, unchunked references."""

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal

from skhmmgmr._core._sequences import Recordings
from skhmmgmr._hmm import _em, _kernels
from skhmmgmr._hmm._em import (
    HMMParameters,
    e_step,
    initialize_parameters,
)
from skhmmgmr._hmm._em_data import Columns, EStepData, recording_blocks
from skhmmgmr._hmm._emissions import FullCovariance
from skhmmgmr._hmm._gaussian import (
    PAIR_BUFFER_VALUES,
    MomentSums,
    NotPositiveDefiniteError,
    augmented_columns,
    compute_precision_cholesky,
    estimate_log_gaussian_prob,
    gaussians_from_moments,
    one_blas_thread,
    stack_gaussians,
    weighted_moments,
)
from skhmmgmr._hmm._gmr import (
    condition_on_inputs,
    conditional_means,
    filter_state_probabilities,
    mix_estimates,
)
from skhmmgmr._hmm._kernels import (
    RESCALE_BELOW,
    UNDERFLOW,
    VECTORISED_STATES,
    forward,
    scaled_densities,
)


def random_gaussians(rng, n_states, n_features):
    means = rng.normal(size=(n_states, n_features))
    factors = rng.normal(size=(n_states, n_features, n_features))
    covariances = factors @ factors.transpose(0, 2, 1) + np.eye(n_features)
    return means, covariances


def random_recordings(rng, lengths):
    stops = np.cumsum(lengths)
    return Recordings(ids=np.arange(len(lengths)), starts=stops - lengths, stops=stops)


@pytest.mark.parametrize("chunk_size", [1, 7, 100, None])
def test_log_prob_matches_scipy_for_any_chunk_size(chunk_size):
    rng = np.random.default_rng(0)
    means, covariances = random_gaussians(rng, 3, 4)
    X = rng.normal(size=(257, 4)) * 2
    log_prob = estimate_log_gaussian_prob(
        X, means, compute_precision_cholesky(covariances), chunk_size=chunk_size
    )
    expected = np.column_stack(
        [multivariate_normal(m, c).logpdf(X) for m, c in zip(means, covariances, strict=True)]
    )
    np.testing.assert_allclose(log_prob, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("n_states, n_features", [(1, 1), (5, 6), (3, 10)])
def test_precision_cholesky_is_the_inverse_transposed_cholesky_factor(n_states, n_features):
    rng = np.random.default_rng(n_features)
    _, covariances = random_gaussians(rng, n_states, n_features)
    covariances[0] *= 1e-6  # a small scale too
    precisions_chol = compute_precision_cholesky(covariances)
    for covariance, factor in zip(covariances, precisions_chol, strict=True):
        expected = np.linalg.inv(np.linalg.cholesky(covariance)).T
        scale = np.abs(expected).max()
        np.testing.assert_allclose(factor, expected, rtol=1e-12, atol=1e-12 * scale)
        assert np.all(np.tril(factor, -1) == 0.0)  # upper triangular, exactly
        np.testing.assert_allclose(factor @ factor.T @ covariance, np.eye(n_features), atol=1e-9)


def test_precision_cholesky_names_the_state_that_cannot_be_factorised():
    _, covariances = random_gaussians(np.random.default_rng(3), 3, 2)
    covariances[1] = [[1.0, 2.0], [2.0, 1.0]]  # indefinite
    with pytest.raises(NotPositiveDefiniteError, match="covariance of state 1 "):
        compute_precision_cholesky(covariances)
    covariances[1] = np.nan
    with pytest.raises(ValueError, match="covariance of state 1 holds NaN or infinity"):
        compute_precision_cholesky(covariances)


def test_nested_one_blas_thread_keeps_the_limit_until_the_outer_context_ends():
    from threadpoolctl import threadpool_info

    def blas_threads():
        return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]

    before = blas_threads()
    with one_blas_thread():
        with one_blas_thread():
            assert set(blas_threads()) <= {1}
        assert set(blas_threads()) <= {1}  # the inner context left the limit in place
    assert blas_threads() == before


@pytest.mark.parametrize("chunk_size", [1, 13, None])
@pytest.mark.parametrize("shifted", [False, True])
def test_weighted_moments_equal_unchunked_sums(chunk_size, shifted):
    rng = np.random.default_rng(1)
    X = rng.normal(size=(301, 5)) + 3.0
    resp = rng.dirichlet(np.ones(4), size=301)
    shift = X.mean(axis=0) if shifted else None
    weights, first, second = weighted_moments(resp, X, shift, chunk_size=chunk_size)
    Xs = X - (0 if shift is None else shift)
    np.testing.assert_allclose(weights, resp.sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(first, resp.T @ Xs, rtol=1e-12)
    np.testing.assert_allclose(second, np.einsum("nk,ni,nj->kij", resp, Xs, Xs), rtol=1e-12)


def centred_covariances(resp, X, means, reg_covar):
    """Plain-loop weighted covariances about each state's mean, reg_covar on the diagonal."""
    n_states, n_features = means.shape
    covariances = np.zeros((n_states, n_features, n_features))
    for k in range(n_states):
        for row, weight in zip(X, resp[:, k], strict=True):
            diff = row - means[k]
            covariances[k] += weight * np.outer(diff, diff)
        covariances[k] /= resp[:, k].sum()
        covariances[k] += reg_covar * np.eye(n_features)
    return covariances


def test_gaussians_from_moments_match_centred_covariances():
    rng = np.random.default_rng(2)
    X = rng.normal(size=(500, 3)) @ rng.normal(size=(3, 3))
    resp = rng.dirichlet(np.ones(3), size=500)
    weights, first, second = weighted_moments(resp, X, X.mean(axis=0), chunk_size=64)
    means, covariances = gaussians_from_moments(weights, first, second, 1e-3, X.mean(axis=0))
    expected_means = (resp.T @ X) / weights[:, np.newaxis]
    expected = centred_covariances(resp, X, expected_means, 1e-3)
    np.testing.assert_allclose(means, expected_means, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(covariances, expected, rtol=1e-11, atol=1e-14)
    np.testing.assert_array_equal(covariances, covariances.transpose(0, 2, 1))


def test_blocks_hold_whole_consecutive_recordings():
    recordings = random_recordings(np.random.default_rng(0), np.array([3, 4, 10, 2, 2, 1]))
    blocks = recording_blocks(recordings, max_rows=8)
    assert [(b[0], b[1]) for b in blocks] == [(0, 7), (7, 17), (17, 22)]
    assert blocks[0][2:] == ([0, 3], [3, 7])
    assert blocks[2][2:] == ([0, 2, 4], [2, 4, 5])


def reference_e_step(X, recordings, params):
    """Log-space forward-backward per recording, one loop step per row."""
    K = params.n_states
    log_b = np.column_stack(
        [
            multivariate_normal(m, c).logpdf(X)
            for m, c in zip(params.means, params.covariances, strict=True)
        ]
    )
    log_a = np.log(params.transmat)
    total, start, trans = 0.0, np.zeros(K), np.zeros((K, K))
    resp = np.empty_like(log_b)
    for _, rows in recordings.slices():
        lb = log_b[rows]
        T = len(lb)
        fwd, bwd = np.empty((T, K)), np.zeros((T, K))
        fwd[0] = np.log(params.startprob) + lb[0]
        for t in range(1, T):
            fwd[t] = logsumexp(fwd[t - 1][:, None] + log_a, axis=0) + lb[t]
        for t in range(T - 2, -1, -1):
            bwd[t] = logsumexp(log_a + lb[t + 1] + bwd[t + 1], axis=1)
        log_p = logsumexp(fwd[-1])
        total += log_p
        resp[rows] = np.exp(fwd + bwd - log_p)
        start += resp[rows][0]
        for t in range(T - 1):
            trans += np.exp(fwd[t][:, None] + log_a + lb[t + 1] + bwd[t + 1] - log_p)
    return total, resp, start, trans


@pytest.mark.parametrize(("chunk_size", "block_size"), [(None, None), (5, 5), (3, 40)])
@pytest.mark.parametrize("n_states", [3, VECTORISED_STATES + 1])
def test_e_step_matches_log_space_reference(chunk_size, block_size, n_states):
    # 3 states: plain recursions, per-state moments; 9 states over 3 features: vectorised
    # recursions and moments from the pairwise products of the columns.
    rng = np.random.default_rng(3)
    X = rng.normal(size=(90, 3))
    recordings = random_recordings(rng, np.array([30, 1, 17, 2, 40]))
    means, covariances = random_gaussians(rng, n_states, 3)
    params = HMMParameters.gaussian(
        startprob=rng.dirichlet(np.ones(n_states) * 2),
        transmat=rng.dirichlet(np.ones(n_states) * 3, size=n_states),
        means=means * 0.5,
        covariances=covariances,
    )
    engine = EStepData(X, recordings, n_states, chunk_size=chunk_size, block_size=block_size)
    stats = e_step(engine, params)
    total, resp, start, trans = reference_e_step(X, recordings, params)
    Xs = X - stats.emission.shift
    assert stats.log_likelihood == pytest.approx(total, rel=1e-12)
    np.testing.assert_allclose(stats.start_counts, start, rtol=1e-10)
    np.testing.assert_allclose(stats.transition_counts, trans, rtol=1e-10)
    np.testing.assert_allclose(stats.emission.weights, resp.sum(axis=0), rtol=1e-10)
    np.testing.assert_allclose(stats.emission.first, resp.T @ Xs, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(
        stats.emission.second, np.einsum("nk,ni,nj->kij", resp, Xs, Xs), rtol=1e-9, atol=1e-12
    )


def test_heaviest_state_from_totals_matches_full_accumulation():
    # From the second E-step on, one state's moments are the totals minus the others'.
    rng = np.random.default_rng(8)
    X = rng.normal(size=(3000, 4)) + 5.0
    recordings = random_recordings(rng, np.array([1000, 2000]))
    params = initialize_parameters(X, recordings, 2, "kmeans", 1e-6, np.random.RandomState(0))
    engine = EStepData(X, recordings, 2)
    e_step(engine, params)
    assert engine.remainder is not None
    derived = e_step(engine, params)
    engine.remainder = None
    full = e_step(engine, params)
    for name in ("weights", "first", "second"):
        np.testing.assert_allclose(
            getattr(derived.emission, name), getattr(full.emission, name), rtol=1e-10, atol=1e-8
        )


@pytest.mark.parametrize("n_states", [2, 6, 12])
@pytest.mark.parametrize(
    ("method", "sub_chunk"), [("direct", None), ("pairs", None), ("pairs", 64), ("pairs", 1)]
)
def test_moment_sums_match_a_plain_sum(n_states, method, sub_chunk):
    rng = np.random.default_rng(9)
    columns = augmented_columns(rng.normal(size=(500, 5)))
    respT = rng.dirichlet(np.ones(n_states), size=500).T.copy()
    sums = MomentSums(n_states, 6, method=method, sub_chunk=sub_chunk)
    # chunks that are not multiples of the sub-chunk, one shorter than it, given as a view or
    # by their first row in the whole array
    sums.add(respT[:, :200], columns[:, :200])
    sums.add(respT[:, 200:230], columns, 200)
    sums.add(respT[:, 230:], columns, 230)
    expected = np.einsum("kt,at,bt->kab", respT, columns, columns)
    np.testing.assert_allclose(sums.result(), expected, rtol=1e-12, atol=1e-12)
    only = MomentSums(n_states, 6, states=[0, n_states - 1], method=method, sub_chunk=sub_chunk)
    only.add(respT, columns)
    np.testing.assert_allclose(only.result()[[0, -1]], expected[[0, -1]], rtol=1e-12)
    assert not only.result()[1:-1].any()


def test_moment_sums_reduce_directly_only_for_one_or_two_states():
    assert MomentSums(2, 10, states=[1]).method == "direct"
    assert MomentSums(3, 20, states=[0, 2]).method == "direct"
    assert MomentSums(1, 20).method == "direct"
    assert MomentSums(4, 5, states=[0, 1, 3]).method == "pairs"
    # sub-chunks of pairwise products stay within the cache-sized buffer
    sums = MomentSums(5, 20)
    assert sums.sub_chunk * 20 * 21 // 2 <= PAIR_BUFFER_VALUES
    with pytest.raises(ValueError, match="method"):
        MomentSums(2, 3, method="einsum")


@pytest.mark.parametrize("numpy_exp", [True, False])
@pytest.mark.parametrize("n_states", [1, 2, 5])
def test_scaled_densities_match_exp_of_log_densities(n_states, numpy_exp, monkeypatch):
    # both paths: NumPy's exp (AVX-512 CPUs) and the compiled one (elsewhere)
    monkeypatch.setattr(_kernels, "NUMPY_VECTOR_EXP", numpy_exp)
    rng = np.random.default_rng(12)
    n_features = 3
    means, covariances = random_gaussians(rng, n_states, n_features)
    if n_states > 1:
        means[1] = means[0] + 100.0  # far apart: frames of one state underflow near the other
    if n_states > 2:
        means[2], covariances[2] = means[1], covariances[1]  # a tie for the largest frame
    X = rng.normal(size=(300, n_features))
    X[:3] = means[0]
    X[3:6] = means[-1]
    precisions_chol = compute_precision_cholesky(covariances)
    factors, norms = stack_gaussians(means, precisions_chol)
    frames, top = np.empty((300, n_states)), np.empty(300)
    scaled_densities(factors @ augmented_columns(X), norms[:, 0], frames, top)

    log_prob = np.column_stack(
        [multivariate_normal(m, c).logpdf(X) for m, c in zip(means, covariances, strict=True)]
    )
    np.testing.assert_allclose(top, log_prob.max(axis=1), rtol=1e-12)
    difference = log_prob - log_prob.max(axis=1, keepdims=True)
    expected = np.where(difference < UNDERFLOW, 0.0, np.exp(difference))
    np.testing.assert_allclose(frames, expected, rtol=1e-10, atol=1e-300)
    assert np.all(frames.max(axis=1) == 1.0)  # exactly one at every row's largest
    if n_states > 1:
        assert np.any(difference < UNDERFLOW)  # the underflow branch was exercised
        assert np.all(frames[difference < UNDERFLOW] == 0.0)
    if n_states > 2:
        np.testing.assert_array_equal(frames[:, 1], frames[:, 2])


@pytest.mark.parametrize("n_states", [2, VECTORISED_STATES])
def test_forward_kernel_matches_plain_loop_and_restarts(n_states):
    rng = np.random.default_rng(10)
    frames = rng.random((40, n_states)) + 0.01
    transmat = rng.dirichlet(np.ones(n_states), size=n_states)
    transmat[:, 0] = 0.0  # state 0 can only start a recording
    transmat /= transmat.sum(axis=1, keepdims=True)
    startprob = np.full(n_states, 1.0 / n_states)
    frames[25] = 0.0
    frames[25, 0] = 1.0  # row 25 fits state 0 only: impossible after row 24
    starts, stops = np.array([0, 10]), np.array([10, 40])
    alpha, scale = np.empty_like(frames), np.empty(40)
    assert forward(frames, starts, stops, startprob, transmat, alpha, scale) == -np.inf
    assert np.isfinite(
        forward(frames, starts, stops, startprob, transmat, alpha, scale, restart=True)
    )
    expected = np.empty_like(frames)
    for lo, hi in zip(starts, stops, strict=True):
        prior = startprob
        for t in range(lo, hi):
            value = prior * frames[t]
            if value.sum() == 0:
                value = frames[t]
            expected[t] = value / value.sum()
            prior = expected[t] @ transmat
    np.testing.assert_allclose(alpha, expected, rtol=1e-13)
    assert alpha[25, 0] == 1.0


@pytest.mark.parametrize("n_states", [2, VECTORISED_STATES])
def test_lazy_forward_rows_are_proportional_and_last_rows_normalised(n_states):
    rng = np.random.default_rng(11)
    # Small frames: a row's total falls below RESCALE_BELOW every few dozen rows.
    frames = rng.uniform(0.01, 0.1, size=(1500, n_states))
    transmat = rng.dirichlet(np.ones(n_states), size=n_states)
    startprob = rng.dirichlet(np.ones(n_states))
    starts, stops = np.array([0, 7, 800]), np.array([7, 800, 1500])
    alpha, scale = np.empty_like(frames), np.empty(1500)
    log_likelihood = forward(frames, starts, stops, startprob, transmat, alpha, scale)
    assert log_likelihood == pytest.approx(np.log(scale).sum(), rel=1e-13)
    lazy_alpha, lazy_scale = np.empty_like(frames), np.empty(1500)
    lazy_log_likelihood = forward(
        frames, starts, stops, startprob, transmat, lazy_alpha, lazy_scale, lazy=True
    )
    assert lazy_log_likelihood == pytest.approx(log_likelihood, rel=1e-13)

    rescaled = lazy_scale != 1.0
    assert 10 < rescaled.sum() < 200  # rescaled only now and then
    assert rescaled[stops - 1].all()
    assert np.all(lazy_alpha.sum(axis=1)[rescaled] == pytest.approx(1.0, rel=1e-14))
    assert np.all(lazy_alpha.sum(axis=1) >= RESCALE_BELOW)
    np.testing.assert_allclose(
        lazy_alpha / lazy_alpha.sum(axis=1, keepdims=True), alpha, rtol=1e-12
    )
    for lo, hi in zip(starts, stops, strict=True):
        assert np.log(lazy_scale[lo:hi]).sum() == pytest.approx(
            np.log(scale[lo:hi]).sum(), rel=1e-13
        )
    frames[900] = 0.0  # an impossible row is still detected
    impossible = forward(frames, starts, stops, startprob, transmat, alpha, scale, lazy=True)
    assert impossible == -np.inf


def test_e_step_statistics_do_not_depend_on_chunking():
    rng = np.random.default_rng(4)
    X = rng.normal(size=(5000, 4))
    recordings = random_recordings(rng, np.array([1200, 3000, 800]))
    params = initialize_parameters(
        X, recordings, 4, "random_from_data", 1e-6, np.random.RandomState(0)
    )
    reference = e_step(EStepData(X, recordings, 4, chunk_size=10**6, block_size=10**6), params)
    for chunk_size, block_size in [(64, 64), (1000, 2500), (None, None)]:
        stats = e_step(EStepData(X, recordings, 4, chunk_size, block_size), params)
        assert stats.log_likelihood == pytest.approx(reference.log_likelihood, rel=1e-13)
        np.testing.assert_allclose(
            stats.transition_counts, reference.transition_counts, rtol=1e-11, atol=1e-10
        )
        for name in ("weights", "first", "second"):
            np.testing.assert_allclose(
                getattr(stats.emission, name),
                getattr(reference.emission, name),
                rtol=1e-11,
                atol=1e-10,
            )


def test_kept_forward_pass_gives_the_same_em_as_full_e_steps(monkeypatch):
    rng = np.random.default_rng(8)
    X = np.vstack([rng.normal(loc=c, size=(700, 3)) for c in (-2, 0, 2)])
    recordings = random_recordings(rng, np.array([900, 1200]))
    start = initialize_parameters(X, recordings, 3, "kmeans", 1e-6, np.random.RandomState(0))
    calls = []

    def run():
        calls.clear()
        return _em.baum_welch(
            X,
            recordings,
            start,
            n_iter=100,
            tol=1e-3,
            reg_covar=1e-6,
            callback=lambda n, *_: calls.append(n),
        )

    kept = run()
    assert kept.converged and kept.n_iter == len(calls) > 2
    monkeypatch.setattr(_em, "KEPT_FORWARD_VALUES", 0)
    full = run()
    assert (full.n_iter, full.converged) == (kept.n_iter, kept.converged)
    np.testing.assert_allclose(full.history, kept.history, rtol=1e-14)
    for name in ("startprob", "transmat", "means", "covariances"):
        np.testing.assert_allclose(getattr(full.parameters, name), getattr(kept.parameters, name))
    # history[-1] is the log-likelihood of the returned parameters
    assert kept.history[-1] == pytest.approx(
        _em.score_hmm(X, recordings, kept.parameters), rel=1e-13
    )


def test_kmeans_initialisation_is_reproducible_with_thread_limits():
    rng = np.random.default_rng(5)
    X = np.vstack([rng.normal(loc=c, size=(200, 2)) for c in (-4, 0, 4)])
    recordings = random_recordings(rng, np.array([600]))
    first = initialize_parameters(X, recordings, 3, "kmeans", 1e-6, np.random.RandomState(0))
    second = initialize_parameters(X, recordings, 3, "kmeans", 1e-6, np.random.RandomState(0))
    np.testing.assert_array_equal(first.means, second.means)
    assert sorted(np.round(first.means[:, 0]).tolist()) == [-4.0, 0.0, 4.0]


@pytest.mark.parametrize("n_outputs", [1, 2])
def test_gmr_readout_matches_einsum_reference(n_outputs):
    rng = np.random.default_rng(6)
    n_inputs, K = 3, 4
    means, covariances = random_gaussians(rng, K, n_inputs + n_outputs)
    emissions = FullCovariance(means, covariances)
    params = condition_on_inputs(
        np.full(K, 1 / K), rng.dirichlet(np.ones(K), size=K), emissions, n_inputs
    )
    X = rng.normal(size=(211, n_inputs))
    recordings = random_recordings(rng, np.array([100, 111]))
    alpha = filter_state_probabilities(X, recordings, params)
    np.testing.assert_allclose(
        filter_state_probabilities(X, recordings, params, chunk_size=16), alpha, rtol=1e-13
    )
    state_means = conditional_means(X, params)
    expected = np.einsum("nf,kof->nko", X, params.coef) + params.intercept
    np.testing.assert_allclose(state_means, expected, rtol=1e-12, atol=1e-12)
    estimate, std = mix_estimates(alpha, state_means, params, return_std=True)
    expected_estimate = np.einsum("nk,nko->no", alpha, expected)
    spread = expected - expected_estimate[:, None, :]
    within = alpha @ np.diagonal(params.conditional_covariances, axis1=1, axis2=2)
    expected_std = np.sqrt(within + np.einsum("nk,nko->no", alpha, spread**2))
    np.testing.assert_allclose(estimate, expected_estimate, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(std, expected_std, rtol=1e-12)


def test_statistics_of_parts_merge_into_those_of_the_whole():
    # What cluster workers rely on: E-steps over disjoint recordings, summed.
    rng = np.random.default_rng(11)
    X = rng.normal(size=(900, 3)) + 2.0
    lengths = np.array([200, 300, 150, 250])
    recordings = random_recordings(rng, lengths)
    params = initialize_parameters(X, recordings, 3, "kmeans", 1e-6, np.random.RandomState(0))
    shift = X.mean(axis=0)

    def statistics(rows, part_lengths):
        columns = Columns(augmented_columns(X[rows], shift), shift)
        return e_step(EStepData(columns, random_recordings(rng, part_lengths), 3), params)

    whole = statistics(slice(None), lengths)
    merged = statistics(slice(0, 500), lengths[:2]).merge(statistics(slice(500, None), lengths[2:]))
    assert merged.log_likelihood == pytest.approx(whole.log_likelihood, rel=1e-13)
    for name in ("start_counts", "transition_counts"):
        np.testing.assert_allclose(getattr(merged, name), getattr(whole, name), rtol=1e-11)
    for name in ("weights", "first", "second"):
        np.testing.assert_allclose(
            getattr(merged.emission, name), getattr(whole.emission, name), rtol=1e-10, atol=1e-9
        )
