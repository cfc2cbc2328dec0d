#ifndef MB_TOLERANCE_H
#define MB_TOLERANCE_H
/* Pose errors of perturbed hexapods, a batch at once: the geometric tolerance budget's
   kernel (plant/hexapod/tolerance.py holds the model and names the inputs).

   Each sample k has its own commanded pose, its own geometry and its own leg errors. The
   controller drives leg i to the nominal inverse kinematics' length lc_i of the commanded
   pose; the real leg then measures
       l_i = l0_i + offset_i + (1 + scale_i) (lc_i - l0_i + homing_i) + play_i
   and the real pose is the forward kinematics of the perturbed joints (B_i + dB_i, a_i + da_i)
   with those lengths, by Newton's iterations from the commanded pose.

   base_joints, platform_joints (6, 3)  the nominal joints B_i in {B}, a_i in {P} [m]
   home_lengths (6)   the nominal leg lengths l0 at home [m]
   samples (n, 66)    per sample: offset (6) [m], scale (6) [1], homing (6) [m], dB (6, 3) [m],
                      da (6, 3) [m], then the 12 joints' plays, not read here (play carries
                      them): tolerance.INPUT_NAMES' order
   play (n, 6)        the clearance's signed change of each leg's length [m], or NULL (none)
   poses (n, 6)       commanded poses [m, rad]
   tol [m], max_iter  Newton stops when every leg's length is within tol
   errors (n, 6)      written: real pose - commanded pose [m, rad]
   Returns -1 when every sample converged, else the first sample k that did not (diverged,
   singular or not within max_iter); its errors row is then NaN and *residual holds its
   largest leg-length residual [m]; every other sample is still solved. */
int mb_tolerance_pose_errors(int n, const double *base_joints, const double *platform_joints,
                             const double *home_lengths, const double *samples, const double *play,
                             const double *poses, double tol, int max_iter, double *errors, double *residual);

#endif
