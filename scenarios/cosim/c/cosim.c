/* The co-simulation master's stepping loop; see cosim.h. Every floating-point operation
   is the one (and in the order) the numpy master did, so results are bit-identical:
   Jacobi extrapolation y + 0.5 * (y - y_prev), Gauss-Seidel u + half * (u - u_prev).
   Extrapolation by derivatives (FMI 3 fmi3GetOutputDerivatives) is this loop's own. */
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

/* FMI 3.0: the variables holding the read elements in one call, the elements into y;
   then their output derivatives where the master asks for them (extrapolation 2). */
static int get_float64(cosim_master *m, cosim_fmu *f)
{
    cosim_fmi3 *g = f->fmi3;
    double *y = m->y + f->read_at, *y_d[2] = {m->y_d1, m->y_d2};
    size_t j;
    int o, status = g->get_float64(f->component, g->read_vr, g->n_read_vr, g->read_values, g->n_read_values);
    if (status > 1)
        return status;
    for (j = 0; j < f->n_read; j++)
        y[j] = g->read_values[g->read_index[j]];
    for (o = 0; o < 2; o++) {
        cosim_derivatives *d = &g->derivatives[o];
        if (d->n == 0)
            continue;
        status = g->get_derivatives(f->component, d->vr, d->n_vr, d->orders, d->values, d->n_values);
        if (status > 1)
            return status;
        for (j = 0; j < d->n; j++)
            y_d[o][d->dst[j]] = d->values[d->src[j]];
    }
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
        size_t s = f->write_from[j];
        double u = m->y[s];
        if (extrapolate == 2 && m->y_order[s] > 0) {
            /* the mean over the coming step of the source's Taylor polynomial at its time:
               u + h/2 u' + h^2/6 u'' (Gauss-Seidel: only where the source has not stepped) */
            double du = 0.5 * m->h * m->y_d1[s];
            if (m->y_order[s] > 1)
                du += m->h * m->h / 6.0 * m->y_d2[s];
            u = u + (m->gauss_seidel ? 2.0 * f->write_half[j] : 1.0) * du;
        } else if (extrapolate && !m->gauss_seidel)
            u = u + 0.5 * (u - m->y_prev[s]);
        else if (extrapolate)
            u = u + f->write_half[j] * (u - m->y_prev[s]);
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
    status = f->fmi3 ? get_float64(m, f) : f->get_real(f->component, f->read_vr, f->n_read, m->y + f->read_at);
    return status > 1 ? failed(m, i, COSIM_GET_REAL, status) : 0;
}

static int jacobi_step(cosim_master *m, long k)
{
    double t = m->t0 + (double)k * m->h;
    size_t i;
    for (i = 0; i < m->n_fmus; i++)
        if (write_inputs(m, i, k ? m->extrapolate : 0))
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
        if (write_inputs(m, i, k ? m->extrapolate : 0) || do_step(m, i, t) || read_outputs(m, i))
            return 1;
    memcpy(m->y_prev, m->y_start, m->n_y * sizeof(double));
    return 0;
}

/* The recorded values into the next row: one read per recorded instance, in the
   recorder's order, as master.Recorder read them with one FMI call each. */
static int record_row(cosim_master *m)
{
    double *row = m->rows + m->n_rows * m->n_columns;
    size_t r, j;
    for (r = 0; r < m->n_records; r++) {
        const cosim_record *c = &m->records[r];
        cosim_fmu *f = &m->fmus[c->fmu];
        int status = f->fmi3 ? f->fmi3->get_float64(f->component, c->vr, c->n_vr, c->values, c->n_values)
                             : f->get_real(f->component, c->vr, c->n_vr, c->values);
        if (status > 1)
            return failed(m, c->fmu, COSIM_GET_REAL, status);
        for (j = 0; j < c->n; j++)
            row[c->column[j]] = c->values[c->index[j]];
    }
    m->n_rows++;
    return 0;
}

int cosim_record_row(cosim_master *m)
{
    m->failed_fmu = -1;
    m->n_rows = 0;
    return record_row(m);
}

long cosim_steps(cosim_master *m, long k, long count)
{
    long done;
    m->failed_fmu = -1;
    m->n_rows = 0;
    for (done = 0; done < count; done++) {
        int due = m->every > 0 && (k + done + 1) % m->every == 0;
        if (due && m->n_rows == m->capacity)
            break;
        if (m->gauss_seidel ? gauss_seidel_step(m, k + done) : jacobi_step(m, k + done))
            break;
        if (due && record_row(m))
            return done + 1;
    }
    return done;
}
