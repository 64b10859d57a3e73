/*
 * Polynomial rows in polyphase order, for identify.noise_spread: the score derivatives of a refit, each a
 * polynomial in a recording's signals (q1, q2, q1_dot, input), evaluated on every `step`-th sample and
 * written in the order the band's polyphase transform reads them (identify.spectral.polyphase_rfft).
 *
 * poly_rows(signals, n, step, m, width, parent, var, row_ptr, mono, coef, out)
 *   signals: tuple of 1-D float64 buffers (C-contiguous, at least n long), the variables;
 *   monomial i (int32 parent, var): monomial parent[i] times variable var[i], parent[i] < i; monomial 0
 *     is the constant 1 (its parent and var are ignored);
 *   row r: sum over k in [row_ptr[r], row_ptr[r + 1]) of coef[k] * monomial mono[k] (int32 row_ptr and
 *     mono, float64 coef);
 *   out: writable, C-contiguous float32 or float64, n_rows x m x length (length >= width): out[r, c, j] =
 *     row r at the sample t = (j m + c) step when j < width and t < n, else 0 (the transform's zero
 *     padding).
 *
 * Why compiled: numpy made each row in several whole-array passes (a product per monomial, one per term of
 * a sum), each writing a temporary of the row's length; here every sample's monomials are made once, in
 * blocks of BLOCK samples that stay in cache, and each row is written once. Evaluated in the output's
 * precision (single, noise_spread.DTYPE: four samples per vector instruction; double for the tests' exact
 * algebra).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdlib.h>
#include <string.h>

#define BLOCK 256
#define MAX_VARS 8
#define MAX_COMPONENTS 64

/* One precision's evaluation (T float or double): see the header. valid[c]: component c's samples below n. */
#define DEFINE_ROWS(NAME, T)                                                                                   \
    static void NAME(const double *const *y, int n_vars, Py_ssize_t step, Py_ssize_t m, Py_ssize_t length,     \
                     const Py_ssize_t *valid, Py_ssize_t longest, int n_mono, const int *parent, const int *var, \
                     int n_rows, const int *ptr, const int *mono, const double *coef, T *out, T *work) {        \
        T *vals = work, *monos = work + (size_t)n_vars * BLOCK, *acc = monos + (size_t)n_mono * BLOCK;          \
        Py_ssize_t stride = m * step;                                                                          \
        for (Py_ssize_t j0 = 0; j0 < longest; j0 += BLOCK) {                                                   \
            for (Py_ssize_t c = 0; c < m; c++) {                                                               \
                if (j0 >= valid[c]) continue;                                                                  \
                int nb = (int)(valid[c] - j0 < BLOCK ? valid[c] - j0 : BLOCK);                                 \
                for (int v = 0; v < n_vars; v++) {                                                             \
                    const double *src = y[v] + c * step + j0 * stride;                                        \
                    T *dst = vals + (size_t)v * BLOCK;                                                         \
                    for (int jj = 0; jj < nb; jj++) dst[jj] = (T)src[jj * stride];                             \
                }                                                                                              \
                for (int jj = 0; jj < nb; jj++) monos[jj] = (T)1;                                              \
                for (int i = 1; i < n_mono; i++) {                                                             \
                    const T *restrict p = monos + (size_t)parent[i] * BLOCK;                                   \
                    const T *restrict x = vals + (size_t)var[i] * BLOCK;                                       \
                    T *restrict q = monos + (size_t)i * BLOCK;                                                 \
                    for (int jj = 0; jj < nb; jj++) q[jj] = p[jj] * x[jj];                                     \
                }                                                                                              \
                for (int r = 0; r < n_rows; r++) {                                                             \
                    T *restrict sum = acc;                                                                     \
                    for (int jj = 0; jj < nb; jj++) sum[jj] = (T)0;                                            \
                    for (int k = ptr[r]; k < ptr[r + 1]; k++) {                                                \
                        const T a = (T)coef[k], *restrict q = monos + (size_t)mono[k] * BLOCK;                 \
                        for (int jj = 0; jj < nb; jj++) sum[jj] += a * q[jj];                                  \
                    }                                                                                          \
                    T *restrict o = out + ((size_t)r * m + c) * length + j0;                                   \
                    for (int jj = 0; jj < nb; jj++) o[jj] = sum[jj];                                           \
                }                                                                                              \
            }                                                                                                  \
        }                                                                                                      \
        for (int r = 0; r < n_rows; r++) /* past the record's end, and the padding */                          \
            for (Py_ssize_t c = 0; c < m; c++)                                                                 \
                memset(out + ((size_t)r * m + c) * length + valid[c], 0, sizeof(T) * (size_t)(length - valid[c])); \
    }

/* A block of columns j is done for every component before the next block: the components read the same
   stretch of the signals, which then comes from cache once (component by component over the whole record,
   a step of 2 in 3 components read each signal 3 times from memory: 1.3x the time). */
DEFINE_ROWS(rows_single, float)
DEFINE_ROWS(rows_double, double)

/* A C-contiguous buffer of one element type (struct format "i" int32, "d" float64, "f" float32); 1 if it
   is, 0 if it is of another type (released), -1 with a Python error if it is no buffer. */
static int typed_buffer(PyObject *obj, Py_buffer *b, int flags, const char *format, Py_ssize_t itemsize) {
    if (PyObject_GetBuffer(obj, b, flags | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        b->obj = NULL;
        return -1;
    }
    if (b->itemsize == itemsize && b->format != NULL && strcmp(b->format, format) == 0 && b->len % itemsize == 0)
        return 1;
    PyBuffer_Release(b);
    b->obj = NULL;
    return 0;
}

static PyObject *poly_rows(PyObject *self, PyObject *args) {
    PyObject *signals, *o_parent, *o_var, *o_ptr, *o_mono, *o_coef, *out_obj, *result = NULL;
    Py_ssize_t n, step, m, width;
    Py_buffer b_parent = {0}, b_var = {0}, b_ptr = {0}, b_mono = {0}, b_coef = {0}, b_out = {0}, sig[MAX_VARS];
    int n_sig = 0, ok = 1, single = 1;
    if (!PyArg_ParseTuple(args, "O!nnnnOOOOOO", &PyTuple_Type, &signals, &n, &step, &m, &width, &o_parent, &o_var,
                          &o_ptr, &o_mono, &o_coef, &out_obj))
        return NULL;
    /* the index arrays int32, the coefficients float64, the output float32 or float64: anything else refused */
    Py_buffer *typed[5] = {&b_parent, &b_var, &b_ptr, &b_mono, &b_coef};
    PyObject *objs[5] = {o_parent, o_var, o_ptr, o_mono, o_coef};
    for (int i = 0; i < 5 && ok > 0; i++)
        ok = i < 4 ? typed_buffer(objs[i], typed[i], PyBUF_SIMPLE, "i", sizeof(int))
                   : typed_buffer(objs[i], typed[i], PyBUF_SIMPLE, "d", sizeof(double));
    if (ok > 0) {
        ok = typed_buffer(out_obj, &b_out, PyBUF_WRITABLE, "f", sizeof(float));
        if (ok == 0) {
            ok = typed_buffer(out_obj, &b_out, PyBUF_WRITABLE, "d", sizeof(double));
            single = 0;
        }
    }
    if (ok <= 0) {
        if (ok == 0) PyErr_SetString(PyExc_ValueError, "poly_rows: int32 indices, float64 coefficients and a float32 "
                                                       "or float64 output expected");
        goto done;
    }
    int n_vars = (int)PyTuple_GET_SIZE(signals);
    int n_mono = (int)(b_parent.len / (Py_ssize_t)sizeof(int));
    int n_rows = (int)(b_ptr.len / (Py_ssize_t)sizeof(int)) - 1;
    Py_ssize_t n_nz = b_coef.len / (Py_ssize_t)sizeof(double);
    Py_ssize_t total = ok > 0 ? b_out.len / b_out.itemsize : 0;
    Py_ssize_t length = (n_rows > 0 && m > 0) ? total / ((Py_ssize_t)n_rows * m) : 0;
    const int *parent = (const int *)b_parent.buf, *var = (const int *)b_var.buf;
    const int *ptr = (const int *)b_ptr.buf, *mono = (const int *)b_mono.buf;
    const double *coef = (const double *)b_coef.buf;
    /* step <= n + 1 and m <= MAX_COMPONENTS keep m step, and the sample indices, far from overflow */
    if (ok > 0 && (n_vars < 1 || n_vars > MAX_VARS || n_mono < 1 || b_var.len != b_parent.len || n_rows < 1 ||
                   n < 0 || step < 1 || step > n + 1 || m < 1 || m > MAX_COMPONENTS || width < 0 || length < width ||
                   total != (Py_ssize_t)n_rows * m * length || b_mono.len / (Py_ssize_t)sizeof(int) != n_nz ||
                   ptr[0] != 0 || ptr[n_rows] != n_nz))
        ok = 0;
    for (int i = 1; ok > 0 && i < n_mono; i++)
        if (parent[i] < 0 || parent[i] >= i || var[i] < 0 || var[i] >= n_vars) ok = 0;
    for (Py_ssize_t k = 0; ok > 0 && k < n_nz; k++)
        if (mono[k] < 0 || mono[k] >= n_mono) ok = 0;
    for (int r = 0; ok > 0 && r < n_rows; r++)
        if (ptr[r] > ptr[r + 1]) ok = 0;
    for (int i = 0; ok > 0 && i < n_vars; i++) {
        if (PyObject_GetBuffer(PyTuple_GET_ITEM(signals, i), &sig[i], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
            ok = -1;
            break;
        }
        n_sig++;
        if (sig[i].itemsize != (Py_ssize_t)sizeof(double) || strcmp(sig[i].format, "d") != 0 ||
            sig[i].len / (Py_ssize_t)sizeof(double) < n)
            ok = 0;
    }
    if (ok <= 0) {
        if (ok == 0) PyErr_SetString(PyExc_ValueError, "poly_rows: inconsistent buffers");
        goto done;
    }
    /* the variables of one block, its monomials, and one row's sum: (n_vars + n_mono + 1) x BLOCK values */
    size_t item = single ? sizeof(float) : sizeof(double);
    void *work = malloc(item * (size_t)(n_vars + n_mono + 1) * BLOCK);
    if (work == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    {
        const double *y[MAX_VARS];
        Py_ssize_t valid[MAX_COMPONENTS], longest = 0, stride = m * step;
        for (int i = 0; i < n_vars; i++) y[i] = (const double *)sig[i].buf;
        for (Py_ssize_t c = 0; c < m; c++) { /* component c holds the samples t = (j m + c) step */
            valid[c] = n > c * step ? (n - c * step + stride - 1) / stride : 0;
            if (valid[c] > width) valid[c] = width;
            if (valid[c] > longest) longest = valid[c];
        }
        Py_BEGIN_ALLOW_THREADS
        if (single)
            rows_single(y, n_vars, step, m, length, valid, longest, n_mono, parent, var, n_rows, ptr, mono, coef,
                        (float *)b_out.buf, (float *)work);
        else
            rows_double(y, n_vars, step, m, length, valid, longest, n_mono, parent, var, n_rows, ptr, mono, coef,
                        (double *)b_out.buf, (double *)work);
        Py_END_ALLOW_THREADS
        free(work);
    }
    Py_INCREF(Py_None);
    result = Py_None;
done:
    for (int i = 0; i < n_sig; i++) PyBuffer_Release(&sig[i]);
    for (int i = 0; i < 5; i++)
        if (typed[i]->obj != NULL) PyBuffer_Release(typed[i]);
    if (b_out.obj != NULL) PyBuffer_Release(&b_out);
    return result;
}

static PyMethodDef methods[] = {
    {"poly_rows", poly_rows, METH_VARARGS, "Polynomials of signals on every step-th sample, in polyphase order."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_polyrows",
                                    "Compiled score rows for identify.noise_spread.", -1, methods};

PyMODINIT_FUNC PyInit__polyrows(void) { return PyModule_Create(&module); }
