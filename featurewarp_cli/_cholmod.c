/* featurewarp_cli._cholmod: a small binding of the system CHOLMOD (SuiteSparse) for solver.py.
 *
 *   analyze(n, rows, cols, supernodal=False, ordering=NATURAL) -> Symbolic
 *                 ordering and symbolic analysis of the pattern of a symmetric matrix
 *                 given by the triplets of its lower triangle
 *   Symbolic.factorize(rows, cols, vals) -> Factor
 *                 numeric Cholesky factorization of a matrix with that pattern
 *   Factor.solve(b, out=None) -> out
 *                 A x = b for b of shape (n,) or (n, k)
 *
 * Indices are int32, CHOLMOD's "int" API (cholmod_*): on the grid systems its simplicial
 * factorization is 1.4 times as fast as the SuiteSparse_long one (cholmod_l_*: 68 vs 48 ms
 * at 51 k unknowns, less memory traffic), and int32 reaches far beyond featurewarp's
 * grids (nnz(L) an estimated 0.2 G at its 4 M-node limit; CHOLMOD reports
 * CHOLMOD_TOO_LARGE, a MemoryError here, past 2^31). Every object owns its own
 * cholmod_common (CHOLMOD's settings, statistics and workspace), so objects may be used
 * from different threads at once: the CHOLMOD calls run without the GIL, and a Factor
 * serialises the solves made on it (they share its workspace). Arrays come in as
 * C-contiguous buffers (no numpy C API).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <pythread.h>
#include <stdint.h>
#include <string.h>

#include "render/_buffer.h"

#include <cholmod.h>

#define CH(name) cholmod_##name
typedef int32_t Int;
#define ITYPE CHOLMOD_INT
#define INT "i", 4
#define INDEX_MAX INT32_MAX

static PyObject *NotPositiveDefinite;
/* Bytes that CHOLMOD still counted as in use when an object was freed (a leak check for
 * the tests: it must stay 0). Updated under the GIL, in the deallocators. */
static Py_ssize_t leaked_bytes = 0;

#define F64 "d", 8

/* A fresh cholmod_common with CHOLMOD's defaults, silent: failures become Python
 * exceptions instead of messages on stdout. */
static void
start(cholmod_common *c)
{
    CH(start)(c);
    c->print = 0;
}

/* Free a cholmod_common's workspace; count what CHOLMOD still held (it must be nothing). */
static void
finish(cholmod_common *c)
{
    CH(finish)(c);
    leaked_bytes += (Py_ssize_t)c->memory_inuse;
}

/* The Python exception for a failed CHOLMOD call (c->status < 0), raised with the GIL. */
static PyObject *
fail(cholmod_common *c, const char *what)
{
    if (c->status == CHOLMOD_OUT_OF_MEMORY || c->status == CHOLMOD_TOO_LARGE)
        return PyErr_Format(PyExc_MemoryError, "CHOLMOD %s: out of memory, or too large for its "
                            "indices (status %d)", what, c->status);
    return PyErr_Format(PyExc_RuntimeError, "CHOLMOD %s failed (status %d)", what, c->status);
}

/* Read the triplets (rows, cols[, vals]) of a lower triangle: equal lengths, and
 * 0 <= col <= row < n for every entry. Returns the count, or -1 with an exception set. */
static Py_ssize_t
triplets(Int n, PyObject *rows, PyObject *cols, PyObject *vals, Py_buffer *r, Py_buffer *c,
         Py_buffer *v)
{
    if (get(rows, r, INT, 0, "rows") < 0)
        return -1;
    if (get(cols, c, INT, 0, "cols") < 0) {
        PyBuffer_Release(r);
        return -1;
    }
    if (vals && get(vals, v, F64, 0, "vals") < 0) {
        PyBuffer_Release(r);
        PyBuffer_Release(c);
        return -1;
    }
    Py_ssize_t m = r->len / r->itemsize;
    Py_ssize_t bad = -1;
    if (c->len == r->len && (!vals || v->len / v->itemsize == m)) {
        const Int *ri = r->buf, *ci = c->buf;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t k = 0; k < m; k++)
            if (ci[k] < 0 || ci[k] > ri[k] || ri[k] >= n) {
                bad = k;
                break;
            }
        Py_END_ALLOW_THREADS
        if (bad < 0)
            return m;
        PyErr_Format(PyExc_ValueError, "entry %zd (%lld, %lld) is not in the lower triangle of a "
                     "%lld x %lld matrix", bad, (long long)((Int *)r->buf)[bad],
                     (long long)((Int *)c->buf)[bad], (long long)n, (long long)n);
    } else {
        PyErr_SetString(PyExc_ValueError, "rows, cols and vals must have the same length");
    }
    PyBuffer_Release(r);
    PyBuffer_Release(c);
    if (vals)
        PyBuffer_Release(v);
    return -1;
}

/* A cholmod_triplet header over the callers' arrays (nothing copied; CHOLMOD only reads
 * them). stype -1: symmetric, the entries are those of the lower triangle. */
static cholmod_triplet
header(Int n, Py_ssize_t m, void *rows, void *cols, void *vals)
{
    cholmod_triplet t;
    memset(&t, 0, sizeof t);
    t.nrow = t.ncol = (size_t)n;
    t.nzmax = t.nnz = (size_t)m;
    t.i = rows;
    t.j = cols;
    t.x = vals;
    t.stype = -1;
    t.itype = ITYPE;
    t.xtype = vals ? CHOLMOD_REAL : CHOLMOD_PATTERN;
    t.dtype = CHOLMOD_DOUBLE;
    return t;
}

/* ------------------------------------------------------------------ Factor */

typedef struct {
    PyObject_HEAD
    cholmod_common c;
    cholmod_factor *L;          /* numeric factor, owned */
    PyThread_type_lock lock;    /* held (without the GIL) while CHOLMOD uses c */
} Factor;

static void
Factor_dealloc(Factor *self)
{
    CH(free_factor)(&self->L, &self->c);
    finish(&self->c);
    if (self->lock)
        PyThread_free_lock(self->lock);
    PyObject_Free(self);
}

static PyObject *
Factor_solve(Factor *self, PyObject *args)
{
    PyObject *b_obj, *out_obj = Py_None;
    if (!PyArg_ParseTuple(args, "O|O:solve", &b_obj, &out_obj))
        return NULL;
    Py_buffer b, out;
    if (get(b_obj, &b, F64, 0, "b") < 0)
        return NULL;
    Int n = (Int)self->L->n;
    if (b.ndim < 1 || b.ndim > 2 || b.shape[0] != n) {
        PyErr_Format(PyExc_ValueError, "b must have shape (%lld,) or (%lld, k)", (long long)n,
                     (long long)n);
        PyBuffer_Release(&b);
        return NULL;
    }
    Py_ssize_t k = b.ndim == 2 ? b.shape[1] : 1;
    if (out_obj == Py_None)
        out_obj = PyObject_CallMethod(b_obj, "copy", NULL);    /* a new array shaped like b */
    else
        Py_INCREF(out_obj);
    if (!out_obj) {
        PyBuffer_Release(&b);
        return NULL;
    }
    if (get(out_obj, &out, F64, 1, "out") < 0) {
        PyBuffer_Release(&b);
        Py_DECREF(out_obj);
        return NULL;
    }
    if (out.len != b.len) {
        PyErr_SetString(PyExc_ValueError, "out must have the shape of b");
        goto error;
    }
    int status = CHOLMOD_OK;
    Py_BEGIN_ALLOW_THREADS
    PyThread_acquire_lock(self->lock, WAIT_LOCK);
    cholmod_common *c = &self->c;
    /* CHOLMOD's dense matrices are column-major: B (n x k) is the transpose of b. */
    cholmod_dense *B = CH(allocate_dense)(n, k, n, CHOLMOD_REAL, c), *X = NULL;
    if (B) {
        const double *src = b.buf;
        double *bx = B->x;
        for (Py_ssize_t i = 0; i < n; i++)
            for (Py_ssize_t j = 0; j < k; j++)
                bx[i + j * n] = src[i * k + j];
        X = CH(solve)(CHOLMOD_A, self->L, B, c);         /* X = A \ B, a new matrix */
    }
    if (X) {
        double *dst = out.buf;
        const double *xx = X->x;
        for (Py_ssize_t i = 0; i < n; i++)
            for (Py_ssize_t j = 0; j < k; j++)
                dst[i * k + j] = xx[i + j * n];
    } else {
        status = c->status;
    }
    CH(free_dense)(&B, c);
    CH(free_dense)(&X, c);
    PyThread_release_lock(self->lock);
    Py_END_ALLOW_THREADS
    if (status < 0) {
        self->c.status = status;
        fail(&self->c, "solve");
        goto error;
    }
    PyBuffer_Release(&b);
    PyBuffer_Release(&out);
    return out_obj;
error:
    PyBuffer_Release(&b);
    PyBuffer_Release(&out);
    Py_DECREF(out_obj);
    return NULL;
}

static PyObject *
Factor_n(Factor *self, void *closure)
{
    return PyLong_FromLongLong((long long)self->L->n);
}

static PyObject *
Factor_supernodal(Factor *self, void *closure)
{
    return PyBool_FromLong(self->L->is_super);
}

static PyMethodDef Factor_methods[] = {
    {"solve", (PyCFunction)Factor_solve, METH_VARARGS,
     "solve(b, out=None) -> out\n\n"
     "x with A x = b, for b float64 of shape (n,) or (n, k), C-contiguous; written to out\n"
     "(shaped like b) or to a new b.copy()."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Factor_getset[] = {
    {"n", (getter)Factor_n, NULL, "Size of the matrix.", NULL},
    {"supernodal", (getter)Factor_supernodal, NULL, "True for a supernodal factor.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject FactorType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "featurewarp_cli._cholmod.Factor",
    .tp_basicsize = sizeof(Factor),
    .tp_dealloc = (destructor)Factor_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "A numeric Cholesky factor (from Symbolic.factorize).",
    .tp_methods = Factor_methods,
    .tp_getset = Factor_getset,
};

/* ------------------------------------------------------------------ Symbolic */

typedef struct {
    PyObject_HEAD
    cholmod_common c;
    cholmod_factor *L;          /* symbolic factor (ordering, elimination tree, counts), owned */
    cholmod_sparse *A;          /* the analysed pattern, to check the matrices factored with it */
} Symbolic;

static void
Symbolic_dealloc(Symbolic *self)
{
    CH(free_factor)(&self->L, &self->c);
    CH(free_sparse)(&self->A, &self->c);
    finish(&self->c);
    PyObject_Free(self);
}

/* Same pattern: the same column pointers and row indices (both sorted and summed). */
static int
same_pattern(const cholmod_sparse *a, const cholmod_sparse *b)
{
    size_t nnz = (size_t)((Int *)a->p)[a->ncol];
    return a->ncol == b->ncol && nnz == (size_t)((Int *)b->p)[b->ncol]
           && !memcmp(a->p, b->p, (a->ncol + 1) * sizeof(Int))
           && !memcmp(a->i, b->i, nnz * sizeof(Int));
}

static PyObject *
Symbolic_factorize(Symbolic *self, PyObject *args)
{
    PyObject *rows, *cols, *vals;
    if (!PyArg_ParseTuple(args, "OOO:factorize", &rows, &cols, &vals))
        return NULL;
    Int n = (Int)self->L->n;
    Py_buffer r, cb, v;
    Py_ssize_t m = triplets(n, rows, cols, vals, &r, &cb, &v);
    if (m < 0)
        return NULL;
    Factor *f = PyObject_New(Factor, &FactorType);
    if (!f)
        goto done;
    f->L = NULL;
    start(&f->c);
    f->lock = PyThread_allocate_lock();
    if (!f->lock) {
        PyErr_NoMemory();
        Py_CLEAR(f);
        goto done;
    }
    int ok = 0, pattern = 1;
    Int minor = n;
    cholmod_common *c = &f->c;
    cholmod_triplet t = header(n, m, r.buf, cb.buf, v.buf);
    Py_BEGIN_ALLOW_THREADS
    /* A in compressed-column form: sorted, duplicates summed, lower triangle (stype -1). */
    cholmod_sparse *A = CH(triplet_to_sparse)(&t, 0, c);
    if (A)
        pattern = same_pattern(A, self->A);
    /* A copy of the symbolic factor (only read here, so other threads may copy it too),
     * then the numeric factorization into it: LDL' (simplicial) or LL' (supernodal). */
    if (A && pattern && (f->L = CH(copy_factor)(self->L, c)) != NULL)
        ok = CH(factorize)(A, f->L, c);
    CH(free_sparse)(&A, c);
    if (ok) {
        /* LL' stops at the first pivot that is not positive (L->minor, status NOT_POSDEF);
         * LDL' only at a zero one, so check the signs of D (the first entry of each column). */
        minor = (Int)f->L->minor;
        if (!f->L->is_super && !f->L->is_ll) {
            const Int *lp = f->L->p;
            const double *lx = f->L->x;
            for (Int j = 0; j < minor; j++)
                if (!(lx[lp[j]] > 0)) {
                    minor = j;
                    break;
                }
        }
    }
    Py_END_ALLOW_THREADS
    if (!pattern) {
        PyErr_SetString(PyExc_ValueError, "the matrix does not have the analysed pattern");
        Py_CLEAR(f);
    } else if (!ok) {
        fail(c, "factorize");
        Py_CLEAR(f);
    } else if (minor < n) {
        PyErr_Format(NotPositiveDefinite, "the matrix is not positive definite (pivot %lld of %lld)",
                     (long long)minor, (long long)n);
        Py_CLEAR(f);
    }
done:
    PyBuffer_Release(&r);
    PyBuffer_Release(&cb);
    PyBuffer_Release(&v);
    return (PyObject *)f;
}

/* Copy an int32 array of the symbolic factor (n entries) into a caller's buffer. */
static PyObject *
copy_out(Symbolic *self, PyObject *arg, const Int *src, const char *name)
{
    Py_buffer out;
    if (get(arg, &out, INT, 1, name) < 0)
        return NULL;
    if (out.len != (Py_ssize_t)(self->L->n * sizeof(Int))) {
        PyBuffer_Release(&out);
        return PyErr_Format(PyExc_ValueError, "%s: expected %zd items", name, (Py_ssize_t)self->L->n);
    }
    memcpy(out.buf, src, out.len);
    PyBuffer_Release(&out);
    Py_RETURN_NONE;
}

static PyObject *
Symbolic_column_counts(Symbolic *self, PyObject *arg)
{
    return copy_out(self, arg, self->L->ColCount, "column_counts");
}

static PyObject *
Symbolic_perm(Symbolic *self, PyObject *arg)
{
    return copy_out(self, arg, self->L->Perm, "perm");
}

static PyObject *
Symbolic_n(Symbolic *self, void *closure)
{
    return PyLong_FromLongLong((long long)self->L->n);
}

static PyObject *
Symbolic_supernodal(Symbolic *self, void *closure)
{
    return PyBool_FromLong(self->L->is_super);
}

static PyObject *
Symbolic_lnz(Symbolic *self, void *closure)
{
    return PyFloat_FromDouble(self->c.lnz);
}

static PyObject *
Symbolic_flops(Symbolic *self, void *closure)
{
    return PyFloat_FromDouble(self->c.fl);
}

static PyMethodDef Symbolic_methods[] = {
    {"factorize", (PyCFunction)Symbolic_factorize, METH_VARARGS,
     "factorize(rows, cols, vals) -> Factor\n\n"
     "Cholesky factor of the symmetric matrix whose lower triangle has the triplets (rows,\n"
     "cols int32 with rows >= cols, vals float64; duplicates are summed). Its pattern must\n"
     "be the analysed one (ValueError otherwise). Raises NotPositiveDefinite when a pivot\n"
     "is not positive."},
    {"column_counts", (PyCFunction)Symbolic_column_counts, METH_O,
     "column_counts(out)\n\nnnz of each column of L (int32, n), into out."},
    {"perm", (PyCFunction)Symbolic_perm, METH_O,
     "perm(out)\n\nThe fill-reducing permutation (int32, n), into out."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Symbolic_getset[] = {
    {"n", (getter)Symbolic_n, NULL, "Size of the matrix.", NULL},
    {"supernodal", (getter)Symbolic_supernodal, NULL, "True for a supernodal analysis.", NULL},
    {"lnz", (getter)Symbolic_lnz, NULL, "nnz(L) of the chosen ordering (CHOLMOD's Common->lnz).", NULL},
    {"flops", (getter)Symbolic_flops, NULL, "Flop count of an LL' factorization (Common->fl).", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject SymbolicType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "featurewarp_cli._cholmod.Symbolic",
    .tp_basicsize = sizeof(Symbolic),
    .tp_dealloc = (destructor)Symbolic_dealloc,
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "An ordering and symbolic analysis (from analyze); factorize() any number of times.",
    .tp_methods = Symbolic_methods,
    .tp_getset = Symbolic_getset,
};

static PyObject *
analyze(PyObject *module, PyObject *args, PyObject *kwargs)
{
    static char *keywords[] = {"n", "rows", "cols", "supernodal", "ordering", NULL};
    Py_ssize_t n;
    PyObject *rows, *cols;
    int supernodal = 0, ordering = CHOLMOD_NATURAL;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "nOO|pi:analyze", keywords, &n, &rows, &cols,
                                     &supernodal, &ordering))
        return NULL;
    if (n < 0 || (int64_t)n > INDEX_MAX || ordering < -1 || ordering > CHOLMOD_POSTORDERED)
        return PyErr_Format(PyExc_ValueError, "bad n (%zd) or ordering (%d)", n, ordering);
    Py_buffer r, cb;
    Py_ssize_t m = triplets(n, rows, cols, NULL, &r, &cb, NULL);
    if (m < 0)
        return NULL;
    Symbolic *s = PyObject_New(Symbolic, &SymbolicType);
    if (!s)
        goto done;
    s->L = NULL;
    s->A = NULL;
    cholmod_common *c = &s->c;
    start(c);
    c->supernodal = supernodal ? CHOLMOD_SUPERNODAL : CHOLMOD_SIMPLICIAL;
    if (ordering >= 0) {        /* one given method; -1: CHOLMOD's default strategy (AMD, maybe METIS) */
        c->nmethods = 1;
        c->method[0].ordering = ordering;
    }
    /* The natural ordering keeps the caller's order exactly (no postorder of the
     * elimination tree either), as scikit-sparse's ordering_method="natural" did. */
    c->postorder = ordering != CHOLMOD_NATURAL;
    cholmod_triplet t = header(n, m, r.buf, cb.buf, NULL);
    Py_BEGIN_ALLOW_THREADS
    /* The pattern in compressed-column form (kept to check factorize's matrices), then
     * the ordering, elimination tree, column counts and (supernodal) supernodes of L. */
    s->A = CH(triplet_to_sparse)(&t, 0, c);
    if (s->A)
        s->L = CH(analyze)(s->A, c);
    Py_END_ALLOW_THREADS
    if (!s->L) {
        fail(c, "analyze");
        Py_CLEAR(s);
    }
done:
    PyBuffer_Release(&r);
    PyBuffer_Release(&cb);
    return (PyObject *)s;
}

static PyObject *
leaked(PyObject *module, PyObject *unused)
{
    return PyLong_FromSsize_t(leaked_bytes);
}

/* ------------------------------------------------------------------ module */

static PyMethodDef methods[] = {
    {"analyze", (PyCFunction)(void (*)(void))analyze, METH_VARARGS | METH_KEYWORDS,
     "analyze(n, rows, cols, supernodal=False, ordering=NATURAL) -> Symbolic\n\n"
     "Order and analyse the pattern of an n x n symmetric matrix given by the triplets of\n"
     "its lower triangle (rows, cols int32, rows >= cols; duplicates allowed). ordering:\n"
     "NATURAL, AMD, METIS, NESDIS, or DEFAULT (CHOLMOD's own strategy). supernodal: a\n"
     "supernodal factorization (dense blocks, BLAS) instead of the simplicial LDL'."},
    {"_leaked_bytes", leaked, METH_NOARGS,
     "_leaked_bytes() -> int\n\nBytes CHOLMOD still counted in use when objects were freed (0)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cholmod",
    "Sparse Cholesky factorization with the system CHOLMOD (featurewarp_cli.solver).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__cholmod(void)
{
    if (PyType_Ready(&FactorType) < 0 || PyType_Ready(&SymbolicType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (!m)
        return NULL;
    NotPositiveDefinite = PyErr_NewExceptionWithDoc(
        "featurewarp_cli._cholmod.NotPositiveDefinite",
        "The matrix is not (numerically) positive definite.", PyExc_ArithmeticError, NULL);
    PyObject *version = Py_BuildValue("(iii)", CHOLMOD_MAIN_VERSION, CHOLMOD_SUB_VERSION,
                                      CHOLMOD_SUBSUB_VERSION);
    int bad = !NotPositiveDefinite || !version
              || PyModule_AddObjectRef(m, "NotPositiveDefinite", NotPositiveDefinite) < 0
              || PyModule_AddObjectRef(m, "Symbolic", (PyObject *)&SymbolicType) < 0
              || PyModule_AddObjectRef(m, "Factor", (PyObject *)&FactorType) < 0
              || PyModule_AddObjectRef(m, "VERSION", version) < 0
              || PyModule_AddIntConstant(m, "NATURAL", CHOLMOD_NATURAL) < 0
              || PyModule_AddIntConstant(m, "AMD", CHOLMOD_AMD) < 0
              || PyModule_AddIntConstant(m, "METIS", CHOLMOD_METIS) < 0
              || PyModule_AddIntConstant(m, "NESDIS", CHOLMOD_NESDIS) < 0
              || PyModule_AddIntConstant(m, "DEFAULT", -1) < 0;
    Py_XDECREF(version);
    if (bad) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
