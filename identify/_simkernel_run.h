/*
 * The free-run kernel of identify/_simkernel.c: the model, its right-hand side and the RK4 steps (included
 * by that file alone, after <Python.h> and <math.h>, so every function here stays static and inlinable in
 * its one translation unit).
 *
 * A term is a product of small integer powers of features; the features of state i are
 * q_i, |q_i|, sign(q_i) (indices 3i, 3i+1, 3i+2), then the inputs (index 3*n_states + j), then the
 * end-stop features of state i (index 3*n_states + n_inputs + 2i, +1): the penetration
 * stop(q_i) = sign(q_i) max(|q_i| - travel_i, 0) and the contact indicator contact(q_i) = [|q_i| > travel_i].
 * The input is supplied on a fine grid of spacing h/2 (h = dt/substeps), so every RK4 stage reads
 * it directly: interpolation (linear, band-limited, analytic) is the caller's choice, in Python.
 *
 * End stops make the right-hand side jump (contact damping) or kink (stop spring) where |q_i| = travel_i,
 * and RK4 straddling that surface is only first order (1 % of the rebound speed per contact at
 * h = 61 us). So models that use these features step with the contact side of each state held fixed
 * (stop/contact continued smoothly across the surface), and a step whose end lands on another side is
 * cut at the crossing, found by regula falsi (Illinois) on the held-side step; the input at a cut is
 * the quadratic through the step's three grid values. Models without them step exactly as before.
 *
 * Speed: a free-run step is four dependent right-hand sides, a chain of latencies rather than of
 * arithmetic, so equation() keeps every value in registers, from the state it reads to the next stage's
 * state (stage()), and touches only the terms with a nonzero coefficient: the same numbers bit for bit as
 * the earlier table-based right-hand side, in about half the time (docs/identification.md, section 6;
 * benchmarks/identify_speed.py --validation-parts).
 */
#ifndef SHAKEID_SIMKERNEL_RUN_H
#define SHAKEID_SIMKERNEL_RUN_H

#define MAX_STATES 8
#define MAX_INPUTS 8
#define MAX_FEATS (5 * MAX_STATES + MAX_INPUTS)

#define MAX_POW 16
#define MAX_NZ 512

typedef struct {
    const int *ptr, *feat, *pow;
    int n_terms, n_states, n_inputs, has_stops;
    double travel[MAX_STATES];
    /* precomputed once per call: which features are used, to which power; nonzero coefficients */
    int used[MAX_FEATS], n_used, max_pow[MAX_FEATS];
    int nz_eq[MAX_NZ], nz_term[MAX_NZ], n_nz;
    double nz_coef[MAX_NZ];
    /* flattened by prepare(): per used feature (slot) its kind (FEAT_*) and source index; per nonzero
       coefficient (in equation order, eq_end[e] past equation e's last), its term's factors as
       (slot, power) pairs */
    int kind[MAX_FEATS], src[MAX_FEATS], eq_end[MAX_STATES];
    int nz_fptr[MAX_NZ + 1], f_slot[MAX_NZ * MAX_POW], f_pow[MAX_NZ * MAX_POW];
} model_t;

enum { FEAT_Q, FEAT_ABS, FEAT_SIGN, FEAT_INPUT, FEAT_STOP, FEAT_CONTACT };

static int prepare(model_t *m, const double *coef) {
    int i, j, k, e, f, n_feats = 5 * m->n_states + m->n_inputs;
    for (f = 0; f < n_feats; f++) m->max_pow[f] = 0;
    for (k = 0; k < m->ptr[m->n_terms]; k++) {
        if (m->feat[k] < 0 || m->feat[k] >= n_feats || m->pow[k] < 1 || m->pow[k] >= MAX_POW) return 0;
        if (m->pow[k] > m->max_pow[m->feat[k]]) m->max_pow[m->feat[k]] = m->pow[k];
    }
    m->n_used = 0;
    m->has_stops = 0;
    for (f = 0; f < n_feats; f++)
        if (m->max_pow[f] > 0) {
            m->used[m->n_used++] = f;
            if (f >= 3 * m->n_states + m->n_inputs) m->has_stops = 1;
        }
    m->n_nz = 0;
    for (e = 0; e < m->n_states; e++)
        for (j = 0; j < m->n_terms; j++)
            if (coef[e * m->n_terms + j] != 0.0) {
                if (m->n_nz >= MAX_NZ) return 0;
                m->nz_eq[m->n_nz] = e;
                m->nz_term[m->n_nz] = j;
                m->nz_coef[m->n_nz++] = coef[e * m->n_terms + j];
            }
    for (e = 0; e < m->n_states; e++) m->eq_end[e] = 0;
    for (i = 0; i < m->n_nz; i++) m->eq_end[m->nz_eq[i]] = i + 1;
    for (e = 1; e < m->n_states; e++)
        if (m->eq_end[e] < m->eq_end[e - 1]) m->eq_end[e] = m->eq_end[e - 1];
    int slot_of[MAX_FEATS], n_off;
    for (i = 0; i < m->n_used; i++) {
        f = m->used[i];
        slot_of[f] = i;
        if (f < 3 * m->n_states) {
            m->kind[i] = f % 3 == 0 ? FEAT_Q : f % 3 == 1 ? FEAT_ABS : FEAT_SIGN;
            m->src[i] = f / 3;
        } else if (f < 3 * m->n_states + m->n_inputs) {
            m->kind[i] = FEAT_INPUT;
            m->src[i] = f - 3 * m->n_states;
        } else {
            int g = f - 3 * m->n_states - m->n_inputs;
            m->kind[i] = g % 2 == 0 ? FEAT_STOP : FEAT_CONTACT;
            m->src[i] = g / 2;
        }
    }
    m->nz_fptr[0] = 0;
    for (i = 0, n_off = 0; i < m->n_nz; i++) {
        j = m->nz_term[i];
        for (k = m->ptr[j]; k < m->ptr[j + 1]; k++, n_off++) {
            if (n_off >= MAX_NZ * MAX_POW) return 0;
            m->f_slot[n_off] = slot_of[m->feat[k]];
            m->f_pow[n_off] = m->pow[k];
        }
        m->nz_fptr[i + 1] = n_off;
    }
    return 1;
}

/* contact side of state i: +1 beyond +travel, -1 beyond -travel, 0 between (and without a stop) */
static int side(const model_t *m, const double *x, int i) {
    return (x[i] > m->travel[i]) - (x[i] < -m->travel[i]);
}

/* Equation e of the right-hand side at state x, input u; `mode` (one side per state) holds the end-stop
   features on that side, NULL: x's own. Only the terms with a nonzero coefficient, each factor's power as
   repeated products, the products and the sum in a fixed order, all in registers: a free-run step is
   four right-hand sides in a chain, so round trips through memory (tables of powers and terms) were most
   of its time. */
static inline __attribute__((always_inline)) double equation(const model_t *m, int e, const double *x, const double *u, const int *mode,
                                                                const int stops) {
    double acc = 0.0;
    for (int j = e ? m->eq_end[e - 1] : 0; j < m->eq_end[e]; j++) {
        double v = 1.0;
        for (int f = m->nz_fptr[j]; f < m->nz_fptr[j + 1]; f++) {
            int sl = m->f_slot[f], s = m->src[sl], st;
            double b, t;
            switch (m->kind[sl]) {
            case FEAT_Q: b = x[s]; break;
            case FEAT_ABS: b = fabs(x[s]); break;
            case FEAT_SIGN: b = (double)((x[s] > 0) - (x[s] < 0)); break;
            case FEAT_INPUT: b = u[s]; break;
            default:
                if (!stops) { /* unreachable: compiled for models without end-stop features */
                    b = 0.0;
                    break;
                }
                if (m->kind[sl] == FEAT_CONTACT) {
                    st = mode ? mode[s] : side(m, x, s);
                    b = (double)(st != 0);
                    break;
                }
                st = mode ? mode[s] : side(m, x, s); /* FEAT_STOP */
                b = st ? x[s] - st * m->travel[s] : 0.0;
            }
            t = b;
            for (int p = 1; p < m->f_pow[f]; p++) t *= b;
            v *= t;
        }
        acc += m->nz_coef[j] * v;
    }
    return acc;
}

/* dx = f(x, u), all equations (mode: as equation()) */
static void rhs(const model_t *m, const double *x, const double *u, const int *mode, double *dx) {
    for (int e = 0; e < m->n_states; e++) dx[e] = equation(m, e, x, u, mode, 1);
}

/* One RK stage of a model without end stops: k = f(xin, u) and xout = x + c k per equation, each
   xout[e] straight from its sum; kp (the last stage): xout = x + c (k1 + 2 k2 + 2 k3 + k), c = h/6,
   and xout may be x. The same operations in the same order as the step written out with rhs(). */
static inline void stage(const model_t *m, const double *x, const double *xin, const double *u, double c,
                         double *k, double *xout, const double (*kp)[MAX_STATES]) {
    for (int e = 0; e < m->n_states; e++) {
        double acc = equation(m, e, xin, u, NULL, 0);
        k[e] = acc;
        xout[e] = kp ? x[e] + c * (kp[0][e] + 2.0 * kp[1][e] + 2.0 * kp[2][e] + acc) : x[e] + c * acc;
    }
}

/* one RK4 step of size h from x with the sides held (ua, ub, uc: inputs at 0, h/2, h) */
static void rk4(const model_t *m, const double *x, double h, const double *ua, const double *ub, const double *uc,
                const int *mode, double *xn) {
    double xs[MAX_STATES] = {0}, k1[MAX_STATES], k2[MAX_STATES], k3[MAX_STATES], k4[MAX_STATES];
    int i;
    rhs(m, x, ua, mode, k1);
    for (i = 0; i < m->n_states; i++) xs[i] = x[i] + 0.5 * h * k1[i];
    rhs(m, xs, ub, mode, k2);
    for (i = 0; i < m->n_states; i++) xs[i] = x[i] + 0.5 * h * k2[i];
    rhs(m, xs, ub, mode, k3);
    for (i = 0; i < m->n_states; i++) xs[i] = x[i] + h * k3[i];
    rhs(m, xs, uc, mode, k4);
    for (i = 0; i < m->n_states; i++) xn[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

/* input at fraction s of a step, from its values at 0, 1/2, 1 (quadratic) */
static void interp(int ni, const double *u0, double s, double *out) {
    double l0 = 2.0 * (s - 0.5) * (s - 1.0), l1 = -4.0 * s * (s - 1.0), l2 = 2.0 * s * (s - 0.5);
    for (int j = 0; j < ni; j++) out[j] = l0 * u0[j] + l1 * u0[ni + j] + l2 * u0[2 * ni + j];
}

/* held-side step over fraction [a, a + th (1 - a)] of the step; returns the crossing function: the
   largest penetration, past the surface, of a state that changed side (< 0: none crossed yet) */
static double cut_step(const model_t *m, const double *x, double h, const double *u0, double a, double th,
                       const int *mode, const int *changed, const int *target, double *xn) {
    double ua[MAX_INPUTS], ub[MAX_INPUTS], uc[MAX_INPUTS], span = th * (1.0 - a), g = -HUGE_VAL;
    int i, ni = m->n_inputs;
    interp(ni, u0, a, ua);
    interp(ni, u0, a + 0.5 * span, ub);
    interp(ni, u0, a + span, uc);
    rk4(m, x, span * h, ua, ub, uc, mode, xn);
    for (i = 0; i < m->n_states; i++)
        if (changed[i]) {
            /* entering: the new side's penetration; leaving: how far back inside the travel */
            double gi = mode[i] == 0 ? target[i] * xn[i] - m->travel[i] : m->travel[i] - mode[i] * xn[i];
            if (gi > g) g = gi;
        }
    return g;
}

/* one substep h from x (updated) with end stops: cut at each change of contact side (at most 4) */
static void stop_substep(const model_t *m, double *x, double h, const double *u0, int *mode) {
    double a = 0.0, xn[MAX_STATES], xl[MAX_STATES];
    int i, cut, changed[MAX_STATES], target[MAX_STATES];
    for (cut = 0; cut < 4 && a < 1.0; cut++) {
        int any = 0;
        for (i = 0; i < m->n_states; i++) changed[i] = target[i] = 0;
        cut_step(m, x, h, u0, a, 1.0, mode, changed, target, xn);
        for (i = 0; i < m->n_states; i++) {
            target[i] = side(m, xn, i);
            changed[i] = target[i] != mode[i];
            any |= changed[i];
        }
        if (!any) {
            for (i = 0; i < m->n_states; i++) x[i] = xn[i];
            return;
        }
        /* bracket [lo, hi] of the fraction of the rest of the step: g(lo) < 0 <= g(hi) */
        double lo = 0.0, hi = 1.0, glo = cut_step(m, x, h, u0, a, 0.0, mode, changed, target, xl), ghi;
        ghi = cut_step(m, x, h, u0, a, 1.0, mode, changed, target, xl);
        int last = 0, it;
        if (glo < 0.0 && ghi >= 0.0) {
            for (it = 0; it < 60 && hi - lo > 1e-12; it++) { /* the cut within 1e-12 of a step */
                double th = (lo * ghi - hi * glo) / (ghi - glo), g;
                if (!(th > lo && th < hi)) th = 0.5 * (lo + hi);
                g = cut_step(m, x, h, u0, a, th, mode, changed, target, xl);
                if (g >= 0.0) {
                    hi = th, ghi = g;
                    if (last == 1) glo *= 0.5; /* Illinois: the same end twice, halve the other */
                    last = 1;
                } else {
                    lo = th, glo = g;
                    if (last == -1) ghi *= 0.5;
                    last = -1;
                }
            }
        } else {
            hi = 0.0; /* already on the surface (or the held side does not cross): switch here */
        }
        cut_step(m, x, h, u0, a, hi, mode, changed, target, xn);
        for (i = 0; i < m->n_states; i++) {
            x[i] = xn[i];
            if (changed[i] && side(m, x, i) == target[i]) mode[i] = target[i];
        }
        if (hi == 0.0)
            for (i = 0; i < m->n_states; i++)
                if (changed[i]) mode[i] = target[i];
        a += hi * (1.0 - a);
    }
    if (a < 1.0) { /* a chatter of contacts within one step: finish it on the sides where it starts */
        for (i = 0; i < m->n_states; i++) changed[i] = 0;
        cut_step(m, x, h, u0, a, 1.0, mode, changed, target, xn);
        for (i = 0; i < m->n_states; i++) x[i] = xn[i];
    }
    for (i = 0; i < m->n_states; i++) mode[i] = side(m, x, i);
}

/* The free run in steps of `stride` samples (h = stride dt) for a model without end stops: the input at a
   step's start, middle and end read from the half-sample grid u (index 2 t is sample t, 2 t + 1 the half
   sample after it), the samples inside a step from RK4's continuous extension, third order like the
   step's own local error (x(t + th h) = x + h (b1 k1 + b2 (k2 + k3) + b4 k4), Hairer, Norsett & Wanner,
   Solving ODEs I, II.6): a smooth model slow against the sample rate (omega dt <= STEP_OMEGA / stride,
   identify.simulate.choose_step) takes stride times fewer right-hand sides on its chain of dependencies.
   The last step may be shorter. Returns the samples written, as simulate. Not inlined into free_run: inlined,
   its loop ran 8-10 % slower (code layout; measured on the Table 1 model, steps of 3 samples). */
static __attribute__((noinline)) Py_ssize_t strided_run(const model_t *m, const double *x0, const double *u, Py_ssize_t n_out, int stride,
                              double dt, double bound, double *out) {
    double x[MAX_STATES], xa[MAX_STATES], xs[MAX_STATES], xt[MAX_STATES], kk[3][MAX_STATES], k4[MAX_STATES];
    int i, ni = m->n_inputs, e, ns = m->n_states;
    Py_ssize_t t0, written = 0;
    if (n_out <= 0) return 0;
    for (i = 0; i < ns; i++) out[i] = x[i] = x0[i];
    written = 1;
    for (t0 = 0; t0 < n_out - 1;) {
        int w = (int)(n_out - 1 - t0 < stride ? n_out - 1 - t0 : stride), ok = 1;
        double h = w * dt;
        const double *ua = u + 2 * t0 * ni;
        for (i = 0; i < ns; i++) xa[i] = x[i];
        stage(m, x, x, ua, 0.5 * h, kk[0], xs, NULL);
        stage(m, x, xs, ua + w * ni, 0.5 * h, kk[1], xt, NULL);
        stage(m, x, xt, ua + w * ni, h, kk[2], xs, NULL);
        stage(m, x, xs, ua + 2 * w * ni, h / 6.0, k4, x, (const double (*)[MAX_STATES])kk);
        for (i = 0; i < ns; i++)
            if (!(fabs(x[i]) <= bound)) ok = 0; /* also catches NaN */
        if (!ok) break;
        for (int j = 1; j <= w; j++) {
            double *o = out + (t0 + j) * ns;
            if (j < w) {
                double th = (double)j / w, b1 = th - 1.5 * th * th + 2.0 / 3.0 * th * th * th,
                       b2 = th * th - 2.0 / 3.0 * th * th * th, b4 = -0.5 * th * th + 2.0 / 3.0 * th * th * th;
                for (e = 0; e < ns; e++)
                    o[e] = xa[e] + h * (b1 * kk[0][e] + b2 * (kk[1][e] + kk[2][e]) + b4 * k4[e]);
            } else {
                for (e = 0; e < ns; e++) o[e] = x[e];
            }
        }
        t0 += w;
        written = t0 + 1;
    }
    return written;
}

/* One free run of n_out samples from x0, `substeps` RK4 steps per sample (end-stop models step by
   stop_substep), or strided_run's steps of `stride` samples: the samples written, fewer than n_out if a
   state left [-bound, bound] or went NaN. Called with the GIL released. Not inlined, like strided_run. */
static __attribute__((noinline)) Py_ssize_t free_run(const model_t *m, const double *x0, const double *u, Py_ssize_t n_out,
                                                     int substeps, int stride, double dt, double bound, double *out) {
    double x[MAX_STATES], xs[MAX_STATES], xt[MAX_STATES], kk[3][MAX_STATES], k4[MAX_STATES];
    double h = dt / substeps;
    int s, i, ni = m->n_inputs, mode[MAX_STATES];
    Py_ssize_t t, written = 0;
    if (stride > 1) return strided_run(m, x0, u, n_out, stride, dt, bound, out);
    for (i = 0; i < m->n_states; i++) x[i] = x0[i];
    for (i = 0; i < m->n_states; i++) mode[i] = side(m, x, i);
    if (n_out > 0) {
        for (i = 0; i < m->n_states; i++) out[i] = x[i];
        written = 1;
    }
    for (t = 1; t < n_out; t++) {
        int ok = 1;
        for (s = 0; s < substeps; s++) {
            const double *u0 = u + ((t - 1) * 2 * (Py_ssize_t)substeps + 2 * s) * ni;
            if (m->has_stops) {
                stop_substep(m, x, h, u0, mode);
                for (i = 0; i < m->n_states; i++)
                    if (!(fabs(x[i]) <= bound)) ok = 0;
                continue;
            }
            /* xs = x + h/2 k1, xt = x + h/2 k2, xs = x + h k3 (as (0.5 * h) * k, the same numbers) */
            stage(m, x, x, u0, 0.5 * h, kk[0], xs, NULL);
            stage(m, x, xs, u0 + ni, 0.5 * h, kk[1], xt, NULL);
            stage(m, x, xt, u0 + ni, h, kk[2], xs, NULL);
            stage(m, x, xs, u0 + 2 * ni, h / 6.0, k4, x, (const double (*)[MAX_STATES])kk);
            for (i = 0; i < m->n_states; i++)
                if (!(fabs(x[i]) <= bound)) ok = 0; /* also catches NaN */
        }
        if (!ok) break;
        for (i = 0; i < m->n_states; i++) out[t * m->n_states + i] = x[i];
        written = t + 1;
    }
    return written;
}

#endif /* SHAKEID_SIMKERNEL_RUN_H */
