/* featurewarp_cli._raster: the per-triangle and per-pixel loops of render.py in C.
 *
 *   triangles()   which triangles reach the canvas and their rows, in rasterizing order
 *   records()     their scanline bounds and inverse affine maps, for a band's triangles
 *                 (these two are render._Triangles)
 *   rasterize()   the inverse maps of one band of rows (render._rasterize_band)
 *   aa_count(), aa_probes(), aa_resolve()
 *                 the minification filter (render._antialiased) around the cv2.remap
 *                 calls that Python makes: count and place the probes of each pyramid
 *                 level, then take the tent / trilinear sums of their samples.
 *   gather(), scatter()
 *                 the pixels the filter leaves to the plain cv2.remap, where it takes
 *                 most of a band.
 *
 * Every value must equal the numpy code's bit for bit: the same float64 and float32
 * operations in the same order, no fused multiply-add (built with -ffp-contract=off),
 * NaN propagated as np.minimum / np.maximum do, and where two triangles claim a
 * pixel the later one wins, as numpy's fancy assignment leaves it. Arrays come in as
 * C-contiguous buffers (no numpy C API); the loops run without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Fields of a triangle's record (float64), as the attributes of render._Triangles:
 * lower and upper x-bounds k + m y (two each), J, p0 and s0. */
enum { LK0, LM0, LK1, LM1, UK0, UM0, UK1, UM1, J00, J01, J10, J11, PX0, PY0, SX0, SY0, NREC };

static inline double max_nan(double a, double b) { return (a > b || a != a) ? a : b; }
static inline double min_nan(double a, double b) { return (a < b || a != a) ? a : b; }

/* A C-contiguous buffer with a struct format code among `codes`, of items of `itemsize`
 * bytes (any size when 0). */
static int
get(PyObject *obj, Py_buffer *view, const char *codes, Py_ssize_t itemsize, int writable,
    const char *name)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0)
        return -1;
    const char *f = view->format ? view->format : "B";
    if (*f == '<' || *f == '=' || *f == '@')
        f++;
    if ((itemsize && view->itemsize != itemsize) || f[0] == '\0' || f[1] != '\0' || !strchr(codes, f[0])) {
        PyErr_Format(PyExc_TypeError, "%s: expected items of %zd bytes ('%s'), got '%s'",
                     name, itemsize, codes, view->format ? view->format : "B");
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

#define F64 "d", 8
#define F32 "f", 4
#define I64 "lq", 8
#define I32 "i", 4
#define N_OF(view) ((view).len / (view).itemsize)

/* ------------------------------------------------------------------ triangles */

/* Triangle n (node indices; nodes holds target x, y and source x, y of each) on a
 * width x height canvas: 0 when it is dropped (flat, or off the canvas), else 1 with
 * its first and last rows in *lo, *hi and, when r is given, its record in r. */
static int
setup(const double *nodes, const int64_t *n, long long width, long long height,
      int64_t *lo, int64_t *hi, double *r)
{
    static const int edge[3][2] = {{0, 1}, {1, 2}, {2, 0}};
    double x[3], y[3];
    for (int c = 0; c < 3; c++) {
        x[c] = nodes[4 * n[c]];
        y[c] = nodes[4 * n[c] + 1];
    }
    double det = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]);
    double first = max_nan(ceil(min_nan(min_nan(y[0], y[1]), y[2])), 0.0);
    double last = min_nan(floor(max_nan(max_nan(y[0], y[1]), y[2])), (double)(height - 1));
    if (!(fabs(det) > 1e-12 && first <= last && max_nan(max_nan(x[0], x[1]), x[2]) >= 0.0
          && min_nan(min_nan(x[0], x[1]), x[2]) <= (double)(width - 1)))
        return 0;
    *lo = (int64_t)first;
    *hi = (int64_t)last;
    if (!r)
        return 1;

    /* Edge a -> b (a the lower-numbered node): x = ax + m (y - ay), stored as k + m y. */
    double ks[3], ms[3];
    int lower[3], upper[3], positive = det > 0;
    for (int e = 0; e < 3; e++) {
        int a = edge[e][0], b = edge[e][1];
        int swap = n[a] > n[b];
        double ax = swap ? x[b] : x[a], ay = swap ? y[b] : y[a];
        double dx = swap ? x[a] - x[b] : x[b] - x[a];
        double dy = swap ? y[a] - y[b] : y[b] - y[a];
        ms[e] = dy == 0 ? 0.0 : dx / dy;
        ks[e] = ax - ms[e] * ay;
        int rising = y[b] > y[a], falling = y[b] < y[a];
        lower[e] = positive ? falling : rising;
        upper[e] = positive ? rising : falling;
    }
    /* The first and the last edge bounding each side (the same one when only one does). */
    const int *flags[2] = {lower, upper};
    for (int side = 0; side < 2; side++) {
        const int *f = flags[side];
        int i = f[0] ? 0 : f[1] ? 1 : 2, j = f[2] ? 2 : f[1] ? 1 : 0;
        int none = !(f[0] || f[1] || f[2]);
        double inf = side ? INFINITY : -INFINITY;
        r[4 * side + 0] = none ? inf : ks[i];
        r[4 * side + 1] = none ? 0.0 : ms[i];
        r[4 * side + 2] = none ? inf : ks[j];
        r[4 * side + 3] = none ? 0.0 : ms[j];
    }

    /* source = s0 + J (q - p0), J = S E^-1. */
    const double *s0 = nodes + 4 * n[0] + 2, *s1 = nodes + 4 * n[1] + 2, *s2 = nodes + 4 * n[2] + 2;
    double sx0 = s0[0], sy0 = s0[1];
    double d1x = s1[0] - sx0, d1y = s1[1] - sy0;
    double d2x = s2[0] - sx0, d2y = s2[1] - sy0;
    double inv = 1.0 / det;
    double i00 = (y[2] - y[0]) * inv, i01 = -(x[2] - x[0]) * inv;
    double i10 = -(y[1] - y[0]) * inv, i11 = (x[1] - x[0]) * inv;
    r[J00] = d1x * i00 + d2x * i10;
    r[J01] = d1x * i01 + d2x * i11;
    r[J10] = d1y * i00 + d2y * i10;
    r[J11] = d1y * i01 + d2y * i11;
    r[PX0] = x[0];
    r[PY0] = y[0];
    r[SX0] = sx0;
    r[SY0] = sy0;
    return 1;
}

/* The kept triangles (index into triangles), in their order or (sort) in the order of
 * a stable sort by first row: the order in which render.py rasterizes its bands, whose
 * triangles are then contiguous. */
static PyObject *
triangles(PyObject *self, PyObject *args)
{
    PyObject *o_nodes, *o_tri, *o_index, *o_ylo, *o_yhi;
    long long width, height;
    int sort;
    if (!PyArg_ParseTuple(args, "OOLLpOOO:triangles", &o_nodes, &o_tri, &width, &height, &sort,
                          &o_index, &o_ylo, &o_yhi))
        return NULL;
    Py_buffer nb = {0}, tri = {0}, ind = {0}, ylo = {0}, yhi = {0};
    PyObject *result = NULL;
    int64_t *row = NULL, *start = NULL;
    if (get(o_nodes, &nb, F64, 0, "nodes") || get(o_tri, &tri, I64, 0, "triangles")
        || get(o_index, &ind, I64, 1, "index") || get(o_ylo, &ylo, I64, 1, "ylo")
        || get(o_yhi, &yhi, I64, 1, "yhi"))
        goto done;
    Py_ssize_t nodes = N_OF(nb) / 4, m = N_OF(tri) / 3;
    if (N_OF(ind) < m || N_OF(ylo) < m || N_OF(yhi) < m || width < 1 || height < 1
        || !(row = malloc((2 * m + 1) * sizeof(int64_t)))
        || !(start = calloc(height + 1, sizeof(int64_t)))) {
        PyErr_SetString(PyExc_ValueError, "triangles: buffer sizes do not match");
        goto done;
    }
    const double *p = nb.buf;
    const int64_t *t = tri.buf;
    int64_t *index = ind.buf, *lo_out = ylo.buf, *hi_out = yhi.buf, *last = row + m;
    Py_ssize_t count = 0, bad = 0;

    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < m && !bad; i++) {        /* rows, and a counting sort */
        const int64_t *n = t + 3 * i;
        bad = n[0] < 0 || n[0] >= nodes || n[1] < 0 || n[1] >= nodes || n[2] < 0 || n[2] >= nodes;
        if (bad || !setup(p, n, width, height, &row[i], &last[i], NULL))
            row[i] = -1;
        else
            start[row[i] + 1]++, count++;
    }
    for (long long y = 0; y < height && !bad; y++)
        start[y + 1] += start[y];
    for (Py_ssize_t i = 0, kept = 0; i < m && !bad; i++) {
        if (row[i] < 0)
            continue;
        int64_t at = sort ? start[row[i]]++ : kept++;
        index[at] = i;
        lo_out[at] = row[i];
        hi_out[at] = last[i];
    }
    Py_END_ALLOW_THREADS

    if (bad)
        PyErr_SetString(PyExc_IndexError, "triangles: node index out of range");
    else
        result = PyLong_FromSsize_t(count);
done:
    free(row);
    free(start);
    PyBuffer_Release(&nb);
    PyBuffer_Release(&tri);
    PyBuffer_Release(&ind);
    PyBuffer_Release(&ylo);
    PyBuffer_Release(&yhi);
    return result;
}

/* The mesh as the functions below take it: nodes (target x, y, source x, y of each),
 * triangles, the kept triangles' indices from triangles() and the canvas. */
typedef struct {
    Py_buffer nodes, tri, ind;
    long long width, height;
} Mesh;

/* Get the mesh's buffers; check what setup() will read for kept triangles sel. */
static int
get_mesh(PyObject *o_nodes, PyObject *o_tri, PyObject *o_ind, const int64_t *sel, Py_ssize_t n,
         Mesh *mesh)
{
    if (get(o_nodes, &mesh->nodes, F64, 0, "nodes") || get(o_tri, &mesh->tri, I64, 0, "triangles")
        || get(o_ind, &mesh->ind, I64, 0, "index"))
        return -1;
    Py_ssize_t nodes = N_OF(mesh->nodes) / 4, m = N_OF(mesh->tri) / 3, kept = N_OF(mesh->ind);
    const int64_t *t = mesh->tri.buf, *index = mesh->ind.buf;
    if (mesh->width < 1 || mesh->height < 1) {
        PyErr_SetString(PyExc_ValueError, "empty canvas");
        return -1;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        int ok = sel[i] >= 0 && sel[i] < kept && index[sel[i]] >= 0 && index[sel[i]] < m;
        for (int c = 0; ok && c < 3; c++)
            ok = t[3 * index[sel[i]] + c] >= 0 && t[3 * index[sel[i]] + c] < nodes;
        if (!ok) {
            PyErr_SetString(PyExc_IndexError, "triangle or node index out of range");
            return -1;
        }
    }
    return 0;
}

static void
release_mesh(Mesh *mesh)
{
    PyBuffer_Release(&mesh->nodes);
    PyBuffer_Release(&mesh->tri);
    PyBuffer_Release(&mesh->ind);
}

/* The records of kept triangles sel (their J feeds the footprints too). */
static PyObject *
records(PyObject *self, PyObject *args)
{
    PyObject *o_nodes, *o_tri, *o_ind, *o_sel, *o_rec;
    Mesh mesh = {0};
    if (!PyArg_ParseTuple(args, "OOOLLOO:records", &o_nodes, &o_tri, &o_ind, &mesh.width,
                          &mesh.height, &o_sel, &o_rec))
        return NULL;
    Py_buffer sel = {0}, rec = {0};
    PyObject *result = NULL;
    if (get(o_sel, &sel, I64, 0, "sel") || get(o_rec, &rec, F64, 1, "rec")
        || get_mesh(o_nodes, o_tri, o_ind, sel.buf, N_OF(sel), &mesh))
        goto done;
    Py_ssize_t n = N_OF(sel);
    if (N_OF(rec) < NREC * n) {
        PyErr_SetString(PyExc_ValueError, "records: buffer too small");
        goto done;
    }
    const int64_t *t = mesh.tri.buf, *index = mesh.ind.buf, *s = sel.buf;
    double *r = rec.buf;
    int64_t lo, hi;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++, r += NREC)
        if (!setup(mesh.nodes.buf, t + 3 * index[s[i]], mesh.width, mesh.height, &lo, &hi, r))
            for (int k = 0; k < NREC; k++)    /* not kept on this canvas: no pixel */
                r[k] = NAN;
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    release_mesh(&mesh);
    PyBuffer_Release(&sel);
    PyBuffer_Release(&rec);
    return result;
}

/* ------------------------------------------------------------------ rasterize */

static PyObject *
rasterize(PyObject *self, PyObject *args)
{
    PyObject *o_rec, *o_ylo, *o_yhi, *o_mx, *o_my, *o_ids, *o_aa;
    long long y0, y1, width;
    if (!PyArg_ParseTuple(args, "OOOLLLOOOO:rasterize", &o_rec, &o_ylo, &o_yhi, &y0, &y1, &width,
                          &o_mx, &o_my, &o_ids, &o_aa))
        return NULL;
    Py_buffer rec = {0}, ylo = {0}, yhi = {0}, mx = {0}, my = {0}, idb = {0}, aa = {0};
    PyObject *result = NULL;
    int with_aa = o_ids != Py_None;
    if (get(o_rec, &rec, F64, 0, "rec") || get(o_ylo, &ylo, I64, 0, "ylo")
        || get(o_yhi, &yhi, I64, 0, "yhi") || get(o_mx, &mx, F32, 1, "mapx")
        || get(o_my, &my, F32, 1, "mapy")
        || (with_aa && (get(o_ids, &idb, I32, 0, "ids") || get(o_aa, &aa, I32, 1, "aatri"))))
        goto done;
    Py_ssize_t count = N_OF(ylo), size = (Py_ssize_t)((y1 - y0) * width);
    if (y1 < y0 || width < 1 || N_OF(rec) < NREC * count || N_OF(yhi) < count
        || N_OF(mx) < size || N_OF(my) < size
        || (with_aa && (N_OF(idb) < count || N_OF(aa) < size))) {
        PyErr_SetString(PyExc_ValueError, "rasterize: buffer sizes do not match");
        goto done;
    }
    const double *records = rec.buf;
    const int64_t *lo_of = ylo.buf, *hi_of = yhi.buf;
    const int32_t *restrict ids = with_aa ? idb.buf : NULL;
    float *restrict mapx = mx.buf, *restrict mapy = my.buf;
    int32_t *restrict aatri = with_aa ? aa.buf : NULL;
    Py_ssize_t marked = 0;

    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t t = 0; t < count; t++) {
        const double *r = records + NREC * t;
        int64_t lo = lo_of[t] > y0 ? lo_of[t] : y0, hi = hi_of[t] < y1 - 1 ? hi_of[t] : y1 - 1;
        int32_t id = with_aa ? ids[t] : -1;
        for (int64_t y = lo; y <= hi; y++) {
            double yd = (double)y;
            double xl = max_nan(r[LM0] * yd + r[LK0], r[LM1] * yd + r[LK1]);
            double xr = min_nan(r[UM0] * yd + r[UK0], r[UM1] * yd + r[UK1]);
            xl = max_nan(ceil(xl), 0.0);
            xr = min_nan(floor(xr), (double)(width - 1));
            if (!(xl <= xr))
                continue;
            int64_t a = (int64_t)xl, n = (int64_t)xr - a + 1;
            double qx = (double)a - r[PX0], qy = yd - r[PY0];
            float start_x = (float)(r[SX0] + r[J00] * qx + r[J01] * qy);
            float start_y = (float)(r[SY0] + r[J10] * qx + r[J11] * qy);
            float step_x = (float)r[J00], step_y = (float)r[J10];
            float *restrict ox = mapx + (y - y0) * width + a, *restrict oy = mapy + (y - y0) * width + a;
            for (int64_t j = 0; j < n; j++) {
                ox[j] = start_x + step_x * (float)j;
                oy[j] = start_y + step_y * (float)j;
            }
            if (id >= 0) {
                int32_t *o = aatri + (y - y0) * width + a;
                for (int64_t j = 0; j < n; j++)
                    o[j] = id;
                marked += n;
            }
        }
    }
    Py_END_ALLOW_THREADS

    result = PyLong_FromSsize_t(marked);
done:
    PyBuffer_Release(&rec);
    PyBuffer_Release(&ylo);
    PyBuffer_Release(&yhi);
    PyBuffer_Release(&mx);
    PyBuffer_Release(&my);
    PyBuffer_Release(&idb);
    PyBuffer_Release(&aa);
    return result;
}

/* ------------------------------------------------------------------ antialiasing
 *
 * Per triangle: ints (k, base, blend) and floats (step x, step y, frac), as in
 * render._Minification. A pixel with aatri >= 0 takes 2k - 1 probes (j = -(k-1) .. k-1)
 * at source + j * step on pyramid level base and, when blend, base + 1. The probes of
 * level L are stored from offsets[L] on, pixel after pixel, in the order of the band.
 */

/* The triangle of AA pixel p, its k, base and blend; 0 when out of range. */
static inline int
aa_pixel(int32_t t, Py_ssize_t tris, const int32_t *ints, Py_ssize_t levels, int *k, int *base,
         int *blend)
{
    if (t >= tris)
        return 0;
    *k = ints[3 * (Py_ssize_t)t];
    *base = ints[3 * (Py_ssize_t)t + 1];
    *blend = ints[3 * (Py_ssize_t)t + 2] != 0;
    return *k >= 1 && *base >= 0 && *base + *blend < levels;
}

static PyObject *
aa_count(PyObject *self, PyObject *args)
{
    PyObject *o_aa, *o_int, *o_counts;
    if (!PyArg_ParseTuple(args, "OOO:aa_count", &o_aa, &o_int, &o_counts))
        return NULL;
    Py_buffer aa = {0}, in = {0}, cn = {0};
    PyObject *result = NULL;
    if (get(o_aa, &aa, I32, 0, "aatri") || get(o_int, &in, I32, 0, "ints")
        || get(o_counts, &cn, I64, 1, "counts"))
        goto done;
    const int32_t *aatri = aa.buf, *ints = in.buf;
    int64_t *counts = cn.buf;
    Py_ssize_t n = N_OF(aa), tris = N_OF(in) / 3, levels = N_OF(cn);
    int ok = 1, k, base, blend;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t p = 0; p < n; p++) {
        if (aatri[p] < 0)
            continue;
        if (!(ok = aa_pixel(aatri[p], tris, ints, levels, &k, &base, &blend)))
            break;
        counts[base] += 2 * k - 1;
        if (blend)
            counts[base + 1] += 2 * k - 1;
    }
    Py_END_ALLOW_THREADS
    if (!ok)
        PyErr_SetString(PyExc_ValueError, "aa_count: triangle or level out of range");
    else
        result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&aa);
    PyBuffer_Release(&in);
    PyBuffer_Release(&cn);
    return result;
}

/* cursor[l] = offsets[l]; 0 unless 0 <= offsets[0] <= ... <= offsets[levels] <= total. */
static int
aa_cursors(const int64_t *offsets, Py_ssize_t levels, Py_ssize_t total, int64_t *cursor)
{
    for (Py_ssize_t l = 0; l < levels; l++) {
        if (offsets[l] < 0 || offsets[l] > offsets[l + 1])
            return 0;
        cursor[l] = offsets[l];
    }
    return offsets[levels] <= total;
}

static PyObject *
aa_probes(PyObject *self, PyObject *args)
{
    PyObject *o_aa, *o_mx, *o_my, *o_int, *o_flt, *o_off, *o_px, *o_py;
    if (!PyArg_ParseTuple(args, "OOOOOOOO:aa_probes", &o_aa, &o_mx, &o_my, &o_int, &o_flt, &o_off,
                          &o_px, &o_py))
        return NULL;
    Py_buffer aa = {0}, mx = {0}, my = {0}, in = {0}, fl = {0}, off = {0}, px = {0}, py = {0};
    PyObject *result = NULL;
    int64_t *cursor = NULL;
    float *scale = NULL;
    if (get(o_aa, &aa, I32, 0, "aatri") || get(o_mx, &mx, F32, 0, "mapx")
        || get(o_my, &my, F32, 0, "mapy") || get(o_int, &in, I32, 0, "ints")
        || get(o_flt, &fl, F32, 0, "floats") || get(o_off, &off, I64, 0, "offsets")
        || get(o_px, &px, F32, 1, "px") || get(o_py, &py, F32, 1, "py"))
        goto done;
    Py_ssize_t n = N_OF(aa), tris = N_OF(in) / 3, levels = N_OF(off) - 1;
    if (N_OF(mx) < n || N_OF(my) < n || N_OF(fl) < 3 * tris || levels < 1 || N_OF(py) != N_OF(px)
        || !(cursor = malloc(levels * sizeof(int64_t))) || !(scale = malloc(levels * sizeof(float)))
        || !aa_cursors(off.buf, levels, N_OF(px), cursor)) {
        PyErr_SetString(PyExc_ValueError, "aa_probes: buffer sizes or offsets do not match");
        goto done;
    }
    for (Py_ssize_t l = 0; l < levels; l++)
        scale[l] = (float)ldexp(1.0, (int)-l);     /* np.float32(0.5 ** l): level l pixel i sits on 2^l i */
    const int32_t *aatri = aa.buf, *ints = in.buf;
    const int64_t *offsets = off.buf;
    const float *mapx = mx.buf, *mapy = my.buf, *floats = fl.buf;
    float *ox = px.buf, *oy = py.buf;
    int ok = 1, k, base, blend;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t p = 0; p < n; p++) {
        int32_t t = aatri[p];
        if (t < 0)
            continue;
        if (!(ok = aa_pixel(t, tris, ints, levels, &k, &base, &blend)))
            break;
        float sx = mapx[p], sy = mapy[p], step_x = floats[3 * t], step_y = floats[3 * t + 1];
        for (int l = base; ok && l <= base + blend; l++) {
            int64_t c = cursor[l];
            if (!(ok = c + 2 * k - 1 <= offsets[l + 1]))
                break;
            for (int j = -(k - 1); j <= k - 1; j++, c++) {
                ox[c] = (sx + (float)j * step_x) * scale[l];
                oy[c] = (sy + (float)j * step_y) * scale[l];
            }
            cursor[l] = c;
        }
        if (!ok)
            break;
    }
    Py_END_ALLOW_THREADS
    if (!ok)
        PyErr_SetString(PyExc_ValueError, "aa_probes: triangle, level or offsets out of range");
    else
        result = Py_NewRef(Py_None);
done:
    free(cursor);
    free(scale);
    PyBuffer_Release(&aa);
    PyBuffer_Release(&mx);
    PyBuffer_Release(&my);
    PyBuffer_Release(&in);
    PyBuffer_Release(&fl);
    PyBuffer_Release(&off);
    PyBuffer_Release(&px);
    PyBuffer_Release(&py);
    return result;
}

/* np.rint on float32 (round half to even) without a libm call in the common case. */
static inline float
round_even(float x)
{
    return x >= 0.0f && x < 8388608.0f ? (x + 8388608.0f) - 8388608.0f : rintf(x);
}

/* value = sum over levels of [w_level *] (sum over j of weight_j * sample_j), as
 * render._antialiased takes it; rounded, clipped to [0, top] and written to the pixel
 * (to channels 0..2 when an alpha channel was added). */
#if defined(__GNUC__)
#define ALWAYS_INLINE static inline __attribute__((always_inline))
#else
#define ALWAYS_INLINE static inline
#endif
#define DEFINE_RESOLVE(NAME, T)                                                                 \
    ALWAYS_INLINE int NAME(const int32_t *restrict aatri, Py_ssize_t n, Py_ssize_t tris,        \
                           const int32_t *restrict ints, const float *restrict floats,          \
                           const float *restrict weights, int kmax,                             \
                           const int64_t *restrict offsets, Py_ssize_t levels,                  \
                           int64_t *restrict cursor, const T *restrict samples, T *restrict out, \
                           const int channels, const int out_channels)                          \
    {                                                                                           \
        const float top = sizeof(T) == 1 ? 255.0f : 65535.0f;                                   \
        int k, base, blend;                                                                     \
        for (Py_ssize_t p = 0; p < n; p++) {                                                    \
            int32_t t = aatri[p];                                                               \
            if (t < 0)                                                                          \
                continue;                                                                       \
            if (!aa_pixel(t, tris, ints, levels, &k, &base, &blend) || k > kmax)                \
                return 0;                                                                       \
            int probes = 2 * k - 1;                                                             \
            int64_t c0 = cursor[base], c1 = blend ? cursor[base + 1] : 0;                       \
            if (c0 + probes > offsets[base + 1] || (blend && c1 + probes > offsets[base + 2]))  \
                return 0;                                                                       \
            cursor[base] = c0 + probes;                                                         \
            if (blend)                                                                          \
                cursor[base + 1] = c1 + probes;                                                 \
            const float *w = weights + (Py_ssize_t)k * (2 * kmax - 1);                          \
            float frac = floats[3 * t + 2], keep = 1.0f - frac;                                 \
            const T *v0 = samples + c0 * channels, *v1 = samples + c1 * channels;              \
            T *o = out + p * out_channels;                                                      \
            for (int c = 0; c < channels; c++) {                                                \
                float sum = (float)v0[c] * w[0];                                                \
                for (int j = 1; j < probes; j++)                                                \
                    sum += (float)v0[j * channels + c] * w[j];                                  \
                float acc = 0.0f;                                                               \
                if (blend) {                                                                    \
                    float sum1 = (float)v1[c] * w[0];                                           \
                    for (int j = 1; j < probes; j++)                                            \
                        sum1 += (float)v1[j * channels + c] * w[j];                             \
                    acc += sum * keep;                                                          \
                    acc += sum1 * frac;                                                         \
                } else {                                                                        \
                    acc += sum;                                                                 \
                }                                                                               \
                float r = round_even(acc);                                                      \
                r = r < 0.0f ? 0.0f : r > top ? top : r;                                        \
                if (out_channels == channels)                                                   \
                    o[c] = (T)r;                                                                \
                else if (channels == 1)                                                         \
                    o[0] = o[1] = o[2] = (T)r;                                                  \
                else                                                                            \
                    o[c] = (T)r;                                                                \
            }                                                                                   \
        }                                                                                       \
        return 1;                                                                               \
    }

DEFINE_RESOLVE(resolve8, uint8_t)
DEFINE_RESOLVE(resolve16, uint16_t)

/* resolve8 / resolve16 with the channel counts as constants (unrolled, in registers). */
#define RESOLVE_ARGS                                                                            \
    const int32_t *aatri, Py_ssize_t n, Py_ssize_t tris, const int32_t *ints,                   \
        const float *floats, const float *weights, int kmax, const int64_t *offsets,            \
        Py_ssize_t levels, int64_t *cursor
#define RESOLVE_PASS aatri, n, tris, ints, floats, weights, kmax, offsets, levels, cursor

static int
resolve(RESOLVE_ARGS, const void *samples, void *out, int depth, int channels, int out_channels)
{
#define CASE(C, OC)                                                                             \
    if (channels == C && out_channels == OC)                                                    \
        return depth == 1 ? resolve8(RESOLVE_PASS, samples, out, C, OC)                         \
                          : resolve16(RESOLVE_PASS, samples, out, C, OC);
    CASE(1, 1) CASE(1, 4) CASE(2, 2) CASE(3, 3) CASE(3, 4) CASE(4, 4)
#undef CASE
    return depth == 1 ? resolve8(RESOLVE_PASS, samples, out, channels, out_channels)
                      : resolve16(RESOLVE_PASS, samples, out, channels, out_channels);
}

static PyObject *
aa_resolve(PyObject *self, PyObject *args)
{
    PyObject *o_aa, *o_int, *o_flt, *o_w, *o_off, *o_smp, *o_out;
    int kmax, channels, out_channels;
    if (!PyArg_ParseTuple(args, "OOOOiOOiOi:aa_resolve", &o_aa, &o_int, &o_flt, &o_w, &kmax, &o_off,
                          &o_smp, &channels, &o_out, &out_channels))
        return NULL;
    Py_buffer aa = {0}, in = {0}, fl = {0}, wb = {0}, off = {0}, smp = {0}, ob = {0};
    PyObject *result = NULL;
    int64_t *cursor = NULL;
    if (get(o_aa, &aa, I32, 0, "aatri") || get(o_int, &in, I32, 0, "ints")
        || get(o_flt, &fl, F32, 0, "floats") || get(o_w, &wb, F32, 0, "weights")
        || get(o_off, &off, I64, 0, "offsets") || get(o_smp, &smp, "BH", 0, 0, "samples")
        || get(o_out, &ob, "BH", 0, 1, "out"))
        goto done;
    Py_ssize_t n = N_OF(aa), tris = N_OF(in) / 3, levels = N_OF(off) - 1;
    if (N_OF(fl) < 3 * tris || levels < 1 || kmax < 1 || N_OF(wb) < (kmax + 1) * (2 * kmax - 1)
        || smp.itemsize != ob.itemsize || channels < 1
        || !(out_channels == channels || (out_channels == 4 && (channels == 1 || channels == 3)))
        || N_OF(ob) < n * out_channels || N_OF(smp) % channels
        || !(cursor = malloc(levels * sizeof(int64_t)))
        || !aa_cursors(off.buf, levels, N_OF(smp) / channels, cursor)) {
        PyErr_SetString(PyExc_ValueError, "aa_resolve: buffer sizes or offsets do not match");
        goto done;
    }
    const int32_t *aatri = aa.buf, *ints = in.buf;
    const float *floats = fl.buf, *weights = wb.buf;
    const int64_t *offsets = off.buf;
    int ok;
    Py_BEGIN_ALLOW_THREADS
    ok = resolve(aatri, n, tris, ints, floats, weights, kmax, offsets, levels, cursor, smp.buf, ob.buf,
                 (int)smp.itemsize, channels, out_channels);
    Py_END_ALLOW_THREADS
    if (!ok)
        PyErr_SetString(PyExc_ValueError, "aa_resolve: triangle, level, steps or offsets out of range");
    else
        result = Py_NewRef(Py_None);
done:
    free(cursor);
    PyBuffer_Release(&aa);
    PyBuffer_Release(&in);
    PyBuffer_Release(&fl);
    PyBuffer_Release(&wb);
    PyBuffer_Release(&off);
    PyBuffer_Release(&smp);
    PyBuffer_Release(&ob);
    return result;
}

/* ------------------------------------------------------------------ plain pixels
 *
 * Where the filter overwrites most of a band, Python resamples only the other pixels
 * (aatri < 0): gather() lists their map positions, scatter() puts the samples back. */

static PyObject *
gather(PyObject *self, PyObject *args)
{
    PyObject *o_aa, *o_mx, *o_my, *o_px, *o_py;
    if (!PyArg_ParseTuple(args, "OOOOO:gather", &o_aa, &o_mx, &o_my, &o_px, &o_py))
        return NULL;
    Py_buffer aa = {0}, mx = {0}, my = {0}, px = {0}, py = {0};
    PyObject *result = NULL;
    if (get(o_aa, &aa, I32, 0, "aatri") || get(o_mx, &mx, F32, 0, "mapx")
        || get(o_my, &my, F32, 0, "mapy") || get(o_px, &px, F32, 1, "px")
        || get(o_py, &py, F32, 1, "py"))
        goto done;
    Py_ssize_t n = N_OF(aa), count = 0;
    if (N_OF(mx) < n || N_OF(my) < n || N_OF(px) < n || N_OF(py) < n) {
        PyErr_SetString(PyExc_ValueError, "gather: buffer sizes do not match");
        goto done;
    }
    const int32_t *aatri = aa.buf;
    const float *mapx = mx.buf, *mapy = my.buf;
    float *ox = px.buf, *oy = py.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t p = 0; p < n; p++)
        if (aatri[p] < 0) {
            ox[count] = mapx[p];
            oy[count++] = mapy[p];
        }
    Py_END_ALLOW_THREADS
    result = PyLong_FromSsize_t(count);
done:
    PyBuffer_Release(&aa);
    PyBuffer_Release(&mx);
    PyBuffer_Release(&my);
    PyBuffer_Release(&px);
    PyBuffer_Release(&py);
    return result;
}

static PyObject *
scatter(PyObject *self, PyObject *args)
{
    PyObject *o_aa, *o_val, *o_out;
    Py_ssize_t channels, out_channels;
    if (!PyArg_ParseTuple(args, "OOnOn:scatter", &o_aa, &o_val, &channels, &o_out, &out_channels))
        return NULL;
    Py_buffer aa = {0}, val = {0}, ob = {0};
    PyObject *result = NULL;
    if (get(o_aa, &aa, I32, 0, "aatri") || get(o_val, &val, "BH", 0, 0, "values")
        || get(o_out, &ob, "BH", 0, 1, "out"))
        goto done;
    Py_ssize_t n = N_OF(aa), size = val.itemsize, count = 0;
    const int32_t *aatri = aa.buf;
    for (Py_ssize_t p = 0; p < n; p++)
        count += aatri[p] < 0;
    if (ob.itemsize != size || channels < 1
        || !(out_channels == channels || (out_channels == 4 && (channels == 1 || channels == 3)))
        || N_OF(val) < count * channels || N_OF(ob) < n * out_channels) {
        PyErr_SetString(PyExc_ValueError, "scatter: buffer sizes do not match");
        goto done;
    }
    const char *in = val.buf;
    char *out = ob.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t p = 0; p < n; p++) {
        if (aatri[p] >= 0)
            continue;
        char *o = out + p * out_channels * size;
        if (out_channels == channels || channels == 3)
            memcpy(o, in, channels * size);
        else                                          /* gray into B, G and R */
            for (int c = 0; c < 3; c++)
                memcpy(o + c * size, in, size);
        in += channels * size;
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&aa);
    PyBuffer_Release(&val);
    PyBuffer_Release(&ob);
    return result;
}

/* ------------------------------------------------------------------ module */

static PyMethodDef methods[] = {
    {"triangles", triangles, METH_VARARGS,
     "triangles(nodes, triangles, width, height, sort, index, ylo, yhi) -> count\n\n"
     "The triangles that reach the canvas (their indices) and their row ranges, in their\n"
     "order or, if sort, stably sorted by first row."},
    {"records", records, METH_VARARGS,
     "records(nodes, triangles, index, width, height, sel, rec)\n\n"
     "The records (16 float64: x-bounds, J, p0, s0) of kept triangles sel."},
    {"rasterize", rasterize, METH_VARARGS,
     "rasterize(rec, ylo, yhi, y0, y1, width, mapx, mapy, ids, aatri) -> int\n\n"
     "Fill the band's maps from the triangles of rec, in order; set aatri to ids[t] where\n"
     "that is >= 0 (minifying triangles); return how many pixels that marked."},
    {"aa_count", aa_count, METH_VARARGS,
     "aa_count(aatri, ints, counts)\n\nAdd the probes of each pyramid level to counts."},
    {"aa_probes", aa_probes, METH_VARARGS,
     "aa_probes(aatri, mapx, mapy, ints, floats, offsets, px, py)\n\n"
     "Probe positions on each level's pixel grid, from offsets[level] on."},
    {"aa_resolve", aa_resolve, METH_VARARGS,
     "aa_resolve(aatri, ints, floats, weights, kmax, offsets, samples, channels, out, out_channels)\n\n"
     "Weighted sums of the probes' samples into the band's pixels."},
    {"gather", gather, METH_VARARGS,
     "gather(aatri, mapx, mapy, px, py) -> count\n\n"
     "The map positions of the pixels with aatri < 0, packed at the start of px, py."},
    {"scatter", scatter, METH_VARARGS,
     "scatter(aatri, values, channels, out, out_channels)\n\n"
     "values (one row per pixel with aatri < 0, in order) into out's rows of those pixels\n"
     "(channels 0..2 when out has an added alpha channel)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_raster",
    "Compiled loops of featurewarp_cli.render (bit-identical to its numpy code).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__raster(void)
{
    return PyModule_Create(&module);
}
