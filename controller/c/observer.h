#ifndef MB_OBSERVER_H
#define MB_OBSERVER_H
/* Per-leg disturbance observer on the controller's model (equations in observer.c). */
enum { MB_OBSERVER_STATES = 4, MB_OBSERVER_MAX_LEGS = 6 };
void mb_observer_start(int n, const double *length_error, double *state);
/* The observer's leg-space mass matrix out (n x n, row-major) [kg]: leg_space 0: mass I (one
   scalar for every mode); else model (the controller's leg-space mass matrix) + (mass - its mean
   diagonal) I: the model's mode shapes and spread, mass its mean diagonal. */
void mb_observer_mass(int n, int leg_space, double mass, const double *model, double *out);
void mb_observer_update(int n, double bandwidth, const double *mass, double h, const double *state, const double *force_gap,
                        const double *length_error, double *estimate, double *new_state);
/* mb_observer_update in two parts, bit for bit the same: the constants of one bandwidth, mass
   (n <= MB_OBSERVER_MAX_LEGS) and step, then the update over them. A caller stepping with the same ones (the
   native LegController) keeps the first: an exp, a sine, a cosine and n^2 divisions a step. */
typedef struct {
    double bandwidth, h;                  /* what they were made for */
    double a11, a12, a21, a22, b1, b2;    /* the zero-order-hold Q filter: x <- A x + b u */
    double mass_h2[36];                   /* mass / h^2, n x n (MB_OBSERVER_MAX_LEGS^2) */
} mb_observer_gains;
void mb_observer_make_gains(int n, double bandwidth, const double *mass, double h, mb_observer_gains *g);
void mb_observer_step(int n, const mb_observer_gains *g, const double *state, const double *force_gap,
                      const double *length_error, double *estimate, double *new_state);
#endif
