"""The core of the FMI wrapper, the same C text for both FMI versions (:mod:`._fmu_wrapper`).

In plain C types over the public API of the generated filter: one heap-allocated instance per
``fmi2Instantiate`` / ``fmi3InstantiateCoSimulation`` (the filter state, the inputs, the last
estimate, std and status, the time, the mode, the logger), its start (inputs at their start
values 0, the filter reset, the outputs at the prior mixture's mean and std), the step (one
update of the filter per communication step of the sampling period; a step of another size is
refused, logged, and changes nothing), the moves between modes, and reading and writing
variables by value reference. Each version's shell (``_fmu_fmi2``, ``_fmu_fmi3``) defines
``emit``, the one function the core declares and leaves to it, and calls the rest.

:data:`CORE` is a :meth:`str.format` template (C braces doubled): the sizes and value
references of the model description, the filter's name, the instantiation token, the sampling
period and the logger fields of the version (``environment``).
"""

CORE = r"""
#define N_INPUTS {n_inputs}
#define N_OUTPUTS {n_outputs}
#define FIRST_INPUT {first_input}
#define FIRST_ESTIMATE {first_estimate}
#define FIRST_STD {first_std}
#define STATUS_REFERENCE {status_reference}
#define TIME_REFERENCE {time_reference}
#define NO_SAMPLE ({no_sample})

/* The filter's sizes are those the model description declares (a compile-time check). */
typedef char inputs_as_declared[{upper}_N_INPUTS == N_INPUTS ? 1 : -1];
typedef char outputs_as_declared[{upper}_N_OUTPUTS == N_OUTPUTS ? 1 : -1];

static const char token[] = "{token}";
static const double sampling_period = {period};
/* A step may differ from the sampling period by this fraction of it (the master's rounding
 * of the time); any other step size is refused. */
static const double step_tolerance = 1e-6;

enum mode {{ INSTANTIATED, INITIALIZATION, STEPPING, TERMINATED }};

typedef struct {{
    {name}_state filter;
    double inputs[N_INPUTS];
    double estimate[N_OUTPUTS];
    double std[N_OUTPUTS];
    int status;     /* of the last update; NO_SAMPLE before the first since the start */
    double time;
    enum mode mode;
    int logging;    /* debug logging: held samples */
    char *name;
{environment}}} fmu_instance;

static void emit(const fmu_instance *self, int error, const char *category, const char *message);

/* Log a message: errors always, the rest with debug logging on. */
static void report(const fmu_instance *self, int error, const char *format, ...)
{{
    char message[600];
    va_list arguments;
    if (!error && !self->logging) {{
        return;
    }}
    va_start(arguments, format);
    vsnprintf(message, sizeof message, format, arguments);
    va_end(arguments);
    emit(self, error, error ? "logStatusError" : "logHeldSamples", message);
}}

/* Inputs at their start values, the filter at the start of a recording. */
static void start(fmu_instance *self)
{{
    double unknown[N_INPUTS];
    int i;
    for (i = 0; i < N_INPUTS; ++i) {{
        self->inputs[i] = 0.0;
        unknown[i] = NAN;
    }}
    {name}_reset(&self->filter);
    /* A sample with no finite input is held: it gives the estimate and std before any sample
     * (the prior mixture's) and leaves the filter as the reset left it. */
    {name}_update(&self->filter, unknown, self->estimate, self->std);
    self->status = NO_SAMPLE;
    self->time = 0.0;
    self->mode = INSTANTIATED;
}}

static fmu_instance *create(const char *name)
{{
    fmu_instance *self = (fmu_instance *)calloc(1, sizeof(fmu_instance));
    size_t length;
    if (self == NULL) {{
        return NULL;
    }}
    name = name == NULL ? "" : name;
    length = strlen(name);
    self->name = (char *)malloc(length + 1);
    if (self->name == NULL) {{
        free(self);
        return NULL;
    }}
    memcpy(self->name, name, length + 1);
    start(self);
    return self;
}}

static void destroy(fmu_instance *self)
{{
    if (self != NULL) {{
        free(self->name);
        free(self);
    }}
}}

static int accepts(const fmu_instance *self, const char *given)
{{
    if (given == NULL || strcmp(given, token) != 0) {{
        report(self, 1, "the token %s is not this FMU's, %s: the binary does not belong to "
               "this modelDescription.xml", given == NULL ? "(none)" : given, token);
        return 0;
    }}
    return 1;
}}

static int in_mode(const fmu_instance *self, const char *function, int allowed)
{{
    static const char *const names[] = {{"instantiated", "initialization", "step", "terminated"}};
    if (!(allowed & (1 << self->mode))) {{
        report(self, 1, "%s is not allowed in the %s mode", function, names[self->mode]);
        return 0;
    }}
    return 1;
}}

#define SETTABLE ((1 << INSTANTIATED) | (1 << INITIALIZATION) | (1 << STEPPING))

/* Move from one of the modes in allowed to the next; refused (and logged) from any other. */
static int move(fmu_instance *self, const char *function, int allowed, enum mode next)
{{
    if (!in_mode(self, function, allowed)) {{
        return 0;
    }}
    self->mode = next;
    return 1;
}}

/* Every value reference i < n through access (an expression of i): the first it refuses
 * ends the calling function. */
#define EACH_REFERENCE(n, access)       \
    do {{                                \
        size_t i;                       \
        for (i = 0; i < (n); ++i) {{     \
            if (!(access)) {{            \
                return REFUSED;         \
            }}                           \
        }}                               \
    }} while (0)

/* One communication step: the update of the filter on the inputs set at its start. */
static int step(fmu_instance *self, double current, double size, const char *function)
{{
    static const char *const held[] = {{"", "an input is not finite", "an outlier"}};
    if (!in_mode(self, function, 1 << STEPPING)) {{
        return 0;
    }}
    if (!(fabs(size - sampling_period) <= step_tolerance * sampling_period)) {{
        report(self, 1, "%s at t = %.15g s: a step of %.15g s is refused; this FMU filters one "
               "sample per step of its sampling period, %.15g s (set the communication step "
               "size to it)", function, current, size, sampling_period);
        return 0;
    }}
    self->status = {name}_update(&self->filter, self->inputs, self->estimate, self->std);
    self->time = current + size;
    if (self->status == {upper}_NON_FINITE || self->status == {upper}_OUTLIER) {{
        report(self, 0, "the sample at t = %.15g s is held: %s", current, held[self->status]);
    }}
    return 1;
}}

static int write_real(fmu_instance *self, unsigned long reference, double value,
                      const char *function)
{{
    if (reference >= FIRST_INPUT && reference < FIRST_INPUT + N_INPUTS) {{
        if (!in_mode(self, function, SETTABLE)) {{
            return 0;
        }}
        self->inputs[reference - FIRST_INPUT] = value;
        return 1;
    }}
    report(self, 1, "%s: the value reference %lu is not an input of this FMU", function,
           reference);
    return 0;
}}

static int read_real(const fmu_instance *self, unsigned long reference, double *value,
                     const char *function)
{{
    if (reference >= FIRST_INPUT && reference < FIRST_INPUT + N_INPUTS) {{
        *value = self->inputs[reference - FIRST_INPUT];
    }} else if (reference >= FIRST_ESTIMATE && reference < FIRST_ESTIMATE + N_OUTPUTS) {{
        *value = self->estimate[reference - FIRST_ESTIMATE];
    }} else if (reference >= FIRST_STD && reference < FIRST_STD + N_OUTPUTS) {{
        *value = self->std[reference - FIRST_STD];
    }} else if (HAS_TIME_VARIABLE && reference == TIME_REFERENCE) {{
        *value = self->time;
    }} else {{
        report(self, 1, "%s: the value reference %lu is not a variable of this type", function,
               reference);
        return 0;
    }}
    return 1;
}}

static int read_integer(const fmu_instance *self, unsigned long reference, INTEGER *value,
                        const char *function)
{{
    if (reference != STATUS_REFERENCE) {{
        report(self, 1, "%s: the value reference %lu is not a variable of this type", function,
               reference);
        return 0;
    }}
    *value = (INTEGER)self->status;
    return 1;
}}


/* A call naming variables of a type or causality this FMU does not have. */
static int no_variables(const fmu_instance *self, size_t count, const char *function)
{{
    if (count > 0) {{
        report(self, 1, "%s: this FMU has no variable of this type that can be accessed so",
               function);
        return 0;
    }}
    return 1;
}}

static void refuse(const fmu_instance *self, const char *function)
{{
    report(self, 1, "%s is not supported: this FMU is for co-simulation, without FMU states, "
           "derivatives or clocks", function);
}}
"""
