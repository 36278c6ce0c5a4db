/* featurewarp_cli.render._raster: the per-triangle and per-pixel loops of the renderer.
 *
 *   triangles()   which triangles reach the canvas and their rows, in rasterizing order
 *   records()     their scanline bounds and inverse affine maps, for a band's triangles
 *                 (these two are raster.Triangles)
 *   rasterize()   the inverse maps of one band of rows
 *   footprints()  the footprints of a band's minifying triangles (antialias.Footprints)
 *   aa_count(), aa_probes(), aa_resolve()
 *                 the minification filter (antialias.filter_band) around the cv2.remap
 *                 calls that Python makes: count and place the probes of each pyramid
 *                 level, then take the tent / trilinear sums of their samples.
 *   gather(), scatter()
 *                 the pixels the filter leaves to the plain cv2.remap, where it takes
 *                 most of a band.
 *
 * The two triangles sharing an edge compute its bounds with the same operations on the
 * same numbers, so every pixel centre is claimed by at least one of them (no cracks).
 * Where two triangles claim a pixel the later one (in rasterizing order) wins. A NaN
 * coordinate drops its triangle or its spans. The tests compare these loops, with a
 * tolerance, against a plain barycentric rasterizer and numpy's SVD (tests/reference_render.py).
 * Arrays come in as C-contiguous buffers (no numpy C API); the loops run without the GIL.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "_buffer.h"
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

/* floor() and ceil() on every span and triangle are a dozen instructions each on plain
 * x86-64 and one (roundsd) with SSE4.1: the loops that use them are built twice and
 * the CPU picks one when the module loads (glibc's ifunc). Same results either way. */
#if defined(__x86_64__) && defined(__GLIBC__) && defined(__has_attribute)
#if __has_attribute(target_clones)
#define ROUNDING_CLONES __attribute__((target_clones("sse4.1", "default")))
#endif
#endif
#ifndef ROUNDING_CLONES
#define ROUNDING_CLONES
#endif
/* Inlined into the clones above (and into the loops specialised by constants below). */
#if defined(__GNUC__)
#define ALWAYS_INLINE static inline __attribute__((always_inline))
#else
#define ALWAYS_INLINE static inline
#endif

/* Fields of a triangle's record (float64), raster.Triangles.FIELDS:
 * lower and upper x-bounds k + m y (two each), J, p0 and s0. */
enum { LK0, LM0, LK1, LM1, UK0, UM0, UK1, UM1, J00, J01, J10, J11, PX0, PY0, SX0, SY0, NREC };

/* max and min that give NaN when either value is NaN (fmax and fmin do not): a NaN
 * coordinate then yields no row or span. */
static inline double max_nan(double a, double b) { return (a > b || a != a) ? a : b; }
static inline double min_nan(double a, double b) { return (a < b || a != a) ? a : b; }

#define F64 "d", 8
#define F32 "f", 4
#define I64 "lq", 8
#define I32 "i", 4
#define N_OF(view) ((view).len / (view).itemsize)

/* ------------------------------------------------------------------ triangles */

/* Triangle n (node indices; target and source hold the nodes' x, y) on a width x height
 * canvas: 0 when it is dropped (flat, or off the canvas), else 1 with its first and last
 * rows in *lo, *hi and, when r is given, its record in r. */
ALWAYS_INLINE int
setup(const double *target, const double *source, const int64_t n[3], long long width,
      long long height, int64_t *lo, int64_t *hi, double *r)
{
    static const int edge[3][2] = {{0, 1}, {1, 2}, {2, 0}};
    double x[3], y[3];
    for (int c = 0; c < 3; c++) {
        x[c] = target[2 * n[c]];
        y[c] = target[2 * n[c] + 1];
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
    const double *s0 = source + 2 * n[0], *s1 = source + 2 * n[1], *s2 = source + 2 * n[2];
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

/* A (rows, 3) int64 buffer of any strides: the triangles, as the mesh holds them (often a
 * transposed view; copying 1.5 M triangles to C order costs more than reading them). */
typedef struct {
    Py_buffer view;
    Py_ssize_t rows, s0, s1;
} Triples;

static int
get_triples(PyObject *obj, Triples *t, const char *name)
{
    if (PyObject_GetBuffer(obj, &t->view, PyBUF_RECORDS_RO) < 0)
        return -1;
    const char *f = t->view.format ? t->view.format : "B";
    if (*f == '<' || *f == '=' || *f == '@')
        f++;
    if (t->view.ndim != 2 || t->view.shape[1] != 3 || t->view.itemsize != 8 || f[0] == '\0' || f[1] != '\0'
        || !strchr("lq", f[0])) {
        PyErr_Format(PyExc_TypeError, "%s: expected an (n, 3) int64 array", name);
        PyBuffer_Release(&t->view);
        return -1;
    }
    t->rows = t->view.shape[0];
    t->s0 = t->view.strides[0];
    t->s1 = t->view.strides[1];
    return 0;
}

static inline int64_t
triple(const Triples *t, Py_ssize_t i, int c)
{
    return *(const int64_t *)((const char *)t->view.buf + i * t->s0 + c * t->s1);
}

/* setup() of triangles 0 .. m-1 for triangles(): rows (row[i] = -1 when dropped, last
 * row in last[i]) and a count of kept triangles per first row in start[row + 1].
 * Returns the number kept, or -1 when a node index is out of range. */
static ROUNDING_CLONES Py_ssize_t
triangle_rows(const double *target, Py_ssize_t nodes, const Triples *t, long long width,
              long long height, int32_t *row, int32_t *last, int64_t *start)
{
    Py_ssize_t count = 0;
    int64_t lo, hi;
    for (Py_ssize_t i = 0; i < t->rows; i++) {
        int64_t n[3] = {triple(t, i, 0), triple(t, i, 1), triple(t, i, 2)};
        if (n[0] < 0 || n[0] >= nodes || n[1] < 0 || n[1] >= nodes || n[2] < 0 || n[2] >= nodes)
            return -1;
        if (!setup(target, NULL, n, width, height, &lo, &hi, NULL))
            row[i] = -1;
        else {
            row[i] = (int32_t)lo;
            last[i] = (int32_t)hi;
            start[lo + 1]++, count++;
        }
    }
    return count;
}

/* The kept triangles (index into triangles) in the order of a stable sort by first row:
 * the order in which they are rasterized (the later one wins a pixel that two claim), in
 * which each band's triangles are contiguous. Their nodes are copied to corners in that order, so
 * that records() reads them in sequence rather than all over the triangle array. */
static PyObject *
triangles(PyObject *self, PyObject *args)
{
    PyObject *o_target, *o_tri, *o_index, *o_ylo, *o_yhi, *o_corners;
    long long width, height;
    if (!PyArg_ParseTuple(args, "OOLLOOOO:triangles", &o_target, &o_tri, &width, &height,
                          &o_index, &o_ylo, &o_yhi, &o_corners))
        return NULL;
    Py_buffer tb = {0}, ind = {0}, ylo = {0}, yhi = {0}, cor = {0};
    Triples tri = {0};
    PyObject *result = NULL;
    int32_t *row = NULL;
    int64_t *start = NULL;
    if (get(o_target, &tb, F64, 0, "target") || get_triples(o_tri, &tri, "triangles")
        || get(o_index, &ind, I64, 1, "index") || get(o_ylo, &ylo, I64, 1, "ylo")
        || get(o_yhi, &yhi, I64, 1, "yhi") || get(o_corners, &cor, I32, 1, "corners"))
        goto done;
    Py_ssize_t nodes = N_OF(tb) / 2, m = tri.rows;
    if (N_OF(ind) < m || N_OF(ylo) < m || N_OF(yhi) < m || N_OF(cor) < 3 * m || width < 1 || height < 1
        || height > INT32_MAX || nodes > INT32_MAX
        || !(row = malloc((2 * m + 1) * sizeof(int32_t)))
        || !(start = calloc(height + 1, sizeof(int64_t)))) {
        PyErr_SetString(PyExc_ValueError, "triangles: buffer sizes do not match");
        goto done;
    }
    int64_t *index = ind.buf, *lo_out = ylo.buf, *hi_out = yhi.buf;
    int32_t *corners = cor.buf, *last = row + m;
    Py_ssize_t count;

    Py_BEGIN_ALLOW_THREADS
    count = triangle_rows(tb.buf, nodes, &tri, width, height, row, last, start);
    for (long long y = 0; y < height && count >= 0; y++)       /* a counting sort */
        start[y + 1] += start[y];
    for (Py_ssize_t i = 0; i < m && count >= 0; i++) {
        if (row[i] < 0)
            continue;
        int64_t at = start[row[i]]++;
        index[at] = i;
        lo_out[at] = row[i];
        hi_out[at] = last[i];
        for (int c = 0; c < 3; c++)
            corners[3 * at + c] = (int32_t)triple(&tri, i, c);
    }
    Py_END_ALLOW_THREADS

    if (count < 0)
        PyErr_SetString(PyExc_IndexError, "triangles: node index out of range");
    else
        result = PyLong_FromSsize_t(count);
done:
    free(row);
    free(start);
    PyBuffer_Release(&tb);
    PyBuffer_Release(&tri.view);
    PyBuffer_Release(&ind);
    PyBuffer_Release(&ylo);
    PyBuffer_Release(&yhi);
    PyBuffer_Release(&cor);
    return result;
}

/* setup() of the kept triangles sel (nodes in corners) into rec; 0 when an index is out
 * of range. */
static ROUNDING_CLONES int
record_rows(const double *target, const double *source, Py_ssize_t nodes, const int32_t *corners,
            Py_ssize_t kept, long long width, long long height, const int64_t *sel, Py_ssize_t n,
            double *r)
{
    int64_t lo, hi;
    for (Py_ssize_t i = 0; i < n; i++, r += NREC) {
        if (sel[i] < 0 || sel[i] >= kept)
            return 0;
        const int32_t *c = corners + 3 * sel[i];
        int64_t nn[3] = {c[0], c[1], c[2]};
        if (nn[0] < 0 || nn[0] >= nodes || nn[1] < 0 || nn[1] >= nodes || nn[2] < 0 || nn[2] >= nodes)
            return 0;
        if (!setup(target, source, nn, width, height, &lo, &hi, r))
            for (int k = 0; k < NREC; k++)    /* not kept on this canvas: no pixel */
                r[k] = NAN;
    }
    return 1;
}

/* The records of kept triangles sel (their J feeds the footprints too). */
static PyObject *
records(PyObject *self, PyObject *args)
{
    PyObject *o_target, *o_source, *o_cor, *o_sel, *o_rec;
    long long width, height;
    if (!PyArg_ParseTuple(args, "OOOLLOO:records", &o_target, &o_source, &o_cor, &width, &height,
                          &o_sel, &o_rec))
        return NULL;
    Py_buffer tb = {0}, sb = {0}, cor = {0}, sel = {0}, rec = {0};
    PyObject *result = NULL;
    if (get(o_target, &tb, F64, 0, "target") || get(o_source, &sb, F64, 0, "source")
        || get(o_cor, &cor, I32, 0, "corners") || get(o_sel, &sel, I64, 0, "sel")
        || get(o_rec, &rec, F64, 1, "rec"))
        goto done;
    Py_ssize_t n = N_OF(sel);
    if (N_OF(rec) < NREC * n || N_OF(sb) != N_OF(tb) || width < 1 || height < 1) {
        PyErr_SetString(PyExc_ValueError, "records: buffer sizes do not match or empty canvas");
        goto done;
    }
    int ok;
    Py_BEGIN_ALLOW_THREADS
    ok = record_rows(tb.buf, sb.buf, N_OF(tb) / 2, cor.buf, N_OF(cor) / 3, width, height, sel.buf, n,
                     rec.buf);
    Py_END_ALLOW_THREADS
    if (!ok)
        PyErr_SetString(PyExc_IndexError, "records: triangle or node index out of range");
    else
        result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&tb);
    PyBuffer_Release(&sb);
    PyBuffer_Release(&cor);
    PyBuffer_Release(&sel);
    PyBuffer_Release(&rec);
    return result;
}

/* The loop of rasterize(): returns how many pixels it marked in aatri. */
static ROUNDING_CLONES Py_ssize_t
fill_band(const double *records, const int64_t *lo_of, const int64_t *hi_of, Py_ssize_t count,
          long long y0, long long y1, long long width, const int32_t *restrict ids,
          float *restrict mapx, float *restrict mapy, int32_t *restrict aatri)
{
    Py_ssize_t marked = 0;
    for (Py_ssize_t t = 0; t < count; t++) {
        const double *r = records + NREC * t;
        int64_t lo = lo_of[t] > y0 ? lo_of[t] : y0, hi = hi_of[t] < y1 - 1 ? hi_of[t] : y1 - 1;
        int32_t id = ids ? ids[t] : -1;
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
    return marked;
}

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
    Py_ssize_t marked;

    Py_BEGIN_ALLOW_THREADS
    marked = fill_band(records, lo_of, hi_of, count, y0, y1, width, ids, mapx, mapy, aatri);
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

/* ------------------------------------------------------------------ footprints
 *
 * A triangle's inverse map J (source pixels per output pixel) is R(theta) diag(s1, s2)
 * R(phi)^T. With u1 + i v1 = (s1 + s2) e^{i (theta + phi)} and u2 + i v2 =
 * (s1 - s2) e^{i (theta - phi)} (sums and differences of J's entries), s1 and s2 are half
 * the sum and the difference of their moduli p and q, and their product is
 * w = (s1^2 - s2^2) e^{2 i theta}. As |w| + w = 2 |w| cos(theta) e^{i theta} and
 * i (|w| - w) = 2 |w| sin(theta) e^{i theta}, the major axis e^{i theta} points along
 * (|w| + Re w, Im w), or along (Im w, |w| - Re w) when Re w < 0 (no cancellation either
 * way). The symmetric tent ignores its sign.
 */

/* The footprint of a minifying J (s1 = (p + q) / 2 above threshold): probes per side k,
 * the pyramid level log2(m2) = base + frac, and the offset between probes. */
ALWAYS_INLINE void
footprint(double u1, double v1, double u2, double v2, double p, double q, int kmax, int32_t *ints,
          float *floats)
{
    double s1 = (p + q) / 2.0, s2 = fabs(p - q) / 2.0;
    double m1 = max_nan(s1, 1.0), m2 = max_nan(s2, 1.0);
    /* A tent of half-width 2 (m1 - m2) along the major axis, probes at most m2 apart (the
     * level's prefilter width), at most kmax a side (then a coarser level: m2 grows). */
    double steps = max_nan(2.0, ceil(2.0 * (m1 - m2) / m2 - 1e-9));
    if (steps > kmax)
        m2 = 2.0 * m1 / (kmax + 2.0);
    int32_t k = (int32_t)min_nan(steps, (double)kmax);
    double half = 2.0 * (m1 - m2);
    if (half < 1e-3)
        k = 1;
    double wr = u1 * u2 - v1 * v2, wi = u1 * v2 + v1 * u2, modulus = p * q;
    double ax = wr >= 0 ? modulus + wr : wi, ay = wr >= 0 ? wi : modulus - wr;
    double norm = sqrt(ax * ax + ay * ay);
    if (!(norm > 0))                      /* isotropic (q = 0): any axis */
        ax = 1.0, ay = 0.0, norm = 1.0;
    double level = log2(m2), base = floor(level);
    float frac = (float)(level - base);
    int32_t blend = frac > 1e-4f;
    double spacing = half / k / norm;
    ints[0] = k;
    ints[1] = (int32_t)base;
    ints[2] = blend;
    floats[0] = (float)(spacing * ax);
    floats[1] = (float)(spacing * ay);
    floats[2] = frac;
}

static PyObject *
footprints(PyObject *self, PyObject *args)
{
    PyObject *o_rec, *o_index, *o_ints, *o_floats, *result = NULL;
    double threshold, largest;
    int kmax;
    if (!PyArg_ParseTuple(args, "OdidOOO:footprints", &o_rec, &threshold, &kmax, &largest, &o_index,
                          &o_ints, &o_floats))
        return NULL;
    Py_buffer rec = {0}, ind = {0}, ib = {0}, fb = {0};
    if (get(o_rec, &rec, F64, 0, "rec") || get(o_index, &ind, I32, 1, "index")
        || get(o_ints, &ib, I32, 1, "ints") || get(o_floats, &fb, F32, 1, "floats"))
        goto done;
    Py_ssize_t n = N_OF(rec) / NREC, count = 0;
    if (N_OF(ind) < n || N_OF(ib) < 3 * n || N_OF(fb) < 3 * n || kmax < 1) {
        PyErr_SetString(PyExc_ValueError, "footprints: buffer sizes do not match");
        goto done;
    }
    const double *r = rec.buf;
    int32_t *index = ind.buf, *ints = ib.buf, max_level = 0;
    float *floats = fb.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++, r += NREC) {
        double a = r[J00], b = r[J01], c = r[J10], d = r[J11];
        double u1 = a + d, v1 = c - b, u2 = a - d, v2 = c + b;
        double p = sqrt(u1 * u1 + v1 * v1), q = sqrt(u2 * u2 + v2 * v2), s1 = (p + q) / 2.0;
        index[i] = -1;
        if (!(s1 > threshold && s1 < largest))       /* not minifying, NaN or overflow */
            continue;
        index[i] = (int32_t)count;
        footprint(u1, v1, u2, v2, p, q, kmax, ints + 3 * count, floats + 3 * count);
        int32_t top = ints[3 * count + 1] + ints[3 * count + 2];
        max_level = top > max_level ? top : max_level;
        count++;
    }
    Py_END_ALLOW_THREADS
    result = Py_BuildValue("ni", count, (int)max_level);
done:
    PyBuffer_Release(&rec);
    PyBuffer_Release(&ind);
    PyBuffer_Release(&ib);
    PyBuffer_Release(&fb);
    return result;
}

/* ------------------------------------------------------------------ antialiasing
 *
 * Per triangle: ints (k, base, blend) and floats (step x, step y, frac), as in
 * antialias.Footprints. A pixel with aatri >= 0 takes 2k - 1 probes (j = -(k-1) .. k-1)
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

/* The 2k - 1 probes of a pixel at (sx, sy) on a level of the given scale. */
ALWAYS_INLINE void
probe_run(float *restrict ox, float *restrict oy, float sx, float sy, float step_x, float step_y,
          float scale, const int k)
{
    for (int j = -(k - 1), c = 0; j <= k - 1; j++, c++) {
        ox[c] = (sx + (float)j * step_x) * scale;
        oy[c] = (sy + (float)j * step_y) * scale;
    }
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
        scale[l] = (float)ldexp(1.0, (int)-l);     /* 2^-l: level l pixel i sits on 2^l i */
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
            switch (k) {           /* constant k: the loop unrolls */
            case 2: probe_run(ox + c, oy + c, sx, sy, step_x, step_y, scale[l], 2); break;
            case 3: probe_run(ox + c, oy + c, sx, sy, step_x, step_y, scale[l], 3); break;
            default: probe_run(ox + c, oy + c, sx, sy, step_x, step_y, scale[l], k);
            }
            cursor[l] = c + 2 * k - 1;
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

/* rintf (round half to even) without a libm call in the common case. */
static inline float
round_even(float x)
{
    return x >= 0.0f && x < 8388608.0f ? (x + 8388608.0f) - 8388608.0f : rintf(x);
}

/* value = sum over levels of [w_level *] (sum over j of weight_j * sample_j), as
 * the filter defines it; rounded, clipped to [0, top] and written to the pixel
 * (to channels 0..2 when an alpha channel was added). */
#define DEFINE_RESOLVE(NAME, T)                                                                 \
    /* One pixel; called with constant probes and blend (below) so that the sums unroll. */   \
    ALWAYS_INLINE void NAME##_pixel(const T *restrict v0, const T *restrict v1,                  \
                                    const float *restrict w, const int probes, const int blend, \
                                    float frac, T *restrict o, const int channels,             \
                                    const int out_channels)                                     \
    {                                                                                           \
        const float top = sizeof(T) == 1 ? 255.0f : 65535.0f, keep = 1.0f - frac;               \
        for (int c = 0; c < channels; c++) {                                                    \
            float sum = (float)v0[c] * w[0];                                                    \
            for (int j = 1; j < probes; j++)                                                    \
                sum += (float)v0[j * channels + c] * w[j];                                      \
            float acc = 0.0f;                                                                   \
            if (blend) {                                                                        \
                float sum1 = (float)v1[c] * w[0];                                               \
                for (int j = 1; j < probes; j++)                                                \
                    sum1 += (float)v1[j * channels + c] * w[j];                                 \
                acc += sum * keep;                                                              \
                acc += sum1 * frac;                                                             \
            } else {                                                                            \
                acc += sum;                                                                     \
            }                                                                                   \
            float r = round_even(acc);                                                          \
            r = r < 0.0f ? 0.0f : r > top ? top : r;                                            \
            if (out_channels == channels)                                                       \
                o[c] = (T)r;                                                                    \
            else if (channels == 1)                                                             \
                o[0] = o[1] = o[2] = (T)r;                                                      \
            else                                                                                \
                o[c] = (T)r;                                                                    \
        }                                                                                       \
    }                                                                                           \
                                                                                                \
    ALWAYS_INLINE int NAME(const int32_t *restrict aatri, Py_ssize_t n, Py_ssize_t tris,        \
                           const int32_t *restrict ints, const float *restrict floats,          \
                           const float *restrict weights, int kmax,                             \
                           const int64_t *restrict offsets, Py_ssize_t levels,                  \
                           int64_t *restrict cursor, const T *restrict samples, T *restrict out, \
                           const int channels, const int out_channels)                          \
    {                                                                                           \
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
            const T *v0 = samples + c0 * channels, *v1 = samples + c1 * channels;              \
            T *o = out + p * out_channels;                                                      \
            float frac = floats[3 * t + 2];                                                     \
            switch (2 * probes + blend) {                                                       \
            case 2 * 1: NAME##_pixel(v0, v1, w, 1, 0, frac, o, channels, out_channels); break;  \
            case 2 * 3: NAME##_pixel(v0, v1, w, 3, 0, frac, o, channels, out_channels); break;  \
            case 2 * 5: NAME##_pixel(v0, v1, w, 5, 0, frac, o, channels, out_channels); break;  \
            case 2 * 7: NAME##_pixel(v0, v1, w, 7, 0, frac, o, channels, out_channels); break;  \
            case 2 * 3 + 1: NAME##_pixel(v0, v1, w, 3, 1, frac, o, channels, out_channels); break; \
            case 2 * 5 + 1: NAME##_pixel(v0, v1, w, 5, 1, frac, o, channels, out_channels); break; \
            default: NAME##_pixel(v0, v1, w, probes, blend, frac, o, channels, out_channels);   \
            }                                                                                   \
        }                                                                                       \
        return 1;                                                                               \
    }

DEFINE_RESOLVE(resolve8, uint8_t)
DEFINE_RESOLVE(resolve16, uint16_t)

#if defined(__SSE2__)
/* resolve8 for 3 or 4 channels with every channel in a lane of an SSE register (the same
 * float operations as resolve8_pixel, lane by lane). */

/* A sample's channels (3 or 4 bytes) as floats; reads a 4th byte of a 3-channel sample
 * only when it lies before end. */
ALWAYS_INLINE __m128
sample_ps(const uint8_t *p, const uint8_t *end, const int channels)
{
    uint32_t u;
    if (channels == 4 || p + 4 <= end)
        memcpy(&u, p, 4);
    else
        u = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16;
    const __m128i zero = _mm_setzero_si128();
    return _mm_cvtepi32_ps(_mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128((int)u), zero), zero));
}

/* sum over j of w[j] * sample_j, as resolve8_pixel sums each channel. */
ALWAYS_INLINE __m128
tent_ps(const uint8_t *v, const uint8_t *end, const float *w, const int probes, const int channels)
{
    __m128 sum = _mm_mul_ps(sample_ps(v, end, channels), _mm_set1_ps(w[0]));
    for (int j = 1; j < probes; j++)
        sum = _mm_add_ps(sum, _mm_mul_ps(sample_ps(v + j * channels, end, channels), _mm_set1_ps(w[j])));
    return sum;
}

ALWAYS_INLINE void
resolve8_ps_pixel(const uint8_t *restrict v0, const uint8_t *restrict v1, const uint8_t *end,
                  const float *restrict w, const int probes, const int blend, float frac,
                  uint8_t *restrict o, const int channels)
{
    __m128 acc = _mm_setzero_ps(), sum = tent_ps(v0, end, w, probes, channels);
    if (blend) {
        __m128 sum1 = tent_ps(v1, end, w, probes, channels);
        acc = _mm_add_ps(acc, _mm_mul_ps(sum, _mm_set1_ps(1.0f - frac)));
        acc = _mm_add_ps(acc, _mm_mul_ps(sum1, _mm_set1_ps(frac)));
    } else {
        acc = _mm_add_ps(acc, sum);
    }
    /* round_even() (the sums lie in [0, 255], where it is (x + 2^23) - 2^23), clip, store */
    const __m128 big = _mm_set1_ps(8388608.0f);
    __m128 r = _mm_sub_ps(_mm_add_ps(acc, big), big);
    r = _mm_min_ps(_mm_max_ps(r, _mm_setzero_ps()), _mm_set1_ps(255.0f));
    __m128i b = _mm_cvttps_epi32(r);
    b = _mm_packs_epi32(b, b);
    uint32_t u = (uint32_t)_mm_cvtsi128_si32(_mm_packus_epi16(b, b));
    if (channels == 4)
        memcpy(o, &u, 4);
    else
        o[0] = (uint8_t)u, o[1] = (uint8_t)(u >> 8), o[2] = (uint8_t)(u >> 16);
}

/* resolve8 for 3 or 4 channels (out_channels: the same, or 4 for 3 channels). */
ALWAYS_INLINE int
resolve8_ps(const int32_t *restrict aatri, Py_ssize_t n, Py_ssize_t tris, const int32_t *restrict ints,
            const float *restrict floats, const float *restrict weights, int kmax,
            const int64_t *restrict offsets, Py_ssize_t levels, int64_t *restrict cursor,
            const uint8_t *restrict samples, Py_ssize_t total, uint8_t *restrict out,
            const int channels, const int out_channels)
{
    const uint8_t *end = samples + total * channels;
    int k, base, blend;
    for (Py_ssize_t p = 0; p < n; p++) {
        int32_t t = aatri[p];
        if (t < 0)
            continue;
        if (!aa_pixel(t, tris, ints, levels, &k, &base, &blend) || k > kmax)
            return 0;
        int probes = 2 * k - 1;
        int64_t c0 = cursor[base], c1 = blend ? cursor[base + 1] : 0;
        if (c0 + probes > offsets[base + 1] || (blend && c1 + probes > offsets[base + 2]))
            return 0;
        cursor[base] = c0 + probes;
        if (blend)
            cursor[base + 1] = c1 + probes;
        const float *w = weights + (Py_ssize_t)k * (2 * kmax - 1);
        const uint8_t *v0 = samples + c0 * channels, *v1 = samples + c1 * channels;
        uint8_t *o = out + p * out_channels;
        float frac = floats[3 * t + 2];
        switch (2 * probes + blend) {
        case 2 * 1: resolve8_ps_pixel(v0, v1, end, w, 1, 0, frac, o, channels); break;
        case 2 * 3: resolve8_ps_pixel(v0, v1, end, w, 3, 0, frac, o, channels); break;
        case 2 * 5: resolve8_ps_pixel(v0, v1, end, w, 5, 0, frac, o, channels); break;
        case 2 * 7: resolve8_ps_pixel(v0, v1, end, w, 7, 0, frac, o, channels); break;
        case 2 * 3 + 1: resolve8_ps_pixel(v0, v1, end, w, 3, 1, frac, o, channels); break;
        case 2 * 5 + 1: resolve8_ps_pixel(v0, v1, end, w, 5, 1, frac, o, channels); break;
        default: resolve8_ps_pixel(v0, v1, end, w, probes, blend, frac, o, channels);
        }
    }
    return 1;
}
#endif

/* resolve8 / resolve16 with the channel counts as constants (unrolled, in registers). */
#define RESOLVE_ARGS                                                                            \
    const int32_t *aatri, Py_ssize_t n, Py_ssize_t tris, const int32_t *ints,                   \
        const float *floats, const float *weights, int kmax, const int64_t *offsets,            \
        Py_ssize_t levels, int64_t *cursor
#define RESOLVE_PASS aatri, n, tris, ints, floats, weights, kmax, offsets, levels, cursor

static int
resolve(RESOLVE_ARGS, const void *samples, Py_ssize_t total, void *out, int depth, int channels,
        int out_channels)
{
#if defined(__SSE2__)
    if (depth == 1 && channels == 3 && out_channels == 3)
        return resolve8_ps(RESOLVE_PASS, samples, total, out, 3, 3);
    if (depth == 1 && channels == 3 && out_channels == 4)
        return resolve8_ps(RESOLVE_PASS, samples, total, out, 3, 4);
    if (depth == 1 && channels == 4 && out_channels == 4)
        return resolve8_ps(RESOLVE_PASS, samples, total, out, 4, 4);
#endif
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
    ok = resolve(aatri, n, tris, ints, floats, weights, kmax, offsets, levels, cursor, smp.buf,
                 N_OF(smp) / channels, ob.buf, (int)smp.itemsize, channels, out_channels);
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

ALWAYS_INLINE void
scatter_pixels(const int32_t *aatri, Py_ssize_t n, const char *in, char *out, const Py_ssize_t size,
               const Py_ssize_t channels, const Py_ssize_t out_channels)
{
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
    Py_BEGIN_ALLOW_THREADS
    if (size == 1 && channels == 3 && out_channels == 3)    /* the usual case: fixed-size copies */
        scatter_pixels(aatri, n, val.buf, ob.buf, 1, 3, 3);
    else
        scatter_pixels(aatri, n, val.buf, ob.buf, size, channels, out_channels);
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
     "triangles(target, triangles, width, height, index, ylo, yhi, corners) -> count\n\n"
     "The triangles that reach the canvas (their indices), their row ranges and nodes,\n"
     "stably sorted by first row."},
    {"records", records, METH_VARARGS,
     "records(target, source, corners, width, height, sel, rec)\n\n"
     "The records (16 float64: x-bounds, J, p0, s0) of kept triangles sel."},
    {"rasterize", rasterize, METH_VARARGS,
     "rasterize(rec, ylo, yhi, y0, y1, width, mapx, mapy, ids, aatri) -> int\n\n"
     "Fill the band's maps from the triangles of rec, in order; set aatri to ids[t] where\n"
     "that is >= 0 (minifying triangles); return how many pixels that marked."},
    {"footprints", footprints, METH_VARARGS,
     "footprints(rec, threshold, kmax, largest, index, ints, floats) -> (count, max_level)\n\n"
     "The minifying triangles of rec (numbered in index, -1 for the others), their ints\n"
     "(k, base, blend) and floats (step x, step y, frac), and the highest level they use."},
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
    "The compiled loops of featurewarp_cli.render: rasterizer and antialiasing filter.", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__raster(void)
{
    return PyModule_Create(&module);
}
