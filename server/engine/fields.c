/*
 * fields.c — material fields (seed 001 §3.3; the representation is in world_internal.h):
 * allocation, the scene's design regions, lumped masses from the density field, and painting
 * at run time (cs_world_paint).
 *
 * Owns: nothing beyond cs_object's fld arrays (freed by cs_fields_free).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "elastic.h"
#include "mat3.h"
#include "world_internal.h"

static bool finite3(const double v[3])
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

static bool in_box(const cs_aabb *b, const double p[3])
{
    return p[0] >= b->min[0] && p[0] <= b->max[0] && p[1] >= b->min[1] && p[1] <= b->max[1] &&
           p[2] >= b->min[2] && p[2] <= b->max[2];
}


/* Local coordinate in [0, 1] of Gauss point g along axis a of its cell. */
static double gauss_t(int g, int a)
{
    return 0.5 + (CS_CORNER[g][a] - 0.5) / sqrt(3.0);
}

/* Trilinear weight of corner k at Gauss point g: N_k(ξ_g). */
static double gauss_weight(int g, int k)
{
    double w = 1;
    for (int a = 0; a < 3; a++)
        w *= CS_CORNER[k][a] ? gauss_t(g, a) : 1 - gauss_t(g, a);
    return w;
}

/* Position of Gauss point g of cell c interpolated from node positions x. */
static void gauss_point(const cs_object *o, const double *x, int c, int g, double p[3])
{
    const int32_t *nd = o->cm.cell_nodes + 8 * (size_t)c;
    p[0] = p[1] = p[2] = 0;
    for (int k = 0; k < 8; k++) {
        const double wk = gauss_weight(g, k);
        for (int a = 0; a < 3; a++)
            p[a] += wk * x[3 * (size_t)nd[k] + a];
    }
}

void cs_fields_free(cs_fields *f)
{
    free(f->young);
    free(f->density);
    free(f->damping);
    free(f->kd);
    free(f->dd);
    free(f->md);
    free(f->tmp);
    memset(f, 0, sizeof *f);
}

int cs_fields_alloc(cs_object *o)
{
    const size_t n = 8 * (size_t)(o->cm.n_cells ? o->cm.n_cells : 1);
    cs_fields_free(&o->fld);
    o->fld.young = malloc(n * sizeof(double));
    o->fld.density = malloc(n * sizeof(double));
    o->fld.damping = malloc(n * sizeof(double));
    o->fld.kd = malloc(n * sizeof(double));
    o->fld.dd = malloc(n * sizeof(double));
    if (!o->fld.young || !o->fld.density || !o->fld.damping || !o->fld.kd || !o->fld.dd)
        return -1;
    for (size_t i = 0; i < n; i++)
        o->fld.young[i] = o->fld.density[i] = o->fld.damping[i] = o->fld.kd[i] =
            o->fld.dd[i] = 1.0;
    return 0;
}

static bool cell_uniform(const double *f)
{
    for (int g = 1; g < 8; g++)
        if (f[g] != f[0])
            return false;
    return true;
}

int cs_object_lump_mass(cs_object *o)
{
    const cs_cubemesh *cm = &o->cm;
    const double h = cm->h, rho = o->mat.density;
    cs_fields *fl = &o->fld;
    fl->has_damping = fl->has_young = false;
    for (size_t i = 0; i < 8 * (size_t)cm->n_cells; i++) {
        fl->kd[i] = fl->young[i] * fl->damping[i];
        fl->dd[i] = fl->density[i] * fl->damping[i];
        if (fl->damping[i] != 1.0)
            fl->has_damping = true;
        if (fl->young[i] != 1.0)
            fl->has_young = true;
    }
    o->fem.kf = fl->has_young ? fl->young : NULL;
    double *md = NULL;
    if (fl->has_damping) {
        md = realloc(fl->md, (size_t)(o->n ? o->n : 1) * sizeof *md);
        if (md)
            fl->md = md;
        double *tmp = realloc(fl->tmp, (size_t)(o->n ? o->n : 1) * 9 * sizeof *tmp);
        if (tmp)
            fl->tmp = tmp;
        if (!md || !tmp)
            return -1;
        memset(md, 0, (size_t)o->n * sizeof *md);
    }
    memset(o->m, 0, (size_t)o->n * sizeof *o->m);
    for (int c = 0; c < cm->n_cells; c++) {
        const double *dn = fl->density + 8 * (size_t)c, *dm = fl->damping + 8 * (size_t)c;
        const int32_t *nd = cm->cell_nodes + 8 * (size_t)c;
        if (cell_uniform(dn)) { /* exactly the plain lumping ρh³/8 when the factor is 1 */
            const double mc = rho * dn[0] * h * h * h;
            for (int k = 0; k < 8; k++)
                o->m[nd[k]] += mc / 8.0;
        } else {
            for (int k = 0; k < 8; k++) {
                double s = 0;
                for (int g = 0; g < 8; g++)
                    s += dn[g] * gauss_weight(g, k);
                o->m[nd[k]] += rho * h * h * h / 8.0 * s;
            }
        }
        if (md)
            for (int k = 0; k < 8; k++) {
                double s = 0;
                for (int g = 0; g < 8; g++)
                    s += dn[g] * dm[g] * gauss_weight(g, k);
                md[nd[k]] += rho * h * h * h / 8.0 * s;
            }
    }
    o->mass = 0;
    for (int i = 0; i < o->n; i++)
        o->mass += o->m[i];
    return cs_elastic_fields_changed(o);
}

static int check_factors(const cs_field_factors *f, const char *what, char *err, size_t errlen)
{
    /* what: the prefix of the message ("fields[2]"), or "" */
    const char *sep = what[0] ? ": " : "";
    if (!f || (f->which & ~(CS_FIELD_YOUNG | CS_FIELD_DENSITY | CS_FIELD_DAMPING)) ||
        !(f->which & (CS_FIELD_YOUNG | CS_FIELD_DENSITY | CS_FIELD_DAMPING)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "%s%sgive at least one of the young, density, damping factors",
                              what, sep);
    if ((f->which & CS_FIELD_YOUNG) && !(f->young >= 1e-6 && f->young <= 1e6))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "%s%syoung factor must be in [1e-6, 1e6], got %g", what, sep, f->young);
    if ((f->which & CS_FIELD_DENSITY) && !(f->density >= 1e-6 && f->density <= 1e6))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "%s%sdensity factor must be in [1e-6, 1e6], got %g", what, sep,
                              f->density);
    if ((f->which & CS_FIELD_DAMPING) && !(f->damping >= 0 && f->damping <= 1e6))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "%s%sdamping factor must be in [0, 1e6], got %g", what, sep,
                              f->damping);
    return CS_OK;
}

int cs_fields_check_region(const cs_field_region *r, int i, char *err, size_t errlen)
{
    char what[48];
    snprintf(what, sizeof what, "fields[%d]", i);
    switch (r->shape) {
    case CS_FIELD_SPHERE:
    case CS_FIELD_RADIAL:
        if (!finite3(r->centre) || !(r->radius > 0 && isfinite(r->radius)))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                                  "%s: centre must be finite and radius > 0, got %g", what,
                                  r->radius);
        break;
    case CS_FIELD_BOX:
        if (!finite3(r->box.min) || !finite3(r->box.max))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID, "%s: box must be finite", what);
        break;
    case CS_FIELD_GRADIENT: {
        const double d[3] = {r->to[0] - r->from[0], r->to[1] - r->from[1], r->to[2] - r->from[2]};
        if (!finite3(r->from) || !finite3(r->to) || !(cs_vec3_norm(d) > 0))
            return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                                  "%s: gradient from and to must be finite and distinct", what);
        break;
    }
    default:
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "%s: unknown shape %d", what,
                              (int)r->shape);
    }
    return check_factors(&r->factors, what, err, errlen);
}

/* The weight in [0, 1] with which region r's factors apply at p (1 − s + s·f). */
static double region_weight(const cs_field_region *r, const double p[3])
{
    switch (r->shape) {
    case CS_FIELD_SPHERE: {
        const double d[3] = {p[0] - r->centre[0], p[1] - r->centre[1], p[2] - r->centre[2]};
        return cs_vec3_norm(d) <= r->radius ? 1.0 : 0.0;
    }
    case CS_FIELD_BOX:
        return in_box(&r->box, p) ? 1.0 : 0.0;
    case CS_FIELD_GRADIENT: {
        double d[3], l2 = 0, t = 0;
        for (int a = 0; a < 3; a++) {
            d[a] = r->to[a] - r->from[a];
            l2 += d[a] * d[a];
            t += (p[a] - r->from[a]) * d[a];
        }
        t /= l2;
        return t < 0 ? 0.0 : t > 1 ? 1.0 : t;
    }
    case CS_FIELD_RADIAL: {
        const double d[3] = {p[0] - r->centre[0], p[1] - r->centre[1], p[2] - r->centre[2]};
        const double q = cs_vec3_norm(d) / r->radius;
        return q >= 1 ? 0.0 : (1 - q * q) * (1 - q * q);
    }
    }
    return 0.0;
}

void cs_fields_apply_regions(cs_object *o, const cs_field_region *r, int n)
{
    for (int c = 0; c < o->cm.n_cells; c++)
        for (int g = 0; g < 8; g++) {
            double p[3];
            gauss_point(o, o->cm.node_rest, c, g, p);
            const size_t i = 8 * (size_t)c + g;
            for (int j = 0; j < n; j++) {
                const double s = region_weight(&r[j], p);
                if (s == 0)
                    continue;
                const cs_field_factors *f = &r[j].factors;
                if (f->which & CS_FIELD_YOUNG)
                    o->fld.young[i] *= 1 - s + s * f->young;
                if (f->which & CS_FIELD_DENSITY)
                    o->fld.density[i] *= 1 - s + s * f->density;
                if (f->which & CS_FIELD_DAMPING)
                    o->fld.damping[i] *= 1 - s + s * f->damping;
            }
        }
}

int cs_world_paint(cs_world_t *w, cs_object_id id, const double centre[3], double radius,
                   const cs_field_factors *f, int *touched, char *err, size_t errlen)
{
    if (touched)
        *touched = 0;
    if (!w || !centre || !f)
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "NULL argument");
    if (!finite3(centre))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID, "paint centre is not finite");
    if (!(radius > 0 && isfinite(radius)))
        return cs_engine_fail(err, errlen, CS_ERR_INVALID,
                              "paint radius must be > 0 m and finite, got %g", radius);
    int rc = check_factors(f, "", err, errlen);
    if (rc != CS_OK)
        return rc;
    cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return cs_engine_fail(err, errlen, CS_ERR_UNKNOWN_OBJECT, "no object with id %u",
                              (unsigned)id);
    /* The scene loads in f_const, without the old masses' gravity. */
    const double *g = w->def.gravity;
    double *load = malloc((size_t)(o->n ? o->n : 1) * 3 * sizeof *load);
    if (!load)
        return cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            load[3 * i + a] = o->f_const[3 * i + a] - o->m[i] * g[a];
    /* the old fields, restored if the paint would make the object's step unstable */
    const size_t nf = 8 * (size_t)(o->cm.n_cells ? o->cm.n_cells : 1);
    double *old = malloc(3 * nf * sizeof *old);
    if (!old) {
        free(load);
        return cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
    }
    memcpy(old, o->fld.young, nf * sizeof *old);
    memcpy(old + nf, o->fld.density, nf * sizeof *old);
    memcpy(old + 2 * nf, o->fld.damping, nf * sizeof *old);
    int count = 0;
    for (int c = 0; c < o->cm.n_cells; c++)
        for (int k = 0; k < 8; k++) {
            double p[3];
            gauss_point(o, o->x, c, k, p);
            const double d[3] = {p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]};
            if (cs_vec3_norm(d) > radius)
                continue;
            const size_t i = 8 * (size_t)c + k;
            if (f->which & CS_FIELD_YOUNG)
                o->fld.young[i] = f->young;
            if (f->which & CS_FIELD_DENSITY)
                o->fld.density[i] = f->density;
            if (f->which & CS_FIELD_DAMPING)
                o->fld.damping[i] = f->damping;
            count++;
        }
    if (cs_object_lump_mass(o) != 0) {
        free(load);
        free(old);
        return cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory");
    }
    rc = cs_object_check_stability(o, w->def.dt, "paint refused: ", err, errlen);
    if (rc != CS_OK) {
        memcpy(o->fld.young, old, nf * sizeof *old);
        memcpy(o->fld.density, old + nf, nf * sizeof *old);
        memcpy(o->fld.damping, old + 2 * nf, nf * sizeof *old);
        const int rc2 = cs_object_lump_mass(o); /* the masses as they were: f_const unchanged */
        free(load);
        free(old);
        return rc2 != 0 ? cs_engine_fail(err, errlen, CS_ERR_NOMEM, "out of memory") : rc;
    }
    free(old);
    for (int i = 0; i < o->n; i++)
        for (int a = 0; a < 3; a++)
            o->f_const[3 * i + a] = o->m[i] * g[a] + load[3 * i + a];
    free(load);
    o->elastic_energy_valid = false;
    if (count > 0) {
        o->sleeping = false;
        o->still_steps = 0;
        o->act_wake_all = true; /* frozen nodes (active regions) no longer balance */
    }
    if (touched)
        *touched = count;
    return CS_OK;
}

int cs_object_fields(const cs_world_t *w, cs_object_id id, const double **young,
                     const double **density, const double **damping, int *n)
{
    const cs_object *o = cs_world_find_internal(w, id);
    if (!o)
        return CS_ERR_UNKNOWN_OBJECT;
    if (young)
        *young = o->fld.young;
    if (density)
        *density = o->fld.density;
    if (damping)
        *damping = o->fld.damping;
    if (n)
        *n = o->cm.n_cells;
    return CS_OK;
}
