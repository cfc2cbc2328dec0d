/* The stepping loop of the co-simulation master (scenarios/cosim/master.py): K macro steps of
   Jacobi or Gauss-Seidel over FMI 2.0 and FMI 3.0 co-simulation instances, called through
   cffi with the instances' own fmi2DoStep/fmi2GetReal/fmi2SetReal or fmi3DoStep/
   fmi3GetFloat64/fmi3SetFloat64, so a macro step costs the FMUs' work and no Python; the
   recorded variables read at every record point into a block of rows, so a recorded
   run's rows cost no Python either until the block is handed over.
   Plain declarations only (kernel_build.py strips preprocessor lines). */
#include <stddef.h>

/* FMI 2.0 (fmi2FunctionTypes.h): fmi2Status is an int-sized enum, fmi2Component void *,
   fmi2ValueReference unsigned int, fmi2Real double, fmi2Boolean int. */
typedef int (*cosim_do_step_fn)(void *component, double t, double h, int no_set_prior_state);
typedef int (*cosim_get_real_fn)(void *component, const unsigned int vr[], size_t nvr, double value[]);
typedef int (*cosim_set_real_fn)(void *component, const unsigned int vr[], size_t nvr, const double value[]);

/* FMI 3.0 (fmi3FunctionTypes.h): fmi3Status an int-sized enum, fmi3Instance void *,
   fmi3ValueReference uint32_t, fmi3Float64 double, fmi3Boolean bool. */
typedef int (*cosim_do_step3_fn)(void *instance, double t, double h, _Bool no_set_prior_state,
                                 _Bool *event_handling_needed, _Bool *terminate_simulation,
                                 _Bool *early_return, double *last_successful_time);
typedef int (*cosim_get_float64_fn)(void *instance, const unsigned int vr[], size_t nvr, double values[], size_t n_values);
typedef int (*cosim_set_float64_fn)(void *instance, const unsigned int vr[], size_t nvr, const double values[], size_t n_values);
typedef int (*cosim_get_derivatives_fn)(void *instance, const unsigned int vr[], size_t nvr, const int orders[],
                                        double values[], size_t n_values);

/* An FMI 3.0 instance's output derivatives of order o (1, 2), read after each of its
   steps with fmi3GetOutputDerivatives: the variables holding read elements that have
   them, in one call into values, element j of them into y_d[o-1][dst[j]]. */
typedef struct {
    const unsigned int *vr;
    size_t n_vr;
    const int *orders;             /* n_vr times o */
    double *values;
    size_t n_values;
    const size_t *src;             /* element j is values[src[j]] ... */
    const size_t *dst;             /* ... and goes to y_d[o-1][dst[j]] */
    size_t n;
} cosim_derivatives;

/* An FMI 3.0 instance's side of the exchange: the master's element lists (cosim_fmu's
   read_vr/write_vr, as FMI 2.0 numbers the elements) lie in whole FMI 3 variables (an
   array of 6 is one value reference): those are read/written in one call into a buffer
   of all their values, element j at buffer[index[j]]. */
typedef struct {
    cosim_do_step3_fn do_step;
    cosim_get_float64_fn get_float64;
    cosim_set_float64_fn set_float64;
    const unsigned int *read_vr;   /* the variables holding cosim_fmu's read elements */
    size_t n_read_vr;
    size_t n_read_values;
    const size_t *read_index;      /* cosim_fmu's read element j is read_values[read_index[j]] */
    double *read_values;
    const unsigned int *write_vr;  /* the variables holding its write elements */
    size_t n_write_vr;
    size_t n_write_values;
    const size_t *write_index;
    double *write_values;
    int write_partial;             /* some of those values are not written: read them first */
    cosim_get_derivatives_fn get_derivatives;
    cosim_derivatives derivatives[2];   /* orders 1 and 2 (n = 0: none read) */
} cosim_fmi3;

typedef struct {
    void *component;
    cosim_fmi3 *fmi3;              /* NULL: an FMI 2.0 instance, stepped by the three below */
    cosim_do_step_fn do_step;
    cosim_get_real_fn get_real;
    cosim_set_real_fn set_real;
    const unsigned int *read_vr;   /* its connected outputs, read into y[read_at ...] */
    size_t n_read;
    size_t read_at;
    const unsigned int *write_vr;  /* its connected inputs, input j fed by y[write_from[j]] */
    size_t n_write;
    const size_t *write_from;
    const double *write_half;      /* Gauss-Seidel: 0.5 where input j's source steps after it, else 0 */
    double *write_buf;             /* n_write values, the last ones written */
    double time;                   /* the t of its last doStep call */
} cosim_fmu;

/* One instance's recorded elements, read at each record point in one call (FMI 2.0
   fmi2GetReal of the elements; FMI 3.0 fmi3GetFloat64 of the variables holding them) into
   values; element j is values[index[j]] and goes to column column[j] of the row. */
typedef struct {
    size_t fmu;                    /* which of cosim_master's fmus */
    const unsigned int *vr;
    size_t n_vr;
    double *values;
    size_t n_values;
    const size_t *index;
    const size_t *column;
    size_t n;
} cosim_record;

enum cosim_call { COSIM_SET_REAL = 0, COSIM_DO_STEP = 1, COSIM_GET_REAL = 2 };

typedef struct {
    cosim_fmu *fmus;               /* in stepping order */
    size_t n_fmus;
    const size_t *read_order;      /* Jacobi: the fmus read after every step, in this order */
    size_t n_read_order;
    double *y;                     /* all connected outputs */
    double *y_prev;                /* their values one macro step earlier */
    double *y_start;               /* scratch, n_y (Gauss-Seidel: y at the start of the step) */
    size_t n_y;
    int gauss_seidel;
    int extrapolate;               /* of held inputs: 0 none, 1 linear, 2 derivatives (linear where y_order is 0) */
    const int *y_order;            /* per y: the highest order of derivative its source gives (0, 1, 2) */
    double *y_d1;                  /* per y: its first and second time derivatives at its time */
    double *y_d2;
    double t0;
    double h;
    const cosim_record *records;   /* the recorded instances, read in this order */
    size_t n_records;
    long every;                    /* a row after each step k with (k + 1) % every == 0 (0: none) */
    double *rows;                  /* capacity x n_columns, row-major: the rows of the last call */
    size_t n_columns;
    size_t capacity;
    size_t n_rows;
    int failed_fmu;                /* on a status above Warning: which fmu, call, status */
    int failed_call;
    int failed_status;
} cosim_master;

/* Macro steps k .. k+count-1, each followed by its row where one is due. Returns how many
   steps completed: fewer when a call answered above Warning (failed_fmu >= 0; the step
   whose row failed counts as completed) or when the next row would not fit the rows. */
long cosim_steps(cosim_master *m, long k, long count);
/* One row now (the run's first, before stepping): 0, or 1 when a read failed. */
int cosim_record_row(cosim_master *m);
