"""The causal first-order read-out: GMR estimates smoothed along each recording.

The GMR estimate jumps with the state probabilities; a driver's torque does not. The read-out
``s_t = a s_{t-1} + (1 - a) e_t`` of the GMR estimates ``e_t`` (``s`` starts at the first
estimate of every recording) is causal, costs one multiply-add per sample, and is the same
in ``predict``, :class:`~skhmmgmr.FilterStream` and the generated C. The decay ``a`` in
``[0, 1)`` is ``exp(-1 / tau)`` for a time constant ``tau`` in rows; ``a = 0`` is the GMR
estimate itself.

"auto" (:func:`weakest_decay`) chooses the weakest read-out whose estimate of the training
recordings is no rougher than the measured outputs; none when the estimate already is, or
when that read-out would change nothing that matters (:func:`changes_little`): the estimate's
roughness by less than 1 % and no recording's accuracy by 0.1 percentage point. A model
without a read-out is written in format version 2, which older releases read.

Roughness is the thesis' smoothness measure (:func:`skhmmgmr.metrics.smoothness_score`), the
standard deviation of the difference between consecutive rows per recording, averaged over
recordings: a sampling period scales it, so comparing two series needs none.
"""

import math
import numbers

import numpy as np
from scipy.signal import lfilter

# The bisection of the decay stops when the bracket is this narrow; it is also the largest
# decay considered (a time constant of about 1e6 rows).
_DECAY_TOLERANCE = 1e-6
#: The longest time constant [rows] a read-out may have: that of the largest decay "auto"
#: considers, and about the longest whose decay single precision (the C export's float32)
#: still tells from one (a float just below one is 6e-8 from it).
MAX_TIME_CONSTANT = 1e6
#: What a read-out must change to matter, on the training recordings: the accuracy of a
#: recording by this many percentage points, or the roughness of the estimate by this share.
#: "auto" keeps no read-out that changes neither (:func:`changes_little`).
NEGLIGIBLE_ACCURACY_CHANGE = 0.1
NEGLIGIBLE_ROUGHNESS_CHANGE = 0.01


def decay_of(time_constant):
    """Decay ``exp(-1 / tau)`` of a time constant ``tau`` >= 0 in rows (0 for 0)."""
    return math.exp(-1.0 / time_constant) if time_constant > 0 else 0.0


def fixed_decay(output_smoothing):
    """Decay of a fixed ``output_smoothing`` (None or a time constant in rows in
    ``[0, MAX_TIME_CONSTANT]``); ValueError naming the parameter for anything else ("auto" is
    chosen in ``fit``)."""
    if output_smoothing is None:
        return 0.0
    if (
        isinstance(output_smoothing, bool)
        or not isinstance(output_smoothing, numbers.Real)
        or not 0 <= output_smoothing <= MAX_TIME_CONSTANT  # NaN and ints beyond a float too
    ):
        raise ValueError(
            "output_smoothing must be None, 'auto' or a time constant in rows in "
            f"[0, {MAX_TIME_CONSTANT:g}]; got {output_smoothing!r}"
        )
    return decay_of(float(output_smoothing))


def time_constant_of(decay):
    """Time constant in rows of a decay in [0, 1) (0 for 0)."""
    return -1.0 / math.log(decay) if decay > 0 else 0.0


def smooth_outputs(estimates, recordings, decay, holds=None):
    """``estimates`` (n_samples, n_outputs), in filter order, through the first-order read-out
    of decay ``decay[j]`` for output ``j``, restarted at every recording; a new array (the
    input itself when every decay is 0). ``holds`` (a
    :class:`~skhmmgmr._hmm._holds.HeldRows`): the read-out runs over the accepted rows only,
    the held ones are left as they are (the caller carries them)."""
    decay = np.asarray(decay, dtype=float)
    if not np.any(decay):
        return estimates
    if holds is not None:
        rows = holds.accepted_rows
        smoothed = np.array(estimates, dtype=float)
        smoothed[rows] = smooth_outputs(estimates[rows], holds.accepted, decay)
        return smoothed
    smoothed = np.array(estimates, dtype=float)
    for j, a in enumerate(decay.tolist()):
        if a > 0:
            for _, rows in recordings.slices():
                smoothed[rows, j] = _first_order(smoothed[rows, j], a)
    return smoothed


def _first_order(values, decay):
    smoothed = np.array(values, dtype=float)
    if values.size > 1:
        # s_0 = e_0 exactly; the state carried into row 1 is decay * s_0.
        smoothed[1:] = lfilter([1.0 - decay], [1.0, -decay], values[1:], zi=[decay * values[0]])[0]
    return smoothed


def roughness(values, recordings):
    """Mean over recordings (of at least three rows) of the standard deviation of the
    differences of ``values`` (1-D, filter order), NaN differences left out; NaN if none."""
    spreads = []
    for _, rows in recordings.slices():
        steps = np.diff(values[rows])
        steps = steps[np.isfinite(steps)]
        if steps.size >= 2:
            spreads.append(np.std(steps))
    return float(np.mean(spreads)) if spreads else math.nan


def weakest_decay(estimates, targets, recordings):
    """Per output, the smallest decay whose read-out of ``estimates`` is no rougher than
    ``targets`` on ``recordings`` (both (n_samples, n_outputs), filter order): 0 when the
    estimates already are, when the targets' roughness cannot be measured, or when that
    read-out changes nothing that matters (:func:`changes_little`). Found by bisection: the
    roughness of a first-order low-pass falls as its decay grows (its gain
    ``(1 - a) / |1 - a e^{-iw}|`` falls at every frequency)."""
    decays = np.zeros(estimates.shape[1])
    for j in range(estimates.shape[1]):
        target = roughness(targets[:, j], recordings)
        if not math.isfinite(target):
            continue

        def too_rough(decay, j=j, target=target):
            column = estimates[:, j]
            if decay > 0:
                column = smooth_outputs(column[:, np.newaxis], recordings, [decay])[:, 0]
            return roughness(column, recordings) > target

        if not too_rough(0.0):
            continue
        low, high = 0.0, 1.0 - _DECAY_TOLERANCE
        if too_rough(high):
            decays[j] = high
            continue
        while high - low > _DECAY_TOLERANCE:
            middle = 0.5 * (low + high)
            low, high = (middle, high) if too_rough(middle) else (low, middle)
        if not changes_little(estimates[:, j], targets[:, j], recordings, high):
            decays[j] = high
    return decays


def changes_little(estimate, target, recordings, decay):
    """Whether the read-out of decay ``decay`` changes nothing that matters in the estimate
    of one output (1-D, filter order) against its measured ``target``: it lowers the
    estimate's roughness by less than :data:`NEGLIGIBLE_ROUGHNESS_CHANGE` (1 %), and in every
    recording whose target varies it moves the estimate by less than
    :data:`NEGLIGIBLE_ACCURACY_CHANGE` percent (0.1 %) of the target's standard deviation
    (root mean square), so that no recording's accuracy ``(1 - RMSE / SD) * 100`` moves by
    0.1 point (the RMSE moves by at most that root mean square). ``False`` when no recording
    can say so."""
    smoothed = smooth_outputs(estimate[:, np.newaxis], recordings, [decay])[:, 0]
    before = roughness(estimate, recordings)
    if not roughness(smoothed, recordings) > (1.0 - NEGLIGIBLE_ROUGHNESS_CHANGE) * before:
        return False
    change = smoothed - estimate
    measured = False
    for _, rows in recordings.slices():
        observed = np.isfinite(target[rows]) & np.isfinite(change[rows])
        if np.count_nonzero(observed) < 2:
            continue
        spread = np.std(target[rows][observed])
        if not spread > 0:
            continue
        moved = math.sqrt(np.mean(change[rows][observed] ** 2))
        if moved * 100.0 >= NEGLIGIBLE_ACCURACY_CHANGE * spread:
            return False
        measured = True
    return measured


def ahead_weights(transmat, decay, steps):
    """How the read-out of decay ``decay`` is forecast ``steps`` rows ahead:
    ``(carried, weights)`` such that the forecast is ``carried * s_t + (1 - carried) * E``,
    where ``s_t`` is the read-out now and ``E`` the estimate under the state probabilities
    ``alpha_t @ weights`` (``weights`` row-stochastic).

    The read-out ahead is ``a^h s_t + (1 - a) sum_{j=1..h} a^(h-j) e_{t+j}``, and the forecast
    of ``e_{t+j}`` mixes the states by ``alpha_t A^j``; so ``carried = a^h`` and ``weights``
    is ``V_h = sum_j a^(h-j) A^j`` scaled to unit rows. ``[A^h, V_h] = [I, 0] B^h`` with
    ``B = [[A, A], [0, a I]]``, a power taken by repeated squaring.
    """
    n_states = transmat.shape[0]
    if steps == 0 or decay == 0:
        return (1.0 if steps == 0 else 0.0), None
    block = np.zeros((2 * n_states, 2 * n_states))
    block[:n_states, :n_states] = transmat
    block[:n_states, n_states:] = transmat
    block[n_states:, n_states:] = decay * np.eye(n_states)
    power, remaining = np.eye(2 * n_states), steps
    while remaining:
        if remaining & 1:
            power = power @ block
        remaining >>= 1
        if remaining:
            block = block @ block
    weights = np.clip(power[:n_states, n_states:], 0.0, None)
    weights /= weights.sum(axis=1, keepdims=True)
    return decay**steps, weights
