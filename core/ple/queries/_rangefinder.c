/* RangeFinder BIQs of ple.queries, compiled: every query ball at once, decision for decision the
 * numpy forms, in three entry points.
 *
 * ``pullback`` (``pullback._query_numpy``): per query ball (in the lattice frame), the candidate
 * range of k by the W-map (§7.1.2, the query widened by the slab margin at the largest scale of
 * W**k); per k the query pulled back by the table row W**-k, kept if the clearance grid lets it
 * reach the base slab; the candidate range of j by the V-map of the pulled query; per j the
 * query pulled back by V**-j and, per template node, the candidate range of i by the U-map. The
 * exact tests run on those candidates in the frame of W**-k: ball-ball for nodes, and, with
 * beams, ball-cone-beam for the beams at every candidate node close enough (a beam found from
 * both ends counts once).
 *
 * ``u_path`` (the O(ū) path of §7.3.1, ``rangefinder._u_candidates`` then ``_exact``): per query
 * ball and U index i, the V and W candidate ranges of the i-sheet's group ball, the sheet
 * skipped when its distance band to a common axis misses the query's; per (j, k) in those
 * ranges, the group ball moved by W**k V**j tested against the query; then each element's own
 * V and W ranges, and the exact tests on elements placed by the cached powers of U, V and W.
 *
 * ``uv_path`` (the O(ūv̄) path of §7.3, ``rangefinder._uv_candidates`` then ``_exact``): per query
 * ball, blocks of W-rows whose bounding ball moved by W**k meets the query for some k of the
 * block's W range; in those, each W-row (i, j) whose group ball moved by W**k meets it, for k
 * in the row's range; then each element's own W range and the same exact tests.
 *
 * The same IEEE operations in the same order as the numpy forms' exact tests and pulls (built
 * with -ffp-contract=off: no fused multiply-adds), so the same hits come out. Candidate ranges
 * and culling tests may differ from numpy's in the last bit (libm against numpy's loops); all
 * are widened (RANGE_SLACK, the culling slack) and conservative either way, the exact tests
 * decide. Each query's hits come out sorted (i, j, k, n|pattern) and distinct, with per-query
 * ends. The GIL is released.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* one row map (rangefinder.RowMap) as packed by rangefinder.packed_map: MAP_WIDTH doubles */
enum {
    M_COUNT, M_HAS_T, M_A, M_OA = M_A + 3, M_NA, M_HAS_D, M_LOG_D, M_F, M_HAS_R = M_F + 3, M_THETA, M_AXIS,
    M_POINT = M_AXIS + 3, M_REF = M_POINT + 3, M_SIDE = M_REF + 3, M_PERIOD = M_SIDE + 3, MAP_WIDTH = 32
};
/* extents of one template: [t_s, t_e, d_s, d_e, r_s, r_e] */
enum { X_T = 0, X_D = 2, X_R = 4, EXT_WIDTH = 6 };
/* scalar parameters */
enum {
    P_H, P_HG, P_BEAM_REACH, P_WIDEN, P_TOUCH, P_SLACK, P_WRAPS, P_CLO, P_CHI = P_CLO + 3, P_CSIZE = P_CHI + 3, P_CSTEP,
    P_CSHAPE, NPARAM = P_CSHAPE + 3
};

typedef struct {
    int64_t *v;
    Py_ssize_t n, cap;
} Vec;

static int push(Vec *a, int64_t x) {
    if (a->n == a->cap) {
        Py_ssize_t cap = a->cap ? 2 * a->cap : 1024;
        int64_t *v = realloc(a->v, cap * sizeof(int64_t));
        if (!v)
            return -1;
        a->v = v;
        a->cap = cap;
    }
    a->v[a->n++] = x;
    return 0;
}

/* ---- extents and candidate ranges (rangefinder.ball_extents, candidate_range) ---- */

/* the R-frame of a point: its angle about the map's axis and its distance from it */
static void r_frame(const double *m, const double *c, double *dist, double *phi) {
    double rel[3] = {c[0] - m[M_POINT], c[1] - m[M_POINT + 1], c[2] - m[M_POINT + 2]};
    double along = rel[0] * m[M_AXIS] + rel[1] * m[M_AXIS + 1] + rel[2] * m[M_AXIS + 2];
    double perp[3] = {rel[0] - along * m[M_AXIS], rel[1] - along * m[M_AXIS + 1], rel[2] - along * m[M_AXIS + 2]};
    *dist = sqrt(perp[0] * perp[0] + perp[1] * perp[1] + perp[2] * perp[2]);
    double y = perp[0] * m[M_SIDE] + perp[1] * m[M_SIDE + 1] + perp[2] * m[M_SIDE + 2];
    double x = perp[0] * m[M_REF] + perp[1] * m[M_REF + 1] + perp[2] * m[M_REF + 2];
    *phi = atan2(y, x);
}

/* extents of the ball (c, r) under each map of m (those it has) */
static void ball_extents(const double *m, const double *c, double r, double *q) {
    if (m[M_HAS_T] != 0.0) {
        double x = c[0] * m[M_A] + c[1] * m[M_A + 1] + c[2] * m[M_A + 2];
        x -= m[M_OA];
        double w = r * m[M_NA];
        q[X_T] = x - w;
        q[X_T + 1] = x + w;
    }
    if (m[M_HAS_D] != 0.0) {
        double d[3] = {c[0] - m[M_F], c[1] - m[M_F + 1], c[2] - m[M_F + 2]};
        double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        double near = dist - r, far = dist + r;
        double a = (near > 0 ? log(near) : -INFINITY) / m[M_LOG_D], b = log(far) / m[M_LOG_D];
        q[X_D] = fmin(a, b);
        q[X_D + 1] = fmax(a, b);
    }
    if (m[M_HAS_R] != 0.0) {
        double dist, phi;
        r_frame(m, c, &dist, &phi);
        double mid = phi / m[M_THETA];
        if (dist <= r) { /* special case: the axis meets the ball, full range */
            q[X_R] = -INFINITY;
            q[X_R + 1] = INFINITY;
        } else {
            double s = r / dist;
            double h = asin(s < 0 ? 0 : (s > 1 ? 1 : s)) / fabs(m[M_THETA]);
            q[X_R] = mid - h;
            q[X_R + 1] = mid + h;
        }
    }
}

/* narrow [lo, hi] to the hull of its integers lying in some wrap [α + mP, β + mP] (§7.1.5) */
static void rotation_range(double period, int wraps, double alpha, double beta, double *lo, double *hi) {
    double l0 = *lo, h0 = *hi;
    if (!(isfinite(alpha) && isfinite(beta) && beta - alpha < period - 1e-12 && l0 <= h0))
        return;
    double new_lo = INFINITY, new_hi = -INFINITY, m = ceil((l0 - beta) / period);
    int todo = 1;
    for (int s = 0; s < wraps && todo; s++, m += 1) {
        double cand = fmax(l0, ceil(alpha + m * period));
        if (cand <= floor(beta + m * period)) {
            new_lo = cand;
            todo = 0;
        } else if (!(cand <= h0)) {
            todo = 0;
        }
    }
    if (todo)
        new_lo = l0; /* unresolved after many wraps: keep the conservative bound */
    m = floor((h0 - alpha) / period);
    todo = 1;
    for (int s = 0; s < wraps && todo; s++, m -= 1) {
        double cand = fmin(h0, floor(beta + m * period));
        if (cand >= ceil(alpha + m * period)) {
            new_hi = cand;
            todo = 0;
        } else if (!(cand >= l0)) {
            todo = 0;
        }
    }
    if (todo)
        new_hi = h0;
    if (!isfinite(new_lo) || !isfinite(new_hi)) {
        new_lo = 1.0;
        new_hi = 0.0;
    }
    *lo = new_lo;
    *hi = new_hi;
}

/* integer candidate range [lo, hi] of a row (empty when hi < lo) from template extents t and
 * query extents q (§7.1.2 theorem, §7.1.6); NaN gives no information (fmax / fmin) */
static void candidate_range(const double *m, const double *t, const double *q, double slack, int wraps, int64_t *lo,
                            int64_t *hi) {
    double l = 0.0, h = m[M_COUNT] - 1.0;
    for (int key = 0; key < 2; key++) {
        if (m[key == 0 ? M_HAS_T : M_HAS_D] == 0.0)
            continue;
        int x = key == 0 ? X_T : X_D;
        double a = q[x] - t[x + 1];
        a -= slack;
        l = fmax(l, ceil(a));
        double b = q[x + 1] - t[x];
        b += slack;
        h = fmin(h, floor(b));
    }
    if (m[M_HAS_R] != 0.0)
        rotation_range(m[M_PERIOD], wraps, q[X_R] - t[X_R + 1] - slack, q[X_R + 1] - t[X_R] + slack, &l, &h);
    l = fmin(l, m[M_COUNT]);
    h = fmax(h, -1.0);
    *lo = (int64_t)l;
    *hi = (int64_t)h;
}

/* ---- exact tests (algebra.elements) ---- */

/* S**-p applied to a point by its 3x4 row block: ((m0 x0 + m1 x1) + m2 x2) + m3 per row */
static inline void pull(const double *m, const double *x, double *y) {
    for (int a = 0; a < 3; a++)
        y[a] = m[4 * a] * x[0] + m[4 * a + 1] * x[1] + m[4 * a + 2] * x[2] + m[4 * a + 3];
}

/* does ball (q, rq) meet cone-beam hull(ball(a, ra), ball(b, rb))? (ball_beam_interfere) */
static int ball_beam(const double *p, double rq, const double *a, double ra, const double *b, double rb, double tol) {
    double ab[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double length = sqrt(ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]);
    double safe = length > 0 ? length : 1.0;
    double e[3] = {ab[0] / safe, ab[1] / safe, ab[2] / safe};
    double ap[3] = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    double x = ap[0] * e[0] + ap[1] * e[1] + ap[2] * e[2];
    double y = sqrt(fmax(ap[0] * ap[0] + ap[1] * ap[1] + ap[2] * ap[2] - x * x, 0.0));
    double s = (ra - rb) / safe;
    s = s < -1.0 ? -1.0 : (s > 1.0 ? 1.0 : s);
    double c = sqrt(1.0 - s * s);
    double u = c * x - s * y;
    double da = sqrt(x * x + y * y) - ra;
    double xl = x - length;
    double db = sqrt(xl * xl + y * y) - rb;
    double side = s * x + c * y - ra;
    double dist = u <= 0 ? da : (u >= c * length ? db : side);
    if (length + rb <= ra) /* special case: one ball contains the other, the hull is the bigger */
        dist = da;
    else if (length + ra <= rb)
        dist = db;
    double scale = fmax(fmax(ra, rb), rq);
    return dist <= rq + tol * scale;
}

static int cmp64(const void *a, const void *b) {
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* sort keys v[from:n) and drop repeats; returns the new n */
static Py_ssize_t sort_unique(int64_t *v, Py_ssize_t from, Py_ssize_t n) {
    if (n - from < 2)
        return n;
    if (n - from <= 16) { /* insertion sort: most queries have a few hits */
        for (Py_ssize_t i = from + 1; i < n; i++) {
            int64_t x = v[i];
            Py_ssize_t j = i;
            while (j > from && v[j - 1] > x) {
                v[j] = v[j - 1];
                j--;
            }
            v[j] = x;
        }
    } else {
        qsort(v + from, n - from, sizeof(int64_t), cmp64);
    }
    Py_ssize_t w = from + 1;
    for (Py_ssize_t i = from + 1; i < n; i++)
        if (v[i] != v[w - 1])
            v[w++] = v[i];
    return w;
}

/* a query's hits done: its node rows (from n0 on) and beam keys (from b0 on) sorted and distinct,
 * and where each list now ends */
static void end_query(Vec *nodes, Py_ssize_t n0, int64_t *node_end, Vec *bk, Py_ssize_t b0, int64_t *beam_end) {
    nodes->n = sort_unique(nodes->v, n0, nodes->n);
    bk->n = sort_unique(bk->v, b0, bk->n);
    *node_end = nodes->n;
    *beam_end = bk->n;
}

typedef struct {
    const double *maps, *ext_w, *ext_v, *ext_u, *w_rows, *w_fac, *v_rows, *v_fac, *slabs;
    const uint8_t *bound;
    const double *par;
    const int64_t *slot, *pats;
    int64_t nu, nv, nw, nn, np, reach; /* reach: largest |dk|, slot has 2 reach + 1 entries */
} Plan;

/* the ball (centre, radius) of node (i, j, n) of the base slab under W**d: 4 doubles */
static inline const double *slab_ball(const Plan *p, int64_t d, int64_t i, int64_t j, int64_t n) {
    return p->slabs + 4 * (((p->slot[d + p->reach] * p->nu + i) * p->nv + j) * p->nn + n);
}

/* a lower bound on the distance from y to the base slab's node centres (pullback._Clearance) */
static double clearance(const Plan *p, const double *y) {
    const double *par = p->par;
    int64_t cell[3];
    double d[3];
    for (int a = 0; a < 3; a++) {
        double f = floor((y[a] - par[P_CLO + a]) / par[P_CSIZE]);
        double top = par[P_CSHAPE + a] - 1.0;
        cell[a] = (int64_t)(f < 0 ? 0 : (f > top ? top : f));
        d[a] = y[a] - fmin(fmax(y[a], par[P_CLO + a]), par[P_CHI + a]);
    }
    double b = p->bound[(cell[0] * (int64_t)par[P_CSHAPE + 1] + cell[1]) * (int64_t)par[P_CSHAPE + 2] + cell[2]] *
               par[P_CSTEP];
    return sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + b * b);
}

/* the beams at candidate node (i, j, k, n), found in the frame of W**-k, against (y, rho) */
static int beams_at(const Plan *p, int64_t i, int64_t j, int64_t k, int64_t n, const double *y, double rho,
                    Vec *out) {
    const double tol = p->par[P_TOUCH];
    for (int64_t b = 0; b < p->np; b++) {
        const int64_t *pt = p->pats + 5 * b;
        int64_t n1 = pt[0], n2 = pt[1], di = pt[2], dj = pt[3], dk = pt[4];
        for (int at_from = 1; at_from >= 0; at_from--) {
            if (n != (at_from ? n1 : n2))
                continue;
            int64_t ai = at_from ? i : i - di, aj = at_from ? j : j - dj, ak = at_from ? k : k - dk;
            if (ai < 0 || ai + di < 0 || ai >= p->nu || ai + di >= p->nu || aj < 0 || aj + dj < 0 || aj >= p->nv ||
                aj + dj >= p->nv || ak < 0 || ak + dk < 0 || ak >= p->nw || ak + dk >= p->nw)
                continue;
            const double *a = slab_ball(p, at_from ? 0 : -dk, ai, aj, n1);
            const double *e = slab_ball(p, at_from ? dk : 0, ai + di, aj + dj, n2);
            if (ball_beam(y, rho, a, a[3], e, e[3], tol) &&
                push(out, (((ai * p->nv + aj) * p->nw + ak) * p->np) + b) < 0)
                return -1;
        }
    }
    return 0;
}

/* every query: node keys ((i nv + j) nw + k) nn + n and beam keys (... ) np + pattern, sorted and
 * distinct per query, with the end of each query's keys */
static int run(const Plan *p, const double *qc, const double *qr, Py_ssize_t nq, int beams, Vec *nodes,
               int64_t *node_end, Vec *bk, int64_t *beam_end) {
    const double *par = p->par;
    const double *mu = p->maps, *mv = p->maps + MAP_WIDTH, *mw = p->maps + 2 * MAP_WIDTH;
    const double widen = par[P_WIDEN], slack = par[P_SLACK], touch = par[P_TOUCH], h = par[P_H];
    const int wraps = (int)par[P_WRAPS];
    double qx[EXT_WIDTH];
    for (Py_ssize_t t = 0; t < nq; t++) {
        const double *c = qc + 3 * t;
        Py_ssize_t n0 = nodes->n, b0 = bk->n;
        int64_t klo, khi;
        ball_extents(mw, c, (qr[t] + par[P_HG]) * widen, qx);
        candidate_range(mw, p->ext_w, qx, slack, wraps, &klo, &khi);
        /* The distance to the slab is 1-Lipschitz and W**-k moves the pulled centre by
         * |W**-(k+1) c - W**-k c| = s**-k |W**-1 c - c|: after a clearance looked up at k0, the
         * k whose centre lies within that clearance less the path travelled since are skipped. */
        double stride = 0.0, room = -INFINITY, travel = 0.0;
        if (klo <= khi && p->nw > 1) {
            double c1[3];
            pull(p->w_rows + 12, c, c1);
            double d0 = c1[0] - c[0], d1 = c1[1] - c[1], d2 = c1[2] - c[2];
            stride = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
        }
        for (int64_t k = klo; k <= khi; k++) {
            double rho = qr[t] * p->w_fac[k];
            double reach = (rho + h) * widen;
            if (k > klo)
                travel += stride * p->w_fac[k - 1];
            if (travel * widen + reach < room)
                continue;
            double y[3];
            pull(p->w_rows + 12 * k, c, y);
            room = clearance(p, y);
            travel = 0.0;
            if (!(room <= reach)) /* W**-k B misses the base slab */
                continue;
            int64_t jlo, jhi;
            ball_extents(mv, y, reach, qx);
            candidate_range(mv, p->ext_v, qx, slack, wraps, &jlo, &jhi);
            for (int64_t j = jlo; j <= jhi; j++) {
                double z[3];
                pull(p->v_rows + 12 * j, y, z);
                ball_extents(mu, z, reach * p->v_fac[j], qx);
                for (int64_t n = 0; n < p->nn; n++) {
                    int64_t ilo, ihi;
                    candidate_range(mu, p->ext_u + EXT_WIDTH * n, qx, slack, wraps, &ilo, &ihi);
                    for (int64_t i = ilo; i <= ihi; i++) {
                        const double *s = slab_ball(p, 0, i, j, n);
                        double d0 = s[0] - y[0], d1 = s[1] - y[1], d2 = s[2] - y[2];
                        double dist2 = d0 * d0 + d1 * d1 + d2 * d2;
                        double rr = rho + s[3];
                        if (dist2 <= rr * rr * (1 + touch) + touch * touch &&
                            push(nodes, ((i * p->nv + j) * p->nw + k) * p->nn + n) < 0)
                            return -1;
                        if (beams) {
                            double near = rho + par[P_BEAM_REACH];
                            if (dist2 <= near * near && beams_at(p, i, j, k, n, y, rho, bk) < 0)
                                return -1;
                        }
                    }
                }
            }
        }
        end_query(nodes, n0, node_end + t, bk, b0, beam_end + t);
    }
    return 0;
}

/* ---- the O(ū) path ---- */

/* The tables of the O(ū) and O(ūv̄) paths. O(ū): per U index i the group ball (gc, gr) of
 * (i, 0, 0) with its V and W extents (gext_v, gext_w) and each element's (ext_v, ext_w, (nu, E)).
 * O(ūv̄): per W-row (i, j) = row i nv + j its group ball and W extents (gc, gr, gext_w, ext_w);
 * blocks of W-rows with bounding balls (kc, kr), their W extents (kext) and rows (order[starts[b]
 * .. starts[b + 1]]). Both: cached powers of U, V, W (rows, fac, from -reach) and the template. */
typedef struct {
    const double *maps, *gext_v, *gext_w, *ext_v, *ext_w, *gc, *gr, *axis, *band, *rows[3], *fac[3], *tc, *tr, *par;
    const double *kc, *kr, *kext;
    const int64_t *pats, *order, *starts;
    int64_t nu, nv, nw, nn, np, reach, has_axis, nb;
} UPlan;

/* node (i, j, k, n) placed by the cached powers: W**k V**j U**i of template ball n */
static void place(const UPlan *p, const int64_t *ijk, int64_t n, double *c, double *r) {
    double x[3] = {p->tc[3 * n], p->tc[3 * n + 1], p->tc[3 * n + 2]};
    *r = p->tr[n];
    for (int a = 0; a < 3; a++) {
        int64_t row = ijk[a] + p->reach;
        pull(p->rows[a] + 12 * row, x, c);
        memcpy(x, c, sizeof(x));
        *r *= p->fac[a][row];
    }
}

/* the exact test of element e (node e < nn, else beam-pattern e - nn) of group (i, j, k) against
 * the query ball (c, rq); a hit's key goes to nodes or bk */
static int exact(const UPlan *p, int64_t i, int64_t j, int64_t k, int64_t e, const double *c, double rq, Vec *nodes,
                 Vec *bk) {
    const double touch = p->par[0];
    int64_t ijk[3] = {i, j, k};
    double ca[4], cb[4];
    if (e < p->nn) {
        place(p, ijk, e, ca, ca + 3);
        double e0 = ca[0] - c[0], e1 = ca[1] - c[1], e2 = ca[2] - c[2], rn = ca[3] + rq;
        if (e0 * e0 + e1 * e1 + e2 * e2 <= rn * rn * (1 + touch) + touch * touch)
            return push(nodes, ((i * p->nv + j) * p->nw + k) * p->nn + e);
        return 0;
    }
    const int64_t *pt = p->pats + 5 * (e - p->nn);
    int64_t to[3] = {i + pt[2], j + pt[3], k + pt[4]};
    if (to[0] < 0 || to[0] >= p->nu || to[1] < 0 || to[1] >= p->nv || to[2] < 0 || to[2] >= p->nw)
        return 0;
    place(p, ijk, pt[0], ca, ca + 3);
    place(p, to, pt[1], cb, cb + 3);
    if (ball_beam(c, rq, ca, ca[3], cb, cb[3], touch))
        return push(bk, ((i * p->nv + j) * p->nw + k) * p->np + (e - p->nn));
    return 0;
}

/* does the ball (x, r) moved by W**k meet the query ball (c, rq)? (the culling levels' test,
 * radius widened by 1e-9 relative and 1e-12) */
static int moved_meets(const UPlan *p, const double *x, double r, int64_t k, const double *c, double rq) {
    const double touch = p->par[0];
    double g[3];
    pull(p->rows[2] + 12 * (k + p->reach), x, g);
    double d0 = g[0] - c[0], d1 = g[1] - c[1], d2 = g[2] - c[2];
    double rr = r * p->fac[2][k + p->reach] * (1 + 1e-9) + 1e-12 + rq;
    return d0 * d0 + d1 * d1 + d2 * d2 <= rr * rr * (1 + touch) + touch * touch;
}

static int u_run(const UPlan *p, const double *qc, const double *qr, Py_ssize_t nq, Vec *nodes, int64_t *node_end,
                 Vec *bk, int64_t *beam_end) {
    const double *mv = p->maps + MAP_WIDTH, *mw = p->maps + 2 * MAP_WIDTH;
    const double touch = p->par[0], slack = p->par[1];
    const int wraps = (int)p->par[2];
    const int64_t ne = p->nn + p->np;
    int64_t *er = malloc(4 * (ne ? ne : 1) * sizeof(int64_t)); /* per element: V range, W range */
    if (!er)
        return -1;
    double qv[EXT_WIDTH], qw[EXT_WIDTH];
    for (Py_ssize_t t = 0; t < nq; t++) {
        const double *c = qc + 3 * t;
        Py_ssize_t n0 = nodes->n, b0 = bk->n;
        ball_extents(mv, c, qr[t], qv);
        ball_extents(mw, c, qr[t], qw);
        double rho = 0.0, qrr = qr[t] * (1 + 1e-9) + 1e-12;
        if (p->has_axis) {
            const double *pt = p->axis, *dir = p->axis + 3;
            double rel[3] = {c[0] - pt[0], c[1] - pt[1], c[2] - pt[2]};
            double along = rel[0] * dir[0] + rel[1] * dir[1] + rel[2] * dir[2];
            double d0 = rel[0] - along * dir[0], d1 = rel[1] - along * dir[1], d2 = rel[2] - along * dir[2];
            rho = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
        }
        for (int64_t i = 0; i < p->nu; i++) {
            if (p->has_axis && (rho + qrr < p->band[2 * i] * (1 - 1e-9) || rho - qrr > p->band[2 * i + 1] * (1 + 1e-9)))
                continue; /* the i-sheet's distance band to the common axis misses the query's */
            int64_t jlo, jhi, klo, khi;
            candidate_range(mv, p->gext_v + EXT_WIDTH * i, qv, slack, wraps, &jlo, &jhi);
            candidate_range(mw, p->gext_w + EXT_WIDTH * i, qw, slack, wraps, &klo, &khi);
            int ready = 0;
            for (int64_t j = jlo; j <= jhi; j++) {
                double gv[3];
                pull(p->rows[1] + 12 * (j + p->reach), p->gc + 3 * i, gv);
                for (int64_t k = klo; k <= khi; k++) {
                    double g[3];
                    pull(p->rows[2] + 12 * (k + p->reach), gv, g);
                    double gr = p->gr[i] * (p->fac[1][j + p->reach] * p->fac[2][k + p->reach]) * (1 + 1e-9) + 1e-12;
                    double d0 = g[0] - c[0], d1 = g[1] - c[1], d2 = g[2] - c[2], rr = gr + qr[t];
                    if (!(d0 * d0 + d1 * d1 + d2 * d2 <= rr * rr * (1 + touch) + touch * touch))
                        continue; /* the moved group ball misses the query */
                    for (int64_t e = 0; e < ne && !ready; e++) { /* each element's own ranges, once per i */
                        candidate_range(mv, p->ext_v + EXT_WIDTH * (i * ne + e), qv, slack, wraps, er + 4 * e,
                                        er + 4 * e + 1);
                        candidate_range(mw, p->ext_w + EXT_WIDTH * (i * ne + e), qw, slack, wraps, er + 4 * e + 2,
                                        er + 4 * e + 3);
                    }
                    ready = 1;
                    for (int64_t e = 0; e < ne; e++) {
                        const int64_t *x = er + 4 * e;
                        if (j >= x[0] && j <= x[1] && k >= x[2] && k <= x[3] &&
                            exact(p, i, j, k, e, c, qr[t], nodes, bk) < 0)
                            goto fail;
                    }
                }
            }
        }
        end_query(nodes, n0, node_end + t, bk, b0, beam_end + t);
    }
    free(er);
    return 0;
fail:
    free(er);
    return -1;
}

/* the O(ūv̄) path: blocks of W-rows culled by their moved bounding balls, then each W-row's group
 * ball, then each element's W range, then the exact tests (rangefinder._uv_candidates, _exact) */
static int uv_run(const UPlan *p, const double *qc, const double *qr, Py_ssize_t nq, Vec *nodes, int64_t *node_end,
                  Vec *bk, int64_t *beam_end) {
    const double *mw = p->maps + 2 * MAP_WIDTH;
    const double slack = p->par[1];
    const int wraps = (int)p->par[2];
    const int64_t ne = p->nn + p->np;
    int64_t *er = malloc(2 * (ne ? ne : 1) * sizeof(int64_t)); /* per element: W range */
    if (!er)
        return -1;
    double qw[EXT_WIDTH];
    for (Py_ssize_t t = 0; t < nq; t++) {
        const double *c = qc + 3 * t;
        Py_ssize_t n0 = nodes->n, b0 = bk->n;
        ball_extents(mw, c, qr[t], qw);
        for (int64_t b = 0; b < p->nb; b++) {
            int64_t lo, hi, k;
            candidate_range(mw, p->kext + EXT_WIDTH * b, qw, slack, wraps, &lo, &hi);
            for (k = lo; k <= hi; k++)
                if (moved_meets(p, p->kc + 3 * b, p->kr[b], k, c, qr[t]))
                    break;
            if (k > hi) /* W**k of the block's ball misses the query for every k in its range */
                continue;
            for (int64_t a = p->starts[b]; a < p->starts[b + 1]; a++) {
                int64_t row = p->order[a], i = row / p->nv, j = row % p->nv, ready = 0;
                candidate_range(mw, p->gext_w + EXT_WIDTH * row, qw, slack, wraps, &lo, &hi);
                for (k = lo; k <= hi; k++) {
                    if (!moved_meets(p, p->gc + 3 * row, p->gr[row], k, c, qr[t]))
                        continue;
                    if (!ready) { /* each element's own W range, once per row */
                        for (int64_t e = 0; e < ne; e++)
                            candidate_range(mw, p->ext_w + EXT_WIDTH * (row * ne + e), qw, slack, wraps, er + 2 * e,
                                            er + 2 * e + 1);
                        ready = 1;
                    }
                    for (int64_t e = 0; e < ne; e++)
                        if (k >= er[2 * e] && k <= er[2 * e + 1] && exact(p, i, j, k, e, c, qr[t], nodes, bk) < 0)
                            goto fail;
                }
            }
        }
        end_query(nodes, n0, node_end + t, bk, b0, beam_end + t);
    }
    free(er);
    return 0;
fail:
    free(er);
    return -1;
}

/* ---- Python ---- */

typedef struct {
    Py_buffer b;
    int held;
} Buf;

static int take(PyObject *o, Buf *buf, char kind, Py_ssize_t count, const char *what) {
    buf->held = 0;
    if (PyObject_GetBuffer(o, &buf->b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    buf->held = 1;
    const char *fmt = buf->b.format[0] == '<' || buf->b.format[0] == '=' ? buf->b.format + 1 : buf->b.format;
    int ok = fmt[1] == 0 && (kind == 'd'   ? fmt[0] == 'd' && buf->b.itemsize == 8
                             : kind == 'q' ? strchr("qlQL", fmt[0]) != NULL && buf->b.itemsize == 8
                                           : fmt[0] == 'B' && buf->b.itemsize == 1);
    if (!ok || (count >= 0 && buf->b.len != count * buf->b.itemsize)) {
        PyErr_Format(PyExc_TypeError, "%s: wrong dtype or size", what);
        return -1;
    }
    return 0;
}

/* the rows (i, j, k, x) of keys as a bytearray of int64 (m, 4) */
static PyObject *rows_of(const Vec *v, int64_t nv, int64_t nw, int64_t nx) {
    PyObject *out = PyByteArray_FromStringAndSize(NULL, v->n * 4 * (Py_ssize_t)sizeof(int64_t));
    if (!out)
        return NULL;
    int64_t *r = (int64_t *)PyByteArray_AS_STRING(out);
    for (Py_ssize_t a = 0; a < v->n; a++) {
        int64_t key = v->v[a];
        r[4 * a + 3] = key % nx;
        key /= nx;
        r[4 * a + 2] = key % nw;
        key /= nw;
        r[4 * a + 1] = key % nv;
        r[4 * a] = key / nv;
    }
    return out;
}

/* (node rows, node ends, beam rows, beam ends) of a finished run: the 4-tuple both entry points
 * return; frees the keys and the ends */
static PyObject *results(int status, Vec *nodes, Vec *bk, int64_t *ends, Py_ssize_t nq, int64_t nv, int64_t nw,
                         int64_t nn, int64_t np) {
    PyObject *res = NULL;
    if (status < 0) {
        PyErr_NoMemory();
    } else {
        PyObject *nr = rows_of(nodes, nv, nw, nn), *br = rows_of(bk, nv, nw, np ? np : 1);
        PyObject *ne = PyBytes_FromStringAndSize((const char *)ends, nq * (Py_ssize_t)sizeof(int64_t));
        PyObject *be = PyBytes_FromStringAndSize((const char *)(ends + nq), nq * (Py_ssize_t)sizeof(int64_t));
        if (nr && br && ne && be)
            res = PyTuple_Pack(4, nr, ne, br, be);
        Py_XDECREF(nr);
        Py_XDECREF(br);
        Py_XDECREF(ne);
        Py_XDECREF(be);
    }
    free(ends);
    free(nodes->v);
    free(bk->v);
    return res;
}

static void release_all(Buf *b, int n) {
    for (int a = 0; a < n; a++)
        if (b[a].held)
            PyBuffer_Release(&b[a].b);
}

/* the buffers of ``n`` arguments, each of kind kinds[a] ('d' float64, 'q' int64, 'B' uint8) and,
 * where sizes[a] >= 0, of that many items; -1 (and every buffer released) on error */
static int take_all(PyObject **o, Buf *b, int n, const char *kinds, const Py_ssize_t *sizes, const char **names) {
    memset(b, 0, n * sizeof(Buf));
    for (int a = 0; a < n; a++)
        if (take(o[a], &b[a], kinds[a], sizes[a], names[a]) < 0) {
            release_all(b, a + 1);
            return -1;
        }
    return 0;
}

/* pullback(counts (nu, nv, nw, nn), maps, ext_w, ext_v, ext_u, w_rows, w_fac, v_rows, v_fac, slabs, slot,
 *          bound, pats, params, qc, qr, beams) -> (node rows, node ends, beam rows, beam ends) */
static PyObject *pullback(PyObject *self, PyObject *args) {
    int64_t nu, nv, nw, nn;
    PyObject *o[15];
    int beams;
    (void)self;
    if (!PyArg_ParseTuple(args, "(LLLL)OOOOOOOOOOOOOOOp", &nu, &nv, &nw, &nn, &o[0], &o[1], &o[2], &o[3], &o[4],
                          &o[5], &o[6], &o[7], &o[8], &o[9], &o[10], &o[11], &o[12], &o[13], &o[14], &beams))
        return NULL;
    if (nu < 1 || nv < 1 || nw < 1 || nn < 1) {
        PyErr_SetString(PyExc_ValueError, "pullback: empty counts");
        return NULL;
    }
    Buf b[15];
    const char *names[15] = {"maps", "ext_w", "ext_v", "ext_u", "w_rows", "w_fac", "v_rows", "v_fac",
                             "slabs", "slot", "bound", "pats", "params", "qc", "qr"};
    Py_ssize_t sizes[15] = {3 * MAP_WIDTH, EXT_WIDTH, EXT_WIDTH, EXT_WIDTH * nn, 12 * nw, nw, 12 * nv, nv,
                            -1, -1, -1, -1, NPARAM, -1, -1};
    if (take_all(o, b, 15, "dddddddddqBqddd", sizes, names) < 0)
        return NULL;
    PyObject *res = NULL;
    Plan p = {b[0].b.buf, b[1].b.buf, b[2].b.buf, b[3].b.buf, b[4].b.buf, b[5].b.buf, b[6].b.buf, b[7].b.buf,
              b[8].b.buf, b[10].b.buf, b[12].b.buf, b[9].b.buf, b[11].b.buf, nu, nv, nw, nn,
              b[11].b.len / 40, (b[9].b.len / 8 - 1) / 2};
    Py_ssize_t nq = b[14].b.len / 8, slabs = b[8].b.len / (32 * nu * nv * nn);
    const double *par = p.par;
    Py_ssize_t cells = (Py_ssize_t)(par[P_CSHAPE] * par[P_CSHAPE + 1] * par[P_CSHAPE + 2]);
    int bad = b[13].b.len != 3 * nq * 8 || b[9].b.len % 16 != 8 || b[11].b.len % 40 != 0 ||
              b[8].b.len != slabs * 32 * nu * nv * nn || b[10].b.len != cells || !(par[P_CSIZE] > 0);
    for (int64_t s = 0; s < 2 * p.reach + 1 && !bad; s++)
        bad = p.slot[s] < -1 || p.slot[s] >= slabs;
    for (int64_t a = 0; a < p.np && !bad; a++) {
        const int64_t *pt = p.pats + 5 * a;
        bad = pt[0] < 0 || pt[0] >= nn || pt[1] < 0 || pt[1] >= nn || pt[4] < -p.reach || pt[4] > p.reach ||
              p.slot[p.reach + pt[4]] < 0 || p.slot[p.reach - pt[4]] < 0;
    }
    if (bad || p.slot[p.reach] < 0) {
        PyErr_SetString(PyExc_ValueError, "pullback: plan arrays of inconsistent sizes");
    } else {
        Vec nodes = {NULL, 0, 0}, bk = {NULL, 0, 0};
        int64_t *ends = malloc((2 * nq + 1) * sizeof(int64_t));
        int status = -1;
        if (ends) {
            Py_BEGIN_ALLOW_THREADS
            status = run(&p, b[13].b.buf, b[14].b.buf, nq, beams, &nodes, ends, &bk, ends + nq);
            Py_END_ALLOW_THREADS
        }
        res = results(status, &nodes, &bk, ends, nq, nv, nw, nn, p.np);
    }
    release_all(b, 15);
    return res;
}

/* u_path(counts (nu, nv, nw, nn), reach, maps, gext_v, gext_w, ext_v, ext_w, gc, gr, axis, band, u_rows, u_fac,
 *        v_rows, v_fac, w_rows, w_fac, tc, tr, pats, params, qc, qr) -> (node rows, node ends, beam rows,
 *        beam ends) */
static PyObject *u_path(PyObject *self, PyObject *args) {
    int64_t nu, nv, nw, nn, reach;
    PyObject *o[21];
    (void)self;
    if (!PyArg_ParseTuple(args, "(LLLL)LOOOOOOOOOOOOOOOOOOOOO", &nu, &nv, &nw, &nn, &reach, &o[0], &o[1], &o[2],
                          &o[3], &o[4], &o[5], &o[6], &o[7], &o[8], &o[9], &o[10], &o[11], &o[12], &o[13], &o[14],
                          &o[15], &o[16], &o[17], &o[18], &o[19], &o[20]))
        return NULL;
    if (nu < 1 || nv < 1 || nw < 1 || nn < 1 || reach < 0) {
        PyErr_SetString(PyExc_ValueError, "u_path: empty counts");
        return NULL;
    }
    Buf b[21];
    const char *names[21] = {"maps", "gext_v", "gext_w", "ext_v", "ext_w", "gc", "gr", "axis", "band", "u_rows",
                             "u_fac", "v_rows", "v_fac", "w_rows", "w_fac", "tc", "tr", "pats", "params", "qc", "qr"};
    Py_ssize_t sizes[21] = {3 * MAP_WIDTH, EXT_WIDTH * nu, EXT_WIDTH * nu, -1, -1, 3 * nu, nu, -1, -1,
                            12 * (nu + 2 * reach), nu + 2 * reach, 12 * (nv + 2 * reach), nv + 2 * reach,
                            12 * (nw + 2 * reach), nw + 2 * reach, 3 * nn, nn, -1, 3, -1, -1};
    if (take_all(o, b, 21, "dddddddddddddddddqddd", sizes, names) < 0)
        return NULL;
    PyObject *res = NULL;
    int64_t np = b[17].b.len / 40, ne = nn + np, has_axis = b[7].b.len == 6 * 8;
    Py_ssize_t nq = b[20].b.len / 8;
    const int64_t *pats = b[17].b.buf;
    int bad = b[17].b.len % 40 != 0 || b[3].b.len != EXT_WIDTH * nu * ne * 8 || b[4].b.len != b[3].b.len ||
              (has_axis ? b[8].b.len != 2 * nu * 8 : b[7].b.len != 0) || b[19].b.len != 3 * nq * 8;
    for (int64_t a = 0; a < np && !bad; a++) {
        const int64_t *pt = pats + 5 * a;
        bad = pt[0] < 0 || pt[0] >= nn || pt[1] < 0 || pt[1] >= nn;
        for (int x = 2; x < 5 && !bad; x++)
            bad = pt[x] < -reach || pt[x] > reach;
    }
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "u_path: plan arrays of inconsistent sizes");
    } else {
        UPlan p = {b[0].b.buf, b[1].b.buf, b[2].b.buf, b[3].b.buf, b[4].b.buf, b[5].b.buf, b[6].b.buf, b[7].b.buf,
                   b[8].b.buf, {b[9].b.buf, b[11].b.buf, b[13].b.buf}, {b[10].b.buf, b[12].b.buf, b[14].b.buf},
                   b[15].b.buf, b[16].b.buf, b[18].b.buf, NULL, NULL, NULL, pats, NULL, NULL, nu, nv, nw, nn, np,
                   reach, has_axis, 0};
        Vec nodes = {NULL, 0, 0}, bk = {NULL, 0, 0};
        int64_t *ends = malloc((2 * nq + 1) * sizeof(int64_t));
        int status = -1;
        if (ends) {
            Py_BEGIN_ALLOW_THREADS
            status = u_run(&p, b[19].b.buf, b[20].b.buf, nq, &nodes, ends, &bk, ends + nq);
            Py_END_ALLOW_THREADS
        }
        res = results(status, &nodes, &bk, ends, nq, nv, nw, nn, np);
    }
    release_all(b, 21);
    return res;
}

/* uv_path(counts (nu, nv, nw, nn), reach, maps, gext_w, ext_w, gc, gr, kc, kr, kext, order, starts, u_rows, u_fac,
 *         v_rows, v_fac, w_rows, w_fac, tc, tr, pats, params, qc, qr) -> (node rows, node ends, beam rows,
 *         beam ends) */
static PyObject *uv_path(PyObject *self, PyObject *args) {
    int64_t nu, nv, nw, nn, reach;
    PyObject *o[22];
    (void)self;
    if (!PyArg_ParseTuple(args, "(LLLL)LOOOOOOOOOOOOOOOOOOOOOO", &nu, &nv, &nw, &nn, &reach, &o[0], &o[1], &o[2],
                          &o[3], &o[4], &o[5], &o[6], &o[7], &o[8], &o[9], &o[10], &o[11], &o[12], &o[13], &o[14],
                          &o[15], &o[16], &o[17], &o[18], &o[19], &o[20], &o[21]))
        return NULL;
    if (nu < 1 || nv < 1 || nw < 1 || nn < 1 || reach < 0) {
        PyErr_SetString(PyExc_ValueError, "uv_path: empty counts");
        return NULL;
    }
    Buf b[22];
    const char *names[22] = {"maps", "gext_w", "ext_w", "gc", "gr", "kc", "kr", "kext", "order", "starts", "u_rows",
                             "u_fac", "v_rows", "v_fac", "w_rows", "w_fac", "tc", "tr", "pats", "params", "qc", "qr"};
    Py_ssize_t rows = nu * nv;
    Py_ssize_t sizes[22] = {3 * MAP_WIDTH, EXT_WIDTH * rows, -1, 3 * rows, rows, -1, -1, -1, rows, -1,
                            12 * (nu + 2 * reach), nu + 2 * reach, 12 * (nv + 2 * reach), nv + 2 * reach,
                            12 * (nw + 2 * reach), nw + 2 * reach, 3 * nn, nn, -1, 3, -1, -1};
    if (take_all(o, b, 22, "ddddddddqqddddddddqddd", sizes, names) < 0)
        return NULL;
    PyObject *res = NULL;
    int64_t np = b[18].b.len / 40, ne = nn + np, nb = b[6].b.len / 8;
    Py_ssize_t nq = b[21].b.len / 8;
    const int64_t *pats = b[18].b.buf, *order = b[8].b.buf, *starts = b[9].b.buf;
    int bad = b[18].b.len % 40 != 0 || b[2].b.len != EXT_WIDTH * rows * ne * 8 || b[5].b.len != 3 * nb * 8 ||
              b[7].b.len != EXT_WIDTH * nb * 8 || b[9].b.len != (nb + 1) * 8 || b[20].b.len != 3 * nq * 8 ||
              starts[0] != 0 || starts[nb] != rows;
    for (int64_t a = 0; a < nb && !bad; a++)
        bad = starts[a + 1] < starts[a];
    for (Py_ssize_t a = 0; a < rows && !bad; a++)
        bad = order[a] < 0 || order[a] >= rows;
    for (int64_t a = 0; a < np && !bad; a++) {
        const int64_t *pt = pats + 5 * a;
        bad = pt[0] < 0 || pt[0] >= nn || pt[1] < 0 || pt[1] >= nn;
        for (int x = 2; x < 5 && !bad; x++)
            bad = pt[x] < -reach || pt[x] > reach;
    }
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "uv_path: plan arrays of inconsistent sizes");
    } else {
        UPlan p = {b[0].b.buf, NULL, b[1].b.buf, NULL, b[2].b.buf, b[3].b.buf, b[4].b.buf, NULL, NULL,
                   {b[10].b.buf, b[12].b.buf, b[14].b.buf}, {b[11].b.buf, b[13].b.buf, b[15].b.buf}, b[16].b.buf,
                   b[17].b.buf, b[19].b.buf, b[5].b.buf, b[6].b.buf, b[7].b.buf, pats, order, starts, nu, nv, nw, nn,
                   np, reach, 0, nb};
        Vec nodes = {NULL, 0, 0}, bk = {NULL, 0, 0};
        int64_t *ends = malloc((2 * nq + 1) * sizeof(int64_t));
        int status = -1;
        if (ends) {
            Py_BEGIN_ALLOW_THREADS
            status = uv_run(&p, b[20].b.buf, b[21].b.buf, nq, &nodes, ends, &bk, ends + nq);
            Py_END_ALLOW_THREADS
        }
        res = results(status, &nodes, &bk, ends, nq, nv, nw, nn, np);
    }
    release_all(b, 22);
    return res;
}

static PyMethodDef methods[] = {
    {"pullback", pullback, METH_VARARGS,
     "pullback(counts, maps, ext_w, ext_v, ext_u, w_rows, w_fac, v_rows, v_fac, slabs, slot, bound, pats, params, "
     "qc, qr, beams) -> (node rows, node ends, beam rows, beam ends): the pulled-back BIQ of every query ball."},
    {"u_path", u_path, METH_VARARGS,
     "u_path(counts, reach, maps, gext_v, gext_w, ext_v, ext_w, gc, gr, axis, band, u_rows, u_fac, v_rows, v_fac, "
     "w_rows, w_fac, tc, tr, pats, params, qc, qr) -> (node rows, node ends, beam rows, beam ends): the O(u) path "
     "of every query ball."},
    {"uv_path", uv_path, METH_VARARGS,
     "uv_path(counts, reach, maps, gext_w, ext_w, gc, gr, kc, kr, kext, order, starts, u_rows, u_fac, v_rows, v_fac, "
     "w_rows, w_fac, tc, tr, pats, params, qc, qr) -> (node rows, node ends, beam rows, beam ends): the O(uv) path "
     "of every query ball."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_rangefinder", "Compiled RangeFinder BIQs.", -1,
                                    methods};

PyMODINIT_FUNC PyInit__rangefinder(void) { return PyModule_Create(&module); }
