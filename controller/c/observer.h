#ifndef MB_OBSERVER_H
#define MB_OBSERVER_H
/* Per-leg disturbance observer on the controller's model (equations in observer.c). */
enum { MB_OBSERVER_STATES = 4 };
void mb_observer_start(int n, const double *length_error, double *state);
void mb_observer_update(int n, double bandwidth, double mass, double h, const double *state, const double *force_gap,
                        const double *length_error, double *estimate, double *new_state);
#endif
