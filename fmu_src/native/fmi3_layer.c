/* The FMI 3.0 co-simulation interface of every native FMU of the kit, over the FMI 2.0
   layer of the same build (fmi2_layer.c; the build's linker version script exports only
   the fmi3 functions, so the fmi2 ones stay inside the binary): one implementation of the variables, the model's init/step,
   the failure rules, the FMU-state block and its checksum serves both standards, and
   the two give the same numbers bit for bit. Like the Reference FMUs'
   fmi3Functions.c beside fmi2Functions.c, over the same model file.

   What this file adds is FMI 3's: the instance states (Instantiated, InitializationMode,
   StepMode, StepDiscarded, Terminated) with fmi3Error and a log line for every call the
   standard does not allow in the current state; arrays (an FMI 3 variable takes the
   value reference of its first FMI 2 element and covers the consecutive ones);
   Enumerations read and written as Int64; the FMI 3 logger (text only, never a format);
   fmi3DoStep's out arguments. The FMU has no event mode, no clocks, no intermediate
   update and no model exchange: those calls answer fmi3Error with a log line. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"
#include "model.h"
#include "crc32.h"
#include "fmi3_variables.h"   /* generated: the FMI 3 variables (arrays, kinds) by FMI 2 value reference */

/* P_INIT_FAILED: the error state after fmi3ExitInitializationMode answered fmi3Error; only
   reads (for diagnosis), fmi3Reset, fmi3FreeInstance and the FMU-state calls lead on
   (fuzz.c: fmi3SetFloat64 and the other setters of no values answered fmi3OK there). */
enum phase3 { P_INSTANTIATED = 1, P_INITIALIZATION = 2, P_STEP = 4, P_STEP_DISCARDED = 8, P_TERMINATED = 16,
              P_INIT_FAILED = 32 };
static const char *phase_name(int p)
{
    switch (p) {
    case P_INSTANTIATED: return "Instantiated";
    case P_INITIALIZATION: return "InitializationMode";
    case P_INIT_FAILED: return "InitializationMode after a failed initialization (the error state)";
    case P_STEP: return "StepMode";
    case P_STEP_DISCARDED: return "StepDiscarded";
    default: return "Terminated";
    }
}


/* The Float64 value references of an instance's last get (or set) call, checked, as runs
   of consecutive FMI 2 elements (run_of): the C master passes the same arrays every step,
   so a call repeating the last one's array compares it (memcmp) instead of checking each
   value reference's kind and finding the runs again. The call's state and each value's
   causality are checked on every call still (allowed, the inner layer). */
typedef struct {
    size_t nvr, nValues, nruns, capacity;
    int has_time;                 /* the independent variable is among them */
    fmi3ValueReference *vr;       /* the call's array */
    fmi3ValueReference *first;    /* each run's first value reference (VR_TIME: the time, alone) */
    size_t *count;                /* and how many values it covers */
} plan;

typedef struct {
    fmi2Component inner;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    int phase;
    double start_time;   /* time before the first step (the FMI 2 layer reports the last step's) */
    const char *integer_call;   /* the fmi3 Int32/Int64 call under way: the inner layer's Integer lines name it */
    unsigned char kind3[MB3_NVARS + 1];
    int count3[MB3_NVARS + 1];
    fmi2ValueReference vr2[MB3_NVARS];   /* vr2[k] = k: the FMI 2 element value references */
    plan get_plan, set_plan;   /* fmi3GetFloat64's and fmi3SetFloat64's */
} instance3;

/* An FMU state: the inner layer's (which holds the stopTime) and the FMI 3 layer's own,
   the instance state (mode) and the start time with it (as the Reference FMUs'
   setFMUState restores them). */
typedef struct {
    int phase;
    double start_time;
    fmi2FMUstate inner;
} state3;

/* The variable table of an instance: value reference -> FMI 3 kind and element count
   (fmi3_variables.h; K_NONE: a later element of an array, e.g. leg_force[2]); the
   independent variable time takes the value reference one past the FMI 2 ones. */
enum { VR_TIME = MB3_NVARS };

static void build_tables(instance3 *inst)
{
    for (int vr = 0; vr < MB3_NVARS; vr++) {
        inst->vr2[vr] = (fmi2ValueReference)vr;
        inst->count3[vr] = MB3_COUNT[vr];
        inst->kind3[vr] = MB3_KIND[vr];
    }
    inst->kind3[VR_TIME] = K_FLOAT64;
    inst->count3[VR_TIME] = 1;
}

/* ---------------------------------------------------------------------- logging */
static void say(instance3 *inst, fmi3Status status, const char *category, const char *fmt, ...)
{
    if (!inst || !inst->log) return;
    char text[1400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    inst->log(inst->env, status, category, text);
}

#define FAIL(inst, ...) (say((inst), fmi3Error, "logStatusError", __VA_ARGS__), fmi3Error)

/* The inner layer names its own functions; its log lines are shown under the FMI 3 names. */
static const char *const RENAMES[][2] = {
    {"fmi2GetReal", "fmi3GetFloat64"}, {"fmi2SetReal", "fmi3SetFloat64"},
    {"fmi2SerializeFMUstate", "fmi3SerializeFMUState"}, {"fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"},
    {"fmi2GetInteger", "fmi3GetInt32"}, {"fmi2SetInteger", "fmi3SetInt32"},
    {"fmi2SetupExperiment", "fmi3EnterInitializationMode"}, {"fmi2Instantiate", "fmi3InstantiateCoSimulation"},
    {"fmi2", "fmi3"}};

static void inner_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                         fmi2String fmt, ...)
{
    (void)name;
    instance3 *inst = env;
    char text[1400], renamed[1500];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    const char *out = text;
    /* misuse harness: a refused fmi3SetInt64 logged "fmi3SetInt32: ..." */
    size_t integer = strlen("fmi2SetInteger");
    if (inst && inst->integer_call && (strncmp(text, "fmi2SetInteger", integer) == 0 ||
                                       strncmp(text, "fmi2GetInteger", integer) == 0)) {
        snprintf(renamed, sizeof renamed, "%s%s", inst->integer_call, text + integer);
        out = renamed;
    }
    for (size_t k = 0; out == text && k < sizeof RENAMES / sizeof RENAMES[0]; k++) {
        size_t n = strlen(RENAMES[k][0]);
        if (strncmp(text, RENAMES[k][0], n) == 0) {
            snprintf(renamed, sizeof renamed, "%s%s", RENAMES[k][1], text + n);
            out = renamed;
            break;
        }
    }
    if (inst && inst->log) inst->log(inst->env, (fmi3Status)status, category, out);
}

static void *alloc_(size_t n, size_t size) { return calloc(n, size); }

/* Is the call allowed in the current state? If not: fmi3Error with a log line. */
static int allowed(instance3 *inst, const char *function, int mask)
{
    if (inst->phase & mask) return 1;
    say(inst, fmi3Error, "logStatusError", "%s: not allowed in state %s", function, phase_name(inst->phase));
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
    static const char *const known[] = {"logStatusWarning", "logStatusDiscard", "logStatusError",
                                        "logStatusFatal", "logAll"};
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    for (size_t n = 0; n < nCategories; n++) {
        int found = 0;
        for (size_t k = 0; k < sizeof known / sizeof known[0]; k++)
            found |= categories && categories[n] && strcmp(categories[n], known[k]) == 0;
        if (!found)
            return FAIL(inst, "fmi3SetDebugLogging: unknown log category '%s'",
                        categories && categories[n] ? categories[n] : "(null)");
    }
    return (fmi3Status)fmi2SetDebugLogging(inst->inner, loggingOn, nCategories, categories);
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
    (void)resourcePath, (void)earlyReturnAllowed, (void)requiredIntermediateVariables, (void)intermediateUpdate;
    instance3 probe = {0};
    probe.env = instanceEnvironment;
    probe.log = logMessage;
    if (MB_MODEL.nvars != MB3_NVARS) {
        say(&probe, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: fmi3_variables.h was generated for "
            "another model than %s", MB_MODEL.identifier);
        return NULL;
    }
    if (eventModeUsed) {
        say(&probe, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: %s has no event mode (hasEventMode is false)",
            MB_MODEL.identifier);
        return NULL;
    }
    if (nRequiredIntermediateVariables) {
        say(&probe, fmi3Error, "logStatusError", "fmi3InstantiateCoSimulation: %s provides no intermediate variables",
            MB_MODEL.identifier);
        return NULL;
    }
    if (!instantiationToken || strcmp(instantiationToken, MB_MODEL.guid) != 0) {
        say(&probe, fmi3Error, "logStatusError",
            "fmi3InstantiateCoSimulation: instantiationToken '%s' is not this FMU's '%s'",
            instantiationToken ? instantiationToken : "(null)", MB_MODEL.guid);
        return NULL;
    }
    instance3 *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    *inst = probe;
    build_tables(inst);
    fmi2CallbackFunctions cb = {inner_logger, alloc_, free, NULL, inst};
    inst->inner = fmi2Instantiate(instanceName, fmi2CoSimulation, MB_MODEL.guid, resourcePath, &cb, visible,
                                      loggingOn);
    if (!inst->inner) {
        free(inst);
        return NULL;
    }
    inst->phase = P_INSTANTIATED;
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible, (void)loggingOn;
    instance3 probe = {0};
    probe.env = instanceEnvironment;
    probe.log = logMessage;
    say(&probe, fmi3Error, "logStatusError", "fmi3InstantiateModelExchange: %s is a co-simulation FMU",
        MB_MODEL.identifier);
    return NULL;
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
    instance3 probe = {0};
    probe.env = instanceEnvironment;
    probe.log = logMessage;
    say(&probe, fmi3Error, "logStatusError", "fmi3InstantiateScheduledExecution: %s is a co-simulation FMU",
        MB_MODEL.identifier);
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    instance3 *inst = instance;
    if (!inst) return;
    fmi2FreeInstance(inst->inner);
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
    INSTANCE("fmi3EnterInitializationMode", P_INSTANTIATED)
    /* the inner layer keeps the stopTime: it refuses one before the startTime and every
       step past it, under this function's and fmi3DoStep's names (RENAMES) */
    fmi2Status s = fmi2SetupExperiment(inst->inner, toleranceDefined, tolerance, startTime, stopTimeDefined,
                                           stopTime);
    if (s > fmi2Warning) return (fmi3Status)s;
    inst->start_time = startTime;
    s = fmi2EnterInitializationMode(inst->inner);
    if (s <= fmi2Warning) inst->phase = P_INITIALIZATION;
    return (fmi3Status)s;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    INSTANCE("fmi3ExitInitializationMode", P_INITIALIZATION)
    fmi2Status s = fmi2ExitInitializationMode(inst->inner);
    inst->phase = s <= fmi2Warning ? P_STEP : P_INIT_FAILED;
    return (fmi3Status)s;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    INSTANCE("fmi3Terminate", P_STEP | P_STEP_DISCARDED)
    fmi2Status s = fmi2Terminate(inst->inner);
    if (s <= fmi2Warning) inst->phase = P_TERMINATED;
    return (fmi3Status)s;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    fmi2Status s = fmi2Reset(inst->inner);
    if (s <= fmi2Warning) inst->phase = P_INSTANTIATED;
    return (fmi3Status)s;
}

/* ---------------------------------------------------------------- get and set */
enum { GETTABLE = P_INITIALIZATION | P_INIT_FAILED | P_STEP | P_STEP_DISCARDED | P_TERMINATED,
       SETTABLE = P_INSTANTIATED | P_INITIALIZATION | P_STEP };

/* Check the value references (each an FMI 3 variable of ``kind``) and the values
   buffer against nValues. */
static int check_refs(instance3 *inst, const char *function, const fmi3ValueReference vr[], size_t nvr,
                      const void *values, size_t nValues, int kind)
{
    size_t total = 0;
    if (nvr && !vr) {
        say(inst, fmi3Error, "logStatusError", "%s: valueReferences is NULL", function);
        return 0;
    }
    for (size_t k = 0; k < nvr; k++) {
        if (vr[k] > (fmi3ValueReference)VR_TIME || inst->kind3[vr[k]] != kind) {
            say(inst, fmi3Error, "logStatusError", "%s: no %s variable has value reference %u", function,
                 kind == K_FLOAT64 ? "Float64" : kind == K_INT32 ? "Int32" : "Enumeration (Int64)", (unsigned)vr[k]);
            return 0;
        }
        total += (size_t)inst->count3[vr[k]];
    }
    if (total && !values) {
        say(inst, fmi3Error, "logStatusError", "%s: values is NULL", function);
        return 0;
    }
    if (total != nValues) {
        say(inst, fmi3Error, "logStatusError", "%s: the value references cover %zu values, nValues is %zu", function, total, nValues);
        return 0;
    }
    return 1;
}

/* How many values from vr[k] on form one run of consecutive FMI 2 elements (the FMI 3
   variables vr[k], vr[k+1], ... one after the other, time excluded), and how many
   variables that is (*nvars): one inner call per run (a pose's six scalars, the
   telescope's 60 outputs), not one per variable, so FMI 3 costs what FMI 2 does. */
static size_t run_of(const instance3 *inst, const fmi3ValueReference vr[], size_t nvr, size_t k, size_t *nvars)
{
    size_t n = (size_t)inst->count3[vr[k]], j = k + 1;
    while (j < nvr && vr[j] != VR_TIME && vr[j] == vr[k] + n) n += (size_t)inst->count3[vr[j++]];
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
            say(inst, fmi3Error, "logStatusError", "%s: out of memory for %zu value references", function, nvr);
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
            p->count[p->nruns] = run_of(inst, vr, nvr, k, &nvars);
        }
    }
    if (nvr) memcpy(p->vr, vr, nvr * sizeof *vr);   /* fuzz.c under UBSan: no value references, p->vr NULL */
    p->nvr = nvr;
    p->nValues = nValues;
    return p;
}

/* May the FMI 2 element vr be set in the instance's state? (the inner layer's rule:
   inputs always, parameters before the end of initialization, outputs never) */
static int settable_now(const instance3 *inst, fmi3ValueReference vr)
{
    int causality = MB_MODEL.vars[vr].causality;
    return causality == MB_INPUT ||
           (causality == MB_PARAMETER && (inst->phase & (P_INSTANTIATED | P_INITIALIZATION)));
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues)
{
    INSTANCE("fmi3GetFloat64", GETTABLE)
    const plan *p = plan_of(inst, &inst->get_plan, "fmi3GetFloat64", vr, nvr, values, nValues);
    if (!p) return fmi3Error;
    for (size_t k = 0; k < p->nruns; k++) {
        if (p->first[k] == VR_TIME) {   /* fmi2GetRealStatus answers only after initialization */
            if (inst->phase & (P_INSTANTIATED | P_INITIALIZATION | P_INIT_FAILED)) *values++ = inst->start_time;
            else fmi2GetRealStatus(inst->inner, fmi2LastSuccessfulTime, values++);
            continue;
        }
        fmi2Status s = fmi2GetReal(inst->inner, &inst->vr2[p->first[k]], p->count[k], values);
        if (s > fmi2Warning) return (fmi3Status)s;   /* a non-finite output: fmi2GetReal's line */
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
    /* every element settable before any is set: a refused call sets nothing (fuzz.c: the
       runs before a refused one were set, with fmi3Error). The refused element goes to the
       inner layer alone, which refuses it with its line. */
    const fmi3Float64 *at = values;
    for (size_t k = 0; k < p->nruns; k++)
        for (size_t e = 0; e < p->count[k]; e++, at++)
            if (!settable_now(inst, p->first[k] + (fmi3ValueReference)e)) {
                fmi2Status s = fmi2SetReal(inst->inner, &inst->vr2[p->first[k] + e], 1, at);
                return s > fmi2Warning ? (fmi3Status)s : FAIL(inst, "fmi3SetFloat64: value reference %u cannot be set now",
                                                              (unsigned)(p->first[k] + e));
            }
    for (size_t k = 0; k < p->nruns; k++) {
        fmi2Status s = fmi2SetReal(inst->inner, &inst->vr2[p->first[k]], p->count[k], values);
        if (s > fmi2Warning) return (fmi3Status)s;
        values += p->count[k];
    }
    return fmi3OK;
}

/* Int32 variables and (as Int64) Enumerations: the inner layer's Integers, element by
   element, every element checked (range, settable) before any is set. */
#define INTEGER_ACCESS(NAME, TYPE, KIND)                                                                         \
    fmi3Status fmi3Get##NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, TYPE values[],    \
                             size_t nValues)                                                                     \
    {                                                                                                            \
        INSTANCE("fmi3Get" #NAME, GETTABLE)                                                                      \
        if (!check_refs(inst, "fmi3Get" #NAME, vr, nvr, values, nValues, KIND)) return fmi3Error;                        \
        size_t at = 0;                                                                                           \
        for (size_t k = 0; k < nvr; k++)                                                                         \
            for (int e = 0; e < inst->count3[vr[k]]; e++) {                                                            \
                fmi2Integer v;                                                                                   \
                inst->integer_call = "fmi3Get" #NAME;                                                            \
                fmi2Status s = fmi2GetInteger(inst->inner, &inst->vr2[vr[k] + (fmi3ValueReference)e], 1, &v);      \
                inst->integer_call = NULL;                                                                       \
                if (s > fmi2Warning) return (fmi3Status)s;                                                       \
                values[at++] = (TYPE)v;                                                                          \
            }                                                                                                    \
        return fmi3OK;                                                                                           \
    }                                                                                                            \
    fmi3Status fmi3Set##NAME(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,                   \
                             const TYPE values[], size_t nValues)                                                \
    {                                                                                                            \
        INSTANCE("fmi3Set" #NAME, SETTABLE)                                                                      \
        if (!check_refs(inst, "fmi3Set" #NAME, vr, nvr, values, nValues, KIND)) return fmi3Error;                        \
        size_t at = 0;                                                                                           \
        for (size_t k = 0; k < nvr; k++)                                                                         \
            for (int e = 0; e < inst->count3[vr[k]]; e++) {                                                      \
                TYPE v = values[at++];                                                                           \
                if (v < -2147483647 - 1 || v > 2147483647)                                                       \
                    return FAIL(inst, "fmi3Set" #NAME ": %s = %lld is outside the Int32 range",                 \
                                MB_MODEL.vars[vr[k]].name, (long long)v);                                        \
                if (!settable_now(inst, vr[k] + (fmi3ValueReference)e)) {                                       \
                    fmi2Integer w = (fmi2Integer)v;   /* the inner layer refuses it, with its line */            \
                    inst->integer_call = "fmi3Set" #NAME;                                                        \
                    fmi2Status s = fmi2SetInteger(inst->inner, &inst->vr2[vr[k] + (fmi3ValueReference)e], 1, &w);\
                    inst->integer_call = NULL;                                                                   \
                    return s > fmi2Warning ? (fmi3Status)s : FAIL(inst, "fmi3Set" #NAME ": cannot be set now");  \
                }                                                                                                \
            }                                                                                                    \
        at = 0;                                                                                                  \
        for (size_t k = 0; k < nvr; k++)                                                                         \
            for (int e = 0; e < inst->count3[vr[k]]; e++) {                                                      \
                fmi2Integer w = (fmi2Integer)values[at++];                                                       \
                inst->integer_call = "fmi3Set" #NAME;                                                            \
                fmi2Status s = fmi2SetInteger(inst->inner, &inst->vr2[vr[k] + (fmi3ValueReference)e], 1, &w);     \
                inst->integer_call = NULL;                                                                       \
                if (s > fmi2Warning) return (fmi3Status)s;                                                       \
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
NONE_OF(String, fmi3String, fmi3String)

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
    INSTANCE("fmi3DoStep", P_STEP)
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return FAIL(inst, "fmi3DoStep: an out argument is NULL");
    /* the communication point, the step size, its resolution and the stopTime are the inner
       fmi2DoStep's checks (their lines renamed to fmi3DoStep) */
    fmi2Status s = fmi2DoStep(inst->inner, currentCommunicationPoint, communicationStepSize,
                                  noSetFMUStatePriorToCurrentPoint);
    fmi2Real last = currentCommunicationPoint;
    fmi2GetRealStatus(inst->inner, fmi2LastSuccessfulTime, &last);
    *eventHandlingNeeded = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = last;
    /* a refused step ends the run: the instance takes no further step (fmi2_layer.c) */
    *terminateSimulation = s == fmi2Discard ? fmi3True : fmi3False;
    if (s == fmi2Discard) inst->phase = P_STEP_DISCARDED;
    return (fmi3Status)s;
}


/* The derivative of order n of an output is the output declared its n-th time derivative
   (MB3_DERIVATIVE, from the catalogue (fmu_src/catalogue.py, output_derivatives): the telescope's rate and
   acceleration outputs, computed analytically with the pose), read at the same point. */
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    INSTANCE("fmi3GetOutputDerivatives", P_STEP | P_STEP_DISCARDED | P_TERMINATED)
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
        fmi2Status s = fmi2GetReal(inst->inner, &inst->vr2[d], (size_t)inst->count3[vr[k]], values);
        if (s > fmi2Warning) return (fmi3Status)s;
        values += inst->count3[vr[k]];
    }
    return fmi3OK;
}

/* ------------------------------------------------------------------ FMU states */
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    if (!FMUState) return FAIL(inst, "fmi3GetFMUState: FMUState is NULL");
    state3 *st = *FMUState;
    if (!st) {
        st = calloc(1, sizeof *st);
        if (!st) return FAIL(inst, "fmi3GetFMUState: out of memory");
    }
    fmi2Status s = fmi2GetFMUstate(inst->inner, &st->inner);
    if (s > fmi2Warning) {
        if (!*FMUState) free(st);
        return (fmi3Status)s;
    }
    st->phase = inst->phase;
    st->start_time = inst->start_time;
    *FMUState = st;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    state3 *st = FMUState;
    if (!st) return FAIL(inst, "fmi3SetFMUState: FMUState is NULL");
    fmi2Status s = fmi2SetFMUstate(inst->inner, st->inner);
    /* the mode the state was saved in, as the inner layer restores its own (misuse
       harness: a state saved in Terminated was restored in StepMode, one saved in
       InitializationMode in Instantiated) */
    if (s <= fmi2Warning) {
        inst->phase = st->phase;
        inst->start_time = st->start_time;
    }
    return (fmi3Status)s;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    if (!FMUState || !*FMUState) return fmi3OK;
    state3 *st = *FMUState;
    fmi2FreeFMUstate(inst->inner, &st->inner);
    free(st);
    *FMUState = NULL;
    return fmi3OK;
}

/* Serialised: the FMI 3 layer's part in HEADER3 bytes (the instance state: 8 bytes; the
   start time: 8 bytes, this platform's double; the CRC-32 of those 16 bytes: 8 bytes),
   then the inner layer's serialised state (its magic, identifier and checksum; the
   stopTime in it). Without the checksum of its own (fuzz.c), a byte changed in the
   instance state (StepMode 4 ^ 0x0c = StepDiscarded 8) or in the start time was accepted. */
enum { HEADER3 = 24 };
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    state3 *st = FMUState;
    if (!st || !size) return FAIL(inst, "fmi3SerializedFMUStateSize: no FMU state or no size");
    size_t inner = 0;
    fmi2Status s = fmi2SerializedFMUstateSize(inst->inner, st->inner, &inner);
    *size = HEADER3 + inner;
    return (fmi3Status)s;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    state3 *st = FMUState;
    if (!st || !serializedState || size < HEADER3)
        return FAIL(inst, "fmi3SerializeFMUState: no FMU state, or the buffer is too small");
    long long phase = st->phase;
    memcpy(serializedState, &phase, 8);
    memcpy(serializedState + 8, &st->start_time, 8);
    unsigned long long crc = mb_crc32(serializedState, 16);
    memcpy(serializedState + 16, &crc, 8);
    return (fmi3Status)fmi2SerializeFMUstate(inst->inner, st->inner, (fmi2Byte *)serializedState + HEADER3,
                                             size - HEADER3);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    instance3 *inst = instance;
    if (!inst) return fmi3Error;
    long long phase = 0;
    double start_time = 0;
    unsigned long long crc = 0;
    if (serializedState && size >= HEADER3) {
        memcpy(&phase, serializedState, 8);
        memcpy(&start_time, serializedState + 8, 8);
        memcpy(&crc, serializedState + 16, 8);
    }
    if (!FMUState || !serializedState || size < HEADER3 || crc != mb_crc32(serializedState, 16) ||
        (phase != P_INSTANTIATED && phase != P_INITIALIZATION && phase != P_STEP && phase != P_STEP_DISCARDED &&
         phase != P_TERMINATED && phase != P_INIT_FAILED))
        return FAIL(inst, "fmi3DeserializeFMUState: the bytes are not a serialised %s state (%zu bytes)",
                    MB_MODEL.identifier, size);
    state3 *st = *FMUState;
    int fresh = !st;
    if (fresh) {
        st = calloc(1, sizeof *st);
        if (!st) return FAIL(inst, "fmi3DeserializeFMUState: out of memory");
    }
    fmi2Status s = fmi2DeSerializeFMUstate(inst->inner, (const fmi2Byte *)serializedState + HEADER3, size - HEADER3,
                                           &st->inner);
    if (s > fmi2Warning) {
        if (fresh) free(st);
        return (fmi3Status)s;
    }
    st->phase = (int)phase;
    st->start_time = start_time;
    *FMUState = st;
    return fmi3OK;
}

/* ------------------------------------- what this co-simulation FMU does not offer */
#define NOT_OFFERED(call, why)                                                               \
    {                                                                                        \
        instance3 *inst = instance;                                                          \
        if (!inst) return fmi3Error;                                                         \
        return FAIL(inst, "%s: %s (%s)", call, why, MB_MODEL.identifier);                  \
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
