#ifndef MB_OBSERVER_H
#define MB_OBSERVER_H
/* Per-leg disturbance observer on the controller's model (equations in observer.c). */
enum { MB_OBSERVER_STATES = 4 };
void mb_observer_start(int n, const double *length_error, double *state);
/* The observer's leg-space mass matrix out (n x n, row-major) [kg]: leg_space 0: mass I (one
   scalar for every mode); else model (the controller's leg-space mass matrix) + (mass - its mean
   diagonal) I: the model's mode shapes and spread, mass its mean diagonal. */
void mb_observer_mass(int n, int leg_space, double mass, const double *model, double *out);
void mb_observer_update(int n, double bandwidth, const double *mass, double h, const double *state, const double *force_gap,
                        const double *length_error, double *estimate, double *new_state);
#endif
