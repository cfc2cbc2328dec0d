/* A shim in front of pythonfmu 0.7.0's C wrapper: binaries/linux64/<id>.so of each of
 * our pythonfmu FMUs (fmu_src/builder.py compiles this file with the machine's cc
 * against fmpy's FMI 2 headers and renames pythonfmu's wrapper <id>.pythonfmu.so).
 *
 * Why: the wrapper turns every Python exception into fmi2Fatal, so a failed
 * initialization (a parameter outside its range, a NaN input) reaches the host as
 * fmi2Fatal, where FMI 2 asks for fmi2Error: the instance is still there to be freed
 * (issue 10). And it finalizes its embedded Python from a global destructor, which a C
 * host runs at exit() after the destructors of the libraries Python loaded later
 * (numpy, scipy's C++ and Fortran runtimes): a crash after main returns
 * (docs/fmi-notes-measured.md).
 *
 * What it does:
 * - fmi2Instantiate dlopens the wrapper (RTLD_NOW | RTLD_LOCAL) from beside this
 *   library (its own path from dladdr) and forwards every FMI 2 function of
 *   fmi2Functions.h the wrapper exports (common and co-simulation: the FUNCTIONS
 *   table), each to the wrapper's own, with the wrapper's component inside ours.
 * - The host's logger is called through ours (same text with '%' doubled, same status). During
 *   fmi2ExitInitializationMode the messages are held until the call returns: if the
 *   wrapper answered fmi2Fatal and the slave had logged an fmi2Error during the call
 *   (GuardedSlave (fmu_src/slave.py) does so before it raises, and keeps the
 *   instance alive for later doStep/terminate/free), the call answers fmi2Error and
 *   the wrapper's own fatal line is dropped: it says only "Fatal py exception
 *   encountered: [exitInitializationMode] PyObject_CallMethod unknown error", against
 *   the status, after the slave's line has said what is wrong. A fatal without the
 *   slave's error (an exception our slave did not catch) stays fmi2Fatal, its
 *   messages delivered as they came.
 * - fmi2GetReal answers fmi2Error when the slave logged an fmi2Error during the call:
 *   GuardedSlave.get_real names an output that is not finite (those a refused
 *   initialization left; the native layer's rule).
 * - fmi2SetupExperiment refuses a stopTime before the startTime; fmi2DoStep refuses,
 *   with fmi2Error and a line, a step whose start is not the FMU's time, of a size not
 *   finite and > 0, too small to advance the time, or ending past the stopTime (the
 *   native layer's rules, fmi2_layer.c).
 * - fmi2DeSerializeFMUstate: bytes that are not a state this FMU serialized (header
 *   line and checksum, GuardedSlave._fmu_state_to_bytes) are refused with fmi2Error and
 *   a log line before the wrapper sees them.
 *   fmi2SetupExperiment (past its stopTime check) and fmi2EnterInitializationMode are forwarded unchanged:
 *   GuardedSlave's methods there only record values (the start time, that
 *   initialization mode began), so a fatal there is one no slave code guarded, and
 *   fmi2Fatal is then the truth. fmi2GetReal/fmi2GetInteger in initialization mode may
 *   run the slave's initialize(); GuardedSlave catches whatever it raises.
 * - After each fmi2Instantiate, fmi2Terminate and before each fmi2FreeInstance, if
 *   libraries were loaded since the last time, the wrapper's exported
 *   finalizePythonInterpreter is registered to run at exit (handlers run
 *   last-registered first, so before those libraries' destructors). It releases the
 *   wrapper's reference to its Python state: Python is finalized then if no instance
 *   is left, and only if the wrapper started it (in a Python host, e.g. fmpy, it did
 *   not, and the call does nothing). This library is made unloadable (RTLD_NODELETE,
 *   as the wrapper already is: it has STB_GNU_UNIQUE symbols) so the handler
 *   registered from here is still mapped at exit after a host's dlclose.
 * The model-exchange functions are not exported (pythonfmu FMUs are co-simulation
 * only). Windows (binaries/win64) keeps pythonfmu's DLL as it is.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <link.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "native/crc32.h"

/* X(name, states, parameters, arguments): every function forwarded as is when called in
 * one of `states` (FMI 2.0 call sequence, allowed()); INNER is the wrapper's component
 * inside ours. */
#define INNER (((Shim *)c)->inner)
#define FORWARDED(X) \
    X(fmi2SetDebugLogging, ANY_PHASE, (fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[]), \
      (INNER, on, n, categories)) \
    X(fmi2GetInteger, READABLE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]), (INNER, vr, n, v)) \
    X(fmi2GetBoolean, READABLE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]), (INNER, vr, n, v)) \
    X(fmi2GetString, READABLE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]), (INNER, vr, n, v)) \
    X(fmi2SetReal, SETTABLE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]), (INNER, vr, n, v)) \
    X(fmi2SetInteger, SETTABLE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]), \
      (INNER, vr, n, v)) \
    X(fmi2SetBoolean, SETTABLE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]), \
      (INNER, vr, n, v)) \
    X(fmi2SetString, SETTABLE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]), \
      (INNER, vr, n, v)) \
    X(fmi2GetFMUstate, ANY_PHASE, (fmi2Component c, fmi2FMUstate *state), (INNER, state)) \
    X(fmi2FreeFMUstate, ANY_PHASE, (fmi2Component c, fmi2FMUstate *state), (INNER, state)) \
    X(fmi2SerializedFMUstateSize, ANY_PHASE, (fmi2Component c, fmi2FMUstate state, size_t *size), (INNER, state, size)) \
    X(fmi2SerializeFMUstate, ANY_PHASE, (fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size), \
      (INNER, state, bytes, size)) \
    X(fmi2GetDirectionalDerivative, ANY_PHASE, (fmi2Component c, const fmi2ValueReference unknown[], size_t n_unknown, \
                                     const fmi2ValueReference known[], size_t n_known, const fmi2Real dv_known[], \
                                     fmi2Real dv_unknown[]), \
      (INNER, unknown, n_unknown, known, n_known, dv_known, dv_unknown)) \
    X(fmi2SetRealInputDerivatives, ANY_PHASE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, \
                                    const fmi2Integer order[], const fmi2Real v[]), (INNER, vr, n, order, v)) \
    X(fmi2GetRealOutputDerivatives, ANY_PHASE, (fmi2Component c, const fmi2ValueReference vr[], size_t n, \
                                     const fmi2Integer order[], fmi2Real v[]), (INNER, vr, n, order, v)) \
    X(fmi2CancelStep, ANY_PHASE, (fmi2Component c), (INNER)) \
    X(fmi2GetStatus, STATUS, (fmi2Component c, const fmi2StatusKind kind, fmi2Status *v), (INNER, kind, v)) \
    X(fmi2GetIntegerStatus, STATUS, (fmi2Component c, const fmi2StatusKind kind, fmi2Integer *v), (INNER, kind, v)) \
    X(fmi2GetBooleanStatus, STATUS, (fmi2Component c, const fmi2StatusKind kind, fmi2Boolean *v), (INNER, kind, v)) \
    X(fmi2GetStringStatus, STATUS, (fmi2Component c, const fmi2StatusKind kind, fmi2String *v), (INNER, kind, v))

/* The functions this file defines itself (they do more than forward). */
#define OWN(Y) Y(fmi2GetTypesPlatform) Y(fmi2GetVersion) Y(fmi2Instantiate) Y(fmi2FreeInstance) \
    Y(fmi2SetupExperiment) Y(fmi2EnterInitializationMode) Y(fmi2ExitInitializationMode) Y(fmi2Reset) \
    Y(fmi2SetFMUstate) Y(fmi2DeSerializeFMUstate) Y(fmi2Terminate) Y(fmi2DoStep) Y(fmi2GetRealStatus) Y(fmi2GetReal)

/* The wrapper's functions, found by dlsym at the first fmi2Instantiate. */
#define MEMBER(name, ...) name##TYPE *name;
#define OWN_MEMBER(name) name##TYPE *name;
static struct {
    FORWARDED(MEMBER)
    OWN(OWN_MEMBER)
    void (*finalize)(void);   /* finalizePythonInterpreter */
} wrapper;

#define ENTRY(name, ...) {#name, (void **)&wrapper.name},
#define OWN_ENTRY(name) {#name, (void **)&wrapper.name},
static const struct { const char *name; void **slot; } SYMBOLS[] = {FORWARDED(ENTRY) OWN(OWN_ENTRY)};

typedef struct { fmi2Status status; char *category, *text; } Held;

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions host;      /* the host's callbacks */
    fmi2CallbackFunctions callbacks; /* given to the wrapper: ours, with this Shim as environment */
    int holding;                     /* messages are held (during fmi2ExitInitializationMode, fmi2GetReal) */
    int slave_error;                 /* an fmi2Error message arrived while holding */
    Held *held;
    size_t n_held, max_held;
    char *name;
    int stepped;                     /* a doStep was accepted: last_ok holds its end */
    fmi2Real last_ok;
    int phase;                       /* enum phase */
    int failed;                      /* a doStep answered Discard or the initialization failed */
    fmi2Real time;                   /* where the next doStep starts; NaN after fmi2SetFMUstate */
    int stop_defined;                /* fmi2SetupExperiment's stopTime: no step may pass it */
    fmi2Real stop;
} Shim;

/* FMI 2.0 states, as fmu_src/native/fmi2_layer.c keeps them (bits for the masks). */
enum phase { INSTANTIATED = 1, INITIALIZATION = 2, STEPPING = 4, TERMINATED = 8 };
#define ANY_PHASE (INSTANTIATED | INITIALIZATION | STEPPING | TERMINATED)
#define READABLE (INITIALIZATION | STEPPING | TERMINATED)
#define SETTABLE (INSTANTIATED | INITIALIZATION | STEPPING)
#define STATUS (STEPPING | TERMINATED)

static pthread_once_t load_once = PTHREAD_ONCE_INIT;
static char load_error[4200];   /* empty once the wrapper is loaded */
static char model_id[256];   /* <id> of binaries/linux64/<id>.so: the slave's class name */

/* dlopen the wrapper <this library's name without .so>.pythonfmu.so beside this one. */
static void load(void) {
    Dl_info self;
    char path[4096];
    if (!dladdr((void *)&load, &self) || !self.dli_fname) {
        snprintf(load_error, sizeof load_error, "pythonfmu shim: dladdr cannot name its own library");
        return;
    }
    size_t n = strlen(self.dli_fname);
    if (n < 3 || strcmp(self.dli_fname + n - 3, ".so") || n + 20 > sizeof path) {
        snprintf(load_error, sizeof load_error, "pythonfmu shim: unexpected library name %s", self.dli_fname);
        return;
    }
    snprintf(path, sizeof path, "%.*s.pythonfmu.so", (int)(n - 3), self.dli_fname);
    const char *base = strrchr(self.dli_fname, '/');
    base = base ? base + 1 : self.dli_fname;
    snprintf(model_id, sizeof model_id, "%.*s", (int)(strlen(base) - 3), base);
    dlopen(self.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);   /* see the header: never unloaded */
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(load_error, sizeof load_error, "pythonfmu shim: dlopen %s: %s", path, dlerror());
        return;
    }
    for (size_t i = 0; i < sizeof SYMBOLS / sizeof SYMBOLS[0]; i++) {
        *SYMBOLS[i].slot = dlsym(lib, SYMBOLS[i].name);
        if (!*SYMBOLS[i].slot) {
            snprintf(load_error, sizeof load_error, "pythonfmu shim: %s has no %s", path, SYMBOLS[i].name);
            return;
        }
    }
    *(void **)&wrapper.finalize = dlsym(lib, "finalizePythonInterpreter");   /* optional */
    load_error[0] = '\0';
}

static int loaded(void) {
    if (pthread_once(&load_once, load) != 0) return 0;
    return load_error[0] == '\0' && wrapper.fmi2Instantiate != NULL;
}

/* ------------------------------------------------------------------ exit handler */
extern int __cxa_atexit(void (*function)(void *), void *argument, void *dso);   /* glibc */
static pthread_mutex_t finalizer_lock = PTHREAD_MUTEX_INITIALIZER;
static unsigned long long registered_at = 0;   /* libraries loaded so far when last registered */

static int count_loads(struct dl_phdr_info *info, size_t size, void *data) {
    (void)size;
    *(unsigned long long *)data = info->dlpi_adds;
    return 1;   /* the counter is the same in every entry: the first one is enough */
}

static void finalize_python(void *unused) {
    (void)unused;
    wrapper.finalize();
}

/* Register finalize_python to run at exit, before the destructors of every library
 * loaded so far; again only if more were loaded since. */
static void finalize_before_exit(void) {
    static unsigned long long loads;   /* under finalizer_lock */
    if (!wrapper.finalize) return;
    pthread_mutex_lock(&finalizer_lock);
    dl_iterate_phdr(count_loads, &loads);
    if (loads != registered_at && __cxa_atexit(finalize_python, NULL, NULL) == 0) registered_at = loads;
    pthread_mutex_unlock(&finalizer_lock);
}

/* ---------------------------------------------------------------------- logging */
/* The host's logger takes a printf format (FMI 2.0). The wrapper passes each message as
 * the format, with no arguments, and a message may hold host strings (a GUID, a category,
 * an instance name with "%s" crashed the host): every '%' is doubled, so a host that
 * formats prints the text, and one that reads the format as the text (a ctypes logger)
 * sees it unchanged unless it held a '%'. */
static void log_text(const fmi2CallbackFunctions *host, const char *name, fmi2Status status, const char *category,
                     const char *text) {
    if (!host->logger) return;
    size_t n = 0, percents = 0;
    for (const char *p = text; *p; p++) percents += *p == '%';
    char *escaped = malloc(strlen(text) + percents + 1);
    if (!escaped) return;
    for (const char *p = text; *p; p++) {
        if (*p == '%') escaped[n++] = '%';
        escaped[n++] = *p;
    }
    escaped[n] = '\0';
    host->logger(host->componentEnvironment, name, status, category, escaped);
    free(escaped);
}

static void deliver(Shim *s, fmi2Status status, const char *category, const char *text) {
    log_text(&s->host, s->name, status, category, text);
}

/* Keep a copy of a message until release(); 0 if out of memory. */
static int hold(Shim *s, fmi2Status status, const char *category, const char *text) {
    if (s->n_held == s->max_held) {
        size_t more = 2 * s->max_held + 4;
        Held *held = realloc(s->held, more * sizeof *held);
        if (!held) return 0;
        s->held = held;
        s->max_held = more;
    }
    char *category_copy = strdup(category), *text_copy = strdup(text);
    if (!category_copy || !text_copy) {
        free(category_copy);
        free(text_copy);
        return 0;
    }
    s->held[s->n_held++] = (Held){status, category_copy, text_copy};
    return 1;
}

/* The wrapper's messages: passed on, or held during fmi2ExitInitializationMode. */
static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    Shim *s = env;
    (void)instance;
    if (!message) return;
    if (!category) category = "";
    if (s->holding && status == fmi2Error) s->slave_error = 1;
    if (!(s->holding && hold(s, status, category, message))) deliver(s, status, category, message);
}

/* Deliver the held messages; with ``drop_fatal``, not the wrapper's fatal ones. */
static void release(Shim *s, int drop_fatal) {
    s->holding = 0;
    for (size_t i = 0; i < s->n_held; i++) {
        Held *m = &s->held[i];
        if (!(drop_fatal && m->status == fmi2Fatal)) deliver(s, m->status, m->category, m->text);
        free(m->category);
        free(m->text);
    }
    s->n_held = 0;
}

static void step_finished(fmi2ComponentEnvironment env, fmi2Status status) {
    Shim *s = env;
    s->host.stepFinished(s->host.componentEnvironment, status);
}

/* -------------------------------------------------------------------- functions */
/* May `function` be called now (FMI 2.0 call sequence, the native layer's rules)? Else an
   error line and 0. Nothing is set in the failed state. */
static int allowed(fmi2Component c, int states, const char *function) {
    Shim *s = c;
    if (!s) return 0;
    int setting = states == SETTABLE && s->phase == STEPPING && s->failed;
    if ((s->phase & states) && !setting) return 1;
    char text[200];
    snprintf(text, sizeof text, "%s: not allowed in %s (FMI 2.0 call sequence)", function,
             s->phase == INSTANTIATED ? "the instantiated state (before fmi2EnterInitializationMode)"
             : s->phase == INITIALIZATION ? "initialization mode"
             : s->phase == TERMINATED ? "the terminated state"
             : s->failed ? "the failed state (after a Discard or a failed initialization)" : "step mode");
    deliver(s, fmi2Error, "logStatusError", text);
    return 0;
}

#define DEFINE(name, states, parameters, arguments) \
    fmi2Status name parameters { return allowed(c, states, #name) ? wrapper.name arguments : fmi2Error; }
FORWARDED(DEFINE)

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolerance_defined, fmi2Real tolerance, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop) {
    Shim *s = c;
    if (!allowed(c, INSTANTIATED, "fmi2SetupExperiment")) return fmi2Error;
    if (stop_defined && !(stop >= start)) {   /* the native layer's rule (fmi2_layer.c fmi2SetupExperiment) */
        char text[200];
        snprintf(text, sizeof text, "fmi2SetupExperiment: stopTime %.17g s is before startTime %.17g s", stop, start);
        deliver(s, fmi2Error, "logStatusError", text);
        return fmi2Error;
    }
    fmi2Status status = wrapper.fmi2SetupExperiment(INNER, tolerance_defined, tolerance, start, stop_defined, stop);
    if (status <= fmi2Warning) {
        s->time = start;
        s->stop_defined = stop_defined != fmi2False;
        s->stop = stop;
    }
    return status;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    if (!allowed(c, INSTANTIATED, "fmi2EnterInitializationMode")) return fmi2Error;
    fmi2Status status = wrapper.fmi2EnterInitializationMode(INNER);
    if (status <= fmi2Warning) ((Shim *)c)->phase = INITIALIZATION;
    return status;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Shim *s = c;
    if (!allowed(c, ANY_PHASE, "fmi2Reset")) return fmi2Error;
    fmi2Status status = wrapper.fmi2Reset(s->inner);
    if (status <= fmi2Warning) {
        s->phase = INSTANTIATED;
        s->failed = s->stepped = s->stop_defined = 0;
        s->time = 0.0;
    }
    return status;
}

/* The state's time is the slave's: the shim does not know it, so the next doStep's start
   is not checked (its end is known again after it). */
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    Shim *s = c;
    if (!allowed(c, ANY_PHASE, "fmi2SetFMUstate")) return fmi2Error;
    fmi2Status status = wrapper.fmi2SetFMUstate(s->inner, state);
    if (status <= fmi2Warning && s->phase & (STEPPING | TERMINATED)) {
        s->phase = STEPPING;
        s->failed = 0;
        s->time = NAN;
    }
    return status;
}

const char *fmi2GetTypesPlatform(void) {
    return loaded() ? wrapper.fmi2GetTypesPlatform() : fmi2TypesPlatform;
}

const char *fmi2GetVersion(void) {
    return loaded() ? wrapper.fmi2GetVersion() : fmi2Version;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean logging) {
    if (!functions) return NULL;
    if (!loaded()) {
        log_text(functions, name, fmi2Fatal, "logStatusFatal", load_error[0] ? load_error : "pythonfmu shim: not loaded");
        return NULL;
    }
    if (!resources || strncmp(resources, "file:", 5) != 0) {   /* the wrapper would crash finding no slave */
        char text[400];
        snprintf(text, sizeof text, "fmi2Instantiate: fmuResourceLocation '%.200s' is not a file: URI of the FMU's "
                 "resources folder, where the Python slave lives", resources ? resources : "(null)");
        log_text(functions, name, fmi2Error, "logStatusError", text);
        return NULL;
    }
    Shim *s = calloc(1, sizeof *s);
    if (!s || !(s->name = strdup(name ? name : ""))) {
        free(s);
        return NULL;
    }
    s->host = *functions;
    s->phase = INSTANTIATED;
    s->callbacks = (fmi2CallbackFunctions){logger, functions->allocateMemory, functions->freeMemory,
                                           functions->stepFinished ? step_finished : NULL, s};
    s->inner = wrapper.fmi2Instantiate(name, type, guid, resources, &s->callbacks, visible, logging);
    finalize_before_exit();
    if (!s->inner) {
        free(s->name);
        free(s);
        return NULL;
    }
    return s;
}

void fmi2FreeInstance(fmi2Component c) {
    Shim *s = c;
    if (!s) return;
    finalize_before_exit();
    wrapper.fmi2FreeInstance(s->inner);
    free(s->held);
    free(s->name);
    free(s);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Shim *s = c;
    if (!allowed(c, INITIALIZATION, "fmi2ExitInitializationMode")) return fmi2Error;
    s->phase = STEPPING;   /* a failed instance too: it refuses doStep with Discard, as the native ones */
    s->holding = 1;
    s->slave_error = 0;
    fmi2Status status = wrapper.fmi2ExitInitializationMode(s->inner);
    int as_error = status == fmi2Fatal && s->slave_error;
    s->failed = status > fmi2Warning;
    release(s, as_error);
    return as_error ? fmi2Error : status;
}

/* Why bytes are not a state this FMU serialized (GuardedSlave._fmu_state_to_bytes: the
   line "movingbase-state <id> <crc32 of the rest, 8 hex digits>" and the JSON), or NULL. */
static const char *foreign(const fmi2Byte *bytes, size_t size) {
    static const char magic[] = "movingbase-state ";
    size_t m = sizeof magic - 1, id = strlen(model_id);
    if (!bytes || size < m + id + 10 || memcmp(bytes, magic, m) != 0) return "no movingbase state header";
    if (memcmp(bytes + m, model_id, id) != 0 || bytes[m + id] != ' ') return "a state of another FMU";
    const char *hex = bytes + m + id + 1;
    char digits[9];
    memcpy(digits, hex, 8);
    digits[8] = '\0';
    char *end;
    unsigned long crc = strtoul(digits, &end, 16);
    if (end != digits + 8 || hex[8] != '\n') return "a damaged header";
    size_t head = m + id + 10;
    if (mb_crc32(bytes + head, size - head) != crc) return "its checksum does not match";
    return NULL;
}

/* Bytes that are not a state of this FMU are refused here, with fmi2Error and a log line:
   given to the wrapper, GuardedSlave could only raise, which the wrapper answers with
   fmi2Fatal after dropping references to the instance, its class and its log queue (a
   crash later, as after a failed initialization). */
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    Shim *s = c;
    const char *why = foreign(bytes, size);
    if (why) {
        char text[256];
        snprintf(text, sizeof text, "fmi2DeSerializeFMUstate: the %zu bytes are not a serialized state of %s (%s)",
                 size, model_id, why);
        deliver(s, fmi2Error, "logStatusError", text);
        return fmi2Error;
    }
    return wrapper.fmi2DeSerializeFMUstate(s->inner, bytes, size, state);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    if (!allowed(c, STEPPING, "fmi2Terminate")) return fmi2Error;
    ((Shim *)c)->phase = TERMINATED;
    fmi2Status status = wrapper.fmi2Terminate(INNER);
    finalize_before_exit();
    return status;
}

/* An output that is not finite (those a refused initialization left) answers fmi2Error:
   GuardedSlave.get_real logs the line naming it, the values come back as they are. */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    Shim *s = c;
    if (!allowed(c, READABLE, "fmi2GetReal")) return fmi2Error;
    s->holding = 1;
    s->slave_error = 0;
    fmi2Status status = wrapper.fmi2GetReal(s->inner, vr, n, v);
    release(s, 0);
    return status <= fmi2Warning && s->slave_error ? fmi2Error : status;
}

/* fmi2LastSuccessfulTime: the end of the last accepted step. The wrapper answers the start
   of the latest doStep, which moves on with every refused step a host keeps sending. */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior) {
    Shim *s = c;
    if (!allowed(c, STEPPING, "fmi2DoStep")) return fmi2Error;
    char text[200];
    text[0] = '\0';
    if (s->failed) {
        /* the slave refuses it with Discard, saying after what */
    } else if (!(isfinite(h) && h > 0)) {
        snprintf(text, sizeof text, "fmi2DoStep: the communication step size must be finite and > 0, got %.17g s", h);
    } else if (!isnan(s->time) && !(fabs(t - s->time) <= 1e-9 * (fabs(s->time) > 1.0 ? fabs(s->time) : 1.0))) {
        snprintf(text, sizeof text, "fmi2DoStep: currentCommunicationPoint %.17g s is not the FMU's time %.17g s "
                 "(the end of the last accepted step)", t, s->time);
    } else if (t + h == t) {
        snprintf(text, sizeof text, "fmi2DoStep: a step of %.17g s does not advance the time %.17g s "
                 "(below its resolution)", h, t);
    } else if (s->stop_defined && t + h > s->stop + 1e-9 * (fabs(s->stop) > 1.0 ? fabs(s->stop) : 1.0)) {
        snprintf(text, sizeof text, "fmi2DoStep: the step to t=%.17g s passes the experiment's stopTime "
                 "%.17g s", t + h, s->stop);
    }
    if (text[0]) {   /* the native layer's rules (fmi2_layer.c fmi2DoStep) */
        deliver(s, fmi2Error, "logStatusError", text);
        return fmi2Error;
    }
    fmi2Status status = wrapper.fmi2DoStep(s->inner, t, h, no_set_prior);
    if (status == fmi2OK || status == fmi2Warning) {
        s->stepped = 1;
        s->last_ok = s->time = t + h;
    } else {
        s->failed = 1;
    }
    return status;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real *v) {
    Shim *s = c;
    if (!allowed(c, STATUS, "fmi2GetRealStatus")) return fmi2Error;
    if (kind == fmi2LastSuccessfulTime && s->stepped) {
        *v = s->last_ok;
        return fmi2OK;
    }
    return wrapper.fmi2GetRealStatus(s->inner, kind, v);
}
