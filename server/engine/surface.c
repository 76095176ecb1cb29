/*
 * surface.c — the surface mesh embedded in the cube mesh (seed 000 §2.1 Table 1, §3, §3.3).
 * Implements surface.h.
 *
 * Binding: a point goes to the cell floor((x - origin)/h); if that cell is not in the mesh, or
 * the point lies on its boundary, the neighbouring cells that contain it within tol are tried
 * (the floor cell first). tol is twice cs_voxel_tolerance (voxelize.h), so whatever
 * voxelization kept binds; local coordinates are not clamped (they leave [0,1] by at most
 * tol/h), so skinning at rest and under affine node maps is exact.
 * Each cell's triangle list holds every triangle meeting the cell grown by tol
 * (exact SAT), so a triangle is always listed in the cell its centroid is assigned to.
 * Skinning is the trilinear interpolation of the cell's 8 nodes, or, in the B-spline cells of a
 * localframe object (cm->spline_nodes), the tricubic map of its 64: the hot path, no allocation.
 * cs_surface_of_cells builds the closed boundary of a cell set on an integer sub-lattice, which
 * makes welding exact.
 */
#include "surface.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "localframe.h"
#include "voxelize.h"


void cs_surface_free(cs_surface *s)
{
    if (!s)
        return;
    free(s->rest);
    free(s->pos);
    free(s->tris);
    free(s->vert_cell);
    free(s->vert_uvw);
    free(s->tri_cell);
    free(s->cell_tri_start);
    free(s->cell_tri_list);
    memset(s, 0, sizeof *s);
}

/* Cell containing p (within tol_h cell widths) and the local coordinates, or -1. */
static int32_t locate(const cs_cubemesh *cm, double tol_h, const double p[3], double uvw[3])
{
    double l[3];
    int base[3], cnt[3], opt[3][2];
    for (int k = 0; k < 3; k++) {
        l[k] = (p[k] - cm->origin[k]) / cm->h;
        double f = floor(l[k]);
        if (!(fabs(f) < 1e9))
            return -1;
        base[k] = (int)f;
        /* candidates: the floor cell, then a neighbour if p is within tolerance of that side */
        cnt[k] = 0;
        opt[k][cnt[k]++] = base[k];
        if (l[k] - f <= tol_h)
            opt[k][cnt[k]++] = base[k] - 1;
        else if (f + 1.0 - l[k] <= tol_h)
            opt[k][cnt[k]++] = base[k] + 1;
    }
    for (int a = 0; a < cnt[0]; a++)
        for (int b = 0; b < cnt[1]; b++)
            for (int c = 0; c < cnt[2]; c++) {
                int32_t cell = cs_cubemesh_find(cm, opt[0][a], opt[1][b], opt[2][c]);
                if (cell < 0)
                    continue;
                const int32_t *ijk = cm->cell_ijk + 3 * cell;
                for (int k = 0; k < 3; k++)
                    uvw[k] = l[k] - ijk[k];
                return cell;
            }
    return -1;
}

typedef struct {
    int32_t cell, tri;
} pair;

int cs_surface_bind(cs_surface *s, const cs_cubemesh *cm, const double *verts, int nv,
                    const int32_t *tris, int nt, char *err, size_t errlen)
{
    memset(s, 0, sizeof *s);
    s->n_vertices = nv;
    s->n_triangles = nt;
    size_t nv3 = (size_t)(nv ? nv : 1) * 3, nt3 = (size_t)(nt ? nt : 1) * 3;
    s->rest = malloc(nv3 * sizeof *s->rest);
    s->pos = malloc(nv3 * sizeof *s->pos);
    s->vert_uvw = malloc(nv3 * sizeof *s->vert_uvw);
    s->vert_cell = malloc((size_t)(nv ? nv : 1) * sizeof *s->vert_cell);
    s->tris = malloc(nt3 * sizeof *s->tris);
    s->tri_cell = malloc((size_t)(nt ? nt : 1) * sizeof *s->tri_cell);
    s->cell_tri_start = calloc((size_t)cm->n_cells + 1, sizeof *s->cell_tri_start);
    if (!s->rest || !s->pos || !s->vert_uvw || !s->vert_cell || !s->tris || !s->tri_cell ||
        !s->cell_tri_start)
        goto oom;
    memcpy(s->rest, verts, (size_t)nv * 3 * sizeof *verts);
    memcpy(s->pos, verts, (size_t)nv * 3 * sizeof *verts);
    memcpy(s->tris, tris, (size_t)nt * 3 * sizeof *tris);
    const double tol = 2.0 * cs_voxel_tolerance(cm->h, verts, nv), tol_h = tol / cm->h;
    for (int i = 0; i < nv; i++) {
        const double *p = verts + 3 * i;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2])) {
            snprintf(err, errlen, "surface: vertex %d is not finite", i);
            goto fail;
        }
        s->vert_cell[i] = locate(cm, tol_h, p, s->vert_uvw + 3 * i);
        if (s->vert_cell[i] < 0) {
            snprintf(err, errlen, "surface: vertex %d at (%g, %g, %g) lies in no cube", i, p[0],
                     p[1], p[2]);
            goto fail;
        }
    }
    for (int t = 0; t < nt; t++) {
        const int32_t *tri = tris + 3 * t;
        if (tri[0] < 0 || tri[0] >= nv || tri[1] < 0 || tri[1] >= nv || tri[2] < 0 ||
            tri[2] >= nv) {
            snprintf(err, errlen, "surface: triangle %d has a bad vertex index", t);
            goto fail;
        }
        const double *a = verts + 3 * tri[0], *b = verts + 3 * tri[1], *c = verts + 3 * tri[2];
        double ctr[3], uvw[3];
        for (int k = 0; k < 3; k++)
            ctr[k] = (a[k] + b[k] + c[k]) / 3.0;
        s->tri_cell[t] = locate(cm, tol_h, ctr, uvw);
        if (s->tri_cell[t] < 0) {
            snprintf(err, errlen, "surface: centroid of triangle %d lies in no cube", t);
            goto fail;
        }
    }
    free(s->cell_tri_start);
    s->cell_tri_start = NULL;
    if (cs_surface_build_cell_lists(s, cm, tol) != 0)
        goto oom;
    return 0;
oom:
    snprintf(err, errlen, "surface: out of memory");
fail:
    cs_surface_free(s);
    return -1;
}

/* The (cell, triangle) overlaps of triangles [t0, t1), appended to *pairs. */
static int overlap_pairs(const cs_surface *s, const cs_cubemesh *cm, double tol, int t0, int t1,
                         pair **pairs, int *n_pairs, int *cap_pairs)
{
    const double h = cm->h, tol_h = tol / h, grown = 0.5 * h + tol;
    const double half[3] = {grown, grown, grown};
    for (int t = t0; t < t1; t++) {
        const int32_t *tri = s->tris + 3 * (size_t)t;
        const double *a = s->rest + 3 * (size_t)tri[0], *b = s->rest + 3 * (size_t)tri[1],
                     *c = s->rest + 3 * (size_t)tri[2];
        int r0[3], r1[3];
        for (int k = 0; k < 3; k++) {
            double lo = fmin(a[k], fmin(b[k], c[k])), hi = fmax(a[k], fmax(b[k], c[k]));
            r0[k] = (int)floor((lo - cm->origin[k]) / h - 2 * tol_h - 1e-9);
            r1[k] = (int)floor((hi - cm->origin[k]) / h + 2 * tol_h + 1e-9);
        }
        for (int k = r0[2]; k <= r1[2]; k++)
            for (int j = r0[1]; j <= r1[1]; j++)
                for (int i = r0[0]; i <= r1[0]; i++) {
                    int32_t cell = cs_cubemesh_find(cm, i, j, k);
                    if (cell < 0)
                        continue;
                    double cc[3] = {cm->origin[0] + (i + 0.5) * h, cm->origin[1] + (j + 0.5) * h,
                                    cm->origin[2] + (k + 0.5) * h};
                    /* the centroid's cell always lists its triangle */
                    if (cell != s->tri_cell[t] && !cs_tri_box_overlap(cc, half, a, b, c))
                        continue;
                    if (*n_pairs == *cap_pairs) {
                        int nc = *cap_pairs ? 2 * *cap_pairs : 1024;
                        pair *np = realloc(*pairs, (size_t)nc * sizeof *np);
                        if (!np)
                            return -1;
                        *pairs = np;
                        *cap_pairs = nc;
                    }
                    (*pairs)[(*n_pairs)++] = (pair){cell, t};
                }
    }
    return 0;
}

/* Lists of triangles [0, first) kept from s's current lists (first = 0: none), the overlaps of
 * [first, n_triangles) added; triangles stay in increasing order within a cell. */
static int cell_lists(cs_surface *s, const cs_cubemesh *cm, double tol, int first)
{
    pair *pairs = NULL;
    int n_pairs = 0, cap_pairs = 0;
    const int32_t *old_start = first > 0 ? s->cell_tri_start : NULL;
    int32_t *start = calloc((size_t)cm->n_cells + 1, sizeof *start), *list = NULL;
    if (!start)
        return -1;
    if (overlap_pairs(s, cm, tol, first, s->n_triangles, &pairs, &n_pairs, &cap_pairs))
        goto oom;
    const int n_old = old_start ? old_start[cm->n_cells] : 0;
    /* CSR by counting sort on the cell: the kept entries first, then the new ones */
    list = malloc((size_t)(n_pairs + n_old ? n_pairs + n_old : 1) * sizeof *list);
    int32_t *fill = malloc((size_t)(cm->n_cells ? cm->n_cells : 1) * sizeof *fill);
    if (!list || !fill) {
        free(fill);
        goto oom;
    }
    for (int c = 0; old_start && c < cm->n_cells; c++)
        start[c + 1] = old_start[c + 1] - old_start[c];
    for (int p = 0; p < n_pairs; p++)
        start[pairs[p].cell + 1]++;
    for (int c = 0; c < cm->n_cells; c++)
        start[c + 1] += start[c];
    memcpy(fill, start, (size_t)cm->n_cells * sizeof *fill);
    for (int c = 0; old_start && c < cm->n_cells; c++) {
        const int n = old_start[c + 1] - old_start[c];
        if (n)
            memcpy(list + fill[c], s->cell_tri_list + old_start[c], (size_t)n * sizeof *list);
        fill[c] += n;
    }
    for (int p = 0; p < n_pairs; p++)
        list[fill[pairs[p].cell]++] = pairs[p].tri;
    free(fill);
    free(pairs);
    free(s->cell_tri_start);
    free(s->cell_tri_list);
    s->cell_tri_start = start;
    s->cell_tri_list = list;
    return 0;
oom:
    free(pairs);
    free(start);
    free(list);
    return -1;
}

int cs_surface_build_cell_lists(cs_surface *s, const cs_cubemesh *cm, double tol)
{
    return cell_lists(s, cm, tol, 0);
}

int cs_surface_extend_cell_lists(cs_surface *s, const cs_cubemesh *cm, double tol, int first)
{
    if (first <= 0 || !s->cell_tri_start)
        return cell_lists(s, cm, tol, 0);
    return cell_lists(s, cm, tol, first);
}

/* One vertex: rest point `rest`, local coordinates `uvw` in `cell` (the hot path of
 * cs_surface_skin, and cs_surface_skin_point: the same arithmetic, bit for bit). */
static inline void skin_one(const cs_cubemesh *cm, const double *node_pos, int32_t cell,
                            const double *uvw, const double *rest, double *out)
{
    const double u = uvw[0], v = uvw[1], w = uvw[2];
    const int32_t *sn = cm->spline_nodes ? cm->spline_nodes + 64 * (size_t)cell : NULL;
    if (sn && sn[0] >= 0) {
        /* B-spline cell: the tricubic map of the localframe model (seed 001 §3.4.1),
         * applied to displacements so that rest positions map to themselves exactly. */
        double bx[4], by[4], bz[4], d[3] = {0.0, 0.0, 0.0};
        cs_bspline_basis(u, bx, NULL);
        cs_bspline_basis(v, by, NULL);
        cs_bspline_basis(w, bz, NULL);
        for (int a = 0; a < 64; a++) {
            const double wa = bx[a % 4] * by[(a / 4) % 4] * bz[a / 16];
            const double *p = node_pos + 3 * (size_t)sn[a];
            const double *r = cm->node_rest + 3 * (size_t)sn[a];
            d[0] += wa * (p[0] - r[0]);
            d[1] += wa * (p[1] - r[1]);
            d[2] += wa * (p[2] - r[2]);
        }
        for (int k = 0; k < 3; k++)
            out[k] = rest[k] + d[k];
        return;
    }
    const int32_t *nodes = cm->cell_nodes + 8 * (size_t)cell;
    const double wx[2] = {1.0 - u, u}, wy[2] = {1.0 - v, v}, wz[2] = {1.0 - w, w};
    double x = 0.0, y = 0.0, z = 0.0;
    for (int k = 0; k < 8; k++) {
        const double wk = wx[CS_CORNER[k][0]] * wy[CS_CORNER[k][1]] * wz[CS_CORNER[k][2]];
        const double *p = node_pos + 3 * (size_t)nodes[k];
        x += wk * p[0];
        y += wk * p[1];
        z += wk * p[2];
    }
    out[0] = x;
    out[1] = y;
    out[2] = z;
}

void cs_surface_skin(cs_surface *s, const cs_cubemesh *cm, const double *node_pos, int threads)
{
    const int nv = s->n_vertices;
    /* (below a few thousand vertices a second thread costs more than it takes) */
#pragma omp parallel for num_threads(threads > 1 ? threads : 1) schedule(static) if (nv >= 4096)
    for (int i = 0; i < nv; i++)
        skin_one(cm, node_pos, s->vert_cell[i], s->vert_uvw + 3 * (size_t)i,
                 s->rest + 3 * (size_t)i, s->pos + 3 * (size_t)i);
}

void cs_surface_skin_point(const cs_cubemesh *cm, const double *node_pos, int32_t cell,
                           const double uvw[3], const double rest[3], double out[3])
{
    skin_one(cm, node_pos, cell, uvw, rest, out);
}

/* ---------------------------------------------------------------- boundary of a cell set */

typedef struct {
    int64_t p[3];
    int32_t idx;
} lattice_pt;

static int cmp_lattice(const void *pa, const void *pb)
{
    const lattice_pt *a = pa, *b = pb;
    for (int k = 0; k < 3; k++)
        if (a->p[k] != b->p[k])
            return a->p[k] < b->p[k] ? -1 : 1;
    return (a->idx > b->idx) - (a->idx < b->idx);
}

typedef struct {
    int32_t lo, hi, cell, corner; /* corner: 3 * triangle + the edge's first corner */
} cell_half_edge;

static int cmp_half_edge(const void *pa, const void *pb)
{
    const cell_half_edge *a = pa, *b = pb;
    if (a->lo != b->lo)
        return a->lo < b->lo ? -1 : 1;
    if (a->hi != b->hi)
        return a->hi < b->hi ? -1 : 1;
    if (a->cell != b->cell)
        return a->cell < b->cell ? -1 : 1;
    return (a->corner > b->corner) - (a->corner < b->corner);
}

/* The triangles' 3·ntri edges, each named by its first corner, sorted by (lo, hi, cell,
 * corner): an edge's uses come together, a cell's side by side. malloc'd, or NULL. */
static cell_half_edge *sorted_half_edges(const int32_t *t, size_t ntri, const int32_t *tcell)
{
    const size_t nc = 3 * ntri;
    cell_half_edge *he = malloc((nc + 1) * sizeof *he);
    if (!he)
        return NULL;
    for (size_t c = 0; c < nc; c++) {
        const int32_t a = t[c], b = t[c - c % 3 + (c % 3 + 1) % 3];
        he[c] = (cell_half_edge){a < b ? a : b, a < b ? b : a, tcell[c / 3], (int32_t)c};
    }
    qsort(he, nc, sizeof *he, cmp_half_edge);
    return he;
}

static int32_t uf_find(int32_t *parent, int32_t i)
{
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

static void uf_union(int32_t *parent, int32_t a, int32_t b)
{
    a = uf_find(parent, a);
    b = uf_find(parent, b);
    if (a != b)
        parent[a > b ? a : b] = a < b ? a : b;
}

/* The corner of triangle `tri` at vertex `vert` (the triangle has it). */
static int32_t corner_at(const int32_t *t, int32_t tri, int32_t vert)
{
    for (int k = 0; k < 3; k++)
        if (t[3 * (size_t)tri + k] == vert)
            return 3 * tri + k;
    return 3 * tri;
}

/*
 * Welded by lattice point alone, the boundary of cells that touch only along an edge uses that
 * edge four times, and of cells that touch only at a corner puts two cones at one vertex. Cells
 * meet through faces: around an edge of four faces, the two of the same cell are paired (each
 * cell's boundary stays its own), every other edge pairs its two triangles; the triangle
 * corners at a vertex joined through paired edges form one fan, and each further fan of a
 * vertex gets a copy of it (appended after the nu vertices). A manifold boundary has one fan per
 * vertex and comes out unchanged. *v grows if needed; returns the new vertex count, -1 if out of
 * memory.
 */
static int64_t split_cell_fans(double **v, size_t nu, int32_t *t, size_t ntri,
                               const int32_t *tcell)
{
    const size_t nc = 3 * ntri;
    cell_half_edge *he = sorted_half_edges(t, ntri, tcell);
    int32_t *parent = malloc((nc + 1) * sizeof *parent);
    int32_t *copy = malloc((nc + 1) * sizeof *copy);
    uint8_t *claimed = calloc(nu + 1, 1);
    int64_t total = -1;
    if (!he || !parent || !copy || !claimed)
        goto out;
    for (size_t c = 0; c < nc; c++) {
        parent[c] = (int32_t)c;
        copy[c] = -1;
    }
    for (size_t i = 0; i < nc;) {
        size_t j = i + 1;
        while (j < nc && he[j].lo == he[i].lo && he[j].hi == he[i].hi)
            j++;
        /* 2: one pair; 4: two cells' pairs, sorted by cell */
        if (j - i == 2 || (j - i == 4 && he[i].cell == he[i + 1].cell &&
                           he[i + 2].cell == he[i + 3].cell))
            for (size_t k = i; k < j; k += 2) {
                const int32_t t1 = he[k].corner / 3, t2 = he[k + 1].corner / 3;
                uf_union(parent, corner_at(t, t1, he[k].lo), corner_at(t, t2, he[k].lo));
                uf_union(parent, corner_at(t, t1, he[k].hi), corner_at(t, t2, he[k].hi));
            }
        i = j;
    }
    size_t n_new = nu;
    for (size_t c = 0; c < nc; c++) {
        const int32_t r = uf_find(parent, (int32_t)c);
        if (copy[r] < 0) {
            if (!claimed[t[c]]) {
                claimed[t[c]] = 1;
                copy[r] = t[c];
            } else {
                copy[r] = (int32_t)n_new++;
            }
        }
    }
    if (n_new > nu) {
        if (n_new > INT32_MAX / 4)
            goto out;
        double *nv = realloc(*v, n_new * 3 * sizeof *nv);
        if (!nv)
            goto out;
        *v = nv;
        for (size_t c = 0; c < nc; c++) {
            const int32_t r = uf_find(parent, (int32_t)c);
            if ((size_t)copy[r] >= nu)
                memcpy(*v + 3 * (size_t)copy[r], *v + 3 * (size_t)t[c], 3 * sizeof **v);
        }
        for (size_t c = 0; c < nc; c++)
            t[c] = copy[uf_find(parent, (int32_t)c)];
    }
    total = (int64_t)n_new;
out:
    free(he);
    free(parent);
    free(copy);
    free(claimed);
    return total;
}

/* Triangle `tri` or one split off it (sib chains them) with the directed edge a -> b: its
 * index and the edge's first corner in *k, or -1. */
static int32_t tri_with_edge(const int32_t *t, const int32_t *sib, int32_t tri, int32_t a,
                             int32_t b, int *k)
{
    for (; tri >= 0; tri = sib[tri])
        for (int m = 0; m < 3; m++)
            if (t[3 * (size_t)tri + m] == a && t[3 * (size_t)tri + (m + 1) % 3] == b) {
                *k = m;
                return tri;
            }
    return -1;
}

/*
 * An edge whose two cells' fans are joined at both of its ends (the cells also meet through
 * faces on either side of the edge's ends) is still used four times after split_cell_fans: no
 * vertex copy separates its two uses. Each cell's pair of triangles on it then gets its own
 * vertex at the edge's midpoint, both triangles split there. *v, *t and *tcell grow; *nu and
 * *ntri are updated. Returns 0, or -1 if out of memory.
 */
static int split_shared_edges(double **v, size_t *nu, int32_t **t, int32_t **tcell, size_t *ntri)
{
    const size_t nc = 3 * *ntri;
    cell_half_edge *he = sorted_half_edges(*t, *ntri, *tcell);
    if (!he)
        return -1;
    size_t groups = 0;
    for (size_t i = 0; i < nc;) {
        size_t j = i + 1;
        while (j < nc && he[j].lo == he[i].lo && he[j].hi == he[i].hi)
            j++;
        if (j - i == 4 && he[i].cell == he[i + 1].cell && he[i + 2].cell == he[i + 3].cell)
            he[groups++] = he[i], he[groups++] = he[i + 1], he[groups++] = he[i + 2],
            he[groups++] = he[i + 3];
        i = j;
    }
    groups /= 4;
    int rc = 0;
    if (groups > 0) {
        const size_t nt_new = *ntri + 4 * groups, nv_new = *nu + 2 * groups;
        int32_t *sib = NULL;
        double *nv = NULL;
        int32_t *nt = NULL, *ncell = NULL;
        if (nt_new > INT32_MAX / 4 || nv_new > INT32_MAX / 4 ||
            !(nv = realloc(*v, nv_new * 3 * sizeof *nv)))
            goto oom;
        *v = nv;
        if (!(nt = realloc(*t, nt_new * 3 * sizeof *nt)))
            goto oom;
        *t = nt;
        if (!(ncell = realloc(*tcell, nt_new * sizeof *ncell)))
            goto oom;
        *tcell = ncell;
        if (!(sib = malloc(nt_new * sizeof *sib)))
            goto oom;
        for (size_t i = 0; i < nt_new; i++)
            sib[i] = -1;
        size_t n_t = *ntri, n_v = *nu;
        for (size_t g = 0; g < groups; g++)
            for (int half = 0; half < 2; half++) {
                const cell_half_edge *e = &he[4 * g + 2 * half];
                const int32_t m = (int32_t)n_v++;
                for (int q = 0; q < 3; q++)
                    nv[3 * (size_t)m + q] = 0.5 * (nv[3 * (size_t)e->lo + q] + nv[3 * (size_t)e->hi + q]);
                for (int side = 0; side < 2; side++) {
                    const int32_t orig = e[side].corner / 3;
                    int k;
                    int32_t tri = tri_with_edge(nt, sib, orig, e->lo, e->hi, &k);
                    if (tri < 0)
                        tri = tri_with_edge(nt, sib, orig, e->hi, e->lo, &k);
                    if (tri < 0)
                        continue; /* cannot happen: the edge is on one of them */
                    int32_t *tt = nt + 3 * (size_t)tri;
                    const int32_t a = tt[k], b = tt[(k + 1) % 3], c = tt[(k + 2) % 3];
                    /* (a, b, c) -> (a, m, c) here and (m, b, c) appended */
                    tt[0] = a, tt[1] = m, tt[2] = c;
                    int32_t *tn = nt + 3 * n_t;
                    tn[0] = m, tn[1] = b, tn[2] = c;
                    ncell[n_t] = ncell[tri];
                    sib[n_t] = sib[tri];
                    sib[tri] = (int32_t)n_t;
                    n_t++;
                }
            }
        *ntri = n_t;
        *nu = n_v;
        free(sib);
        goto done;
oom:
        free(sib);
        rc = -1;
    }
done:
    free(he);
    return rc;
}

int cs_surface_of_cells(const cs_cubemesh *cm, int sub, double **verts, int *nv,
                        int32_t **tris, int *nt, char *err, size_t errlen)
{
    *verts = NULL;
    *tris = NULL;
    *nv = *nt = 0;
    if (sub < 1 || sub > 1024) {
        snprintf(err, errlen, "surface of cells: subdivision %d out of range [1, 1024]", sub);
        return -1;
    }
    /* count exposed faces */
    size_t faces = 0;
    for (int c = 0; c < cm->n_cells; c++) {
        const int32_t *q = cm->cell_ijk + 3 * c;
        for (int f = 0; f < 6; f++) {
            int d[3] = {0, 0, 0};
            d[f / 2] = f % 2 ? -1 : 1;
            faces += cs_cubemesh_find(cm, q[0] + d[0], q[1] + d[1], q[2] + d[2]) < 0;
        }
    }
    size_t quads = faces * (size_t)sub * (size_t)sub;
    if (quads * 4 > INT32_MAX / 2) {
        snprintf(err, errlen, "surface of cells: too many faces (%zu)", faces);
        return -1;
    }
    lattice_pt *pts = malloc((quads * 4 + 1) * sizeof *pts);
    int32_t *t = malloc((quads * 2 + 1) * 3 * sizeof *t);
    int32_t *remap = malloc((quads * 4 + 1) * sizeof *remap);
    int32_t *tcell = malloc((quads * 2 + 1) * sizeof *tcell);
    double *v = NULL;
    if (!pts || !t || !remap || !tcell)
        goto oom;
    size_t np = 0, ntri = 0;
    for (int c = 0; c < cm->n_cells; c++) {
        const int32_t *q = cm->cell_ijk + 3 * c;
        for (int f = 0; f < 6; f++) {
            int ax = f / 2, sign = f % 2 ? -1 : 1;
            int d[3] = {0, 0, 0};
            d[ax] = sign;
            if (cs_cubemesh_find(cm, q[0] + d[0], q[1] + d[1], q[2] + d[2]) >= 0)
                continue;
            int b = (ax + 1) % 3, e = (ax + 2) % 3;
            /* e_b × e_e = e_ax: (b,e) counter-clockwise is outward for the + face */
            int64_t plane = (int64_t)(q[ax] + (sign > 0 ? 1 : 0)) * sub;
            for (int s1 = 0; s1 < sub; s1++)
                for (int s2 = 0; s2 < sub; s2++) {
                    static const int corner[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
                    size_t first = np;
                    for (int m = 0; m < 4; m++) {
                        lattice_pt *lp = &pts[np];
                        lp->p[ax] = plane;
                        lp->p[b] = (int64_t)q[b] * sub + s1 + corner[m][0];
                        lp->p[e] = (int64_t)q[e] * sub + s2 + corner[m][1];
                        lp->idx = (int32_t)np;
                        np++;
                    }
                    int32_t i0 = (int32_t)first, i1 = i0 + 1, i2 = i0 + 2, i3 = i0 + 3;
                    if (sign < 0) { /* reverse the winding for the - face */
                        int32_t tmp = i1;
                        i1 = i3;
                        i3 = tmp;
                    }
                    int32_t *tt = t + 3 * ntri;
                    tt[0] = i0, tt[1] = i1, tt[2] = i2;
                    tt[3] = i0, tt[4] = i2, tt[5] = i3;
                    tcell[ntri] = tcell[ntri + 1] = c;
                    ntri += 2;
                }
        }
    }
    qsort(pts, np, sizeof *pts, cmp_lattice);
    size_t nu = 0;
    for (size_t i = 0; i < np;) {
        size_t j = i + 1;
        while (j < np && !memcmp(pts[j].p, pts[i].p, sizeof pts[i].p))
            j++;
        for (size_t k = i; k < j; k++)
            remap[pts[k].idx] = (int32_t)nu;
        pts[nu].p[0] = pts[i].p[0], pts[nu].p[1] = pts[i].p[1], pts[nu].p[2] = pts[i].p[2];
        nu++;
        i = j;
    }
    v = malloc((nu + 1) * 3 * sizeof *v);
    if (!v)
        goto oom;
    for (size_t i = 0; i < nu; i++)
        for (int k = 0; k < 3; k++)
            v[3 * i + k] = cm->origin[k] + cm->h * ((double)pts[i].p[k] / sub);
    for (size_t i = 0; i < 3 * ntri; i++)
        t[i] = remap[t[i]];
    free(pts);
    free(remap);
    pts = NULL;
    remap = NULL;
    const int64_t n_split = split_cell_fans(&v, nu, t, ntri, tcell);
    if (n_split < 0)
        goto oom;
    nu = (size_t)n_split;
    if (split_shared_edges(&v, &nu, &t, &tcell, &ntri) != 0)
        goto oom;
    free(tcell);
    *verts = v;
    *tris = t;
    *nv = (int)nu;
    *nt = (int)ntri;
    return 0;
oom:
    free(pts);
    free(t);
    free(remap);
    free(tcell);
    free(v);
    snprintf(err, errlen, "surface of cells: out of memory");
    return -1;
}
