/* The compiled fit of mold placements (see mold_fits.py, which documents and wraps it).
 *
 * The same damped Gauss-Newton steps and Lawson rounds as `fit_mold_placements` in numpy,
 * panel by panel in one pass over each panel's points per step, instead of a dozen (p, s, 8)
 * temporaries per step. Every panel takes the same steps, refuses the same ones and stops in
 * the same round and iteration as on the numpy path; only the order in which the sums are
 * added, and the 8 x 8 solve (here Gaussian elimination with partial pivoting, there
 * LAPACK's), round differently (tests/test_mold_fits.py holds them together).
 * Arrays arrive through the buffer protocol, C-contiguous float64 (the flags as uint8); the
 * loops run without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* A C-contiguous buffer of `count` items of `itemsize` bytes, its format one of the
 * characters of `formats` (int64 says 'l' on some platforms, 'q' on others). */
static int get_buffer(PyObject *obj, Py_buffer *view, int writable, const char *name,
                      const char *formats, Py_ssize_t itemsize, Py_ssize_t count)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0)
        return -1;
    const char *f = view->format ? view->format : "B";
    if (f[0] == '<' || f[0] == '=' || f[0] == '@')
        f++;
    if (f[0] == '\0' || !strchr(formats, f[0]) || view->itemsize != itemsize
            || view->len != count * itemsize) {
        PyErr_Format(PyExc_TypeError, "%s: expected %zd items of format '%s', got %zd bytes "
                     "of format '%s'", name, count, formats, view->len, view->format);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* q = M[:3, :3] p + M[:3, 3] and its gap z - (k1 x^2 + k2 y^2) / 2 for s points. */
static void place(const double *P, const double *M, const double *K, Py_ssize_t s,
                  double *q, double *r)
{
    for (Py_ssize_t j = 0; j < s; j++) {
        const double *p = P + 3 * j;
        double *o = q + 3 * j;
        for (int a = 0; a < 3; a++)
            o[a] = M[4 * a] * p[0] + M[4 * a + 1] * p[1] + M[4 * a + 2] * p[2] + M[4 * a + 3];
        r[j] = o[2] - 0.5 * (K[0] * o[0] * o[0] + K[1] * o[1] * o[1]);
    }
}

static double weighted_squares(const double *w, const double *r, Py_ssize_t s)
{
    double sum = 0.0;
    for (Py_ssize_t j = 0; j < s; j++)
        sum += w[j] * r[j] * r[j];
    return sum;
}

/* Solves A x = b (n x n, row-major, overwritten) by Gaussian elimination with partial
 * pivoting; returns 0, or 1 on a zero pivot. */
static int solve_small(double *A, double *b, int n)
{
    for (int c = 0; c < n; c++) {
        int pivot = c;
        for (int i = c + 1; i < n; i++)
            if (fabs(A[i * n + c]) > fabs(A[pivot * n + c]))
                pivot = i;
        if (A[pivot * n + c] == 0.0)
            return 1;
        if (pivot != c) {
            for (int j = 0; j < n; j++) {
                double t = A[c * n + j];
                A[c * n + j] = A[pivot * n + j];
                A[pivot * n + j] = t;
            }
            double t = b[c];
            b[c] = b[pivot];
            b[pivot] = t;
        }
        for (int i = c + 1; i < n; i++) {
            double f = A[i * n + c] / A[c * n + c];
            for (int j = c; j < n; j++)
                A[i * n + j] -= f * A[c * n + j];
            b[i] -= f * b[c];
        }
    }
    for (int c = n - 1; c >= 0; c--) {
        double sum = b[c];
        for (int j = c + 1; j < n; j++)
            sum -= A[c * n + j] * b[j];
        b[c] = sum / A[c * n + c];
    }
    return 0;
}

/* The rigid motion of a step: rotation about w by |w| (Rodrigues), then the shift t. */
static void step_motion(const double *w, const double *t, double *D)
{
    double angle = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    double d = angle > 1e-300 ? angle : 1e-300;
    double x = w[0] / d, y = w[1] / d, z = w[2] / d;
    double S[9] = {0.0, -z, y, z, 0.0, -x, -y, x, 0.0};
    double s = sin(angle), c = 1.0 - cos(angle);
    memset(D, 0, 16 * sizeof(double));
    for (int a = 0; a < 3; a++) {
        for (int b = 0; b < 3; b++) {
            double SS = S[3 * a] * S[b] + S[3 * a + 1] * S[3 + b] + S[3 * a + 2] * S[6 + b];
            D[4 * a + b] = (a == b ? 1.0 : 0.0) + s * S[3 * a + b] + c * SS;
        }
        D[4 * a + 3] = t[a];
    }
    D[15] = 1.0;
}

static void multiply4(const double *A, const double *B, double *out)
{
    for (int a = 0; a < 4; a++)
        for (int b = 0; b < 4; b++)
            out[4 * a + b] = A[4 * a] * B[b] + A[4 * a + 1] * B[4 + b] + A[4 * a + 2] * B[8 + b]
                             + A[4 * a + 3] * B[12 + b];
}

/* The largest |gap| over the points that must be met (0 when there are none). */
static double largest_gap(const double *r, const uint8_t *must, Py_ssize_t s)
{
    double top = 0.0;
    for (Py_ssize_t j = 0; j < s; j++)
        if (must[j] && fabs(r[j]) > top)
            top = fabs(r[j]);
    return top;
}

/* The normal equations of one panel's step at its placed points q and gaps r, columns
 * scaled to unit size: normal = (A (n x n, row-major in 64), b (8), scale (8)). */
static void normal_equations(const double *w, Py_ssize_t s, int n, const double *K,
                             const double *q, const double *r, double *normal)
{
    double *A = normal, *b = normal + 64, *scale = normal + 72, J[8];
    memset(normal, 0, 80 * sizeof(double));
    for (Py_ssize_t j = 0; j < s; j++) {
        const double *o = q + 3 * j;
        double gx = -K[0] * o[0], gy = -K[1] * o[1];
        J[0] = o[1] - o[2] * gy;
        J[1] = o[2] * gx - o[0];
        J[2] = o[0] * gy - o[1] * gx;
        J[3] = gx;
        J[4] = gy;
        J[5] = 1.0;
        if (n == 8) {
            J[6] = -0.5 * o[0] * o[0];
            J[7] = -0.5 * o[1] * o[1];
        }
        for (int a = 0; a < n; a++) {
            double wa = w[j] * J[a];
            b[a] += wa * r[j];
            for (int c = a; c < n; c++)
                A[a * n + c] += wa * J[c];
        }
    }
    // columns scaled to unit size, as on the numpy path (divided one scale at a time: a
    // column of zeros has scale 1e-300, whose square underflows)
    for (int a = 0; a < n; a++)
        scale[a] = sqrt(A[a * n + a]) + 1e-300;
    for (int a = 0; a < n; a++) {
        for (int c = a; c < n; c++) {
            A[a * n + c] = A[a * n + c] / scale[a] / scale[c];
            A[c * n + a] = A[a * n + c];
        }
        b[a] = -b[a] / scale[a];
    }
}

/* One damped Gauss-Newton step of one panel; returns whether it was taken and moved the
 * panel by more than 1e-9 mm. `normal` holds the panel's normal equations where `known`
 * (a step not taken leaves them as they were: only the damping changes). */
static int panel_step(const double *P, const double *w, Py_ssize_t s, int n, double *M,
                      double *K, double *q, double *r, double *trial_q, double *trial_r,
                      double *damping, double *current, double *normal, uint8_t *known)
{
    if (!*known)
        normal_equations(w, s, n, K, q, r, normal);
    *known = 1;
    double A[64], b[8];
    const double *scale = normal + 72;
    memcpy(A, normal, sizeof A);
    memcpy(b, normal + 64, sizeof b);
    for (int a = 0; a < n; a++)
        A[a * n + a] += *damping;
    double step[8] = {0.0};
    if (solve_small(A, b, n) == 0)
        for (int a = 0; a < n; a++)
            step[a] = b[a] / scale[a];
    double D[16], trial_M[16], trial_K[2] = {K[0], K[1]};
    step_motion(step, step + 3, D);
    multiply4(D, M, trial_M);
    if (n == 8) {
        trial_K[0] += step[6];
        trial_K[1] += step[7];
    }
    place(P, trial_M, trial_K, s, trial_q, trial_r);
    double trial = weighted_squares(w, trial_r, s);
    // Levenberg-Marquardt: a step that lowers the cost is taken and the damping eased
    int better = trial < *current;
    if (better) {
        *known = 0;
        memcpy(M, trial_M, sizeof trial_M);
        K[0] = trial_K[0];
        K[1] = trial_K[1];
        memcpy(q, trial_q, 3 * s * sizeof(double));
        memcpy(r, trial_r, s * sizeof(double));
        *current = trial;
    }
    double eased = better ? *damping / 3.0 : *damping * 10.0;
    *damping = eased < 1e-12 ? 1e-12 : (eased > 1e12 ? 1e12 : eased);
    double shift = fmax(fabs(step[3]), fmax(fabs(step[4]), fabs(step[5])));
    return better && shift > 1e-9;
}

/* fit(points, base, must, free, M, K, best_M, best_K, best_gap, p, s, iterations, rounds):
 * M, K are the start and are overwritten; best_M, best_K, best_gap receive the result. */
static PyObject *fit(PyObject *self, PyObject *args)
{
    PyObject *objs[9];
    Py_ssize_t p, s;
    int iterations, rounds;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOnnii", &objs[0], &objs[1], &objs[2], &objs[3],
                          &objs[4], &objs[5], &objs[6], &objs[7], &objs[8], &p, &s,
                          &iterations, &rounds))
        return NULL;
    static const char *names[9] = {"points", "base", "must", "free", "M", "K", "best_M",
                                   "best_K", "best_gap"};
    static const char *formats[9] = {"d", "d", "B", "B", "d", "d", "d", "d", "d"};
    Py_ssize_t counts[9] = {p * s * 3, p * s, p * s, p, p * 16, p * 2, p * 16, p * 2, p};
    Py_buffer views[9];
    int got = 0;
    for (; got < 9; got++)
        if (get_buffer(objs[got], &views[got], got >= 4, names[got], formats[got],
                       formats[got][0] == 'd' ? 8 : 1, counts[got]) < 0)
            break;
    int failed = got < 9;
    double *work = NULL;
    if (!failed) {
        // per panel: q, trial q (3 s each), r, trial r, w, lawson (s each), its normal
        // equations (80)
        work = malloc((size_t)(p * s * 10 + 80 * p + 1) * sizeof(double));
        failed = work == NULL;
        if (failed)
            PyErr_NoMemory();
    }
    double *damping = NULL, *current = NULL;
    uint8_t *known = NULL;
    if (!failed) {
        damping = malloc((size_t)(2 * p + 1) * sizeof(double));
        known = malloc((size_t)p + 1);
        failed = damping == NULL || known == NULL;
        if (failed)
            PyErr_NoMemory();
        else
            current = damping + p;
    }
    if (!failed) {
        const double *P = views[0].buf, *base = views[1].buf;
        const uint8_t *must = views[2].buf, *free_shape = views[3].buf;
        double *M = views[4].buf, *K = views[5].buf, *best_M = views[6].buf;
        double *best_K = views[7].buf, *best_gap = views[8].buf;
        double *Q = work, *TQ = work + 3 * p * s, *R = work + 6 * p * s;
        double *TR = R + p * s, *W = TR + p * s, *L = W + p * s, *N = L + p * s;
        Py_BEGIN_ALLOW_THREADS
        int any_free = 0;
        for (Py_ssize_t i = 0; i < p; i++) {
            any_free |= free_shape[i] != 0;
            damping[i] = 1e-4;
            place(P + 3 * s * i, M + 16 * i, K + 2 * i, s, Q + 3 * s * i, R + s * i);
            memcpy(best_M + 16 * i, M + 16 * i, 16 * sizeof(double));
            best_K[2 * i] = K[2 * i];
            best_K[2 * i + 1] = K[2 * i + 1];
            best_gap[i] = largest_gap(R + s * i, must + s * i, s);
        }
        memcpy(W, base, p * s * sizeof(double));
        for (Py_ssize_t j = 0; j < p * s; j++)
            L[j] = 1.0;
        for (int round = 0; round < (rounds > 1 ? rounds : 1); round++) {
            for (Py_ssize_t i = 0; i < p; i++) {
                current[i] = weighted_squares(W + s * i, R + s * i, s);
                known[i] = 0;       // the weights changed
            }
            for (int it = 0; it < iterations; it++) {
                int moved = 0;
                for (Py_ssize_t i = 0; i < p; i++)
                    moved |= panel_step(P + 3 * s * i, W + s * i, s,
                                        any_free && free_shape[i] ? 8 : 6, M + 16 * i,
                                        K + 2 * i, Q + 3 * s * i, R + s * i, TQ + 3 * s * i,
                                        TR + s * i, damping + i, current + i, N + 80 * i,
                                        known + i);
                // a round ends when no panel moves any more, as on the numpy path
                if (!moved)
                    break;
            }
            for (Py_ssize_t i = 0; i < p; i++) {
                const double *r = R + s * i;
                const uint8_t *mu = must + s * i;
                double top = largest_gap(r, mu, s);
                if (top < best_gap[i]) {
                    memcpy(best_M + 16 * i, M + 16 * i, 16 * sizeof(double));
                    best_K[2 * i] = K[2 * i];
                    best_K[2 * i + 1] = K[2 * i + 1];
                    best_gap[i] = top;
                }
                // Lawson: the weights of the points that must be met grow with their gaps
                double *l = L + s * i, sum = 0.0;
                Py_ssize_t count = 0;
                for (Py_ssize_t j = 0; j < s; j++) {
                    l[j] = mu[j] ? l[j] * (fabs(r[j]) + 1e-3 * top + 1e-12) : 0.0;
                    sum += l[j];
                    count += mu[j] != 0;
                }
                double norm = (double)count / (sum > 1e-300 ? sum : 1e-300);
                for (Py_ssize_t j = 0; j < s; j++) {
                    l[j] *= norm;
                    W[s * i + j] = base[s * i + j] * (mu[j] ? l[j] : 1.0);
                }
            }
        }
        Py_END_ALLOW_THREADS
    }
    free(work);
    free(damping);
    free(known);
    for (int i = 0; i < got; i++)
        PyBuffer_Release(&views[i]);
    if (failed)
        return NULL;
    Py_RETURN_NONE;
}

/* gap_block(U, Z, rows, cols, v, K, deviation, variant, p, s, m): for every panel of `rows`
 * (n,) and mold of `cols` (c,) with curvatures K (c, 2), the gap of the panel's samples in
 * placement frame v on the mold, half the spread of z - (u0 k1 + u1 k2) / 2 (U (p, 4, s, 2),
 * Z (p, 4, s)); where it is smaller than deviation[row, col] (p, m) it is written there and
 * v in variant[row, col]. The products and sums are those of `_gap_matrix`'s numpy path,
 * in its order: the same numbers. A NaN gap replaces nothing, as there. */
static PyObject *gap_block(PyObject *self, PyObject *args)
{
    PyObject *objs[8];
    Py_ssize_t v, p, s, m;
    if (!PyArg_ParseTuple(args, "OOOOnOOOnnn", &objs[0], &objs[1], &objs[2], &objs[3], &v,
                          &objs[4], &objs[5], &objs[6], &p, &s, &m))
        return NULL;
    if (v < 0 || v > 3) {
        PyErr_SetString(PyExc_ValueError, "v: a placement frame 0 .. 3");
        return NULL;
    }
    if (s <= 0) {
        PyErr_SetString(PyExc_ValueError, "s: a panel has at least one sample");
        return NULL;
    }
    Py_ssize_t n = PyObject_Length(objs[2]), c = PyObject_Length(objs[3]);
    if (n < 0 || c < 0)
        return NULL;
    static const char *names[7] = {"U", "Z", "rows", "cols", "K", "deviation", "variant"};
    static const char *formats[7] = {"d", "d", "lq", "lq", "d", "d", "lq"};
    Py_ssize_t counts[7] = {p * 4 * s * 2, p * 4 * s, n, c, c * 2, p * m, p * m};
    Py_buffer views[7];
    int got = 0;
    for (; got < 7; got++)
        if (get_buffer(objs[got], &views[got], got >= 5, names[got], formats[got], 8,
                       counts[got]) < 0)
            break;
    int failed = got < 7;
    if (!failed) {
        const double *U = views[0].buf, *Z = views[1].buf, *K = views[4].buf;
        const int64_t *row = views[2].buf, *col = views[3].buf;
        double *deviation = views[5].buf;
        int64_t *variant = views[6].buf;
        for (Py_ssize_t i = 0; i < n && !failed; i++)
            failed = row[i] < 0 || row[i] >= p;
        for (Py_ssize_t j = 0; j < c && !failed; j++)
            failed = col[j] < 0 || col[j] >= m;
        if (failed)
            PyErr_SetString(PyExc_IndexError, "gap_block: a row or column out of range");
        else {
            Py_BEGIN_ALLOW_THREADS
            for (Py_ssize_t i = 0; i < n; i++) {
                const double *u = U + ((row[i] * 4 + v) * s) * 2, *z = Z + (row[i] * 4 + v) * s;
                for (Py_ssize_t j = 0; j < c; j++) {
                    const double k0 = K[2 * j], k1 = K[2 * j + 1];
                    double hi = -INFINITY, lo = INFINITY;
                    int nan = 0;
                    for (Py_ssize_t t = 0; t < s; t++) {
                        double r = z[t] - 0.5 * (u[2 * t] * k0 + u[2 * t + 1] * k1);
                        nan |= r != r;
                        hi = r > hi ? r : hi;
                        lo = r < lo ? r : lo;
                    }
                    double gap = nan ? NAN : 0.5 * (hi - lo);
                    double *slot = deviation + row[i] * m + col[j];
                    if (gap < *slot) {
                        *slot = gap;
                        variant[row[i] * m + col[j]] = v;
                    }
                }
            }
            Py_END_ALLOW_THREADS
        }
    }
    for (int i = 0; i < got; i++)
        PyBuffer_Release(&views[i]);
    if (failed)
        return NULL;
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"fit", fit, METH_VARARGS, "Fit mold placements (see fabplan.fabricate.molds.mold_fits)."},
    {"gap_block", gap_block, METH_VARARGS,
     "Gaps of panels on molds (see fabplan.fabricate.molds.mold_assignment._gap_matrix)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "mold_fit_kernel", "The compiled fit of mold placements.", -1,
    methods,
};

PyMODINIT_FUNC PyInit_mold_fit_kernel(void)
{
    return PyModule_Create(&module);
}
