/*
 * Fixed-step RK4 free-run simulation of a sparse ODE model  dq_e/dt = sum_j coef[e][j] * term_j(q, u).
 *
 * A term is a product of small integer powers of features; the features of state i are
 * q_i, |q_i|, sign(q_i) (indices 3i, 3i+1, 3i+2), then the inputs (index 3*n_states + j).
 * The input is supplied on a fine grid of spacing h/2 (h = dt/substeps), so every RK4 stage reads
 * it directly: interpolation (linear, band-limited, analytic) is the caller's choice, in Python.
 *
 * simulate(term_ptr, fac_feat, fac_pow, coef, x0, u_fine, n_inputs, n_out, substeps, dt, bound, out)
 *   int32 buffers: term_ptr (n_terms+1), fac_feat, fac_pow; float64 buffers: coef (n_states*n_terms),
 *   x0 (n_states), u_fine ((n_out-1)*2*substeps+1 rows of n_inputs), out (n_out*n_states, writable).
 * Returns the number of samples written: n_out, or fewer if a state left [-bound, bound] or went NaN.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#define MAX_STATES 8
#define MAX_FEATS (3 * MAX_STATES + 8)

#define MAX_POW 16
#define MAX_NZ 512

typedef struct {
    const int *ptr, *feat, *pow;
    int n_terms, n_states, n_inputs;
    /* precomputed once per call: which features are used, to which power; nonzero coefficients */
    int used[MAX_FEATS], n_used, max_pow[MAX_FEATS];
    int nz_eq[MAX_NZ], nz_term[MAX_NZ], n_nz;
    double nz_coef[MAX_NZ];
} model_t;

static int prepare(model_t *m, const double *coef) {
    int j, k, e, f, n_feats = 3 * m->n_states + m->n_inputs;
    for (f = 0; f < n_feats; f++) m->max_pow[f] = 0;
    for (k = 0; k < m->ptr[m->n_terms]; k++) {
        if (m->feat[k] < 0 || m->feat[k] >= n_feats || m->pow[k] < 1 || m->pow[k] >= MAX_POW) return 0;
        if (m->pow[k] > m->max_pow[m->feat[k]]) m->max_pow[m->feat[k]] = m->pow[k];
    }
    m->n_used = 0;
    for (f = 0; f < n_feats; f++)
        if (m->max_pow[f] > 0) m->used[m->n_used++] = f;
    m->n_nz = 0;
    for (e = 0; e < m->n_states; e++)
        for (j = 0; j < m->n_terms; j++)
            if (coef[e * m->n_terms + j] != 0.0) {
                if (m->n_nz >= MAX_NZ) return 0;
                m->nz_eq[m->n_nz] = e;
                m->nz_term[m->n_nz] = j;
                m->nz_coef[m->n_nz++] = coef[e * m->n_terms + j];
            }
    return 1;
}

static void rhs(const model_t *m, const double *x, const double *u, double *dx) {
    double pw[MAX_FEATS][MAX_POW], val[MAX_NZ];
    int i, j, k, f, p;
    for (i = 0; i < m->n_used; i++) {
        f = m->used[i];
        double b;
        if (f < 3 * m->n_states) {
            double q = x[f / 3];
            b = (f % 3 == 0) ? q : (f % 3 == 1) ? fabs(q) : (double)((q > 0) - (q < 0));
        } else {
            b = u[f - 3 * m->n_states];
        }
        pw[f][1] = b;
        for (p = 2; p <= m->max_pow[f]; p++) pw[f][p] = pw[f][p - 1] * b;
    }
    for (j = 0; j < m->n_terms; j++) {
        double v = 1.0;
        for (k = m->ptr[j]; k < m->ptr[j + 1]; k++) v *= pw[m->feat[k]][m->pow[k]];
        val[j] = v;
    }
    for (i = 0; i < m->n_states; i++) dx[i] = 0.0;
    for (i = 0; i < m->n_nz; i++) dx[m->nz_eq[i]] += m->nz_coef[i] * val[m->nz_term[i]];
}

static PyObject *simulate(PyObject *self, PyObject *args) {
    Py_buffer b_ptr, b_feat, b_pow, b_coef, b_x0, b_u, b_out;
    int n_inputs, substeps;
    Py_ssize_t n_out;
    double dt, bound;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*iniddw*", &b_ptr, &b_feat, &b_pow, &b_coef, &b_x0, &b_u,
                          &n_inputs, &n_out, &substeps, &dt, &bound, &b_out))
        return NULL;
    model_t m;
    m.ptr = (const int *)b_ptr.buf;
    m.feat = (const int *)b_feat.buf;
    m.pow = (const int *)b_pow.buf;
    m.n_terms = (int)(b_ptr.len / sizeof(int)) - 1;
    m.n_states = (int)(b_x0.len / sizeof(double));
    m.n_inputs = n_inputs;
    const double *u = (const double *)b_u.buf;
    double *out = (double *)b_out.buf;
    Py_ssize_t need_u = (n_out > 0 ? (n_out - 1) * 2 * (Py_ssize_t)substeps + 1 : 0) * n_inputs;
    PyObject *result = NULL;
    if (m.n_states < 1 || m.n_states > MAX_STATES || n_inputs < 0 || n_inputs > 8 || substeps < 1 ||
        b_coef.len != (Py_ssize_t)(sizeof(double) * m.n_states * m.n_terms) ||
        b_u.len < (Py_ssize_t)sizeof(double) * need_u ||
        b_out.len < (Py_ssize_t)sizeof(double) * n_out * m.n_states || m.n_terms > MAX_NZ ||
        !prepare(&m, (const double *)b_coef.buf)) {
        PyErr_SetString(PyExc_ValueError, "simulate: inconsistent buffer sizes or model too large");
        goto done;
    }
    {
        double x[MAX_STATES], xs[MAX_STATES], k1[MAX_STATES], k2[MAX_STATES], k3[MAX_STATES],
            k4[MAX_STATES];
        double h = dt / substeps;
        int i, s, ni = n_inputs;
        Py_ssize_t t, written = 0;
        for (i = 0; i < m.n_states; i++) x[i] = ((const double *)b_x0.buf)[i];
        Py_BEGIN_ALLOW_THREADS
        if (n_out > 0) {
            for (i = 0; i < m.n_states; i++) out[i] = x[i];
            written = 1;
        }
        for (t = 1; t < n_out; t++) {
            int ok = 1;
            for (s = 0; s < substeps; s++) {
                const double *u0 = u + ((t - 1) * 2 * (Py_ssize_t)substeps + 2 * s) * ni;
                rhs(&m, x, u0, k1);
                for (i = 0; i < m.n_states; i++) xs[i] = x[i] + 0.5 * h * k1[i];
                rhs(&m, xs, u0 + ni, k2);
                for (i = 0; i < m.n_states; i++) xs[i] = x[i] + 0.5 * h * k2[i];
                rhs(&m, xs, u0 + ni, k3);
                for (i = 0; i < m.n_states; i++) xs[i] = x[i] + h * k3[i];
                rhs(&m, xs, u0 + 2 * ni, k4);
                for (i = 0; i < m.n_states; i++) {
                    x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                    if (!(fabs(x[i]) <= bound)) ok = 0; /* also catches NaN */
                }
            }
            if (!ok) break;
            for (i = 0; i < m.n_states; i++) out[t * m.n_states + i] = x[i];
            written = t + 1;
        }
        Py_END_ALLOW_THREADS
        result = PyLong_FromSsize_t(written);
    }
done:
    PyBuffer_Release(&b_ptr);
    PyBuffer_Release(&b_feat);
    PyBuffer_Release(&b_pow);
    PyBuffer_Release(&b_coef);
    PyBuffer_Release(&b_x0);
    PyBuffer_Release(&b_u);
    PyBuffer_Release(&b_out);
    return result;
}

static PyMethodDef methods[] = {
    {"simulate", simulate, METH_VARARGS, "Fixed-step RK4 free run of a sparse term model."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_simkernel",
                                    "Compiled RK4 stepping for identify.simulate.", -1, methods};

PyMODINIT_FUNC PyInit__simkernel(void) { return PyModule_Create(&module); }
