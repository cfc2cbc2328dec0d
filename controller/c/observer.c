/* Disturbance observer per leg, on the controller's own model of the leg.

   The controller's model says the leg force f_model(reference) makes the platform follow
   the reference. A leg that moves off it by e = l_measured - l_reference needs M e'' more
   (M: the leg-space mass matrix, reflected mass included: ``mass``, n x n; mb_observer_mass
   forms it, one scalar on the diagonal or the model's matrix). What
   the leg really pushes with is f_measured (the load cell). So the force the leg got from
   elsewhere (wind, friction the model lacks; leg space, + extends) is
       d = f_model(ref) + M e'' - f_measured,
   made proper by a second-order low-pass Q(s) = w^2 / (s^2 + 2 zeta w s + w^2),
   w = 2 pi bandwidth, zeta = 1/sqrt(2) (Butterworth: no overshoot of |Q|). Sampled every
   step h, with the second difference for e'' (centred one step back; a held e through
   Q s^2 would add a false damping M w^2 h / 2 to the leg):
       u_k = g_k + M (e_k - 2 e_{k-1} + e_{k-2}) / h^2,   g = f_model(ref) - f_measured (``force_gap``)
   (with M the plant's own matrix, M e'' + f_model - f_measured is the external leg force exactly,
   every mode's; a scalar M leaves (M - M_plant) e'' in it, which sets the lightest mode's margin)
       x' = [[0, 1], [-w^2, -2 zeta w]] x + [0, w^2] u,   d_hat = x1,
   with u held over the step (zero-order hold, exact: the exponential in closed form for the
   complex poles). The estimate of step k is the state before it: u_k acts from the next
   step, so the load cell does not feed through to the command. The controller subtracts
   d_hat from its command (the classical disturbance observer: u = u_c - d_hat). ``state`` holds (x1, x2, e_{k-1}, e_{k-2}) of leg i at [4 i ..]. */
#include <math.h>
#include "observer.h"

void mb_observer_start(int n, const double *length_error, double *state)
{
    for (int i = 0; i < n; i++) {
        state[4 * i] = state[4 * i + 1] = 0.0;
        state[4 * i + 2] = state[4 * i + 3] = length_error[i];
    }
}

void mb_observer_mass(int n, int leg_space, double mass, const double *model, double *out)
{
    double mean = 0.0;
    for (int i = 0; i < n; i++) mean += model[i * n + i];
    mean /= n;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++)
            out[i * n + j] = leg_space ? model[i * n + j] + (i == j ? mass - mean : 0.0) : (i == j ? mass : 0.0);
}

void mb_observer_make_gains(int n, double bandwidth, const double *mass, double h, mb_observer_gains *g)
{
    const double zeta = 0.7071067811865476, w = 6.283185307179586 * bandwidth, w2 = w * w;
    double sigma = -zeta * w, wd = w * sqrt(1.0 - zeta * zeta), decay = exp(sigma * h);
    double c = cos(wd * h), s = sin(wd * h) / wd;
    /* Ad = e^{sigma h} (c I + s (A - sigma I)), A = [[0, 1], [-w^2, -2 zeta w]] */
    g->a11 = decay * (c - s * sigma);
    g->a12 = decay * s;
    g->a21 = -decay * s * w2;
    g->a22 = decay * (c + s * (-2.0 * zeta * w - sigma));
    /* Bd = A^-1 (Ad - I) (0, w^2), A^-1 = [[-2 zeta / w, -1 / w^2], [1, 0]] */
    double v1 = g->a12 * w2, v2 = (g->a22 - 1.0) * w2;
    g->b1 = -2.0 * zeta * v1 / w - v2 / w2;
    g->b2 = v1;
    double h2 = h * h;
    for (int k = 0; k < n * n; k++) g->mass_h2[k] = mass[k] / h2;
    g->bandwidth = bandwidth;
    g->h = h;
}

void mb_observer_step(int n, const mb_observer_gains *g, const double *state, const double *force_gap,
                      const double *length_error, double *estimate, double *new_state)
{
    double acc[n];   /* every leg's second difference first: each leg's u reads them all */
    for (int j = 0; j < n; j++) acc[j] = length_error[j] - 2.0 * state[4 * j + 2] + state[4 * j + 3];
    for (int i = 0; i < n; i++) {
        const double *x = state + 4 * i;
        double *y = new_state + 4 * i;
        double u = 0.0;   /* a diagonal M: mass / h^2 times the leg's own, as one scalar gives it */
        for (int j = 0; j < n; j++) u += g->mass_h2[i * n + j] * acc[j];
        u = force_gap[i] + u;
        estimate[i] = x[0];
        y[0] = g->a11 * x[0] + g->a12 * x[1] + g->b1 * u;
        y[1] = g->a21 * x[0] + g->a22 * x[1] + g->b2 * u;
        y[3] = x[2];
        y[2] = length_error[i];
    }
}

void mb_observer_update(int n, double bandwidth, const double *mass, double h, const double *state, const double *force_gap,
                        const double *length_error, double *estimate, double *new_state)
{
    mb_observer_gains g;
    mb_observer_make_gains(n, bandwidth, mass, h, &g);
    mb_observer_step(n, &g, state, force_gap, length_error, estimate, new_state);
}
