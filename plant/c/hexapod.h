#ifndef MB_HEXAPOD_H
#define MB_HEXAPOD_H
/* Kane kernel of the 6-UPS hexapod: M, h, J per state, the ID / FD solves, the fixed-step
   integrator of the plant FMU and the leg read-out (derivation in plant/hexapod/model.py).

   Generalised speeds u = (v, w) of the platform frame {P} relative to the base frame {B},
   expressed in {B}:  M du/dt + h = J^T F.  SI units throughout (m, rad, s, kg, N).
   Arrays are double, row-major and contiguous; "(n, 6)" means n rows of 6.

   Parameters (what plant.hexapod.model.StewartParams holds, so an FMU can keep them as arrays):
     base_joints      (6, 3)  base joint positions B_j in {B} [m]
     platform_joints  (6, 3)  platform joint positions P_j in {P} [m]
     data             (MB_HEXAPOD_NDATA) = StewartParams.kernel_data:
                      [m_p, I_p(3), m_f, l_f, m_m, l_m, I_axial, I_transverse, g, c_p(3)]
                      platform mass [kg], platform principal inertias about its centre in
                      {P} [kg m^2], cylinder mass [kg], cylinder COM distance from the base
                      joint [m], rod mass [kg], rod COM distance from the platform joint [m],
                      leg axial and transverse inertia (cylinder + rod) [kg m^2], gravity
                      [m/s^2] (acts along -z of the world frame {W}), the platform's
                      centre of mass in {P} [m] (0: at o_P).
   A pose is [x, y, z, roll, pitch, yaw] of {P} in {B} [m, rad] (R = Rz(yaw) Ry(pitch)
   Rx(roll)); a base pose/rate/acc the same of {B} in {W}, its time derivatives.
   Leg j runs from B_j to the platform joint p + R P_j; a leg force > 0 extends it [N]. */

enum { MB_HEXAPOD_NDATA = 14 };

/* What mb_hexapod_kane solves for. */
enum mb_hexapod_solve {
    MB_HEXAPOD_ID = 0,     /* inverse dynamics: leg forces from accelerations */
    MB_HEXAPOD_FD = 1,     /* forward dynamics: accelerations from leg forces */
    MB_HEXAPOD_TERMS = 2   /* M, h, J, leg lengths and rates and det J only */
};

/* How much base motion the kernel keeps. */
enum mb_hexapod_base_mode {
    MB_HEXAPOD_BASE_NONE = 0,     /* fixed, upright base: base arrays are not read (may be NULL) */
    MB_HEXAPOD_BASE_GRAVITY = 1,  /* base attitude tilts gravity only: base_pose read */
    MB_HEXAPOD_BASE_FULL = 2      /* base pose, rate and acceleration all read */
};

/* Status of mb_hexapod_advance_fixed. */
enum mb_hexapod_status {
    MB_HEXAPOD_OK = 0,
    MB_HEXAPOD_BAD_INPUT = 1,  /* an input is NaN or inf: x untouched */
    MB_HEXAPOD_DIVERGED = 2,   /* the state became non-finite or |position| > 100 m */
    MB_HEXAPOD_STROKE = 3,     /* a leg length left [bounds[0], bounds[1]] */
    MB_HEXAPOD_WORK = 4        /* mb_hexapod_advance_controlled needed more than max_substeps tries */
};

/* Batched kernel over n states; mirrors plant.hexapod.kernel.kane.
   pose       (n, 6)  platform pose [m, rad]
   rate       (n, 6)  RPY-angle pose rates [m/s, rad/s], or the twist (v, w) [m/s, rad/s]
                      in {B} when twist_speeds
   arg        (n, 6)  ID: pose accelerations [m/s^2, rad/s^2] (the twist acceleration
                      when twist_speeds); FD: leg forces [N]; TERMS: not read (may be NULL)
   base_pose, base_rate, base_acc  (n, 6)  base motion in {W}, read per base_mode
   base_mode  enum mb_hexapod_base_mode;  legs  0: massless legs, else legs have mass
   twist_speeds  0: rate/arg/out use RPY-angle rates, else the twist (v, w)
   solve      enum mb_hexapod_solve
   Outputs (all written for every solve, except out):
   M (n, 6, 6) mass matrix [kg, kg m, kg m^2];  h (n, 6) bias [N, N m];
   J (n, 6, 6) leg Jacobian (rows: unit leg axis s, rho x s);  ldot (n, 6) leg rates [m/s];
   length (n, 6) leg lengths [m];  det (n) det J [m^3];
   out (n, 6) ID: leg forces [N]; FD: pose accelerations (twist acceleration when
   twist_speeds); TERMS: not written (may be NULL). */
void mb_hexapod_kane(const double *base_joints, const double *platform_joints, const double *data,
                     int n, const double *pose, const double *rate, const double *arg,
                     const double *base_pose, const double *base_rate, const double *base_acc,
                     int base_mode, int legs, int twist_speeds, int solve,
                     double *M, double *h, double *J, double *ldot, double *length,
                     double *out, double *det);

/* mb_hexapod_kane after looking for NaN or inf in the six state arrays (each n x 6; a
   NULL one is skipped), its outputs in one block: work (97 n) holds M, h, J, ldot, length,
   out and det one after the other. Returns 0 when all inputs are finite, else a bitmask
   (bit k set for array k of pose, rate, arg, base_pose, base_rate, base_acc), and then
   writes nothing. The Python API's call: one check in one pass, one output pointer. */
int mb_hexapod_kane_checked(const double *base_joints, const double *platform_joints, const double *data,
                            int n, const double *pose, const double *rate, const double *arg,
                            const double *base_pose, const double *base_rate, const double *base_acc,
                            int base_mode, int legs, int twist_speeds, int solve, double *work);

/* mb_hexapod_kane with two more terms (both off when 0 / NULL, then bit for bit the same):
   reflected_mass m_r [kg]: motor rotor and screw inertia reflected along every leg
     (J_rotor (2 pi / pitch)^2), kinetic energy m_r ld_j^2 / 2 per leg: M += m_r J^T J and
     h += m_r J^T (dJ/dt u). The rotor's spin coupling to the leg's own rotation
     (J_rotor 2 pi / pitch * axial angular acceleration) is left out: ~1e-3 N here.
   wrench (n, 6) or NULL: external force [N] and moment [N m] on the platform at {P}'s
     origin, in {B}: M du + (h - W) = J^T F, so h is written with -W in it. */
void mb_hexapod_kane_ext(const double *base_joints, const double *platform_joints, const double *data,
                         int n, const double *pose, const double *rate, const double *arg,
                         const double *base_pose, const double *base_rate, const double *base_acc,
                         int base_mode, int legs, int twist_speeds, int solve, double reflected_mass,
                         const double *wrench, double *M, double *h, double *J, double *ldot,
                         double *length, double *out, double *det);

/* The electromechanical leg actuator (motor + ball screw), one set for all six legs:
   act (MB_ACTUATOR_NDATA) = [bandwidth, reflected_mass, coulomb, viscous,
   friction_velocity, force_limit]:
     bandwidth [Hz]          0: the motor force is the command at once; > 0: a first-order
                             force loop per leg, dF/dt = 2 pi bandwidth (F_cmd - F), whose
                             six forces F are states x[12..17]
     reflected_mass [kg]     see mb_hexapod_kane_ext
     coulomb [N], viscous [N s/m], friction_velocity [m/s]: screw friction
                             F_fric = coulomb tanh(ld / friction_velocity) + viscous ld,
                             opposing the leg rate ld (0, 0: none; friction_velocity > 0)
     force_limit [N]         0: none; > 0: the command is clipped to +-force_limit
   The force delivered to leg j is F_j (or the clipped command) - F_fric(ld_j).
   All zero: the ideal actuator of mb_hexapod_advance_fixed, bit for bit. */
enum { MB_ACTUATOR_NDATA = 6 };
enum mb_actuator_field {
    MB_ACT_BANDWIDTH = 0, MB_ACT_REFLECTED_MASS = 1, MB_ACT_COULOMB = 2, MB_ACT_VISCOUS = 3,
    MB_ACT_FRICTION_VELOCITY = 4, MB_ACT_FORCE_LIMIT = 5
};

/* mb_hexapod_rhs with the actuator act (or NULL: ideal) and an external wrench (6, or NULL):
   x is (12) or, with a bandwidth, (18) = [pose, twist, motor forces]; command (6) the
   commanded leg forces [N]; dx as x; force (6, or NULL) receives the delivered leg forces. */
double mb_hexapod_rhs_actuated(const double *base_joints, const double *platform_joints, const double *data,
                               const double *act, const double *x, const double *command, const double *wrench,
                               const double *base0, double t0, double t, int base_mode, int legs, double *dx,
                               double *force);

/* dx/dt of one state x (12) = [pose, twist (v, w) in {B}] under leg forces (6) [N],
   with the base extrapolated from base0 (3, 6) = [base pose, rate, acc] at time t0 [s] to
   time t [s] (second-order Taylor; base0 is not read for BASE_NONE and may be NULL). Writes dx (12) = [pose rates (RPY rates), twist
   acceleration] and returns |det J| [m^3]; mirrors plant.hexapod.kernel.rhs. */
double mb_hexapod_rhs(const double *base_joints, const double *platform_joints, const double *data,
                      const double *x, const double *forces, const double *base0, double t0, double t,
                      int base_mode, int legs, double *dx);

/* Advance x (12) = [pose, twist] in place over [t0, t0 + h] [s] by `substeps` equal steps
   of classic RK4 (rk4 != 0) or explicit Euler, inputs held over the step:
   inputs  (4, 6) = leg forces [N], base pose, base rate, base acc (in {W})
   bounds  (2, 6) = lowest and highest leg lengths allowed [m] (the stroke)
   outputs (3, 6) = leg lengths [m], leg rates [m/s], pose rates at t0 + h (written when
                    the status is OK or STROKE)
   *det_min = the smallest |det J| met over all stages [m^3] (0 on BAD_INPUT).
   Returns enum mb_hexapod_status; mirrors plant.hexapod.kernel.advance_fixed. */
int mb_hexapod_advance_fixed(int rk4, int substeps, const double *base_joints,
                             const double *platform_joints, const double *data, double *x,
                             const double *inputs, double t0, double h, int base_mode, int legs,
                             const double *bounds, double *outputs, double *det_min);

/* mb_hexapod_advance_fixed with the actuator act (see above; all zero = advance_fixed):
   x (12) or, with a bandwidth, (18) = [pose, twist, motor forces];
   inputs (5, 6) = commanded leg forces [N], base pose, rate, acc, and the external
                   wrench on the platform [N, N m] in {B} (all zero: no wrench term)
   outputs (4, 6) = leg lengths, leg rates, pose rates and the delivered leg forces [N]. */
int mb_hexapod_advance_actuated(int rk4, int substeps, const double *base_joints, const double *platform_joints,
                                const double *data, const double *act, double *x, const double *inputs,
                                double t0, double h, int base_mode, int legs, const double *bounds,
                                double *outputs, double *det_min);

/* mb_hexapod_advance_actuated with error-controlled substeps: classic RK4 on [pose, twist]
   over substeps of at most max_step [s], each accepted when the embedded third-order
   estimate of its pose error (x + dt/6 (k1 + 2 k2 + 2 k3 + k5), k5 the pose rates at the
   new state: kinematics, no dynamics) is at most tol [m for positions, rad for angles];
   the next substep from the usual controller for a local error of order 4 (within 0.2x
   and 4x, at most max_step), the first one min(h, max_step). The lag's motor forces
   x[12..17] (with a bandwidth) are integrated exactly: the command is held over the step,
   so F(t) = F_cmd + (F(t0) - F_cmd) exp(-2 pi bandwidth (t - t0)) at every stage.
   A rejected substep's retry starts from the rates it already has (k1 at the same state).
   counts (2) = substeps accepted, rejected. More than max_substeps tries: MB_HEXAPOD_WORK,
   x untouched. Otherwise as mb_hexapod_advance_actuated. */
int mb_hexapod_advance_controlled(double tol, double max_step, int max_substeps, const double *base_joints,
                                  const double *platform_joints, const double *data, const double *act, double *x,
                                  const double *inputs, double t0, double h, int base_mode, int legs,
                                  const double *bounds, double *outputs, double *det_min, int *counts);

/* Kinematic read-out of x (12) = [pose, twist]: outputs (3, 6) = leg lengths [m], leg
   rates [m/s], pose rates (velocity [m/s], RPY rates [rad/s]). */
void mb_hexapod_leg_kinematics(const double *base_joints, const double *platform_joints,
                               const double *x, double *outputs);

/* Inverse dynamics of one state, for a controller (no scratch buffers needed):
   pose, pose_rate (RPY rates), pose_acc (RPY accelerations)  (6) each
   base_pose, base_rate, base_acc  (6) each, read per base_mode (may be NULL for NONE)
   legs  0: massless legs.  Writes forces (6) [N], length (6) [m], ldot (6) [m/s];
   returns det J [m^3] (near 0: singular pose, forces then unreliable or NaN). */
double mb_hexapod_inverse_dynamics(const double *base_joints, const double *platform_joints,
                                   const double *data, const double *pose, const double *pose_rate,
                                   const double *pose_acc, const double *base_pose,
                                   const double *base_rate, const double *base_acc, int base_mode,
                                   int legs, double *forces, double *length, double *ldot);

/* One state's inverse dynamics as a per-step caller sets it up: the hexapod (as for
   mb_hexapod_kane), the fidelity, three output buffers of 6 doubles, fixed once, and
   the six inputs of 6 doubles (pose, pose_rate, pose_acc, base_pose, base_rate,
   base_acc), repointed only when the caller's arrays change. */
struct mb_hexapod_state_id {
    const double *base_joints, *platform_joints, *data;
    int base_mode, legs;
    double *forces, *length, *ldot;
    const double *state[6];
};

/* mb_hexapod_inverse_dynamics of the set-up state: det J, the outputs written. A call
   from Python converts one argument instead of 14. */
double mb_hexapod_state_inverse_dynamics(const struct mb_hexapod_state_id *setup);

#endif
