/*
 * elastic.c — dispatch from the integrators to the element model of each object.
 */
#include "elastic.h"

#include <stdlib.h>

#include "localframe.h"

int cs_elastic_init(cs_object *o, int threads)
{
    /* Every model keeps the FEM record: fracture uses its adjacency and rotations. */
    if (cs_fem_init(&o->fem, &o->cm, o->mat.young, o->mat.poisson,
                    o->model != CS_MODEL_LINEAR, threads) != 0)
        return -1;
    /* the stiffness field (world_internal.h); NULL while uniform 1 */
    o->fem.kf = o->fld.has_young ? o->fld.young : NULL;
    if (o->model == CS_MODEL_LOCALFRAME) {
        o->lf = malloc(sizeof *o->lf);
        if (!o->lf || cs_lf_init(o->lf, &o->cm, o->mat.young, o->mat.poisson, o->mat.density,
                                 threads) != 0) {
            free(o->lf);
            o->lf = NULL;
            return -1;
        }
    }
    return 0;
}

void cs_elastic_free(cs_object *o)
{
    cs_fem_free(&o->fem);
    if (o->lf) {
        cs_lf_free(o->lf);
        free(o->lf);
        o->lf = NULL;
    }
}

int cs_elastic_relink(cs_object *o)
{
    o->fem.kf = o->fld.has_young ? o->fld.young : NULL;
    if (cs_fem_relink(&o->fem, &o->cm) != 0)
        return -1;
    return o->lf ? cs_lf_relink(o->lf, &o->cm) : 0;
}

void cs_elastic_reset(cs_object *o)
{
    cs_fem_reset_rotations(&o->fem);
    if (o->lf)
        cs_lf_reset(o->lf);
}

void cs_elastic_update(cs_object *o, const double *x)
{
    if (o->lf)
        cs_lf_update(o->lf, x);
    else
        cs_fem_update_rotations(&o->fem, x);
}

void cs_elastic_force(cs_object *o, const double *x, double *f, double *energy)
{
    if (o->lf)
        cs_lf_force(o->lf, x, f, energy);
    else
        cs_fem_elastic_force(&o->fem, x, f, energy);
}

double cs_elastic_energy(cs_object *o, const double *x)
{
    return o->lf ? cs_lf_energy(o->lf, x) : cs_fem_energy(&o->fem, x);
}

void cs_elastic_apply_K(cs_object *o, const double *p, double *y)
{
    if (o->lf)
        cs_lf_apply_K(o->lf, p, y);
    else
        cs_fem_apply_K(&o->fem, p, y);
}

void cs_elastic_diag_blocks(cs_object *o, double *blocks)
{
    if (o->lf)
        cs_lf_diag_blocks(o->lf, blocks);
    else
        cs_fem_diag_blocks(&o->fem, blocks);
}

void cs_elastic_apply_M(cs_object *o, const double *p, double *y, double coef)
{
    if (o->lf) {
        cs_lf_apply_M(o->lf, p, y, coef);
        return;
    }
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            y[3 * i + a] += coef * o->m[i] * p[3 * i + a];
}

const double *cs_elastic_mass_diag(const cs_object *o)
{
    return o->lf ? o->lf->mdiag : o->m;
}

const double *cs_elastic_mass_rows(const cs_object *o)
{
    return o->lf ? o->lf->mrow : NULL;
}

int cs_elastic_prepare_tangent(cs_object *o, const double *x)
{
    /* localframe: the warped stiffness R K Rᵀ is its Newton operator (K is never rebuilt). */
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
    return o->lf ? o->lf->threads : o->fem.threads;
}
