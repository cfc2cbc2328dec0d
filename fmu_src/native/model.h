#ifndef MB_MODEL_H
#define MB_MODEL_H
/* What one model file (hexapod_plant_fmu.c, telescope_fmu.c, ...) gives the instance core
   shared by the FMI 2.0 and FMI 3.0 layers (instance.c), and what the core gives it back.

   Every variable lives in one of two arrays indexed by value reference: r[vr] for Reals,
   i[vr] for Integers (the vr namespace is shared, as pythonfmu numbers them); vector
   elements name[1..n] have consecutive vrs, so a model passes &r[VR_name] to a kernel.
   The variable table (names, types, causalities, starts, ranges) is generated from the
   pythonfmu FMU at build time (fmu_src/native_build.py) into <modelIdentifier>_vars.h.
   String parameters (the telescope's replay_table) live apart, in memory the core owns per
   instance (mb_string), outside the FMU state, as what a model reads from them (the
   replay table: mb_keep). The model keeps its own state in a plain struct of model_size
   bytes, so the core saves, restores and serialises an FMU state as bytes; a pointer in it
   (the telescope's to its table) is set again from mb_kept at every init and step. */
#include <math.h>
#include <stddef.h>

enum mb_type { MB_REAL = 0, MB_INTEGER = 1, MB_STRING = 2 };   /* a String starts at "" */
enum mb_causality { MB_PARAMETER = 0, MB_INPUT = 1, MB_OUTPUT = 2, MB_LOCAL = 3 };

typedef struct {
    const char *name;
    const char *unit;  /* "" when none */
    int type;          /* enum mb_type */
    int causality;     /* enum mb_causality */
    double start;
    int has_min, has_max;
    double min, max;
    int n_allowed;     /* > 0: an Integer whose range has gaps takes only these values */
    int allowed[4];
} mb_var;

typedef struct mb_instance mb_instance;

typedef struct {
    const char *identifier;
    const char *guid;
    int nvars;
    const mb_var *vars;
    size_t model_size;
    /* Bytes at the start of the model struct that init writes and doStep only reads (the
       Wind's gust components; 0 for most): a doStep's backup, what a refused step restores,
       leaves them out (instance.c, step_bytes). A step must not write them. */
    size_t step_fixed;
    /* exitInitializationMode: outputs at the start time from the parameters and inputs.
       Returns 0, or 1 after mb_error. */
    int (*init)(mb_instance *inst, double *r, int *i, void *model, double start_time);
    /* doStep(t, h): returns 0 (accepted), or 1 after mb_error (the core answers
       Discard and restores r, i and the model to their state before the step). */
    int (*step)(mb_instance *inst, double *r, int *i, void *model, double t, double h);
} mb_model_info;

extern const mb_model_info MB_MODEL;

/* Record the failure of init/step: kind names it as the Python FMU's exception class
   does (InvalidInputError, StrokeError, ...); the core adds when it happened and logs
   it at error level. */
void mb_error(mb_instance *inst, const char *kind, const char *fmt, ...);

/* The work bound of one doStep: a model integrating on substeps takes at most this many
   (the plant's RK4 substep costs ~1-3 us, so a doStep stays within seconds). A longer
   step is refused with Discard and a line saying how many substeps it would need:
   a 1e6 s step at max_step 1e-3 s would otherwise run 1e9 substeps for hours, and
   their count overflows an int, so the plant would integrate nothing and answer OK. */
#define MB_MAX_SUBSTEPS 1000000
/* A String variable's value (never NULL; "" until set). Valid until it is set again. */
const char *mb_string(const mb_instance *inst, int vr);
/* The FMU's resources folder as a file system path ending in '/' (FMI 2.0's
   fmuResourceLocation file URI decoded, FMI 3.0's resourcePath), or NULL when the host
   gave none. */
const char *mb_resources(const mb_instance *inst);
/* Memory the model keeps per instance outside the FMU state (malloc'd; the core frees
   the one kept before, and the last in freeInstance), and the one kept now (or NULL). */
void mb_keep(mb_instance *inst, void *memory);
void *mb_kept(const mb_instance *inst);

/* A warning log line (category logStatusWarning). */
void mb_warning(mb_instance *inst, const char *fmt, ...);

/* v as Python's repr(float) writes it (shortest round trip, "0.0", "1e-05"), into buf
   (at least 32 chars); returns buf. For messages worded as the Python FMUs word them. */
const char *mb_repr(double v, char *buf);

/* The checks of controller.pid.PIDGains (gains finite and >= 0, force_limit finite and
   > 0): 0, or 1 after mb_error naming the gain. Both native controllers use it
   (model_checks.c). */
int mb_check_pid_gains(mb_instance *inst, double kp, double ki, double kd, double force_limit);

/* The plants' integrator parameter (an index of INTEGRATOR_NAMES; radau is the pythonfmu
   FMU's alone) and max_step > 0: 0, or 1 after mb_error. Both native plants use it. */
int mb_check_integrator(mb_instance *inst, const char *model, int integrator, int n_integrators, int radau,
                        double max_step);

/* "a, b" list of the names whose row of `width` values in `rows` holds NaN or inf,
   written into out (size n); returns the number of such rows. */
int mb_nonfinite_rows(int nrows, int width, const double *rows, const char *const *names,
                      char *out, size_t n);

/* substeps = ceil(h / max_step) (at least 1), computed in double: 0, or 1 after mb_error
   (WorkBoundError) when it passes MB_MAX_SUBSTEPS. Every model with substeps uses it; here
   (not in a layer) with the models' other shared code. */
static inline int mb_substeps(mb_instance *inst, double h, double max_step, int *substeps)
{
    char hb[32], mb[32];
    double n = ceil(h / max_step - 1e-9);   /* a double: no int overflow, whatever h and max_step */
    if (!(n <= MB_MAX_SUBSTEPS)) {
        mb_error(inst, "WorkBoundError", "a step of %s s needs %.3g substeps of at most %s s, more than the %d a "
                 "doStep may take: take shorter communication steps", mb_repr(h, hb), n, mb_repr(max_step, mb),
                 MB_MAX_SUBSTEPS);
        return 1;
    }
    *substeps = n > 1 ? (int)n : 1;
    return 0;
}
#endif
