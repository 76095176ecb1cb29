/*
 * fuzz_surface_state.c — libFuzzer target: a client's surface state (common/surface_state.c)
 * fed a sequence of snapshot chunks, deltas, topology changes and poses whose fields come
 * from the input (counts small, values mostly near the valid range, some huge, floats with
 * NaN and infinities), as the clients build them from decoded LCM messages (arrays as long as
 * their counts say, which lcm-gen's decoding guarantees). Nothing may crash, leak or read out
 * of bounds; a rejection is fine. Built and run by `make fuzz` (clang; see the Makefile).
 */
#include "surface_state.h"
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
typedef struct {
    const uint8_t *p;
    size_t n, i;
} rd;
static uint8_t u8(rd *r)
{
    return r->i < r->n ? r->p[r->i++] : 0;
}
static int32_t si(rd *r)
{
    uint8_t b = u8(r);
    if (b < 200)
        return (int32_t)(b % 24) - 2;
    if (b < 250) {
        uint32_t lo = u8(r), hi = u8(r);
        return (int32_t)(lo | hi << 8);
    }
    uint32_t v = 0;
    for (int k = 0; k < 4; k++)
        v |= (uint32_t)u8(r) << (8 * k);
    return (int32_t)v;
}
static float fl(rd *r)
{
    uint8_t b = u8(r);
    if (b == 255)
        return NAN;
    if (b == 254)
        return INFINITY;
    if (b == 253)
        return 1e30f;
    return (float)((int)b - 100) * 0.01f;
}
static int32_t *ia(rd *r, int n)
{
    int32_t *a = malloc(sizeof(int32_t) * (n ? n : 1));
    if (!a)
        abort(); /* the harness only: a few hundred bytes */
    for (int k = 0; k < n; k++)
        a[k] = si(r);
    return a;
}
static float *fa(rd *r, int n)
{
    float *a = malloc(sizeof(float) * (n ? n : 1));
    if (!a)
        abort(); /* the harness only: a few hundred bytes */
    for (int k = 0; k < n; k++)
        a[k] = fl(r);
    return a;
}
static int cnt(rd *r)
{
    return u8(r) % 40;
}
static cs_ss_header hdr(rd *r, int64_t *frame)
{
    *frame += u8(r) % 3;
    cs_ss_header h = {1 + (u8(r) % 2), u8(r) % 2, *frame, *frame + (u8(r) % 3),
                      0.01 * (double)*frame};
    return h;
}
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    rd r = {data, size, 0};
    cs_surface_state st;
    cs_surface_state_init(&st);
    st.track_volume = u8(&r) & 1;
    int64_t frame = 0;
    char err[300];
    for (int op = 0; op < 64 && r.i < r.n; op++) {
        switch (u8(&r) % 4) {
        case 0: {
            cs_ss_chunk c = {0};
            c.header = hdr(&r, &frame);
            c.snapshot_id = si(&r);
            c.chunk = si(&r);
            c.n_chunks = si(&r);
            c.n_objects = si(&r);
            c.object_id = si(&r);
            c.object_name = (u8(&r) & 1) ? "a" : "";
            c.model = "fem";
            c.topology_version = si(&r);
            c.n_vertices_total = si(&r);
            c.n_triangles_total = si(&r);
            c.vertex_offset = si(&r);
            c.n_coords = cnt(&r);
            float *x = fa(&r, c.n_coords);
            c.xyz = x;
            c.triangle_offset = si(&r);
            c.n_indices = cnt(&r);
            int32_t *ix = ia(&r, c.n_indices);
            c.indices = ix;
            cs_surface_state_apply_chunk(&st, &c, err, sizeof err);
            free(x);
            free(ix);
            break;
        }
        case 1: {
            cs_ss_delta d = {0};
            d.header = hdr(&r, &frame);
            d.object_id = si(&r);
            d.topology_version = si(&r);
            d.chunk = si(&r);
            d.n_chunks = si(&r);
            d.n_vertices_total = si(&r);
            d.n = cnt(&r);
            int32_t *ix = ia(&r, d.n);
            d.index = ix;
            d.n_coords = cnt(&r);
            float *x = fa(&r, d.n_coords);
            d.xyz = x;
            cs_surface_state_apply_delta(&st, &d, err, sizeof err);
            free(x);
            free(ix);
            break;
        }
        case 2: {
            cs_ss_topo t = {0};
            t.header = hdr(&r, &frame);
            t.change_id = si(&r);
            t.chunk = si(&r);
            t.n_chunks = si(&r);
            t.object_id = si(&r);
            t.parent_id = si(&r);
            t.name = "p";
            t.model = "fem";
            t.from_version = si(&r);
            t.to_version = si(&r);
            t.n_vertices_total = si(&r);
            t.n_triangles_total = si(&r);
            t.total_vremove = si(&r);
            t.total_vnew = si(&r);
            t.total_tremove = si(&r);
            t.total_tset = si(&r);
            t.total_tnew = si(&r);
            t.vremove_offset = si(&r);
            t.n_vremove = cnt(&r);
            int32_t *a = ia(&r, t.n_vremove);
            t.vremove = a;
            t.vnew_offset = si(&r);
            t.n_vnew_coords = cnt(&r);
            float *b = fa(&r, t.n_vnew_coords);
            t.vnew_xyz = b;
            t.tremove_offset = si(&r);
            t.n_tremove = cnt(&r);
            int32_t *c = ia(&r, t.n_tremove);
            t.tremove = c;
            t.tset_offset = si(&r);
            t.n_tset = cnt(&r);
            int32_t *d = ia(&r, t.n_tset);
            t.tset_index = d;
            t.n_tset_indices = cnt(&r);
            int32_t *e = ia(&r, t.n_tset_indices);
            t.tset_tri = e;
            t.tnew_offset = si(&r);
            t.n_tnew_indices = cnt(&r);
            int32_t *f = ia(&r, t.n_tnew_indices);
            t.tnew = f;
            t.n_vnew_src = cnt(&r);
            int32_t *g = ia(&r, t.n_vnew_src);
            t.vnew_src = g;
            cs_surface_state_apply_topology(&st, &t, err, sizeof err);
            free(a);
            free(b);
            free(c);
            free(d);
            free(e);
            free(f);
            free(g);
            break;
        }
        default: {
            cs_ss_pose p = {0};
            p.header = hdr(&r, &frame);
            p.object_id = si(&r);
            p.topology_version = si(&r);
            p.n_vertices_total = si(&r);
            p.reference = si(&r);
            for (int k = 0; k < 3; k++)
                p.position[k] = fl(&r);
            for (int k = 0; k < 4; k++)
                p.orientation[k] = fl(&r);
            cs_surface_state_apply_pose(&st, &p, err, sizeof err);
            break;
        }
        }
    }
    cs_mesh *pieces = NULL;
    char **names = NULL;
    int n = 0;
    if (cs_surface_state_to_meshes(&st, &pieces, &names, &n, err, sizeof err) == 0)
        cs_surface_state_meshes_free(pieces, names, n);
    cs_surface_state_free(&st);
    return 0;
}
