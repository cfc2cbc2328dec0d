/* A careless or hostile FMI 2.0 host: runs one script of calls on one FMU and prints what
 * every call answered, so tests/hosts/test_c_host_misuse.py can hold each answer against the FMI
 * 2.0 standard (and the Reference FMUs) in a fresh process per case.
 *
 * Why: fmpy, fmusim and the Compliance Checker call an FMU in the order the standard
 * prescribes; the defects of issue 18 (a crash by format string, an int overflow, calls
 * out of sequence answered fmi2OK) show only under calls none of them makes.
 *
 * Usage: misuse UNZIPDIR MODEL_IDENTIFIER GUID COMMAND...
 *   inst GUID NAME      fmi2Instantiate ("-": the right GUID, the name "misuse");
 *                       prints "fmi2Instantiate instance" or "fmi2Instantiate NULL"
 *   nores               the next fmi2Instantiate gets "" as fmuResourceLocation
 *   log CATEGORY        SetDebugLogging(on) for that one category
 *   setup T0 | setup-stop T0 TSTOP | enter | exit | term | reset | free
 *   step T H            fmi2DoStep
 *   setr VR X | seti VR N | getr VR | geti VR   (getr prints "value VR X")
 *   save | restore | drop   fmi2GetFMUstate / fmi2SetFMUstate / fmi2FreeFMUstate (one slot)
 *   bytes               serialize the slot; prints "bytes N CRC" (CRC-32 of the whole blob)
 *   last                GetRealStatus(fmi2LastSuccessfulTime): "last T"
 *   threads N STEPS H   N threads, each its own instance through init and STEPS doSteps;
 *                       prints "thread K X" (the hash of every Real after the run)
 *   many N              N instances at once, each initialized, then all freed
 * Each call prints "CALL STATUS". The logger formats the message as printf does (as C
 * hosts do) and prints "log STATUS CATEGORY: TEXT". "done" ends a run that returned.
 */
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "misuse_common.h"

static const char *STATUS[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};

static void log_message(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                        fmi2String message, ...)
{
    (void)env, (void)instance;
    va_list args;
    va_start(args, message);
    pthread_mutex_lock(&print_lock);
    printf("log %s %s: ", status <= fmi2Pending ? STATUS[status] : "?", category ? category : "");
    vprintf(message, args);   /* as a C host does: the message is a format */
    printf("\n");
    fflush(stdout);
    pthread_mutex_unlock(&print_lock);
    va_end(args);
}

static void *lib;
static const char *guid_right;
static char resources[4200];   /* file://UNZIPDIR/resources */
#define F(name) static fmi2##name##TYPE *name;   /* the FMU's fmi2<name> */
F(Instantiate) F(FreeInstance) F(SetDebugLogging) F(SetupExperiment)
F(EnterInitializationMode) F(ExitInitializationMode) F(Terminate) F(Reset) F(DoStep)
F(SetReal) F(GetReal) F(SetInteger) F(GetInteger) F(GetFMUstate) F(SetFMUstate)
F(FreeFMUstate) F(SerializedFMUstateSize) F(SerializeFMUstate) F(GetRealStatus) F(SetString) F(GetString)
#undef F

static void *sym(const char *name)
{
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "misuse: missing symbol %s\n", name);
        exit(11);
    }
    return f;
}

static fmi2Status said(const char *call, fmi2Status status)
{
    pthread_mutex_lock(&print_lock);
    printf("%s %s\n", call, status <= fmi2Pending ? STATUS[status] : "?");
    fflush(stdout);
    pthread_mutex_unlock(&print_lock);
    return status;
}

static const fmi2CallbackFunctions CALLBACKS = {log_message, calloc, free, NULL, NULL};

/* The threads' and the many instances' logger: their runs probe every value reference. */
static void quiet(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                  fmi2String message, ...)
{
    (void)env, (void)instance, (void)status, (void)category, (void)message;
}
static const fmi2CallbackFunctions QUIET = {quiet, calloc, free, NULL, NULL};

/* One instance through initialization and `steps` doSteps; the hash of its Reals 0..511
   that answer (value references past the last are refused one by one). */

static void *run_one(void *arg)
{
    Run *run = arg;
    fmi2Component c = Instantiate("thread", fmi2CoSimulation, guid_right, resources, &QUIET, fmi2False, fmi2False);
    run->ok = c != NULL;
    if (!c) return NULL;
    run->ok = SetupExperiment(c, fmi2False, 0, 0, fmi2False, 0) == fmi2OK && EnterInitializationMode(c) == fmi2OK &&
              ExitInitializationMode(c) == fmi2OK;
    for (int k = 0; run->ok && k < run->steps; k++) run->ok = DoStep(c, k * run->h, run->h, fmi2True) == fmi2OK;
    double values[512];
    size_t n = 0;
    for (fmi2ValueReference vr = 0; vr < 512; vr++) {
        double v;
        if (GetReal(c, &vr, 1, &v) == fmi2OK) values[n++] = v;
    }
    run->hash = crc32((const unsigned char *)values, n * sizeof(double));
    Terminate(c);
    FreeInstance(c);
    return NULL;
}

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: %s UNZIPDIR MODEL_IDENTIFIER GUID COMMAND...\n", argv[0]);
        return 10;
    }
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    guid_right = argv[3];
    snprintf(resources, sizeof resources, "file://%s/resources", argv[1]);
    lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "misuse: dlopen %s: %s\n", path, dlerror());
        return 11;
    }
#define F(name) name = (fmi2##name##TYPE *)sym("fmi2" #name);
    F(Instantiate) F(FreeInstance) F(SetDebugLogging) F(SetupExperiment)
    F(EnterInitializationMode) F(ExitInitializationMode) F(Terminate) F(Reset) F(DoStep)
    F(SetReal) F(GetReal) F(SetInteger) F(GetInteger) F(GetFMUstate) F(SetFMUstate)
    F(FreeFMUstate) F(SerializedFMUstateSize) F(SerializeFMUstate) F(GetRealStatus) F(SetString) F(GetString)
#undef F
    fmi2Component c = NULL;
    fmi2FMUstate state = NULL;
    for (int i = 4; i < argc; i++) {
        const char *cmd = argv[i];
#define ARG(k) (i + (k) < argc ? argv[i + (k)] : (fprintf(stderr, "misuse: %s needs arguments\n", cmd), exit(10), ""))
        if (!strcmp(cmd, "inst")) {
            const char *guid = strcmp(ARG(1), "-") ? ARG(1) : guid_right;
            const char *name = strcmp(ARG(2), "-") ? ARG(2) : "misuse";
            i += 2;
            c = Instantiate(name, fmi2CoSimulation, guid, resources, &CALLBACKS, fmi2False, fmi2True);
            printf("fmi2Instantiate %s\n", c ? "instance" : "NULL");
        } else if (!strcmp(cmd, "nores")) {
            resources[0] = '\0';
        } else if (!strcmp(cmd, "log")) {
            fmi2String category = ARG(1);
            i++;
            said("fmi2SetDebugLogging", SetDebugLogging(c, fmi2True, 1, &category));
        } else if (!strcmp(cmd, "setup")) {
            said("fmi2SetupExperiment", SetupExperiment(c, fmi2False, 0, strtod(ARG(1), NULL), fmi2False, 0));
            i++;
        } else if (!strcmp(cmd, "setup-stop")) {
            said("fmi2SetupExperiment", SetupExperiment(c, fmi2False, 0, strtod(ARG(1), NULL), fmi2True,
                                                        strtod(ARG(2), NULL)));
            i += 2;
        } else if (!strcmp(cmd, "enter")) said("fmi2EnterInitializationMode", EnterInitializationMode(c));
        else if (!strcmp(cmd, "exit")) said("fmi2ExitInitializationMode", ExitInitializationMode(c));
        else if (!strcmp(cmd, "term")) said("fmi2Terminate", Terminate(c));
        else if (!strcmp(cmd, "reset")) said("fmi2Reset", Reset(c));
        else if (!strcmp(cmd, "free")) {
            FreeInstance(c);
            c = NULL;
            printf("fmi2FreeInstance\n");
        } else if (!strcmp(cmd, "step")) {
            said("fmi2DoStep", DoStep(c, strtod(ARG(1), NULL), strtod(ARG(2), NULL), fmi2True));
            i += 2;
        } else if (!strcmp(cmd, "setr") || !strcmp(cmd, "seti")) {
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(ARG(1), NULL, 10);
            if (cmd[3] == 'r') {
                double x = strtod(ARG(2), NULL);
                said("fmi2SetReal", SetReal(c, &vr, 1, &x));
            } else {
                int x = atoi(ARG(2));
                said("fmi2SetInteger", SetInteger(c, &vr, 1, &x));
            }
            i += 2;
        } else if (!strcmp(cmd, "sets")) {   /* sets VR TEXT: TEXT "NULL" passes a NULL string */
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(ARG(1), NULL, 10);
            fmi2String text = strcmp(ARG(2), "NULL") ? ARG(2) : NULL;
            said("fmi2SetString", SetString(c, &vr, 1, &text));
            i += 2;
        } else if (!strcmp(cmd, "gets")) {
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(ARG(1), NULL, 10);
            fmi2String text = NULL;
            if (said("fmi2GetString", GetString(c, &vr, 1, &text)) == fmi2OK) printf("string %u '%s'\n", (unsigned)vr, text);
            i++;
        } else if (!strcmp(cmd, "getr") || !strcmp(cmd, "geti")) {
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(ARG(1), NULL, 10);
            double x = 0;
            int n = 0;
            fmi2Status s = cmd[3] == 'r' ? said("fmi2GetReal", GetReal(c, &vr, 1, &x))
                                         : said("fmi2GetInteger", GetInteger(c, &vr, 1, &n));
            if (s == fmi2OK) printf("value %u %.17g\n", (unsigned)vr, cmd[3] == 'r' ? x : n);
            i++;
        } else if (!strcmp(cmd, "save")) said("fmi2GetFMUstate", GetFMUstate(c, &state));
        else if (!strcmp(cmd, "restore")) said("fmi2SetFMUstate", SetFMUstate(c, state));
        else if (!strcmp(cmd, "drop")) said("fmi2FreeFMUstate", FreeFMUstate(c, &state));
        else if (!strcmp(cmd, "bytes")) {
            size_t n = 0;
            if (said("fmi2SerializedFMUstateSize", SerializedFMUstateSize(c, state, &n)) == fmi2OK) {
                unsigned char *blob = malloc(n);
                if (said("fmi2SerializeFMUstate", SerializeFMUstate(c, state, (fmi2Byte *)blob, n)) == fmi2OK)
                    printf("bytes %zu %08lx\n", n, crc32(blob, n));
                free(blob);
            }
        } else if (!strcmp(cmd, "last")) {
            double t = 0;
            if (said("fmi2GetRealStatus", GetRealStatus(c, fmi2LastSuccessfulTime, &t)) == fmi2OK)
                printf("last %.17g\n", t);
        } else if (!strcmp(cmd, "threads")) {
            run_threads(atoi(ARG(1)), atoi(ARG(2)), strtod(ARG(3), NULL), run_one);
            i += 3;
        } else if (!strcmp(cmd, "many")) {
            int n = atoi(ARG(1)), ok = 0;
            fmi2Component *all = calloc((size_t)n, sizeof *all);
            for (int k = 0; k < n; k++) {
                all[k] = Instantiate("many", fmi2CoSimulation, guid_right, resources, &QUIET, fmi2False, fmi2False);
                ok += all[k] && SetupExperiment(all[k], fmi2False, 0, 0, fmi2False, 0) == fmi2OK &&
                      EnterInitializationMode(all[k]) == fmi2OK && ExitInitializationMode(all[k]) == fmi2OK;
            }
            for (int k = 0; k < n; k++) FreeInstance(all[k]);
            free(all);
            printf("many %d of %d\n", ok, n);
            i++;
        } else {
            fprintf(stderr, "misuse: unknown command %s\n", cmd);
            return 10;
        }
    }
    if (state && c) FreeFMUstate(c, &state);
    if (c) FreeInstance(c);
    printf("done\n");
    fflush(stdout);
    return 0;
}
