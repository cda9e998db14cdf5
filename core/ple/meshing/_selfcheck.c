/* Self-intersections of a triangle mesh, compiled: the compiled form of ``selfcheck``'s numpy
 * path, decision for decision.
 *
 * Broad phase: face boxes hashed into a uniform grid of spacing ``cell``: a face goes into the
 * bucket of every cell its box meets (once per bucket), and a pair of faces whose boxes meet is
 * tested only in the bucket of the cell holding the lower corner of the boxes' intersection (the
 * corner lies in both boxes, so both faces are there): each pair once, no list of candidates.
 * Memory: two ints per grid entry and per bucket, nothing per pair.
 *
 * Narrow phase: the numpy form's tests (``selfcheck._disjoint_pairs``, ``_seg_tri``, ...) on the
 * same points in the same order, so the same pairs come out. Every sign is exact: orient3d and
 * orient2d in doubles with Shewchuk's static error bounds, and, where the bound does not decide,
 * recomputed exactly with floating-point expansions (Shewchuk, "Adaptive precision floating-point
 * arithmetic and fast robust geometric predicates", 1997: Two-Sum, Two-Product by Dekker's split,
 * Grow-Expansion, Scale-Expansion, zero elimination). Built with -ffp-contract=off: the error-free
 * transformations need IEEE operations as written. The GIL is released.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define EPS 1.1102230246251565e-16 /* 2^-53 */
#define O3_BOUND ((7.0 + 56.0 * EPS) * EPS)
#define O2_BOUND (4.0 * EPS)
#define EXP_MAX 256 /* components of an orient3d determinant: at most 192 */
#define MAX_ENTRIES 3 /* grid entries per face, at most (the cell doubles until so): measured best 2-3 */
#define MAX_WORKERS 64

/* ---- exact arithmetic on expansions (sums of nonoverlapping doubles, increasing magnitude) ---- */

static inline void two_sum(double a, double b, double *x, double *y) {
    double s = a + b, bv = s - a, av = s - bv;
    *x = s;
    *y = (a - av) + (b - bv);
}

static inline void fast_two_sum(double a, double b, double *x, double *y) {
    double s = a + b;
    *x = s;
    *y = b - (s - a);
}

static inline void split(double a, double *hi, double *lo) {
    double c = 134217729.0 * a; /* 2^27 + 1 */
    double big = c - a;
    *hi = c - big;
    *lo = a - *hi;
}

static inline void two_prod(double a, double b, double *x, double *y) {
    double p = a * b, ahi, alo, bhi, blo;
    split(a, &ahi, &alo);
    split(b, &bhi, &blo);
    double e1 = p - ahi * bhi, e2 = e1 - alo * bhi, e3 = e2 - ahi * blo;
    *x = p;
    *y = alo * blo - e3;
}

/* a − b exactly: h (2 components at most); returns the length */
static int diff(double a, double b, double *h) {
    double x, y;
    two_sum(a, -b, &x, &y);
    int k = 0;
    if (y != 0.0)
        h[k++] = y;
    h[k++] = x;
    return k;
}

/* h ← h + b in place (Grow-Expansion with zero elimination); returns the length */
static int grow(double *h, int n, double b) {
    double q = b, qn, hh;
    int k = 0;
    for (int i = 0; i < n; i++) {
        two_sum(q, h[i], &qn, &hh);
        q = qn;
        if (hh != 0.0)
            h[k++] = hh;
    }
    if (q != 0.0 || k == 0)
        h[k++] = q;
    return k;
}

/* h = e · b (Scale-Expansion with zero elimination) */
static int scale(const double *e, int n, double b, double *h) {
    double q, hh, p1, p0, s;
    int k = 0;
    two_prod(e[0], b, &q, &hh);
    if (hh != 0.0)
        h[k++] = hh;
    for (int i = 1; i < n; i++) {
        two_prod(e[i], b, &p1, &p0);
        two_sum(q, p0, &s, &hh);
        if (hh != 0.0)
            h[k++] = hh;
        fast_two_sum(p1, s, &q, &hh);
        if (hh != 0.0)
            h[k++] = hh;
    }
    if (q != 0.0 || k == 0)
        h[k++] = q;
    return k;
}

/* h = sign · e · f */
static int mul(const double *e, int ne, const double *f, int nf, double sign, double *h) {
    double t[EXP_MAX];
    int k = 0;
    for (int j = 0; j < nf; j++) {
        int m = scale(e, ne, sign * f[j], t);
        for (int i = 0; i < m; i++)
            k = grow(h, k, t[i]);
    }
    return k;
}

static inline int sign_of(const double *h, int n) { return (h[n - 1] > 0.0) - (h[n - 1] < 0.0); }

/* exact sign of (a0 − c0)(b1 − c1) − (a1 − c1)(b0 − c0) */
static int orient2d_exact(const double *a, const double *b, const double *c) {
    double acx[2], acy[2], bcx[2], bcy[2], h[EXP_MAX], t[EXP_MAX];
    int nax = diff(a[0], c[0], acx), nay = diff(a[1], c[1], acy);
    int nbx = diff(b[0], c[0], bcx), nby = diff(b[1], c[1], bcy);
    int n = mul(acx, nax, bcy, nby, 1.0, h);
    int m = mul(acy, nay, bcx, nbx, -1.0, t);
    for (int i = 0; i < m; i++)
        n = grow(h, n, t[i]);
    return sign_of(h, n);
}

/* exact sign of det[a − d, b − d, c − d] */
static int orient3d_exact(const double *a, const double *b, const double *c, const double *d) {
    double ad[3][2], bd[3][2], cd[3][2], det[EXP_MAX], m[EXP_MAX], t[EXP_MAX], u[EXP_MAX];
    int na[3], nb[3], nc[3], n = 0;
    for (int i = 0; i < 3; i++) {
        na[i] = diff(a[i], d[i], ad[i]);
        nb[i] = diff(b[i], d[i], bd[i]);
        nc[i] = diff(c[i], d[i], cd[i]);
    }
    for (int i = 0; i < 3; i++) { /* ad_i · (bd_j cd_k − bd_k cd_j), (i, j, k) cyclic */
        int j = (i + 1) % 3, k = (i + 2) % 3;
        int nm = mul(bd[j], nb[j], cd[k], nc[k], 1.0, m);
        int nt = mul(bd[k], nb[k], cd[j], nc[j], -1.0, t);
        for (int q = 0; q < nt; q++)
            nm = grow(m, nm, t[q]);
        int nu = mul(m, nm, ad[i], na[i], 1.0, u);
        for (int q = 0; q < nu; q++)
            n = grow(det, n, u[q]);
    }
    return sign_of(det, n);
}

/* ---- the predicates with the numpy form's static filters ---- */

static _Thread_local long long exact_calls; /* predicates the filters left to the exact form, per call */

static int orient3d(const double *a, const double *b, const double *c, const double *d) {
    double ad0 = a[0] - d[0], ad1 = a[1] - d[1], ad2 = a[2] - d[2];
    double bd0 = b[0] - d[0], bd1 = b[1] - d[1], bd2 = b[2] - d[2];
    double cd0 = c[0] - d[0], cd1 = c[1] - d[1], cd2 = c[2] - d[2];
    double m1 = bd1 * cd2 - bd2 * cd1, m2 = bd2 * cd0 - bd0 * cd2, m3 = bd0 * cd1 - bd1 * cd0;
    double det = ad0 * m1 + ad1 * m2 + ad2 * m3;
    double perm = fabs(ad0) * (fabs(bd1 * cd2) + fabs(bd2 * cd1)) + fabs(ad1) * (fabs(bd2 * cd0) + fabs(bd0 * cd2)) +
                  fabs(ad2) * (fabs(bd0 * cd1) + fabs(bd1 * cd0));
    if (fabs(det) > O3_BOUND * perm)
        return (det > 0.0) - (det < 0.0);
    exact_calls++;
    return orient3d_exact(a, b, c, d);
}

static int orient2d(const double *a, const double *b, const double *c) {
    double l = (a[0] - c[0]) * (b[1] - c[1]), r = (a[1] - c[1]) * (b[0] - c[0]);
    double det = l - r;
    if (fabs(det) > O2_BOUND * (fabs(l) + fabs(r)))
        return (det > 0.0) - (det < 0.0);
    exact_calls++;
    return orient2d_exact(a, b, c);
}

/* ---- the narrow phase: selfcheck's numpy tests, one pair at a time ---- */

typedef const double *P;

/* the two axes kept when dropping the dominant axis of cross(b − a, c − a) (np.argmax: first maximum) */
static void keep_axes(P a, P b, P c, int *k0, int *k1) {
    double u0 = b[0] - a[0], u1 = b[1] - a[1], u2 = b[2] - a[2];
    double w0 = c[0] - a[0], w1 = c[1] - a[1], w2 = c[2] - a[2];
    double n0 = fabs(u1 * w2 - u2 * w1), n1 = fabs(u2 * w0 - u0 * w2), n2 = fabs(u0 * w1 - u1 * w0);
    int k = 0;
    double best = n0;
    if (n1 > best) {
        k = 1;
        best = n1;
    }
    if (n2 > best)
        k = 2;
    *k0 = k == 0 ? 1 : 0;
    *k1 = k == 2 ? 1 : 2;
}

static inline void proj(P p, int k0, int k1, double *out) {
    out[0] = p[k0];
    out[1] = p[k1];
}

static inline int all_same(int a, int b, int c) { return (a >= 0 && b >= 0 && c >= 0) || (a <= 0 && b <= 0 && c <= 0); }

/* _seg_tri_2d: closed segment pq meets closed triangle abc, all in one plane */
static int seg_tri_2d(P p, P q, P a, P b, P c) {
    int k0, k1;
    keep_axes(a, b, c, &k0, &k1);
    double u[3][2], w[2][2];
    proj(a, k0, k1, u[0]);
    proj(b, k0, k1, u[1]);
    proj(c, k0, k1, u[2]);
    proj(p, k0, k1, w[0]);
    proj(q, k0, k1, w[1]);
    for (int j = 0; j < 3; j++) {
        const double *s = u[j], *e = u[(j + 1) % 3];
        int o1 = orient2d(s, e, w[0]), o2 = orient2d(s, e, w[1]);
        int o3 = orient2d(w[0], w[1], s), o4 = orient2d(w[0], w[1], e);
        if (o1 * o2 <= 0 && o3 * o4 <= 0 && !(o1 == 0 && o2 == 0 && o3 == 0 && o4 == 0))
            return 1;
    }
    for (int i = 0; i < 2; i++)
        if (all_same(orient2d(u[0], u[1], w[i]), orient2d(u[1], u[2], w[i]), orient2d(u[2], u[0], w[i])))
            return 1;
    return 0;
}

/* _seg_tri: closed segment pq meets closed triangle abc */
static int seg_tri(P p, P q, P a, P b, P c) {
    int dp = orient3d(a, b, c, p), dq = orient3d(a, b, c, q);
    if (dp == 0 && dq == 0)
        return seg_tri_2d(p, q, a, b, c);
    if (dp * dq > 0)
        return 0;
    return all_same(orient3d(p, q, a, b), orient3d(p, q, b, c), orient3d(p, q, c, a));
}

/* _coplanar_overlap of t1 = (a, b, c) and t2 = (p, q, r), projected along t1's normal */
static int coplanar_overlap(P a, P b, P c, P p, P q, P r) {
    int k0, k1;
    keep_axes(a, b, c, &k0, &k1);
    double u[3][2], w[3][2];
    P t1[3] = {a, b, c}, t2[3] = {p, q, r};
    for (int i = 0; i < 3; i++) {
        proj(t1[i], k0, k1, u[i]);
        proj(t2[i], k0, k1, w[i]);
    }
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            const double *s0 = u[i], *s1 = u[(i + 1) % 3], *t0 = w[j], *t1_ = w[(j + 1) % 3];
            int o1 = orient2d(s0, s1, t0), o2 = orient2d(s0, s1, t1_);
            int o3 = orient2d(t0, t1_, s0), o4 = orient2d(t0, t1_, s1);
            if (o1 * o2 < 0 && o3 * o4 < 0)
                return 1;
        }
    for (int i = 0; i < 3; i++) {
        if (all_same(orient2d(w[0], w[1], u[i]), orient2d(w[1], w[2], u[i]), orient2d(w[2], w[0], u[i])))
            return 1;
    }
    for (int i = 0; i < 3; i++) {
        if (all_same(orient2d(u[0], u[1], w[i]), orient2d(u[1], u[2], w[i]), orient2d(u[2], u[0], w[i])))
            return 1;
    }
    return 0;
}

static inline int strict_same(int a, int b, int c) { return (a > 0 && b > 0 && c > 0) || (a < 0 && b < 0 && c < 0); }

/* _disjoint_pairs: triangles without a common vertex meet */
static int disjoint_pair(P a, P b, P c, P p, P q, P r) {
    int dp = orient3d(a, b, c, p), dq = orient3d(a, b, c, q), dr = orient3d(a, b, c, r);
    if (strict_same(dp, dq, dr))
        return 0;
    if (dp == 0 && dq == 0 && dr == 0)
        return coplanar_overlap(a, b, c, p, q, r);
    if (strict_same(orient3d(p, q, r, a), orient3d(p, q, r, b), orient3d(p, q, r, c)))
        return 0;
    return seg_tri(p, q, a, b, c) || seg_tri(q, r, a, b, c) || seg_tri(r, p, a, b, c) || seg_tri(a, b, p, q, r) ||
           seg_tri(b, c, p, q, r) || seg_tri(c, a, p, q, r);
}

/* self_intersections' decision for faces fa, fb (vertex ids) of the vertices v */
static int pair_hit(const double *v, const int64_t *fa, const int64_t *fb) {
    int sa[3], sb[3], ns = 0;
    for (int i = 0; i < 3; i++) {
        sa[i] = fa[i] == fb[0] || fa[i] == fb[1] || fa[i] == fb[2];
        sb[i] = fb[i] == fa[0] || fb[i] == fa[1] || fb[i] == fa[2];
        ns += sa[i];
    }
    P A[3] = {v + 3 * fa[0], v + 3 * fa[1], v + 3 * fa[2]};
    P B[3] = {v + 3 * fb[0], v + 3 * fb[1], v + 3 * fb[2]};
    if (ns == 0)
        return disjoint_pair(A[0], A[1], A[2], B[0], B[1], B[2]);
    if (ns == 1) { /* rotate both so the shared vertex comes first: the opposite edges */
        int ia = sa[0] ? 0 : sa[1] ? 1 : 2, ib = sb[0] ? 0 : sb[1] ? 1 : 2;
        P a0 = A[ia], a1 = A[(ia + 1) % 3], a2 = A[(ia + 2) % 3];
        P b0 = B[ib], b1 = B[(ib + 1) % 3], b2 = B[(ib + 2) % 3];
        return seg_tri(a1, a2, b0, b1, b2) || seg_tri(b1, b2, a0, a1, a2);
    }
    if (ns == 2) { /* a fold: the far vertices coplanar and on one side of the shared edge */
        int ia = !sa[0] ? 0 : !sa[1] ? 1 : 2, ib = !sb[0] ? 0 : !sb[1] ? 1 : 2;
        P a0 = A[ia], a1 = A[(ia + 1) % 3], a2 = A[(ia + 2) % 3];
        if (orient3d(a0, a1, a2, B[ib]) != 0)
            return 0;
        int k0, k1;
        keep_axes(a0, a1, a2, &k0, &k1);
        double u0[2], u1[2], u2[2], w0[2];
        proj(a0, k0, k1, u0);
        proj(a1, k0, k1, u1);
        proj(a2, k0, k1, u2);
        proj(B[ib], k0, k1, w0);
        return orient2d(u1, u2, u0) * orient2d(u1, u2, w0) > 0;
    }
    return 1; /* the same three vertices: the faces coincide */
}

/* ---- the broad phase ---- */

static inline uint64_t cell_hash(int64_t x, int64_t y, int64_t z) {
    uint64_t h = (uint64_t)x * 0x9E3779B97F4A7C15ULL;
    h ^= (uint64_t)y * 0xC2B2AE3D27D4EB4FULL + (h << 6) + (h >> 2);
    h ^= (uint64_t)z * 0x165667B19E3779F9ULL + (h << 6) + (h >> 2);
    return h ^ (h >> 29);
}

typedef struct {
    int64_t *data;
    Py_ssize_t n, cap;
} Out;

static int push(Out *o, int64_t a, int64_t b) {
    if (o->n + 2 > o->cap) {
        Py_ssize_t cap = o->cap ? 2 * o->cap : 1024;
        int64_t *d = realloc(o->data, cap * sizeof(int64_t));
        if (!d)
            return -1;
        o->data = d;
        o->cap = cap;
    }
    o->data[o->n++] = a;
    o->data[o->n++] = b;
    return 0;
}

/* The grid: cell (i, j, k) is [origin + (i, j, k) h, origin + (i + 1, j + 1, k + 1) h]; a coordinate's
 * cell index is floor((x − origin) / h) as computed (monotone in x). A face lies in the cells of its
 * box, sliced across its longest box axis ``axis``: in slab s of that axis, only the cells of the box
 * of the triangle's part in the slab grown by ``slack`` (``rng``: 4 cell indices per slab, the two
 * other axes in cyclic order), so a long needle does not fill its box. Every point of the triangle
 * lies, as computed, in one of its cells (the slack exceeds the rounding). */
typedef struct {
    const double *v;
    const int64_t *f;
    double origin[3], h, slack;
    double *lo, *hi;      /* face boxes (F, 3) */
    int64_t *clo, *chi;   /* their cell ranges (F, 3) */
    int8_t *axis;         /* slab axis per face */
    int64_t *off;         /* first slab row of each face in rng */
    int64_t *rng;         /* (slabs, 4) */
    int64_t *cells;       /* cells per face */
    uint8_t *boxed;       /* the face lies in every cell of its box (at most 3 cells along each axis) */
} Grid;

typedef struct { /* a face of a bucket, copied beside the others */
    double lo[3], hi[3];
    int64_t clo[3];
    int32_t face;
    uint8_t fresh, kind; /* kind 0: in one cell; 1: boxed; 2: sliced */
} Local;

static inline int64_t cell_of(const Grid *g, double x, int k) { return (int64_t)floor((x - g->origin[k]) / g->h); }

/* cell ranges of face i's part in slab s (its cell index along its axis) into r[4] */
static void slab_ranges(const Grid *g, Py_ssize_t i, int64_t s, int64_t *r) {
    int d = g->axis[i], e1 = (d + 1) % 3, e2 = (d + 2) % 3;
    const int64_t *t = g->f + 3 * i;
    double a = g->origin[d] + (double)s * g->h - g->slack, b = g->origin[d] + (double)(s + 1) * g->h + g->slack;
    double m1 = INFINITY, M1 = -INFINITY, m2 = INFINITY, M2 = -INFINITY;
    for (int k = 0; k < 3; k++) {
        const double *p = g->v + 3 * t[k], *q = g->v + 3 * t[(k + 1) % 3];
        if (p[d] >= a && p[d] <= b) {
            m1 = fmin(m1, p[e1]), M1 = fmax(M1, p[e1]), m2 = fmin(m2, p[e2]), M2 = fmax(M2, p[e2]);
        }
        double c[2] = {a, b};
        for (int j = 0; j < 2; j++)
            if ((p[d] - c[j]) * (q[d] - c[j]) < 0.0) { /* the edge crosses the slab's plane */
                double u = (c[j] - p[d]) / (q[d] - p[d]);
                double y = p[e1] + u * (q[e1] - p[e1]), z = p[e2] + u * (q[e2] - p[e2]);
                m1 = fmin(m1, y), M1 = fmax(M1, y), m2 = fmin(m2, z), M2 = fmax(M2, z);
            }
    }
    const int64_t *lo = g->clo + 3 * i, *hi = g->chi + 3 * i;
    if (!(m1 <= M1) || !(m2 <= M2)) { /* nothing found (cannot happen): the whole box */
        r[0] = lo[e1], r[1] = hi[e1], r[2] = lo[e2], r[3] = hi[e2];
        return;
    }
    int64_t x;
    r[0] = (x = cell_of(g, m1 - g->slack, e1)) > lo[e1] ? x : lo[e1];
    r[1] = (x = cell_of(g, M1 + g->slack, e1)) < hi[e1] ? x : hi[e1];
    r[2] = (x = cell_of(g, m2 - g->slack, e2)) > lo[e2] ? x : lo[e2];
    r[3] = (x = cell_of(g, M2 + g->slack, e2)) < hi[e2] ? x : hi[e2];
}

/* face i lies in cell c */
static inline int member(const Grid *g, int64_t i, const int64_t *c) {
    int d = g->axis[i];
    int64_t s = c[d] - g->clo[3 * i + d];
    if (s < 0 || c[d] > g->chi[3 * i + d])
        return 0;
    const int64_t *r = g->rng + 4 * (g->off[i] + s);
    int64_t y = c[(d + 1) % 3], z = c[(d + 2) % 3];
    return y >= r[0] && y <= r[1] && z >= r[2] && z <= r[3];
}

/* the first cell of face a (in its slab order) inside face b's box range that face b lies in,
 * into c; 0 if none */
static int first_common(const Grid *g, int64_t a, int64_t b, int64_t *c) {
    int d = g->axis[a], e1 = (d + 1) % 3, e2 = (d + 2) % 3;
    const int64_t *bl = g->clo + 3 * b, *bh = g->chi + 3 * b;
    int64_t s0 = g->clo[3 * a + d] > bl[d] ? g->clo[3 * a + d] : bl[d];
    int64_t s1 = g->chi[3 * a + d] < bh[d] ? g->chi[3 * a + d] : bh[d];
    for (int64_t s = s0; s <= s1; s++) {
        const int64_t *r = g->rng + 4 * (g->off[a] + s - g->clo[3 * a + d]);
        int64_t y0 = r[0] > bl[e1] ? r[0] : bl[e1], y1 = r[1] < bh[e1] ? r[1] : bh[e1];
        int64_t z0 = r[2] > bl[e2] ? r[2] : bl[e2], z1 = r[3] < bh[e2] ? r[3] : bh[e2];
        c[d] = s;
        for (int64_t y = y0; y <= y1; y++)
            for (int64_t z = z0; z <= z1; z++) {
                c[e1] = y, c[e2] = z;
                if (member(g, b, c))
                    return 1;
            }
    }
    return 0;
}

static inline uint64_t spread(uint64_t x) { /* 21 bits to every third of 63 */
    x &= 0x1FFFFF;
    x = (x | x << 32) & 0x1F00000000FFFFULL;
    x = (x | x << 16) & 0x1F0000FF0000FFULL;
    x = (x | x << 8) & 0x100F00F00F00F00FULL;
    x = (x | x << 4) & 0x10C30C30C30C30C3ULL;
    x = (x | x << 2) & 0x1249249249249249ULL;
    return x;
}

static int by_key(const void *p, const void *q) {
    uint64_t a = ((const uint64_t *)p)[0], b = ((const uint64_t *)q)[0];
    return (a > b) - (a < b);
}

static int by_low_x(const void *p, const void *q) {
    double a = ((const Local *)p)->lo[0], b = ((const Local *)q)->lo[0];
    return (a > b) - (a < b);
}

/* a face with three distinct corners that are not collinear (exact: a projection of its area is not 0) */
static int has_area(const double *v, const int64_t *t) {
    if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0])
        return 0;
    for (int k = 0; k < 3; k++) {
        int i = k, j = (k + 1) % 3;
        double a[2] = {v[3 * t[0] + i], v[3 * t[0] + j]}, b[2] = {v[3 * t[1] + i], v[3 * t[1] + j]};
        double c[2] = {v[3 * t[2] + i], v[3 * t[2] + j]};
        if (orient2d(a, b, c) != 0)
            return 1;
    }
    return 0;
}

/* one worker's buckets [h0, h1): every pair of faces tested once (see find_pairs) */
typedef struct {
    const Grid *g;
    const double *v;
    const int64_t *f, *orig;
    const uint8_t *fresh; /* NULL: every face fresh; with ``apart``, each face's side (0 or 1) */
    int apart;            /* only pairs of faces on different sides */
    const int32_t *entries;
    const int64_t *start;
    uint64_t nb, h0, h1;
    Out out;
    long long exact;
    int status;
} Sweep;

static void *sweep(void *arg) {
    Sweep *job = arg;
    const Grid *gp = job->g;
    const double *v = job->v;
    const int64_t *f = job->f, *orig = job->orig, *start = job->start;
    const int32_t *entries = job->entries;
    const uint8_t *fresh0 = job->fresh;
    uint64_t nb = job->nb;
    Out *out = &job->out;
    Local *local = NULL;
    int64_t cap = 0;
    exact_calls = 0;
    for (uint64_t h = job->h0; h < job->h1; h++) {
        const int32_t *e = entries + start[h];
        int64_t k = start[h + 1] - start[h];
        if (k < 2)
            continue;
        if (fresh0) { /* a bucket without a fresh face (or with faces of one side only) holds no pair */
            int any = 0;
            for (int64_t i = 0; i < k && !any; i++)
                any = job->apart ? fresh0[e[i]] != fresh0[e[0]] : fresh0[e[i]];
            if (!any)
                continue;
        }
        if (k > cap) {
            free(local);
            cap = 2 * k;
            if (!(local = malloc(cap * sizeof(Local))))
                goto done;
        }
        for (int64_t i = 0; i < k; i++) { /* the bucket's faces side by side */
            Local *l = local + i;
            int32_t a = e[i];
            memcpy(l->lo, gp->lo + 3 * a, 3 * sizeof(double));
            memcpy(l->hi, gp->hi + 3 * a, 3 * sizeof(double));
            l->face = a;
            l->fresh = fresh0 ? fresh0[a] : 1;
            l->kind = gp->cells[a] == 1 ? 0 : gp->boxed[a] ? 1 : 2;
            for (int q = 0; q < 3; q++)
                l->clo[q] = gp->clo[3 * a + q];
        }
        qsort(local, k, sizeof(Local), by_low_x); /* sweep along x */
        for (int64_t i = 0; i < k; i++) {
            const Local *A = local + i;
            for (int64_t j = i + 1; j < k && local[j].lo[0] <= A->hi[0]; j++) {
                const Local *B = local + j;
                if (A->lo[1] > B->hi[1] || B->lo[1] > A->hi[1] ||
                    A->lo[2] > B->hi[2] || B->lo[2] > A->hi[2] ||
                    (job->apart ? A->fresh == B->fresh : !(A->fresh | B->fresh)))
                    continue;
                /* each pair once: a face in one cell is in one bucket; two boxed faces meet first in
                 * the corner of their boxes' intersection; else the bucket of the first cell both
                 * lie in, in the slab order of the face with fewer cells (the lower one on a tie) */
                if (A->kind && B->kind) {
                    int64_t c[3], a = A->face, b = B->face;
                    if (A->kind == 1 && B->kind == 1) {
                        for (int q = 0; q < 3; q++)
                            c[q] = A->clo[q] > B->clo[q] ? A->clo[q] : B->clo[q];
                    } else {
                        int64_t scan = gp->cells[b] < gp->cells[a] || (gp->cells[b] == gp->cells[a] && b < a) ? b : a;
                        if (!first_common(gp, scan, scan == a ? b : a, c))
                            continue;
                    }
                    if ((cell_hash(c[0], c[1], c[2]) & (nb - 1)) != h)
                        continue;
                }
                int32_t a = A->face, b = B->face;
                int first = orig[a] < orig[b];
                if (pair_hit(v, f + 3 * (first ? a : b), f + 3 * (first ? b : a)) &&
                    push(out, first ? orig[a] : orig[b], first ? orig[b] : orig[a]) < 0)
                    goto done;
            }
        }
    }
    job->status = 0;
done:
    job->exact = exact_calls;
    free(local);
    return NULL;
}

/* The intersecting pairs (i < j) of the faces f (F, 3) of the vertices v (V, 3), only pairs with
 * a fresh face when ``fresh``; faces without area (``has_area``) are left out. The faces are
 * renumbered in Morton order of their boxes' cells (neighbours near in memory). -1: out of memory. */
static int find_pairs(const double *v, const int64_t *f0, Py_ssize_t nf0, const uint8_t *fresh0, int apart,
                      double cell, int workers, Out *out) {
    exact_calls = 0;
    Grid g = {v, NULL, {INFINITY, INFINITY, INFINITY}, cell, 0.0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL};
    int64_t *orig = malloc((nf0 + 1) * sizeof(int64_t)), *f = NULL;
    uint64_t *keys = NULL;
    uint8_t *fresh = NULL;
    int32_t *last = NULL, *entries = NULL;
    int64_t *start = NULL;
    int status = -1;
    Py_ssize_t nf = 0;
    if (!orig)
        goto done;
    for (Py_ssize_t i = 0; i < nf0; i++)
        if (has_area(v, f0 + 3 * i))
            orig[nf++] = i;
    g.lo = malloc((nf + 1) * 3 * sizeof(double));
    g.hi = malloc((nf + 1) * 3 * sizeof(double));
    g.clo = malloc((nf + 1) * 3 * sizeof(int64_t));
    g.chi = malloc((nf + 1) * 3 * sizeof(int64_t));
    g.axis = malloc(nf + 1);
    g.off = malloc((nf + 1) * sizeof(int64_t));
    g.cells = malloc((nf + 1) * sizeof(int64_t));
    keys = malloc((nf + 1) * 2 * sizeof(uint64_t));
    f = malloc((nf + 1) * 3 * sizeof(int64_t));
    fresh = malloc(nf + 1);
    g.boxed = malloc(nf + 1);
    if (!g.boxed || !g.cells || !g.lo || !g.hi || !g.clo || !g.chi || !g.axis || !g.off || !keys || !f || !fresh)
        goto done;
    double big = 0.0;
    for (Py_ssize_t i = 0; i < nf; i++) {
        const int64_t *t = f0 + 3 * orig[i];
        for (int k = 0; k < 3; k++) {
            double x = v[3 * t[0] + k], y = v[3 * t[1] + k], z = v[3 * t[2] + k];
            double l = fmin(x, fmin(y, z)), u = fmax(x, fmax(y, z));
            g.origin[k] = fmin(g.origin[k], l);
            big = fmax(big, fmax(fabs(l), fabs(u)));
        }
    }
    /* cells of at least 2^-29 of the coordinates (cell indices fit 31 bits), doubled until the faces
     * lie in at most MAX_ENTRIES cells each on average (fine cells: few faces per cell, but faces in
     * many cells; coarse: the reverse) */
    g.h = fmax(cell, big * 0x1p-29);
    for (Py_ssize_t i = 0; i < nf; i++) { /* Morton order of the boxes' low cells */
        const int64_t *t = f0 + 3 * orig[i];
        uint64_t key = 0;
        for (int k = 0; k < 3; k++) {
            double l = fmin(v[3 * t[0] + k], fmin(v[3 * t[1] + k], v[3 * t[2] + k]));
            key |= spread((uint64_t)cell_of(&g, l, k)) << k;
        }
        keys[2 * i] = key;
        keys[2 * i + 1] = (uint64_t)orig[i];
    }
    qsort(keys, nf, 2 * sizeof(uint64_t), by_key);
    for (Py_ssize_t i = 0; i < nf; i++) {
        orig[i] = (int64_t)keys[2 * i + 1];
        memcpy(f + 3 * i, f0 + 3 * orig[i], 3 * sizeof(int64_t));
        fresh[i] = fresh0 ? fresh0[orig[i]] : 1;
        for (int k = 0; k < 3; k++) {
            const int64_t *t = f + 3 * i;
            double x = v[3 * t[0] + k], y = v[3 * t[1] + k], z = v[3 * t[2] + k];
            g.lo[3 * i + k] = fmin(x, fmin(y, z));
            g.hi[3 * i + k] = fmax(x, fmax(y, z));
        }
    }
    g.f = f;
    free(keys);
    keys = NULL;
    int64_t slabs, total, limit = MAX_ENTRIES * (int64_t)nf + 1024;
    for (;;) {
        g.slack = 1e-6 * g.h; /* far above the rounding of the slabs' clipping, of order 1e-16 (h + big) */
        slabs = 0;
        for (Py_ssize_t i = 0; i < nf; i++) {
            double ext = -1.0;
            for (int k = 0; k < 3; k++) {
                g.clo[3 * i + k] = cell_of(&g, g.lo[3 * i + k], k);
                g.chi[3 * i + k] = cell_of(&g, g.hi[3 * i + k], k);
                if (g.hi[3 * i + k] - g.lo[3 * i + k] > ext) {
                    ext = g.hi[3 * i + k] - g.lo[3 * i + k];
                    g.axis[i] = (int8_t)k;
                }
            }
            g.off[i] = slabs;
            slabs += g.chi[3 * i + g.axis[i]] - g.clo[3 * i + g.axis[i]] + 1;
        }
        if (slabs > limit) { /* every slab holds a cell at least */
            g.h *= 2.0;
            continue;
        }
        free(g.rng);
        g.rng = malloc((slabs + 1) * 4 * sizeof(int64_t));
        if (!g.rng)
            goto done;
        total = 0;
        for (Py_ssize_t i = 0; i < nf; i++) {
            int d = g.axis[i];
            int64_t *r = g.rng + 4 * g.off[i];
            g.cells[i] = 0;
            g.boxed[i] = 1;
            for (int k = 0; k < 3; k++)
                g.boxed[i] &= g.chi[3 * i + k] - g.clo[3 * i + k] < 3;
            for (int64_t s = g.clo[3 * i + d]; s <= g.chi[3 * i + d]; s++, r += 4) {
                if (g.boxed[i]) { /* the box */
                    r[0] = g.clo[3 * i + (d + 1) % 3], r[1] = g.chi[3 * i + (d + 1) % 3];
                    r[2] = g.clo[3 * i + (d + 2) % 3], r[3] = g.chi[3 * i + (d + 2) % 3];
                } else {
                    slab_ranges(&g, i, s, r);
                }
                g.cells[i] += (r[1] - r[0] + 1) * (r[3] - r[2] + 1);
                if (total + g.cells[i] > limit)
                    break;
            }
            total += g.cells[i];
            if (total > limit)
                break;
        }
        if (total <= limit)
            break;
        g.h *= 2.0;
    }
    uint64_t nb = 1024;
    while (nb < (uint64_t)total)
        nb <<= 1;
    last = malloc(nb * sizeof(int32_t));
    start = calloc(nb + 1, sizeof(int64_t));
    if (!last || !start)
        goto done;
    /* counting sort of (bucket, face), each face once per bucket (faces come in increasing order) */
    for (int pass = 0; pass < 2; pass++) {
        memset(last, 0xff, nb * sizeof(int32_t));
        for (Py_ssize_t i = 0; i < nf; i++) {
            int d = g.axis[i], e1 = (d + 1) % 3, e2 = (d + 2) % 3;
            int64_t c[3];
            for (int64_t s = g.clo[3 * i + d]; s <= g.chi[3 * i + d]; s++) {
                const int64_t *r = g.rng + 4 * (g.off[i] + s - g.clo[3 * i + d]);
                c[d] = s;
                for (int64_t y = r[0]; y <= r[1]; y++)
                    for (int64_t z = r[2]; z <= r[3]; z++) {
                        c[e1] = y, c[e2] = z;
                        uint64_t h = cell_hash(c[0], c[1], c[2]) & (nb - 1);
                        if (last[h] == (int32_t)i)
                            continue;
                        last[h] = (int32_t)i;
                        if (pass == 0)
                            start[h + 1]++;
                        else
                            entries[start[h]++] = (int32_t)i;
                    }
            }
        }
        if (pass == 0) {
            for (uint64_t h = 0; h < nb; h++)
                start[h + 1] += start[h];
            entries = malloc((start[nb] ? start[nb] : 1) * sizeof(int32_t));
            if (!entries)
                goto done;
        } else { /* start[h] moved to the end of bucket h: shift back */
            memmove(start + 1, start, nb * sizeof(int64_t));
            start[0] = 0;
        }
    }
    free(last);
    last = NULL;
    if (workers < 1)
        workers = 1;
    if (workers > MAX_WORKERS)
        workers = MAX_WORKERS;
    Sweep jobs[MAX_WORKERS];
    pthread_t threads[MAX_WORKERS];
    int started[MAX_WORKERS] = {0};
    uint64_t h0 = 0;
    for (int t = 0; t < workers; t++) { /* bucket ranges of about equal entries */
        uint64_t h1 = h0;
        int64_t goal = start[nb] * (t + 1) / workers;
        while (h1 < nb && (t == workers - 1 || start[h1] < goal))
            h1++;
        jobs[t] = (Sweep){&g, v, f, orig, fresh0 ? fresh : NULL, apart && fresh0, entries, start, nb, h0, h1,
                          {NULL, 0, 0}, 0, -1};
        h0 = h1;
    }
    long long exact = exact_calls; /* faces without area; sweep counts anew in this thread */
    for (int t = 1; t < workers; t++)
        started[t] = pthread_create(&threads[t], NULL, sweep, &jobs[t]) == 0;
    sweep(&jobs[0]);
    for (int t = 1; t < workers; t++)
        if (!started[t])
            sweep(&jobs[t]); /* no thread: here */
        else
            pthread_join(threads[t], NULL);
    int ok = 1;
    for (int t = 0; t < workers; t++) {
        exact += jobs[t].exact;
        ok &= jobs[t].status == 0;
        for (Py_ssize_t i = 0; ok && i < jobs[t].out.n; i += 2)
            ok = push(out, jobs[t].out.data[i], jobs[t].out.data[i + 1]) == 0;
        free(jobs[t].out.data);
    }
    exact_calls = exact;
    if (!ok)
        goto done;
    status = 0;
done:
    free(orig);
    free(f);
    free(keys);
    free(fresh);
    free(g.lo);
    free(g.hi);
    free(g.clo);
    free(g.chi);
    free(g.axis);
    free(g.off);
    free(g.rng);
    free(g.cells);
    free(g.boxed);
    free(last);
    free(start);
    free(entries);
    return status;
}

/* ---- Python ---- */

static int take(PyObject *o, Py_buffer *b, char kind, Py_ssize_t per, const char *what) {
    if (PyObject_GetBuffer(o, b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    const char *fmt = b->format[0] == '<' || b->format[0] == '=' ? b->format + 1 : b->format;
    int ok = fmt[1] == 0 && (kind == 'd'   ? fmt[0] == 'd' && b->itemsize == 8
                             : kind == 'q' ? strchr("qlQL", fmt[0]) && b->itemsize == 8
                                           : strchr("B?", fmt[0]) && b->itemsize == 1);
    if (!ok || b->len % (per * b->itemsize)) {
        PyErr_Format(PyExc_TypeError, "%s: wrong dtype or shape", what);
        PyBuffer_Release(b);
        return -1;
    }
    return 0;
}

/* pairs(vertices float64 (V, 3), faces int64 (F, 3), fresh bool (F,) or None, cell, workers=1, apart=0) ->
 * (bytes of int64 pairs (i < j) in no particular order, number of predicates decided by the exact
 * form); ``workers`` threads test the buckets (the same pairs for any number). With ``apart``,
 * ``fresh`` is each face's side (0 or 1) and only pairs of faces on different sides are tested */
static PyObject *pairs(PyObject *self, PyObject *args) {
    PyObject *ov, *of, *ofr;
    double cell;
    int workers = 1, apart = 0;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOd|ii", &ov, &of, &ofr, &cell, &workers, &apart))
        return NULL;
    Py_buffer bv, bf, bfr;
    if (take(ov, &bv, 'd', 3, "vertices") < 0)
        return NULL;
    if (take(of, &bf, 'q', 3, "faces") < 0) {
        PyBuffer_Release(&bv);
        return NULL;
    }
    int has_fresh = ofr != Py_None;
    if (has_fresh && take(ofr, &bfr, 'B', 1, "fresh") < 0) {
        PyBuffer_Release(&bv);
        PyBuffer_Release(&bf);
        return NULL;
    }
    Py_ssize_t nv = bv.len / 24, nf = bf.len / 24;
    const int64_t *f = bf.buf;
    int bad = (has_fresh && bfr.len != nf) || !(cell > 0.0) || !isfinite(cell) || nf >= INT32_MAX;
    for (Py_ssize_t i = 0; i < 3 * nf && !bad; i++)
        bad = f[i] < 0 || f[i] >= nv;
    PyObject *res = NULL;
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "pairs: a face index out of range, fresh of another length, or a bad cell");
    } else {
        Out out = {NULL, 0, 0};
        int status;
        long long exact;
        Py_BEGIN_ALLOW_THREADS
        status = find_pairs(bv.buf, f, nf, has_fresh ? bfr.buf : NULL, apart, cell, workers, &out);
        exact = exact_calls;
        Py_END_ALLOW_THREADS
        if (status < 0)
            PyErr_NoMemory();
        else
            res = Py_BuildValue("y#L", (const char *)(out.data ? out.data : (int64_t *)""),
                                out.n * (Py_ssize_t)sizeof(int64_t), exact);
        free(out.data);
    }
    PyBuffer_Release(&bv);
    PyBuffer_Release(&bf);
    if (has_fresh)
        PyBuffer_Release(&bfr);
    return res;
}

/* orient3d(a, b, c, d: float64 (N, 3) each) -> bytes of N int8 signs (the filtered, exact predicate) */
static PyObject *signs3(PyObject *self, PyObject *args) {
    PyObject *o[4];
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOO", &o[0], &o[1], &o[2], &o[3]))
        return NULL;
    Py_buffer b[4];
    int held = 0;
    for (; held < 4; held++)
        if (take(o[held], &b[held], 'd', 3, "points") < 0)
            break;
    PyObject *res = NULL;
    if (held == 4) {
        Py_ssize_t n = b[0].len / 24;
        if (b[1].len / 24 != n || b[2].len / 24 != n || b[3].len / 24 != n) {
            PyErr_SetString(PyExc_ValueError, "orient3d: point arrays of different lengths");
        } else if ((res = PyBytes_FromStringAndSize(NULL, n))) {
            int8_t *s = (int8_t *)PyBytes_AS_STRING(res);
            const double *a = b[0].buf, *bb = b[1].buf, *c = b[2].buf, *d = b[3].buf;
            for (Py_ssize_t i = 0; i < n; i++)
                s[i] = (int8_t)orient3d_exact(a + 3 * i, bb + 3 * i, c + 3 * i, d + 3 * i);
        }
    }
    for (int i = 0; i < held; i++)
        PyBuffer_Release(&b[i]);
    return res;
}

/* weld(points float64 (N, 3)) -> (inverse int64 (N,), first int64 (U,)): points with equal
 * coordinates (−0 equal to 0) get one id, ids numbered by first occurrence (a hash table) */
static PyObject *weld(PyObject *self, PyObject *args) {
    PyObject *o;
    (void)self;
    if (!PyArg_ParseTuple(args, "O", &o))
        return NULL;
    Py_buffer b;
    if (take(o, &b, 'd', 3, "points") < 0)
        return NULL;
    Py_ssize_t n = b.len / 24;
    const double *p = b.buf;
    PyObject *inv = PyBytes_FromStringAndSize(NULL, n * 8), *first = NULL, *res = NULL;
    uint64_t cap = 16;
    while (cap < 2 * (uint64_t)n)
        cap <<= 1;
    int64_t *table = malloc(cap * sizeof(int64_t)), *firsts = malloc((n + 1) * sizeof(int64_t));
    Py_ssize_t u = 0;
    if (!inv || !table || !firsts) {
        PyErr_NoMemory();
        goto out;
    }
    int64_t *iv = (int64_t *)PyBytes_AS_STRING(inv);
    Py_BEGIN_ALLOW_THREADS
    memset(table, 0xff, cap * sizeof(int64_t));
    for (Py_ssize_t i = 0; i < n; i++) {
        double x = p[3 * i] + 0.0, y = p[3 * i + 1] + 0.0, z = p[3 * i + 2] + 0.0; /* −0 + 0 = +0 */
        uint64_t k[3];
        memcpy(&k[0], &x, 8), memcpy(&k[1], &y, 8), memcpy(&k[2], &z, 8);
        uint64_t h = cell_hash((int64_t)k[0], (int64_t)k[1], (int64_t)k[2]) & (cap - 1);
        for (;; h = (h + 1) & (cap - 1)) {
            int64_t j = table[h];
            if (j < 0) {
                table[h] = u;
                firsts[u] = i;
                iv[i] = u++;
                break;
            }
            const double *q = p + 3 * firsts[j];
            if (q[0] == x && q[1] == y && q[2] == z) {
                iv[i] = j;
                break;
            }
        }
    }
    Py_END_ALLOW_THREADS
    first = PyBytes_FromStringAndSize((const char *)firsts, u * 8);
    if (first)
        res = PyTuple_Pack(2, inv, first);
out:
    Py_XDECREF(inv);
    Py_XDECREF(first);
    free(table);
    free(firsts);
    PyBuffer_Release(&b);
    return res;
}

/* flat(vertices float64 (V, 3), faces int64 (F, 3)) -> bytes of F bools: faces without area */
static PyObject *flat(PyObject *self, PyObject *args) {
    PyObject *ov, *of;
    (void)self;
    if (!PyArg_ParseTuple(args, "OO", &ov, &of))
        return NULL;
    Py_buffer bv, bf;
    if (take(ov, &bv, 'd', 3, "vertices") < 0)
        return NULL;
    if (take(of, &bf, 'q', 3, "faces") < 0) {
        PyBuffer_Release(&bv);
        return NULL;
    }
    Py_ssize_t nv = bv.len / 24, nf = bf.len / 24;
    const int64_t *f = bf.buf;
    PyObject *res = NULL;
    int bad = 0;
    for (Py_ssize_t i = 0; i < 3 * nf && !bad; i++)
        bad = f[i] < 0 || f[i] >= nv;
    if (bad)
        PyErr_SetString(PyExc_ValueError, "flat: a face index out of range");
    else if ((res = PyBytes_FromStringAndSize(NULL, nf))) {
        uint8_t *out = (uint8_t *)PyBytes_AS_STRING(res);
        for (Py_ssize_t i = 0; i < nf; i++)
            out[i] = !has_area(bv.buf, f + 3 * i);
    }
    PyBuffer_Release(&bv);
    PyBuffer_Release(&bf);
    return res;
}

static PyMethodDef methods[] = {
    {"pairs", pairs, METH_VARARGS,
     "pairs(vertices, faces, fresh, cell, workers=1, apart=0) -> (bytes of int64 (i, j): the intersecting face "
     "pairs, exact predicates); apart: fresh is each face's side, and only pairs across sides are tested."},
    {"weld", weld, METH_VARARGS, "weld(points) -> (bytes of int64 ids, bytes of int64 first rows): equal points merged."},
    {"flat", flat, METH_VARARGS, "flat(vertices, faces) -> bytes of bools: faces without area (exact)."},
    {"orient3d_exact", signs3, METH_VARARGS,
     "orient3d_exact(a, b, c, d) -> bytes of int8: exact signs by expansions (no filter)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_selfcheck", "Compiled self-intersection check.", -1,
                                    methods};

PyMODINIT_FUNC PyInit__selfcheck(void) { return PyModule_Create(&module); }
