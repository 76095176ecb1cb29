/*
 * elastic.c — dispatch from the integrators to the element model of each object.
 */
#include "elastic.h"

int cs_elastic_init(cs_object *o, int threads)
{
    /* Every model keeps the FEM record: fracture uses its adjacency and rotations. */
    int rc = cs_fem_init(&o->fem, &o->cm, o->mat.young, o->mat.poisson,
                         o->model != CS_MODEL_LINEAR, threads);
    /* the stiffness field (world_internal.h); NULL while uniform 1 */
    o->fem.kf = o->fld.has_young ? o->fld.young : NULL;
    return rc;
}

void cs_elastic_free(cs_object *o)
{
    cs_fem_free(&o->fem);
}

int cs_elastic_relink(cs_object *o)
{
    o->fem.kf = o->fld.has_young ? o->fld.young : NULL;
    return cs_fem_relink(&o->fem, &o->cm);
}

void cs_elastic_reset(cs_object *o)
{
    cs_fem_reset_rotations(&o->fem);
}

void cs_elastic_update(cs_object *o, const double *x)
{
    cs_fem_update_rotations(&o->fem, x);
}

void cs_elastic_force(cs_object *o, const double *x, double *f, double *energy)
{
    cs_fem_elastic_force(&o->fem, x, f, energy);
}

double cs_elastic_energy(cs_object *o, const double *x)
{
    return cs_fem_energy(&o->fem, x);
}

void cs_elastic_apply_K(cs_object *o, const double *p, double *y)
{
    cs_fem_apply_K(&o->fem, p, y);
}

void cs_elastic_diag_blocks(cs_object *o, double *blocks)
{
    cs_fem_diag_blocks(&o->fem, blocks);
}

int cs_elastic_prepare_tangent(cs_object *o, const double *x)
{
    if (o->model != CS_MODEL_COROTATIONAL)
        return -1;
    return cs_fem_prepare_tangent(&o->fem, x);
}

void cs_elastic_apply_tangent(cs_object *o, const double *p, double *y)
{
    cs_fem_apply_tangent(&o->fem, p, y);
}

void cs_elastic_release_tangent(cs_object *o)
{
    cs_fem_release_tangent(&o->fem);
}

int cs_elastic_threads(const cs_object *o)
{
    return o->fem.threads;
}
