/* The instance core of every native FMU of the kit (instance.h), over one model file
   (model.h says what a model provides), under the FMI 2.0 and FMI 3.0 layers
   (fmi2_layer.c, fmi3_layer.c). Like the Reference FMUs' cosimulation.c, without their
   macros: one instance struct, a variable table for get/set, a byte block holding
   everything an FMU state needs.

   Behaviour follows the pythonfmu FMUs (fmu_src/slave.py): a failing step answers
   Discard with an error log line saying what and when, the instance then refuses
   further steps, and the outputs keep the last accepted state; a failing initialization
   answers Error. The core never prints and never aborts: every misuse is an Error with a
   log line. Memory comes from calloc/free (the modelDescriptions say
   canNotUseMemoryManagementFunctions).

   Rules every model gets from here, whatever its file forgets:
   - A log line carries the status the call returns (Discard on a refused step, Error on
     a failed initialization or a misuse) and names the function the host called.
   - doStep (its arguments checked here, mbi_step_refused: STEP_TIME_TOLERANCE): after a
     Discard the instance stays failed and answers every further doStep with Discard
     ("refusing doStep"), as the pythonfmu FMUs do (where the standard lets the host call
     it). A stopTime before the startTime is refused at setup.
   - No OK with a non-finite output: after every step and initialization each Real
     output is checked; one NaN/inf answers Discard (initialization: Error) with a line
     naming the outputs and the input or parameter of largest magnitude; and reading an
     output that is not finite (the outputs a refused initialization left) answers Error.
   - Work bound: a model integrating on substeps asks mb_substeps (model.h), which
     refuses a step needing more than MB_MAX_SUBSTEPS substeps (Discard, a line saying
     how many it would need) instead of overflowing an int or running for hours.
   - Strings (the Telescope's replay_table) are copies the instance owns, apart from the
     FMU-state block: a NULL value is refused, freeInstance frees them, reset sets them
     to "", and a state neither saves nor restores them (nor what a model keeps, mb_keep).
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

#include "instance.h"
#include "crc32.h"

const char *const MBI_CATEGORIES[MBI_NCAT] = {"logStatusWarning", "logStatusDiscard", "logStatusError",
                                              "logStatusFatal", "logAll"};

struct mb_instance {
    mbi_logger logger;
    void *log_env;            /* the layer's bytes for its logger (a copy) */
    char *name;
    int category_on[MBI_NCAT];
    int dirty;                /* initialization mode: inputs or parameters set since the outputs were computed */
    size_t size, r_off, i_off, m_off;
    unsigned char *block;     /* mbi_core_state | double r[n] | int i[n] | model */
    unsigned char *backup;    /* r, i and the model before the running doStep (what a refused step restores) */
    unsigned char *access;    /* per value reference: enum access bits, from the variable table */
    int *output_runs;         /* the Real outputs as runs of consecutive value references: first, count, ... */
    int n_output_runs;
    char **strings;           /* per value reference: a String's value (instance-owned), else NULL */
    char *resources;          /* the resources folder, ending in '/', or NULL */
    void *kept;               /* what the model keeps outside the FMU state (mb_keep) */
    char kind[64];
    char message[896];
};

struct mbi_state {
    size_t size;
    unsigned char data[];
};

static const char MAGIC[8] = {'M', 'B', 'F', 'M', 'U', 'S', '4', '\0'};   /* 4: one state for FMI 2.0 and 3.0 */

#define CORE(inst) ((mbi_core_state *)(inst)->block)
#define PHASE(inst) (CORE(inst)->phase)
#define REALS(inst) ((double *)((inst)->block + (inst)->r_off))
#define INTS(inst) ((int *)((inst)->block + (inst)->i_off))
#define MODEL(inst) ((void *)((inst)->block + (inst)->m_off))

/* What get/set may do with a value reference, one byte each, made at instantiation from
   the variable table: the calls a host repeats every step (the C master's set and get of
   Reals) check one byte per value reference, and only a call that fails one walks the
   table again to name the problem. */
enum access {
    A_REAL = 1,         /* a Real variable: get reads it */
    A_OUTPUT = 2,       /* a Real output: read only while finite */
    A_SET_ALWAYS = 4,   /* a Real input: set in any state that allows the call */
    A_SET_EARLY = 8     /* a Real input or parameter: settable before the end of initialization */
};

static void set_outputs(mb_instance *inst, int start);

static size_t align16(size_t n) { return (n + 15) & ~(size_t)15; }

/* ------------------------------------------------------------------------- logging */
static const int STATUS_CATEGORY[] = {MBI_CAT_ALL, MBI_CAT_WARNING, MBI_CAT_DISCARD, MBI_CAT_ERROR, MBI_CAT_FATAL};

/* Discard, Error and Fatal lines are always delivered: they explain a status. */
static void emit(mb_instance *inst, mbi_status status, const char *text)
{
    int category = STATUS_CATEGORY[status];
    if (!inst || !inst->logger) return;
    if (status < MBI_DISCARD && !inst->category_on[category] && !inst->category_on[MBI_CAT_ALL]) return;
    inst->logger(inst->log_env, inst->name, status, MBI_CATEGORIES[category], text);
}

void mbi_logf(mb_instance *inst, mbi_status status, const char *fmt, ...)
{
    char text[1400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    emit(inst, status, text);
}

void mbi_log_host(mbi_logger logger, const void *env, const char *instance_name, mbi_status status,
                  const char *fmt, ...)
{
    char text[1400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    if (logger) logger(env, instance_name, status, MBI_CATEGORIES[STATUS_CATEGORY[status]], text);
}

int mbi_category(const char *name)
{
    for (int k = 0; name && k < MBI_NCAT; k++)
        if (strcmp(name, MBI_CATEGORIES[k]) == 0) return k;
    return -1;
}

void mbi_set_logging(mb_instance *inst, int category, int on)
{
    for (int k = 0; k < MBI_NCAT; k++)
        if (category < 0 || k == category) inst->category_on[k] = on;
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
    emit(inst, MBI_WARNING, text);
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
static void record_failure(mb_instance *inst, const char *when, mbi_status status)
{
    mbi_core_state *s = CORE(inst);
    s->failed = 1;
    snprintf(s->failure, sizeof s->failure, "%s %s: %s", inst->kind, when, inst->message);
    emit(inst, status, s->failure);
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

/* Built with -DMB_EMPTY_MODEL: the same interface, initialization and doStep do nothing
   (the exchange floor of benchmarks/bench_native.py). */
#ifdef MB_EMPTY_MODEL
#define MODEL_INIT(inst, t0) 0
#define MODEL_STEP(inst, t, h) 0
#else
#define MODEL_INIT(inst, t0) MB_MODEL.init(inst, REALS(inst), INTS(inst), MODEL(inst), t0)
#define MODEL_STEP(inst, t, h) MB_MODEL.step(inst, REALS(inst), INTS(inst), MODEL(inst), t, h)
#endif

/* --------------------------------------------------------------------- life cycle */
static void load_starts(mb_instance *inst)
{
    memset(inst->block, 0, inst->size);
    PHASE(inst) = MBI_INSTANTIATED;
    double *r = REALS(inst);
    int *iv = INTS(inst);
    for (int vr = 0; vr < MB_MODEL.nvars; vr++) {
        const mb_var *v = &MB_MODEL.vars[vr];
        if (v->type == MB_REAL) r[vr] = v->start;
        else iv[vr] = (int)v->start;
    }
}

/* Every String back to "" (instantiation, reset): 1 when out of memory. */
static int clear_strings(mb_instance *inst)
{
    for (int vr = 0; vr < MB_MODEL.nvars; vr++) {
        if (MB_MODEL.vars[vr].type != MB_STRING) continue;
        free(inst->strings[vr]);
        inst->strings[vr] = calloc(1, 1);
        if (!inst->strings[vr]) return 1;
    }
    return 0;
}

void mbi_free_instance(mb_instance *inst)
{
    if (!inst) return;
    for (int vr = 0; inst->strings && vr < MB_MODEL.nvars; vr++) free(inst->strings[vr]);
    free(inst->strings);
    free(inst->resources);
    free(inst->kept);
    free(inst->block);
    free(inst->backup);
    free(inst->access);
    free(inst->output_runs);
    free(inst->log_env);
    free(inst->name);
    free(inst);
}

mb_instance *mbi_instantiate(const char *instance_name, mbi_logger logger, const void *env, size_t env_size,
                             int logging_on)
{
    mb_instance *inst = calloc(1, sizeof *inst);
    if (!inst) return NULL;
    inst->logger = logger;
    const char *name = instance_name ? instance_name : "";
    inst->name = malloc(strlen(name) + 1);
    inst->log_env = calloc(1, env_size ? env_size : 1);
    inst->r_off = align16(sizeof(mbi_core_state));
    inst->i_off = inst->r_off + align16(sizeof(double) * (size_t)MB_MODEL.nvars);
    inst->m_off = inst->i_off + align16(sizeof(int) * (size_t)MB_MODEL.nvars);
    inst->size = inst->m_off + align16(MB_MODEL.model_size);
    inst->block = calloc(1, inst->size);
    inst->backup = calloc(1, inst->size - inst->r_off);
    inst->access = calloc((size_t)MB_MODEL.nvars + 1, 1);
    inst->output_runs = calloc(2 * (size_t)MB_MODEL.nvars + 1, sizeof(int));
    inst->strings = calloc((size_t)MB_MODEL.nvars + 1, sizeof(char *));
    if (!inst->name || !inst->log_env || !inst->block || !inst->backup || !inst->access || !inst->output_runs ||
        !inst->strings || clear_strings(inst)) {
        mbi_free_instance(inst);
        return NULL;
    }
    if (env_size) memcpy(inst->log_env, env, env_size);
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
    mbi_set_logging(inst, -1, logging_on);
    load_starts(inst);
    return inst;
}

int mbi_set_resources(mb_instance *inst, const char *path)
{
    free(inst->resources);
    inst->resources = NULL;
    if (!path || !*path) return 0;
    size_t n = strlen(path);
    inst->resources = malloc(n + 2);
    if (!inst->resources) return 1;
    memcpy(inst->resources, path, n + 1);
    if (path[n - 1] != '/') strcpy(inst->resources + n, "/");
    return 0;
}

const char *mb_resources(const mb_instance *inst) { return inst->resources; }
const char *mb_string(const mb_instance *inst, int vr) { return inst->strings[vr] ? inst->strings[vr] : ""; }
void *mb_kept(const mb_instance *inst) { return inst->kept; }

void mb_keep(mb_instance *inst, void *memory)
{
    if (memory != inst->kept) free(inst->kept);
    inst->kept = memory;
}

const mbi_core_state *mbi_core(const mb_instance *inst) { return CORE(inst); }
int mbi_phase(const mb_instance *inst) { return PHASE(inst); }
int mbi_failed(const mb_instance *inst) { return CORE(inst)->failed; }

mbi_status mbi_setup_experiment(mb_instance *inst, const char *function, double start_time, int stop_defined,
                                double stop_time)
{
    if (!isfinite(start_time)) {
        mbi_logf(inst, MBI_ERROR, "%s: startTime must be finite", function);
        return MBI_ERROR;
    }
    char startb[32], stopb[32];
    if (stop_defined && !(stop_time >= start_time)) {   /* misuse harness: accepted, and then ignored */
        mbi_logf(inst, MBI_ERROR, "%s: stopTime %s s is before startTime %s s", function, mb_repr(stop_time, stopb),
                 mb_repr(start_time, startb));
        return MBI_ERROR;
    }
    mbi_core_state *s = CORE(inst);
    s->start_time = start_time;
    s->time = start_time;
    s->stop_defined = stop_defined != 0;
    s->stop_time = stop_time;
    return MBI_OK;
}

void mbi_enter_initialization(mb_instance *inst)
{
    PHASE(inst) = MBI_INITIALIZATION;
    inst->dirty = 1;
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

mbi_status mbi_exit_initialization(mb_instance *inst)
{
    PHASE(inst) = MBI_STEP;
    if (check_start(inst) || MODEL_INIT(inst, CORE(inst)->start_time) || nonfinite_outputs(inst)) {
        set_outputs(inst, 0);
        PHASE(inst) = MBI_INIT_FAILED;
        record_failure(inst, "in initialization", MBI_ERROR);
        return MBI_ERROR;
    }
    return MBI_OK;
}

void mbi_terminate(mb_instance *inst) { PHASE(inst) = MBI_TERMINATED; }

void mbi_reset(mb_instance *inst)
{
    load_starts(inst);
    if (clear_strings(inst)) mbi_logf(inst, MBI_ERROR, "reset: out of memory for the String variables");
}

/* ---------------------------------------------------------------------- stepping */
/* A model's init and step write r, i and its own struct, never the core's state (its
   failure goes to inst->kind and message): the rollback of a refused step saves and
   restores those, not the 1 KB mbi_core_state before them. */
static void save_model(mb_instance *inst) { memcpy(inst->backup, inst->block + inst->r_off, inst->size - inst->r_off); }

/* What a doStep may change, saved and restored: r, i and the model but its step-fixed
   start (MB_MODEL.step_fixed: the Wind's 12 KB of gust components, whose copy every step
   cost that FMU as much as its sum). The backup keeps the block's offsets. */
static void step_bytes(mb_instance *inst, int save)
{
    size_t start = inst->r_off, fixed = inst->m_off + MB_MODEL.step_fixed;
    size_t n = MB_MODEL.step_fixed ? inst->m_off - start : inst->size - start;   /* r, i (and all the model) */
    unsigned char *block = inst->block, *backup = inst->backup;
    if (save) memcpy(backup, block + start, n);
    else memcpy(block + start, backup, n);
    if (!MB_MODEL.step_fixed) return;
    n = inst->size - fixed;   /* the model after its fixed start */
    if (save) memcpy(backup + (fixed - start), block + fixed, n);
    else memcpy(block + fixed, backup + (fixed - start), n);
}

mbi_status mbi_do_step(mb_instance *inst, double t, double h)
{
    mbi_core_state *s = CORE(inst);
    if (s->failed) {
        mbi_logf(inst, MBI_DISCARD, "refusing doStep at t=%.6g s after: %s", t, s->failure);
        return MBI_DISCARD;
    }
    step_bytes(inst, 1);
    if (!MODEL_STEP(inst, t, h) && !nonfinite_outputs(inst)) {
        s->time = t + h;
        return MBI_OK;
    }
    step_bytes(inst, 0);   /* outputs keep the last accepted state */
    char when[64];
    snprintf(when, sizeof when, "at t=%.6g s", t);
    PHASE(inst) = MBI_STEP_FAILED;
    record_failure(inst, when, MBI_DISCARD);
    return MBI_DISCARD;
}

/* ------------------------------------------------------------------- get and set */
/* Every Real output to its start value (start = 1) or to NaN (0 after a failed
   initialization: read, each answers Error naming the failure). What a read returns
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
   model cannot compute them yet, they read their start values; exiting initialization
   reports the problem. The parameters and inputs read as they were set: a model's init may
   write an input (HexapodPlant's start_equilibrium, the leg forces that hold the platform),
   and an evaluation left it written, so a later start_equilibrium 0 or a refused exit kept
   forces a replay of the same sets without the reads did not have (fuzz.c). */
static void evaluate_initial(mb_instance *inst)
{
    if (PHASE(inst) != MBI_INITIALIZATION || !inst->dirty) return;
    inst->dirty = 0;
    save_model(inst);
    int failed = MODEL_INIT(inst, CORE(inst)->start_time) || nonfinite_outputs(inst);
    const double *r0 = (const double *)inst->backup;
    const int *i0 = (const int *)(inst->backup + (inst->i_off - inst->r_off));
    for (int vr = 0; vr < MB_MODEL.nvars; vr++) {
        int set = MB_MODEL.vars[vr].causality == MB_PARAMETER || MB_MODEL.vars[vr].causality == MB_INPUT;
        if (set && MB_MODEL.vars[vr].type == MB_REAL) REALS(inst)[vr] = r0[vr];
        else if (set) INTS(inst)[vr] = i0[vr];
    }
    if (failed) set_outputs(inst, 1);
}

/* A count of values with no array to hold them (fuzz.c: a NULL array crashed the host): Error. */
static int arrays_given(mb_instance *inst, const char *function, size_t nvr, const void *vr, const void *value)
{
    if (nvr == 0 || (vr && value)) return 1;
    mbi_logf(inst, MBI_ERROR, "%s: %s is NULL for %zu values", function, vr ? "the values array" :
             "the value reference array", nvr);
    return 0;
}

static int valid_vr(mb_instance *inst, const char *function, mbi_vr vr, int type)
{
    if (vr >= (mbi_vr)MB_MODEL.nvars || MB_MODEL.vars[vr].type != type) {
        mbi_logf(inst, MBI_ERROR, "%s: no %s variable has value reference %u", function,
                 type == MB_REAL ? "Real" : type == MB_STRING ? "String" : "Integer", (unsigned)vr);
        return 0;
    }
    return 1;
}

/* May the variable be set now? (outputs never; parameters before the end of
   initialization; inputs always). Ranges are checked when initialization ends. */
static int settable(mb_instance *inst, const char *function, mbi_vr vr)
{
    const mb_var *v = &MB_MODEL.vars[vr];
    if (v->causality == MB_OUTPUT || v->causality == MB_LOCAL) {
        mbi_logf(inst, MBI_ERROR, "%s: %s is an output and cannot be set", function, v->name);
        return 0;
    }
    if (v->causality == MB_PARAMETER) {
        if (!(PHASE(inst) & (MBI_INSTANTIATED | MBI_INITIALIZATION))) {
            mbi_logf(inst, MBI_ERROR, "%s: parameter %s is fixed after initialization", function, v->name);
            return 0;
        }
    }
    return 1;
}

mbi_status mbi_get_real(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr, double value[])
{
    if (!arrays_given(inst, function, nvr, vr, value)) return MBI_ERROR;
    evaluate_initial(inst);
    const double *r = REALS(inst);
    const unsigned char *access = inst->access;
    char text[32];
    for (size_t k = 0; k < nvr; k++) {
        int a = vr[k] < (mbi_vr)MB_MODEL.nvars ? access[vr[k]] : 0;
        if (!(a & A_REAL)) {
            valid_vr(inst, function, vr[k], MB_REAL);   /* its line */
            return MBI_ERROR;
        }
        value[k] = r[vr[k]];
        /* misuse harness: after an initialization refused for a non-finite output (say
           SliderController's amplitude = 1e300), the outputs were read back NaN with OK */
        if ((a & A_OUTPUT) && !(fabs(value[k]) <= DBL_MAX)) {
            const mbi_core_state *s = CORE(inst);
            mbi_logf(inst, MBI_ERROR, "%s: output %s is %s, not finite%s%s%s", function, MB_MODEL.vars[vr[k]].name,
                     mb_repr(value[k], text), s->failed ? " (after: " : "", s->failed ? s->failure : "",
                     s->failed ? ")" : "");
            return MBI_ERROR;
        }
    }
    return MBI_OK;
}

mbi_status mbi_get_integer(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr, int value[])
{
    if (!arrays_given(inst, function, nvr, vr, value)) return MBI_ERROR;
    evaluate_initial(inst);
    const int *iv = INTS(inst);
    for (size_t k = 0; k < nvr; k++) {
        if (!valid_vr(inst, function, vr[k], MB_INTEGER)) return MBI_ERROR;
        value[k] = iv[vr[k]];
    }
    return MBI_OK;
}

int mbi_settable_real(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr)
{
    const unsigned char *access = inst->access;
    int settable_now = PHASE(inst) & (MBI_INSTANTIATED | MBI_INITIALIZATION) ? A_SET_EARLY : A_SET_ALWAYS;
    for (size_t k = 0; k < nvr; k++) {
        if (!(vr[k] < (mbi_vr)MB_MODEL.nvars && (access[vr[k]] & settable_now))) {
            if (valid_vr(inst, function, vr[k], MB_REAL)) settable(inst, function, vr[k]);   /* its line */
            return 0;
        }
    }
    return 1;
}

mbi_status mbi_set_real(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr, const double value[])
{
    /* every value reference checked before any value is set: a refused call sets nothing
       (fuzz.c: the values before a bad reference were set, with an Error) */
    if (!arrays_given(inst, function, nvr, vr, value) || !mbi_settable_real(inst, function, vr, nvr)) return MBI_ERROR;
    double *r = REALS(inst);
    for (size_t k = 0; k < nvr; k++) r[vr[k]] = value[k];
    inst->dirty = 1;
    return MBI_OK;
}

int mbi_settable_integer(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr)
{
    for (size_t k = 0; k < nvr; k++)
        if (!valid_vr(inst, function, vr[k], MB_INTEGER) || !settable(inst, function, vr[k])) return 0;
    return 1;
}

mbi_status mbi_set_integer(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr, const int value[])
{
    if (!arrays_given(inst, function, nvr, vr, value) || !mbi_settable_integer(inst, function, vr, nvr))
        return MBI_ERROR;
    int *iv = INTS(inst);
    for (size_t k = 0; k < nvr; k++) iv[vr[k]] = value[k];
    inst->dirty = 1;
    return MBI_OK;
}

mbi_status mbi_get_string(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr,
                          const char *value[])
{
    if (!arrays_given(inst, function, nvr, vr, value)) return MBI_ERROR;
    for (size_t k = 0; k < nvr; k++)
        if (!valid_vr(inst, function, vr[k], MB_STRING)) return MBI_ERROR;
    for (size_t k = 0; k < nvr; k++) value[k] = mb_string(inst, (int)vr[k]);
    return MBI_OK;
}

mbi_status mbi_set_string(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr,
                          const char *const value[])
{
    if (!arrays_given(inst, function, nvr, vr, value)) return MBI_ERROR;
    for (size_t k = 0; k < nvr; k++) {
        if (!valid_vr(inst, function, vr[k], MB_STRING) || !settable(inst, function, vr[k])) return MBI_ERROR;
        if (!value[k]) {
            mbi_logf(inst, MBI_ERROR, "%s: the value of %s is NULL (a String is text, \"\" when empty)", function,
                     MB_MODEL.vars[vr[k]].name);
            return MBI_ERROR;
        }
    }
    char **copies = calloc(nvr + 1, sizeof *copies);   /* all copied before any is set */
    for (size_t k = 0; copies && k < nvr; k++) {
        copies[k] = malloc(strlen(value[k]) + 1);
        if (!copies[k]) {
            while (k) free(copies[--k]);
            free(copies);
            copies = NULL;
        } else {
            strcpy(copies[k], value[k]);
        }
    }
    if (!copies) {
        mbi_logf(inst, MBI_ERROR, "%s: out of memory for %zu strings", function, nvr);
        return MBI_ERROR;
    }
    for (size_t k = 0; k < nvr; k++) {
        free(inst->strings[vr[k]]);
        inst->strings[vr[k]] = copies[k];
    }
    free(copies);
    inst->dirty = 1;
    return MBI_OK;
}

/* ------------------------------------------------------------------- FMU states */
/* The state to write into: the host's (it must be this FMU's size) or a new one; NULL
   after a log line, or when memory runs out. */
static mbi_state *state_slot(mb_instance *inst, const char *function, mbi_state *st)
{
    if (st && st->size != inst->size) {
        mbi_logf(inst, MBI_ERROR, "%s: the given state is not one of this FMU's", function);
        return NULL;
    }
    if (!st) {
        st = calloc(1, sizeof *st + inst->size);
        if (st) st->size = inst->size;
    }
    return st;
}

mbi_status mbi_get_state(mb_instance *inst, const char *function, mbi_state **state)
{
    mbi_state *st = state_slot(inst, function, *state);
    if (!st) return MBI_ERROR;
    memcpy(st->data, inst->block, inst->size);
    *state = st;
    return MBI_OK;
}

mbi_status mbi_set_state(mb_instance *inst, const char *function, const mbi_state *state)
{
    if (!state || state->size != inst->size) {
        mbi_logf(inst, MBI_ERROR, "%s: the given state is not one of this FMU's", function);
        return MBI_ERROR;
    }
    memcpy(inst->block, state->data, inst->size);   /* the state's phase with it */
    inst->dirty = 1;   /* fuzz.c: outputs read in initialization mode came from the inputs before the restore */
    return MBI_OK;
}

void mbi_free_state(mbi_state **state)
{
    if (!state) return;
    free(*state);
    *state = NULL;
}

/* Serialised: MAGIC, the block size as 8 bytes, the model identifier (ID_BYTES, zero
   padded), the CRC-32 of the block as 8 bytes, the block (this platform's doubles). */
enum { ID_BYTES = 64, CRC_AT = sizeof MAGIC + 8 + ID_BYTES, HEADER = CRC_AT + 8 };

mbi_status mbi_serialized_size(mb_instance *inst, const char *function, const mbi_state *state, size_t *size)
{
    if (!size || !state || state->size != inst->size) {
        mbi_logf(inst, MBI_ERROR, "%s: %s", function, size ? "no state of this FMU" : "size is NULL");
        return MBI_ERROR;
    }
    *size = HEADER + inst->size;
    return MBI_OK;
}

mbi_status mbi_serialize(mb_instance *inst, const char *function, const mbi_state *state, unsigned char bytes[],
                         size_t size)
{
    if (!state || state->size != inst->size || size < HEADER + state->size || !bytes) {
        mbi_logf(inst, MBI_ERROR, "%s: no state of this FMU, or the buffer is too small", function);
        return MBI_ERROR;
    }
    unsigned long long n = state->size;
    memcpy(bytes, MAGIC, sizeof MAGIC);
    memcpy(bytes + sizeof MAGIC, &n, 8);
    memset(bytes + sizeof MAGIC + 8, 0, ID_BYTES);
    strncpy((char *)bytes + sizeof MAGIC + 8, MB_MODEL.identifier, ID_BYTES - 1);
    unsigned long long crc = mb_crc32(state->data, state->size);
    memcpy(bytes + CRC_AT, &crc, 8);
    memcpy(bytes + HEADER, state->data, state->size);
    return MBI_OK;
}

mbi_status mbi_deserialize(mb_instance *inst, const char *function, const unsigned char bytes[], size_t size,
                           mbi_state **state)
{
    unsigned long long n = 0, crc = 0;
    char id[ID_BYTES] = {0};   /* the identifier as serialised: zero padded, every byte compared */
    strncpy(id, MB_MODEL.identifier, ID_BYTES - 1);
    if (!bytes) size = 0;   /* fuzz.c: NULL bytes of the right size were read */
    if (size >= HEADER) {
        memcpy(&n, bytes + sizeof MAGIC, 8);
        memcpy(&crc, bytes + CRC_AT, 8);
    }
    if (size != HEADER + inst->size || memcmp(bytes, MAGIC, sizeof MAGIC) != 0 || n != inst->size ||
        memcmp(bytes + sizeof MAGIC + 8, id, ID_BYTES) != 0 || crc != mb_crc32(bytes + HEADER, inst->size)) {
        mbi_logf(inst, MBI_ERROR, "%s: the bytes are not a serialised %s state (%zu bytes%s)", function,
                 MB_MODEL.identifier, size, size == HEADER + inst->size ? ", or damaged: header or checksum" : "");
        return MBI_ERROR;
    }
    mbi_state *st = state_slot(inst, function, *state);
    if (!st) return MBI_ERROR;
    memcpy(st->data, bytes + HEADER, inst->size);
    *state = st;
    return MBI_OK;
}

/* The preconditions of a doStep (as the Reference FMUs' fmi2DoStep and fmi3DoStep check theirs):
   currentCommunicationPoint the FMU's time (the end of the last accepted step, to
   STEP_TIME_TOLERANCE relative), the step finite, > 0 and large enough to advance the
   time, and its end not past the stopTime the host gave. Else a line naming ``function``, 1. */
int mbi_step_refused(mb_instance *inst, const char *function, double t, double h)
{
    const mbi_core_state *s = mbi_core(inst);
    char tb[32], hb[32], nowb[32];
    if (!(isfinite(h) && h > 0)) {   /* the Reference FMUs: "Communication step size must be > 0" */
        mbi_logf(inst, MBI_ERROR, "%s: the communication step size must be finite and > 0, got %s s", function,
                 mb_repr(h, hb));
        return 1;
    }
    if (!(fabs(t - s->time) <= STEP_TIME_TOLERANCE * fmax(1.0, fabs(s->time)))) {
        mbi_logf(inst, MBI_ERROR, "%s: currentCommunicationPoint %s s is not the FMU's time %s s "
                 "(the end of the last accepted step)", function, mb_repr(t, tb), mb_repr(s->time, nowb));
        return 1;
    }
    if (t + h == t) {   /* misuse harness: at t = 1e300 a step of 1 ms left the time where it was, with OK */
        mbi_logf(inst, MBI_ERROR, "%s: a step of %s s does not advance the time %s s (below its resolution)", function,
                 mb_repr(h, hb), mb_repr(t, tb));
        return 1;
    }
    /* to the tolerance of the communication point, so a last step ending at stopTime by sums of h runs */
    if (s->stop_defined && t + h > s->stop_time + STEP_TIME_TOLERANCE * fmax(1.0, fabs(s->stop_time))) {
        mbi_logf(inst, MBI_ERROR, "%s: the step to t=%s s passes the experiment's stopTime %s s", function,
                 mb_repr(t + h, tb), mb_repr(s->stop_time, nowb));
        return 1;
    }
    return 0;
}
