/*
 * test_fracture_open.c — a fracture through a crack that had opened before (an open crack):
 * what the surface looks like at the instant of the fracture, before any step re-skins it.
 *
 * The scene is the mechanism of the fracture storm's failure at seed 5 (tests/stress), made
 * small: a 4×1×2 bar of cubes, cells (i, 0, k). A first cut separates the top cubes i = 2, 3
 * from the ones below them (the paper's rule: the − cells take copies of every node of the
 * crack faces, so at the crack's rim the top cube (2,0,1) tears from its unlabelled neighbour
 * (1,0,1) along one edge): the two top cubes are a flap hinged on (1,0,1) by the two nodes of
 * their face's upper edge, still one piece. The flap is turned rigidly about that hinge by
 * half a radian (no cube deformed), which opens the crack. The surface vertices on the rim,
 * (2h, y, h), are bound to the flap cell (2,0,1), so they moved with it (0.49 h), while their
 * triangles in the bottom cube (2,0,0) stayed joined to them (that cube still shares nodes
 * with the flap's neighbours). A second cut between (1,0,0) and (2,0,0) makes the bottom
 * cubes i = 2, 3 a piece of their own: the rim vertices get copies bound to (2,0,0), at rest.
 * At that instant every piece must be closed, oriented and enclose a positive volume at its
 * current positions, and every surface vertex must lie where its bound cell puts it (the
 * skinned position the next step gives it; every cube here is undeformed, so that is exact to
 * round-off). Before the fix the copies started where their source was, on the flap, 0.05 m
 * from their cube.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"
#include "watertight.h"
#include "world_internal.h"

#define H 0.1
/* The trilinear skin of vertex v of o's surface (a corotational box: no B-spline cells). */
static void skinned(const cs_object *o, int v, double out[3])
{
    const cs_surface *s = &o->surf;
    const double *u = s->vert_uvw + 3 * (size_t)v;
    const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)s->vert_cell[v];
    out[0] = out[1] = out[2] = 0;
    for (int k = 0; k < 8; k++) {
        const double wk = (CS_CORNER[k][0] ? u[0] : 1 - u[0]) * (CS_CORNER[k][1] ? u[1] : 1 - u[1]) *
                          (CS_CORNER[k][2] ? u[2] : 1 - u[2]);
        for (int a = 0; a < 3; a++)
            out[a] += wk * o->x[3 * (size_t)nd[k] + a];
    }
}

/* The largest |pos - skinned| over o's surface vertices used by a triangle. */
static double skin_error(const cs_object *o, int *worst)
{
    const cs_surface *s = &o->surf;
    double e = 0;
    *worst = -1;
    for (int t = 0; t < s->n_triangles; t++)
        for (int k = 0; k < 3; k++) {
            const int v = s->tris[3 * t + k];
            double q[3];
            skinned(o, v, q);
            for (int a = 0; a < 3; a++)
                if (fabs(q[a] - s->pos[3 * (size_t)v + a]) > e) {
                    e = fabs(q[a] - s->pos[3 * (size_t)v + a]);
                    *worst = v;
                }
        }
    return e;
}

/* The cell of o at lattice (i, j, k). */
static int32_t cell_at(const cs_object *o, int i, int j, int k)
{
    return cs_cubemesh_find(&o->cm, i, j, k);
}

/* Mean edge vectors' determinant of cell c (h³ if undeformed or rigidly moved). */
static double cell_det(const cs_object *o, int32_t c)
{
    double E[3][3] = {{0}};
    for (int ax = 0; ax < 3; ax++)
        for (int k = 0; k < 8; k++) {
            const double sg = CS_CORNER[k][ax] ? 0.25 : -0.25;
            for (int a = 0; a < 3; a++)
                E[ax][a] += sg * o->x[3 * (size_t)o->cm.cell_nodes[8 * (size_t)c + k] + a];
        }
    return E[0][0] * (E[1][1] * E[2][2] - E[1][2] * E[2][1]) -
           E[0][1] * (E[1][0] * E[2][2] - E[1][2] * E[2][0]) +
           E[0][2] * (E[1][0] * E[2][1] - E[1][1] * E[2][0]);
}

TEST(fracture_open_crack_copies_start_on_their_side)
{
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = 0;
    cs_world_t *w = NULL;
    ENSURE(cs_world_create(&wd, &w, NULL, 0) == CS_OK);
    int32_t ijk[3 * 8];
    for (int c = 0; c < 8; c++) {
        ijk[3 * c] = c % 4;
        ijk[3 * c + 1] = 0;
        ijk[3 * c + 2] = c / 4;
    }
    cs_object_def od = cs_object_def_default();
    od.name = "bar";
    od.cube_size = H;
    od.cells_ijk = ijk;
    od.n_cells = 8;
    cs_object_id id = 0;
    char err[256] = "";
    ENSURE_MSG(cs_world_add_object(w, &od, &id, err, sizeof err) == CS_OK, "%s", err);

    /* 1. the crack: centre (3,0,0), normal -z: the bottom cubes within 1.5 h are +, the top
     * ones -, (1,0,1) (sqrt(5) h away) is not labelled */
    ENSURE(cs_world_fracture(w, id, (double[3]){3.5 * H, 0.5 * H, 0.5 * H},
                             (double[3]){0, 0, -1}, 1.5 * H, err, sizeof err) == CS_OK);
    cs_object_id ids[8];
    ENSURE_MSG(cs_world_object_ids(w, ids, 8) == 1, "the first cut must leave one piece");
    cs_object *o = cs_world_find_internal(w, id);
    ENSURE(o && o->cm.n_cells == 8);
    const int32_t F0 = cell_at(o, 2, 0, 1), F1 = cell_at(o, 3, 0, 1), L = cell_at(o, 1, 0, 1);
    ENSURE(F0 >= 0 && F1 >= 0 && L >= 0);
    int shared = 0;
    for (int a = 0; a < 8; a++)
        for (int b = 0; b < 8; b++)
            shared += o->cm.cell_nodes[8 * (size_t)F0 + a] == o->cm.cell_nodes[8 * (size_t)L + b];
    ENSURE_MSG(shared == 2, "the flap shares %d nodes with (1,0,1), want 2 (the hinge)", shared);

    /* 2. open it: the flap's nodes turned by 0.5 rad about the hinge (x = 2h, z = 2h, along
     * y), upwards; the hinge nodes lie on the axis */
    const double phi = 0.5, cphi = cos(phi), sphi = sin(phi);
    uint8_t *moved = calloc((size_t)o->n, 1);
    ENSURE(moved);
    for (int f = 0; f < 2; f++)
        for (int k = 0; k < 8; k++) {
            const int32_t nd = o->cm.cell_nodes[8 * (size_t)(f ? F1 : F0) + k];
            if (moved[nd])
                continue;
            moved[nd] = 1;
            double *x = o->x + 3 * (size_t)nd;
            const double rx = x[0] - 2 * H, rz = x[2] - 2 * H;
            x[0] = 2 * H + cphi * rx - sphi * rz;
            x[2] = 2 * H + sphi * rx + cphi * rz;
        }
    free(moved);
    cs_surface_skin(&o->surf, &o->cm, o->x, 1);
    for (int c = 0; c < 8; c++)
        ENSURE_NEAR(cell_det(o, c), H * H * H, 1e-15);
    int rim = 0; /* surface vertices at the rim (2h, y, h), bound to the flap */
    for (int v = 0; v < o->surf.n_vertices; v++) {
        const double *X = o->surf.rest + 3 * (size_t)v, *x = o->surf.pos + 3 * (size_t)v;
        if (fabs(X[0] - 2 * H) < 1e-12 && fabs(X[2] - H) < 1e-12 && o->surf.vert_cell[v] == F0) {
            rim++;
            ENSURE_MSG(hypot(x[0] - X[0], x[2] - X[2]) > 0.4 * H, "rim vertex %d moved %g m", v,
                       hypot(x[0] - X[0], x[2] - X[2]));
        }
    }
    ENSURE_MSG(rim >= 2, "%d rim vertices bound to the flap, want 2 or more", rim);

    /* 3. the second cut: (1,0,0) | (2,0,0) (centre (2,0,0), normal +x, radius 1.01 h: the
     * flap's cube (2,0,1) has moved out of it) */
    ENSURE(cs_world_fracture(w, id, (double[3]){2.5 * H, 0.5 * H, 0.5 * H},
                             (double[3]){1, 0, 0}, 1.01 * H, err, sizeof err) == CS_OK);
    const int n = cs_world_object_ids(w, ids, 8);
    ENSURE_MSG(n == 2, "%d pieces after the second cut, want 2", n);
    for (int i = 0; i < n; i++) {
        const double *v;
        const int32_t *t;
        int nv, nt;
        ENSURE(cs_object_surface(w, ids[i], &v, &nv, &t, &nt) == CS_OK);
        cs_watertight_report rep;
        char why[256] = "";
        const bool ok = cs_watertight_check(v, nv, t, nt, &rep, why, sizeof why);
        const cs_object *p = cs_world_find_internal(w, ids[i]);
        int worst;
        const double e = skin_error(p, &worst);
        printf("    piece %u: %d cubes, %d triangles, volume %.6g m^3 at current positions, "
               "vertices at most %.3g m from where their cubes put them\n", (unsigned)ids[i],
               p->cm.n_cells, nt, rep.volume, e);
        ENSURE_MSG(ok, "piece %u: %s", (unsigned)ids[i], why);
        ENSURE_MSG(rep.volume > 0.5 * H * H * H, "piece %u encloses %g m^3, want >= h^3",
                   (unsigned)ids[i], rep.volume);
        ENSURE_MSG(e < 1e-12, "piece %u: vertex %d (cube %d) lies %.3g m from where its cube "
                   "puts it", (unsigned)ids[i], worst, worst >= 0 ? p->surf.vert_cell[worst] : -1,
                   e);
    }
    cs_world_destroy(w);
}
