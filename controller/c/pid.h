#ifndef MB_PID_H
#define MB_PID_H
/* Per-leg PID update with conditional-integration anti-windup (controller/pid.py says why). */
void mb_pid_update(double kp, double ki, double kd, double limit, int n, const double *integral,
                   const double *error, const double *error_rate, const double *feedforward, double dt,
                   double *force, double *new_integral);
#endif
