/* Compiled sums of the normal equations (see kernels.py, which documents and wraps them).
 *
 * The terms are formed with the same operations and added in the same order as numpy's
 * np.add.at and np.bincount do, so the results are the same to the last bit. Built with
 * floating-point contraction off: a fused multiply-add would round differently.
 * Arrays arrive through the buffer protocol, C-contiguous; the loops run without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

/* An index array's element as a Py_ssize_t: int32 or int64. */
static inline Py_ssize_t index_at(const void *data, Py_ssize_t itemsize, Py_ssize_t i)
{
    return itemsize == 4 ? (Py_ssize_t)((const int32_t *)data)[i]
                         : (Py_ssize_t)((const int64_t *)data)[i];
}

static int get_buffer(PyObject *obj, Py_buffer *view, int writable, const char *name,
                      int floating)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0)
        return -1;
    const char *f = view->format ? view->format : "B";
    if (f[0] == '<' || f[0] == '=' || f[0] == '@')
        f++;
    int ok = floating ? (f[0] == 'd' && view->itemsize == 8)
                      : ((view->itemsize == 4 || view->itemsize == 8) && strchr("ilq", f[0]) != NULL);
    if (!ok) {
        PyErr_Format(PyExc_TypeError, "%s: expected %s, got format '%s' of %zd bytes", name,
                     floating ? "float64" : "int32 or int64", view->format, view->itemsize);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* The products of sum_products; one of slots32 and slots64 is given. Returns 1 on a slot
 * out of range. Written twice over the index type so that the inner loop has no branch. */
#define PRODUCTS_LOOP(SLOTS)                                                           \
    for (Py_ssize_t i = 0; i < k; i++) {                                               \
        for (Py_ssize_t j = i; j < k; j++, pair++) {                                   \
            const double *a = wd + i * m, *b = wd + j * m;                             \
            const double *mp = md ? md + pair * m : NULL;                              \
            for (Py_ssize_t r = 0; r < m; r++) {                                       \
                Py_ssize_t s = (Py_ssize_t)SLOTS[at + r];                              \
                if (s < 0 || s >= nsummed) return 1;                                   \
                double product = a[r] * b[r];                                          \
                out[s] += mp ? product * mp[r] : product;                              \
            }                                                                          \
            at += m;                                                                   \
        }                                                                              \
    }

static int products_loop(const double *wd, const double *md, const int32_t *slots32,
                         const int64_t *slots64, Py_ssize_t k, Py_ssize_t m, Py_ssize_t at,
                         double *out, Py_ssize_t nsummed)
{
    Py_ssize_t pair = 0;
    if (slots32) {
        PRODUCTS_LOOP(slots32)
    } else {
        PRODUCTS_LOOP(slots64)
    }
    return 0;
}

/* sum_products(weighted (k, m), k, m, multiplicity (p, m) or None, slots, start, summed)
 * -> the next family's first product. Pair-major, then rows: the products' order. */
static PyObject *sum_products(PyObject *self, PyObject *args)
{
    PyObject *w_obj, *mult_obj, *slots_obj, *summed_obj;
    Py_ssize_t k, m, start;
    if (!PyArg_ParseTuple(args, "OnnOOnO", &w_obj, &k, &m, &mult_obj, &slots_obj, &start,
                          &summed_obj))
        return NULL;
    Py_buffer w, mult, slots, summed;
    int has_mult = mult_obj != Py_None;
    if (get_buffer(w_obj, &w, 0, "weighted", 1) < 0)
        return NULL;
    if (has_mult && get_buffer(mult_obj, &mult, 0, "multiplicity", 1) < 0) {
        PyBuffer_Release(&w);
        return NULL;
    }
    if (get_buffer(slots_obj, &slots, 0, "slots", 0) < 0) {
        PyBuffer_Release(&w);
        if (has_mult) PyBuffer_Release(&mult);
        return NULL;
    }
    if (get_buffer(summed_obj, &summed, 1, "summed", 1) < 0) {
        PyBuffer_Release(&w);
        if (has_mult) PyBuffer_Release(&mult);
        PyBuffer_Release(&slots);
        return NULL;
    }
    Py_ssize_t pairs = k * (k + 1) / 2;
    Py_ssize_t nslots = slots.len / slots.itemsize, nsummed = summed.len / 8;
    int fits = w.len / 8 >= k * m && start >= 0 && start + pairs * m <= nslots
               && (!has_mult || mult.len / 8 >= pairs * m);
    Py_ssize_t at = start;
    if (fits) {
        const double *wd = (const double *)w.buf;
        const double *md = has_mult ? (const double *)mult.buf : NULL;
        double *out = (double *)summed.buf;
        Py_ssize_t bad = 0;
        Py_BEGIN_ALLOW_THREADS
        if (slots.itemsize == 4)
            bad = products_loop(wd, md, (const int32_t *)slots.buf, NULL, k, m, at, out, nsummed);
        else
            bad = products_loop(wd, md, NULL, (const int64_t *)slots.buf, k, m, at, out, nsummed);
        Py_END_ALLOW_THREADS
        at += pairs * m;
        fits = !bad;
    }
    PyBuffer_Release(&w);
    if (has_mult) PyBuffer_Release(&mult);
    PyBuffer_Release(&slots);
    PyBuffer_Release(&summed);
    if (!fits) {
        PyErr_SetString(PyExc_ValueError, "sum_products: arrays do not match their shapes");
        return NULL;
    }
    return PyLong_FromSsize_t(at);
}

/* sum_gradient(jacobian (m, k), k, m, weights (m,), residual (m,), columns (m, k), part)
 * part[columns[r, i]] += (J[r, i] w[r]) (w[r] res[r]), row-major as np.bincount reads it. */
static PyObject *sum_gradient(PyObject *self, PyObject *args)
{
    PyObject *j_obj, *w_obj, *r_obj, *c_obj, *p_obj;
    Py_ssize_t k, m;
    if (!PyArg_ParseTuple(args, "OnnOOOO", &j_obj, &k, &m, &w_obj, &r_obj, &c_obj, &p_obj))
        return NULL;
    Py_buffer jac, wts, res, cols, part;
    if (get_buffer(j_obj, &jac, 0, "jacobian", 1) < 0)
        return NULL;
    if (get_buffer(w_obj, &wts, 0, "weights", 1) < 0) {
        PyBuffer_Release(&jac);
        return NULL;
    }
    if (get_buffer(r_obj, &res, 0, "residual", 1) < 0) {
        PyBuffer_Release(&jac); PyBuffer_Release(&wts);
        return NULL;
    }
    if (get_buffer(c_obj, &cols, 0, "columns", 0) < 0) {
        PyBuffer_Release(&jac); PyBuffer_Release(&wts); PyBuffer_Release(&res);
        return NULL;
    }
    if (get_buffer(p_obj, &part, 1, "part", 1) < 0) {
        PyBuffer_Release(&jac); PyBuffer_Release(&wts); PyBuffer_Release(&res);
        PyBuffer_Release(&cols);
        return NULL;
    }
    Py_ssize_t nparts = part.len / 8;
    int fits = jac.len / 8 >= k * m && wts.len / 8 >= m && res.len / 8 >= m
               && cols.len / cols.itemsize >= k * m;
    if (fits) {
        const double *J = (const double *)jac.buf, *W = (const double *)wts.buf;
        const double *R = (const double *)res.buf;
        double *out = (double *)part.buf;
        Py_ssize_t bad = 0;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t r = 0; r < m && !bad; r++) {
            double wr = W[r] * R[r];
            for (Py_ssize_t i = 0; i < k; i++) {
                Py_ssize_t c = index_at(cols.buf, cols.itemsize, r * k + i);
                if (c < 0 || c >= nparts) { bad = 1; break; }
                out[c] += (J[r * k + i] * W[r]) * wr;
            }
        }
        Py_END_ALLOW_THREADS
        fits = !bad;
    }
    PyBuffer_Release(&jac); PyBuffer_Release(&wts); PyBuffer_Release(&res);
    PyBuffer_Release(&cols); PyBuffer_Release(&part);
    if (!fits) {
        PyErr_SetString(PyExc_ValueError, "sum_gradient: arrays do not match their shapes");
        return NULL;
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"sum_products", sum_products, METH_VARARGS, "Add a family's entry products into the "
     "normal equations' values, in np.add.at's order."},
    {"sum_gradient", sum_gradient, METH_VARARGS, "Add a family's J^T W^2 r terms, in "
     "np.bincount's order."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "normal_sums", "Compiled sums of the normal equations.", -1, methods,
};

PyMODINIT_FUNC PyInit_normal_sums(void)
{
    return PyModule_Create(&module);
}
