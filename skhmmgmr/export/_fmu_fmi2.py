"""The FMI 2.0 shell of the wrapper (:mod:`._fmu_wrapper`): every function
``fmi2Functions.h`` declares, over the core of :mod:`._fmu_instance`.

:data:`SHELL` is plain C (no template): the logger's callback, instantiation (co-simulation
only), the modes, reset, reading and writing variables, ``fmi2DoStep`` and the status queries.
:data:`REFUSED` and :data:`NO_VARIABLES` list the other functions the header declares, by
name, with their parameters after the instance: :mod:`._fmu_wrapper` writes their
definitions, which refuse (``fmi2Error`` and a logged message) or accept only an empty list of
value references.
"""

#: The instance parameter of every function, and the name of the count of value references.
INSTANCE = ("fmi2Component c", "nvr")
#: The instance's fields for the importer's logger (the core's ``{environment}``).
ENVIRONMENT = "    fmi2CallbackLogger logger;\n    fmi2ComponentEnvironment environment;\n"

SHELL = r"""
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

# The functions of the header this FMU does not implement (no FMU states, derivatives, events
# or model exchange): they refuse with fmi2Error and a logged message.
REFUSED = {
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
}

# The accessors of the types this FMU has no variable of: they accept an empty list of value
# references and refuse any other.
NO_VARIABLES = {
    f"fmi2{access}{kind}": (f"const fmi2ValueReference vr[], size_t nvr, {const}fmi2{kind} value[]")
    for access, const, kinds in (
        ("Get", "", ("Boolean", "String")),
        ("Set", "const ", ("Integer", "Boolean", "String")),
    )
    for kind in kinds
}
