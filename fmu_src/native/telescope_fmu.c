/* Telescope, native: the variables of fmu_src/telescope_fmu.py over the telescope
   kernel (plant/c/telescope.h, mb_tel_fmu_rows). The 40 outputs at a communication point
   are the kernel's row at that time; the time is formed as the Python FMU forms it
   (block start + h * index over blocks of BLOCK points, a new block off the grid), so the
   two agree bit for bit.

   Profile replay reads its table from replay_table (a path, or resource:<name> in the
   FMU's resources folder): a prepared replay table (plant/telescope/replay.py
   write_prepared: the smoothing spline the kit made from a log, checked there against the
   drives' limits), read at initialization, checked (magic, version, size, finite,
   increasing knots, its smoothing time equal to replay_smoothing) and kept per instance
   outside the FMU state (mb_keep); the profile's pointers to it are set again at every
   init and step, so a restored state evaluates this instance's table. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "Telescope_vars.h"
#include "telescope.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif
#define SERVO_MAX_WH 0.05   /* w h of one servo RK4 substep, as plant/c/telescope.c takes it */

typedef struct {
    mb_tel_params params;
    mb_tel_profile profile;
    double block_t, block_h;
    int servo;               /* servo_bandwidth > 0 */
    double command[6];       /* command axes at the last communication point */
    double state[4];         /* actual axes (A, A', E, E') */
    mb_tel_support support;  /* the flexible feed support (telescope.h) */
    int support_on;          /* a mode's frequency > 0 */
    double support_state[6];
} Model;

/* A prepared replay table (plant/telescope/replay.py PREPARED_*): "MBREPLAY", version,
   knot count n, smoothing time, then n knots and (n - 1) x 8 coefficients, little-endian
   doubles. Kept as one block: this header, then the arrays. */
#define PREPARED_VERSION 1u
#define PREPARED_HEADER 24
#define PREPARED_MAX_KNOTS 100000000u
typedef struct {
    int n;
    double smoothing;
    double *t, *coef;
} Table;

/* replay_table's file read and checked into a kept Table: 0, or 1 after mb_error. */
static int load_table(mb_instance *inst, const char *name, double smoothing)
{
    const char *resource = "resource:";
    char path[4096], buf[32], hb[32];
    if (!*name) {
        mb_error(inst, "InvalidInputError", "the replay profile needs a table: replay_table is empty");
        return 1;
    }
    if (strncmp(name, resource, strlen(resource)) == 0) {
        if (!mb_resources(inst)) {
            mb_error(inst, "InvalidInputError", "replay_table %s: the host gave no resources folder", name);
            return 1;
        }
        snprintf(path, sizeof path, "%s%s", mb_resources(inst), name + strlen(resource));
    } else {
        snprintf(path, sizeof path, "%s", name);
    }
    FILE *f = fopen(path, "rb");
    if (!f) {
        mb_error(inst, "InvalidInputError", "replay table '%s' cannot be opened (missing or unreadable)", path);
        return 1;
    }
    unsigned char head[PREPARED_HEADER];
    uint32_t version = 0, n = 0;
    double h = 0.0;
    long size = -1;
    int ok = fread(head, 1, sizeof head, f) == sizeof head && memcmp(head, "MBREPLAY", 8) == 0;
    if (ok) {
        memcpy(&version, head + 8, 4);
        memcpy(&n, head + 12, 4);
        memcpy(&h, head + 16, 8);
        if (fseek(f, 0, SEEK_END) == 0) size = ftell(f);
    }
    if (!ok) {
        fclose(f);
        mb_error(inst, "InvalidInputError", "replay table '%s' is not a prepared replay table (no MBREPLAY header): "
                 "make one with python -m fmu_src.replay_table", path);
        return 1;
    }
    if (version != PREPARED_VERSION || n < 2 || n > PREPARED_MAX_KNOTS ||
        size != PREPARED_HEADER + 8 * (long)n + 64 * (long)(n - 1)) {
        fclose(f);
        mb_error(inst, "InvalidInputError", "replay table '%s': version %u (read: %u), %u knots (2..%u) in %ld bytes "
                 "(%ld expected): truncated or damaged", path, version, PREPARED_VERSION, n, PREPARED_MAX_KNOTS, size,
                 n >= 2 ? PREPARED_HEADER + 8 * (long)n + 64 * (long)(n - 1) : -1L);
        return 1;
    }
    if (!(h == smoothing)) {
        fclose(f);
        mb_error(inst, "InvalidInputError", "replay table '%s' was smoothed over %s s, replay_smoothing is %s s: "
                 "prepare it with this smoothing time or set it to the table's", path, mb_repr(h, buf),
                 mb_repr(smoothing, hb));
        return 1;
    }
    Table *table = malloc(sizeof *table + 8 * ((size_t)n + 8 * ((size_t)n - 1)));
    if (!table) {
        fclose(f);
        mb_error(inst, "MemoryError", "replay table '%s': out of memory for %u knots", path, n);
        return 1;
    }
    table->n = (int)n;
    table->smoothing = h;
    table->t = (double *)(table + 1);
    table->coef = table->t + n;
    ok = fseek(f, PREPARED_HEADER, SEEK_SET) == 0 && fread(table->t, 8, n, f) == n &&
         fread(table->coef, 8, 8 * ((size_t)n - 1), f) == 8 * ((size_t)n - 1);
    fclose(f);
    int first_bad = -1;
    if (!ok || mb_tel_replay_check(table->n, table->t, table->coef, &first_bad)) {
        free(table);
        if (!ok) mb_error(inst, "InvalidInputError", "replay table '%s' could not be read whole", path);
        else mb_error(inst, "InvalidInputError", "replay table '%s': knot %d (0-based) is not finite or does not "
                      "follow the one before (%s)", path, first_bad, mb_tel_status_text(MB_TEL_REPLAY_TABLE));
        return 1;
    }
    mb_keep(inst, table);
    return 0;
}

/* The profile's replay arrays: this instance's kept table (none: n = 0, which the
   kernel refuses), whatever a restored state's bytes hold. */
static void attach(const mb_instance *inst, Model *m)
{
    const Table *table = mb_kept(inst);
    m->profile.replay_n = table ? table->n : 0;
    m->profile.replay_t = table ? table->t : NULL;
    m->profile.replay_coef = table ? table->coef : NULL;
}

/* slave.py's message for a kernel status (plant/telescope/model.py _status_error). */
static void fail_status(mb_instance *inst, const Model *m, int status, double t)
{
    char buf[32];
    const mb_tel_profile *p = &m->profile;
    if (status == MB_TEL_BELOW_HORIZON)
        mb_error(inst, "InvalidInputError", "the source is below the horizon at t = %s s", mb_repr(t - p->start_delay, buf));
    else if (status == MB_TEL_DEC_RANGE)
        mb_error(inst, "InvalidInputError", "dec must lie in [-90, 90] deg, got %.6g deg", p->dec * 57.29577951308232);
    else if (status == MB_TEL_DURATION_NOT_POSITIVE)
        mb_error(inst, "InvalidInputError", "T must be > 0, got %s", mb_repr(p->paper_duration, buf));
    else if (status == MB_TEL_ELEVATION_RANGE)
        mb_error(inst, "InvalidInputError", "slew elevation must lie in [0, 90] deg, got %.6g..%.6g deg",
                 57.29577951308232 * (p->start_el < p->target_el ? p->start_el : p->target_el),
                 57.29577951308232 * (p->start_el > p->target_el ? p->start_el : p->target_el));
    else
        mb_error(inst, "InvalidInputError", "%s", mb_tel_status_text(status));
}

/* Outputs at time t after a step of h (telescope_fmu.py Telescope._publish). */
static int publish(mb_instance *inst, double *r, Model *m, double t, double h)
{
    double index = -1.0;
    if (m->block_h == h && h > 0) index = nearbyint((t - m->block_t) / m->block_h);
    if (!(index >= 0 && index < BLOCK && fabs(m->block_t + index * h - t) <= 1e-9 * (fabs(t) > 1.0 ? fabs(t) : 1.0))) {
        m->block_t = t;
        m->block_h = h;
        index = 0.0;
    }
    double time = m->block_t + h * index, row[60];
    int first_bad = -1;
    int status = mb_tel_fmu_rows_full(&m->params, &m->profile, 1, &time, row, &first_bad);
    if (status) {
        fail_status(inst, m, status, time);
        return 1;
    }
    memcpy(&r[VR_base_pose], row, sizeof row);   /* the 60 outputs have consecutive vrs */
    return 0;
}

/* The command axes at t, or 1 after mb_error (servo on). */
static int command_at(mb_instance *inst, Model *m, double t, double *axes)
{
    int first_bad = -1;
    int status = mb_tel_axes(&m->params, &m->profile, 1, &t, axes, &first_bad);
    if (status) {
        fail_status(inst, m, status, t);
        return 1;
    }
    return 0;
}

static void publish_servo(double *r, Model *m, double t)
{
    mb_tel_servo_row(&m->params, &m->profile, r[VR_servo_bandwidth], r[VR_servo_damping], t, m->command, m->state,
                     &r[VR_base_pose]);
}

/* The support's modes over the step h (< 0: the start) added to the rigid row (telescope_fmu.py _sway). */
static int sway(mb_instance *inst, double *r, Model *m, double h)
{
    if (!m->support_on) return 0;
    int status = h < 0 ? mb_tel_support_start(&m->support, &r[VR_support_load], m->support_state, &r[VR_base_pose],
                                              &r[VR_support_sway])
                       : mb_tel_support_step(&m->support, h, &r[VR_support_load], m->support_state, &r[VR_base_pose],
                                             &r[VR_support_sway]);
    if (status) {
        mb_error(inst, "InvalidInputError", "support_load input contains NaN or inf");
        return 1;
    }
    return 0;
}

/* The support's settings (telescope_fmu.py _support_variables), checked. */
static int support_init(mb_instance *inst, double *r, Model *m)
{
    mb_tel_support *s = &m->support;
    memset(s, 0, sizeof *s);
    for (int j = 0; j < 2; j++) {
        s->mode[j].frequency = r[VR_support_frequency + j];
        s->mode[j].damping = r[VR_support_damping + j];
        s->mode[j].modal_mass = r[VR_support_modal_mass + j];
        s->mode[j].participation = r[VR_support_participation + j];
        memcpy(s->mode[j].shape, &r[j ? VR_support_shape_2 : VR_support_shape_1], sizeof s->mode[j].shape);
    }
    s->load_gain = r[VR_support_load_gain];
    memcpy(s->load_point, &r[VR_support_load_point], sizeof s->load_point);
    memcpy(s->preload, &r[VR_support_preload], sizeof s->preload);
    if (mb_tel_support_check(s)) {
        mb_error(inst, "InvalidInputError", "%s", mb_tel_status_text(MB_TEL_SUPPORT_RANGE));
        return 1;
    }
    m->support_on = mb_tel_support_on(s);
    memset(m->support_state, 0, sizeof m->support_state);
    return 0;
}

static int init(mb_instance *inst, double *r, int *i, void *model, double start_time)
{
    (void)start_time;
    Model *m = model;
    int kind = i[VR_profile];
    if (kind < 0 || kind >= N_PROFILE_NAMES) {
        mb_error(inst, "IndexError", "profile %d is not one of 0..%d (0 slew, 1 sidereal, 2 paper, 3 replay)", kind,
                 N_PROFILE_NAMES - 1);
        return 1;
    }
    mb_keep(inst, NULL);
    if (kind == PROFILE_REPLAY && load_table(inst, mb_string(inst, VR_replay_table), r[VR_replay_smoothing])) return 1;
    mb_tel_params *p = &m->params;
    p->latitude = r[VR_latitude];
    p->longitude = r[VR_longitude];
    p->lever_arm = r[VR_lever_arm];
    p->az_rate_max = r[VR_az_rate_max];
    p->az_acc_max = r[VR_az_acc_max];
    p->el_rate_max = r[VR_el_rate_max];
    p->el_acc_max = r[VR_el_acc_max];
    p->b_y = TIANMA_B_Y;
    p->c_y = TIANMA_C_Y;
    p->b_z = TIANMA_B_Z;
    p->c_z = TIANMA_C_Z;
    memcpy(p->home, TIANMA_HOME, sizeof p->home);
    mb_tel_profile *f = &m->profile;
    f->kind = kind == PROFILE_SLEW ? MB_TEL_SLEW : kind == PROFILE_SIDEREAL ? MB_TEL_SIDEREAL
            : kind == PROFILE_PAPER ? MB_TEL_PAPER : MB_TEL_REPLAY;
    f->start_az = r[VR_start_azimuth];
    f->start_el = r[VR_start_elevation];
    f->target_az = r[VR_target_azimuth];
    f->target_el = r[VR_target_elevation];
    f->ra = r[VR_right_ascension];
    f->dec = r[VR_declination];
    f->utc_start = r[VR_utc_start];
    f->paper_duration = r[VR_paper_duration];
    f->start_delay = r[VR_start_delay];
    memcpy(f->ref_start, HOME_POSE, sizeof f->ref_start);
    memcpy(f->ref_stop, S_BAND_POSE, sizeof f->ref_stop);
    attach(inst, m);
    int status = mb_tel_check_params(p);
    if (status) {
        mb_error(inst, "InvalidInputError", "%s", mb_tel_status_text(status));
        return 1;
    }
    if (support_init(inst, r, m)) return 1;
    m->block_t = INFINITY;
    m->block_h = 0.0;
    m->servo = r[VR_servo_bandwidth] > 0;
    if (m->servo) {
        char buf[32];
        if (!(isfinite(r[VR_servo_damping]) && r[VR_servo_damping] > 0)) {   /* telescope.check_servo */
            mb_error(inst, "InvalidInputError", "servo_damping must be finite and > 0, got %s",
                     mb_repr(r[VR_servo_damping], buf));
            return 1;
        }
        if (command_at(inst, m, 0.0, m->command)) return 1;
        m->state[0] = m->command[0];   /* starts on the command */
        m->state[1] = m->command[1];
        m->state[2] = m->command[3];
        m->state[3] = m->command[4];
        publish_servo(r, m, 0.0);
        return sway(inst, r, m, -1.0);
    }
    return publish(inst, r, m, 0.0, 0.0) || sway(inst, r, m, -1.0);
}

static int step(mb_instance *inst, double *r, int *i, void *model, double t, double h)
{
    (void)i;
    Model *m = model;
    attach(inst, m);
    if (m->servo) {
        double command[6];
        int substeps;   /* the count mb_tel_servo_advance takes: w h / SERVO_MAX_WH (plant/c/telescope.c) */
        if (mb_substeps(inst, h, SERVO_MAX_WH / (2 * M_PI * r[VR_servo_bandwidth]), &substeps)) return 1;
        if (command_at(inst, m, t + h, command)) return 1;
        mb_tel_servo_advance(r[VR_servo_bandwidth], r[VR_servo_damping], h, m->command, command, m->state);
        memcpy(m->command, command, sizeof command);
        publish_servo(r, m, t + h);
        return sway(inst, r, m, h);
    }
    return publish(inst, r, m, t + h, h) || sway(inst, r, m, h);
}

const mb_model_info MB_MODEL = {MB_IDENTIFIER, MB_GUID, MB_NVARS, MB_VARS, sizeof(Model), 0, init, step};
