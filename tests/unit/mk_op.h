/*
 * mk_op.h — the test operator of the multigrid and thread tests (test_multigrid.c,
 * test_threads.c): y = kc K p + M p, the implicit step's matrix with K from cs_fem_apply_K
 * and M the object's lumped node masses, as a cs_matvec_fn for cs_mg_setup and the CG solves,
 * and its inverted diagonal blocks.
 */
#ifndef CS_TEST_MK_OP_H
#define CS_TEST_MK_OP_H

#include "fem.h"
#include "solver.h"
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

/* inv (9 per node) = the inverted 3×3 diagonal blocks of kc K + M: the block-Jacobi
 * smoother data cs_mg_setup takes. */
static inline void mk_op_inv_diag(mk_opctx *c, double *inv)
{
    cs_object *o = c->o;
    cs_fem_diag_blocks(&o->fem, inv);
    for (int i = 0; i < o->n; i++) {
        for (int k = 0; k < 9; k++)
            inv[9 * i + k] *= c->kc;
        for (int a = 0; a < 3; a++)
            inv[9 * i + 4 * a] += o->m[i];
    }
    cs_invert_blocks(inv, o->n);
}

#endif
