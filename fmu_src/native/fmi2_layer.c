/* The FMI 2.0 co-simulation interface shared by every native FMU of the kit, over one
   model file (model.h says what a model provides). Like the Reference FMUs'
   fmi2Functions.c / cosimulation.c, without their macros: one instance struct, a
   variable table for get/set, a byte block holding everything an FMU state needs.

   Behaviour follows the pythonfmu FMUs (fmu_src/slave.py): a failing step answers
   fmi2Discard with an error log line saying what and when, the instance then refuses
   further steps, and the outputs keep the last accepted state; a failing initialization
   answers fmi2Error. The layer never prints and never aborts: every misuse is an
   fmi2Error with a log line. Memory comes from calloc/free (the modelDescription says
   canNotUseMemoryManagementFunctions).

   Rules every model gets from here, whatever its file forgets:
   - Log text reaches the host's logger as its format with every '%' doubled (a host
     string such as a GUID or a category holding "%s" is printed, never read as a
     conversion), and the line carries the status the call returns (Discard on a refused
     step, Error on a failed initialization or a misuse).
   - The FMI 2.0 call sequence (allowed() with each function's mask of states, as the Reference FMUs'
     fmi2Functions.c): a call outside its states answers fmi2Error. One deliberate
     difference: after a Discard the instance stays failed and answers every further
     doStep with fmi2Discard ("refusing doStep"), as the pythonfmu FMUs do.
   - doStep: currentCommunicationPoint must be the FMU's time (the end of the last
     accepted step, to 1e-9 relative), the step finite, > 0 and large enough to advance
     the time, and its end not past a stopTime given to fmi2SetupExperiment (a stopTime
     before the startTime is refused there), else fmi2Error.
   - No fmi2OK with a non-finite output: after every step and initialization each Real
     output is checked; one NaN/inf answers fmi2Discard (initialization: fmi2Error) with
     a line naming the outputs and the input or parameter of largest magnitude; and
     fmi2GetReal answers fmi2Error naming an output that is not finite (the outputs a
     refused initialization left).
   - Work bound: a model integrating on substeps asks mb_substeps (model.h), which
     refuses a step needing more than MB_MAX_SUBSTEPS substeps (fmi2Discard, a line
     saying how many it would need) instead of overflowing an int or running for hours.
   - A refused call changes nothing (every value reference is checked before any value
     is set; a NULL array with a count is refused), and what a read returns is a
     function of the values set, never of earlier reads: tests/c_host/fuzz.c replays the
     calls an instance accepted on a fresh one and compares every value bit for bit. */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"
#include "crc32.h"

/* FMI 2.0 states (bits, for the masks of allowed()); a failed step is STEPPING with
   layer_state.failed set (the standard's stepFailed). */
enum phase { INSTANTIATED = 1, INITIALIZATION = 2, STEPPING = 4, TERMINATED = 8 };
#define ANY_PHASE (INSTANTIATED | INITIALIZATION | STEPPING | TERMINATED)
#define READABLE (INITIALIZATION | STEPPING | TERMINATED)
static const char *phase_name(int phase, int failed)
{
    return phase == INSTANTIATED ? "the instantiated state (before fmi2EnterInitializationMode)"
         : phase == INITIALIZATION ? "initialization mode"
         : phase == STEPPING ? (failed ? "the failed state (after a Discard or a failed initialization)"
                                       : "step mode")
         : "the terminated state";
}
enum { CAT_WARNING, CAT_DISCARD, CAT_ERROR, CAT_FATAL, CAT_ALL, NCAT };
static const char *const CATEGORIES[NCAT] = {"logStatusWarning", "logStatusDiscard", "logStatusError",
                                             "logStatusFatal", "logAll"};

/* Everything of an instance that an FMU state holds, at the start of the block. */
typedef struct {
    double start_time;
    double time;              /* end of the last accepted step (fmi2LastSuccessfulTime) */
    double stop_time;         /* fmi2SetupExperiment's stopTime: no step may pass it, if stop_defined */
    int failed;
    int phase;                /* enum phase: an FMU state restores it */
    int stop_defined;
    char failure[1024];
} layer_state;

struct mb_instance {
    fmi2CallbackFunctions cb;
    char *name;
    int category_on[NCAT];
    int dirty;                /* initialization mode: inputs or parameters set since the outputs were computed */
    size_t size, r_off, i_off, m_off;
    unsigned char *block;     /* layer_state | double r[n] | int i[n] | model */
    unsigned char *backup;    /* r, i and the model before the running doStep (what a refused step restores) */
    unsigned char *access;    /* per value reference: enum access bits, from the variable table */
    int *output_runs;         /* the Real outputs as runs of consecutive value references: first, count, ... */
    int n_output_runs;
    char kind[64];
    char message[896];
};

typedef struct {
    size_t size;
    unsigned char data[];
} saved_state;

static const char MAGIC[8] = {'M', 'B', 'F', 'M', 'U', 'S', '3', '\0'};   /* 3: with the checksum */

#define LAYER(inst) ((layer_state *)(inst)->block)
#define PHASE(inst) (LAYER(inst)->phase)
#define REALS(inst) ((double *)((inst)->block + (inst)->r_off))
#define INTS(inst) ((int *)((inst)->block + (inst)->i_off))
#define MODEL(inst) ((void *)((inst)->block + (inst)->m_off))

/* What get/set may do with a value reference, one byte each, made at instantiation from
   the variable table: the calls a host repeats every step (the C master's fmi2SetReal and
   fmi2GetReal) check one byte per value reference, and only a call that fails one walks
   the table again to name the problem. */
enum access {
    A_REAL = 1,         /* a Real variable: fmi2GetReal reads it */
    A_OUTPUT = 2,       /* a Real output: read only while finite */
    A_SET_ALWAYS = 4,   /* a Real input: fmi2SetReal sets it in any state that allows the call */
    A_SET_EARLY = 8     /* a Real input or parameter: settable before the end of initialization */
};

static void set_outputs(mb_instance *inst, int start);

static size_t align16(size_t n) { return (n + 15) & ~(size_t)15; }

/* ------------------------------------------------------------------------- logging */
/* The logger's message is a printf format (FMI 2.0): the text goes with every '%'
   doubled, so a host that formats it prints the text and one that reads it as text
   (a ctypes logger) sees the text unchanged unless it held a '%'. Discard, Error and
   Fatal lines are always delivered: they explain a status. */
static void emit(mb_instance *inst, fmi2Status status, int category, const char *text)
{
    char escaped[2 * 1400 + 1];
    size_t n = 0;
    if (!inst || !inst->cb.logger) return;
    if (status < fmi2Discard && !inst->category_on[category] && !inst->category_on[CAT_ALL]) return;
    for (const char *p = text; *p && n + 2 < sizeof escaped; p++) {
        if (*p == '%') escaped[n++] = '%';
        escaped[n++] = *p;
    }
    escaped[n] = '\0';
    inst->cb.logger(inst->cb.componentEnvironment, inst->name, status, CATEGORIES[category], escaped);
}

static void logf_(mb_instance *inst, fmi2Status status, int category, const char *fmt, ...)
{
    char text[1400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    emit(inst, status, category, text);
}

void mb_error(mb_instance *inst, const char *kind, const char *fmt, ...)
{
    va_list ap;
    snprintf(inst->kind, sizeof inst->kind, "%s", kind);
    va_start(ap, fmt);
    vsnprintf(inst->message, sizeof inst->message, fmt, ap);
    va_end(ap);
}

void mb_warning(mb_instance *inst, const char *fmt, ...)
{
    char text[1400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    emit(inst, fmi2Warning, CAT_WARNING, text);
}

/* Are x[0..n) all finite? One pass without a branch per value: a double is NaN or inf
   when its exponent bits are all ones, and only then does adding one to the exponent
   carry into the sign bit. The checks every step makes (the outputs after a doStep, a
   controller's inputs) cost this; the walks that name what is not finite run after it fails. */
static int all_finite(const double *x, int n)
{
    const uint64_t exponent = 0x7ff0000000000000u, exponent_one = 0x0010000000000000u;
    uint64_t carries = 0;
    for (int k = 0; k < n; k++) {
        uint64_t bits;
        memcpy(&bits, &x[k], sizeof bits);
        carries |= (bits & exponent) + exponent_one;
    }
    return !(carries >> 63);
}

int mb_nonfinite_rows(int nrows, int width, const double *rows, const char *const *names, char *out, size_t n)
{
    int count = 0;
    size_t used = 0;
    out[0] = '\0';
    if (all_finite(rows, nrows * width)) return 0;
    for (int row = 0; row < nrows; row++) {
        int bad = 0;
        for (int k = 0; k < width; k++) bad |= !isfinite(rows[row * width + k]);
        if (!bad) continue;
        int w = snprintf(out + used, used < n ? n - used : 0, "%s%s", count ? ", " : "", names[row]);
        if (w > 0) used += (size_t)w;
        if (used >= n) used = n - 1;
        count++;
    }
    return count;
}

const char *mb_repr(double v, char *buf)
{
    if (isnan(v)) return strcpy(buf, "nan");
    if (isinf(v)) return strcpy(buf, v > 0 ? "inf" : "-inf");
    int p = 1;
    for (; p < 17; p++) {   /* fewest significant digits that read back as v */
        snprintf(buf, 32, "%.*e", p - 1, v);
        if (strtod(buf, NULL) == v) break;
    }
    snprintf(buf, 32, "%.*e", p - 1, v);
    int exponent = atoi(strchr(buf, 'e') + 1);
    if (exponent < -4 || exponent >= 16) {   /* Python: 1e-05, 1.5e+16 (C pads the exponent to 2 digits too) */
        return buf;
    }
    int decimals = p - 1 - exponent;
    snprintf(buf, 32, "%.*f", decimals > 0 ? decimals : 0, v);
    if (!strchr(buf, '.')) strcat(buf, ".0");
    return buf;
}

/* Record the model's failure "<kind> <when>: <message>" (slave.py's GuardedSlave.fail),
   logged with the status the call answers. */
static void record_failure(mb_instance *inst, const char *when, fmi2Status status)
{
    layer_state *s = LAYER(inst);
    s->failed = 1;
    snprintf(s->failure, sizeof s->failure, "%s %s: %s", inst->kind, when, inst->message);
    emit(inst, status, status == fmi2Discard ? CAT_DISCARD : CAT_ERROR, s->failure);
}

/* Every Real output finite? Else mb_error naming the outputs and the input or parameter
   of largest magnitude (a NaN counts largest): 1. No model answers OK with NaN/inf. */
static int nonfinite_outputs(mb_instance *inst)
{
    const double *r = REALS(inst);
    int finite = 1;   /* the message's walk only when an output is not finite */
    for (int k = 0; k < inst->n_output_runs; k++)
        finite &= all_finite(r + inst->output_runs[2 * k], inst->output_runs[2 * k + 1]);
    if (finite) return 0;
    char outs[400] = "", value[32];
    size_t used = 0;
    int count = 0, worst = -1;
    for (int vr = 0; vr < MB_MODEL.nvars; vr++) {
        const mb_var *v = &MB_MODEL.vars[vr];
        if (v->type != MB_REAL) continue;
        if (v->causality == MB_OUTPUT && !isfinite(r[vr])) {
            if (count++ < 4 && used < sizeof outs)
                used += (size_t)snprintf(outs + used, sizeof outs - used, "%s%s = %s", count > 1 ? ", " : "", v->name,
                                         mb_repr(r[vr], value));
        } else if ((v->causality == MB_INPUT || v->causality == MB_PARAMETER) &&
                   (worst < 0 || !(fabs(r[vr]) <= fabs(r[worst])))) {
            if (worst < 0 || !isnan(r[worst])) worst = vr;
        }
    }
    if (!count) return 0;
    char cause[160] = "";
    if (worst >= 0)
        snprintf(cause, sizeof cause, "; the input or parameter of largest magnitude is %s = %s",
                 MB_MODEL.vars[worst].name, mb_repr(r[worst], value));
    mb_error(inst, "NonFiniteOutputError", "%d output%s not finite (%s%s)%s", count, count > 1 ? "s" : "", outs,
             count > 4 ? ", ..." : "", cause);
    return 1;
}

/* --------------------------------------------------------------------- instance */
static void load_starts(mb_instance *inst)
{
    memset(inst->block, 0, inst->size);
    PHASE(inst) = INSTANTIATED;
    double *r = REALS(inst);
    int *iv = INTS(inst);
    for (int vr = 0; vr < MB_MODEL.nvars; vr++) {
        const mb_var *v = &MB_MODEL.vars[vr];
        if (v->type == MB_REAL) r[vr] = v->start;
        else iv[vr] = (int)v->start;
    }
}

/* Is `function` allowed in the instance's state (mask of enum phase)? Else an error line
   (the FMI 2.0 call sequence; the Reference FMUs' "Illegal call sequence"). */
static int allowed(mb_instance *inst, const char *function, int mask)
{
    if (PHASE(inst) & mask) return 1;
    logf_(inst, fmi2Error, CAT_ERROR, "%s: not allowed in %s (FMI 2.0 call sequence)", function,
          phase_name(PHASE(inst), LAYER(inst)->failed));
    return 0;
}

static int usable(fmi2Component c)
{
    return c != NULL && ((mb_instance *)c)->block != NULL;
}

/* Built with -DMB_EMPTY_MODEL: the same interface, initialization and doStep do nothing
   (the exchange floor of benchmarks/bench_native.py). */
#ifdef MB_EMPTY_MODEL
#define MODEL_INIT(inst, t0) 0
#define MODEL_STEP(inst, t, h) 0
#else
#define MODEL_INIT(inst, t0) MB_MODEL.init(inst, REALS(inst), INTS(inst), MODEL(inst), t0)
#define MODEL_STEP(inst, t, h) MB_MODEL.step(inst, REALS(inst), INTS(inst), MODEL(inst), t, h)
#endif

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (nCategories == 0) {
        for (int k = 0; k < NCAT; k++) inst->category_on[k] = loggingOn;
        return fmi2OK;
    }
    if (!categories) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2SetDebugLogging: categories is NULL for %zu categories", nCategories);
        return fmi2Error;
    }
    for (size_t n = 0; n < nCategories; n++) {
        int found = 0;
        for (int k = 0; k < NCAT; k++) {
            if (categories[n] && strcmp(categories[n], CATEGORIES[k]) == 0) {
                inst->category_on[k] = loggingOn;
                found = 1;
            }
        }
        if (!found) {
            logf_(inst, fmi2Error, CAT_ERROR, "fmi2SetDebugLogging: unknown log category '%s'",
                  categories[n] ? categories[n] : "(null)");
            return fmi2Error;
        }
    }
    return fmi2OK;
}

static void free_instance(mb_instance *inst)
{
    free(inst->block);
    free(inst->backup);
    free(inst->access);
    free(inst->output_runs);
    free(inst->name);
    free(inst);
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation;
    (void)visible;
    mb_instance probe;
    memset(&probe, 0, sizeof probe);
    if (functions) probe.cb = *functions;
    probe.name = (char *)(instanceName ? instanceName : "?");
    if (fmuType != fmi2CoSimulation) {
        logf_(&probe, fmi2Error, CAT_ERROR, "fmi2Instantiate: %s supports co-simulation only", MB_MODEL.identifier);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, MB_MODEL.guid) != 0) {
        logf_(&probe, fmi2Error, CAT_ERROR, "fmi2Instantiate: GUID '%s' is not this FMU's '%s'",
              fmuGUID ? fmuGUID : "(null)", MB_MODEL.guid);
        return NULL;
    }
    mb_instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->cb = probe.cb;
    const char *name = instanceName ? instanceName : "";
    inst->name = malloc(strlen(name) + 1);
    inst->r_off = align16(sizeof(layer_state));
    inst->i_off = inst->r_off + align16(sizeof(double) * (size_t)MB_MODEL.nvars);
    inst->m_off = inst->i_off + align16(sizeof(int) * (size_t)MB_MODEL.nvars);
    inst->size = inst->m_off + align16(MB_MODEL.model_size);
    inst->block = calloc(1, inst->size);
    inst->backup = calloc(1, inst->size - inst->r_off);
    inst->access = calloc((size_t)MB_MODEL.nvars + 1, 1);
    inst->output_runs = calloc(2 * (size_t)MB_MODEL.nvars + 1, sizeof(int));
    if (!inst->name || !inst->block || !inst->backup || !inst->access || !inst->output_runs) {
        free_instance(inst);
        return NULL;
    }
    for (int vr = 0; vr < MB_MODEL.nvars; vr++) {
        const mb_var *v = &MB_MODEL.vars[vr];
        if (v->type != MB_REAL) continue;
        inst->access[vr] = (unsigned char)(A_REAL | (v->causality == MB_OUTPUT ? A_OUTPUT : 0) |
                                           (v->causality == MB_INPUT ? A_SET_ALWAYS | A_SET_EARLY : 0) |
                                           (v->causality == MB_PARAMETER ? A_SET_EARLY : 0));
        if (v->causality == MB_OUTPUT) {
            int *last = inst->output_runs + 2 * (inst->n_output_runs - 1);
            if (inst->n_output_runs && last[0] + last[1] == vr) last[1]++;
            else {
                inst->output_runs[2 * inst->n_output_runs++] = vr;
                inst->output_runs[2 * inst->n_output_runs - 1] = 1;
            }
        }
    }
    strcpy(inst->name, name);
    for (int k = 0; k < NCAT; k++) inst->category_on[k] = loggingOn;
    load_starts(inst);
    return inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    if (c) free_instance(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined, (void)tolerance;
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!allowed(inst, "fmi2SetupExperiment", INSTANTIATED)) return fmi2Error;
    if (!isfinite(startTime)) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2SetupExperiment: startTime must be finite");
        return fmi2Error;
    }
    char startb[32], stopb[32];
    if (stopTimeDefined && !(stopTime >= startTime)) {   /* misuse harness: accepted, and then ignored */
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2SetupExperiment: stopTime %s s is before startTime %s s",
              mb_repr(stopTime, stopb), mb_repr(startTime, startb));
        return fmi2Error;
    }
    LAYER(inst)->start_time = startTime;
    LAYER(inst)->time = startTime;
    LAYER(inst)->stop_defined = stopTimeDefined != fmi2False;
    LAYER(inst)->stop_time = stopTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!allowed(inst, "fmi2EnterInitializationMode", INSTANTIATED)) return fmi2Error;
    PHASE(inst) = INITIALIZATION;
    inst->dirty = 1;
    return fmi2OK;
}

/* "value unit" as the Python FMUs write a quantity (slave.py _quantity): 6 digits, degrees
   beside radians. */
static void quantity(char *out, size_t n, double v, const char *unit)
{
    char number[40];
    if (isnan(v)) strcpy(number, "nan");
    else snprintf(number, sizeof number, "%.6g", v);
    snprintf(out, n, "%s%s%s", number, *unit ? " " : "", unit);
    if (strncmp(unit, "rad", 3) == 0 && isfinite(v)) {
        size_t used = strlen(out);
        snprintf(out + used, n - used, " (%.6g deg%s)", v * (180.0 / 3.141592653589793), unit + 3);
    }
}

/* slave.py range_text */
static void range_text(char *out, size_t n, const mb_var *v)
{
    char q[96];
    if (!v->has_max) {
        quantity(q, sizeof q, v->min, v->unit);
        snprintf(out, n, ">= %s", q);
    } else if (!v->has_min) {
        quantity(q, sizeof q, v->max, v->unit);
        snprintf(out, n, "<= %s", q);
    } else {
        snprintf(out, n, "[%.6g, %.6g]%s%s", v->min, v->max, *v->unit ? " " : "", v->unit);
        if (strncmp(v->unit, "rad", 3) == 0) {
            size_t used = strlen(out);
            snprintf(out + used, n - used, " ([%.6g, %.6g] deg%s)", v->min * (180.0 / 3.141592653589793),
                     v->max * (180.0 / 3.141592653589793), v->unit + 3);
        }
    }
}

/* Every parameter outside its range and every input that is not finite, as one message
   (slave.py GuardedSlave.check_start); 0 when there is none. */
static int check_start(mb_instance *inst)
{
    char problems[sizeof inst->message] = "", one[320], q[96], range[160];
    const double *r = REALS(inst);
    const int *iv = INTS(inst);
    for (int pass = 0; pass < 2; pass++) {
        for (int vr = 0; vr < MB_MODEL.nvars; vr++) {
            const mb_var *v = &MB_MODEL.vars[vr];
            double value = v->type == MB_REAL ? r[vr] : (double)iv[vr];
            one[0] = '\0';
            if (pass == 0 && v->causality == MB_PARAMETER && (v->has_min || v->has_max) &&
                !((!v->has_min || value >= v->min) && (!v->has_max || value <= v->max))) {
                quantity(q, sizeof q, value, v->unit);
                range_text(range, sizeof range, v);
                snprintf(one, sizeof one, "parameter %s = %s is outside its valid range %s", v->name, q, range);
            } else if (pass == 0 && v->causality == MB_PARAMETER && v->n_allowed > 0) {
                int ok = 0;
                size_t used = 0;
                char list[64] = "";
                for (int k = 0; k < v->n_allowed; k++) {
                    ok |= iv[vr] == v->allowed[k];
                    used += (size_t)snprintf(list + used, sizeof list - used, "%s%d", k ? ", " : "", v->allowed[k]);
                }
                if (!ok) snprintf(one, sizeof one, "parameter %s = %d is not one of %s", v->name, iv[vr], list);
            } else if (pass == 1 && v->causality == MB_INPUT && v->type == MB_REAL && !isfinite(value)) {
                char text[32];
                snprintf(one, sizeof one, "input %s = %s at initialization: inputs must be finite", v->name,
                         mb_repr(value, text));
            }
            if (one[0]) {
                size_t used = strlen(problems);
                snprintf(problems + used, sizeof problems - used, "%s%s", used ? "; " : "", one);
            }
        }
    }
    if (!problems[0]) return 0;
    mb_error(inst, "InvalidInputError", "%s", problems);
    return 1;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!allowed(inst, "fmi2ExitInitializationMode", INITIALIZATION)) return fmi2Error;
    PHASE(inst) = STEPPING;
    layer_state *s = LAYER(inst);
    if (check_start(inst) || MODEL_INIT(inst, s->start_time) || nonfinite_outputs(inst)) {
        set_outputs(inst, 0);
        record_failure(inst, "in initialization", fmi2Error);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    if (!usable(c) || !allowed(c, "fmi2Terminate", STEPPING)) return fmi2Error;
    PHASE((mb_instance *)c) = TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    load_starts(inst);
    return fmi2OK;
}

/* ------------------------------------------------------------------- get and set */
/* A model's init and step write r, i and its own struct, never the layer's state (its
   failure goes to inst->kind and message): the rollback of a refused step saves and
   restores those, not the 1 KB layer_state before them. */
static void save_model(mb_instance *inst) { memcpy(inst->backup, inst->block + inst->r_off, inst->size - inst->r_off); }
static void restore_model(mb_instance *inst) { memcpy(inst->block + inst->r_off, inst->backup, inst->size - inst->r_off); }

/* Every Real output to its start value (start = 1) or to NaN (0 after a failed
   initialization: read, each answers fmi2Error naming the failure). What a read returns
   is a function of the values set, never of earlier reads (fuzz.c: after a refused
   initialization the outputs held whatever the last read in initialization mode had
   computed, and a replay of the same sets without those reads read other numbers). */
static void set_outputs(mb_instance *inst, int start)
{
    double *r = REALS(inst);
    for (int vr = 0; vr < MB_MODEL.nvars; vr++)
        if (MB_MODEL.vars[vr].type == MB_REAL && MB_MODEL.vars[vr].causality == MB_OUTPUT)
            r[vr] = start ? MB_MODEL.vars[vr].start : NAN;
}

/* Outputs read in initialization mode are computed from the parameters and inputs set so
   far (as the Reference FMUs do), so that an importer that propagates values during
   initialization (libcosim) starts every FMU from its neighbours' initial outputs. If the
   model cannot compute them yet, they read their start values; fmi2ExitInitializationMode
   reports the problem. */
static void evaluate_initial(mb_instance *inst)
{
    if (PHASE(inst) != INITIALIZATION || !inst->dirty) return;
    inst->dirty = 0;
    if (MODEL_INIT(inst, LAYER(inst)->start_time) || nonfinite_outputs(inst)) set_outputs(inst, 1);
}

/* A count of values with no array to hold them (fuzz.c: a NULL array crashed the host): fmi2Error. */
static int arrays_given(mb_instance *inst, const char *function, size_t nvr, const void *vr, const void *value)
{
    if (nvr == 0 || (vr && value)) return 1;
    logf_(inst, fmi2Error, CAT_ERROR, "%s: %s is NULL for %zu values", function, vr ? "the values array" :
          "the value reference array", nvr);
    return 0;
}

static int valid_vr(mb_instance *inst, const char *function, fmi2ValueReference vr, int type)
{
    if (vr >= (fmi2ValueReference)MB_MODEL.nvars || MB_MODEL.vars[vr].type != type) {
        logf_(inst, fmi2Error, CAT_ERROR, "%s: no %s variable has value reference %u", function,
              type == MB_REAL ? "Real" : "Integer", (unsigned)vr);
        return 0;
    }
    return 1;
}

/* Nothing is set in the failed state (the standard's stepFailed): only reading, fmi2Terminate,
   fmi2Reset, fmi2SetFMUstate and fmi2FreeInstance lead on. */
static int unfailed(mb_instance *inst, const char *function)
{
    if (!(PHASE(inst) == STEPPING && LAYER(inst)->failed)) return 1;
    logf_(inst, fmi2Error, CAT_ERROR, "%s: not allowed in %s (FMI 2.0 call sequence)", function,
          phase_name(STEPPING, 1));
    return 0;
}

/* May the variable be set now? (outputs never; parameters before the end of
   initialization; inputs always). Ranges are checked at fmi2ExitInitializationMode. */
static int settable(mb_instance *inst, const char *function, fmi2ValueReference vr)
{
    const mb_var *v = &MB_MODEL.vars[vr];
    if (v->causality == MB_OUTPUT || v->causality == MB_LOCAL) {
        logf_(inst, fmi2Error, CAT_ERROR, "%s: %s is an output and cannot be set", function, v->name);
        return 0;
    }
    if (v->causality == MB_PARAMETER) {
        if (!(PHASE(inst) & (INSTANTIATED | INITIALIZATION))) {
            logf_(inst, fmi2Error, CAT_ERROR, "%s: parameter %s is fixed after initialization", function, v->name);
            return 0;
        }
    }
    return 1;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!allowed(inst, "fmi2GetReal", READABLE) || !arrays_given(inst, "fmi2GetReal", nvr, vr, value)) return fmi2Error;
    evaluate_initial(inst);
    const double *r = REALS(inst);
    const unsigned char *access = inst->access;
    char text[32];
    for (size_t k = 0; k < nvr; k++) {
        int a = vr[k] < (fmi2ValueReference)MB_MODEL.nvars ? access[vr[k]] : 0;
        if (!(a & A_REAL)) {
            valid_vr(inst, "fmi2GetReal", vr[k], MB_REAL);   /* its line */
            return fmi2Error;
        }
        value[k] = r[vr[k]];
        /* misuse harness: after an initialization refused for a non-finite output (say
           SliderController's amplitude = 1e300), the outputs were read back NaN with fmi2OK */
        if ((a & A_OUTPUT) && !(fabs(value[k]) <= DBL_MAX)) {
            logf_(inst, fmi2Error, CAT_ERROR, "fmi2GetReal: output %s is %s, not finite%s%s%s",
                  MB_MODEL.vars[vr[k]].name, mb_repr(value[k], text), LAYER(inst)->failed ? " (after: " : "",
                  LAYER(inst)->failed ? LAYER(inst)->failure : "", LAYER(inst)->failed ? ")" : "");
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!allowed(inst, "fmi2GetInteger", READABLE) || !arrays_given(inst, "fmi2GetInteger", nvr, vr, value))
        return fmi2Error;
    evaluate_initial(inst);
    const int *iv = INTS(inst);
    for (size_t k = 0; k < nvr; k++) {
        if (!valid_vr(inst, "fmi2GetInteger", vr[k], MB_INTEGER)) return fmi2Error;
        value[k] = iv[vr[k]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!allowed(inst, "fmi2SetReal", INSTANTIATED | INITIALIZATION | STEPPING) || !unfailed(inst, "fmi2SetReal") ||
        !arrays_given(inst, "fmi2SetReal", nvr, vr, value))
        return fmi2Error;
    double *r = REALS(inst);
    const unsigned char *access = inst->access;
    int settable_now = PHASE(inst) & (INSTANTIATED | INITIALIZATION) ? A_SET_EARLY : A_SET_ALWAYS;
    /* every value reference checked before any value is set: a refused call sets nothing
       (fuzz.c: the values before a bad reference were set, with fmi2Error) */
    for (size_t k = 0; k < nvr; k++) {
        if (!(vr[k] < (fmi2ValueReference)MB_MODEL.nvars && (access[vr[k]] & settable_now))) {
            if (valid_vr(inst, "fmi2SetReal", vr[k], MB_REAL)) settable(inst, "fmi2SetReal", vr[k]);   /* its line */
            return fmi2Error;
        }
    }
    for (size_t k = 0; k < nvr; k++) r[vr[k]] = value[k];
    inst->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!allowed(inst, "fmi2SetInteger", INSTANTIATED | INITIALIZATION | STEPPING) ||
        !unfailed(inst, "fmi2SetInteger") || !arrays_given(inst, "fmi2SetInteger", nvr, vr, value))
        return fmi2Error;
    int *iv = INTS(inst);
    for (size_t k = 0; k < nvr; k++)   /* all checked first: a refused call sets nothing */
        if (!valid_vr(inst, "fmi2SetInteger", vr[k], MB_INTEGER) || !settable(inst, "fmi2SetInteger", vr[k]))
            return fmi2Error;
    for (size_t k = 0; k < nvr; k++) iv[vr[k]] = value[k];
    inst->dirty = 1;
    return fmi2OK;
}

static fmi2Status no_variables(fmi2Component c, const char *function, size_t nvr, const char *type, int mask)
{
    /* a setter, like fmi2SetReal, not in the failed state (fuzz.c: fmi2SetBoolean of no values answered OK there) */
    if (!usable(c) || !allowed(c, function, mask) || ((mask & INSTANTIATED) && !unfailed(c, function))) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    logf_(c, fmi2Error, CAT_ERROR, "%s: %s has no %s variables", function, MB_MODEL.identifier, type);
    return fmi2Error;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    (void)vr, (void)value;
    return no_variables(c, "fmi2GetBoolean", nvr, "Boolean", READABLE);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    (void)vr, (void)value;
    return no_variables(c, "fmi2SetBoolean", nvr, "Boolean", INSTANTIATED | INITIALIZATION | STEPPING);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    (void)vr, (void)value;
    return no_variables(c, "fmi2GetString", nvr, "String", READABLE);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    (void)vr, (void)value;
    return no_variables(c, "fmi2SetString", nvr, "String", INSTANTIATED | INITIALIZATION | STEPPING);
}

/* ---------------------------------------------------------------------- stepping */
/* How far currentCommunicationPoint may lie from the FMU's time, relative to max(1 s, |time|):
   a host summing t += h drifts by ulps, a host skipping or repeating a step is off by h. */
#define STEP_TIME_TOLERANCE 1e-9

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    layer_state *s = LAYER(inst);
    if (!allowed(inst, "fmi2DoStep", STEPPING)) return fmi2Error;
    if (s->failed) {
        logf_(inst, fmi2Discard, CAT_DISCARD, "refusing doStep at t=%.6g s after: %s", currentCommunicationPoint,
              s->failure);
        return fmi2Discard;
    }
    double t = currentCommunicationPoint, h = communicationStepSize;
    char tb[32], hb[32], nowb[32];
    if (!(isfinite(h) && h > 0)) {   /* the Reference FMUs: "Communication step size must be > 0" */
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2DoStep: the communication step size must be finite and > 0, got %s s",
              mb_repr(h, hb));
        return fmi2Error;
    }
    if (!(fabs(t - s->time) <= STEP_TIME_TOLERANCE * fmax(1.0, fabs(s->time)))) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2DoStep: currentCommunicationPoint %s s is not the FMU's time %s s "
              "(the end of the last accepted step)", mb_repr(t, tb), mb_repr(s->time, nowb));
        return fmi2Error;
    }
    if (t + h == t) {   /* misuse harness: at t = 1e300 a step of 1 ms left the time where it was, with OK */
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2DoStep: a step of %s s does not advance the time %s s "
              "(below its resolution)", mb_repr(h, hb), mb_repr(t, tb));
        return fmi2Error;
    }
    /* FMI 2.0: no step past a defined stopTime (to the tolerance of the communication
       point, so a last step ending at stopTime by sums of h runs) */
    if (s->stop_defined && t + h > s->stop_time + STEP_TIME_TOLERANCE * fmax(1.0, fabs(s->stop_time))) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2DoStep: the step to t=%s s passes the experiment's stopTime "
              "%s s", mb_repr(t + h, tb), mb_repr(s->stop_time, nowb));
        return fmi2Error;
    }
    save_model(inst);
    if (!MODEL_STEP(inst, t, h) && !nonfinite_outputs(inst)) {
        s->time = t + h;
        return fmi2OK;
    }
    restore_model(inst);   /* outputs keep the last accepted state */
    char when[64];
    snprintf(when, sizeof when, "at t=%.6g s", t);
    record_failure(inst, when, fmi2Discard);
    return fmi2Discard;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    if (!usable(c)) return fmi2Error;
    logf_(c, fmi2Error, CAT_ERROR, "fmi2CancelStep: fmi2DoStep never returns fmi2Pending, nothing to cancel");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    if (!usable(c) || !allowed(c, "fmi2GetStatus", STEPPING | TERMINATED) || !arrays_given(c, "fmi2GetStatus", 1, value, value))
        return fmi2Error;
    if (s == fmi2DoStepStatus) {   /* doStep is synchronous: the last one is done */
        *value = LAYER((mb_instance *)c)->failed ? fmi2Discard : fmi2OK;
        return fmi2OK;
    }
    logf_(c, fmi2Error, CAT_ERROR, "fmi2GetStatus: status kind %d is not an fmi2Status", (int)s);
    return fmi2Error;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    if (!usable(c) || !allowed(c, "fmi2GetRealStatus", STEPPING | TERMINATED) || !arrays_given(c, "fmi2GetRealStatus", 1, value, value))
        return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = LAYER((mb_instance *)c)->time;
        return fmi2OK;
    }
    logf_(c, fmi2Error, CAT_ERROR, "fmi2GetRealStatus: only fmi2LastSuccessfulTime is a Real status");
    return fmi2Error;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)value;
    if (!usable(c) || !allowed(c, "fmi2GetIntegerStatus", STEPPING | TERMINATED)) return fmi2Error;
    logf_(c, fmi2Error, CAT_ERROR, "fmi2GetIntegerStatus: no Integer status (kind %d)", (int)s);
    return fmi2Error;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    if (!usable(c) || !allowed(c, "fmi2GetBooleanStatus", STEPPING | TERMINATED) || !arrays_given(c, "fmi2GetBooleanStatus", 1, value, value))
        return fmi2Error;
    if (s == fmi2Terminated) {   /* a failed instance has ended its simulation */
        *value = LAYER((mb_instance *)c)->failed ? fmi2True : fmi2False;
        return fmi2OK;
    }
    logf_(c, fmi2Error, CAT_ERROR, "fmi2GetBooleanStatus: only fmi2Terminated is a Boolean status");
    return fmi2Error;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)value;
    if (!usable(c) || !allowed(c, "fmi2GetStringStatus", STEPPING | TERMINATED)) return fmi2Error;
    logf_(c, fmi2Error, CAT_ERROR, "fmi2GetStringStatus: no String status (kind %d)", (int)s);
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    if (!usable(c)) return fmi2Error;
    logf_(c, fmi2Error, CAT_ERROR, "fmi2SetRealInputDerivatives: canInterpolateInputs is false");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    if (!usable(c)) return fmi2Error;
    logf_(c, fmi2Error, CAT_ERROR, "fmi2GetRealOutputDerivatives: maxOutputDerivativeOrder is 0");
    return fmi2Error;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    if (!usable(c)) return fmi2Error;
    logf_(c, fmi2Error, CAT_ERROR, "fmi2GetDirectionalDerivative: providesDirectionalDerivative is false");
    return fmi2Error;
}

/* ------------------------------------------------------------------- FMU states */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!FMUstate) {   /* fuzz.c: this fmi2Error came without a log line */
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2GetFMUstate: FMUstate is NULL");
        return fmi2Error;
    }
    saved_state *st = *FMUstate;
    if (st && st->size != inst->size) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2GetFMUstate: the given state is not one of this FMU's");
        return fmi2Error;
    }
    if (!st) {
        st = calloc(1, sizeof *st + inst->size);
        if (!st) return fmi2Error;
        st->size = inst->size;
    }
    memcpy(st->data, inst->block, inst->size);
    *FMUstate = st;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    saved_state *st = FMUstate;
    if (!st || st->size != inst->size) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2SetFMUstate: the given state is not one of this FMU's");
        return fmi2Error;
    }
    memcpy(inst->block, st->data, inst->size);   /* the state's phase with it */
    inst->dirty = 1;   /* fuzz.c: outputs read in initialization mode came from the inputs before the restore */
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    if (!usable(c)) return fmi2Error;
    if (FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

/* Serialised: MAGIC, the block size as 8 bytes, the model identifier (ID_BYTES, zero
   padded), the CRC-32 of the block as 8 bytes, the block (this platform's doubles). */
enum { ID_BYTES = 64, CRC_AT = sizeof MAGIC + 8 + ID_BYTES, HEADER = CRC_AT + 8 };
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    const saved_state *st = FMUstate;
    if (!size || !st || st->size != inst->size) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2SerializedFMUstateSize: %s", size ? "no state of this FMU" : "size is NULL");
        return fmi2Error;
    }
    *size = HEADER + inst->size;
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size)
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    saved_state *st = FMUstate;
    if (!st || st->size != inst->size || size < HEADER + st->size || !serializedState) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2SerializeFMUstate: no state of this FMU, or the buffer is too small");
        return fmi2Error;
    }
    unsigned long long n = st->size;
    memcpy(serializedState, MAGIC, sizeof MAGIC);
    memcpy(serializedState + sizeof MAGIC, &n, 8);
    memset(serializedState + sizeof MAGIC + 8, 0, ID_BYTES);
    strncpy((char *)serializedState + sizeof MAGIC + 8, MB_MODEL.identifier, ID_BYTES - 1);
    unsigned long long crc = mb_crc32(st->data, st->size);
    memcpy(serializedState + CRC_AT, &crc, 8);
    memcpy(serializedState + HEADER, st->data, st->size);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    if (!usable(c)) return fmi2Error;
    mb_instance *inst = c;
    if (!FMUstate) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2DeSerializeFMUstate: FMUstate is NULL");
        return fmi2Error;
    }
    unsigned long long n = 0, crc = 0;
    char id[ID_BYTES] = {0};   /* the identifier as serialised: zero padded, every byte compared */
    strncpy(id, MB_MODEL.identifier, ID_BYTES - 1);
    if (!serializedState) size = 0;   /* fuzz.c: NULL bytes of the right size were read */
    if (size >= HEADER) {
        memcpy(&n, serializedState + sizeof MAGIC, 8);
        memcpy(&crc, serializedState + CRC_AT, 8);
    }
    if (size != HEADER + inst->size || memcmp(serializedState, MAGIC, sizeof MAGIC) != 0 || n != inst->size ||
        memcmp(serializedState + sizeof MAGIC + 8, id, ID_BYTES) != 0 ||
        crc != mb_crc32(serializedState + HEADER, inst->size)) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2DeSerializeFMUstate: the bytes are not a serialised %s state (%zu bytes%s)",
              MB_MODEL.identifier, size, size == HEADER + inst->size ? ", or damaged: header or checksum" : "");
        return fmi2Error;
    }
    saved_state *st = *FMUstate;
    if (st && st->size != inst->size) {
        logf_(inst, fmi2Error, CAT_ERROR, "fmi2DeSerializeFMUstate: the given state is not one of this FMU's");
        return fmi2Error;
    }
    if (!st) {
        st = calloc(1, sizeof *st + inst->size);
        if (!st) return fmi2Error;
        st->size = inst->size;
    }
    memcpy(st->data, serializedState + HEADER, inst->size);
    *FMUstate = st;
    return fmi2OK;
}

/* ------------------------------------------- model exchange: not this FMU's type */
#define NOT_ME(call) \
    logf_(c, fmi2Error, CAT_ERROR, "%s: %s is a co-simulation FMU", call, MB_MODEL.identifier); \
    return fmi2Error;

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
