/* The FMI 2.0 co-simulation interface of every native FMU of the kit: the fmi2 functions
   mapped onto the instance core (instance.h), as the Reference FMUs' fmi2Functions.c
   over their cosimulation.c. What is FMI 2.0's lives here:
   - the call sequence (allowed() with each function's mask of states, as the Reference
     FMUs' fmi2Functions.c): a call outside its states answers fmi2Error with a line. A
     failed doStep or initialization leaves the standard's stepFailed (step mode, failed):
     reading, fmi2DoStep (fmi2Discard, "refusing doStep", as the pythonfmu FMUs do),
     fmi2Terminate, fmi2Reset, fmi2SetFMUstate and fmi2FreeInstance lead on, nothing is set;
   - the logger: its message is a printf format, so the text goes with every '%' doubled
     (a host string such as a GUID or a category holding "%s" is printed, never read as a
     conversion; a ctypes logger reading it as text sees it unchanged unless it held a '%');
   - the status functions, and the model-exchange functions this co-simulation FMU refuses. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "instance.h"

/* FMI 2.0 counts both failed states as step mode (the standard's stepFailed). */
enum { STEPPING = MBI_STEP | MBI_STEP_FAILED | MBI_INIT_FAILED,
       READABLE = MBI_INITIALIZATION | STEPPING | MBI_TERMINATED,
       SETTABLE = MBI_INSTANTIATED | MBI_INITIALIZATION | STEPPING,
       FAILED = MBI_STEP_FAILED | MBI_INIT_FAILED };

static const char *phase_name(int phase)
{
    return phase == MBI_INSTANTIATED ? "the instantiated state (before fmi2EnterInitializationMode)"
         : phase == MBI_INITIALIZATION ? "initialization mode"
         : phase == MBI_STEP ? "step mode"
         : phase & FAILED ? "the failed state (after a Discard or a failed initialization)"
         : "the terminated state";
}

/* The instance core's lines to the host's fmi2CallbackLogger (env: the fmi2CallbackFunctions). */
static void logger2(const void *env, const char *name, mbi_status status, const char *category, const char *text)
{
    const fmi2CallbackFunctions *cb = env;
    char escaped[2 * 1400 + 1];
    size_t n = 0;
    if (!cb->logger) return;
    for (const char *p = text; *p && n + 2 < sizeof escaped; p++) {
        if (*p == '%') escaped[n++] = '%';
        escaped[n++] = *p;
    }
    escaped[n] = '\0';
    cb->logger(cb->componentEnvironment, name, (fmi2Status)status, category, escaped);
}

#define FAIL(inst, ...) (mbi_logf((inst), MBI_ERROR, __VA_ARGS__), fmi2Error)

/* Is `function` allowed in the instance's state (mask of enum mbi_phase)? Else an error line
   (the FMI 2.0 call sequence; the Reference FMUs' "Illegal call sequence"). */
static int allowed(mb_instance *inst, const char *function, int mask)
{
    if (mbi_phase(inst) & mask) return 1;
    mbi_logf(inst, MBI_ERROR, "%s: not allowed in %s (FMI 2.0 call sequence)", function, phase_name(mbi_phase(inst)));
    return 0;
}

/* Nothing is set in the failed state (the standard's stepFailed). */
static int unfailed(mb_instance *inst, const char *function)
{
    if (!(mbi_phase(inst) & FAILED)) return 1;
    mbi_logf(inst, MBI_ERROR, "%s: not allowed in %s (FMI 2.0 call sequence)", function, phase_name(MBI_STEP_FAILED));
    return 0;
}

#define INSTANCE(function, mask)                                 \
    mb_instance *inst = c;                                       \
    if (!inst || !allowed(inst, function, mask)) return fmi2Error;

/* ------------------------------------------------------------------- life cycle */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    mb_instance *inst = c;
    if (!inst) return fmi2Error;
    if (nCategories == 0) {
        mbi_set_logging(inst, -1, loggingOn);
        return fmi2OK;
    }
    if (!categories) return FAIL(inst, "fmi2SetDebugLogging: categories is NULL for %zu categories", nCategories);
    for (size_t n = 0; n < nCategories; n++) {
        int k = mbi_category(categories[n]);
        if (k < 0)
            return FAIL(inst, "fmi2SetDebugLogging: unknown log category '%s'", categories[n] ? categories[n] : "(null)");
        mbi_set_logging(inst, k, loggingOn);
    }
    return fmi2OK;
}

/* fmuResourceLocation (a URI: file:///path/resources, file:/path, percent-encoded) as the
   folder path the model reads resources from; another scheme gives none (a model needing
   one says so when it needs it). 1 when out of memory. */
static int resource_folder(mb_instance *inst, const char *uri)
{
    if (!uri || strncmp(uri, "file:", 5) != 0) return mbi_set_resources(inst, NULL);
    const char *p = uri + 5;
    if (strncmp(p, "///", 3) == 0) p += 2;   /* file:///path -> /path */
    else if (strncmp(p, "//localhost/", 12) == 0) p += 11;
    char *path = malloc(strlen(p) + 1);
    if (!path) return 1;
    size_t n = 0;
    for (; *p; p++) {
        unsigned hex;
        if (p[0] == '%' && p[1] && p[2] && sscanf(p + 1, "%2x", &hex) == 1) {
            path[n++] = (char)hex;
            p += 2;
        } else {
            path[n++] = *p;
        }
    }
    path[n] = '\0';
    int failed = mbi_set_resources(inst, path);
    free(path);
    return failed;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)visible;
    fmi2CallbackFunctions cb;
    memset(&cb, 0, sizeof cb);
    if (functions) cb = *functions;
    const char *name = instanceName ? instanceName : "?";
    if (fmuType != fmi2CoSimulation) {
        mbi_log_host(logger2, &cb, name, MBI_ERROR, "fmi2Instantiate: %s supports co-simulation only",
                     MB_MODEL.identifier);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MB_MODEL.guid) != 0) {
        mbi_log_host(logger2, &cb, name, MBI_ERROR, "fmi2Instantiate: GUID '%s' is not this FMU's '%s'",
                     fmuGUID ? fmuGUID : "(null)", MB_MODEL.guid);
        return NULL;
    }
    mb_instance *inst = mbi_instantiate(instanceName, logger2, &cb, sizeof cb, loggingOn);
    if (inst && resource_folder(inst, fmuResourceLocation)) {
        mbi_free_instance(inst);
        return NULL;
    }
    return inst;
}

void fmi2FreeInstance(fmi2Component c) { mbi_free_instance(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined, (void)tolerance;
    INSTANCE("fmi2SetupExperiment", MBI_INSTANTIATED)
    return (fmi2Status)mbi_setup_experiment(inst, "fmi2SetupExperiment", startTime, stopTimeDefined != fmi2False,
                                            stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    INSTANCE("fmi2EnterInitializationMode", MBI_INSTANTIATED)
    mbi_enter_initialization(inst);
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    INSTANCE("fmi2ExitInitializationMode", MBI_INITIALIZATION)
    return (fmi2Status)mbi_exit_initialization(inst);
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    INSTANCE("fmi2Terminate", STEPPING)
    mbi_terminate(inst);
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    if (!c) return fmi2Error;
    mbi_reset(c);
    return fmi2OK;
}

/* ------------------------------------------------------------------- get and set */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    INSTANCE("fmi2GetReal", READABLE)
    return (fmi2Status)mbi_get_real(inst, "fmi2GetReal", vr, nvr, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    INSTANCE("fmi2GetInteger", READABLE)
    return (fmi2Status)mbi_get_integer(inst, "fmi2GetInteger", vr, nvr, value);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    INSTANCE("fmi2SetReal", SETTABLE)
    if (!unfailed(inst, "fmi2SetReal")) return fmi2Error;
    return (fmi2Status)mbi_set_real(inst, "fmi2SetReal", vr, nvr, value);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    INSTANCE("fmi2SetInteger", SETTABLE)
    if (!unfailed(inst, "fmi2SetInteger")) return fmi2Error;
    return (fmi2Status)mbi_set_integer(inst, "fmi2SetInteger", vr, nvr, value);
}

static fmi2Status no_variables(fmi2Component c, const char *function, size_t nvr, const char *type, int mask)
{
    /* a setter, like fmi2SetReal, not in the failed state (fuzz.c: fmi2SetBoolean of no values answered OK there) */
    INSTANCE(function, mask)
    if ((mask & MBI_INSTANTIATED) && !unfailed(inst, function)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return FAIL(inst, "%s: %s has no %s variables", function, MB_MODEL.identifier, type);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    (void)vr, (void)value;
    return no_variables(c, "fmi2GetBoolean", nvr, "Boolean", READABLE);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    (void)vr, (void)value;
    return no_variables(c, "fmi2SetBoolean", nvr, "Boolean", SETTABLE);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    INSTANCE("fmi2GetString", READABLE)
    return (fmi2Status)mbi_get_string(inst, "fmi2GetString", vr, nvr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    INSTANCE("fmi2SetString", SETTABLE)
    if (!unfailed(inst, "fmi2SetString")) return fmi2Error;
    return (fmi2Status)mbi_set_string(inst, "fmi2SetString", vr, nvr, value);
}

/* ---------------------------------------------------------------------- stepping */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    INSTANCE("fmi2DoStep", STEPPING)
    /* a failed instance refuses every step, with fmi2Discard, whatever its arguments */
    if (!mbi_failed(inst) && mbi_step_refused(inst, "fmi2DoStep", currentCommunicationPoint, communicationStepSize))
        return fmi2Error;
    return (fmi2Status)mbi_do_step(inst, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    if (!c) return fmi2Error;
    return FAIL(c, "fmi2CancelStep: fmi2DoStep never returns fmi2Pending, nothing to cancel");
}

/* A status query allowed now, with somewhere to put its answer? Else fmi2Error and a line. */
static int status_query(mb_instance *inst, const char *function, const void *value)
{
    if (!inst || !allowed(inst, function, STEPPING | MBI_TERMINATED)) return 0;
    if (value) return 1;
    mbi_logf(inst, MBI_ERROR, "%s: the value reference array is NULL for 1 values", function);
    return 0;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    if (!status_query(c, "fmi2GetStatus", value)) return fmi2Error;
    if (s != fmi2DoStepStatus) return FAIL(c, "fmi2GetStatus: status kind %d is not an fmi2Status", (int)s);
    *value = mbi_failed(c) ? fmi2Discard : fmi2OK;   /* doStep is synchronous: the last one is done */
    return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    if (!status_query(c, "fmi2GetRealStatus", value)) return fmi2Error;
    if (s != fmi2LastSuccessfulTime) return FAIL(c, "fmi2GetRealStatus: only fmi2LastSuccessfulTime is a Real status");
    *value = mbi_core(c)->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)value;
    INSTANCE("fmi2GetIntegerStatus", STEPPING | MBI_TERMINATED)
    return FAIL(inst, "fmi2GetIntegerStatus: no Integer status (kind %d)", (int)s);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    if (!status_query(c, "fmi2GetBooleanStatus", value)) return fmi2Error;
    if (s != fmi2Terminated) return FAIL(c, "fmi2GetBooleanStatus: only fmi2Terminated is a Boolean status");
    *value = mbi_failed(c) ? fmi2True : fmi2False;   /* a failed instance has ended its simulation */
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)value;
    INSTANCE("fmi2GetStringStatus", STEPPING | MBI_TERMINATED)
    return FAIL(inst, "fmi2GetStringStatus: no String status (kind %d)", (int)s);
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    if (!c) return fmi2Error;
    return FAIL(c, "fmi2SetRealInputDerivatives: canInterpolateInputs is false");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    if (!c) return fmi2Error;
    return FAIL(c, "fmi2GetRealOutputDerivatives: maxOutputDerivativeOrder is 0");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    if (!c) return fmi2Error;
    return FAIL(c, "fmi2GetDirectionalDerivative: providesDirectionalDerivative is false");
}

/* ------------------------------------------------------------------- FMU states */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    if (!c) return fmi2Error;
    if (!FMUstate) return FAIL(c, "fmi2GetFMUstate: FMUstate is NULL");   /* fuzz.c: it came without a line */
    return (fmi2Status)mbi_get_state(c, "fmi2GetFMUstate", (mbi_state **)FMUstate);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    if (!c) return fmi2Error;
    return (fmi2Status)mbi_set_state(c, "fmi2SetFMUstate", FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    if (!c) return fmi2Error;
    mbi_free_state((mbi_state **)FMUstate);
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    if (!c) return fmi2Error;
    return (fmi2Status)mbi_serialized_size(c, "fmi2SerializedFMUstateSize", FMUstate, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    if (!c) return fmi2Error;
    return (fmi2Status)mbi_serialize(c, "fmi2SerializeFMUstate", FMUstate, (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    if (!c) return fmi2Error;
    if (!FMUstate) return FAIL(c, "fmi2DeSerializeFMUstate: FMUstate is NULL");
    return (fmi2Status)mbi_deserialize(c, "fmi2DeSerializeFMUstate", (const unsigned char *)serializedState, size,
                                       (mbi_state **)FMUstate);
}

/* ------------------------------------------- model exchange: not this FMU's type */
#define NOT_ME(call) return c ? FAIL(c, "%s: %s is a co-simulation FMU", call, MB_MODEL.identifier) : fmi2Error;

fmi2Status fmi2EnterEventMode(fmi2Component c) { NOT_ME("fmi2EnterEventMode") }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) { (void)e; NOT_ME("fmi2NewDiscreteStates") }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { NOT_ME("fmi2EnterContinuousTimeMode") }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean a, fmi2Boolean *b, fmi2Boolean *d)
{ (void)a, (void)b, (void)d; NOT_ME("fmi2CompletedIntegratorStep") }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { (void)t; NOT_ME("fmi2SetTime") }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) { (void)x, (void)n; NOT_ME("fmi2SetContinuousStates") }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) { (void)d, (void)n; NOT_ME("fmi2GetDerivatives") }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real e[], size_t n) { (void)e, (void)n; NOT_ME("fmi2GetEventIndicators") }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { (void)x, (void)n; NOT_ME("fmi2GetContinuousStates") }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { (void)x, (void)n; NOT_ME("fmi2GetNominalsOfContinuousStates") }
