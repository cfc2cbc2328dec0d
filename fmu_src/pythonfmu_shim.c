/* A shim in front of pythonfmu 0.7.0's C wrapper: binaries/linux64/<id>.so of each of
 * our pythonfmu FMUs (fmu_src/python_build.py compiles this file with the machine's cc
 * against fmpy's FMI 2 headers and renames pythonfmu's wrapper <id>.pythonfmu.so).
 *
 * Why: the wrapper turns every Python exception into fmi2Fatal, so a failed
 * initialization (a parameter outside its range, a NaN input) reaches the host as
 * fmi2Fatal, where FMI 2 asks for fmi2Error: the instance is still there to be freed
 * (docs/fmu-rules.md). And it finalizes its embedded Python from a global destructor, which a C
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
 * - The getters and setters (VALUES) answer fmi2Error when the slave logged an fmi2Error
 *   during the call: GuardedSlave refuses, before it sets anything, a value reference
 *   that is not a variable of the type, an output, a parameter after initialization, and
 *   GuardedSlave.get_real names an output that is not finite (those a refused
 *   initialization left; the native layer's rules). A NULL array with a count is refused
 *   here. fmi2Instantiate refuses model exchange and gives the wrapper an ASCII name.
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
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "native/crc32.h"

/* Y(name, states, value type): the getters and setters, forwarded when allowed() and both
 * arrays are given, with the slave's messages held: one at fmi2Error (GuardedSlave names a
 * value reference that is not a variable of the type, an output set, a parameter set after
 * initialization, an output not finite) makes the call answer fmi2Error. */
#define VALUES(Y) Y(fmi2GetReal, READABLE, fmi2Real) Y(fmi2GetInteger, READABLE, fmi2Integer) \
    Y(fmi2GetBoolean, READABLE, fmi2Boolean) Y(fmi2GetString, READABLE, fmi2String) \
    Y(fmi2SetReal, SETTABLE, const fmi2Real) Y(fmi2SetInteger, SETTABLE, const fmi2Integer) \
    Y(fmi2SetBoolean, SETTABLE, const fmi2Boolean) Y(fmi2SetString, SETTABLE, const fmi2String)

/* The functions this file defines itself (they do more than forward). */
#define OWN(Y) Y(fmi2GetTypesPlatform) Y(fmi2GetVersion) Y(fmi2Instantiate) Y(fmi2FreeInstance) Y(fmi2SetDebugLogging) \
    Y(fmi2SetupExperiment) Y(fmi2EnterInitializationMode) Y(fmi2ExitInitializationMode) Y(fmi2Reset) \
    Y(fmi2SetFMUstate) Y(fmi2DeSerializeFMUstate) Y(fmi2Terminate) Y(fmi2DoStep) \
    Y(fmi2GetFMUstate) Y(fmi2FreeFMUstate) Y(fmi2SerializedFMUstateSize) Y(fmi2SerializeFMUstate)

/* The wrapper's functions, found by dlsym at the first fmi2Instantiate. */
#define MEMBER(name, ...) name##TYPE *name;
#define OWN_MEMBER(name) name##TYPE *name;
static struct {
    VALUES(MEMBER)
    OWN(OWN_MEMBER)
    void (*finalize)(void);   /* finalizePythonInterpreter */
} wrapper;

#define ENTRY(name, ...) {#name, (void **)&wrapper.name},
#define OWN_ENTRY(name) {#name, (void **)&wrapper.name},
static const struct { const char *name; void **slot; } SYMBOLS[] = {VALUES(ENTRY) OWN(OWN_ENTRY)};

typedef struct { fmi2Status status; char *category, *text; } Held;

/* What the shim knows of an instance beyond the slave: saved and restored with every FMU
   state (and serialized after the slave's bytes), as the native layer's block holds its
   phase, so a restored state steps from its own time in its own phase. */
typedef struct {
    int32_t phase;          /* enum phase */
    int32_t failed;         /* a doStep answered Discard or the initialization failed */
    int32_t stop_defined;   /* fmi2SetupExperiment's stopTime: no step may pass it */
    int32_t unused;         /* zero: no padding byte is left undefined in a serialized state */
    fmi2Real time;          /* the start time, then the end of the last accepted step */
    fmi2Real stop;
} Book;

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions host;      /* the host's callbacks */
    fmi2CallbackFunctions callbacks; /* given to the wrapper: ours, with this Shim as environment */
    int holding;                     /* messages are held (fmi2ExitInitializationMode, VALUES) */
    int slave_error;                 /* an fmi2Error message arrived while holding */
    Held *held;
    size_t n_held, max_held;
    char *name;
    int category_on[5];              /* CATEGORIES, as the host set them */
    Book b;
} Shim;

/* pythonfmu's log categories (Fmi2Slave.log_categories), as the native layer's. */
static const char *const CATEGORIES[] = {"logStatusWarning", "logStatusDiscard", "logStatusError", "logStatusFatal",
                                         "logAll"};
enum { NCAT = sizeof CATEGORIES / sizeof CATEGORIES[0], CAT_ALL = NCAT - 1 };

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

/* A line at Discard or worse always reaches the host (it explains the status the call
   answers); one below only when the host turned its category (or logAll) on: the native
   layer's rule (fmi2_layer.c emit). The wrapper logs only with its logging on, so it is
   instantiated with it on and the shim filters. */
static void deliver(Shim *s, fmi2Status status, const char *category, const char *text) {
    int on = s->category_on[CAT_ALL];
    for (int k = 0; k < CAT_ALL; k++) on |= s->category_on[k] && strcmp(category, CATEGORIES[k]) == 0;
    if (status >= fmi2Discard || on) log_text(&s->host, s->name, status, category, text);
}

/* An fmi2Error with its line. */
static fmi2Status refuse(fmi2Component c, const char *text) {
    deliver(c, fmi2Error, "logStatusError", text);
    return fmi2Error;
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
    int setting = states == SETTABLE && s->b.phase == STEPPING && s->b.failed;
    if ((s->b.phase & states) && !setting) return 1;
    char text[200];
    snprintf(text, sizeof text, "%s: not allowed in %s (FMI 2.0 call sequence)", function,
             s->b.phase == INSTANTIATED ? "the instantiated state (before fmi2EnterInitializationMode)"
             : s->b.phase == INITIALIZATION ? "initialization mode"
             : s->b.phase == TERMINATED ? "the terminated state"
             : s->b.failed ? "the failed state (after a Discard or a failed initialization)" : "step mode");
    deliver(s, fmi2Error, "logStatusError", text);
    return 0;
}

/* What these FMUs do not offer (canInterpolateInputs, maxOutputDerivativeOrder,
   providesDirectionalDerivative false; doStep never pending): fmi2Error with a line (the
   wrapper answered fmi2Error without one). */
fmi2Status fmi2CancelStep(fmi2Component c) {
    return refuse(c, "fmi2CancelStep: fmi2DoStep never returns fmi2Pending, nothing to cancel");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real v[]) {
    (void)vr, (void)n, (void)order, (void)v;
    return refuse(c, "fmi2SetRealInputDerivatives: canInterpolateInputs is false");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real v[]) {
    (void)vr, (void)n, (void)order, (void)v;
    return refuse(c, "fmi2GetRealOutputDerivatives: maxOutputDerivativeOrder is 0");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknown[], size_t n_unknown,
                                        const fmi2ValueReference known[], size_t n_known, const fmi2Real dv_known[],
                                        fmi2Real dv_unknown[]) {
    (void)unknown, (void)n_unknown, (void)known, (void)n_known, (void)dv_known, (void)dv_unknown;
    return refuse(c, "fmi2GetDirectionalDerivative: providesDirectionalDerivative is false");
}

/* The categories are the shim's to filter (deliver); the wrapper keeps its logging on. */
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[]) {
    Shim *s = c;
    if (!allowed(c, ANY_PHASE, "fmi2SetDebugLogging")) return fmi2Error;
    if (n && !categories) return refuse(c, "fmi2SetDebugLogging: categories is NULL");
    int set[NCAT] = {0};
    for (size_t k = 0; k < n; k++) {
        int found = 0;
        for (int j = 0; j < NCAT; j++)
            if (categories[k] && strcmp(categories[k], CATEGORIES[j]) == 0) set[j] = found = 1;
        if (!found) {
            char text[300];
            snprintf(text, sizeof text, "fmi2SetDebugLogging: unknown log category '%.200s'",
                     categories[k] ? categories[k] : "(null)");
            return refuse(c, text);
        }
    }
    for (int j = 0; j < NCAT; j++)
        if (!n || set[j]) s->category_on[j] = on != fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolerance_defined, fmi2Real tolerance, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop) {
    Shim *s = c;
    if (!allowed(c, INSTANTIATED, "fmi2SetupExperiment")) return fmi2Error;
    if (!isfinite(start) || (stop_defined && !(stop >= start))) {   /* the native layer's rules (fmi2_layer.c) */
        char text[200];
        if (!isfinite(start)) snprintf(text, sizeof text, "fmi2SetupExperiment: startTime %.17g s is not finite", start);
        else snprintf(text, sizeof text, "fmi2SetupExperiment: stopTime %.17g s is before startTime %.17g s", stop, start);
        deliver(s, fmi2Error, "logStatusError", text);
        return fmi2Error;
    }
    fmi2Status status = wrapper.fmi2SetupExperiment(s->inner, tolerance_defined, tolerance, start, stop_defined, stop);
    if (status <= fmi2Warning) {
        s->b.time = start;
        s->b.stop_defined = stop_defined != fmi2False;
        s->b.stop = stop;
    }
    return status;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    if (!allowed(c, INSTANTIATED, "fmi2EnterInitializationMode")) return fmi2Error;
    fmi2Status status = wrapper.fmi2EnterInitializationMode(((Shim *)c)->inner);
    if (status <= fmi2Warning) ((Shim *)c)->b.phase = INITIALIZATION;
    return status;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Shim *s = c;
    if (!allowed(c, ANY_PHASE, "fmi2Reset")) return fmi2Error;
    fmi2Status status = wrapper.fmi2Reset(s->inner);
    if (status <= fmi2Warning) {
        s->b.phase = INSTANTIATED;
        s->b.failed = s->b.stop_defined = 0;
        s->b.time = 0.0;
    }
    return status;
}

const char *fmi2GetTypesPlatform(void) {
    return loaded() ? wrapper.fmi2GetTypesPlatform() : fmi2TypesPlatform;
}

const char *fmi2GetVersion(void) {
    return loaded() ? wrapper.fmi2GetVersion() : fmi2Version;
}

/* The instance name as the wrapper may take it: every byte past ASCII as '?' (the wrapper's
   PyUnicode_FromString of "\xff\xfe", not UTF-8, failed and it crashed the host: fuzz.c).
   The shim's own log lines keep the host's name. */
static char *ascii_name(const char *name) {
    char *out = strdup(name);
    for (char *p = out; p && *p; p++)
        if ((unsigned char)*p >= 0x80) *p = '?';
    return out;
}

/* Why ``guid`` is not the GUID of the FMU whose resources folder the URI names (its
   modelDescription.xml beside that folder, when there is one), or NULL. pythonfmu's
   wrapper checks no GUID: an instance of another FMU's GUID, or of none, was made (fuzz.c). */
static const char *wrong_guid(const char *guid, const char *resources) {
    if (!guid) return "the GUID is NULL";
    const char *p = resources + 5;   /* past "file:" */
    if (strncmp(p, "//", 2) == 0) p += 2;
    char path[4200];
    size_t n = 0;
    for (; *p && n < sizeof path - 40; p++) {   /* the URI's path, %XX decoded */
        unsigned x;
        if (*p == '%' && sscanf(p + 1, "%2x", &x) == 1) path[n++] = (char)x, p += 2;
        else path[n++] = *p;
    }
    while (n && path[n - 1] == '/') n--;
    while (n && path[n - 1] != '/') n--;   /* the folder holding resources/ */
    snprintf(path + n, sizeof path - n, "modelDescription.xml");
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;   /* not extracted (fmpy's simulate_fmu extracts binaries and resources only): unchecked */
    static char xml[1 << 16];   /* the GUID is an attribute of the root element, near the top */
    size_t got = fread(xml, 1, sizeof xml - 1, f);
    fclose(f);
    xml[got] = '\0';
    const char *at = strstr(xml, " guid=\"");
    if (!at) return "modelDescription.xml has no guid";
    at += 7;
    size_t len = strlen(guid);
    return strncmp(at, guid, len) == 0 && at[len] == '"' ? NULL : "it is not this FMU's GUID";
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
    const char *why = wrong_guid(guid, resources);
    if (why) {
        char text[600];
        snprintf(text, sizeof text, "fmi2Instantiate: GUID '%.200s' refused: %s", guid ? guid : "(null)", why);
        log_text(functions, name, fmi2Error, "logStatusError", text);
        return NULL;
    }
    if (type != fmi2CoSimulation) {   /* the wrapper made an instance of any type */
        char text[400];
        snprintf(text, sizeof text, "fmi2Instantiate: %s supports co-simulation only", model_id);
        log_text(functions, name, fmi2Error, "logStatusError", text);
        return NULL;
    }
    Shim *s = calloc(1, sizeof *s);
    if (!s || !(s->name = strdup(name ? name : ""))) {
        free(s);
        return NULL;
    }
    s->host = *functions;
    s->b.phase = INSTANTIATED;
    s->callbacks = (fmi2CallbackFunctions){logger, functions->allocateMemory, functions->freeMemory,
                                           functions->stepFinished ? step_finished : NULL, s};
    char *ascii = ascii_name(s->name);
    for (int k = 0; k < NCAT; k++) s->category_on[k] = logging != fmi2False;
    s->inner = ascii ? wrapper.fmi2Instantiate(ascii, type, guid, resources, &s->callbacks, visible, fmi2True) : NULL;
    free(ascii);
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
    s->b.phase = STEPPING;   /* a failed instance too: it refuses doStep with Discard, as the native ones */
    s->holding = 1;
    s->slave_error = 0;
    fmi2Status status = wrapper.fmi2ExitInitializationMode(s->inner);
    int as_error = status == fmi2Fatal && s->slave_error;
    s->b.failed = status > fmi2Warning;
    release(s, as_error);
    return as_error ? fmi2Error : status;
}

/* ------------------------------------------------------------------- FMU states */
/* An FMU state: the wrapper's (the slave's) and the shim's Book. Serialized: the slave's
   bytes, the Book, the CRC-32 of the Book (4 bytes, this platform's order). */
typedef struct {
    fmi2FMUstate inner;
    Book b;
} State;
enum { TRAILER = sizeof(Book) + 4 };

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Shim *s = c;
    if (!allowed(c, ANY_PHASE, "fmi2GetFMUstate")) return fmi2Error;
    if (!state) return refuse(c, "fmi2GetFMUstate: FMUstate is NULL");
    State *st = *state ? *state : calloc(1, sizeof *st);
    if (!st) return refuse(c, "fmi2GetFMUstate: out of memory");
    fmi2Status status = wrapper.fmi2GetFMUstate(s->inner, &st->inner);
    if (status > fmi2Warning) {
        if (!*state) free(st);
        return status;
    }
    st->b = s->b;
    *state = st;
    return status;
}

/* The state's phase, time and failure come back with it (the native layer's block). */
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    Shim *s = c;
    State *st = state;
    if (!allowed(c, ANY_PHASE, "fmi2SetFMUstate")) return fmi2Error;
    if (!st) return refuse(c, "fmi2SetFMUstate: the given state is NULL");
    fmi2Status status = wrapper.fmi2SetFMUstate(s->inner, st->inner);
    if (status <= fmi2Warning) s->b = st->b;
    return status;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    Shim *s = c;
    if (!allowed(c, ANY_PHASE, "fmi2FreeFMUstate")) return fmi2Error;
    if (!state || !*state) return fmi2OK;   /* nothing to free */
    State *st = *state;
    fmi2Status status = st->inner ? wrapper.fmi2FreeFMUstate(s->inner, &st->inner) : fmi2OK;
    free(st);
    *state = NULL;
    return status;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    Shim *s = c;
    State *st = state;
    if (!allowed(c, ANY_PHASE, "fmi2SerializedFMUstateSize")) return fmi2Error;
    if (!st || !size) return refuse(c, st ? "fmi2SerializedFMUstateSize: size is NULL"
                                          : "fmi2SerializedFMUstateSize: the given state is NULL");
    fmi2Status status = wrapper.fmi2SerializedFMUstateSize(s->inner, st->inner, size);
    if (status <= fmi2Warning) *size += TRAILER;
    return status;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    Shim *s = c;
    State *st = state;
    size_t inner = 0;
    if (!allowed(c, ANY_PHASE, "fmi2SerializeFMUstate")) return fmi2Error;
    if (!st || !bytes) return refuse(c, "fmi2SerializeFMUstate: the state or the byte array is NULL");
    fmi2Status status = wrapper.fmi2SerializedFMUstateSize(s->inner, st->inner, &inner);
    if (status > fmi2Warning) return status;
    if (size < inner + TRAILER) return refuse(c, "fmi2SerializeFMUstate: the buffer is too small");
    status = wrapper.fmi2SerializeFMUstate(s->inner, st->inner, bytes, inner);
    if (status > fmi2Warning) return status;
    uint32_t crc = (uint32_t)mb_crc32(&st->b, sizeof st->b);
    memcpy(bytes + inner, &st->b, sizeof st->b);
    memcpy(bytes + inner + sizeof st->b, &crc, 4);
    return status;
}

/* Why bytes are not a state this FMU serialized (GuardedSlave._fmu_state_to_bytes: the
   line "movingbase-state <id> <crc32 of the rest, 8 hex digits>" and the JSON; then the
   shim's Book and its CRC-32), or NULL. */
static const char *foreign(const fmi2Byte *bytes, size_t size) {
    static const char magic[] = "movingbase-state ";
    size_t m = sizeof magic - 1, id = strlen(model_id);
    if (!bytes || size < m + id + 10 + TRAILER || memcmp(bytes, magic, m) != 0) return "no movingbase state header";
    if (memcmp(bytes + m, model_id, id) != 0 || bytes[m + id] != ' ') return "a state of another FMU";
    const char *hex = bytes + m + id + 1;
    char digits[9];
    memcpy(digits, hex, 8);
    digits[8] = '\0';
    char *end;
    unsigned long crc = strtoul(digits, &end, 16);
    if (end != digits + 8 || hex[8] != '\n') return "a damaged header";
    size_t head = m + id + 10, inner = size - TRAILER;
    if (mb_crc32(bytes + head, inner - head) != crc) return "its checksum does not match";
    uint32_t book_crc;
    memcpy(&book_crc, bytes + inner + sizeof(Book), 4);
    if ((uint32_t)mb_crc32(bytes + inner, sizeof(Book)) != book_crc) return "the shim's part does not match its checksum";
    return NULL;
}

/* Bytes that are not a state of this FMU are refused here, with fmi2Error and a log line:
   given to the wrapper, GuardedSlave could only raise, which the wrapper answers with
   fmi2Fatal after dropping references to the instance, its class and its log queue (a
   crash later, as after a failed initialization). */
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    Shim *s = c;
    if (!allowed(c, ANY_PHASE, "fmi2DeSerializeFMUstate")) return fmi2Error;
    if (!state) return refuse(c, "fmi2DeSerializeFMUstate: FMUstate is NULL");
    const char *why = foreign(bytes, size);
    if (why) {
        char text[256];
        snprintf(text, sizeof text, "fmi2DeSerializeFMUstate: the %zu bytes are not a serialized state of %s (%s)",
                 size, model_id, why);
        return refuse(c, text);
    }
    State *st = *state ? *state : calloc(1, sizeof *st);
    if (!st) return refuse(c, "fmi2DeSerializeFMUstate: out of memory");
    fmi2Status status = wrapper.fmi2DeSerializeFMUstate(s->inner, bytes, size - TRAILER, &st->inner);
    if (status > fmi2Warning) {
        if (!*state) free(st);
        return status;
    }
    memcpy(&st->b, bytes + size - TRAILER, sizeof st->b);
    *state = st;
    return status;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    if (!allowed(c, STEPPING, "fmi2Terminate")) return fmi2Error;
    ((Shim *)c)->b.phase = TERMINATED;
    fmi2Status status = wrapper.fmi2Terminate(((Shim *)c)->inner);
    finalize_before_exit();
    return status;
}

/* A count of values with no array to hold them: fmi2Error (the native layer's arrays_given;
   the wrapper read through the NULL pointer). */
static int arrays_given(Shim *s, const char *function, size_t n, const void *vr, const void *values) {
    if (n == 0 || (vr && values)) return 1;
    char text[200];
    snprintf(text, sizeof text, "%s: %s is NULL for %zu values", function,
             vr ? "the values array" : "the value reference array", n);
    deliver(s, fmi2Error, "logStatusError", text);
    return 0;
}

/* The wrapper's answer to a get or set during which the slave's messages were held: fmi2Error
   if the slave logged one (it then set nothing, GuardedSlave._refused). */
static fmi2Status held_answer(Shim *s, fmi2Status status) {
    release(s, 0);
    return status <= fmi2Warning && s->slave_error ? fmi2Error : status;
}

#define DEFINE_VALUES(name, states, type) \
    fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, type v[]) { \
        Shim *s = c; \
        if (!allowed(c, states, #name) || !arrays_given(s, #name, n, vr, v)) return fmi2Error; \
        s->holding = 1; \
        s->slave_error = 0; \
        return held_answer(s, wrapper.name(s->inner, vr, n, v)); \
    }
VALUES(DEFINE_VALUES)

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior) {
    Shim *s = c;
    if (!allowed(c, STEPPING, "fmi2DoStep")) return fmi2Error;
    char text[200];
    text[0] = '\0';
    if (s->b.failed) {
        /* the slave refuses it with Discard, saying after what */
    } else if (!(isfinite(h) && h > 0)) {
        snprintf(text, sizeof text, "fmi2DoStep: the communication step size must be finite and > 0, got %.17g s", h);
    } else if (!(fabs(t - s->b.time) <= 1e-9 * (fabs(s->b.time) > 1.0 ? fabs(s->b.time) : 1.0))) {
        snprintf(text, sizeof text, "fmi2DoStep: currentCommunicationPoint %.17g s is not the FMU's time %.17g s "
                 "(the end of the last accepted step)", t, s->b.time);
    } else if (t + h == t) {
        snprintf(text, sizeof text, "fmi2DoStep: a step of %.17g s does not advance the time %.17g s "
                 "(below its resolution)", h, t);
    } else if (s->b.stop_defined && t + h > s->b.stop + 1e-9 * (fabs(s->b.stop) > 1.0 ? fabs(s->b.stop) : 1.0)) {
        snprintf(text, sizeof text, "fmi2DoStep: the step to t=%.17g s passes the experiment's stopTime "
                 "%.17g s", t + h, s->b.stop);
    }
    if (text[0]) {   /* the native layer's rules (fmi2_layer.c fmi2DoStep) */
        deliver(s, fmi2Error, "logStatusError", text);
        return fmi2Error;
    }
    fmi2Status status = wrapper.fmi2DoStep(s->inner, t, h, no_set_prior);
    if (status == fmi2OK || status == fmi2Warning) {
        s->b.time = t + h;
    } else {
        s->b.failed = 1;
    }
    return status;
}

/* ------------------------------------------------------------------ status queries */
/* Answered here, as the native layer answers them (the wrapper answered fmi2Discard with
   "FMI function not supported" for all but fmi2LastSuccessfulTime, which it answered with
   the start of the latest doStep, moving on with every refused step). */
static int status_query(fmi2Component c, const char *function, const void *value) {
    return allowed(c, STATUS, function) && arrays_given(c, function, 1, value, value);
}

static fmi2Status no_status(fmi2Component c, const char *function, fmi2StatusKind kind) {
    char text[200];
    snprintf(text, sizeof text, "%s: no status of kind %d", function, (int)kind);
    deliver(c, fmi2Error, "logStatusError", text);
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Status *v) {
    if (!status_query(c, "fmi2GetStatus", v)) return fmi2Error;
    if (kind != fmi2DoStepStatus) return no_status(c, "fmi2GetStatus", kind);
    *v = ((Shim *)c)->b.failed ? fmi2Discard : fmi2OK;   /* doStep is synchronous: the last one is done */
    return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real *v) {
    if (!status_query(c, "fmi2GetRealStatus", v)) return fmi2Error;
    if (kind != fmi2LastSuccessfulTime) return no_status(c, "fmi2GetRealStatus", kind);
    *v = ((Shim *)c)->b.time;
    return fmi2OK;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Boolean *v) {
    if (!status_query(c, "fmi2GetBooleanStatus", v)) return fmi2Error;
    if (kind != fmi2Terminated) return no_status(c, "fmi2GetBooleanStatus", kind);
    *v = ((Shim *)c)->b.failed ? fmi2True : fmi2False;   /* a failed instance has ended its simulation */
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Integer *v) {
    (void)v;
    return allowed(c, STATUS, "fmi2GetIntegerStatus") ? no_status(c, "fmi2GetIntegerStatus", kind) : fmi2Error;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind kind, fmi2String *v) {
    (void)v;
    return allowed(c, STATUS, "fmi2GetStringStatus") ? no_status(c, "fmi2GetStringStatus", kind) : fmi2Error;
}
