/* A random FMI 2.0 or FMI 3.0 host held against a model of the standard: from a seed, one
 * or two instances of an FMU take N random calls over the whole co-simulation API (calls
 * out of sequence, bad times and steps, invalid, duplicated and huge value references and
 * counts, wrong nValues, NULL arrays, NaN/inf/1e308/denormal values, FMU states of either
 * instance, freed and corrupted states, Reset/Terminate/FreeInstance at any time, logging
 * with odd categories), and a model of the call sequence (the standard's state tables, as
 * the Reference FMUs' masks read them, plus the kit's rules of docs/fmu-rules.md) runs
 * beside the FMU.
 *
 * Why: a hand-written misuse script (misuse.c, misuse3.c) finds what its author imagined;
 * a random sequence finds the rest. "No crash" is not enough of a truth, so each call is
 * checked:
 * - the status is one the model allows (a call out of sequence answers Error, an FMI 2.0
 *   doStep after a Discard Discard, an initialization with a parameter outside its
 *   declared range Error, ...);
 * - every status other than OK comes with a log line at that status (the logger here);
 * - a pure function of the accepted calls: the calls that changed an instance, replayed on
 *   a fresh instance, give the same answers and the same values bit for bit; an FMU state
 *   restored gives the values read when it was saved; the last successful time is the
 *   model's; no output is read non-finite with OK.
 * What it never feeds (undefined for the host under any FMU): a pointer to freed memory
 * (an instance after FreeInstance, a state of a freed instance: freed with it), an array
 * shorter than its count, a NULL callback structure or logger.
 *
 * Usage: fuzz UNZIPDIR MODEL_IDENTIFIER GUID SEED NCALLS VARS [3] [pythonfmu]
 *   VARS: "vr:t:c:start:min:max[:floor];..." per variable: t r (Real/Float64), i
 *   (Integer, Enumeration in FMI 2.0; Int32 in FMI 3.0), e (an FMI 3.0 Enumeration, read
 *   as Int64), followed by the number of elements of an FMI 3.0 array (r6); c p
 *   (parameter), i (input), o (output), x (other: the independent time); min/max "-" when
 *   not declared; a floor: no valid value below it is fed (max_step at its minimum 1e-9
 *   makes each 1 ms step a million substeps, seconds within the work bound: the budget of
 *   a run, not a defect). An argument 3: the FMU is FMI 3.0; pythonfmu: a pythonfmu
 *   FMU through the shim (the differences it is allowed: the option's uses below).
 * Prints one line per call ("K INSTANCE CALL ARGS -> STATUS"), then "fuzz ok ..." and
 * exit 0, or "VIOLATION ..." and exit 1. The same arguments replay the same calls.
 */
#include <dlfcn.h>
#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"

/* ------------------------------------------------------------------ randomness */
static uint64_t rng_state;
static uint64_t next_random(void)   /* splitmix64 */
{
    uint64_t z = (rng_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}
static int below(int n) { return (int)(next_random() % (uint64_t)n); }
static double unit(void) { return (double)(next_random() >> 11) * 0x1.0p-53; }
static int chance(double p) { return unit() < p; }

static int v3;   /* the FMU is FMI 3.0 */
/* Option "pythonfmu": a pythonfmu FMU through fmu_src/pythonfmu_shim.c, with the
   differences docs/fmu-rules.md names in its pythonfmu column (see each use). It exports
   no model-exchange function (co-simulation only): fmi2SetTime and fmi2EnterEventMode
   may be absent, and are then not called. */
static int pythonfmu;

/* -------------------------------------------------------------- the variables */
enum { C_PARAM, C_INPUT, C_OUTPUT, C_OTHER };
enum { K_REAL, K_INT, K_INT64 };   /* how a variable is read and set: Real/Float64, Integer/Int32, Int64 */
typedef struct {
    unsigned vr;
    int kind, count, causality, has_min, has_max;
    double start, min, max;
    double floor;   /* > 0: no finite value in [min, floor) is fed (a cost, not a rule: see VARS) */
} Var;
#define MAXV 512
static Var vars[MAXV];
static int nvars;
static unsigned max_vr;

static void parse_vars(char *spec)
{
    for (char *item = strtok(spec, ";"); item && nvars < MAXV; item = strtok(NULL, ";")) {
        Var *v = &vars[nvars++];
        char t[16], c, mn[64], mx[64];
        int n = sscanf(item, "%u:%15[^:]:%c:%lf:%63[^:]:%63[^:]:%lf", &v->vr, t, &c, &v->start, mn, mx, &v->floor);
        if (n != 6 && n != 7) {
            fprintf(stderr, "fuzz: bad variable '%s'\n", item);
            exit(10);
        }
        v->kind = t[0] == 'i' ? K_INT : t[0] == 'e' ? K_INT64 : K_REAL;
        v->count = t[1] ? atoi(t + 1) : 1;
        v->causality = c == 'p' ? C_PARAM : c == 'i' ? C_INPUT : c == 'o' ? C_OUTPUT : C_OTHER;
        v->has_min = strcmp(mn, "-") != 0;
        v->has_max = strcmp(mx, "-") != 0;
        v->min = v->has_min ? strtod(mn, NULL) : 0;
        v->max = v->has_max ? strtod(mx, NULL) : 0;
        if (v->vr > max_vr) max_vr = v->vr;
    }
}

static int var_of(unsigned vr)
{
    for (int k = 0; k < nvars; k++)
        if (vars[k].vr == vr) return k;
    return -1;
}

/* ------------------------------------------------------------------ the model */
/* The co-simulation states. FAILED: FMI 2.0 stepFailed (after a Discard) and the state
   after a failed initialization (the kit answers both alike, docs/fmu-rules.md); FMI 3.0
   StepDiscarded. A failed FMI 3.0 initialization stays in INIT with failed set (the
   standard's error state: reads, Reset, FreeInstance and the state calls lead on). */
enum { S_INSTANTIATED, S_INIT, S_STEP, S_FAILED, S_TERMINATED };
static const char *const STATE_NAME[] = {"Instantiated", "InitializationMode", "StepComplete/StepMode",
                                         "StepFailed/StepDiscarded", "Terminated"};
typedef struct {
    int st, failed, stop_defined;
    double start, time, tstop;
    double value[MAXV];   /* every scalar variable's value as set (Integers as doubles) */
} Model;

/* The calls that changed an instance since it was instantiated: replayed on a fresh one. */
enum { OP_SETUP, OP_ENTER, OP_EXIT, OP_SET, OP_STEP, OP_TERM };
typedef struct {
    int kind, status, stop_defined, type;
    double a, b;
    size_t n, nvalues;
    unsigned *vr;
    void *values;
} Op;
static Op *arena;   /* every op ever recorded (immutable); a history is a list of indices */
static int narena, arena_cap;
typedef struct { int *op; int n, cap; } History;

static void history_add(History *h, int op)
{
    if (h->n == h->cap) {
        h->cap = h->cap ? 2 * h->cap : 64;
        h->op = realloc(h->op, (size_t)h->cap * sizeof *h->op);
    }
    h->op[h->n++] = op;
}
static void history_copy(History *to, const History *from)
{
    to->n = 0;
    for (int k = 0; k < from->n; k++) history_add(to, from->op[k]);
}
static int record(Op op)
{
    if (narena == arena_cap) {
        arena_cap = arena_cap ? 2 * arena_cap : 256;
        arena = realloc(arena, (size_t)arena_cap * sizeof *arena);
    }
    arena[narena] = op;
    return narena++;
}

/* One variable read: its status, the first element, and a hash of every element's bits. */
typedef struct { int status; double first; uint64_t hash; } Reading;

typedef struct {
    void *c;   /* fmi2Component or fmi3Instance */
    Model m;
    History h;
} Instance;

typedef struct {
    void *s;   /* fmi2FMUstate or fmi3FMUState */
    int owner;   /* the instance whose call allocated it */
    Model m;
    History h;
    int readable;
    Reading r[MAXV];
} Slot;

typedef struct {
    unsigned char *data;
    size_t size;
    Model m;
    History h;
    int readable;
    Reading r[MAXV];
} Blob;

#define NINST 2
#define NSLOT 3
#define NBLOB 2
static Instance inst[NINST];
static Slot slot[NSLOT];
static Blob blob[NBLOB];
static Model start_model;

/* ------------------------------------------------------------------- the FMU */
static void *lib;
static const char *guid;
static char resources[4200], resource_path[4200];
/* The calls of each version, named once: declared here, looked up in main. */
#define FMI2_CALLS(X)                                                                                          \
    X(Instantiate) X(FreeInstance) X(SetDebugLogging) X(SetupExperiment) X(EnterInitializationMode)            \
    X(ExitInitializationMode) X(Terminate) X(Reset) X(DoStep) X(CancelStep) X(SetReal) X(GetReal) X(SetInteger) \
    X(GetInteger) X(SetBoolean) X(GetBoolean) X(SetString) X(GetString) X(GetFMUstate) X(SetFMUstate)           \
    X(FreeFMUstate) X(SerializedFMUstateSize) X(SerializeFMUstate) X(DeSerializeFMUstate) X(GetStatus)          \
    X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus) X(GetStringStatus) X(SetRealInputDerivatives)      \
    X(GetRealOutputDerivatives) X(GetDirectionalDerivative) X(GetTypesPlatform) X(GetVersion) X(SetTime)        \
    X(EnterEventMode)
#define FMI3_CALLS(X)                                                                                          \
    X(InstantiateCoSimulation) X(InstantiateModelExchange) X(FreeInstance) X(SetDebugLogging)                  \
    X(EnterInitializationMode) X(ExitInitializationMode) X(Terminate) X(Reset) X(DoStep) X(GetFloat64)         \
    X(SetFloat64) X(GetInt32) X(SetInt32) X(GetInt64) X(SetInt64) X(GetBoolean) X(SetBoolean) X(GetString)    \
    X(SetString) X(GetFloat32) X(SetUInt8) X(GetFMUState) X(SetFMUState) X(FreeFMUState)                      \
    X(SerializedFMUStateSize) X(SerializeFMUState) X(DeserializeFMUState) X(EnterEventMode) X(EnterStepMode)  \
    X(EnterConfigurationMode) X(SetTime) X(GetDirectionalDerivative) X(GetVersion)
#define DECLARE2(name) static fmi2##name##TYPE *name;
#define DECLARE3(name) static fmi3##name##TYPE *name##3;
FMI2_CALLS(DECLARE2)
FMI3_CALLS(DECLARE3)

static const char *STATUS[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};
static const char *status_name(int s) { return s >= 0 && s <= fmi2Pending ? STATUS[s] : "?"; }

static long call_no;
static int current;   /* the instance of the call under way */
static char seen_call[600];
static int seen_state, seen_failed;
static int last_log = -1;   /* the status of the last log line of the call under way */
static char last_text[600];

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env, (void)name, (void)category;
    va_list ap;
    va_start(ap, message);
    vsnprintf(last_text, sizeof last_text, message, ap);   /* a C host: the message is a format */
    va_end(ap);
    last_log = status;
}
static const fmi2CallbackFunctions CALLBACKS = {logger, calloc, free, NULL, NULL};

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env, (void)category;
    snprintf(last_text, sizeof last_text, "%s", message ? message : "(null)");   /* FMI 3.0: text */
    last_log = status;
}

static void violation(const char *fmt, ...)
{
    va_list ap;
    printf("\nVIOLATION at call %ld (%s): ", call_no, seen_call);
    va_start(ap, fmt);
    vprintf(fmt, ap);
    va_end(ap);
    printf("\nthe model's state of instance %d before the call: %s%s\nlast log line: %s\n", current,
           STATE_NAME[seen_state], seen_failed ? " (failed)" : "", last_log >= 0 ? last_text : "(none)");
    fflush(stdout);
    exit(1);
}

static void begin(int i, const char *fmt, ...)
{
    va_list ap;
    int n = snprintf(seen_call, sizeof seen_call, "%d fmi%d", i, v3 ? 3 : 2);
    current = i;
    seen_state = inst[i].m.st;
    seen_failed = inst[i].m.failed;
    va_start(ap, fmt);
    vsnprintf(seen_call + n, sizeof seen_call - (size_t)n, fmt, ap);
    va_end(ap);
    call_no++;
    printf("%ld %s -> ", call_no, seen_call);
    fflush(stdout);
    last_log = -1;
}

enum { OK = 1 << fmi2OK, DISCARD = 1 << fmi2Discard, ERROR = 1 << fmi2Error };
static long answered[6];

/* The answer against the model's set of allowed statuses, and its log line. */
static int check(int status, int allowed)
{
    printf("%s\n", status_name(status));
    if (status >= 0 && status <= fmi2Pending) answered[status]++;
    if (status < 0 || status > fmi2Pending || !(allowed & (1 << status)))
        violation("answered %s, the model allows only%s%s%s", status_name(status), allowed & OK ? " OK" : "",
                  allowed & DISCARD ? " Discard" : "", allowed & ERROR ? " Error" : "");
    if (status != fmi2OK && last_log != status)
        violation("answered %s without a log line at %s (last line at %s)", status_name(status),
                  status_name(status), last_log >= 0 ? status_name(last_log) : "none");
    return status;
}

/* ------------------------------------------------------------ values to feed */
static const double ODD[] = {NAN, INFINITY, -INFINITY, 1e308, -1e308, DBL_MAX, -DBL_MAX, 5e-324, -5e-324,
                             2.2250738585072014e-308, 0.0, -0.0, 1e-300, 1e300, -1e300, 1.0, -1.0, 1e9, -1e9};
#define NODD ((int)(sizeof ODD / sizeof ODD[0]))

static double odd_or_edge(const Var *v)
{
    int k = below(10);
    if (k < 6) return v->start * (1 + 0.01 * (unit() - 0.5)) + (v->causality == C_INPUT ? 0.01 * (unit() - 0.5) : 0);
    if (k < 7 && (v->has_min || v->has_max)) {
        double edge = v->has_min && (!v->has_max || chance(0.5)) ? v->min : v->max;
        return chance(0.5) ? edge : edge + (edge == v->min ? -1 : 1) * (fabs(edge) * 1e-6 + 1e-9);
    }
    return ODD[below(NODD)];
}

static double real_for(const Var *v)
{
    double x = odd_or_edge(v);
    return v->floor > 0 && x > 0 && x < v->floor && !(v->has_min && x < v->min) ? v->floor : x;
}

static long long int_for(const Var *v)
{
    switch (below(9)) {
    case 0: return INT_MIN;
    case 1: return INT_MAX;
    case 2: return v->has_min ? (long long)v->min - 1 : -1;
    case 3: return v->has_max ? (long long)v->max + 1 : 7;
    case 4: return below(5) - 2;
    case 5: return v->kind == K_INT64 ? (chance(0.5) ? LLONG_MIN : 1ll << 40) : (long long)v->start;
    default: return (long long)v->start;
    }
}

/* A random variable of the kind, of a causality when >= 0. */
static int pick_var(int kind, int causality)
{
    int found[MAXV], n = 0;
    for (int k = 0; k < nvars; k++)
        if (vars[k].kind == kind && (causality < 0 || vars[k].causality == causality)) found[n++] = k;
    if (!n) return -1;
    return found[below(n)];
}

/* Value references for a get or set: mostly a few valid ones of the kind, sometimes
   none, a huge count with duplicates, or invalid ones (past the last, UINT_MAX, of
   another kind). */
static size_t pick_refs(int kind, int set, unsigned *vr, size_t cap)
{
    size_t n = chance(0.05) ? 0 : chance(0.05) ? (size_t)(500 + below(3000)) : (size_t)(1 + below(4));
    if (n > cap) n = cap;
    int wanted = set ? (chance(0.5) ? C_INPUT : C_PARAM) : -1;
    for (size_t k = 0; k < n; k++) {
        int j = pick_var(kind, chance(0.8) ? wanted : -1);
        if (j < 0) j = pick_var(kind, -1);
        vr[k] = j >= 0 ? vars[j].vr : max_vr + 1;
        if (chance(0.03)) {
            static const unsigned BAD[] = {UINT_MAX, 0x80000000u, 100000u};
            int other = pick_var((kind + 1 + below(2)) % 3, -1);
            int b = below(5);
            vr[k] = b < 3 ? BAD[b] : b == 3 ? max_vr + 1 : (other >= 0 ? vars[other].vr : max_vr + 1);
        }
    }
    return n;
}

static int element_count(const unsigned *vr, size_t n, int kind, int *valid)
{
    size_t total = 0;
    for (size_t k = 0; k < n; k++) {
        int j = var_of(vr[k]);
        if (j < 0 || vars[j].kind != kind) *valid = 0;
        else total += (size_t)vars[j].count;
    }
    return (int)total;
}

/* ------------------------------------------------------ calls of either version */
static size_t elem_size(int kind) { return kind == K_REAL ? sizeof(double) : kind == K_INT ? sizeof(int) : sizeof(long long); }

static int api_get(void *c, int kind, const unsigned *vr, size_t n, void *values, size_t nvalues)
{
    if (!v3) {
        if (kind == K_REAL) return GetReal(c, vr, n, values);
        return GetInteger(c, vr, n, values);
    }
    if (kind == K_REAL) return GetFloat643(c, vr, n, values, nvalues);
    if (kind == K_INT) return GetInt323(c, vr, n, values, nvalues);
    return GetInt643(c, vr, n, values, nvalues);
}

static int api_set(void *c, int kind, const unsigned *vr, size_t n, const void *values, size_t nvalues)
{
    if (!v3) {
        if (kind == K_REAL) return SetReal(c, vr, n, values);
        return SetInteger(c, vr, n, values);
    }
    if (kind == K_REAL) return SetFloat643(c, vr, n, values, nvalues);
    if (kind == K_INT) return SetInt323(c, vr, n, values, nvalues);
    return SetInt643(c, vr, n, values, nvalues);
}

static int api_step(void *c, double t, double h, int null_out, int *terminate, double *last)
{
    if (!v3) return DoStep(c, t, h, fmi2True);
    fmi3Boolean event = 7, term = 7, early = 7;
    double l = NAN;
    int s = DoStep3(c, t, h, fmi3True, null_out ? NULL : &event, &term, &early, &l);
    *terminate = term;
    *last = l;
    if (s <= fmi3Discard && !null_out && (event || early))
        violation("fmi3DoStep: eventHandlingNeeded %d, earlyReturn %d (the FMU has neither)", event, early);
    return s;
}

static int api_enter(void *c, double t0, int stop_defined, double stop)
{
    if (!v3) return EnterInitializationMode(c);
    return EnterInitializationMode3(c, fmi3False, 0, t0, (fmi3Boolean)stop_defined, stop);
}

static void *fresh_instance(const char *name)
{
    if (!v3) return Instantiate(name, fmi2CoSimulation, guid, resources, &CALLBACKS, fmi2False, fmi2False);
    return InstantiateCoSimulation3(name, guid, resource_path, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0,
                                    NULL, logger3, NULL);
}

/* ---------------------------------------------------------- reading everything */
static int readable(const Model *m) { return m->st != S_INSTANTIATED; }

static void read_all(void *c, Reading *out)
{
    for (int k = 0; k < nvars; k++) {
        unsigned vr = vars[k].vr;
        size_t n = (size_t)vars[k].count;
        unsigned char bytes[1024 * 8] = {0};
        if (n > 1024) n = 1024;
        out[k].status = api_get(c, vars[k].kind, &vr, 1, bytes, n);
        uint64_t hash = 1469598103934665603ull;   /* FNV-1a of every element's bytes */
        for (size_t b = 0; out[k].status == fmi2OK && b < n * elem_size(vars[k].kind); b++)
            hash = (hash ^ bytes[b]) * 1099511628211ull;
        out[k].hash = out[k].status == fmi2OK ? hash : 0;
        out[k].first = vars[k].kind == K_REAL ? *(double *)bytes
                     : vars[k].kind == K_INT ? *(int *)bytes : (double)*(long long *)bytes;
        if (out[k].status != fmi2OK) out[k].first = 0;
    }
}

/* Do the outputs of an instance with this model and history replay bit for bit? Not
   always under the option pythonfmu (docs/fmu-rules.md, the row "What a read returns is a
   function of the values set": no pythonfmu rule): in initialization mode, and after a
   refused initialization, the outputs are what the last evaluation that succeeded left
   (an evaluation of bad start values leaves them as they were), a function of the reads
   in initialization mode too. Every other variable is compared. */
static int outputs_replay(const Model *m, const History *h)
{
    if (!pythonfmu) return 1;
    int init_refused = 0;
    for (int k = 0; k < h->n; k++)
        init_refused |= arena[h->op[k]].kind == OP_EXIT && arena[h->op[k]].status != fmi2OK;
    return m->st != S_INIT && !init_refused;
}

/* ``outputs``: 0 to leave the outputs out (outputs_replay). */
static void compare(const Reading *a, const Reading *b, const char *what, int outputs)
{
    for (int k = 0; k < nvars; k++)
        if ((outputs || vars[k].causality != C_OUTPUT) && (a[k].status != b[k].status || a[k].hash != b[k].hash))
            violation("%s: value reference %u reads %s %.17g..., expected %s %.17g...", what, vars[k].vr,
                      status_name(b[k].status), b[k].first, status_name(a[k].status), a[k].first);
}

/* ------------------------------------------------------------------ the calls */
static void instantiate(int i)
{
    static const char *const NAMES[] = {"fuzz", "%s%n%s", "", "a name with spaces", "\xff\xfe"};
    const char *name = NAMES[below(5)];
    int kind = below(12);   /* 0: a wrong GUID/token, 1: none, 2: model exchange, 3: (FMI 3) event mode, else right */
    const char *g = kind == 0 ? "{00000000-%s-%n}" : kind == 1 ? NULL : guid;
    int on = below(2);
    begin(i, "Instantiate(name '%s', %s, GUID %s, loggingOn %d)", name,
          kind == 2 ? "ME" : kind == 3 && v3 ? "CS with event mode" : "CS",
          kind == 0 ? "wrong" : kind == 1 ? "NULL" : "right", on);
    void *c;
    if (!v3) c = Instantiate(name, kind == 2 ? fmi2ModelExchange : fmi2CoSimulation, g, resources, &CALLBACKS,
                             fmi2False, (fmi2Boolean)on);
    else if (kind == 2) c = InstantiateModelExchange3(name, g, resource_path, fmi3False, (fmi3Boolean)on, NULL, logger3);
    else c = InstantiateCoSimulation3(name, g, resource_path, fmi3False, (fmi3Boolean)on, kind == 3, fmi3False, NULL, 0,
                                      NULL, logger3, NULL);
    int expected = kind > 3 || (kind == 3 && !v3);
    printf("%s\n", c ? "instance" : "NULL");
    if ((c != NULL) != expected) violation("Instantiate answered %s", c ? "an instance" : "NULL");
    if (!c && last_log != fmi2Error) violation("Instantiate answered NULL without a log line at Error");
    inst[i].c = c;
    inst[i].m = start_model;
    inst[i].h.n = 0;
}

static void free_slot(int i, int k)
{
    begin(i, "FreeFMUstate(slot %d)", k);
    check(v3 ? FreeFMUState3(inst[i].c, &slot[k].s) : FreeFMUstate(inst[i].c, &slot[k].s), OK);
    if (slot[k].s) violation("FreeFMUstate left the state pointer set");
}

static void free_instance(int i)
{
    for (int k = 0; k < NSLOT; k++)   /* a state of a freed instance is gone with it */
        if (slot[k].s && slot[k].owner == i) free_slot(i, k);
    begin(i, "FreeInstance");
    if (v3) FreeInstance3(inst[i].c);
    else FreeInstance(inst[i].c);
    printf("done\n");
    inst[i].c = NULL;
}

/* FMI 2.0 fmi2SetupExperiment, or (FMI 3.0) the same arguments to fmi3EnterInitializationMode. */
static void setup(int i)
{
    static const double T0[] = {0.0, 0.0, 0.0, 1.5, -5.0, 1e9, 1e300, NAN, INFINITY, 5e-324};
    Model *m = &inst[i].m;
    double t0 = T0[below(10)], stop = 0;
    int stop_defined = chance(0.3);
    if (stop_defined) {
        static const double AFTER[] = {0.005, 1.0, INFINITY, NAN, -1.0, 0.0};
        stop = t0 + AFTER[below(6)];
    }
    begin(i, "%s(startTime %.17g, stopTimeDefined %d, stopTime %.17g)", v3 ? "EnterInitializationMode" :
          "SetupExperiment", t0, stop_defined, stop);
    int ok = m->st == S_INSTANTIATED && isfinite(t0) && (!stop_defined || stop >= t0);
    int s = check(v3 ? api_enter(inst[i].c, t0, stop_defined, stop)
                     : (int)SetupExperiment(inst[i].c, fmi2False, 0, t0, (fmi2Boolean)stop_defined, stop), ok ? OK : ERROR);
    if (s == fmi2OK) {
        m->start = m->time = t0;
        m->stop_defined = stop_defined;
        m->tstop = stop;
        if (v3) m->st = S_INIT;
        history_add(&inst[i].h, record((Op){.kind = v3 ? OP_ENTER : OP_SETUP, .status = s, .a = t0, .b = stop,
                                            .stop_defined = stop_defined}));
    }
}

static void enter(int i)
{
    if (v3) {
        setup(i);
        return;
    }
    Model *m = &inst[i].m;
    begin(i, "EnterInitializationMode");
    if (check(EnterInitializationMode(inst[i].c), m->st == S_INSTANTIATED ? OK : ERROR) == fmi2OK) {
        m->st = S_INIT;
        history_add(&inst[i].h, record((Op){.kind = OP_ENTER, .status = fmi2OK}));
    }
}

/* A scalar parameter outside its declared range or a scalar Real input that is not
   finite: the initialization must fail (Error). */
static int surely_invalid(const Model *m)
{
    for (int k = 0; k < nvars; k++) {
        const Var *v = &vars[k];
        double x = m->value[k];
        if (v->count != 1) continue;
        if (v->causality == C_PARAM && ((v->has_min && !(x >= v->min)) || (v->has_max && !(x <= v->max)))) return 1;
        if (v->causality == C_INPUT && v->kind == K_REAL && !isfinite(x)) return 1;
    }
    return 0;
}

static void exit_init(int i)
{
    Model *m = &inst[i].m;
    begin(i, "ExitInitializationMode");
    int may = m->st == S_INIT && !m->failed;
    int allowed = !may ? ERROR : surely_invalid(m) ? ERROR : OK | ERROR;
    int s = check(v3 ? ExitInitializationMode3(inst[i].c) : ExitInitializationMode(inst[i].c), allowed);
    if (may) {   /* a failed initialization: FMI 2.0 (the kit) failed; FMI 3.0 the error state */
        m->st = s == fmi2OK ? S_STEP : v3 ? S_INIT : S_FAILED;
        m->failed = s != fmi2OK;
        history_add(&inst[i].h, record((Op){.kind = OP_EXIT, .status = s}));
    }
}

static void terminate(int i)
{
    Model *m = &inst[i].m;
    begin(i, "Terminate");
    int ok = m->st == S_STEP || m->st == S_FAILED;
    if (check(v3 ? Terminate3(inst[i].c) : Terminate(inst[i].c), ok ? OK : ERROR) == fmi2OK) {
        m->st = S_TERMINATED;
        history_add(&inst[i].h, record((Op){.kind = OP_TERM, .status = fmi2OK}));
    }
}

static void reset(int i)
{
    begin(i, "Reset");
    check(v3 ? Reset3(inst[i].c) : Reset(inst[i].c), OK);
    inst[i].m = start_model;
    inst[i].h.n = 0;
}

static double bigger(double a, double b) { return a > b ? a : b; }   /* fmax, without libm (the host links none) */
#define TOLERANCE 1e-9   /* docs/fmu-rules.md: the communication point to 1e-9 relative to max(1 s, |t|) */
static void step(int i)
{
    Model *m = &inst[i].m;
    static const double ODD_H[] = {0.0, -1e-3, NAN, INFINITY, -INFINITY, 5e-324, 1e308, 1e9, 1e7, 1e-300};
    double h = chance(0.85) ? (chance(0.6) ? 1e-3 : 1e-5 + 1e-2 * unit() * unit() * unit()) : ODD_H[below(10)];
    double t = m->time;
    if (chance(0.12)) {
        static const double OFF[] = {1e-3, -1e-3, 5.0, 1e-12, NAN, INFINITY, 1e300, -1e300};
        double off = OFF[below(8)];
        t = off == 1e-12 ? t + off : off == 1e-3 || off == -1e-3 ? t + off * bigger(1.0, fabs(t)) : off;
    }
    int null_out = v3 && chance(0.03);
    begin(i, "DoStep(%.17g, %.17g%s)", t, h, null_out ? ", NULL out argument" : "");
    int allowed;
    if (m->st == S_FAILED && !v3) allowed = DISCARD;   /* the kit: a failed instance refuses every step */
    else if (m->st != S_STEP || null_out) allowed = ERROR;
    else if (!(isfinite(h) && h > 0) || !(fabs(t - m->time) <= TOLERANCE * bigger(1.0, fabs(m->time))) || t + h == t ||
             (m->stop_defined && t + h > m->tstop + TOLERANCE * bigger(1.0, fabs(m->tstop))))
        allowed = ERROR;
    else allowed = OK | DISCARD;
    int terminate_simulation = 0;
    double last = 0;
    int s = check(api_step(inst[i].c, t, h, null_out, &terminate_simulation, &last), allowed);
    if (m->st == S_STEP && s != fmi2Error) {
        double before = m->time;
        if (s == fmi2OK) m->time = t + h;
        else m->st = S_FAILED, m->failed = 1;
        history_add(&inst[i].h, record((Op){.kind = OP_STEP, .status = s, .a = t, .b = h}));
        if (v3 && (terminate_simulation != (s == fmi2Discard) || memcmp(&last, s == fmi2OK ? &m->time : &before,
                                                                        sizeof last) != 0))
            violation("fmi3DoStep: terminateSimulation %d, lastSuccessfulTime %.17g; the model says %d, %.17g",
                      terminate_simulation, last, s == fmi2Discard, s == fmi2OK ? m->time : before);
    }
}

static unsigned refs[4096];

static void set_values(int i, int kind)
{
    Model *m = &inst[i].m;
    size_t n = pick_refs(kind, 1, refs, sizeof refs / sizeof refs[0]);
    int null_refs = n && chance(0.02), null_values = n && chance(0.02);
    int valid = (m->st == S_INSTANTIATED || m->st == S_INIT || m->st == S_STEP) && !m->failed;
    int kinds_ok = 1;
    size_t total = (size_t)element_count(refs, n, kind, &kinds_ok), given = total;
    if (v3 && chance(0.05)) given = total + 1 - 2 * (size_t)(total > 0 && chance(0.5));
    size_t cap = (total > given ? total : given) + n + 1, at = 0;   /* FMI 2.0: one value per reference, valid or not */
    unsigned char *values = calloc(cap, 8);
    for (size_t k = 0; k < n; k++) {
        int j = var_of(refs[k]);
        int count = j >= 0 && vars[j].kind == kind ? vars[j].count : v3 ? 0 : 1;
        for (int e = 0; e < count; e++, at++) {
            if (kind == K_REAL) ((double *)values)[at] = j >= 0 ? real_for(&vars[j]) : ODD[below(NODD)];
            else {
                long long x = j >= 0 ? int_for(&vars[j]) : INT_MIN;
                if (kind == K_INT) ((int *)values)[at] = (int)(x < INT_MIN ? INT_MIN : x > INT_MAX ? INT_MAX : x);
                else ((long long *)values)[at] = x, valid &= x >= INT_MIN && x <= INT_MAX;
            }
        }
        valid &= j >= 0 && vars[j].kind == kind &&
                 (vars[j].causality == C_INPUT || (vars[j].causality == C_PARAM && m->st != S_STEP));
    }
    valid &= kinds_ok && !null_refs && !null_values && given == total;
    begin(i, "Set%s(%zu refs, %zu values%s%s: %u, ...)", kind == K_REAL ? "Real/Float64" : kind == K_INT ?
          "Integer/Int32" : "Int64", n, given, null_refs ? ", NULL vr" : "", null_values ? ", NULL values" : "",
          n ? refs[0] : 0);
    int s = check(api_set(inst[i].c, kind, null_refs ? NULL : refs, n, null_values ? NULL : values, given),
                  valid ? OK : ERROR);
    if (s == fmi2OK) {
        Op op = {.kind = OP_SET, .status = s, .type = kind, .n = n, .nvalues = given, .values = values};
        op.vr = malloc((n + 1) * sizeof *op.vr);
        memcpy(op.vr, refs, n * sizeof *op.vr);
        history_add(&inst[i].h, record(op));
        at = 0;
        for (size_t k = 0; k < n; k++) {
            int j = var_of(refs[k]);
            m->value[j] = kind == K_REAL ? ((double *)values)[at] : kind == K_INT ? ((int *)values)[at]
                                                                   : (double)((long long *)values)[at];
            at += (size_t)vars[j].count;
        }
        values = NULL;
    }
    free(values);
}

static void get_values(int i, int kind)
{
    Model *m = &inst[i].m;
    size_t n = pick_refs(kind, 0, refs, sizeof refs / sizeof refs[0]);
    int null_refs = n && chance(0.02), null_values = n && chance(0.02);
    int valid = !null_refs && !null_values, has_output = 0;
    size_t total = (size_t)element_count(refs, n, kind, &valid), given = total;
    if (v3 && chance(0.05)) given = total + 1 - 2 * (size_t)(total > 0 && chance(0.5));
    valid &= given == total;
    for (size_t k = 0; k < n; k++) {
        int j = var_of(refs[k]);
        has_output |= j >= 0 && vars[j].causality == C_OUTPUT;
    }
    /* FMI 2.0: one value per reference, valid or not (a refused get may write them all) */
    unsigned char *values = calloc((total > given ? total : given) + n + 1, 8);
    begin(i, "Get%s(%zu refs, %zu values%s%s, first %u)", kind == K_REAL ? "Real/Float64" : kind == K_INT ?
          "Integer/Int32" : "Int64", n, given, null_refs ? ", NULL vr" : "", null_values ? ", NULL values" : "",
          n ? refs[0] : 0);
    int allowed = !valid ? ERROR
                : m->st == S_INSTANTIATED ? (v3 ? OK | ERROR : ERROR)   /* FMI 3.0 allows it, the kit refuses */
                : m->failed && has_output ? OK | ERROR                  /* a failed initialization's outputs */
                : m->st == S_FAILED && v3 ? OK | ERROR                  /* StepDiscarded: the kit answers */
                : OK;
    int s = check(api_get(inst[i].c, kind, null_refs ? NULL : refs, n, null_values ? NULL : values, given), allowed);
    if (s == fmi2OK && kind == K_REAL) {
        size_t at = 0;
        double now = m->st == S_INIT ? m->start : m->time;
        for (size_t k = 0; k < n; k++) {
            int j = var_of(refs[k]);
            for (int e = 0; e < vars[j].count; e++, at++) {
                double x = ((double *)values)[at];
                if (vars[j].causality == C_OUTPUT && !isfinite(x)) violation("output %u read %g with OK", refs[k], x);
                if (v3 && vars[j].causality == C_OTHER && memcmp(&x, &now, sizeof x) != 0)   /* the independent time */
                    violation("time (value reference %u) reads %.17g, the model's %.17g", refs[k], x, now);
            }
        }
    }
    free(values);
}

/* The types the kit's FMUs have no variables of: an empty call is fine where allowed. */
static void other_types(int i)
{
    Model *m = &inst[i].m;
    size_t n = chance(0.5) ? 0 : 1 + (size_t)below(3);
    unsigned vr[4] = {0, 1, 2, 3};
    unsigned char buffer[64] = {0};
    const char *str[4] = {"a", "%s", "", "b"};
    int which = below(v3 ? 6 : 4);
    int get_ok = readable(m) && (!v3 || m->st != S_FAILED);
    int set_ok = (m->st == S_INSTANTIATED || m->st == S_INIT || m->st == S_STEP) && !m->failed;
    int get_maybe = v3 && (m->st == S_INSTANTIATED || m->st == S_FAILED || m->failed);   /* standard vs kit */
    int set_maybe = v3 && m->st == S_TERMINATED;
    static const char *const NAME[] = {"GetBoolean", "SetBoolean", "GetString", "SetString", "GetFloat32", "SetUInt8"};
    begin(i, "%s(%zu refs)", NAME[which], n);
    int ok = which % 2 ? set_ok : get_ok, maybe = which % 2 ? set_maybe : get_maybe;
    int allowed = n ? ERROR : ok ? OK : maybe ? OK | ERROR : ERROR;
    void *c = inst[i].c;
    int s;
    if (!v3) {
        s = which == 0 ? GetBoolean(c, vr, n, (fmi2Boolean *)buffer) : which == 1 ? SetBoolean(c, vr, n, (fmi2Boolean *)buffer)
          : which == 2 ? GetString(c, vr, n, str) : SetString(c, vr, n, str);
    } else {
        s = which == 0 ? GetBoolean3(c, vr, n, (fmi3Boolean *)buffer, n) : which == 1 ? SetBoolean3(c, vr, n, (fmi3Boolean *)buffer, n)
          : which == 2 ? GetString3(c, vr, n, str, n) : which == 3 ? SetString3(c, vr, n, str, n)
          : which == 4 ? GetFloat323(c, vr, n, (fmi3Float32 *)buffer, n) : SetUInt83(c, vr, n, buffer, n);
    }
    check(s, allowed);
}

/* FMI 2.0's status queries (FMI 3.0 has none: the call of what the FMU does not offer instead). */
static void not_offered(int i);
static void status_query(int i)
{
    if (v3) {
        not_offered(i);
        return;
    }
    Model *m = &inst[i].m;
    int ok_state = m->st == S_STEP || m->st == S_FAILED || m->st == S_TERMINATED;
    int kind = chance(0.8) ? below(4) : (chance(0.5) ? 99 : -1);
    int which = below(5), null_value = chance(0.03);
    static const char *const NAME[] = {"GetStatus", "GetRealStatus", "GetIntegerStatus", "GetBooleanStatus",
                                       "GetStringStatus"};
    begin(i, "%s(kind %d%s)", NAME[which], kind, null_value ? ", NULL value" : "");
    fmi2StatusKind k = (fmi2StatusKind)kind;
    ok_state &= !null_value;
    if (which == 0) {
        fmi2Status v = fmi2Fatal;
        if (check(GetStatus(inst[i].c, k, null_value ? NULL : &v), ok_state && k == fmi2DoStepStatus ? OK : ERROR) ==
                fmi2OK && v != (m->failed ? fmi2Discard : fmi2OK))
            violation("fmi2DoStepStatus is %s, the model says %s", status_name(v), m->failed ? "Discard" : "OK");
    } else if (which == 1) {
        double t = -1;
        if (check(GetRealStatus(inst[i].c, k, null_value ? NULL : &t), ok_state && k == fmi2LastSuccessfulTime ? OK :
                  ERROR) == fmi2OK && memcmp(&t, &m->time, sizeof t) != 0)
            violation("fmi2LastSuccessfulTime is %.17g, the model's time %.17g", t, m->time);
    } else if (which == 2) {
        fmi2Integer v;
        check(GetIntegerStatus(inst[i].c, k, &v), ERROR);
    } else if (which == 3) {
        fmi2Boolean v = 7;
        if (check(GetBooleanStatus(inst[i].c, k, null_value ? NULL : &v), ok_state && k == fmi2Terminated ? OK : ERROR)
                == fmi2OK && v != (m->failed ? fmi2True : fmi2False))
            violation("fmi2Terminated is %d, the model says %d", v, m->failed);
    } else {
        fmi2String v;
        check(GetStringStatus(inst[i].c, k, &v), ERROR);
    }
}

static void logging(int i)
{
    static const char *const CATS[] = {"logStatusWarning", "logStatusDiscard", "logStatusError", "logStatusFatal",
                                       "logAll", "", "%s%n%s", "logEvents", NULL};
    const char *cats[4];
    size_t n = (size_t)below(4);
    int known = 1, null_array = n && chance(0.1);
    for (size_t k = 0; k < n; k++) {
        int c = chance(0.7) ? below(5) : 5 + below(4);
        cats[k] = CATS[c];
        known &= c < 5;
    }
    int on = below(2);
    begin(i, "SetDebugLogging(%d, %zu categories%s, first '%s')", on, n, null_array ? ", NULL array" : "",
          n && cats[0] ? cats[0] : "(null)");
    const char **given = null_array ? NULL : cats;
    check(v3 ? SetDebugLogging3(inst[i].c, (fmi3Boolean)on, n, given) : SetDebugLogging(inst[i].c, (fmi2Boolean)on, n, given),
          known && !null_array ? OK : ERROR);
}

static void not_offered(int i)
{
    unsigned vr = 0;
    fmi2Integer order = 1;
    double x = 0, y = 0;
    int which = below(pythonfmu && !SetTime ? 4 : 6);
    static const char *const NAME2[] = {"CancelStep", "SetRealInputDerivatives", "GetRealOutputDerivatives",
                                        "GetDirectionalDerivative", "SetTime", "EnterEventMode"};
    static const char *const NAME3[] = {"EnterEventMode", "EnterStepMode", "EnterConfigurationMode",
                                        "GetDirectionalDerivative", "SetTime", "InstantiateModelExchange"};
    void *c = inst[i].c;
    if (v3) {
        begin(i, "%s", NAME3[which]);
        if (which == 5) {
            void *me = InstantiateModelExchange3("me", guid, resource_path, fmi3False, fmi3False, NULL, logger3);
            printf("%s\n", me ? "instance" : "NULL");
            if (me || last_log != fmi2Error) violation("a co-simulation FMU instantiated as model exchange answered "
                                                       "%s, %s a log line at Error", me ? "an instance" : "NULL",
                                                       last_log == fmi2Error ? "with" : "without");
            return;
        }
        int s = which == 0 ? EnterEventMode3(c) : which == 1 ? EnterStepMode3(c) : which == 2 ? EnterConfigurationMode3(c)
              : which == 3 ? GetDirectionalDerivative3(c, &vr, 1, &vr, 1, &x, 1, &y, 1) : SetTime3(c, 0.0);
        check(s, ERROR);
        return;
    }
    begin(i, "%s", NAME2[which]);
    switch (which) {
    case 0: check(CancelStep(c), ERROR); break;
    case 1: check(SetRealInputDerivatives(c, &vr, 1, &order, &x), ERROR); break;
    case 2: check(GetRealOutputDerivatives(c, &vr, 1, &order, &x), ERROR); break;
    case 3: check(GetDirectionalDerivative(c, &vr, 1, &vr, 1, &x, &y), ERROR); break;
    case 4: check(SetTime(c, 0.0), ERROR); break;
    default: check(EnterEventMode(c), ERROR); break;
    }
}

/* ------------------------------------------------------------------ FMU states */
static void save(int i)
{
    int k = below(NSLOT);
    int null_pointer = chance(0.03);
    begin(i, "GetFMUstate(slot %d%s%s)", k, slot[k].s ? ", reused" : "", null_pointer ? ", NULL pointer" : "");
    int fresh = !slot[k].s;
    void **where = null_pointer ? NULL : &slot[k].s;
    if (check(v3 ? GetFMUState3(inst[i].c, where) : GetFMUstate(inst[i].c, where), null_pointer ? ERROR : OK) != fmi2OK)
        return;
    if (fresh) slot[k].owner = i;
    slot[k].m = inst[i].m;
    history_copy(&slot[k].h, &inst[i].h);
    slot[k].readable = readable(&inst[i].m);
    if (slot[k].readable) read_all(inst[i].c, slot[k].r);
}

static void restore(int i)
{
    int k = below(NSLOT);
    begin(i, "SetFMUstate(slot %d%s)", k, slot[k].s ? "" : ", NULL");
    int s = v3 ? SetFMUState3(inst[i].c, slot[k].s) : SetFMUstate(inst[i].c, slot[k].s);
    if (check(s, slot[k].s ? OK : ERROR) != fmi2OK) return;
    inst[i].m = slot[k].m;
    history_copy(&inst[i].h, &slot[k].h);
    if (slot[k].readable) {
        Reading now[MAXV];
        read_all(inst[i].c, now);
        compare(slot[k].r, now, "a restored FMU state", outputs_replay(&slot[k].m, &slot[k].h));
    }
}

static void serialize(int i)
{
    int k = below(NSLOT), b = below(NBLOB);
    size_t size = 0;
    begin(i, "SerializedFMUstateSize(slot %d%s)", k, slot[k].s ? "" : ", NULL");
    int s = v3 ? SerializedFMUStateSize3(inst[i].c, slot[k].s, &size)
               : SerializedFMUstateSize(inst[i].c, slot[k].s, &size);
    if (check(s, slot[k].s ? OK : OK | ERROR) != fmi2OK) return;
    int short_buffer = chance(0.1);
    size_t given = short_buffer && size ? size - 1 : size;
    unsigned char *data = malloc(size + 1);
    begin(i, "SerializeFMUstate(slot %d%s, %zu of %zu bytes)", k, slot[k].s ? "" : ", NULL", given, size);
    s = v3 ? SerializeFMUState3(inst[i].c, slot[k].s, data, given)
           : SerializeFMUstate(inst[i].c, slot[k].s, (fmi2Byte *)data, given);
    if (check(s, slot[k].s && !short_buffer ? OK : ERROR) != fmi2OK) {
        free(data);
        return;
    }
    free(blob[b].data);
    blob[b].data = data;
    blob[b].size = size;
    blob[b].m = slot[k].m;
    history_copy(&blob[b].h, &slot[k].h);
    blob[b].readable = slot[k].readable;
    memcpy(blob[b].r, slot[k].r, sizeof blob[b].r);
}

static void deserialize(int i)
{
    int b = below(NBLOB), k = below(NSLOT);
    if (!blob[b].data) return;
    size_t size = blob[b].size;
    unsigned char *data = malloc(size + 1);
    memcpy(data, blob[b].data, size);
    data[size] = (unsigned char)below(256);
    int how = below(8);   /* 0-3: intact; 4: a byte flipped; 5: truncated; 6: one byte more; 7: NULL */
    size_t at = 0;
    if (how == 4) {
        at = (size_t)below((int)size);
        data[at] ^= (unsigned char)(1 + below(255));
    }
    size_t given = how == 5 ? size - 1 : how == 6 ? size + 1 : how == 7 && chance(0.5) ? 0 : size;
    static const char *const HOW[] = {"intact", "intact", "intact", "intact", "a byte flipped", "truncated",
                                      "one byte more", "NULL"};
    begin(i, "DeSerializeFMUstate(blob %d %s%s%zu, %zu bytes, into slot %d%s)", b, HOW[how], how == 4 ? " at " : "",
          how == 4 ? at : 0, given, k, slot[k].s ? ", reused" : "");
    int fresh = !slot[k].s;
    const unsigned char *bytes = how == 7 ? NULL : data;
    int s = v3 ? DeserializeFMUState3(inst[i].c, bytes, given, &slot[k].s)
               : DeSerializeFMUstate(inst[i].c, (const fmi2Byte *)bytes, given, &slot[k].s);
    check(s, how < 4 ? OK : ERROR);
    free(data);
    if (s != fmi2OK) return;
    if (fresh) slot[k].owner = i;
    slot[k].m = blob[b].m;
    history_copy(&slot[k].h, &blob[b].h);
    slot[k].readable = blob[b].readable;
    memcpy(slot[k].r, blob[b].r, sizeof slot[k].r);
}

/* --------------------------------------------------- the pure-function check */
/* The instance's history replayed on a fresh instance: every call answers as it did,
   and every value reads the same, bit for bit. */
static void replay_check(int i)
{
    if (!inst[i].c || !readable(&inst[i].m)) return;
    begin(i, "(replay of %d calls on a fresh instance)", inst[i].h.n);
    void *c = fresh_instance("replay");
    if (!c) violation("a fresh instance could not be made");
    for (int k = 0; k < inst[i].h.n; k++) {
        const Op *op = &arena[inst[i].h.op[k]];
        int terminate_simulation;
        double last;
        int s = op->kind == OP_SETUP ? (int)SetupExperiment(c, fmi2False, 0, op->a, (fmi2Boolean)op->stop_defined, op->b)
              : op->kind == OP_ENTER ? api_enter(c, op->a, op->stop_defined, op->b)
              : op->kind == OP_EXIT ? (v3 ? (int)ExitInitializationMode3(c) : (int)ExitInitializationMode(c))
              : op->kind == OP_SET ? api_set(c, op->type, op->vr, op->n, op->values, op->nvalues)
              : op->kind == OP_STEP ? api_step(c, op->a, op->b, 0, &terminate_simulation, &last)
              : (v3 ? (int)Terminate3(c) : (int)Terminate(c));
        if (s != op->status)
            violation("replayed call %d of %d (kind %d) answered %s, first %s", k + 1, inst[i].h.n, op->kind,
                      status_name(s), status_name(op->status));
    }
    Reading a[MAXV], b[MAXV];
    read_all(inst[i].c, a);
    read_all(c, b);
    compare(a, b, "the replay on a fresh instance", outputs_replay(&inst[i].m, &inst[i].h));
    if (v3) FreeInstance3(c);
    else FreeInstance(c);
    printf("same\n");
}

/* ------------------------------------------------------------------------ main */
static void *sym(const char *name)
{
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "fuzz: missing symbol %s\n", name);
        exit(11);
    }
    return f;
}

/* One random call on instance i: mostly what the state leads to, the rest anything. */
static void one_call(int i)
{
    if (!inst[i].c) {
        instantiate(i);
        return;
    }
    const Model *m = &inst[i].m;
    int action = below(100);
    if (chance(0.6)) {   /* the sensible next call, so that runs get somewhere */
        if (m->st == S_INSTANTIATED) action = chance(0.5) ? 0 : 1;
        else if (m->st == S_INIT) action = chance(0.3) ? 2 : chance(0.7) ? 10 : 12;
        else if (m->st == S_STEP) action = chance(0.7) ? 20 : chance(0.5) ? 10 : 12;
    }
    int kind = chance(0.8) ? K_REAL : v3 && chance(0.5) ? K_INT64 : K_INT;
    if (action < 1) setup(i);
    else if (action < 2) enter(i);
    else if (action < 3) exit_init(i);
    else if (action < 5) terminate(i);
    else if (action < 6) reset(i);
    else if (action < 7) free_instance(i);
    else if (action < 12) set_values(i, kind);
    else if (action < 18) get_values(i, kind);
    else if (action < 19) other_types(i);
    else if (action < 30) step(i);
    else if (action < 34) status_query(i);
    else if (action < 36) logging(i);
    else if (action < 37) not_offered(i);
    else if (action < 42) save(i);
    else if (action < 46) restore(i);
    else if (action < 48) free_slot(i, below(NSLOT));
    else if (action < 51) serialize(i);
    else if (action < 54) deserialize(i);
    else if (action < 56) replay_check(i);
    else step(i);
}

int main(int argc, char **argv)
{
    if (argc < 7) {
        fprintf(stderr, "usage: %s UNZIPDIR MODEL_IDENTIFIER GUID SEED NCALLS VARS [3] [pythonfmu]\n", argv[0]);
        return 10;
    }
    for (int k = 7; k < argc; k++) {
        if (strcmp(argv[k], "3") == 0) v3 = 1;
        else if (strcmp(argv[k], "pythonfmu") == 0) pythonfmu = 1;
        else {
            fprintf(stderr, "fuzz: unknown option '%s'\n", argv[k]);
            return 10;
        }
    }
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/%s/%s.so", argv[1], v3 ? "x86_64-linux" : "linux64", argv[2]);
    snprintf(resources, sizeof resources, "file://%s/resources", argv[1]);
    snprintf(resource_path, sizeof resource_path, "%s/resources/", argv[1]);
    guid = argv[3];
    rng_state = strtoull(argv[4], NULL, 10);
    long ncalls = atol(argv[5]);
    parse_vars(argv[6]);
    lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "fuzz: dlopen %s: %s\n", path, dlerror());
        return 11;
    }
    if (!v3) {
#define LOAD2(name) name = (fmi2##name##TYPE *)(pythonfmu && (!strcmp(#name, "SetTime") || !strcmp(#name, "EnterEventMode")) \
                                                  ? dlsym(lib, "fmi2" #name) : sym("fmi2" #name));
        FMI2_CALLS(LOAD2)
        if (strcmp(GetVersion(), "2.0") != 0 || strcmp(GetTypesPlatform(), "default") != 0)
            violation("fmi2GetVersion '%s', fmi2GetTypesPlatform '%s'", GetVersion(), GetTypesPlatform());
    } else {
#define LOAD3(name) name##3 = (fmi3##name##TYPE *)sym("fmi3" #name);
        FMI3_CALLS(LOAD3)
        if (strcmp(GetVersion3(), "3.0") != 0) violation("fmi3GetVersion '%s'", GetVersion3());
    }
    start_model.st = S_INSTANTIATED;
    for (int k = 0; k < nvars; k++) start_model.value[k] = vars[k].start;
    while (call_no < ncalls) {
        int i = chance(0.8) ? 0 : 1;
        one_call(i);
    }
    for (int i = 0; i < NINST; i++) replay_check(i);
    for (int i = 0; i < NINST; i++)
        if (inst[i].c) free_instance(i);
    for (int k = 0; k < NSLOT; k++)   /* states whose instance was freed went with it */
        if (slot[k].s) violation("slot %d outlived its instance", k);
    for (int b = 0; b < NBLOB; b++) free(blob[b].data);
    for (int k = 0; k < narena; k++) free(arena[k].vr), free(arena[k].values);
    free(arena);
    for (int i = 0; i < NINST; i++) free(inst[i].h.op);
    for (int k = 0; k < NSLOT; k++) free(slot[k].h.op);
    for (int b = 0; b < NBLOB; b++) free(blob[b].h.op);
    printf("fuzz ok: %ld calls, %ld OK, %ld Discard, %ld Error\n", call_no, answered[fmi2OK], answered[fmi2Discard],
           answered[fmi2Error]);
    return 0;
}
