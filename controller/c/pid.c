/* The PID step of controller/pid.py: the current error counts (backward Euler), and a
   leg's integral holds while its unclamped force is past the limit and the error pushes
   it further out. */
#include <math.h>
#include "pid.h"

void mb_pid_update(double kp, double ki, double kd, double limit, int n, const double *integral,
                   const double *error, const double *error_rate, const double *feedforward, double dt,
                   double *force, double *new_integral)
{
    for (int i = 0; i < n; i++) {
        double fixed = feedforward[i] + kp * error[i] + kd * error_rate[i];
        double candidate = integral[i] + dt * error[i];
        double unclamped = fixed + ki * candidate;
        int winding = fabs(unclamped) > limit && error[i] * unclamped > 0;
        new_integral[i] = winding ? integral[i] : candidate;
        double f = fixed + ki * new_integral[i];
        force[i] = f < -limit ? -limit : (f > limit ? limit : f);
    }
}
