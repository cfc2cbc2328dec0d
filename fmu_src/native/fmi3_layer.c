/* The FMI 3.0 co-simulation interface of every native FMU of the kit: the fmi3 functions
   mapped onto the instance core (instance.h) that the FMI 2.0 layer (fmi2_layer.c) maps
   the fmi2 ones onto, as the Reference FMUs' fmi3Functions.c beside fmi2Functions.c over
   their cosimulation.c: one implementation of the variables, the model's init/step, the
   failure rules and the FMU-state block serves both standards, and the two give the same
   numbers bit for bit.

   What this file adds is FMI 3's: the instance states (Instantiated, InitializationMode,
   StepMode, StepDiscarded, Terminated, and the error state after a failed
   initialization) with fmi3Error and a log line for every call the standard does not
   allow in the current state; arrays (an FMI 3 variable takes the value reference of
   its first element in the core's table and covers the consecutive ones);
   Enumerations read and written as Int64; the FMI 3 logger (text only, never a format);
   fmi3DoStep's out arguments; output derivatives. The FMU has no event mode, no clocks,
   no intermediate update and no model exchange: those calls answer fmi3Error with a
   log line. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "instance.h"
#include "fmi3_variables.h"   /* generated: the FMI 3 variables (arrays, kinds) by the core's value reference */

/* After a failed fmi3ExitInitializationMode (MBI_INIT_FAILED, the error state) only reads
   (for diagnosis), fmi3Reset, fmi3FreeInstance and the FMU-state calls lead on (fuzz.c:
   fmi3SetFloat64 and the other setters of no values answered fmi3OK there). */
enum { GETTABLE = MBI_INITIALIZATION | MBI_INIT_FAILED | MBI_STEP | MBI_STEP_FAILED | MBI_TERMINATED,
       SETTABLE = MBI_INSTANTIATED | MBI_INITIALIZATION | MBI_STEP };

static const char *phase_name(int phase)
{
    switch (phase) {
    case MBI_INSTANTIATED: return "Instantiated";
    case MBI_INITIALIZATION: return "InitializationMode";
    case MBI_INIT_FAILED: return "InitializationMode after a failed initialization (the error state)";
    case MBI_STEP: return "StepMode";
    case MBI_STEP_FAILED: return "StepDiscarded";
    default: return "Terminated";
    }
}

/* The Float64 value references of an instance's last get (or set) call, checked, as runs
   of consecutive elements (run_of): the C master passes the same arrays every step, so a
   call repeating the last one's array compares it (memcmp) instead of checking each value
   reference's kind and finding the runs again. The call's state and each value's
   causality are checked on every call still (allowed, the core). */
typedef struct {
    size_t nvr, nValues, nruns, capacity;
    int has_time;                 /* the independent variable is among them */
    fmi3ValueReference *vr;       /* the call's array */
    fmi3ValueReference *first;    /* each run's first value reference (VR_TIME: the time, alone) */
    size_t *count;                /* and how many values it covers */
} plan;

/* The host's logger, which the core's copy of it hands back to logger3. */
typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} host3;

typedef struct {
    mb_instance *core;
    mbi_vr vr[MB3_NVARS];          /* vr[k] = k: the core's value references, for runs of them */
    plan get_plan, set_plan;       /* fmi3GetFloat64's and fmi3SetFloat64's */
} instance3;

/* The variable table: value reference -> FMI 3 kind and element count (fmi3_variables.h;
   K_NONE: a later element of an array, e.g. leg_force[2]); the independent variable time
   takes the value reference one past the core's. Callers check vr <= VR_TIME. */
enum { VR_TIME = MB3_NVARS };
static int kind_of(fmi3ValueReference vr) { return vr == VR_TIME ? K_FLOAT64 : MB3_KIND[vr]; }
static size_t count_of(fmi3ValueReference vr) { return vr == VR_TIME ? 1 : (size_t)MB3_COUNT[vr]; }

/* ---------------------------------------------------------------------- logging */
static void logger3(const void *env, const char *name, mbi_status status, const char *category, const char *text)
{
    (void)name;
    const host3 *host = env;
    if (host->log) host->log(host->env, (fmi3Status)status, category, text);
}

#define SAY(inst, ...) mbi_logf((inst)->core, MBI_ERROR, __VA_ARGS__)
#define FAIL(inst, ...) (SAY(inst, __VA_ARGS__), fmi3Error)

/* Is the call allowed in the current state? If not: fmi3Error with a log line. */
static int allowed(instance3 *inst, const char *function, int mask)
{
    int phase = mbi_phase(inst->core);
    if (phase & mask) return 1;
    SAY(inst, "%s: not allowed in state %s", function, phase_name(phase));
    return 0;
}

#define INSTANCE(function, mask)                                   \
    instance3 *inst = instance;                                    \
    if (!inst) return fmi3Error;                                   \
    if (!allowed(inst, function, mask)) return fmi3Error;

/* ------------------------------------------------------------------- life cycle */
const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    for (size_t n = 0; n < nCategories; n++)   /* all known before any is switched */
        if (mbi_category(categories ? categories[n] : NULL) < 0)
            return FAIL(inst, "fmi3SetDebugLogging: unknown log category '%s'",
                        categories && categories[n] ? categories[n] : "(null)");
    if (nCategories == 0) mbi_set_logging(inst->core, -1, loggingOn);
    for (size_t n = 0; n < nCategories; n++) mbi_set_logging(inst->core, mbi_category(categories[n]), loggingOn);
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    (void)visible, (void)earlyReturnAllowed, (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    host3 host = {instanceEnvironment, logMessage};
    if (MB_MODEL.nvars != MB3_NVARS) {
        mbi_log_host(logger3, &host, instanceName, MBI_ERROR, "fmi3InstantiateCoSimulation: fmi3_variables.h was "
                     "generated for another model than %s", MB_MODEL.identifier);
        return NULL;
    }
    if (eventModeUsed) {
        mbi_log_host(logger3, &host, instanceName, MBI_ERROR, "fmi3InstantiateCoSimulation: %s has no event mode "
                     "(hasEventMode is false)", MB_MODEL.identifier);
        return NULL;
    }
    if (nRequiredIntermediateVariables) {
        mbi_log_host(logger3, &host, instanceName, MBI_ERROR, "fmi3InstantiateCoSimulation: %s provides no "
                     "intermediate variables", MB_MODEL.identifier);
        return NULL;
    }
    if (!instantiationToken || strcmp(instantiationToken, MB_MODEL.guid) != 0) {
        mbi_log_host(logger3, &host, instanceName, MBI_ERROR,
                     "fmi3InstantiateCoSimulation: instantiationToken '%s' is not this FMU's '%s'",
                     instantiationToken ? instantiationToken : "(null)", MB_MODEL.guid);
        return NULL;
    }
    instance3 *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->core = mbi_instantiate(instanceName, logger3, &host, sizeof host, loggingOn);
    if (inst->core && mbi_set_resources(inst->core, resourcePath)) {   /* the folder the model reads files from */
        mbi_free_instance(inst->core);
        inst->core = NULL;
    }
    if (!inst->core) {
        free(inst);
        return NULL;
    }
    for (int vr = 0; vr < MB3_NVARS; vr++) inst->vr[vr] = (mbi_vr)vr;
    return inst;
}

/* What a co-simulation FMU cannot be instantiated as: NULL, with a line. */
static fmi3Instance not_this_type(const char *function, fmi3InstanceEnvironment env, fmi3LogMessageCallback log)
{
    host3 host = {env, log};
    mbi_log_host(logger3, &host, NULL, MBI_ERROR, "%s: %s is a co-simulation FMU", function, MB_MODEL.identifier);
    return NULL;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    return not_this_type("fmi3InstantiateModelExchange", instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    return not_this_type("fmi3InstantiateScheduledExecution", instanceEnvironment, logMessage);
}

void fmi3FreeInstance(fmi3Instance instance)
{
    instance3 *inst = instance;
    if (!inst) return;
    mbi_free_instance(inst->core);
    for (plan *p = &inst->get_plan; p <= &inst->set_plan; p++) {
        free(p->vr);
        free(p->first);
        free(p->count);
    }
    free(inst);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    (void)toleranceDefined, (void)tolerance;
    INSTANCE("fmi3EnterInitializationMode", MBI_INSTANTIATED)
    /* the core keeps the stopTime: it refuses one before the startTime and every step past it */
    mbi_status s = mbi_setup_experiment(inst->core, "fmi3EnterInitializationMode", startTime, stopTimeDefined,
                                        stopTime);
    if (s > MBI_WARNING) return (fmi3Status)s;
    mbi_enter_initialization(inst->core);
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    INSTANCE("fmi3ExitInitializationMode", MBI_INITIALIZATION)
    return (fmi3Status)mbi_exit_initialization(inst->core);
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    INSTANCE("fmi3Terminate", MBI_STEP | MBI_STEP_FAILED)
    mbi_terminate(inst->core);
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    mbi_reset(inst->core);
    return fmi3OK;
}

/* ---------------------------------------------------------------- get and set */
/* Check the value references (each an FMI 3 variable of ``kind``) and the values
   buffer against nValues. */
static int check_refs(instance3 *inst, const char *function, const fmi3ValueReference vr[], size_t nvr,
                      const void *values, size_t nValues, int kind)
{
    size_t total = 0;
    if (nvr && !vr) {
        SAY(inst, "%s: valueReferences is NULL", function);
        return 0;
    }
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] > (fmi3ValueReference)VR_TIME || kind_of(vr[k]) != kind) {
            SAY(inst, "%s: no %s variable has value reference %u", function,
                kind == K_FLOAT64 ? "Float64" : kind == K_INT32 ? "Int32" : "Enumeration (Int64)", (unsigned)vr[k]);
            return 0;
        }
        total += count_of(vr[k]);
    }
    if (total && !values) {
        SAY(inst, "%s: values is NULL", function);
        return 0;
    }
    if (total != nValues) {
        SAY(inst, "%s: the value references cover %zu values, nValues is %zu", function, total, nValues);
        return 0;
    }
    return 1;
}

/* How many values from vr[k] on form one run of consecutive elements (the FMI 3
   variables vr[k], vr[k+1], ... one after the other, time excluded), and how many
   variables that is (*nvars): one core call per run (a pose's six scalars, the
   telescope's 60 outputs), not one per variable, so FMI 3 costs what FMI 2 does. */
static size_t run_of(const fmi3ValueReference vr[], size_t nvr, size_t k, size_t *nvars)
{
    size_t n = count_of(vr[k]), j = k + 1;
    while (j < nvr && vr[j] != VR_TIME && vr[j] == vr[k] + n) n += count_of(vr[j++]);
    *nvars = j - k;
    return n;
}

/* The plan of a Float64 call (see plan): the last one's when vr[] repeats its array, else
   vr[] checked (check_refs: fmi3Error and its line, NULL) and made the plan. */
static const plan *plan_of(instance3 *inst, plan *p, const char *function, const fmi3ValueReference vr[], size_t nvr,
                           const void *values, size_t nValues)
{
    if (nvr && vr && values && nvr == p->nvr && nValues == p->nValues && memcmp(vr, p->vr, nvr * sizeof *vr) == 0)
        return p;
    if (!check_refs(inst, function, vr, nvr, values, nValues, K_FLOAT64)) return NULL;
    p->nvr = 0;   /* no plan until this one is whole */
    if (nvr > p->capacity) {
        free(p->vr);
        free(p->first);
        free(p->count);
        p->vr = malloc(nvr * sizeof *p->vr);
        p->first = malloc(nvr * sizeof *p->first);
        p->count = malloc(nvr * sizeof *p->count);
        p->capacity = p->vr && p->first && p->count ? nvr : 0;
        if (!p->capacity) {
            SAY(inst, "%s: out of memory for %zu value references", function, nvr);
            return NULL;
        }
    }
    p->nruns = 0;
    p->has_time = 0;
    for (size_t k = 0, nvars; k < nvr; k += nvars, p->nruns++) {
        p->first[p->nruns] = vr[k];
        if (vr[k] == VR_TIME) {
            p->has_time = 1;
            p->count[p->nruns] = nvars = 1;
        } else {
            p->count[p->nruns] = run_of(vr, nvr, k, &nvars);
        }
    }
    if (nvr) memcpy(p->vr, vr, nvr * sizeof *vr);   /* fuzz.c under UBSan: no value references, p->vr NULL */
    p->nvr = nvr;
    p->nValues = nValues;
    return p;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    INSTANCE("fmi3GetFloat64", GETTABLE)
    const plan *p = plan_of(inst, &inst->get_plan, "fmi3GetFloat64", vr, nvr, values, nValues);
    if (!p) return fmi3Error;
    for (size_t k = 0; k < p->nruns; k++) {
        if (p->first[k] == VR_TIME) {   /* the start time until the first step may be taken */
            const mbi_core_state *s = mbi_core(inst->core);
            *values++ = s->phase & (MBI_INITIALIZATION | MBI_INIT_FAILED) ? s->start_time : s->time;
            continue;
        }
        mbi_status s = mbi_get_real(inst->core, "fmi3GetFloat64", &inst->vr[p->first[k]], p->count[k], values);
        if (s > MBI_WARNING) return (fmi3Status)s;   /* a non-finite output: the core's line */
        values += p->count[k];
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    INSTANCE("fmi3SetFloat64", SETTABLE)
    const plan *p = plan_of(inst, &inst->set_plan, "fmi3SetFloat64", vr, nvr, values, nValues);
    if (!p) return fmi3Error;
    if (p->has_time) return FAIL(inst, "fmi3SetFloat64: time is the independent variable, it cannot be set");
    /* every run settable before any is set: a refused call sets nothing (fuzz.c: the runs
       before a refused one were set, with fmi3Error) */
    for (size_t k = 0; k < p->nruns; k++)
        if (!mbi_settable_real(inst->core, "fmi3SetFloat64", &inst->vr[p->first[k]], p->count[k])) return fmi3Error;
    for (size_t k = 0; k < p->nruns; k++) {
        mbi_status s = mbi_set_real(inst->core, "fmi3SetFloat64", &inst->vr[p->first[k]], p->count[k], values);
        if (s > MBI_WARNING) return (fmi3Status)s;
        values += p->count[k];
    }
    return fmi3OK;
}

/* Int32 variables and (as Int64) Enumerations: the core's Integers, element by element,
   every element checked (range, settable) before any is set. */
#define INTEGER_ACCESS(NAME, TYPE, KIND)                                                                         \
    fmi3Status fmi3Get##NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, TYPE values[],    \
                             size_t nValues)                                                                     \
    {                                                                                                            \
        INSTANCE("fmi3Get" #NAME, GETTABLE)                                                                      \
        if (!check_refs(inst, "fmi3Get" #NAME, vr, nvr, values, nValues, KIND)) return fmi3Error;                \
        size_t at = 0;                                                                                           \
        for (size_t k = 0; k < nvr; k++)                                                                         \
            for (size_t e = 0; e < count_of(vr[k]); e++) {                                                       \
                int v;                                                                                           \
                mbi_status s = mbi_get_integer(inst->core, "fmi3Get" #NAME, &inst->vr[vr[k] + e], 1, &v);        \
                if (s > MBI_WARNING) return (fmi3Status)s;                                                       \
                values[at++] = (TYPE)v;                                                                          \
            }                                                                                                    \
        return fmi3OK;                                                                                           \
    }                                                                                                            \
    fmi3Status fmi3Set##NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,                   \
                             const TYPE values[], size_t nValues)                                                \
    {                                                                                                            \
        INSTANCE("fmi3Set" #NAME, SETTABLE)                                                                      \
        if (!check_refs(inst, "fmi3Set" #NAME, vr, nvr, values, nValues, KIND)) return fmi3Error;                \
        size_t at = 0;                                                                                           \
        for (size_t k = 0; k < nvr; k++)                                                                         \
            for (size_t e = 0; e < count_of(vr[k]); e++) {                                                       \
                TYPE v = values[at++];                                                                           \
                if (v < -2147483647 - 1 || v > 2147483647)                                                       \
                    return FAIL(inst, "fmi3Set" #NAME ": %s = %lld is outside the Int32 range",                 \
                                MB_MODEL.vars[vr[k]].name, (long long)v);                                        \
                if (!mbi_settable_integer(inst->core, "fmi3Set" #NAME, &inst->vr[vr[k] + e], 1))                 \
                    return fmi3Error;                                                                            \
            }                                                                                                    \
        at = 0;                                                                                                  \
        for (size_t k = 0; k < nvr; k++)                                                                         \
            for (size_t e = 0; e < count_of(vr[k]); e++) {                                                       \
                int w = (int)values[at++];                                                                       \
                mbi_status s = mbi_set_integer(inst->core, "fmi3Set" #NAME, &inst->vr[vr[k] + e], 1, &w);        \
                if (s > MBI_WARNING) return (fmi3Status)s;                                                       \
            }                                                                                                    \
        return fmi3OK;                                                                                           \
    }

INTEGER_ACCESS(Int32, fmi3Int32, K_INT32)
INTEGER_ACCESS(Int64, fmi3Int64, K_ENUM)

/* Types this FMU has no variables of: an empty call is fine, any reference is an error. */
#define NONE_OF(NAME, GETTYPE, SETTYPE)                                                                        \
    fmi3Status fmi3Get##NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, GETTYPE values[], \
                             size_t nValues)                                                                   \
    {                                                                                                          \
        (void)vr, (void)values, (void)nValues;                                                                 \
        INSTANCE("fmi3Get" #NAME, GETTABLE)                                                                    \
        if (nvr) return FAIL(inst, "fmi3Get" #NAME ": %s has no " #NAME " variables", MB_MODEL.identifier);   \
        return fmi3OK;                                                                                         \
    }                                                                                                          \
    fmi3Status fmi3Set##NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,                 \
                             const SETTYPE values[], size_t nValues)                                           \
    {                                                                                                          \
        (void)vr, (void)values, (void)nValues;                                                                 \
        INSTANCE("fmi3Set" #NAME, SETTABLE)                                                                    \
        if (nvr) return FAIL(inst, "fmi3Set" #NAME ": %s has no " #NAME " variables", MB_MODEL.identifier);   \
        return fmi3OK;                                                                                         \
    }

NONE_OF(Float32, fmi3Float32, fmi3Float32)
NONE_OF(Int8, fmi3Int8, fmi3Int8)
NONE_OF(UInt8, fmi3UInt8, fmi3UInt8)
NONE_OF(Int16, fmi3Int16, fmi3Int16)
NONE_OF(UInt16, fmi3UInt16, fmi3UInt16)
NONE_OF(UInt32, fmi3UInt32, fmi3UInt32)
NONE_OF(UInt64, fmi3UInt64, fmi3UInt64)
NONE_OF(Boolean, fmi3Boolean, fmi3Boolean)

/* Strings (scalars here: one value per value reference). */
static int string_refs(instance3 *inst, const char *function, const fmi3ValueReference vr[], size_t nvr,
                       const void *values, size_t nValues)
{
    if (nvr && (!vr || !values)) {
        SAY(inst, "%s: %s is NULL for %zu values", function, vr ? "values" : "the value reference array", nvr);
        return 0;
    }
    for (size_t k = 0; k < nvr; k++)
        if (vr[k] >= VR_TIME || MB3_KIND[vr[k]] != K_STRING) {
            SAY(inst, "%s: no String variable has value reference %u", function, (unsigned)vr[k]);
            return 0;
        }
    if (nvr != nValues) {
        SAY(inst, "%s: the value references cover %zu values, nValues is %zu", function, nvr, nValues);
        return 0;
    }
    return 1;
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3String values[],
                         size_t nValues)
{
    INSTANCE("fmi3GetString", GETTABLE)
    if (!string_refs(inst, "fmi3GetString", vr, nvr, values, nValues)) return fmi3Error;
    return (fmi3Status)mbi_get_string(inst->core, "fmi3GetString", vr, nvr, values);
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3String values[],
                         size_t nValues)
{
    INSTANCE("fmi3SetString", SETTABLE)
    if (!string_refs(inst, "fmi3SetString", vr, nvr, values, nValues)) return fmi3Error;
    return (fmi3Status)mbi_set_string(inst->core, "fmi3SetString", vr, nvr, values);
}

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues)
{
    (void)vr, (void)valueSizes, (void)values, (void)nValues;
    INSTANCE("fmi3GetBinary", GETTABLE)
    if (nvr) return FAIL(inst, "fmi3GetBinary: %s has no Binary variables", MB_MODEL.identifier);
    return fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues)
{
    (void)vr, (void)valueSizes, (void)values, (void)nValues;
    INSTANCE("fmi3SetBinary", SETTABLE)
    if (nvr) return FAIL(inst, "fmi3SetBinary: %s has no Binary variables", MB_MODEL.identifier);
    return fmi3OK;
}

/* ------------------------------------------------------------------- stepping */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    INSTANCE("fmi3DoStep", MBI_STEP)
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return FAIL(inst, "fmi3DoStep: an out argument is NULL");
    mbi_status s = mbi_step_refused(inst->core, "fmi3DoStep", currentCommunicationPoint, communicationStepSize)
                       ? MBI_ERROR : mbi_do_step(inst->core, currentCommunicationPoint, communicationStepSize);
    *eventHandlingNeeded = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = mbi_core(inst->core)->time;
    /* a refused step ends the run: the instance is StepDiscarded and takes no further step */
    *terminateSimulation = s == MBI_DISCARD ? fmi3True : fmi3False;
    return (fmi3Status)s;
}

/* The derivative of order n of an output is the output declared its n-th time derivative
   (MB3_DERIVATIVE, from the catalogue (fmu_src/catalogue.py, output_derivatives): the telescope's rate and
   acceleration outputs, computed analytically with the pose), read at the same point. */
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    INSTANCE("fmi3GetOutputDerivatives", MBI_STEP | MBI_STEP_FAILED | MBI_TERMINATED)
    if (MB3_MAX_DERIVATIVE_ORDER == 0)
        return FAIL(inst, "fmi3GetOutputDerivatives: maxOutputDerivativeOrder is 0");
    if (!check_refs(inst, "fmi3GetOutputDerivatives", vr, nvr, values, nValues, K_FLOAT64)) return fmi3Error;
    if (nvr && !orders) return FAIL(inst, "fmi3GetOutputDerivatives: orders is NULL");
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] == VR_TIME || MB_MODEL.vars[vr[k]].causality != MB_OUTPUT)
            return FAIL(inst, "fmi3GetOutputDerivatives: value reference %u is not an output", (unsigned)vr[k]);
        if (orders[k] < 1 || orders[k] > MB3_MAX_DERIVATIVE_ORDER)
            return FAIL(inst, "fmi3GetOutputDerivatives: order %d of %s: orders run from 1 to "
                        "maxOutputDerivativeOrder %d", (int)orders[k], MB_MODEL.vars[vr[k]].name,
                        MB3_MAX_DERIVATIVE_ORDER);
        int d = (int)vr[k];
        for (int order = 1; order <= orders[k]; order++) {
            d = MB3_DERIVATIVE[d];
            if (d < 0)
                return FAIL(inst, "fmi3GetOutputDerivatives: %s has no derivative of order %d (it has %d)",
                            MB_MODEL.vars[vr[k]].name, (int)orders[k], order - 1);
        }
        mbi_status s = mbi_get_real(inst->core, "fmi3GetOutputDerivatives", &inst->vr[d], count_of(vr[k]), values);
        if (s > MBI_WARNING) return (fmi3Status)s;
        values += count_of(vr[k]);
    }
    return fmi3OK;
}

/* ------------------------------------------------------------------ FMU states */
/* The core's state: the whole instance, its state (mode), start time and stopTime with
   it (as the Reference FMUs' setFMUState restores them); serialised with a checksum, so
   a byte changed anywhere (fuzz.c: StepMode turned StepDiscarded) is refused. */
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    if (!FMUState) return FAIL(inst, "fmi3GetFMUState: FMUState is NULL");
    return (fmi3Status)mbi_get_state(inst->core, "fmi3GetFMUState", (mbi_state **)FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    if (!FMUState) return FAIL(inst, "fmi3SetFMUState: FMUState is NULL");
    return (fmi3Status)mbi_set_state(inst->core, "fmi3SetFMUState", FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    if (!instance) return fmi3Error;
    mbi_free_state((mbi_state **)FMUState);
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    if (!FMUState || !size) return FAIL(inst, "fmi3SerializedFMUStateSize: no FMU state or no size");
    return (fmi3Status)mbi_serialized_size(inst->core, "fmi3SerializedFMUStateSize", FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    if (!FMUState || !serializedState)
        return FAIL(inst, "fmi3SerializeFMUState: no FMU state, or the buffer is too small");
    return (fmi3Status)mbi_serialize(inst->core, "fmi3SerializeFMUState", FMUState, serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    if (!FMUState || !serializedState)
        return FAIL(inst, "fmi3DeserializeFMUState: the bytes are not a serialised %s state (%zu bytes)",
                    MB_MODEL.identifier, size);
    return (fmi3Status)mbi_deserialize(inst->core, "fmi3DeserializeFMUState", serializedState, size,
                                       (mbi_state **)FMUState);
}

/* ------------------------------------- what this co-simulation FMU does not offer */
#define NOT_OFFERED(call, why)                                                               \
    {                                                                                        \
        instance3 *inst = instance;                                                          \
        if (!inst) return fmi3Error;                                                         \
        return FAIL(inst, "%s: %s (%s)", call, why, MB_MODEL.identifier);                    \
    }
#define NO_EVENTS(call) NOT_OFFERED(call, "no event mode, no clocks")
#define NOT_ME(call) NOT_OFFERED(call, "a co-simulation FMU")

fmi3Status fmi3EnterEventMode(fmi3Instance instance) NO_EVENTS("fmi3EnterEventMode")
fmi3Status fmi3EnterStepMode(fmi3Instance instance) NO_EVENTS("fmi3EnterStepMode")
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[])
{ (void)vr, (void)nvr, (void)values; NO_EVENTS("fmi3GetClock") }
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[])
{ (void)vr, (void)nvr, (void)values; NO_EVENTS("fmi3SetClock") }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{ (void)vr, (void)nvr, (void)intervals, (void)qualifiers; NO_EVENTS("fmi3GetIntervalDecimal") }
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[])
{ (void)vr, (void)nvr, (void)counters, (void)resolutions, (void)qualifiers; NO_EVENTS("fmi3GetIntervalFraction") }
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[])
{ (void)vr, (void)nvr, (void)shifts; NO_EVENTS("fmi3GetShiftDecimal") }
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{ (void)vr, (void)nvr, (void)counters, (void)resolutions; NO_EVENTS("fmi3GetShiftFraction") }
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[])
{ (void)vr, (void)nvr, (void)intervals; NO_EVENTS("fmi3SetIntervalDecimal") }
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{ (void)vr, (void)nvr, (void)counters, (void)resolutions; NO_EVENTS("fmi3SetIntervalFraction") }
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[])
{ (void)vr, (void)nvr, (void)shifts; NO_EVENTS("fmi3SetShiftDecimal") }
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{ (void)vr, (void)nvr, (void)counters, (void)resolutions; NO_EVENTS("fmi3SetShiftFraction") }
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) NO_EVENTS("fmi3EvaluateDiscreteStates")
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *a, fmi3Boolean *b, fmi3Boolean *c,
                                    fmi3Boolean *d, fmi3Boolean *e, fmi3Float64 *f)
{ (void)a, (void)b, (void)c, (void)d, (void)e, (void)f; NO_EVENTS("fmi3UpdateDiscreteStates") }
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{ (void)clockReference, (void)activationTime; NOT_OFFERED("fmi3ActivateModelPartition", "not a scheduled-execution FMU") }
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
    NOT_OFFERED("fmi3EnterConfigurationMode", "no structural parameters")
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
    NOT_OFFERED("fmi3ExitConfigurationMode", "no structural parameters")
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference vr, size_t *n)
{ (void)vr, (void)n; NOT_OFFERED("fmi3GetNumberOfVariableDependencies", "providesPerElementDependencies is false") }
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent, size_t a[],
                                       fmi3ValueReference b[], size_t c[], fmi3DependencyKind d[], size_t n)
{ (void)dependent, (void)a, (void)b, (void)c, (void)d, (void)n;
  NOT_OFFERED("fmi3GetVariableDependencies", "providesPerElementDependencies is false") }
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference a[], size_t na,
                                        const fmi3ValueReference b[], size_t nb, const fmi3Float64 c[], size_t nc,
                                        fmi3Float64 d[], size_t nd)
{ (void)a, (void)na, (void)b, (void)nb, (void)c, (void)nc, (void)d, (void)nd;
  NOT_OFFERED("fmi3GetDirectionalDerivative", "providesDirectionalDerivatives is false") }
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference a[], size_t na,
                                    const fmi3ValueReference b[], size_t nb, const fmi3Float64 c[], size_t nc,
                                    fmi3Float64 d[], size_t nd)
{ (void)a, (void)na, (void)b, (void)nb, (void)c, (void)nc, (void)d, (void)nd;
  NOT_OFFERED("fmi3GetAdjointDerivative", "providesAdjointDerivatives is false") }
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) NOT_ME("fmi3EnterContinuousTimeMode")
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean a, fmi3Boolean *b, fmi3Boolean *c)
{ (void)a, (void)b, (void)c; NOT_ME("fmi3CompletedIntegratorStep") }
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 t) { (void)t; NOT_ME("fmi3SetTime") }
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t n)
{ (void)x, (void)n; NOT_ME("fmi3SetContinuousStates") }
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 x[], size_t n)
{ (void)x, (void)n; NOT_ME("fmi3GetContinuousStateDerivatives") }
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 x[], size_t n)
{ (void)x, (void)n; NOT_ME("fmi3GetEventIndicators") }
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t n)
{ (void)x, (void)n; NOT_ME("fmi3GetContinuousStates") }
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 x[], size_t n)
{ (void)x, (void)n; NOT_ME("fmi3GetNominalsOfContinuousStates") }
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *n)
{ (void)n; NOT_ME("fmi3GetNumberOfEventIndicators") }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *n)
{ (void)n; NOT_ME("fmi3GetNumberOfContinuousStates") }
