/* Times the doStep of one model built as an FMI 2.0 and as an FMI 3.0 FMU, in one C
   process, interleaved (benchmarks/bench_native.py compiles and runs it): what each
   layer costs without Python's ctypes in the loop.

     fmi_step_timer FMI2_LIB FMI3_LIB TOKEN STEPS REPEATS [r:VR:v1,v2,..] [i:VR:v] ...

   r:VR:values sets Reals in initialization mode (FMI 2: elements VR, VR+1, ..; FMI 3:
   the variable VR, an array of that many elements), i:VR:v an Integer (FMI 3: Int32).
   Prints "fmi2 <us per doStep>" and "fmi3 <us per doStep>" per repeat; exit 1 on a
   failing call. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void log2_(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                  fmi2String message, ...)
{
    (void)env, (void)name, (void)category;
    if (status > fmi2Warning) fprintf(stderr, "FMI 2: %s\n", message);
}

static void log3_(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env, (void)category;
    if (status > fmi3Warning) fprintf(stderr, "FMI 3: %s\n", message);
}

static void *symbol(void *lib, const char *name)
{
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "missing %s\n", name);
        exit(1);
    }
    return f;
}

#define CHECK(call)                                       \
    if ((call) > 1) {                                     \
        fprintf(stderr, "failed: %s\n", #call);           \
        return 1;                                         \
    }

int main(int argc, char **argv)
{
    if (argc < 6) {
        fprintf(stderr, "usage: fmi_step_timer FMI2_LIB FMI3_LIB TOKEN STEPS REPEATS [r:VR:v,..] [i:VR:v]\n");
        return 2;
    }
    void *lib2 = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL), *lib3 = dlopen(argv[2], RTLD_NOW | RTLD_LOCAL);
    if (!lib2 || !lib3) {
        fprintf(stderr, "%s\n", dlerror());
        return 1;
    }
    const char *token = argv[3];
    long steps = atol(argv[4]), repeats = atol(argv[5]);
    double h = 1e-3;

    fmi2CallbackFunctions cb = {log2_, calloc, free, NULL, NULL};
    fmi2Component c2 = ((fmi2InstantiateTYPE *)symbol(lib2, "fmi2Instantiate"))("t", fmi2CoSimulation, token, "",
                                                                                 &cb, 0, 0);
    fmi3Instance c3 = ((fmi3InstantiateCoSimulationTYPE *)symbol(lib3, "fmi3InstantiateCoSimulation"))(
        "t", token, "", 0, 0, 0, 0, NULL, 0, NULL, log3_, NULL);
    if (!c2 || !c3) return 1;
    CHECK(((fmi2SetupExperimentTYPE *)symbol(lib2, "fmi2SetupExperiment"))(c2, 0, 0.0, 0.0, 0, 0.0))
    CHECK(((fmi2EnterInitializationModeTYPE *)symbol(lib2, "fmi2EnterInitializationMode"))(c2))
    CHECK(((fmi3EnterInitializationModeTYPE *)symbol(lib3, "fmi3EnterInitializationMode"))(c3, 0, 0.0, 0.0, 0, 0.0))
    for (int a = 6; a < argc; a++) {
        char kind = argv[a][0];
        char *rest = argv[a] + 2;
        unsigned vr = (unsigned)strtoul(rest, &rest, 10);
        double values[64];
        size_t n = 0;
        for (char *p = rest + 1; *p && n < 64; p += (*p == ',')) values[n++] = strtod(p, &p);
        if (kind == 'r') {
            fmi2ValueReference vrs[64];
            for (size_t k = 0; k < n; k++) vrs[k] = vr + (unsigned)k;
            CHECK(((fmi2SetRealTYPE *)symbol(lib2, "fmi2SetReal"))(c2, vrs, n, values))
            CHECK(((fmi3SetFloat64TYPE *)symbol(lib3, "fmi3SetFloat64"))(c3, &vr, 1, values, n))
        } else {
            fmi2Integer v2 = (fmi2Integer)values[0];
            fmi3Int32 v3 = (fmi3Int32)values[0];
            CHECK(((fmi2SetIntegerTYPE *)symbol(lib2, "fmi2SetInteger"))(c2, &vr, 1, &v2))
            CHECK(((fmi3SetInt32TYPE *)symbol(lib3, "fmi3SetInt32"))(c3, &vr, 1, &v3, 1))
        }
    }
    CHECK(((fmi2ExitInitializationModeTYPE *)symbol(lib2, "fmi2ExitInitializationMode"))(c2))
    CHECK(((fmi3ExitInitializationModeTYPE *)symbol(lib3, "fmi3ExitInitializationMode"))(c3))
    fmi2DoStepTYPE *step2 = symbol(lib2, "fmi2DoStep");
    fmi3DoStepTYPE *step3 = symbol(lib3, "fmi3DoStep");
    fmi3Boolean event, terminate, early;
    fmi3Float64 last;
    long k2 = 0, k3 = 0;
    for (long r = 0; r < repeats; r++) {
        double t = now();
        for (long k = 0; k < steps; k++, k2++) CHECK(step2(c2, (double)k2 * h, h, fmi2True))
        printf("fmi2 %.4f\n", (now() - t) / (double)steps * 1e6);
        t = now();
        for (long k = 0; k < steps; k++, k3++)
            CHECK(step3(c3, (double)k3 * h, h, fmi3True, &event, &terminate, &early, &last))
        printf("fmi3 %.4f\n", (now() - t) / (double)steps * 1e6);
    }
    return 0;
}
