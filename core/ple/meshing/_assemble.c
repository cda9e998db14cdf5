/* Box assembly of ple.meshing.tessellate, compiled: hub template vertices placed by each hub's
 * similarity, and faces of repeated local pieces offset into the box's vertex array.
 *
 * The compiled form of ``tessellate._place_numpy`` and ``tessellate._fill_numpy``, value for
 * value: the same IEEE operations in the same order (built with -ffp-contract=off: no fused
 * multiply-adds), integer offsets added as there. The GIL is released, so the threads of a
 * stream assemble boxes at once. tessellate uses it when it was built (an optional extension)
 * and the tests check it against the numpy forms.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

typedef struct {
    Py_buffer b;
    int held;
} Buf;

static void release(Buf *bufs, int n) {
    for (int i = 0; i < n; i++)
        if (bufs[i].held)
            PyBuffer_Release(&bufs[i].b);
}

/* A C-contiguous buffer of ``itemsize``-byte items (0: 4 or 8) of the format class ``kinds`` (a
 * struct character set), a multiple of ``per`` items long; None allowed when ``optional``. */
static int take(PyObject *o, Buf *buf, int writable, const char *kinds, Py_ssize_t itemsize, Py_ssize_t per,
                int optional, const char *what) {
    buf->held = 0;
    if (o == Py_None && optional)
        return 0;
    if (PyObject_GetBuffer(o, &buf->b, (writable ? PyBUF_WRITABLE : 0) | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    buf->held = 1;
    const char *fmt = buf->b.format[0] == '<' || buf->b.format[0] == '=' ? buf->b.format + 1 : buf->b.format;
    Py_ssize_t size = buf->b.itemsize;
    if (strchr(kinds, fmt[0]) == NULL || fmt[1] != 0 || (itemsize ? size != itemsize : size != 4 && size != 8) ||
        buf->b.len % (per * size) != 0) {
        PyErr_Format(PyExc_TypeError, "%s: wrong dtype or shape", what);
        return -1;
    }
    return 0;
}

#define N(buf, size) ((buf).b.len / (size))

/* The arrays of a tuple (chunks of a table), all of one format class and row width: their
 * buffers, data pointers and row counts, allocated here (``free_chunks``). NULL on error. */
typedef struct {
    Py_ssize_t n;
    Buf *bufs;
    const void **ptr;
    Py_ssize_t *rows;
} Chunks;

static void free_chunks(Chunks *c) {
    if (c->bufs)
        release(c->bufs, (int)c->n);
    PyMem_Free(c->bufs);
    PyMem_Free((void *)c->ptr);
    PyMem_Free(c->rows);
}

static int take_chunks(PyObject *tuple, Chunks *c, const char *kinds, Py_ssize_t itemsize, Py_ssize_t per,
                       const char *what) {
    memset(c, 0, sizeof(*c));
    if (!PyTuple_Check(tuple)) {
        PyErr_Format(PyExc_TypeError, "%s: a tuple of arrays", what);
        return -1;
    }
    Py_ssize_t n = PyTuple_GET_SIZE(tuple);
    c->bufs = PyMem_Calloc(n + 1, sizeof(Buf));
    c->ptr = PyMem_Calloc(n + 1, sizeof(void *));
    c->rows = PyMem_Calloc(n + 1, sizeof(Py_ssize_t));
    if (!c->bufs || !c->ptr || !c->rows) {
        free_chunks(c);
        PyErr_NoMemory();
        return -1;
    }
    for (Py_ssize_t k = 0; k < n; k++) {
        c->n = k + 1;
        if (take(PyTuple_GET_ITEM(tuple, k), &c->bufs[k], 0, kinds, itemsize, per, 0, what) < 0) {
            free_chunks(c);
            return -1;
        }
        c->ptr[k] = c->bufs[k].b.buf;
        c->rows[k] = c->bufs[k].b.len / (per * c->bufs[k].b.itemsize);
    }
    return 0;
}

/* place(tvs (tuple of float64 (T_c, 3)), chunk int64 (n_tpl,), vstart int64 (n_tpl,), vcount int64
 * (n_tpl,), tid int64 (n,), offset int64 (n,), m float64 (n, 4, 4), out float64 (V, 3)): for each
 * hub i, the vcount[t] vertices of template t = tid[i] from row vstart[t] of tvs[chunk[t]], mapped
 * by m[i] (x' = R x + T, row by row ((R0 x + R1 y) + R2 z) + T), into rows offset[i] … of out. */
static PyObject *place(PyObject *self, PyObject *args) {
    PyObject *tvs, *o[7];
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOOOOO", &tvs, &o[0], &o[1], &o[2], &o[3], &o[4], &o[5], &o[6]))
        return NULL;
    Chunks tc;
    Buf b[7];
    memset(b, 0, sizeof(b));
    const char *I = "qlQL";
    if (take(o[0], &b[0], 0, I, 8, 1, 0, "chunk") < 0 || take(o[1], &b[1], 0, I, 8, 1, 0, "vstart") < 0 ||
        take(o[2], &b[2], 0, I, 8, 1, 0, "vcount") < 0 || take(o[3], &b[3], 0, I, 8, 1, 0, "tid") < 0 ||
        take(o[4], &b[4], 0, I, 8, 1, 0, "offset") < 0 || take(o[5], &b[5], 0, "d", 8, 16, 0, "m") < 0 ||
        take(o[6], &b[6], 1, "d", 8, 3, 0, "out") < 0) {
        release(b, 7);
        return NULL;
    }
    if (take_chunks(tvs, &tc, "d", 8, 3, "template vertices") < 0) {
        release(b, 7);
        return NULL;
    }
    Py_ssize_t nc = tc.n;
    const void **cptr = tc.ptr;
    const Py_ssize_t *crows = tc.rows;
    const double *m = b[5].b.buf;
    const int64_t *chunk = b[0].b.buf, *vstart = b[1].b.buf, *vcount = b[2].b.buf, *tid = b[3].b.buf;
    const int64_t *off = b[4].b.buf;
    double *out = b[6].b.buf;
    Py_ssize_t ntpl = N(b[0], 8), n = N(b[3], 8), nout = N(b[6], 24);
    int bad = N(b[1], 8) != ntpl || N(b[2], 8) != ntpl || N(b[4], 8) != n || N(b[5], 128) != n;
    if (bad)
        PyErr_SetString(PyExc_ValueError, "place: chunk/vstart/vcount or tid/offset/m lengths differ");
    for (Py_ssize_t i = 0; i < n && !bad; i++) {  /* every range inside its array, before any write */
        int64_t t = tid[i];
        bad = t < 0 || t >= ntpl || chunk[t] < 0 || chunk[t] >= nc || vstart[t] < 0 || vcount[t] < 0 ||
              vstart[t] + vcount[t] > crows[chunk[t]] || off[i] < 0 || off[i] + vcount[t] > nout;
        if (bad)
            PyErr_Format(PyExc_IndexError, "place: hub %zd (template %lld) out of range", i, (long long)t);
    }
    if (bad) {
        free_chunks(&tc);
        release(b, 7);
        return NULL;
    }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *r = m + 16 * i;
        const double *src = (const double *)cptr[chunk[tid[i]]] + 3 * vstart[tid[i]];
        double *dst = out + 3 * off[i];
        for (int64_t k = 0; k < vcount[tid[i]]; k++) {
            double x = src[3 * k], y = src[3 * k + 1], z = src[3 * k + 2];
            for (int j = 0; j < 3; j++) {
                double s = r[4 * j] * x;
                s = s + r[4 * j + 1] * y;
                s = s + r[4 * j + 2] * z;
                dst[3 * k + j] = s + r[4 * j + 3];
            }
        }
    }
    Py_END_ALLOW_THREADS
    free_chunks(&tc);
    release(b, 7);
    Py_RETURN_NONE;
}

/* fill(out int32|int64 (F, 3), pos, Ls (tuple of int32 (l_c, 3)), pc int64 (P,) or None, W uint8
 * (l_0, 3) or None, pf0 int64 (P,), pfn int64 (P,), A int64 (a,), B int64 (a,) or None, pa0 int64
 * (P,), pan int64 (P,)) -> pos': for each piece p, for each of its pan[p] offsets a = A[j] (b = B[j],
 * or a), its pfn[p] local faces from row pf0[p] of Ls[pc[p]] (pc None: Ls[0]), each corner plus a
 * (plus b where W is 1; W only with one chunk), written from face pos on. */
#define FILL(NAME, OUT)                                                                                       \
    static void NAME(OUT *out, Py_ssize_t pos, const void **Ls, const int64_t *pc, const uint8_t *W,          \
                     const int64_t *pf0, const int64_t *pfn, const int64_t *A, const int64_t *B,              \
                     const int64_t *pa0, const int64_t *pan, Py_ssize_t np_) {                                \
        OUT *dst = out + 3 * pos;                                                                             \
        for (Py_ssize_t p = 0; p < np_; p++) {                                                                \
            const int32_t *f = (const int32_t *)Ls[pc ? pc[p] : 0] + 3 * pf0[p];                             \
            const uint8_t *w = W ? W + 3 * pf0[p] : NULL;                                                     \
            int64_t nf = pfn[p];                                                                              \
            for (int64_t j = pa0[p]; j < pa0[p] + pan[p]; j++) {                                              \
                OUT a = (OUT)A[j], bb = B ? (OUT)B[j] : a;                                                    \
                if (w == NULL) {                                                                              \
                    for (int64_t k = 0; k < 3 * nf; k++)                                                      \
                        dst[k] = (OUT)f[k] + a;                                                               \
                } else {                                                                                      \
                    for (int64_t k = 0; k < 3 * nf; k++)                                                      \
                        dst[k] = (OUT)f[k] + (w[k] ? bb : a);                                                 \
                }                                                                                             \
                dst += 3 * nf;                                                                                \
            }                                                                                                 \
        }                                                                                                     \
    }
FILL(fill_32, int32_t)
FILL(fill_64, int64_t)

static PyObject *fill(PyObject *self, PyObject *args) {
    PyObject *lo, *o[9];
    Py_ssize_t pos;
    (void)self;
    if (!PyArg_ParseTuple(args, "OnOOOOOOOOO", &o[0], &pos, &lo, &o[1], &o[2], &o[3], &o[4], &o[5], &o[6], &o[7],
                          &o[8]))
        return NULL;
    Buf b[9];
    memset(b, 0, sizeof(b));
    const char *I = "qlQL";
    if (take(o[0], &b[0], 1, "iIqlQL", 0, 3, 0, "out") < 0 || take(o[1], &b[1], 0, I, 8, 1, 1, "pc") < 0 ||
        take(o[2], &b[2], 0, "B?", 1, 3, 1, "corner sides") < 0 || take(o[3], &b[3], 0, I, 8, 1, 0, "pf0") < 0 ||
        take(o[4], &b[4], 0, I, 8, 1, 0, "pfn") < 0 || take(o[5], &b[5], 0, I, 8, 1, 0, "A") < 0 ||
        take(o[6], &b[6], 0, I, 8, 1, 1, "B") < 0 || take(o[7], &b[7], 0, I, 8, 1, 0, "pa0") < 0 ||
        take(o[8], &b[8], 0, I, 8, 1, 0, "pan") < 0) {
        release(b, 9);
        return NULL;
    }
    Chunks lc;
    if (take_chunks(lo, &lc, "iI", 4, 3, "local faces") < 0) {
        release(b, 9);
        return NULL;
    }
    Py_ssize_t osz = b[0].b.itemsize, na = N(b[5], 8), nout = N(b[0], 3 * osz), np_ = N(b[3], 8);
    const int64_t *pc = b[1].held ? b[1].b.buf : NULL;
    const int64_t *pf0 = b[3].b.buf, *pfn = b[4].b.buf, *pa0 = b[7].b.buf, *pan = b[8].b.buf;
    int bad = N(b[4], 8) != np_ || N(b[7], 8) != np_ || N(b[8], 8) != np_ || (pc && N(b[1], 8) != np_) ||
              (b[6].held && N(b[6], 8) != na) || pos < 0 || (lc.n == 0 && np_ > 0) ||
              (b[2].held && (lc.n != 1 || N(b[2], 3) != lc.rows[0]));
    Py_ssize_t end = pos;
    for (Py_ssize_t p = 0; p < np_ && !bad; p++) {  /* every range inside its array, before any write */
        int64_t c = pc ? pc[p] : 0;
        bad = c < 0 || c >= lc.n || pf0[p] < 0 || pfn[p] < 0 || pf0[p] + pfn[p] > lc.rows[c] || pa0[p] < 0 ||
              pan[p] < 0 || pa0[p] + pan[p] > na;
        end += bad ? 0 : pfn[p] * pan[p];
        bad |= end > nout;
    }
    if (bad) {
        PyErr_SetString(PyExc_IndexError, "fill: a piece's faces, offsets or output out of range");
        free_chunks(&lc);
        release(b, 9);
        return NULL;
    }
    const uint8_t *W = b[2].held ? b[2].b.buf : NULL;
    const int64_t *A = b[5].b.buf, *B = b[6].held ? b[6].b.buf : NULL;
    const void **Ls = lc.ptr;
    Py_BEGIN_ALLOW_THREADS
    if (osz == 4)
        fill_32(b[0].b.buf, pos, Ls, pc, W, pf0, pfn, A, B, pa0, pan, np_);
    else
        fill_64(b[0].b.buf, pos, Ls, pc, W, pf0, pfn, A, B, pa0, pan, np_);
    Py_END_ALLOW_THREADS
    free_chunks(&lc);
    release(b, 9);
    return PyLong_FromSsize_t(end);
}

static PyMethodDef methods[] = {
    {"place", place, METH_VARARGS,
     "place(tvs, chunk, vstart, vcount, tid, offset, m, out): template vertices mapped by each hub's similarity."},
    {"fill", fill, METH_VARARGS,
     "fill(out, pos, Ls, pc, W, pf0, pfn, A, B, pa0, pan) -> pos': pieces of local faces offset into out."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_assemble", "Compiled box assembly.", -1, methods};

PyMODINIT_FUNC PyInit__assemble(void) { return PyModule_Create(&module); }
