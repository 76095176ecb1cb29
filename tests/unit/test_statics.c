/*
 * test_statics.c — the static solve's load stepping and its stop: an L bracket (a column of
 * 2×4×20 cubes held at its foot, an arm of 18×4×2 cubes at its top, a dead load on the arm's
 * end face) of corotational cubes at ν 0.49, a case that needs partial load levels.
 * - its answer does not depend on the solver tolerance beyond that tolerance (a partial level
 *   used to be "reached" at the rest state whenever its loads were below 1e3·tol of the full
 *   ones, which at tolerance 1e-3 was every level: only the full load was ever solved, and
 *   the solve failed and returned the rest state).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "cubesim.h"

#define LB_H 0.025

typedef struct bracket {
    cs_world_t *w;
    cs_object_id id;
} bracket;

static int bracket_make(bracket *b, double tol)
{
    memset(b, 0, sizeof *b);
    cs_world_def wd = cs_world_def_default();
    wd.gravity[2] = 0;
    wd.threads = 1;
    wd.cg_tolerance = tol;
    if (cs_world_create(&wd, &b->w, NULL, 0) != CS_OK)
        return -1;
    int32_t cells[3 * (2 * 4 * 20 + 18 * 4 * 2)];
    int n = 0;
    for (int i = 0; i < 20; i++)
        for (int j = 0; j < 4; j++)
            for (int k = 0; k < 20; k++)
                if (i < 2 || k >= 18) {
                    cells[3 * n] = i, cells[3 * n + 1] = j, cells[3 * n + 2] = k;
                    n++;
                }
    cs_object_def d = cs_object_def_default();
    d.name = "L";
    d.model = CS_MODEL_COROTATIONAL;
    d.material.young = 1e6;
    d.material.poisson = 0.49;
    d.material.density = 1000;
    d.cube_size = LB_H;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = cells;
    d.n_cells = n;
    const cs_aabb fix = {{-1, -1, -1e-3 * LB_H}, {1, 1, 1e-3 * LB_H}};
    d.fixed = &fix;
    d.n_fixed = 1;
    const double xe = 20 * LB_H; /* the arm's end face */
    const cs_load load = {{{xe - 1e-3 * LB_H, -1, -1}, {xe + 1e-3 * LB_H, 1, 2}}, {0, 0, -1.0927}};
    d.loads = &load;
    d.n_loads = 1;
    char err[256];
    if (cs_world_add_object(b->w, &d, &b->id, err, sizeof err) != CS_OK) {
        printf("    add: %s\n", err);
        cs_world_destroy(b->w);
        return -1;
    }
    return 0;
}

/* The mean z displacement of the arm's end face, and the largest |x − X| of any node. */
static double bracket_tip(const bracket *b, double *umax)
{
    const double *X, *x;
    int n;
    cs_object_nodes(b->w, b->id, &X, &x, NULL, &n);
    double s = 0, m = 0;
    int c = 0;
    for (int i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++)
            m = fmax(m, fabs(x[3 * i + a] - X[3 * i + a]));
        if (fabs(X[3 * i] - 20 * LB_H) < 1e-9) {
            s += x[3 * i + 2] - X[3 * i + 2];
            c++;
        }
    }
    if (umax)
        *umax = m;
    return c ? s / c : NAN;
}

TEST(statics_load_levels_are_solved_at_a_loose_tolerance)
{
    const double tols[3] = {1e-6, 1e-4, 1e-3};
    double tip[3];
    for (int k = 0; k < 3; k++) {
        bracket b;
        ENSURE(bracket_make(&b, tols[k]) == 0);
        const int rc = cs_world_solve_static(b.w);
        const cs_step_stats *st = cs_world_last_stats(b.w);
        tip[k] = bracket_tip(&b, NULL);
        printf("    tolerance %g: %s, %d CG iterations, residual %.3g, tip %.9g m\n", tols[k],
               cs_status_str(rc), st->cg_iterations, st->cg_residual, tip[k]);
        cs_world_destroy(b.w);
        ENSURE_MSG(rc == CS_OK, "tolerance %g: %s", tols[k], cs_status_str(rc));
        ENSURE(st->cg_residual <= tols[k] * 1.0001);
    }
    /* the arm bends down by about 0.1 m; the looser answers within their tolerance's reach */
    ENSURE(tip[0] < -0.05);
    ENSURE_NEAR(tip[1], tip[0], 1e-4 * fabs(tip[0]));
    ENSURE_NEAR(tip[2], tip[0], 1e-2 * fabs(tip[0]));
}
