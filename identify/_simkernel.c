/*
 * Fixed-step RK4 free-run simulation of a sparse ODE model  dq_e/dt = sum_j coef[e][j] * term_j(q, u).
 *
 * The Python entry points; the model and its stepping are in _simkernel_run.h (features, end stops,
 * what makes a step fast).
 *
 * simulate(term_ptr, fac_feat, fac_pow, coef, x0, u_fine, n_inputs, n_out, substeps, stride, dt, bound, out
 *          [, travel])
 *   stride > 1 (substeps 1, no end stops): steps of `stride` samples, the samples between from RK4's
 *   continuous extension (strided_run).
 *   int32 buffers: term_ptr (n_terms+1), fac_feat, fac_pow; float64 buffers: coef (n_states*n_terms),
 *   x0 (n_states), u_fine ((n_out-1)*2*substeps+1 rows of n_inputs), out (n_out*n_states, writable),
 *   travel (n_states, m; inf = no end stop; omitted = none anywhere).
 * Returns the number of samples written: n_out, or fewer if a state left [-bound, bound] or went NaN.
 *
 * simulate_segments(term_ptr, fac_feat, fac_pow, coef, x0s, u_fine, n_inputs, starts, stops, substeps, stride,
 *                   dt, bound, out, written [, travel])
 *   simulate for the k segments of one record (multiple shooting, identify.simulation.shooting) in one call,
 *   the GIL released for all of them: per segment ~35 us of Python had held it against ~76 us of stepping.
 *
 * rhs_rows(term_ptr, fac_feat, fac_pow, coef, columns, eq, out [, travel]): equation eq of the right-hand
 *   side at n independent rows (the one-step prediction and a diverged free run's q1_dot, identify.validation).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "_simkernel_run.h"

/* Every buffer an entry point parsed, released (an optional one left unfilled, {0}, has no object: a no-op). */
static void release(Py_buffer *const *views, size_t n) {
    for (size_t i = 0; i < n; i++) PyBuffer_Release(views[i]);
}
#define RELEASE(...) do { Py_buffer *const views_[] = {__VA_ARGS__}; release(views_, sizeof views_ / sizeof *views_); } while (0)

/* The model from simulate's and simulate_segments' buffers: 0 (and a ValueError set) if they disagree. */
static int model_from(const char *caller, model_t *m, Py_buffer *b_ptr, Py_buffer *b_feat, Py_buffer *b_pow,
                      Py_buffer *b_coef, int n_states, int n_inputs, Py_buffer *b_travel) {
    int i, has_travel = b_travel->buf != NULL;
    m->ptr = (const int *)b_ptr->buf;
    m->feat = (const int *)b_feat->buf;
    m->pow = (const int *)b_pow->buf;
    m->n_terms = (int)(b_ptr->len / sizeof(int)) - 1;
    m->n_states = n_states;
    m->n_inputs = n_inputs;
    if (n_states < 1 || n_states > MAX_STATES || n_inputs < 0 || n_inputs > MAX_INPUTS ||
        (has_travel && b_travel->len != (Py_ssize_t)sizeof(double) * n_states) ||
        b_coef->len != (Py_ssize_t)(sizeof(double) * n_states * m->n_terms) || m->n_terms > MAX_NZ ||
        !prepare(m, (const double *)b_coef->buf)) {
        PyErr_Format(PyExc_ValueError, "%s: inconsistent buffer sizes or model too large", caller);
        return 0;
    }
    for (i = 0; i < n_states; i++) m->travel[i] = has_travel ? ((const double *)b_travel->buf)[i] : HUGE_VAL;
    return 1;
}

static int check_step(const char *caller, const model_t *m, int substeps, int stride) {
    if (substeps < 1 || stride < 1 || (stride > 1 && (substeps != 1 || m->has_stops))) {
        PyErr_Format(PyExc_ValueError, "%s: substeps >= 1; a stride of several samples needs substeps 1 and no end stops",
                     caller);
        return 0;
    }
    return 1;
}

static PyObject *simulate(PyObject *self, PyObject *args) {
    Py_buffer b_ptr, b_feat, b_pow, b_coef, b_x0, b_u, b_out, b_travel = {0};
    int n_inputs, substeps, stride;
    Py_ssize_t n_out, written;
    double dt, bound;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*iniiddw*|y*", &b_ptr, &b_feat, &b_pow, &b_coef, &b_x0, &b_u,
                          &n_inputs, &n_out, &substeps, &stride, &dt, &bound, &b_out, &b_travel))
        return NULL;
    model_t m;
    PyObject *result = NULL;
    int n_states = (int)(b_x0.len / sizeof(double));
    if (!model_from("simulate", &m, &b_ptr, &b_feat, &b_pow, &b_coef, n_states, n_inputs, &b_travel) ||
        !check_step("simulate", &m, substeps, stride))
        goto done;
    Py_ssize_t need_u = (n_out > 0 ? (n_out - 1) * 2 * (Py_ssize_t)substeps + 1 : 0) * n_inputs;
    if (b_u.len < (Py_ssize_t)sizeof(double) * need_u || b_out.len < (Py_ssize_t)sizeof(double) * n_out * n_states) {
        PyErr_SetString(PyExc_ValueError, "simulate: inconsistent buffer sizes or model too large");
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    written = free_run(&m, (const double *)b_x0.buf, (const double *)b_u.buf, n_out, substeps, stride, dt, bound,
                       (double *)b_out.buf);
    Py_END_ALLOW_THREADS
    result = PyLong_FromSsize_t(written);
done:
    RELEASE(&b_ptr, &b_feat, &b_pow, &b_coef, &b_x0, &b_u, &b_out, &b_travel);
    return result;
}

/* simulate_segments(term_ptr, fac_feat, fac_pow, coef, x0s, u_fine, n_inputs, starts, stops, substeps,
   stride, dt, bound, out, written [, travel]): simulate for k segments of one record at once (multiple
   shooting), the GIL released for all of them: segment j runs from x0s[j] (k x n_states float64) over the
   record's samples starts[j] .. stops[j] - 1 (int64), reading u_fine (the whole record's h/2 grid, sample r
   at row 2 substeps r) from its first sample on, and writes its states into out's rows starts[j] ..
   (out: the record's n_rows x n_states float64, writable) and its samples written into written[j] (int64,
   writable). The segments must not overlap (each non-empty; identify.simulation.simulate.simulate_segments
   checks both): callers in several threads write disjoint rows of one `out`. The same numbers as k calls of
   simulate, without k calls' overhead. */
static PyObject *simulate_segments(PyObject *self, PyObject *args) {
    Py_buffer b_ptr, b_feat, b_pow, b_coef, b_x0, b_u, b_starts, b_stops, b_out, b_written, b_travel = {0};
    int n_inputs, substeps, stride;
    double dt, bound;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*iy*y*iiddw*w*|y*", &b_ptr, &b_feat, &b_pow, &b_coef, &b_x0, &b_u,
                          &n_inputs, &b_starts, &b_stops, &substeps, &stride, &dt, &bound, &b_out, &b_written,
                          &b_travel))
        return NULL;
    model_t m;
    PyObject *result = NULL;
    Py_ssize_t k = b_starts.len / (Py_ssize_t)sizeof(long long), j, up = 2 * (Py_ssize_t)substeps;
    const long long *starts = (const long long *)b_starts.buf, *stops = (const long long *)b_stops.buf;
    long long *written = (long long *)b_written.buf;
    int n_states = k > 0 ? (int)(b_x0.len / (Py_ssize_t)sizeof(double) / k) : 1;
    if (!model_from("simulate_segments", &m, &b_ptr, &b_feat, &b_pow, &b_coef, n_states, n_inputs, &b_travel) ||
        !check_step("simulate_segments", &m, substeps, stride))
        goto done;
    Py_ssize_t rows_u = n_inputs > 0 ? b_u.len / (Py_ssize_t)sizeof(double) / n_inputs : 0;
    Py_ssize_t rows_out = b_out.len / (Py_ssize_t)sizeof(double) / n_states;
    int ok = b_stops.len == b_starts.len && b_written.len == b_starts.len &&
             b_x0.len == (Py_ssize_t)sizeof(double) * n_states * k;
    for (j = 0; ok && j < k; j++)
        ok = starts[j] >= 0 && stops[j] > starts[j] && stops[j] <= rows_out &&
             (n_inputs == 0 || (stops[j] - 1) * up + 1 <= rows_u);
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "simulate_segments: inconsistent buffer sizes or segments");
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    for (j = 0; j < k; j++)
        written[j] = free_run(&m, (const double *)b_x0.buf + j * n_states,
                              (const double *)b_u.buf + starts[j] * up * n_inputs, stops[j] - starts[j], substeps,
                              stride, dt, bound, (double *)b_out.buf + starts[j] * n_states);
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    result = Py_None;
done:
    RELEASE(&b_ptr, &b_feat, &b_pow, &b_coef, &b_x0, &b_u, &b_starts, &b_stops, &b_out, &b_written, &b_travel);
    return result;
}

/* rhs_rows(term_ptr, fac_feat, fac_pow, coef, columns, eq, out [, travel]): out[t] = f_eq(x_t, u_t), the
   model's right-hand side of equation `eq` at n independent rows (the one-step prediction, a diverged free
   run's q1_dot), with each row's own contact sides. `columns`: a tuple of n_states + n_inputs 1-D float64
   buffers (strided views allowed), the states then the inputs; out: n doubles, writable. Rows are
   independent, so unlike the free run this is not one long chain of dependent operations. */
static PyObject *rhs_rows(PyObject *self, PyObject *args) {
    Py_buffer b_ptr, b_feat, b_pow, b_coef, b_out, b_travel = {0}, cols[MAX_STATES + MAX_INPUTS];
    PyObject *columns, *result = NULL;
    int eq, n_cols = 0, i, ok = 1;
    if (!PyArg_ParseTuple(args, "y*y*y*y*O!iw*|y*", &b_ptr, &b_feat, &b_pow, &b_coef, &PyTuple_Type, &columns,
                          &eq, &b_out, &b_travel))
        return NULL;
    model_t m;
    int has_travel = b_travel.buf != NULL;
    Py_ssize_t n = b_out.len / (Py_ssize_t)sizeof(double);
    m.ptr = (const int *)b_ptr.buf;
    m.feat = (const int *)b_feat.buf;
    m.pow = (const int *)b_pow.buf;
    m.n_terms = (int)(b_ptr.len / sizeof(int)) - 1;
    m.n_states = b_coef.len / (Py_ssize_t)sizeof(double) / (m.n_terms > 0 ? m.n_terms : 1);
    m.n_inputs = (int)PyTuple_GET_SIZE(columns) - m.n_states;
    if (m.n_terms < 1 || m.n_terms > MAX_NZ || m.n_states < 1 || m.n_states > MAX_STATES || m.n_inputs < 0 ||
        m.n_inputs > MAX_INPUTS || eq < 0 || eq >= m.n_states ||
        b_coef.len != (Py_ssize_t)(sizeof(double) * m.n_states * m.n_terms) ||
        (has_travel && b_travel.len != (Py_ssize_t)sizeof(double) * m.n_states) ||
        !prepare(&m, (const double *)b_coef.buf))
        ok = 0;
    for (i = 0; ok && i < m.n_states + m.n_inputs; i++) {
        if (PyObject_GetBuffer(PyTuple_GET_ITEM(columns, i), &cols[i], PyBUF_RECORDS_RO) < 0) {
            ok = -1;
            break;
        }
        n_cols++;
        if (cols[i].ndim != 1 || cols[i].itemsize != sizeof(double) || strcmp(cols[i].format, "d") != 0 ||
            cols[i].shape[0] < n)
            ok = 0;
    }
    if (ok <= 0) {
        if (ok == 0) PyErr_SetString(PyExc_ValueError, "rhs_rows: inconsistent buffer sizes or model too large");
        goto done;
    }
    for (i = 0; i < m.n_states; i++) m.travel[i] = has_travel ? ((const double *)b_travel.buf)[i] : HUGE_VAL;
    {
        double x[MAX_STATES], u[MAX_INPUTS], *out = (double *)b_out.buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t t = 0; t < n; t++) {
            for (i = 0; i < m.n_states + m.n_inputs; i++) {
                double v = *(const double *)((const char *)cols[i].buf + t * cols[i].strides[0]);
                if (i < m.n_states) x[i] = v; else u[i - m.n_states] = v;
            }
            out[t] = m.has_stops ? equation(&m, eq, x, u, NULL, 1) : equation(&m, eq, x, u, NULL, 0);
        }
        Py_END_ALLOW_THREADS
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    for (i = 0; i < n_cols; i++) PyBuffer_Release(&cols[i]);
    RELEASE(&b_ptr, &b_feat, &b_pow, &b_coef, &b_out, &b_travel);
    return result;
}

static PyMethodDef methods[] = {
    {"simulate", simulate, METH_VARARGS, "Fixed-step RK4 free run of a sparse term model."},
    {"simulate_segments", simulate_segments, METH_VARARGS, "simulate for several segments of one record in one call."},
    {"rhs_rows", rhs_rows, METH_VARARGS, "One equation of a sparse term model's right-hand side at independent rows."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_simkernel",
                                    "Compiled RK4 stepping for identify.simulate.", -1, methods};

PyMODINIT_FUNC PyInit__simkernel(void) { return PyModule_Create(&module); }
