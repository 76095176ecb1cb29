/*
 * topo.c — applying and checking a surface topology change (see topo.h for the order of the
 * five steps). One implementation for the engine, the daemon's mirror and every client, so
 * that all of them end with the same arrays.
 */
#include "topo.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int fail(char *err, size_t errlen, const char *fmt, ...)
{
    if (err && errlen) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err, errlen, fmt, ap);
        va_end(ap);
    }
    return -1;
}

static int check_desc(const int32_t *idx, int n, int count, const char *what, char *err,
                      size_t errlen)
{
    for (int i = 0; i < n; i++) {
        if (idx[i] < 0 || idx[i] >= count - i)
            return fail(err, errlen, what, (long)i, (long)idx[i]);
        if (i > 0 && idx[i] >= idx[i - 1])
            return fail(err, errlen, what, (long)i, (long)idx[i]);
    }
    return 0;
}

int cs_topo_check(const cs_topo_change *c, int nv, int nt, char *err, size_t errlen)
{
    if (!c)
        return fail(err, errlen, "topology change is NULL");
    if (c->to_version <= c->from_version)
        return fail(err, errlen, "topology to_version %ld is not after from_version %ld",
                    (long)c->to_version, (long)c->from_version);
    if (c->n_vremove < 0 || c->n_vnew < 0 || c->n_tremove < 0 || c->n_tset < 0 ||
        c->n_tnew < 0 || c->n_vertices_total < 0 || c->n_triangles_total < 0)
        return fail(err, errlen, "topology change has a negative count");
    if ((c->n_vremove && !c->vremove) || (c->n_vnew && !c->vnew_xyz) ||
        (c->n_tremove && !c->tremove) || (c->n_tset && (!c->tset_index || !c->tset_tri)) ||
        (c->n_tnew && !c->tnew))
        return fail(err, errlen, "topology change has a missing array");
    if (check_desc(c->vremove, c->n_vremove, nv,
                   "topology vremove[%ld] = %ld is out of range or not descending", err,
                   errlen))
        return -1;
    if (check_desc(c->tremove, c->n_tremove, nt,
                   "topology tremove[%ld] = %ld is out of range or not descending", err,
                   errlen))
        return -1;
    long nv1 = (long)nv - c->n_vremove + c->n_vnew;
    long nt1 = (long)nt - c->n_tremove;
    if (nv1 != c->n_vertices_total)
        return fail(err, errlen, "topology change leaves %ld vertices, total says %ld", nv1,
                    (long)c->n_vertices_total);
    if (nt1 + c->n_tnew != c->n_triangles_total)
        return fail(err, errlen, "topology change leaves %ld triangles, total says %ld",
                    nt1 + c->n_tnew, (long)c->n_triangles_total);
    for (int i = 0; i < 3 * c->n_vnew; i++)
        if (!isfinite(c->vnew_xyz[i]))
            return fail(err, errlen, "topology new vertex %ld is not finite", (long)(i / 3));
    for (int i = 0; c->vnew_src && i < c->n_vnew; i++)
        if (c->vnew_src[i] < -1 || (c->from_version > 0 && c->vnew_src[i] >= nv))
            return fail(err, errlen, "topology new vertex %ld is a copy of vertex %ld, out of "
                        "range", (long)i, (long)c->vnew_src[i]);
    for (int i = 0; i < c->n_tset; i++) {
        if (c->tset_index[i] < 0 || c->tset_index[i] >= nt1)
            return fail(err, errlen, "topology tset_index[%ld] = %ld is out of range", (long)i,
                        (long)c->tset_index[i]);
        const int32_t *t = c->tset_tri + 3 * i;
        for (int k = 0; k < 3; k++)
            if (t[k] < 0 || t[k] >= nv1)
                return fail(err, errlen, "topology rewired triangle %ld has index %ld out of "
                            "range", (long)i, (long)t[k]);
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
            return fail(err, errlen, "topology rewired triangle %ld repeats a vertex", (long)i);
    }
    for (int i = 0; i < c->n_tnew; i++) {
        const int32_t *t = c->tnew + 3 * i;
        for (int k = 0; k < 3; k++)
            if (t[k] < 0 || t[k] >= nv1)
                return fail(err, errlen, "topology new triangle %ld has index %ld out of range",
                            (long)i, (long)t[k]);
        if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
            return fail(err, errlen, "topology new triangle %ld repeats a vertex", (long)i);
    }
    return 0;
}

static int swap_remove(const int32_t *idx, int n, void *arr, size_t elem, int count)
{
    unsigned char *a = arr;
    for (int i = 0; i < n; i++) {
        int last = count - 1;
        if (idx[i] != last)
            memcpy(a + (size_t)idx[i] * elem, a + (size_t)last * elem, elem);
        count = last;
    }
    return count;
}

int cs_topo_remove_vertices(const cs_topo_change *c, void *arr, size_t elem, int nv)
{
    return swap_remove(c->vremove, c->n_vremove, arr, elem, nv);
}

int cs_topo_remove_triangles(const cs_topo_change *c, void *arr, size_t elem, int nt)
{
    return swap_remove(c->tremove, c->n_tremove, arr, elem, nt);
}

int cs_topo_apply_triangles(const cs_topo_change *c, int32_t *tris, int nt)
{
    nt = cs_topo_remove_triangles(c, tris, 3 * sizeof *tris, nt);
    for (int i = 0; i < c->n_tset; i++)
        memcpy(tris + 3 * (size_t)c->tset_index[i], c->tset_tri + 3 * (size_t)i,
               3 * sizeof *tris);
    if (c->n_tnew)
        memcpy(tris + 3 * (size_t)nt, c->tnew, 3 * (size_t)c->n_tnew * sizeof *tris);
    return nt + c->n_tnew;
}
