/* A minimal, generic FMI 2.0 co-simulation host: a process that is not Python.
 *
 * Why: an FMU must behave in any importer, not only in fmpy inside a Python process
 * (issue 10: pythonfmu FMUs crashed a C host at exit). This host knows nothing about
 * the FMUs it runs; tests/hosts/c_host.py compiles and drives it.
 *
 * Usage: fmi2_host UNZIPDIR MODEL_IDENTIFIER GUID [options]
 *   --steps N          doSteps to run (default 10)
 *   --h H              communication step size in s (default 1e-3)
 *   --start T          start time (default 0)
 *   --real VR=X        set a Real before fmi2EnterInitializationMode (X may be nan, inf, -inf)
 *   --int VR=N         set an Integer before fmi2EnterInitializationMode
 *   --real-init VR=X   set a Real in initialization mode
 *   --real-at K:VR=X   set a Real before doStep number K (0-based)
 *   --out VR[,VR...]   Reals printed after initialization and after every doStep
 *   --init-out         also print them in initialization mode, after the --real-init sets
 *                      ("init T V..."), as an importer that propagates initial values reads
 *   --state K          after doStep K: fmi2GetFMUstate, run to the end, fmi2SetFMUstate,
 *                      rerun the same steps ("replay" lines), fmi2FreeFMUstate
 *   --keep-going       go on stepping after a Discard (default: stop stepping)
 *   --no-dlclose       leave the library loaded at exit
 *   --quiet            no logger output
 *   --time             print "step_us X": wall-clock µs per doStep over the run (for
 *                      benchmarks/bench_native.py; pass no --out so nothing else is timed)
 *
 * stdout lines: "status CALL STATUS" for every call that did not return fmi2OK,
 * "out T V..." / "replay T V..." for outputs, "last_successful_time T" after a
 * Discard (if fmi2GetRealStatus answers), and "done" just before main returns.
 * Exit code: the worst fmi2Status any call returned (0 OK, 1 Warning, 2 Discard,
 * 3 Error, 4 Fatal, 5 Pending); 10 usage, 11 dlopen/dlsym, 12 fmi2Instantiate NULL.
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

#define MAX_SETS 256
#define MAX_OUT 256

typedef struct { int step; fmi2ValueReference vr; double real; int integer; int is_int; } Setting;

static const char *STATUS[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};
static int worst = fmi2OK;
static int quiet = 0;

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env;
    if (quiet) return;
    va_list args;
    va_start(args, message);
    fprintf(stderr, "[%s] %s %s: ", status <= fmi2Pending ? STATUS[status] : "?",
            instance ? instance : "", category ? category : "");
    vfprintf(stderr, message, args);
    fputc('\n', stderr);
    va_end(args);
}

/* Record a status; non-OK ones are printed so a test can see which call said what. */
static fmi2Status check(const char *call, fmi2Status status) {
    if ((int)status > worst) worst = (int)status;
    if (status != fmi2OK) {
        printf("status %s %s\n", call, status <= fmi2Pending ? STATUS[status] : "?");
        fflush(stdout);
    }
    return status;
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "fmi2_host: missing symbol %s: %s\n", name, dlerror());
        exit(11);
    }
    return f;
}

static int parse_setting(const char *text, int with_step, int is_int, Setting *s) {
    char *end;
    s->step = -1;
    s->is_int = is_int;
    if (with_step) {
        s->step = (int)strtol(text, &end, 10);
        if (*end != ':') return 0;
        text = end + 1;
    }
    s->vr = (fmi2ValueReference)strtoul(text, &end, 10);
    if (*end != '=') return 0;
    text = end + 1;
    if (is_int) s->integer = (int)strtol(text, &end, 10);
    else s->real = strtod(text, &end);
    return *end == '\0' && end != text;
}

static fmi2Status apply(fmi2SetRealTYPE *setReal, fmi2SetIntegerTYPE *setInteger, fmi2Component c,
                        const Setting *s) {
    if (s->is_int) return check("fmi2SetInteger", setInteger(c, &s->vr, 1, &s->integer));
    return check("fmi2SetReal", setReal(c, &s->vr, 1, &s->real));
}

static void print_outputs(fmi2GetRealTYPE *getReal, fmi2Component c, const char *tag, double t,
                          const fmi2ValueReference *vrs, size_t n) {
    double values[MAX_OUT];
    if (n == 0) return;
    if (check("fmi2GetReal", getReal(c, vrs, n, values)) > fmi2Warning) return;
    printf("%s %.17g", tag, t);
    for (size_t i = 0; i < n; i++) printf(" %.17g", values[i]);
    printf("\n");
    fflush(stdout);
}

int main(int argc, char **argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: %s UNZIPDIR MODEL_IDENTIFIER GUID [options]\n", argv[0]);
        return 10;
    }
    const char *dir = argv[1], *id = argv[2], *guid = argv[3];
    int steps = 10, state_step = -1, keep_going = 0, do_dlclose = 1, timed = 0, init_out = 0;
    double h = 1e-3, start = 0.0;
    Setting before[MAX_SETS], in_init[MAX_SETS], at_step[MAX_SETS];
    size_t n_before = 0, n_init = 0, n_at = 0, n_out = 0;
    fmi2ValueReference out[MAX_OUT];

    for (int i = 4; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        int ok = 1;
        if (!strcmp(a, "--keep-going")) { keep_going = 1; continue; }
        if (!strcmp(a, "--no-dlclose")) { do_dlclose = 0; continue; }
        if (!strcmp(a, "--quiet")) { quiet = 1; continue; }
        if (!strcmp(a, "--time")) { timed = 1; continue; }
        if (!strcmp(a, "--init-out")) { init_out = 1; continue; }
        if (!v) { fprintf(stderr, "fmi2_host: %s needs a value\n", a); return 10; }
        i++;
        if (!strcmp(a, "--steps")) steps = atoi(v);
        else if (!strcmp(a, "--h")) h = strtod(v, NULL);
        else if (!strcmp(a, "--start")) start = strtod(v, NULL);
        else if (!strcmp(a, "--state")) state_step = atoi(v);
        else if (!strcmp(a, "--real") && n_before < MAX_SETS) ok = parse_setting(v, 0, 0, &before[n_before++]);
        else if (!strcmp(a, "--int") && n_before < MAX_SETS) ok = parse_setting(v, 0, 1, &before[n_before++]);
        else if (!strcmp(a, "--real-init") && n_init < MAX_SETS) ok = parse_setting(v, 0, 0, &in_init[n_init++]);
        else if (!strcmp(a, "--real-at") && n_at < MAX_SETS) ok = parse_setting(v, 1, 0, &at_step[n_at++]);
        else if (!strcmp(a, "--out")) {
            char *copy = strdup(v), *save = NULL;
            for (char *tok = strtok_r(copy, ",", &save); tok && n_out < MAX_OUT; tok = strtok_r(NULL, ",", &save))
                out[n_out++] = (fmi2ValueReference)strtoul(tok, NULL, 10);
            free(copy);
        } else ok = 0;
        if (!ok) { fprintf(stderr, "fmi2_host: bad option %s %s\n", a, v); return 10; }
    }

    char path[4096], resources[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    snprintf(resources, sizeof resources, "file://%s/resources", dir);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "fmi2_host: dlopen %s: %s\n", path, dlerror()); return 11; }

    fmi2InstantiateTYPE *instantiate = sym(lib, "fmi2Instantiate");
    fmi2FreeInstanceTYPE *freeInstance = sym(lib, "fmi2FreeInstance");
    fmi2SetupExperimentTYPE *setup = sym(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enterInit = sym(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exitInit = sym(lib, "fmi2ExitInitializationMode");
    fmi2TerminateTYPE *terminate = sym(lib, "fmi2Terminate");
    fmi2SetRealTYPE *setReal = sym(lib, "fmi2SetReal");
    fmi2GetRealTYPE *getReal = sym(lib, "fmi2GetReal");
    fmi2SetIntegerTYPE *setInteger = sym(lib, "fmi2SetInteger");
    fmi2DoStepTYPE *doStep = sym(lib, "fmi2DoStep");
    fmi2GetRealStatusTYPE *getRealStatus = sym(lib, "fmi2GetRealStatus");
    fmi2GetFMUstateTYPE *getState = sym(lib, "fmi2GetFMUstate");
    fmi2SetFMUstateTYPE *setState = sym(lib, "fmi2SetFMUstate");
    fmi2FreeFMUstateTYPE *freeState = sym(lib, "fmi2FreeFMUstate");

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("host", fmi2CoSimulation, guid, resources, &callbacks, fmi2False, fmi2True);
    if (!c) { fprintf(stderr, "fmi2_host: fmi2Instantiate returned NULL\n"); return 12; }

    int alive = 1;   /* 0 after Error/Fatal: only fmi2FreeInstance (Error) or nothing (Fatal) */
    for (size_t i = 0; i < n_before && alive; i++)
        if (apply(setReal, setInteger, c, &before[i]) > fmi2Discard) alive = 0;
    if (alive && check("fmi2SetupExperiment", setup(c, fmi2False, 0.0, start, fmi2False, 0.0)) > fmi2Discard) alive = 0;
    if (alive && check("fmi2EnterInitializationMode", enterInit(c)) > fmi2Discard) alive = 0;
    for (size_t i = 0; i < n_init && alive; i++)
        if (apply(setReal, setInteger, c, &in_init[i]) > fmi2Discard) alive = 0;
    if (alive && init_out) print_outputs(getReal, c, "init", start, out, n_out);
    if (alive && check("fmi2ExitInitializationMode", exitInit(c)) > fmi2Discard) alive = 0;
    if (alive) print_outputs(getReal, c, "out", start, out, n_out);

    fmi2FMUstate saved = NULL;
    int k = 0, first = 0, stopped = 0;
    const char *tag = "out";
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    while (alive && k < steps) {
        double t = start + k * h;
        for (size_t i = 0; i < n_at; i++)
            if (at_step[i].step == k) apply(setReal, setInteger, c, &at_step[i]);
        fmi2Status s = check("fmi2DoStep", doStep(c, t, h, fmi2True));
        if (s == fmi2Discard) {
            double last;
            if (getRealStatus(c, fmi2LastSuccessfulTime, &last) == fmi2OK) printf("last_successful_time %.17g\n", last);
            else printf("last_successful_time unavailable\n");
            print_outputs(getReal, c, "discarded", t + h, out, n_out);
            if (!keep_going) { stopped = 1; break; }
        } else if (s > fmi2Discard) {
            alive = 0;
            break;
        } else {
            print_outputs(getReal, c, tag, t + h, out, n_out);
        }
        if (k == state_step && !saved) {
            if (check("fmi2GetFMUstate", getState(c, &saved)) > fmi2Warning) saved = NULL;
            else first = k + 1;
        }
        k++;
        if (k == steps && saved && tag[0] == 'o') {   /* replay once from the saved state */
            if (check("fmi2SetFMUstate", setState(c, saved)) > fmi2Warning) break;
            k = first;
            tag = "replay";
        }
    }
    (void)stopped;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    if (timed && k > 0)
        printf("step_us %.6g\n", ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / 1e3 / k);
    if (saved && worst < fmi2Fatal) check("fmi2FreeFMUstate", freeState(c, &saved));
    if (worst < fmi2Error) check("fmi2Terminate", terminate(c));
    if (worst < fmi2Fatal) freeInstance(c);
    if (do_dlclose && dlclose(lib) != 0) fprintf(stderr, "fmi2_host: dlclose: %s\n", dlerror());
    printf("done\n");
    fflush(stdout);
    return worst;
}
