/* Binary STL records of vertices[faces], snapped to a float32 grid, in one pass per face.
 *
 * The compiled form of ple.io.export's numpy encoder (``stl_chunk`` of a (vertices, faces) pair:
 * ``ple.meshing.weld.snapped_slices`` then ``_encode``), byte for byte: the same IEEE operations
 * in the same order, no fused multiply-adds (built with -ffp-contract=off), the GIL released.
 * ple.io.export uses it when it was built (an optional extension) and checks it against the numpy
 * encoder in the tests.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define RECORD 50

static int get_buffer(PyObject *obj, Py_buffer *view, int writable, const char *what) {
    if (PyObject_GetBuffer(obj, view, (writable ? PyBUF_WRITABLE : 0) | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    (void)what;
    return 0;
}

/* Records of the faces f[0 .. 3 nf) (int32 or int64 corners) over the float32 vertices v32, into
 * out; with snap, faces two of whose corners are equal as floats are not kept. Branch-free: each
 * record is written at the next free slot, which advances only if the face is kept (corners often
 * share one coordinate, so short-circuit tests would be mispredicted). Returns the records kept. */
#define FACE_LOOP(NAME, INT)                                                                            \
    static Py_ssize_t NAME(const float *v32, const INT *f, Py_ssize_t nf, int snap, unsigned char *out) { \
        Py_ssize_t n = 0;                                                                               \
        for (Py_ssize_t t = 0; t < nf; t++) {                                                           \
            const float *p0 = v32 + 3 * (Py_ssize_t)f[3 * t];                                           \
            const float *p1 = v32 + 3 * (Py_ssize_t)f[3 * t + 1];                                       \
            const float *p2 = v32 + 3 * (Py_ssize_t)f[3 * t + 2];                                       \
            float a0 = p1[0] - p0[0], a1 = p1[1] - p0[1], a2 = p1[2] - p0[2];                           \
            float b0 = p2[0] - p0[0], b1 = p2[1] - p0[1], b2 = p2[2] - p0[2];                           \
            float n0 = a1 * b2 - a2 * b1;                                                               \
            float n1 = a2 * b0 - a0 * b2;                                                               \
            float n2 = a0 * b1 - a1 * b0;                                                               \
            float s = n0 * n0;                                                                          \
            s = s + n1 * n1;                                                                            \
            s = s + n2 * n2;                                                                            \
            float ln = sqrtf(s);                                                                        \
            ln = ln == 0 ? 1 : ln;                                                                      \
            float nrm[3] = {n0 / ln, n1 / ln, n2 / ln};                                                 \
            unsigned char *r = out + RECORD * n; /* straight to the record: no copy through a stack */  \
            memcpy(r, nrm, 12);                                                                         \
            memcpy(r + 12, p0, 12);                                                                     \
            memcpy(r + 24, p1, 12);                                                                     \
            memcpy(r + 36, p2, 12);                                                                     \
            r[48] = 0;                                                                                  \
            r[49] = 0;                                                                                  \
            int e01 = (p0[0] == p1[0]) & (p0[1] == p1[1]) & (p0[2] == p1[2]);                           \
            int e12 = (p1[0] == p2[0]) & (p1[1] == p2[1]) & (p1[2] == p2[2]);                           \
            int e20 = (p2[0] == p0[0]) & (p2[1] == p0[1]) & (p2[2] == p0[2]);                           \
            n += 1 - (snap & (e01 | e12 | e20));                                                        \
        }                                                                                               \
        return n;                                                                                       \
    }
FACE_LOOP(faces32, int32_t)
FACE_LOOP(faces64, int64_t)

/* The index of the first of the m corners f outside [0, nv), or -1 (a branch-free scan first). */
#define CORNER_CHECK(NAME, INT)                                         \
    static Py_ssize_t NAME(const INT *f, Py_ssize_t m, Py_ssize_t nv) { \
        int bad = 0;                                                    \
        for (Py_ssize_t i = 0; i < m; i++)                              \
            bad |= (f[i] < 0) | ((int64_t)f[i] >= (int64_t)nv);         \
        for (Py_ssize_t i = 0; bad && i < m; i++)                       \
            if (f[i] < 0 || (int64_t)f[i] >= (int64_t)nv)               \
                return i;                                               \
        return -1;                                                      \
    }
CORNER_CHECK(check32, int32_t)
CORNER_CHECK(check64, int64_t)

/* encode(vertices float64 (V, 3), faces int32 or int64 (k, 3), grid (<= 0: no snap), out bytes (k * 50))
 * -> records written. With a grid, each vertex is rounded to it (rint(x / g) * g, as np.round)
 * and faces two of whose corners are then equal as floats are dropped. The float32 vertices are
 * kept in out beyond its k records when it has room (12 V + 3 bytes: a caller's reused buffer,
 * no fresh pages to fault in on every call), else in memory allocated here. */
static PyObject *encode(PyObject *self, PyObject *args) {
    PyObject *vo, *fo, *oo;
    double g;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOdO", &vo, &fo, &g, &oo))
        return NULL;
    Py_buffer vb, fb, ob;
    if (get_buffer(vo, &vb, 0, "vertices") < 0)
        return NULL;
    if (get_buffer(fo, &fb, 0, "faces") < 0) {
        PyBuffer_Release(&vb);
        return NULL;
    }
    if (get_buffer(oo, &ob, 1, "out") < 0) {
        PyBuffer_Release(&vb);
        PyBuffer_Release(&fb);
        return NULL;
    }
    PyObject *result = NULL;
    if (strcmp(vb.format, "d") != 0 || vb.len % (3 * sizeof(double)) != 0) {
        PyErr_SetString(PyExc_TypeError, "vertices must be contiguous float64 (V, 3)");
        goto done;
    }
    int wide = fb.itemsize == 8;
    if (strchr("qlQLiI", fb.format[0]) == NULL || fb.format[1] != 0 || (fb.itemsize != 8 && fb.itemsize != 4) ||
        fb.len % (3 * fb.itemsize) != 0) {
        PyErr_SetString(PyExc_TypeError, "faces must be contiguous int32 or int64 (k, 3)");
        goto done;
    }
    Py_ssize_t nv = vb.len / (3 * (Py_ssize_t)sizeof(double));
    Py_ssize_t nf = fb.len / (3 * fb.itemsize);
    if (ob.len < nf * RECORD) {
        PyErr_SetString(PyExc_ValueError, "out is smaller than 50 bytes per face");
        goto done;
    }
    const double *v = (const double *)vb.buf;
    const int64_t *f64 = (const int64_t *)fb.buf;
    const int32_t *f32 = (const int32_t *)fb.buf;
    Py_ssize_t bad = wide ? check64(f64, 3 * nf, nv) : check32(f32, 3 * nf, nv);
    if (bad >= 0) {
        PyErr_Format(PyExc_IndexError, "face corner %lld out of range for %zd vertices",
                     wide ? (long long)f64[bad] : (long long)f32[bad], nv);
        goto done;
    }
    size_t tail = (size_t)ob.len - (size_t)nf * RECORD;
    size_t skip = (4 - ((uintptr_t)ob.buf + (size_t)nf * RECORD) % 4) % 4;
    int own = tail < skip + (size_t)(3 * nv) * sizeof(float);
    float *v32 = own ? (float *)malloc((size_t)(3 * nv + 1) * sizeof(float))
                     : (float *)((unsigned char *)ob.buf + (size_t)nf * RECORD + skip);
    if (v32 == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    Py_ssize_t n = 0;
    unsigned char *out = (unsigned char *)ob.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < 3 * nv; i++)
        v32[i] = (float)(g > 0 ? rint(v[i] / g) * g : v[i]);
    n = wide ? faces64(v32, f64, nf, g > 0, out) : faces32(v32, f32, nf, g > 0, out);
    Py_END_ALLOW_THREADS
    if (own)
        free(v32);
    result = PyLong_FromSsize_t(n);
done:
    PyBuffer_Release(&vb);
    PyBuffer_Release(&fb);
    PyBuffer_Release(&ob);
    return result;
}

static PyMethodDef methods[] = {
    {"encode", encode, METH_VARARGS,
     "encode(vertices, faces, grid, out) -> records: binary STL records of vertices[faces] (grid > 0: "
     "snapped, faces with coinciding corners dropped) written into out."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_stlcodec", "Compiled binary STL encoder.", -1, methods};

PyMODINIT_FUNC PyInit__stlcodec(void) { return PyModule_Create(&module); }
