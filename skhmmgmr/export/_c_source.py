"""``<name>.c``: the causal filter of a fitted model, sample by sample.

The generated code runs what :class:`~skhmmgmr.FilterStream` runs (METHOD.md section 2), on
parameters written into the source as ``static const`` arrays (:mod:`._c_code`):

1. the derived inputs of a torque pipeline (:class:`~skhmmgmr.SteeringFeatures`): the friction
   input ``tanh(v / friction_velocity)`` of the velocity (or ``tanh(v / w_j)`` for every width
   of a friction basis), low-pass filtered when the transformer has ``velocity_filter``
   (started at the recording's first finite velocity; a non-finite one leaves the filter
   alone and the next is taken in over the whole time since the last, as
   :func:`~skhmmgmr.torque_pipeline.low_pass`), the hysteresis inputs of the plays on the
   angle (``friction_angle``), and the signed powers ``sign(x) |x|^p``;
2. the standardised inputs ``z``; a non-finite one holds the sample (return 1), so do
   standardised inputs out of range (return 2: the outlier policy of
   :mod:`skhmmgmr._hmm._holds`, absolute values summing to 1e100 or more, 1e30 in ``float``);
3. the log input density of every state, ``norm_k - |z @ G_k + o_k|^2``, ``G_k`` upper
   triangular (each row an axpy over the columns from its own on); with a shared covariance
   ``z @ G`` is computed once. A sample whose largest log-density is not finite (or a NaN
   one) is out of range, and one whose log-densities are all below the model's
   ``min_log_density``, when set, is held: return 2;
4. the normalised forward step with the restart rule, in log space: densities relative to the
   best state (``exp(log b_k - max log b)``, exactly 1 there, so that none underflows to a
   hold), ``alpha ∝ prior * b``, from ``b`` alone when every product is zero, then ``prior =
   A^T alpha`` for the next sample;
5. the states' conditional output means and their mixture, and on request the predictive std
   (law of total variance) at the last accepted sample, or the prior mixture before any;
6. for a model whose read-out smooths, the first-order read-out of the mixture
   (``output_decay``, :mod:`skhmmgmr._hmm._readout`).

A held sample leaves the filter state unchanged and returns the last estimate. The state is one
struct the caller owns (no heap, no globals written), so several recordings can be filtered at
once. All of it runs in the filter's arithmetic, ``double`` or ``float`` (``dtype="float32"``),
its inputs and estimates included.
"""

from .._version import __version__
from ._c_code import density_code, derived_code, helpers, means_code, parameters
from ._c_text import TYPES, number


def _gather(spec, dtype):
    """``(statements, array)``: the statements that gather the raw and derived inputs into
    ``x`` and the array ``z`` is standardised from (``x``, or ``inputs`` without derived)."""
    if not spec.derived.n_derived:
        return "", "inputs"
    real = TYPES[dtype]["real"]
    return (
        f"""\
    {real} x[{spec.n_inputs}];
    for (i = 0; i < {spec.n_raw_inputs}; ++i) {{
        x[i] = inputs[i];
    }}
{derived_code(spec, dtype)}""",
        "x",
    )


def _read_out(spec):
    """``(before, statement)``: what the update remembers before the step, and the statement
    writing ``state->estimate[o]`` from the mixture ``mixed``."""
    if not spec.smoothed:
        return "", "        state->estimate[o] = mixed * output_scale[o] + output_center[o];"
    # the first-order read-out, from the GMR estimate of a recording's first sample
    return (
        "    const int started = state->started;\n",
        """\
        const REAL gmr = mixed * output_scale[o] + output_center[o];
        state->estimate[o] = started ? output_gain[o] * gmr + output_decay[o] * state->estimate[o]
                                     : gmr;""",
    )


def _held_test(spec):
    """The condition under which a sample with finite standardised inputs is held (return 2)."""
    in_range = "isfinite(top) && !isnan(log_sum)"
    if spec.min_log_density is None:
        return f"!({in_range})"
    return f"!(top >= min_log_density && {in_range})"


def source(spec, name, dtype):
    """Text of ``<name>.c``."""
    types = TYPES[dtype]
    real, exp, sqrt, fabs = types["real"], types["exp"], types["sqrt"], types["fabs"]
    n_states, n_outputs, n_inputs, n_raw = (
        spec.n_states,
        spec.n_outputs,
        spec.n_inputs,
        spec.n_raw_inputs,
    )
    zero = number(0.0, dtype)
    velocity_reset = ""
    if spec.derived.velocity_decay is not None:
        velocity_reset = f"    state->velocity = {zero};\n    state->velocity_since = {zero};\n"
    if spec.derived.slow_decay is not None:
        velocity_reset += (
            f"    state->slow_velocity = {zero};\n    state->slow_velocity_since = {zero};\n"
        )
    if spec.derived.hysteresis is not None:
        velocity_reset += "    state->play_started = 0;\n"
    gather, source_of_z = _gather(spec, dtype)
    remember_started, read_out = _read_out(spec)
    read_out = read_out.replace("REAL", real)
    upper = name.upper()
    return f"""\
/* {name}.c: causal HMM-GMR filter of a fitted skhmmgmr model (C99), see {name}.h.
 *
 * Generated by skhmmgmr {__version__} (skhmmgmr.export.write_c); do not edit: export again.
 * The model's parameters are in the standardised units the model works in.
 */
#include <math.h>
#include <stddef.h>

#include "{name}.h"

/* Standardised inputs whose absolute values sum to this or more are out of range. */
static const {real} max_standardised = {number(types["max_standardised"], dtype)};

{parameters(spec, dtype)}{helpers(spec, name, dtype)}
int {name}_n_inputs(void)
{{
    return {n_raw};
}}

int {name}_n_outputs(void)
{{
    return {n_outputs};
}}

const char *{name}_input_name(int i)
{{
    return (i >= 0 && i < {n_raw}) ? input_names[i] : NULL;
}}

size_t {name}_state_size(void)
{{
    return sizeof({name}_state);
}}

void {name}_reset({name}_state *state)
{{
    int k;
    for (k = 0; k < {n_states}; ++k) {{
        state->alpha[k] = startprob[k];
        state->prior[k] = startprob[k];
    }}
    for (k = 0; k < {n_states * n_outputs}; ++k) {{
        state->means[k] = 0;
    }}
    for (k = 0; k < {n_outputs}; ++k) {{
        state->estimate[k] = prior_estimate[k];
    }}
    state->started = 0;
{velocity_reset}}}

/* Log input density of every state at the standardised inputs z. */
static void log_densities(const {real} *z, {real} *log_prob)
{{
{density_code(spec, real)}
}}

/* Every state's conditional output means (standardised), means[k * n_outputs + o]. */
static void output_means(const {real} *z, {real} *means)
{{
{means_code(spec, real)}
}}

/* Predictive std at the last accepted sample (law of total variance), or the prior's. */
static void write_std(const {name}_state *state, {real} *std)
{{
    int k, o;
    if (!state->started) {{
        for (o = 0; o < {n_outputs}; ++o) {{
            std[o] = prior_std[o];
        }}
        return;
    }}
    for (o = 0; o < {n_outputs}; ++o) {{
        {real} mean = 0, within = 0, between = 0;
        for (k = 0; k < {n_states}; ++k) {{
            mean += state->alpha[k] * state->means[k * {n_outputs} + o];
        }}
        for (k = 0; k < {n_states}; ++k) {{
            const {real} spread = state->means[k * {n_outputs} + o] - mean;
            within += state->alpha[k] * conditional_variances[k * {n_outputs} + o];
            between += state->alpha[k] * (spread * spread);
        }}
        std[o] = {sqrt}(within + between) * output_scale[o];
    }}
}}

static int held(const {name}_state *state, int code, {real} *estimate, {real} *std)
{{
    int o;
    for (o = 0; o < {n_outputs}; ++o) {{
        estimate[o] = state->estimate[o];
    }}
    if (std != NULL) {{
        write_std(state, std);
    }}
    return code;
}}

int {name}_update({name}_state *state, const {real} *inputs, {real} *estimate, {real} *std)
{{
    {real} z[{n_inputs}], log_prob[{n_states}], frames[{n_states}], alpha[{n_states}];
    {real} top, inverse, total = 0, magnitude = 0, log_sum = 0;
    int i, k, o;
{gather}
    for (i = 0; i < {n_inputs}; ++i) {{
        const {real} value = ({source_of_z}[i] - input_center[i]) / input_scale[i];
        if (!isfinite(value)) {{
            return held(state, {upper}_NON_FINITE, estimate, std);
        }}
        magnitude += {fabs}(value);
        z[i] = value;
    }}
    if (!(magnitude < max_standardised)) {{
        return held(state, {upper}_OUTLIER, estimate, std);
    }}
    log_densities(z, log_prob);
    top = log_prob[0];
    for (k = 0; k < {n_states}; ++k) {{
        top = log_prob[k] > top ? log_prob[k] : top;
        log_sum += log_prob[k];
    }}
    if ({_held_test(spec)}) {{
        return held(state, {upper}_OUTLIER, estimate, std);
    }}
    /* densities relative to the best state (exactly 1 there) times the predicted probabilities */
    for (k = 0; k < {n_states}; ++k) {{
        frames[k] = {exp}(log_prob[k] - top);
        alpha[k] = state->prior[k] * frames[k];
        total += alpha[k];
    }}
    if (!(total > 0)) {{
        /* no state the transitions allow explains the sample: restart from its densities */
        total = 0;
        for (k = 0; k < {n_states}; ++k) {{
            alpha[k] = frames[k];
            total += alpha[k];
        }}
    }}
    inverse = 1 / total;
    for (k = 0; k < {n_states}; ++k) {{
        state->alpha[k] = alpha[k] * inverse;
    }}
    for (k = 0; k < {n_states}; ++k) {{
        {real} next = 0;
        for (i = 0; i < {n_states}; ++i) {{
            next += transmat_t[k * {n_states} + i] * state->alpha[i];
        }}
        state->prior[k] = next;
    }}
    output_means(z, state->means);
{remember_started}    state->started = 1;
    for (o = 0; o < {n_outputs}; ++o) {{
        {real} mixed = 0;
        for (k = 0; k < {n_states}; ++k) {{
            mixed += state->alpha[k] * state->means[k * {n_outputs} + o];
        }}
{read_out}
        estimate[o] = state->estimate[o];
    }}
    if (std != NULL) {{
        write_std(state, std);
    }}
    return {upper}_FILTERED;
}}
"""
