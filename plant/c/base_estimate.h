#ifndef MB_BASE_ESTIMATE_H
#define MB_BASE_ESTIMATE_H
/* What the controller's feedforward can know of the base: an estimate of the base's pose,
   rate and acceleration (as the telescope kernel's mb_tel_base_motion gives them) from
   the antenna's axis encoders (source 0) or from an inertial sensor on the base (source 1).
   The BaseSensor FMUs (fmu_src/base_sensor_fmu.py, fmu_src/native/base_sensor_fmu.c) call
   these functions; SI (m, rad, s).

   Encoders: the angles (Az, E) quantised to encoder_resolution (round to nearest), rates
   by the backward difference of the quantised angles, accelerations by the backward
   difference of the rates, each difference through a first-order low-pass of cut-off
   rate_cutoff discretised exactly for a held input (y += (1 - exp(-2 pi fc h)) (x - y));
   rate_cutoff 0 = the plain difference. Its transfer function per stage:
   H(z) = (1 - z^-1) / h * a / (1 - (1 - a) z^-1), a = 1 - exp(-2 pi fc h).
   IMU: a gyro measuring the base's angular velocity w_B (in {B}) and an accelerometer
   measuring the base origin's acceleration (gravity taken out exactly), each with white
   noise of the given density N (square root of the two-sided PSD: per sample of step h a
   normal of standard deviation N / sqrt(h), so the integrated gyro has the angle random
   walk N sqrt(t)) plus a constant bias on every axis, in the sensor's (the base's) axes.
   Axis rates from the gyro (E' = -w_x, A' = w_y cos E + w_z sin E), accelerations by the
   filtered difference of those rates, angles from the encoders (an IMU gives no
   absolute azimuth), translation acceleration from the accelerometer. An IMU misaligned
   by R (imu_alignment) reads R w and R a for the base's w and a (gravity compensated in
   its own axes), before bias and noise; computed as v + (R - 1) v, so 0 leaves v exact. */
#include "random.h"

enum mb_bs_source { MB_BS_ENCODERS = 0, MB_BS_IMU = 1 };

typedef struct {
    int source;                   /* enum mb_bs_source */
    double encoder_resolution;    /* rad, 0 = exact angles */
    double rate_cutoff;           /* Hz, 0 = plain backward differences */
    double gyro_noise_density;    /* rad/s/sqrt(Hz) */
    double gyro_bias;             /* rad/s */
    double accel_noise_density;   /* m/s2/sqrt(Hz) */
    double accel_bias;            /* m/s2 */
    double lever_arm;             /* m, axis intersection -> base along the boresight */
    double imu_alignment[3];      /* rad, roll, pitch, yaw (as plant.rotations.rpy_matrix) of the IMU's axes
                                     in the base's: it reads a vector v of the base as R v */
} mb_bs_params;

typedef struct {
    unsigned long long rng;       /* the mb_rng's state (random.h; cffi reads headers in order) */
    double angle[2];              /* last quantised mount angles (A, E) */
    double rate[2];               /* filtered rates (A', E') */
    double acc[2];                /* filtered accelerations (A'', E'') */
} mb_bs_state;

/* 0, or 1 if a parameter is not finite, negative or the source unknown. */
int mb_bs_check(const mb_bs_params *p);

/* The encoder reading of an angle: resolution * round(angle / resolution) (resolution 0:
   the angle). */
double mb_bs_quantise(double angle, double resolution);

/* Start on the measured angles axis = (Az, E) with the true rates axis_rate = (Az', E'),
   zero acceleration, the generator seeded; writes the estimate (pose, rate, acc: 18). */
void mb_bs_start(const mb_bs_params *p, unsigned long long seed, const double *axis,
                 const double *axis_rate, const double *base_pose, const double *base_rate,
                 const double *base_acc, mb_bs_state *s, double *estimate);

/* One sample after a step h > 0: the estimate (18) from the true inputs. */
void mb_bs_step(const mb_bs_params *p, double h, const double *axis, const double *base_pose,
                const double *base_rate, const double *base_acc, mb_bs_state *s, double *estimate);
#endif
