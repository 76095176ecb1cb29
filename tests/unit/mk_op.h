/*
 * mk_op.h — the test operator of the multigrid and thread tests (test_multigrid.c,
 * test_threads.c): y = kc K p + M p, the implicit step's matrix with K from cs_fem_apply_K
 * and M the object's lumped node masses, as a cs_matvec_fn for cs_mg_setup and the CG solves.
 */
#ifndef CS_TEST_MK_OP_H
#define CS_TEST_MK_OP_H

#include "fem.h"
#include "world_internal.h"

typedef struct mk_opctx {
    cs_object *o;
    double kc; /* the stiffness factor (dt² for implicit Euler) */
} mk_opctx;

static inline void mk_op(void *ctx, const double *p, double *y)
{
    mk_opctx *c = ctx;
    cs_fem_apply_K(&c->o->fem, p, y);
    for (int i = 0; i < c->o->n; i++)
        for (int a = 0; a < 3; a++)
            y[3 * i + a] = c->kc * y[3 * i + a] + c->o->m[i] * p[3 * i + a];
}

#endif
