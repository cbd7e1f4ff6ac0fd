/* Compiled sums of the normal equations and their pattern (see kernels.py, which documents
 * and wraps them).
 *
 * The terms are formed with the same operations and added in the same order as numpy's
 * np.add.at and np.bincount do, so the results are the same to the last bit. Built with
 * floating-point contraction off: a fused multiply-add would round differently.
 * Arrays arrive through the buffer protocol, C-contiguous; the loops run without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <stdlib.h>
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

/* ------------------------------------------------------------------ the pattern
 * The upper triangle of J^T J: row p holds every q >= p that some Jacobian row's two
 * entries name (p the smaller free column), and p itself; columns sorted within a row.
 * `pattern_rows` finds the rows and hands them over in a capsule; `pattern_fill` copies
 * them out in the pattern's index type and writes every product's slot. The same pattern
 * as the numpy path builds (fabplan/solve/pattern.py), which a test compares. */

typedef struct {
    int32_t *columns;       /* the rows' columns, one row after the other */
    Py_ssize_t nnz;
} Rows;

static void free_rows(PyObject *capsule)
{
    Rows *rows = PyCapsule_GetPointer(capsule, "fabplan.pattern_rows");
    if (rows) {
        free(rows->columns);
        free(rows);
    }
}

/* The families' column arrays, each (m, k) int64 C-contiguous, as buffers. */
static int family_buffers(PyObject *families, Py_buffer **views, Py_ssize_t *count)
{
    PyObject *seq = PySequence_Fast(families, "families: expected a sequence of arrays");
    if (!seq)
        return -1;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    *views = calloc(n ? n : 1, sizeof(Py_buffer));
    if (!*views) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t f = 0; f < n; f++) {
        PyObject *a = PySequence_Fast_GET_ITEM(seq, f);
        if (PyObject_GetBuffer(a, &(*views)[f], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_ND) < 0
            || (*views)[f].itemsize != 8 || (*views)[f].ndim != 2) {
            if (!PyErr_Occurred())
                PyErr_SetString(PyExc_TypeError, "families: expected (m, k) int64 arrays");
            else
                f--;
            for (Py_ssize_t g = 0; g <= f; g++)
                PyBuffer_Release(&(*views)[g]);
            free(*views);
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    *count = n;
    return 0;
}

static void release_families(Py_buffer *views, Py_ssize_t count)
{
    for (Py_ssize_t f = 0; f < count; f++)
        PyBuffer_Release(&views[f]);
    free(views);
}

static int compare_int32(const void *a, const void *b)
{
    int32_t x = *(const int32_t *)a, y = *(const int32_t *)b;
    return (x > y) - (x < y);
}

static void sort_int32(int32_t *a, Py_ssize_t n)
{
    if (n > 32) {
        qsort(a, (size_t)n, sizeof(int32_t), compare_int32);
        return;
    }
    for (Py_ssize_t i = 1; i < n; i++) {
        int32_t v = a[i];
        Py_ssize_t j = i;
        for (; j > 0 && a[j - 1] > v; j--)
            a[j] = a[j - 1];
        a[j] = v;
    }
}

/* Runs the code given for every product of a family, with `p <= q` its columns, `held_`
 * whether either is held and `index_` its place in the family's products (pair-major,
 * then by row). The loop runs by row: a row's products name few rows of the pattern,
 * which stay in the cache for them. */
#define FOR_PRODUCTS(view, nfree, ...)                                                 \
    do {                                                                               \
        const int64_t *c_ = (const int64_t *)(view).buf;                               \
        Py_ssize_t m_ = (view).shape[0], k_ = (view).shape[1];                         \
        for (Py_ssize_t r_ = 0; r_ < m_; r_++) {                                       \
            const int64_t *row_ = c_ + r_ * k_;                                        \
            Py_ssize_t pair_ = 0;                                                      \
            for (Py_ssize_t i_ = 0; i_ < k_; i_++)                                     \
                for (Py_ssize_t j_ = i_; j_ < k_; j_++, pair_++) {                     \
                    int64_t a_ = row_[i_], b_ = row_[j_];                              \
                    int held_ = a_ < 0 || b_ < 0 || a_ >= (nfree) || b_ >= (nfree);    \
                    int64_t p = a_ < b_ ? a_ : b_, q = a_ < b_ ? b_ : a_;              \
                    Py_ssize_t index_ = pair_ * m_ + r_;                               \
                    (void)q;                                                           \
                    (void)index_;                                                      \
                    __VA_ARGS__                                                        \
                }                                                                      \
        }                                                                              \
    } while (0)

/* pattern_rows(families, nfree, indptr (nfree + 1,) int64) -> (capsule of the rows,
 * per family whether a row names one free variable at two entries). */
static PyObject *pattern_rows(PyObject *self, PyObject *args)
{
    PyObject *families, *indptr_obj;
    Py_ssize_t nfree;
    if (!PyArg_ParseTuple(args, "OnO", &families, &nfree, &indptr_obj))
        return NULL;
    if (nfree < 0 || nfree >= INT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "pattern_rows: too many free variables");
        return NULL;
    }
    Py_buffer indptr;
    if (get_buffer(indptr_obj, &indptr, 1, "indptr", 0) < 0)
        return NULL;
    if (indptr.itemsize != 8 || indptr.len / 8 != nfree + 1) {
        PyBuffer_Release(&indptr);
        PyErr_SetString(PyExc_ValueError, "pattern_rows: indptr must be (nfree + 1,) int64");
        return NULL;
    }
    Py_buffer *views;
    Py_ssize_t count;
    if (family_buffers(families, &views, &count) < 0) {
        PyBuffer_Release(&indptr);
        return NULL;
    }
    int64_t *start = (int64_t *)indptr.buf;
    int64_t *fill = calloc((size_t)nfree + 1, sizeof(int64_t));
    char *repeats = calloc((size_t)count + 1, 1);     /* a row names a variable twice */
    int32_t *mark = malloc(((size_t)nfree + 1) * sizeof(int32_t));
    Rows *rows = calloc(1, sizeof(Rows));
    int32_t *bucket = NULL;
    int failed = !fill || !mark || !rows || !repeats;
    if (!failed) {
        Py_BEGIN_ALLOW_THREADS
        /* the candidates of every row, duplicates and its diagonal included */
        memset(start, 0, ((size_t)nfree + 1) * sizeof(int64_t));
        for (Py_ssize_t f = 0; f < count; f++)
            FOR_PRODUCTS(views[f], nfree, {
                if (!held_) {
                    start[p + 1]++;
                    repeats[f] |= p == q && i_ != j_;
                }
            });
        for (Py_ssize_t p = 0; p < nfree; p++)
            start[p + 1] += start[p] + 1;
        bucket = malloc(((size_t)start[nfree] + 1) * sizeof(int32_t));
        if (bucket) {
            for (Py_ssize_t p = 0; p < nfree; p++) {
                bucket[start[p]] = (int32_t)p;
                fill[p] = start[p] + 1;
            }
            for (Py_ssize_t f = 0; f < count; f++)
                FOR_PRODUCTS(views[f], nfree, if (!held_) bucket[fill[p]++] = (int32_t)q;);
            /* each row's distinct columns, sorted, moved down in place: a row never
             * starts after its candidates did */
            for (Py_ssize_t p = 0; p <= nfree; p++)
                mark[p] = -1;
            int64_t at = 0;
            for (Py_ssize_t p = 0; p < nfree; p++) {
                int64_t from = start[p], to = start[p + 1], row = at;
                for (int64_t t = from; t < to; t++) {
                    int32_t q = bucket[t];
                    if (mark[q] != (int32_t)p) {
                        mark[q] = (int32_t)p;
                        bucket[at++] = q;
                    }
                }
                sort_int32(bucket + row, at - row);
                start[p] = row;
            }
            start[nfree] = at;
            rows->nnz = at;
        }
        Py_END_ALLOW_THREADS
        failed = bucket == NULL;
    }
    free(fill);
    free(mark);
    release_families(views, count);
    PyBuffer_Release(&indptr);
    if (failed) {
        free(bucket);
        free(rows);
        free(repeats);
        return PyErr_NoMemory();
    }
    rows->columns = bucket;
    PyObject *capsule = PyCapsule_New(rows, "fabplan.pattern_rows", free_rows);
    if (!capsule) {
        free(bucket);
        free(rows);
        free(repeats);
        return NULL;
    }
    PyObject *flags = PyTuple_New(count);
    for (Py_ssize_t f = 0; flags && f < count; f++)
        PyTuple_SET_ITEM(flags, f, PyBool_FromLong(repeats[f]));
    free(repeats);
    if (!flags) {
        Py_DECREF(capsule);
        return NULL;
    }
    PyObject *result = PyTuple_Pack(2, capsule, flags);
    Py_DECREF(capsule);
    Py_DECREF(flags);
    return result;
}

/* pattern_fill(rows, families, nfree, indptr (nfree + 1,) int64, indices (nnz,),
 * slots (products,)): the rows' columns into `indices` and every product's position in
 * them into `slots` (nnz for a product on a held variable); indices and slots int32 or
 * int64 alike. */
static PyObject *pattern_fill(PyObject *self, PyObject *args)
{
    PyObject *capsule, *families, *indptr_obj, *indices_obj, *slots_obj;
    Py_ssize_t nfree;
    if (!PyArg_ParseTuple(args, "OOnOOO", &capsule, &families, &nfree, &indptr_obj,
                          &indices_obj, &slots_obj))
        return NULL;
    Rows *rows = PyCapsule_GetPointer(capsule, "fabplan.pattern_rows");
    if (!rows)
        return NULL;
    Py_buffer indptr, indices, slots;
    if (get_buffer(indptr_obj, &indptr, 0, "indptr", 0) < 0)
        return NULL;
    if (get_buffer(indices_obj, &indices, 1, "indices", 0) < 0) {
        PyBuffer_Release(&indptr);
        return NULL;
    }
    if (get_buffer(slots_obj, &slots, 1, "slots", 0) < 0) {
        PyBuffer_Release(&indptr);
        PyBuffer_Release(&indices);
        return NULL;
    }
    Py_buffer *views;
    Py_ssize_t count;
    if (family_buffers(families, &views, &count) < 0) {
        PyBuffer_Release(&indptr); PyBuffer_Release(&indices); PyBuffer_Release(&slots);
        return NULL;
    }
    Py_ssize_t products = 0;
    for (Py_ssize_t f = 0; f < count; f++)
        products += views[f].shape[1] * (views[f].shape[1] + 1) / 2 * views[f].shape[0];
    int fits = indptr.itemsize == 8 && indptr.len / 8 == nfree + 1
               && ((int64_t *)indptr.buf)[nfree] == rows->nnz
               && indices.len / indices.itemsize == rows->nnz
               && slots.len / slots.itemsize == products
               && indices.itemsize == slots.itemsize;
    if (fits) {
        const int64_t *ptr = (const int64_t *)indptr.buf;
        const int32_t *cols = rows->columns;
        int64_t nnz = rows->nnz;
        int wide = indices.itemsize == 8;
        Py_BEGIN_ALLOW_THREADS
        for (int64_t t = 0; t < nnz; t++) {
            if (wide)
                ((int64_t *)indices.buf)[t] = cols[t];
            else
                ((int32_t *)indices.buf)[t] = cols[t];
        }
        Py_ssize_t at = 0;
        for (Py_ssize_t f = 0; f < count; f++) {
            FOR_PRODUCTS(views[f], nfree, {
                int64_t slot = nnz;
                if (!held_) {
                    int64_t lo = ptr[p], hi = ptr[p + 1] - 1;
                    while (lo < hi) {           /* q is in row p: find it */
                        int64_t mid = lo + (hi - lo) / 2;
                        if (cols[mid] < q) lo = mid + 1; else hi = mid;
                    }
                    slot = lo;
                }
                if (wide)
                    ((int64_t *)slots.buf)[at + index_] = slot;
                else
                    ((int32_t *)slots.buf)[at + index_] = (int32_t)slot;
            });
            at += views[f].shape[1] * (views[f].shape[1] + 1) / 2 * views[f].shape[0];
        }
        Py_END_ALLOW_THREADS
    }
    release_families(views, count);
    PyBuffer_Release(&indptr); PyBuffer_Release(&indices); PyBuffer_Release(&slots);
    if (!fits) {
        PyErr_SetString(PyExc_ValueError, "pattern_fill: arrays do not match the rows");
        return NULL;
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"sum_products", sum_products, METH_VARARGS, "Add a family's entry products into the "
     "normal equations' values, in np.add.at's order."},
    {"sum_gradient", sum_gradient, METH_VARARGS, "Add a family's J^T W^2 r terms, in "
     "np.bincount's order."},
    {"pattern_rows", pattern_rows, METH_VARARGS, "The upper triangle's rows of J^T J."},
    {"pattern_fill", pattern_fill, METH_VARARGS, "The pattern's indices and every "
     "product's slot."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "normal_sums", "Compiled sums of the normal equations.", -1, methods,
};

PyMODINIT_FUNC PyInit_normal_sums(void)
{
    return PyModule_Create(&module);
}
