"""The FMI 3.0 shell of the wrapper (:mod:`._fmu_wrapper`): every function
``fmi3Functions.h`` declares, over the core of :mod:`._fmu_instance`.

:data:`SHELL` is plain C (no template): the logger's callback, instantiation (co-simulation
only; model exchange and scheduled execution refuse), the modes, reset, reading and writing
variables (the time among them), ``fmi3DoStep``. An FMI 3.0 FMU exports every function its
header declares, those of the interface types it does not implement included: :data:`REFUSED`
and :data:`NO_VARIABLES` list them, by name, with their parameters after the instance, and
:mod:`._fmu_wrapper` writes their definitions, which refuse (``fmi3Error`` and a logged
message) or accept only an empty list of value references.
"""

#: The instance parameter of every function, and the name of the count of value references.
INSTANCE = ("fmi3Instance instance", "nValueReferences")
#: The instance's fields for the importer's logger (the core's ``{environment}``).
ENVIRONMENT = "    fmi3LogMessageCallback logger;\n    fmi3InstanceEnvironment environment;\n"

SHELL = r"""
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

# The functions of the header this FMU does not implement (no FMU states, derivatives, events,
# clocks, model exchange or scheduled execution): they refuse with fmi3Error and a logged
# message.
REFUSED = {
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
        "const fmi3ValueReference valueReferences[], size_t nValueReferences, fmi3Float64 shifts[]"
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
    "fmi3GetContinuousStateDerivatives": ("fmi3Float64 derivatives[], size_t nContinuousStates"),
    "fmi3GetEventIndicators": "fmi3Float64 eventIndicators[], size_t nEventIndicators",
    "fmi3GetContinuousStates": "fmi3Float64 continuousStates[], size_t nContinuousStates",
    "fmi3GetNominalsOfContinuousStates": "fmi3Float64 nominals[], size_t nContinuousStates",
    "fmi3EnterStepMode": "",
    "fmi3GetOutputDerivatives": (
        "const fmi3ValueReference valueReferences[], size_t nValueReferences, "
        "const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues"
    ),
    "fmi3ActivateModelPartition": ("fmi3ValueReference clockReference, fmi3Float64 activationTime"),
}

_TYPES = ("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
_REFERENCES = "const fmi3ValueReference valueReferences[], size_t nValueReferences, "

# The accessors of the types (or causalities) this FMU has no variable of: they accept an empty
# list of value references and refuse any other.
NO_VARIABLES = {
    **{
        f"fmi3{access}{kind}": (f"{_REFERENCES}{const}fmi3{kind} values[], size_t nValues")
        for access, const, kinds in (
            ("Get", "", ("Float32", *_TYPES, "Boolean", "String")),
            ("Set", "const ", ("Float32", *_TYPES, "Boolean", "String")),
        )
        for kind in kinds
        if (access, kind) != ("Get", "Int32")
    },
    "fmi3GetBinary": f"{_REFERENCES}size_t valueSizes[], fmi3Binary values[], size_t nValues",
    "fmi3SetBinary": f"{_REFERENCES}const size_t valueSizes[], "
    "const fmi3Binary values[], size_t nValues",
    "fmi3GetClock": f"{_REFERENCES}fmi3Clock values[]",
    "fmi3SetClock": f"{_REFERENCES}const fmi3Clock values[]",
}
