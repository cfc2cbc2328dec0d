/* The co-simulation master's stepping loop; see cosim.h. Every floating-point operation
   is the one (and in the order) the numpy master did, so results are bit-identical:
   Jacobi extrapolation y + 0.5 * (y - y_prev), Gauss-Seidel u + half * (u - u_prev). */
#include <stddef.h>
#include <string.h>
#include "cosim.h"

static int failed(cosim_master *m, size_t fmu, int call, int status)
{
    m->failed_fmu = (int)fmu;
    m->failed_call = call;
    m->failed_status = status;
    return 1;
}

/* FMI 3.0: the elements of write_buf into their variables' values, set in one call; the
   values not connected keep what the FMU holds. */
static int set_float64(cosim_fmu *f)
{
    cosim_fmi3 *g = f->fmi3;
    size_t j;
    int status;
    if (g->write_partial) {
        status = g->get_float64(f->component, g->write_vr, g->n_write_vr, g->write_values, g->n_write_values);
        if (status > 1)
            return status;
    }
    for (j = 0; j < f->n_write; j++)
        g->write_values[g->write_index[j]] = f->write_buf[j];
    return g->set_float64(f->component, g->write_vr, g->n_write_vr, g->write_values, g->n_write_values);
}

/* FMI 3.0: the variables holding the read elements in one call, the elements into y. */
static int get_float64(cosim_fmu *f, double *y)
{
    cosim_fmi3 *g = f->fmi3;
    size_t j;
    int status = g->get_float64(f->component, g->read_vr, g->n_read_vr, g->read_values, g->n_read_values);
    if (status <= 1)
        for (j = 0; j < f->n_read; j++)
            y[j] = g->read_values[g->read_index[j]];
    return status;
}

static int write_inputs(cosim_master *m, size_t i, int extrapolate)
{
    cosim_fmu *f = &m->fmus[i];
    size_t j;
    int status;
    if (f->n_write == 0)
        return 0;
    for (j = 0; j < f->n_write; j++) {
        double u = m->y[f->write_from[j]];
        if (extrapolate && !m->gauss_seidel)
            u = u + 0.5 * (u - m->y_prev[f->write_from[j]]);
        else if (extrapolate)
            u = u + f->write_half[j] * (u - m->y_prev[f->write_from[j]]);
        f->write_buf[j] = u;
    }
    status = f->fmi3 ? set_float64(f) : f->set_real(f->component, f->write_vr, f->n_write, f->write_buf);
    return status > 1 ? failed(m, i, COSIM_SET_REAL, status) : 0;
}

static int do_step(cosim_master *m, size_t i, double t)
{
    cosim_fmu *f = &m->fmus[i];
    int status;
    f->time = t;
    if (f->fmi3) {   /* a refused step answers Discard (terminateSimulation set): the run stops either way */
        _Bool event, terminate, early;
        double last;
        status = f->fmi3->do_step(f->component, t, m->h, 1, &event, &terminate, &early, &last);
    } else
        status = f->do_step(f->component, t, m->h, 1);
    return status > 1 ? failed(m, i, COSIM_DO_STEP, status) : 0;
}

static int read_outputs(cosim_master *m, size_t i)
{
    cosim_fmu *f = &m->fmus[i];
    int status;
    if (f->n_read == 0)
        return 0;
    status = f->fmi3 ? get_float64(f, m->y + f->read_at) : f->get_real(f->component, f->read_vr, f->n_read, m->y + f->read_at);
    return status > 1 ? failed(m, i, COSIM_GET_REAL, status) : 0;
}

static int jacobi_step(cosim_master *m, long k)
{
    double t = m->t0 + (double)k * m->h;
    size_t i;
    for (i = 0; i < m->n_fmus; i++)
        if (write_inputs(m, i, m->extrapolate && k))
            return 1;
    memcpy(m->y_prev, m->y, m->n_y * sizeof(double));
    for (i = 0; i < m->n_fmus; i++)
        if (do_step(m, i, t))
            return 1;
    for (i = 0; i < m->n_read_order; i++)
        if (read_outputs(m, m->read_order[i]))
            return 1;
    return 0;
}

static int gauss_seidel_step(cosim_master *m, long k)
{
    double t = m->t0 + (double)k * m->h;
    size_t i;
    memcpy(m->y_start, m->y, m->n_y * sizeof(double));
    for (i = 0; i < m->n_fmus; i++)
        if (write_inputs(m, i, m->extrapolate && k) || do_step(m, i, t) || read_outputs(m, i))
            return 1;
    memcpy(m->y_prev, m->y_start, m->n_y * sizeof(double));
    return 0;
}

long cosim_steps(cosim_master *m, long k, long count)
{
    long done;
    m->failed_fmu = -1;
    for (done = 0; done < count; done++)
        if (m->gauss_seidel ? gauss_seidel_step(m, k + done) : jacobi_step(m, k + done))
            break;
    return done;
}
