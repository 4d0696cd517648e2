"""The parts of ``<name>.c`` that depend on the model: its parameters as ``static const``
arrays, the derived inputs of a torque pipeline, the log-densities and the state output means.

Every number and every operation is of the filter's arithmetic (``double``, or ``float`` for
``dtype="float32"``: ``float`` literals and ``expf``, ``tanhf``, ``powf``, ``fabsf``, so that no
value is promoted to ``double`` on the way); the friction inputs are ``tanh(v /
friction_velocity)`` for one band, ``tanh(v / friction_widths[j])`` for every width of a
basis, the velocity (filtered or not) read once, then the same of the slow velocity (its own
filter, ``slow_low_pass``) when there is one; the hysteresis inputs are ``(a - p_j) /
friction_radii[j]`` of the plays on the angle ``a`` (their positions in the state; with a
lead, ``a`` is the angle plus ``angle_lead`` times the unfiltered velocity); a signed power
``sign(x) |x|^p`` is a chain of multiplications in single precision up to
:data:`CHAINED_POWERS`, ``pow``/``powf`` beyond (and for ``p > 2`` in double precision, as
:class:`~skhmmgmr.SteeringFeatures` computes it).
"""

import numpy as np

from ._c_text import TYPES, array, check_float32, number, string

# Signed powers up to this are multiplication chains in single precision.
CHAINED_POWERS = 8


def _triangle(gating):
    """The upper triangle of every state's rows, row by row (row ``i`` from column ``i``)."""
    n_inputs = gating.shape[-1]
    return np.concatenate([g[i, i:] for g in gating for i in range(n_inputs)])


def _named_parameters(spec):
    """``(name, values, comment)`` of every array and constant of ``<name>.c``."""
    gating = spec.gating[:1] if spec.shared_gating else spec.gating
    if spec.triangular:
        gating_values, layout = _triangle(gating), "upper triangle, row by row"
    else:
        gating_values, layout = gating, "row by row"
    parts = [
        ("input_center", spec.input_center, None),
        ("input_scale", spec.input_scale, None),
        ("output_center", spec.output_center, None),
        ("output_scale", spec.output_scale, None),
        ("prior_estimate", spec.prior_estimate, "output mean and std before any sample"),
        ("prior_std", spec.prior_std, None),
        ("startprob", spec.startprob, None),
        ("transmat_t", spec.transmat.T, "row j: probabilities of entering state j from each"),
        ("gating", gating_values, f"weights of z_i in the density terms ({layout})"),
        ("offsets", spec.offsets, "constant of every density term"),
        ("norms", spec.norms[:1] if spec.shared_gating else spec.norms, "log normalisers"),
        ("coef", spec.coef[:1] if spec.shared_coef else spec.coef, "output means: coef z + b"),
        ("intercept", spec.intercept, None),
        ("conditional_variances", spec.conditional_variances, None),
    ]
    if spec.smoothed:
        decay = spec.output_decay
        parts.append(("output_decay", decay, "first-order read-out"))
        parts.append(("output_gain", 1.0 - decay, None))
    constants = []
    derived = spec.derived
    if derived.friction is not None and len(derived.friction[1]) == 1:
        constants.append(("friction_velocity", derived.friction[1][0]))
    elif derived.friction is not None:
        parts.append(("friction_widths", np.asarray(derived.friction[1]), "friction basis"))
    if derived.hysteresis is not None:
        radii = np.asarray(derived.hysteresis[1])
        parts.append(("friction_radii", radii, "half-widths of the plays (hysteresis inputs)"))
    if derived.angle_lead is not None:
        constants.append(("angle_lead", derived.angle_lead[1]))
    if derived.velocity_decay is not None:
        constants.append(("velocity_decay", derived.velocity_decay))
        constants.append(("velocity_gain", 1.0 - derived.velocity_decay))
    if derived.slow_decay is not None:
        constants.append(("slow_velocity_decay", derived.slow_decay))
        constants.append(("slow_velocity_gain", 1.0 - derived.slow_decay))
    if spec.min_log_density is not None:
        constants.append(("min_log_density", spec.min_log_density))
    return parts, constants


def parameters(spec, dtype):
    """The ``static const`` arrays and constants of ``<name>.c`` (the input names first)."""
    arrays, constants = _named_parameters(spec)
    if dtype == "float32":
        check_float32({name: values for name, values, _ in arrays} | dict(constants))
    real = TYPES[dtype]["real"]
    names = [f"input_name_{i}" for i in range(spec.n_raw_inputs)]
    parts = [string(text, name) for text, name in zip(spec.input_names, names, strict=True)]
    listed = ",\n    ".join(names)
    parts.append(
        f"static const char *const input_names[{spec.n_raw_inputs}] = {{\n    {listed}\n}};\n"
    )
    parts += [array(name, dtype, values, comment) for name, values, comment in arrays]
    parts += [
        f"static const {real} {name} = {number(value, dtype)};\n" for name, value in constants
    ]
    return "\n".join(parts)


def _power(x, power, dtype):
    """C expression of ``|x|^power`` in ``dtype``."""
    types = TYPES[dtype]
    size = f"{types['fabs']}({x})"
    if power == 2 or (dtype == "float32" and power <= CHAINED_POWERS):
        return " * ".join([size] * power)
    return f"{types['pow']}({size}, {number(power, dtype)})"


def derived_code(spec, dtype):
    """Statements writing the derived inputs into ``x[n_raw:]`` (and the velocity filter)."""
    derived, column, tanh = spec.derived, spec.n_raw_inputs, TYPES[dtype]["tanh"]
    lines = []
    if derived.friction is not None:
        velocity = f"inputs[{derived.friction[0]}]"
        if derived.velocity_decay is not None:
            velocity = f"low_pass(state, {velocity})"
        widths = derived.friction[1]
        slow = None
        if derived.slow_decay is not None:  # the slow filter's friction inputs follow
            slow = f"slow_low_pass(state, inputs[{derived.friction[0]}])"
        if len(widths) == 1:
            lines.append(f"    x[{column}] = {tanh}({velocity} / friction_velocity);")
            if slow is not None:
                lines.append(f"    x[{column + 1}] = {tanh}({slow} / friction_velocity);")
        else:  # a basis: the velocity read once (the filter steps once), every width
            real = TYPES[dtype]["real"]
            lines.append(f"    {{\n        const {real} velocity = {velocity};")
            lines += [
                f"        x[{column + j}] = {tanh}(velocity / friction_widths[{j}]);"
                for j in range(len(widths))
            ]
            if slow is not None:
                lines.append(f"        const {real} slow = {slow};")
                first = column + len(widths)
                lines += [
                    f"        x[{first + j}] = {tanh}(slow / friction_widths[{j}]);"
                    for j in range(len(widths))
                ]
            lines.append("    }")
        column += len(widths) * (1 if slow is None else 2)
    if derived.hysteresis is not None:
        angle = f"inputs[{derived.hysteresis[0]}]"
        if derived.angle_lead is not None:
            angle += f" + angle_lead * inputs[{derived.angle_lead[0]}]"
        lines.append(f"    play(state, {angle}, x + {column});")
        column += len(derived.hysteresis[1])
    for position, power in derived.powers:
        magnitude = _power(f"inputs[{position}]", power, dtype)
        lines.append(f"    x[{column}] = signum(inputs[{position}]) * ({magnitude});")
        column += 1
    return "\n".join(lines)


_LOW_PASS = """
/* The velocity through the first-order low-pass filter of SteeringFeatures (low_pass): the
 * first finite value is taken as it is, the next after g non-finite ones over g + 1 periods. */
static @REAL@ @F@low_pass(@NAME@_state *state, @REAL@ velocity)
{
    @REAL@ lapse;
    if (!isfinite(velocity)) {
        if (state->@F@velocity_since > @ZERO@) {
            state->@F@velocity_since += @ONE@;
        }
        return velocity;
    }
    if (state->@F@velocity_since == @ZERO@) {
        state->@F@velocity = @F@velocity_gain * velocity + @F@velocity_decay * velocity;
    } else if (state->@F@velocity_since == @ONE@) {
        state->@F@velocity = @F@velocity_gain * velocity + @F@velocity_decay * state->@F@velocity;
    } else {
        lapse = @POW@(@F@velocity_decay, state->@F@velocity_since);
        state->@F@velocity = @F@velocity_gain * velocity
                          + (lapse * state->@F@velocity + (@F@velocity_decay - lapse) * velocity);
    }
    state->@F@velocity_since = @ONE@;
    return state->@F@velocity;
}
"""

_PLAY = """
/* The hysteresis inputs (angle - p_j) / r_j of SteeringFeatures (friction_angle), the plays
 * p_j following the angle at most r_j behind it from the recording's first finite angle; a
 * non-finite angle leaves them alone (and holds the sample). */
static void play(@NAME@_state *state, @REAL@ angle, @REAL@ *out)
{
    int j;
    if (!isfinite(angle)) {
        for (j = 0; j < @N_PLAYS@; ++j) {
            out[j] = angle;
        }
        return;
    }
    if (!state->play_started) {
        for (j = 0; j < @N_PLAYS@; ++j) {
            state->play[j] = angle;
        }
        state->play_started = 1;
    }
    for (j = 0; j < @N_PLAYS@; ++j) {
        if (state->play[j] < angle - friction_radii[j]) {
            state->play[j] = angle - friction_radii[j];
        } else if (state->play[j] > angle + friction_radii[j]) {
            state->play[j] = angle + friction_radii[j];
        }
        out[j] = (angle - state->play[j]) / friction_radii[j];
    }
}
"""

_SIGNUM = """
static @REAL@ signum(@REAL@ value)
{
    return (@REAL@)((value > @ZERO@) - (value < @ZERO@));
}
"""


def helpers(spec, name, dtype):
    """The static functions the derived inputs need: the velocity filters, the plays and the
    sign."""
    types = TYPES[dtype]
    hysteresis = spec.derived.hysteresis
    words = {
        "NAME": name,
        "REAL": types["real"],
        "POW": types["pow"],
        "ZERO": number(0.0, dtype),
        "ONE": number(1.0, dtype),
        "N_PLAYS": str(0 if hysteresis is None else len(hysteresis[1])),
    }
    text = ""
    if spec.derived.velocity_decay is not None:
        text += _LOW_PASS.replace("@F@", "")
    if spec.derived.slow_decay is not None:  # the slow velocity: its own filter and state
        text += _LOW_PASS.replace("@F@", "slow_")
    if hysteresis is not None:
        text += _PLAY
    if spec.derived.powers:
        text += _SIGNUM
    for word, value in words.items():
        text = text.replace(f"@{word}@", value)
    return text


def density_code(spec, real):
    """Body of ``log_densities``: ``log_prob[k]`` for every state."""
    n_states, n_inputs = spec.n_states, spec.n_inputs
    start = "i" if spec.triangular else "0"
    width = f"{n_inputs} - i" if spec.triangular else f"{n_inputs}"
    whiten = f"""\
        for (i = 0; i < {n_inputs}; ++i) {{
            const {real} zi = z[i];
            for (j = {start}; j < {n_inputs}; ++j) {{
                terms[j] += zi * weights[j - {start}];
            }}
            weights += {width};
        }}"""
    if spec.shared_gating:
        return f"""\
    {real} whitened[{n_inputs}];
    const {real} *weights = gating;
    int i, j, k;
    for (j = 0; j < {n_inputs}; ++j) {{
        whitened[j] = 0;
    }}
    {{
        {real} *terms = whitened;
{whiten}
    }}
    for (k = 0; k < {n_states}; ++k) {{
        {real} total = norms[0];
        for (j = 0; j < {n_inputs}; ++j) {{
            const {real} term = whitened[j] + offsets[k * {n_inputs} + j];
            total -= term * term;
        }}
        log_prob[k] = total;
    }}"""
    return f"""\
    {real} terms[{n_inputs}];
    const {real} *weights = gating;
    int i, j, k;
    for (k = 0; k < {n_states}; ++k) {{
        {real} total = norms[k];
        for (j = 0; j < {n_inputs}; ++j) {{
            terms[j] = offsets[k * {n_inputs} + j];
        }}
{whiten}
        for (j = 0; j < {n_inputs}; ++j) {{
            total -= terms[j] * terms[j];
        }}
        log_prob[k] = total;
    }}"""


def means_code(spec, real):
    """Body of ``output_means``: ``means[k * n_outputs + o]`` for every state."""
    n_states, n_outputs, n_inputs = spec.n_states, spec.n_outputs, spec.n_inputs
    if spec.shared_coef:
        return f"""\
    int i, k, o;
    for (o = 0; o < {n_outputs}; ++o) {{
        {real} slope = 0;
        for (i = 0; i < {n_inputs}; ++i) {{
            slope += coef[o * {n_inputs} + i] * z[i];
        }}
        for (k = 0; k < {n_states}; ++k) {{
            means[k * {n_outputs} + o] = slope + intercept[k * {n_outputs} + o];
        }}
    }}"""
    return f"""\
    int i, k;
    for (k = 0; k < {n_states * n_outputs}; ++k) {{
        {real} mean = intercept[k];
        for (i = 0; i < {n_inputs}; ++i) {{
            mean += coef[k * {n_inputs} + i] * z[i];
        }}
        means[k] = mean;
    }}"""
