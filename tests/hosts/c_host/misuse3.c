/* A careless or hostile FMI 3.0 host: runs one script of calls on one FMI 3.0 FMU and
 * prints what every call answered, so tests/hosts/test_c_host_misuse.py can hold each answer
 * against FMI 3.0 in a fresh process per case. The FMI 3 twin of misuse.c.
 *
 * Why: fmpy, ecos and fmi-sim call an FMU in the order FMI 3.0 prescribes, with nValues
 * that match; what a host gets back when it does not (calls out of sequence, wrong
 * nValues, NULL arguments, garbage FMU states) shows only under calls none of them makes.
 *
 * Usage: misuse3 UNZIPDIR MODEL_IDENTIFIER TOKEN COMMAND...
 *   inst TOKEN NAME     fmi3InstantiateCoSimulation ("-": the right token / the name
 *                       "misuse"; "NULL": a NULL pointer); prints "fmi3InstantiateCoSimulation
 *                       instance" or "... NULL"
 *   inst-events | inst-required | inst-me | inst-se
 *                       instantiation with eventModeUsed, with a required intermediate
 *                       variable, as model exchange, as scheduled execution
 *   nores | nolog       the next instantiation gets a NULL resourcePath / a NULL logMessage
 *   log CATEGORY        fmi3SetDebugLogging(on) for that one category
 *   enter T0 | enter-stop T0 TSTOP | exit | term | reset | free | free-null
 *   step T H            fmi3DoStep; on OK/Warning/Discard also prints
 *                       "stepout TERMINATE EARLYRETURN LASTSUCCESSFULTIME"
 *   step-null T H       fmi3DoStep with NULL out arguments
 *   setf VR N X1..XN    fmi3SetFloat64 of one value reference with nValues N
 *   getf VR N           fmi3GetFloat64 of one value reference with nValues N: "value VR X1..XN"
 *   getf-null-vr | getf-null-values VR N      the same with a NULL array
 *   seti32 VR X | geti32 VR | seti64 VR X | geti64 VR     Int32 / Int64 (Enumerations)
 *   getbool VR | getstring VR | getbinary VR              types the FMU has no variable of
 *   save | restore | drop | save-null | restore-null
 *                       fmi3GetFMUState / SetFMUState / FreeFMUState (one slot); -null: NULL
 *   bytes               serialize the slot; keeps the blob; "bytes N CRC" (CRC-32)
 *   short               serialize the slot into a buffer one byte short
 *   load                deserialize the kept blob into the slot
 *   load-truncated | load-flipped | load-garbage N | load-flipped-at K
 *                       deserialize the kept blob less its last byte / with one byte of its
 *                       block flipped / N bytes of a pattern / byte K xor 0x0c (K 0: the
 *                       instance state, StepMode 4 becomes StepDiscarded 8)
 *   unsupported         every call this co-simulation FMU does not offer, each printed
 *   threads N STEPS H   N threads, each its own instance through init and STEPS doSteps;
 *                       prints "thread K OK|failed HASH" (of every Float64 after the run)
 *   many N              N instances at once, each initialized, then all freed
 * Each call prints "CALL STATUS". The logger prints "log STATUS CATEGORY: TEXT" (an FMI 3
 * message is text, not a format). "done" ends a run that returned.
 */
#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "misuse_common.h"

static const char *STATUS[] = {"OK", "Warning", "Discard", "Error", "Fatal"};

static const char *status_name(fmi3Status s) { return (unsigned)s <= fmi3Fatal ? STATUS[s] : "?"; }

static void log_message(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    pthread_mutex_lock(&print_lock);
    printf("log %s %s: %s\n", status_name(status), category ? category : "", message ? message : "(null)");
    fflush(stdout);
    pthread_mutex_unlock(&print_lock);
}

/* The threads' and the many instances' logger: their runs probe every value reference. */
static void quiet(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env, (void)status, (void)category, (void)message;
}

static void *lib;
static const char *token_right;
static char resources[4200];   /* UNZIPDIR/resources/: FMI 3 passes a path, not a URI */
/* Every fmi3 function the host calls, declared and loaded from one list. */
#define FUNCTIONS(F)                                                                                                \
    F(InstantiateCoSimulation) F(InstantiateModelExchange) F(InstantiateScheduledExecution) F(FreeInstance)        \
    F(SetDebugLogging) F(EnterInitializationMode) F(ExitInitializationMode) F(Terminate) F(Reset) F(DoStep)        \
    F(GetFloat64) F(SetFloat64) F(GetInt32) F(SetInt32) F(GetInt64) F(SetInt64) F(GetBoolean) F(GetString)        \
    F(GetBinary) F(GetFMUState) F(SetFMUState) F(FreeFMUState) F(SerializedFMUStateSize) F(SerializeFMUState)     \
    F(DeserializeFMUState) F(EnterEventMode) F(EnterStepMode) F(UpdateDiscreteStates) F(EnterConfigurationMode)   \
    F(GetDirectionalDerivative) F(SetTime) F(GetContinuousStates) F(GetClock) F(GetNumberOfContinuousStates)
#define DECLARE(name) static fmi3##name##TYPE *name;   /* the FMU's fmi3<name> */
FUNCTIONS(DECLARE)

static void *sym(const char *name)
{
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "misuse3: missing symbol %s\n", name);
        exit(11);
    }
    return f;
}

static fmi3Status said(const char *call, fmi3Status status)
{
    pthread_mutex_lock(&print_lock);
    printf("%s %s\n", call, status_name(status));
    fflush(stdout);
    pthread_mutex_unlock(&print_lock);
    return status;
}

static fmi3Instance instantiate(const char *name, const char *token, const char *res, fmi3LogMessageCallback log,
                                fmi3Boolean events, size_t nrequired)
{
    static const fmi3ValueReference required[1] = {0};
    return InstantiateCoSimulation(name, token, res, fmi3False, fmi3True, events, fmi3False,
                                   nrequired ? required : NULL, nrequired, NULL, log, NULL);
}

static fmi3Status step(fmi3Instance c, double t, double h)
{
    fmi3Boolean event = 0, terminate = 0, early = 0;
    fmi3Float64 last = 0;
    return DoStep(c, t, h, fmi3False, &event, &terminate, &early, &last);
}

/* One instance through initialization and `steps` doSteps; the hash of the Float64
   variables 0..511 that answer one value (arrays and other types are refused one by one). */

static void *run_one(void *arg)
{
    Run *run = arg;
    fmi3Instance c = instantiate("thread", token_right, resources, quiet, fmi3False, 0);
    run->ok = c != NULL;
    if (!c) return NULL;
    run->ok = EnterInitializationMode(c, fmi3False, 0, 0, fmi3False, 0) == fmi3OK && ExitInitializationMode(c) == fmi3OK;
    double t = 0;
    for (int k = 0; run->ok && k < run->steps; k++, t += run->h) run->ok = step(c, t, run->h) == fmi3OK;
    double values[512];
    size_t n = 0;
    for (fmi3ValueReference vr = 0; vr < 512; vr++) {
        double v;
        if (GetFloat64(c, &vr, 1, &v, 1) == fmi3OK) values[n++] = v;
    }
    run->hash = crc32((const unsigned char *)values, n * sizeof(double));
    Terminate(c);
    FreeInstance(c);
    return NULL;
}

static const char *name_or_null(const char *arg, const char *dash)
{
    return !strcmp(arg, "NULL") ? NULL : !strcmp(arg, "-") ? dash : arg;
}

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: %s UNZIPDIR MODEL_IDENTIFIER TOKEN COMMAND...\n", argv[0]);
        return 10;
    }
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/x86_64-linux/%s.so", argv[1], argv[2]);
    token_right = argv[3];
    snprintf(resources, sizeof resources, "%s/resources/", argv[1]);
    lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "misuse3: dlopen %s: %s\n", path, dlerror());
        return 11;
    }
#define LOAD(name) name = (fmi3##name##TYPE *)sym("fmi3" #name);
    FUNCTIONS(LOAD)
    fmi3Instance c = NULL;
    fmi3FMUState state = NULL;
    unsigned char *blob = NULL;
    size_t blob_size = 0;
    const char *res = resources;
    fmi3LogMessageCallback logger = log_message;
    for (int i = 4; i < argc; i++) {
        const char *cmd = argv[i];
#define ARG(k) (i + (k) < argc ? argv[i + (k)] : (fprintf(stderr, "misuse3: %s needs arguments\n", cmd), exit(10), ""))
#define VR(k) ((fmi3ValueReference)strtoul(ARG(k), NULL, 10))
        if (!strcmp(cmd, "inst")) {
            c = instantiate(name_or_null(ARG(2), "misuse"), name_or_null(ARG(1), token_right), res, logger, fmi3False, 0);
            printf("fmi3InstantiateCoSimulation %s\n", c ? "instance" : "NULL");
            i += 2;
        } else if (!strcmp(cmd, "inst-events") || !strcmp(cmd, "inst-required")) {
            int events = cmd[5] == 'e';
            c = instantiate("misuse", token_right, res, logger, events ? fmi3True : fmi3False, events ? 0 : 1);
            printf("fmi3InstantiateCoSimulation %s\n", c ? "instance" : "NULL");
        } else if (!strcmp(cmd, "inst-me")) {
            c = InstantiateModelExchange("misuse", token_right, res, fmi3False, fmi3True, NULL, logger);
            printf("fmi3InstantiateModelExchange %s\n", c ? "instance" : "NULL");
        } else if (!strcmp(cmd, "inst-se")) {
            c = InstantiateScheduledExecution("misuse", token_right, res, fmi3False, fmi3True, NULL, logger, NULL, NULL,
                                              NULL);
            printf("fmi3InstantiateScheduledExecution %s\n", c ? "instance" : "NULL");
        } else if (!strcmp(cmd, "nores")) {
            res = NULL;
        } else if (!strcmp(cmd, "nolog")) {
            logger = NULL;
        } else if (!strcmp(cmd, "log")) {
            fmi3String category = ARG(1);
            i++;
            said("fmi3SetDebugLogging", SetDebugLogging(c, fmi3True, 1, &category));
        } else if (!strcmp(cmd, "enter")) {
            said("fmi3EnterInitializationMode", EnterInitializationMode(c, fmi3False, 0, strtod(ARG(1), NULL), fmi3False, 0));
            i++;
        } else if (!strcmp(cmd, "enter-stop")) {
            said("fmi3EnterInitializationMode",
                 EnterInitializationMode(c, fmi3False, 0, strtod(ARG(1), NULL), fmi3True, strtod(ARG(2), NULL)));
            i += 2;
        } else if (!strcmp(cmd, "exit")) said("fmi3ExitInitializationMode", ExitInitializationMode(c));
        else if (!strcmp(cmd, "term")) said("fmi3Terminate", Terminate(c));
        else if (!strcmp(cmd, "reset")) said("fmi3Reset", Reset(c));
        else if (!strcmp(cmd, "free") || !strcmp(cmd, "free-null")) {
            if (!cmd[4]) {
                if (state && c) FreeFMUState(c, &state);
                FreeInstance(c);
                c = NULL;
            } else FreeInstance(NULL);
            printf("fmi3FreeInstance\n");
        } else if (!strcmp(cmd, "step")) {
            fmi3Boolean event = 9, terminate = 9, early = 9;
            fmi3Float64 last = -1;
            fmi3Status s = said("fmi3DoStep", DoStep(c, strtod(ARG(1), NULL), strtod(ARG(2), NULL), fmi3False, &event,
                                                     &terminate, &early, &last));
            if (s <= fmi3Discard) printf("stepout %d %d %.17g\n", (int)terminate, (int)early, last);
            i += 2;
        } else if (!strcmp(cmd, "step-null")) {
            said("fmi3DoStep", DoStep(c, strtod(ARG(1), NULL), strtod(ARG(2), NULL), fmi3False, NULL, NULL, NULL, NULL));
            i += 2;
        } else if (!strcmp(cmd, "setf")) {
            fmi3ValueReference vr = VR(1);
            size_t n = strtoul(ARG(2), NULL, 10);
            double *x = calloc(n + 1, sizeof *x);
            for (size_t k = 0; k < n; k++) x[k] = strtod(ARG(3 + (int)k), NULL);
            said("fmi3SetFloat64", SetFloat64(c, &vr, 1, x, n));
            free(x);
            i += 2 + (int)n;
        } else if (!strcmp(cmd, "getf") || !strcmp(cmd, "getf-null-values")) {
            fmi3ValueReference vr = VR(1);
            size_t n = strtoul(ARG(2), NULL, 10);
            double *x = calloc(n + 1, sizeof *x);
            if (said("fmi3GetFloat64", GetFloat64(c, &vr, 1, cmd[4] ? NULL : x, n)) == fmi3OK) {
                printf("value %u", (unsigned)vr);
                for (size_t k = 0; k < n; k++) printf(" %.17g", x[k]);
                printf("\n");
            }
            free(x);
            i += 2;
        } else if (!strcmp(cmd, "getf-null-vr")) {
            double x[8];
            said("fmi3GetFloat64", GetFloat64(c, NULL, 1, x, 1));
        } else if (!strcmp(cmd, "seti32") || !strcmp(cmd, "seti64")) {
            fmi3ValueReference vr = VR(1);
            long long x = strtoll(ARG(2), NULL, 10);
            if (cmd[4] == '3') {
                fmi3Int32 y = (fmi3Int32)x;
                said("fmi3SetInt32", SetInt32(c, &vr, 1, &y, 1));
            } else {
                fmi3Int64 y = x;
                said("fmi3SetInt64", SetInt64(c, &vr, 1, &y, 1));
            }
            i += 2;
        } else if (!strcmp(cmd, "geti32") || !strcmp(cmd, "geti64")) {
            fmi3ValueReference vr = VR(1);
            fmi3Int32 y32 = 0;
            fmi3Int64 y64 = 0;
            fmi3Status s = cmd[4] == '3' ? said("fmi3GetInt32", GetInt32(c, &vr, 1, &y32, 1))
                                         : said("fmi3GetInt64", GetInt64(c, &vr, 1, &y64, 1));
            if (s == fmi3OK) printf("value %u %lld\n", (unsigned)vr, cmd[4] == '3' ? (long long)y32 : (long long)y64);
            i++;
        } else if (!strcmp(cmd, "getbool")) {
            fmi3ValueReference vr = VR(1);
            fmi3Boolean b;
            said("fmi3GetBoolean", GetBoolean(c, &vr, 1, &b, 1));
            i++;
        } else if (!strcmp(cmd, "getstring")) {
            fmi3ValueReference vr = VR(1);
            fmi3String s;
            said("fmi3GetString", GetString(c, &vr, 1, &s, 1));
            i++;
        } else if (!strcmp(cmd, "getbinary")) {
            fmi3ValueReference vr = VR(1);
            size_t size;
            fmi3Binary b;
            said("fmi3GetBinary", GetBinary(c, &vr, 1, &size, &b, 1));
            i++;
        } else if (!strcmp(cmd, "save")) said("fmi3GetFMUState", GetFMUState(c, &state));
        else if (!strcmp(cmd, "save-null")) said("fmi3GetFMUState", GetFMUState(c, NULL));
        else if (!strcmp(cmd, "restore")) said("fmi3SetFMUState", SetFMUState(c, state));
        else if (!strcmp(cmd, "restore-null")) said("fmi3SetFMUState", SetFMUState(c, NULL));
        else if (!strcmp(cmd, "drop")) said("fmi3FreeFMUState", FreeFMUState(c, &state));
        else if (!strcmp(cmd, "bytes") || !strcmp(cmd, "short")) {
            size_t n = 0;
            if (said("fmi3SerializedFMUStateSize", SerializedFMUStateSize(c, state, &n)) == fmi3OK) {
                int shortened = cmd[0] == 's';
                unsigned char *buffer = malloc(n);   /* exactly the size: ASan sees a write past it */
                if (said("fmi3SerializeFMUState", SerializeFMUState(c, state, buffer, n - (size_t)shortened)) == fmi3OK &&
                    !shortened) {
                    printf("bytes %zu %08lx\n", n, crc32(buffer, n));
                    free(blob);
                    blob = buffer, blob_size = n, buffer = NULL;
                }
                free(buffer);
            }
        } else if (!strncmp(cmd, "load", 4)) {
            size_t n = blob_size;
            unsigned char *bytes = malloc(blob_size + 1);
            if (blob) memcpy(bytes, blob, blob_size);
            if (!strcmp(cmd, "load-truncated") && n) {
                n--;
                bytes = realloc(bytes, n ? n : 1);   /* exactly n bytes: ASan sees a read past them */
            } else if (!strcmp(cmd, "load-flipped") && n) {
                bytes[n - 1] ^= 0x40;
            } else if (!strcmp(cmd, "load-flipped-at")) {
                size_t at = strtoul(ARG(1), NULL, 10);
                if (at < n) bytes[at] ^= 0x0c;
                i++;
            } else if (!strcmp(cmd, "load-garbage")) {
                n = strtoul(ARG(1), NULL, 10);
                free(bytes);
                bytes = malloc(n ? n : 1);
                for (size_t k = 0; k < n; k++) bytes[k] = (unsigned char)(k * 37 + 11);
                i++;
            }
            said("fmi3DeserializeFMUState", DeserializeFMUState(c, bytes, n, &state));
            free(bytes);
        } else if (!strcmp(cmd, "unsupported")) {
            fmi3Boolean a, b, d, e, f;
            fmi3Float64 g = 0, x[4] = {0};
            size_t n = 0;
            fmi3ValueReference vr = 0;
            fmi3Clock clock;
            said("fmi3EnterEventMode", EnterEventMode(c));
            said("fmi3EnterStepMode", EnterStepMode(c));
            said("fmi3UpdateDiscreteStates", UpdateDiscreteStates(c, &a, &b, &d, &e, &f, &g));
            said("fmi3EnterConfigurationMode", EnterConfigurationMode(c));
            said("fmi3GetDirectionalDerivative", GetDirectionalDerivative(c, &vr, 1, &vr, 1, x, 1, x + 1, 1));
            said("fmi3SetTime", SetTime(c, 0.0));
            said("fmi3GetContinuousStates", GetContinuousStates(c, x, 1));
            said("fmi3GetClock", GetClock(c, &vr, 1, &clock));
            said("fmi3GetNumberOfContinuousStates", GetNumberOfContinuousStates(c, &n));
        } else if (!strcmp(cmd, "threads")) {
            run_threads(atoi(ARG(1)), atoi(ARG(2)), strtod(ARG(3), NULL), run_one);
            i += 3;
        } else if (!strcmp(cmd, "many")) {
            int n = atoi(ARG(1)), ok = 0;
            fmi3Instance *all = calloc((size_t)n, sizeof *all);
            for (int k = 0; k < n; k++) {
                all[k] = instantiate("many", token_right, resources, quiet, fmi3False, 0);
                ok += all[k] && EnterInitializationMode(all[k], fmi3False, 0, 0, fmi3False, 0) == fmi3OK &&
                      ExitInitializationMode(all[k]) == fmi3OK;
            }
            for (int k = 0; k < n; k++) FreeInstance(all[k]);
            free(all);
            printf("many %d of %d\n", ok, n);
            i++;
        } else {
            fprintf(stderr, "misuse3: unknown command %s\n", cmd);
            return 10;
        }
    }
    if (state && c) FreeFMUState(c, &state);
    if (c) FreeInstance(c);
    free(blob);
    printf("done\n");
    fflush(stdout);
    return 0;
}
