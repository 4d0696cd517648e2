"""The FMI wrapper of a generated filter: ``<name>_fmi2.c`` or ``<name>_fmi3.c``.

The wrapper is C99 over the public API of the filter that :func:`~skhmmgmr.export.write_c`
generates (``<name>_reset``, ``<name>_update`` and its return codes, ``<NAME>_N_INPUTS``,
``<NAME>_N_OUTPUTS``) and the FMI headers of the importer (``fmi2Functions.h`` or
``fmi3Functions.h``, which FMPy ships; never in the FMU). It has two parts:

- the core, the same text for both versions, in plain C types: one heap-allocated instance per
  ``fmi2Instantiate`` / ``fmi3InstantiateCoSimulation`` (the filter state, the inputs, the
  last estimate, std and status, the time, the mode, the logger), its start (inputs at their
  start values 0, the filter reset, the outputs at the prior mixture's mean and std), the
  step (one update of the filter per communication step of the sampling period; a step of
  another size is refused, logged, and changes nothing), and reading and writing variables
  by value reference;
- the shell of each FMI version: every function its header declares (an FMI 3.0 FMU exports
  all of them, those of the interface types it does not implement included, which refuse),
  calling the core.

Instances share nothing: the filter's parameters are ``static const``, everything that changes
is in the instance, so that two instances in one process filter two recordings independently.
"""

import re

from .._version import __version__
from ._fmu_description import NO_SAMPLE, TIME_REFERENCE

_CORE = r"""
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

_HEAD = r"""/* {name}_fmi{major}.c: the FMI {version} co-simulation interface of the filter in
 * {name}.c.
 *
 * Generated by skhmmgmr {package} (skhmmgmr.export.write_fmu); do not edit: export again.
 * Builds with the FMI {version} headers of the importer (fmi{major}Functions.h, not in the FMU)
 * and {name}.c, in C99: cc -std=c99 -shared -fPIC -I<headers> {name}.c {name}_fmi{major}.c -lm
 * Value references: {layout}. One doStep of the sampling period ({period} s) filters the inputs
 * set before it; the outputs after it are the estimate of that sample.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi{major}Functions.h"
#include "{name}.h"

#define HAS_TIME_VARIABLE {has_time}
#define UNUSED(x) ((void)(x))
#define INTEGER fmi{major}{integer}
#define REFUSED fmi{major}Error
#define DONE(ok) ((ok) ? fmi{major}OK : REFUSED)
"""

_FMI2 = r"""
static void emit(const fmu_instance *self, int error, const char *category, const char *message)
{
    /* the logger reads the message as a printf format: every '%' doubled */
    char escaped[1200];
    size_t i, j = 0;
    for (i = 0; message[i] != '\0' && j + 2 < sizeof escaped; ++i) {
        if (message[i] == '%') {
            escaped[j++] = '%';
        }
        escaped[j++] = message[i];
    }
    escaped[j] = '\0';
    if (self->logger != NULL) {
        self->logger(self->environment, self->name, error ? fmi2Error : fmi2OK, category, escaped);
    }
}

#define SELF ((fmu_instance *)c)

static fmi2Status unsupported(fmi2Component c, const char *function)
{
    refuse(SELF, function);
    return fmi2Error;
}

const char *fmi2GetTypesPlatform(void)
{
    return fmi2TypesPlatform;
}

const char *fmi2GetVersion(void)
{
    return fmi2Version;
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    UNUSED(nCategories);
    UNUSED(categories);
    SELF->logging = loggingOn != fmi2False;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    fmu_instance *self = create(instanceName);
    UNUSED(fmuResourceLocation);
    UNUSED(visible);
    if (self == NULL) {
        return NULL;
    }
    if (functions != NULL) {
        self->logger = functions->logger;
        self->environment = functions->componentEnvironment;
    }
    self->logging = loggingOn != fmi2False;
    if (fmuType != fmi2CoSimulation) {
        report(self, 1, "fmi2Instantiate: this FMU is for co-simulation only");
        destroy(self);
        return NULL;
    }
    if (!accepts(self, fmuGUID)) {
        destroy(self);
        return NULL;
    }
    return self;
}

void fmi2FreeInstance(fmi2Component c)
{
    destroy(SELF);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    UNUSED(toleranceDefined);
    UNUSED(tolerance);
    UNUSED(stopTimeDefined);
    UNUSED(stopTime);
    if (!in_mode(SELF, "fmi2SetupExperiment", 1 << INSTANTIATED)) {
        return fmi2Error;
    }
    SELF->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    return DONE(move(SELF, "fmi2EnterInitializationMode", 1 << INSTANTIATED, INITIALIZATION));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    return DONE(move(SELF, "fmi2ExitInitializationMode", 1 << INITIALIZATION, STEPPING));
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    return DONE(move(SELF, "fmi2Terminate", 1 << STEPPING, TERMINATED));
}

fmi2Status fmi2Reset(fmi2Component c)
{
    start(SELF);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[])
{
    EACH_REFERENCE(nvr, read_real(SELF, vr[i], &value[i], "fmi2GetReal"));
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    EACH_REFERENCE(nvr, read_integer(SELF, vr[i], &value[i], "fmi2GetInteger"));
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    EACH_REFERENCE(nvr, write_real(SELF, vr[i], value[i], "fmi2SetReal"));
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    return DONE(step(SELF, currentCommunicationPoint, communicationStepSize, "fmi2DoStep"));
}

/* Every step completes within fmi2DoStep: there is never a pending one. */
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    UNUSED(c);
    UNUSED(s);
    UNUSED(value);
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    if (s != fmi2LastSuccessfulTime) {
        return fmi2Discard;
    }
    *value = SELF->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    UNUSED(c);
    UNUSED(s);
    UNUSED(value);
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    UNUSED(c);
    if (s != fmi2Terminated) {
        return fmi2Discard;
    }
    *value = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    UNUSED(c);
    UNUSED(s);
    UNUSED(value);
    return fmi2Discard;
}
"""

_FMI3 = r"""
static void emit(const fmu_instance *self, int error, const char *category, const char *message)
{
    if (self->logger != NULL) {
        self->logger(self->environment, error ? fmi3Error : fmi3OK, category, message);
    }
}

#define SELF ((fmu_instance *)instance)

static fmi3Status unsupported(fmi3Instance instance, const char *function)
{
    refuse(SELF, function);
    return fmi3Error;
}

/* FMI 3.0 accessors give one value per reference: every variable is a scalar. */
static int scalars(const fmu_instance *self, size_t references, size_t values,
                   const char *function)
{
    if (references != values) {
        report(self, 1, "%s: %lu values for %lu value references; every variable of this FMU "
               "is a scalar", function, (unsigned long)values, (unsigned long)references);
        return 0;
    }
    return 1;
}

const char *fmi3GetVersion(void)
{
    return fmi3Version;
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    UNUSED(nCategories);
    UNUSED(categories);
    SELF->logging = loggingOn != fmi3False;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    UNUSED(instanceName);
    UNUSED(instantiationToken);
    UNUSED(resourcePath);
    UNUSED(visible);
    UNUSED(loggingOn);
    if (logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateModelExchange: this FMU is for co-simulation only");
    }
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible,
                                         fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    fmu_instance *self = create(instanceName);
    UNUSED(resourcePath);
    UNUSED(visible);
    UNUSED(eventModeUsed);
    UNUSED(earlyReturnAllowed);
    UNUSED(requiredIntermediateVariables);
    UNUSED(nRequiredIntermediateVariables);
    UNUSED(intermediateUpdate);
    if (self == NULL) {
        return NULL;
    }
    self->logger = logMessage;
    self->environment = instanceEnvironment;
    self->logging = loggingOn != fmi3False;
    if (!accepts(self, instantiationToken)) {
        destroy(self);
        return NULL;
    }
    return self;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName,
                                               fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    UNUSED(instanceName);
    UNUSED(instantiationToken);
    UNUSED(resourcePath);
    UNUSED(visible);
    UNUSED(loggingOn);
    UNUSED(clockUpdate);
    UNUSED(lockPreemption);
    UNUSED(unlockPreemption);
    if (logMessage != NULL) {
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: this FMU is for co-simulation only");
    }
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    destroy(SELF);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    UNUSED(toleranceDefined);
    UNUSED(tolerance);
    UNUSED(stopTimeDefined);
    UNUSED(stopTime);
    if (!move(SELF, "fmi3EnterInitializationMode", 1 << INSTANTIATED, INITIALIZATION)) {
        return fmi3Error;
    }
    SELF->time = startTime;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    return DONE(move(SELF, "fmi3ExitInitializationMode", 1 << INITIALIZATION, STEPPING));
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    int allowed = (1 << STEPPING) | (1 << INITIALIZATION);
    return DONE(move(SELF, "fmi3Terminate", allowed, TERMINATED));
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    start(SELF);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    if (!scalars(SELF, nValueReferences, nValues, "fmi3GetFloat64")) {
        return fmi3Error;
    }
    EACH_REFERENCE(nValues, read_real(SELF, valueReferences[i], &values[i], "fmi3GetFloat64"));
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues)
{
    if (!scalars(SELF, nValueReferences, nValues, "fmi3GetInt32")) {
        return fmi3Error;
    }
    EACH_REFERENCE(nValues, read_integer(SELF, valueReferences[i], &values[i], "fmi3GetInt32"));
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    if (!scalars(SELF, nValueReferences, nValues, "fmi3SetFloat64")) {
        return fmi3Error;
    }
    EACH_REFERENCE(nValues, write_real(SELF, valueReferences[i], values[i], "fmi3SetFloat64"));
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    UNUSED(instance);
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    UNUSED(instance);
    *nContinuousStates = 0;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    int done;
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    done = step(SELF, currentCommunicationPoint, communicationStepSize, "fmi3DoStep");
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = SELF->time;
    return DONE(done);
}

"""

# The functions a version's header declares that this FMU does not implement, by name: their
# parameters after the instance. They refuse with fmi2Error / fmi3Error and a logged message
# (no FMU states, derivatives, events, clocks, model exchange or scheduled execution).
_REFUSED = {
    "2.0": {
        "fmi2GetFMUstate": "fmi2FMUstate *FMUstate",
        "fmi2SetFMUstate": "fmi2FMUstate FMUstate",
        "fmi2FreeFMUstate": "fmi2FMUstate *FMUstate",
        "fmi2SerializedFMUstateSize": "fmi2FMUstate FMUstate, size_t *size",
        "fmi2SerializeFMUstate": "fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size",
        "fmi2DeSerializeFMUstate": (
            "const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate"
        ),
        "fmi2GetDirectionalDerivative": (
            "const fmi2ValueReference vUnknown_ref[], size_t nUnknown, "
            "const fmi2ValueReference vKnown_ref[], size_t nKnown, const fmi2Real dvKnown[], "
            "fmi2Real dvUnknown[]"
        ),
        "fmi2EnterEventMode": "",
        "fmi2NewDiscreteStates": "fmi2EventInfo *fmi2eventInfo",
        "fmi2EnterContinuousTimeMode": "",
        "fmi2CompletedIntegratorStep": (
            "fmi2Boolean noSetFMUStatePriorToCurrentPoint, fmi2Boolean *enterEventMode, "
            "fmi2Boolean *terminateSimulation"
        ),
        "fmi2SetTime": "fmi2Real time",
        "fmi2SetContinuousStates": "const fmi2Real x[], size_t nx",
        "fmi2GetDerivatives": "fmi2Real derivatives[], size_t nx",
        "fmi2GetEventIndicators": "fmi2Real eventIndicators[], size_t ni",
        "fmi2GetContinuousStates": "fmi2Real x[], size_t nx",
        "fmi2GetNominalsOfContinuousStates": "fmi2Real x_nominal[], size_t nx",
        "fmi2SetRealInputDerivatives": (
            "const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[], "
            "const fmi2Real value[]"
        ),
        "fmi2GetRealOutputDerivatives": (
            "const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[], fmi2Real value[]"
        ),
        "fmi2CancelStep": "",
    },
    "3.0": {
        "fmi3EnterEventMode": "",
        "fmi3GetNumberOfVariableDependencies": (
            "fmi3ValueReference valueReference, size_t *nDependencies"
        ),
        "fmi3GetVariableDependencies": (
            "fmi3ValueReference dependent, size_t elementIndicesOfDependent[], "
            "fmi3ValueReference independents[], size_t elementIndicesOfIndependents[], "
            "fmi3DependencyKind dependencyKinds[], size_t nDependencies"
        ),
        "fmi3GetFMUState": "fmi3FMUState *FMUState",
        "fmi3SetFMUState": "fmi3FMUState FMUState",
        "fmi3FreeFMUState": "fmi3FMUState *FMUState",
        "fmi3SerializedFMUStateSize": "fmi3FMUState FMUState, size_t *size",
        "fmi3SerializeFMUState": "fmi3FMUState FMUState, fmi3Byte serializedState[], size_t size",
        "fmi3DeserializeFMUState": (
            "const fmi3Byte serializedState[], size_t size, fmi3FMUState *FMUState"
        ),
        **{
            f"fmi3Get{kind}Derivative": (
                "const fmi3ValueReference unknowns[], size_t nUnknowns, "
                "const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[], "
                "size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity"
            )
            for kind in ("Directional", "Adjoint")
        },
        "fmi3EnterConfigurationMode": "",
        "fmi3ExitConfigurationMode": "",
        "fmi3GetIntervalDecimal": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]"
        ),
        "fmi3GetIntervalFraction": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]"
        ),
        "fmi3GetShiftDecimal": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "fmi3Float64 shifts[]"
        ),
        "fmi3GetShiftFraction": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "fmi3UInt64 counters[], fmi3UInt64 resolutions[]"
        ),
        "fmi3SetIntervalDecimal": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "const fmi3Float64 intervals[]"
        ),
        "fmi3SetIntervalFraction": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]"
        ),
        "fmi3SetShiftDecimal": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "const fmi3Float64 shifts[]"
        ),
        "fmi3SetShiftFraction": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]"
        ),
        "fmi3EvaluateDiscreteStates": "",
        "fmi3UpdateDiscreteStates": (
            "fmi3Boolean *discreteStatesNeedUpdate, fmi3Boolean *terminateSimulation, "
            "fmi3Boolean *nominalsOfContinuousStatesChanged, "
            "fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined, "
            "fmi3Float64 *nextEventTime"
        ),
        "fmi3EnterContinuousTimeMode": "",
        "fmi3CompletedIntegratorStep": (
            "fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *enterEventMode, "
            "fmi3Boolean *terminateSimulation"
        ),
        "fmi3SetTime": "fmi3Float64 time",
        "fmi3SetContinuousStates": "const fmi3Float64 continuousStates[], size_t nContinuousStates",
        "fmi3GetContinuousStateDerivatives": (
            "fmi3Float64 derivatives[], size_t nContinuousStates"
        ),
        "fmi3GetEventIndicators": "fmi3Float64 eventIndicators[], size_t nEventIndicators",
        "fmi3GetContinuousStates": "fmi3Float64 continuousStates[], size_t nContinuousStates",
        "fmi3GetNominalsOfContinuousStates": "fmi3Float64 nominals[], size_t nContinuousStates",
        "fmi3EnterStepMode": "",
        "fmi3GetOutputDerivatives": (
            "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
            "const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues"
        ),
        "fmi3ActivateModelPartition": (
            "fmi3ValueReference clockReference, fmi3Float64 activationTime"
        ),
    },
}

_FMI3_TYPES = ("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
_FMI3_REFERENCES = "const fmi3ValueReference valueReferences[], size_t nValueReferences, "

# The accessors of the types (or causalities) this FMU has no variable of: their parameters
# after the instance. They accept an empty list of value references and refuse any other.
_NO_VARIABLES = {
    "2.0": {
        f"fmi2{access}{kind}": (
            f"const fmi2ValueReference vr[], size_t nvr, {const}fmi2{kind} value[]"
        )
        for access, const, kinds in (
            ("Get", "", ("Boolean", "String")),
            ("Set", "const ", ("Integer", "Boolean", "String")),
        )
        for kind in kinds
    },
    "3.0": {
        **{
            f"fmi3{access}{kind}": (f"{_FMI3_REFERENCES}{const}fmi3{kind} values[], size_t nValues")
            for access, const, kinds in (
                ("Get", "", ("Float32", *_FMI3_TYPES, "Boolean", "String")),
                ("Set", "const ", ("Float32", *_FMI3_TYPES, "Boolean", "String")),
            )
            for kind in kinds
            if (access, kind) != ("Get", "Int32")
        },
        "fmi3GetBinary": f"{_FMI3_REFERENCES}size_t valueSizes[], fmi3Binary values[], "
        "size_t nValues",
        "fmi3SetBinary": f"{_FMI3_REFERENCES}const size_t valueSizes[], "
        "const fmi3Binary values[], size_t nValues",
        "fmi3GetClock": f"{_FMI3_REFERENCES}fmi3Clock values[]",
        "fmi3SetClock": f"{_FMI3_REFERENCES}const fmi3Clock values[]",
    },
}
# the instance parameter and the name of the count of value references, by version
_INSTANCE = {
    "2.0": ("fmi2Component c", "nvr"),
    "3.0": ("fmi3Instance instance", "nValueReferences"),
}


def _parameter_names(parameters):
    """The names in a C parameter list (``"const double x[], size_t *n"`` -> x, n)."""
    return [
        re.sub(r"\[\]$", "", part.split()[-1]).lstrip("*")
        for part in parameters.split(",")
        if part.strip()
    ]


def _stub(fmi_version, function, parameters, no_variables):
    """The C definition of a function of :data:`_REFUSED` or :data:`_NO_VARIABLES`."""
    instance, count = _INSTANCE[fmi_version]
    prefix = f"fmi{fmi_version[0]}Status {function}("
    lines = [prefix]
    parts = [instance, *(p.strip() for p in parameters.split(",") if p.strip())]
    for position, part in enumerate(parts):
        part += ")" if position == len(parts) - 1 else ","
        if len(lines[-1]) + len(part) + 1 > 96 and lines[-1].strip():
            lines.append(" " * len(prefix))
        lines[-1] += part if lines[-1].endswith(("(", " ")) else " " + part
    head = "\n".join(lines)
    names = _parameter_names(parameters)
    unused = [n for n in names if not (no_variables and n == count)]
    body = "".join(f"    UNUSED({name});\n" for name in unused)
    self_name = instance.split()[-1]
    call = (
        f'DONE(no_variables(SELF, {count}, "{function}"))'
        if no_variables
        else f'unsupported({self_name}, "{function}")'
    )
    return f"\n{head}\n{{\n{body}    return {call};\n}}\n"


_ENVIRONMENT = {
    "2.0": "    fmi2CallbackLogger logger;\n    fmi2ComponentEnvironment environment;\n",
    "3.0": "    fmi3LogMessageCallback logger;\n    fmi3InstanceEnvironment environment;\n",
}


def wrapper_name(name, fmi_version):
    """File name of the wrapper: ``<name>_fmi2.c`` or ``<name>_fmi3.c``."""
    return f"{name}_fmi{fmi_version[0]}.c"


def wrapper(interface, fmi_version):
    """Text of the FMI ``fmi_version`` wrapper of the filter ``interface.model_identifier``."""
    name = interface.model_identifier
    major = fmi_version[0]
    time = "0 the time, " if fmi_version == "3.0" else ""
    layout = (
        f"{time}{interface.first_input}.. the inputs, {interface.first_estimate}.. the "
        f"estimates, {interface.first_std}.. their std, {interface.status_reference} the status"
    )
    head = _HEAD.format(
        name=name,
        major=major,
        version=fmi_version,
        package=__version__,
        layout=layout,
        period=repr(interface.sampling_period),
        has_time=int(fmi_version == "3.0"),
        integer="Integer" if fmi_version == "2.0" else "Int32",
    )
    core = _CORE.format(
        n_inputs=interface.n_inputs,
        n_outputs=interface.n_outputs,
        first_input=interface.first_input,
        first_estimate=interface.first_estimate,
        first_std=interface.first_std,
        status_reference=interface.status_reference,
        time_reference=TIME_REFERENCE,
        no_sample=NO_SAMPLE,
        upper=name.upper(),
        name=name,
        token=interface.token,
        period=repr(interface.sampling_period),
        environment=_ENVIRONMENT[fmi_version],
    )
    shell = _FMI2 if fmi_version == "2.0" else _FMI3
    stubs = [_stub(fmi_version, f, p, False) for f, p in _REFUSED[fmi_version].items()]
    stubs += [_stub(fmi_version, f, p, True) for f, p in _NO_VARIABLES[fmi_version].items()]
    return head + core + shell + "".join(stubs)
