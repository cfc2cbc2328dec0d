#ifndef MB_MECHANISM3T_H
#define MB_MECHANISM3T_H
/* Single-state kernel of the 3T mechanism of Shen et al. 2024 ("mechanism 1"): O', the
   generalised mass matrix M, the bias forces, inverse and forward dynamics, the plant RHS
   and fixed-step RK4 / Euler, for ONE state. plant/mechanism3t/model.py (batched numpy) is the
   validated reference; plant/mechanism3t/kernel.py is the Python (cffi) face of this file.

   Units: SI throughout (m, m/s, m/s^2, N, kg, kg m^2, s). Arrays are float64, contiguous,
   row-major; the callee never allocates and never keeps a pointer.
   rho = (x_A2, y_A1, y_A3): slider positions (m); rho_dot, rho_ddot: their rates and
   accelerations; forces: actuator force on slider x_A2 along +x, on y_A1 and y_A3 along +y (N).
   p = O', the moving platform centre in frame O (m).
   mode: assembly mode, +1 or -1, the sign before the square root of eq. 11 (paper: +1).

   Every function returns an mb_m3t_status (MB_M3T_OK or the first problem found) and never
   produces NaN on its own: a non-OK status means the outputs are not meaningful (except
   where said). The codes equal the Python constants of plant.mechanism3t.kernel.

   pa: the packed parameters, MB_M3T_NPARAM doubles, = plant.mechanism3t.kernel.pack(P):
     pa[0..9]   a, b, d, e, l1, l2, l3, l4, l5, l6 (m), dimensions of paper 3.1.3
     pa[10]     g (m/s^2), gravity along -z
     pa[11..12] knee_1, knee_2: knee signs (+1.0 / -1.0) of the passive limbs I and II
     pa[13..23] (MB_M3T_M0) masses (kg) in body order: slider_2 (x_A2), slider_1 (y_A1),
                slider_3 (y_A3), b1c1, c1d1, b2c2, c2d2, b3c3, c3d3, d3e3,
                platform (platform + payload)
     pa[24..29] (MB_M3T_I0) own inertias about the swing axes through the centres
                (kg m^2) of b1c1, c1d1, b2c2, c2d2, b3c3, d3e3
   The paper's values (Mechanism3TParams.paper(), whose inertias come from Table 1 by a
   parallel-axis shift) are computed in Python; a pure C user takes them from pack(P). */

enum mb_m3t_size {
    MB_M3T_NPARAM = 30,   /* doubles in pa */
    MB_M3T_NBODY = 11,    /* bodies with a mass */
    MB_M3T_NTURN = 6,     /* bodies with a swing inertia */
    MB_M3T_M0 = 13,       /* offset of the masses in pa */
    MB_M3T_I0 = 24        /* offset of the inertias in pa */
};

enum mb_m3t_status {
    MB_M3T_OK = 0,
    MB_M3T_BAD_RHO = 1,          /* rho contains NaN or inf */
    MB_M3T_BAD_RHO_DOT = 2,      /* rho_dot contains NaN or inf */
    MB_M3T_BAD_FORCE = 3,        /* forces contain NaN or inf */
    MB_M3T_BAD_RHO_DDOT = 4,     /* rho_ddot contains NaN or inf */
    MB_M3T_BAD_MODE = 5,         /* mode is neither +1 nor -1 */
    MB_M3T_UNREACH_D3E3 = 10,    /* eq. 10-11: l6^2 - (y_A1 + d - y_A3)^2 < 0 */
    MB_M3T_UNREACH_ARCCOS = 11,  /* eq. 11: arccos argument outside [-1, 1] */
    MB_M3T_UNREACH_LIMB1 = 12,   /* limb I cannot close (eq. 8 root negative) */
    MB_M3T_UNREACH_LIMB2 = 13,   /* limb II cannot close (eq. 8 root negative) */
    MB_M3T_SING_SIN = 20,        /* output singularity: sin theta = 0 */
    MB_M3T_SING_W = 21,          /* output singularity: x - e + a + l4 cos theta = 0 */
    MB_M3T_SING_LIMB1 = 22,      /* limb I fully stretched or folded */
    MB_M3T_SING_LIMB2 = 23,      /* limb II fully stretched or folded */
    MB_M3T_SING_MASS = 24,       /* mass matrix singular */
    MB_M3T_DIVERGED = 30         /* mb_m3t_plant_step: the state is no longer finite */
};

/* O' p (3, m) of assembly mode `mode` for slider positions rho (3, m): forward_branch.
   p is written whenever rho is finite, also with an UNREACH_* status (then z is that of
   the clamped arccos). */
int mb_m3t_position(const double *pa, const double *rho, int mode, double *p);

/* Dynamics terms of one state: M (3 x 3, row-major, kg), bias (3, N) with
   slider_forces = M rho_ddot + bias, and O' p (3, m); dynamics_terms. */
int mb_m3t_terms(const double *pa, const double *rho, const double *rho_dot, int mode,
                 double *M, double *bias, double *p);

/* Inverse dynamics: forces (3, N) = M rho_ddot + bias for rho (3, m), rho_dot (3, m/s),
   rho_ddot (3, m/s^2); slider_forces. */
int mb_m3t_slider_forces(const double *pa, const double *rho, const double *rho_dot,
                         const double *rho_ddot, int mode, double *forces);

/* Forward dynamics: rho_ddot (3, m/s^2) = M^-1 (forces - bias) for rho (3, m),
   rho_dot (3, m/s), forces (3, N); forward_dynamics. */
int mb_m3t_forward_dynamics(const double *pa, const double *rho, const double *rho_dot,
                            const double *forces, int mode, double *rho_ddot);

/* Plant right-hand side: xdot (6) = (rho_dot, rho_ddot) of x (6) = (rho (m), rho_dot (m/s))
   under forces (3, N). xdot[0..2] is written whatever the status. */
int mb_m3t_rhs(const double *pa, const double *x, const double *forces, int mode, double *xdot);

/* x (6) = (rho (m), rho_dot (m/s)) advanced IN PLACE by `substeps` equal steps of dt (s)
   of classic RK4 (rk4 != 0) or explicit Euler (rk4 == 0) under held forces (3, N), with
   plant.integrators.rk4 / euler's arithmetic. On a non-OK status x holds the state at the
   start of the failing substep. */
int mb_m3t_advance_fixed(const double *pa, double *x, const double *forces, int mode,
                         int rk4, int substeps, double dt);

/* One co-simulation step of the plant (Mechanism3TPlant.doStep for RK4 / Euler):
   mb_m3t_advance_fixed, then MB_M3T_DIVERGED if the new x is not finite, then O' p (3, m)
   of the new slider positions (mb_m3t_position). x (6) in/out as above; the slider
   positions and rates are x[0..2] and x[3..5]. */
int mb_m3t_plant_step(const double *pa, double *x, const double *forces, int mode,
                      int rk4, int substeps, double dt, double *p);

/* Slider reference of paper 4.3 at time t (s): rho = centre + amplitude sin(omega t) on
   every slider (centre (3, m), amplitude (m), omega (rad/s)), with its rate and
   acceleration (3 each); plant.mechanism3t.model.paper_motion. */
void mb_m3t_paper_motion(double t, const double *centre, double amplitude, double omega,
                         double *rho, double *rho_dot, double *rho_ddot);

/* The feedforward of SliderController at time t (s): the paper_motion reference
   (ref (3, m), ref_rate (3, m/s), ref_acc (3, m/s^2)) and its inverse dynamics
   forces (3, N); the PID on top is controller/c mb_pid_update. The reference is written
   whatever the status. */
int mb_m3t_reference_forces(const double *pa, double t, const double *centre, double amplitude,
                            double omega, int mode, double *ref, double *ref_rate,
                            double *ref_acc, double *forces);

#endif
