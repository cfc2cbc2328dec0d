#ifndef MB_INSTANCE_H
#define MB_INSTANCE_H
/* The instance core every native FMU shares, whatever its FMI version (instance.c): like
   the Reference FMUs' cosimulation.c under their fmi2Functions.c and fmi3Functions.c, it
   holds the instance and everything it does, and the thin layers fmi2_layer.c and
   fmi3_layer.c map the standard's functions onto it. No FMI type appears here.

   - The layers check each call against the standard's states (their masks and their
     wording, over mbi_phase); the core makes the transitions and does the work.
   - Every line the core logs names the function the host called (`function`), so an
     FMI 3.0 host reads fmi3SetFloat64 where an FMI 2.0 one reads fmi2SetReal.
   - Log lines reach the host through the layer's mbi_logger, with the status the call
     answers and its category: Warning lines only when their category is on (or logAll),
     Discard, Error and Fatal lines always (they explain a status). */
#include <stddef.h>

#include "model.h"

/* The call's outcome, 1:1 with fmi2Status and fmi3Status (OK, Warning, Discard, Error, Fatal). */
typedef enum { MBI_OK = 0, MBI_WARNING, MBI_DISCARD, MBI_ERROR, MBI_FATAL } mbi_status;

/* The instance's state (bits, for the layers' masks of allowed states). A failed doStep
   leaves STEP_FAILED (FMI 2.0 stepFailed, FMI 3.0 StepDiscarded), a failed initialization
   INIT_FAILED (FMI 3.0's error state); FMI 2.0 counts both as step mode, failed. */
enum mbi_phase { MBI_INSTANTIATED = 1, MBI_INITIALIZATION = 2, MBI_STEP = 4, MBI_STEP_FAILED = 8,
                 MBI_TERMINATED = 16, MBI_INIT_FAILED = 32 };

/* Log categories, as the modelDescriptions declare them. */
enum { MBI_CAT_WARNING, MBI_CAT_DISCARD, MBI_CAT_ERROR, MBI_CAT_FATAL, MBI_CAT_ALL, MBI_NCAT };
extern const char *const MBI_CATEGORIES[MBI_NCAT];

/* A value reference (fmi2ValueReference and fmi3ValueReference are both 32-bit unsigned). */
typedef unsigned int mbi_vr;

/* The layer's logger: passes one line of text to the host's callback, which the layer
   keeps in env (the core's copy of the bytes given to mbi_instantiate). */
typedef void (*mbi_logger)(const void *env, const char *instance_name, mbi_status status, const char *category,
                           const char *text);

/* A line to a host before there is an instance (instantiation refused), always delivered. */
void mbi_log_host(mbi_logger logger, const void *env, const char *instance_name, mbi_status status,
                  const char *fmt, ...);
/* A line of the instance, category from the status (logStatusWarning, ..., logStatusFatal). */
void mbi_logf(mb_instance *inst, mbi_status status, const char *fmt, ...);
/* The index of a category name, or -1; switch one category (or all: -1) on or off. */
int mbi_category(const char *name);
void mbi_set_logging(mb_instance *inst, int category, int on);

/* ---------------------------------------------------------------- life cycle */
/* NULL when out of memory; env_size bytes of env are copied (the layer's logger reads them). */
mb_instance *mbi_instantiate(const char *instance_name, mbi_logger logger, const void *env, size_t env_size,
                             int logging_on);
void mbi_free_instance(mb_instance *inst);
/* The resources folder a model reads files from (mb_resources): a path ending in '/', or
   NULL; 1 when out of memory. */
int mbi_set_resources(mb_instance *inst, const char *path);

/* The instance's own state, which an FMU state holds with the variables and the model. */
typedef struct {
    double start_time;
    double time;              /* the end of the last accepted step (the last successful time) */
    double stop_time;         /* the stopTime given at setup: no step may pass it, if stop_defined */
    int failed;               /* an initialization or a step failed (kept after terminate) */
    int phase;                /* enum mbi_phase: an FMU state restores it */
    int stop_defined;
    char failure[1024];       /* "<kind> <when>: <message>" of that failure */
} mbi_core_state;
const mbi_core_state *mbi_core(const mb_instance *inst);
int mbi_phase(const mb_instance *inst);          /* mbi_core(inst)->phase */
int mbi_failed(const mb_instance *inst);         /* mbi_core(inst)->failed */

/* startTime must be finite and a stopTime, if defined, not before it (else MBI_ERROR). */
mbi_status mbi_setup_experiment(mb_instance *inst, const char *function, double start_time, int stop_defined,
                                double stop_time);
void mbi_enter_initialization(mb_instance *inst);
/* The start checks, the model's init and the outputs' check: MBI_OK and step mode, or
   MBI_ERROR with the failure logged and recorded (INIT_FAILED). */
mbi_status mbi_exit_initialization(mb_instance *inst);
/* How far a doStep's currentCommunicationPoint may lie from the FMU's time, relative to
   max(1 s, |time|): a host summing t += h drifts by ulps, a host skipping or repeating a
   step is off by h. The standards' preconditions of a doStep (t the FMU's time, h finite,
   > 0 and large enough to advance the time, the step's end not past the stopTime) are
   checked by mbi_step_refused, for both layers. */
#define STEP_TIME_TOLERANCE 1e-9
int mbi_step_refused(mb_instance *inst, const char *function, double t, double h);
/* One step from the FMU's time t by h: MBI_OK; MBI_DISCARD when the model refuses it or an
   output is not finite (everything restored to before the step, STEP_FAILED, the
   failure logged), and for every step after a failure ("refusing doStep"). */
mbi_status mbi_do_step(mb_instance *inst, double t, double h);
void mbi_terminate(mb_instance *inst);
void mbi_reset(mb_instance *inst);               /* back to the instantiated state and the start values */

/* --------------------------------------------------------------- get and set */
/* Each checks every value reference (type, and for the setters causality and state)
   before writing anything: a refused call changes nothing and logs why. A NULL array
   with a count is refused. Reading in initialization mode computes the outputs first. */
mbi_status mbi_get_real(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr, double value[]);
mbi_status mbi_get_integer(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr, int value[]);
mbi_status mbi_set_real(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr,
                        const double value[]);
mbi_status mbi_set_integer(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr,
                           const int value[]);
/* Strings: the instance's own copies (mbi_set_string copies each value; a NULL value is
   refused). What mbi_get_string returns stays valid until the variable is set again or
   the instance is freed. Strings are parameters: not part of an FMU state. */
mbi_status mbi_get_string(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr,
                          const char *value[]);
mbi_status mbi_set_string(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr,
                          const char *const value[]);
/* The setters' checks alone: 1 when mbi_set_* would accept the value references, else
   0 with the line (a layer setting several runs checks them all before setting any). */
int mbi_settable_real(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr);
int mbi_settable_integer(mb_instance *inst, const char *function, const mbi_vr vr[], size_t nvr);

/* ---------------------------------------------------------------- FMU states */
/* A state holds the whole instance (its state, time, stopTime, failure, numeric variables
   and model) as bytes; not its Strings nor what the model keeps (mb_keep: the telescope's
   replay table), which are the instance's: restoring a state into an instance given
   another table is the host's business (the model evaluates the table it holds). mbi_get_state fills *state (allocating it when NULL); the others
   refuse a state of another FMU. Serialised: a header (magic, size, model identifier,
   CRC-32 of the block) and the block; mbi_deserialize refuses any other bytes. */
typedef struct mbi_state mbi_state;
mbi_status mbi_get_state(mb_instance *inst, const char *function, mbi_state **state);
mbi_status mbi_set_state(mb_instance *inst, const char *function, const mbi_state *state);
void mbi_free_state(mbi_state **state);
mbi_status mbi_serialized_size(mb_instance *inst, const char *function, const mbi_state *state, size_t *size);
mbi_status mbi_serialize(mb_instance *inst, const char *function, const mbi_state *state, unsigned char bytes[],
                         size_t size);
mbi_status mbi_deserialize(mb_instance *inst, const char *function, const unsigned char bytes[], size_t size,
                           mbi_state **state);
#endif
