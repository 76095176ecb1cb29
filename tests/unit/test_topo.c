/*
 * test_topo.c — common/topo.c, the one implementation of a surface topology change that the
 * engine, the daemon's mirror and every client share: each of the five steps in its fixed
 * order, swap-remove semantics, a new piece, and the refusals of cs_topo_check.
 */
#include "check.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "topo.h"

/* Vertices are tagged by their x coordinate so their slots can be followed. */
static void tagged(double *v, int n)
{
    for (int i = 0; i < n; i++) {
        v[3 * i] = 10 + i;
        v[3 * i + 1] = 0;
        v[3 * i + 2] = 0;
    }
}

TEST(topo_swap_remove_vertices)
{
    double v[15];
    tagged(v, 5); /* a b c d e = 10 11 12 13 14 */
    static const int32_t rm[2] = {3, 1};
    cs_topo_change c = {0};
    c.n_vremove = 2;
    c.vremove = rm;
    /* remove 3: e moves into 3 -> a b c e; remove 1: e moves into 1 -> a e c */
    int n = cs_topo_remove_vertices(&c, v, 3 * sizeof(double), 5);
    ENSURE(n == 3);
    ENSURE(v[0] == 10 && v[3] == 14 && v[6] == 12);
    /* removing the last slot moves nothing */
    static const int32_t rm_last[1] = {2};
    c.n_vremove = 1;
    c.vremove = rm_last;
    n = cs_topo_remove_vertices(&c, v, 3 * sizeof(double), 3);
    ENSURE(n == 2 && v[0] == 10 && v[3] == 14);
}

/* The tetrahedron 0..3 taken through all five steps. */
static const int32_t tet_t[12] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
static const int32_t full_vrm[1] = {1};
static const double full_vnew[6] = {0.5, 0.5, 0.5, 0.25, 0.25, 0.25};
static const int32_t full_trm[2] = {3, 0};
static const int32_t full_tset_i[1] = {1};
static const int32_t full_tset_t[3] = {0, 4, 3};
static const int32_t full_tnew[3] = {3, 4, 2};

static cs_topo_change full_change(void)
{
    cs_topo_change c = {0};
    c.object_id = 7;
    c.from_version = 1;
    c.to_version = 2;
    c.n_vertices_total = 5;
    c.n_triangles_total = 3;
    c.n_vremove = 1;
    c.vremove = full_vrm;
    c.n_vnew = 2;
    c.vnew_xyz = full_vnew;
    c.n_tremove = 2;
    c.tremove = full_trm;
    c.n_tset = 1;
    c.tset_index = full_tset_i;
    c.tset_tri = full_tset_t;
    c.n_tnew = 1;
    c.tnew = full_tnew;
    return c;
}

TEST(topo_five_steps_in_order)
{
    cs_topo_change c = full_change();
    char err[200] = "";
    ENSURE_MSG(cs_topo_check(&c, 4, 4, err, sizeof err) == 0, "%s", err);
    double v[15];
    tagged(v, 4);
    /* 1. vremove [1]: vertex 3 moves into slot 1 -> 10 13 12 */
    int nv = cs_topo_remove_vertices(&c, v, 3 * sizeof(double), 4);
    ENSURE(nv == 3 && v[0] == 10 && v[3] == 13 && v[6] == 12);
    /* 2. vnew appended at 3, 4 */
    memcpy(v + 3 * nv, c.vnew_xyz, 6 * sizeof(double));
    nv += c.n_vnew;
    ENSURE(nv == c.n_vertices_total && v[9] == 0.5 && v[12] == 0.25);
    /* 3. tremove [3, 0]: t = [t0 t1 t2 t3] -> [t0 t1 t2] -> [t2 t1];
     * 4. tset slot 1 = {0 4 3}; 5. tnew {3 4 2} appended. */
    int32_t t[12];
    memcpy(t, tet_t, sizeof t);
    int nt = cs_topo_apply_triangles(&c, t, 4);
    static const int32_t want[9] = {0, 3, 2, 0, 4, 3, 3, 4, 2};
    ENSURE(nt == 3);
    ENSURE(memcmp(t, want, sizeof want) == 0);
    /* A per-triangle side array follows step 3 the same way. */
    int tag[4] = {100, 101, 102, 103};
    ENSURE(cs_topo_remove_triangles(&c, tag, sizeof tag[0], 4) == 2);
    ENSURE(tag[0] == 102 && tag[1] == 101);
}

TEST(topo_new_piece_from_empty)
{
    static const double vn[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    cs_topo_change c = {0};
    c.object_id = 9;
    c.parent_id = 7;
    c.name = "tet.1";
    c.model = "corotational";
    c.from_version = 0;
    c.to_version = 1;
    c.n_vertices_total = 4;
    c.n_triangles_total = 4;
    c.n_vnew = 4;
    c.vnew_xyz = vn;
    c.n_tnew = 4;
    c.tnew = tet_t;
    char err[200] = "";
    ENSURE_MSG(cs_topo_check(&c, 0, 0, err, sizeof err) == 0, "%s", err);
    /* a new piece's sources index its parent's vertices, which the check does not hold:
     * any index >= -1 passes */
    static const int32_t src[4] = {-1, 0, 17, 3};
    c.vnew_src = src;
    ENSURE_MSG(cs_topo_check(&c, 0, 0, err, sizeof err) == 0, "%s", err);
    double v[12];
    ENSURE(cs_topo_remove_vertices(&c, v, sizeof v[0] * 3, 0) == 0);
    int32_t t[12];
    ENSURE(cs_topo_apply_triangles(&c, t, 0) == 4);
    ENSURE(memcmp(t, tet_t, sizeof t) == 0);
}

TEST(topo_check_refusals)
{
    char err[200];
    cs_topo_change c;
    /* each case: one field broken, the message names it */
    struct {
        const char *why;
        int nv, nt;
        const char *want;
    } cases[] = {
        {"versions", 4, 4, "to_version"},
        {"vremove ascending", 5, 4, "vremove[1]"},
        {"vremove out of range", 4, 4, "vremove[0]"},
        {"tremove not descending", 4, 4, "tremove[1]"},
        {"vertex total", 4, 4, "vertices, total"},
        {"triangle total", 4, 4, "triangles, total"},
        {"NaN position", 4, 4, "not finite"},
        {"tset slot out of range", 4, 4, "tset_index[0]"},
        {"rewired index out of range", 4, 4, "rewired triangle 0"},
        {"new triangle index out of range", 4, 4, "new triangle 0"},
        {"repeated vertex", 4, 4, "repeats a vertex"},
        {"missing array", 4, 4, "missing array"},
        {"negative count", 4, 4, "negative count"},
        {"source beyond the vertices before the change", 4, 4, "copy of vertex 4"},
        {"source below -1", 4, 4, "copy of vertex -2"},
    };
    static const int32_t src_big[2] = {1, 4}, src_neg[2] = {-2, 0};
    static const int32_t asc[2] = {0, 1}, big[1] = {4}, trm_eq[2] = {2, 2};
    static const int32_t bad_slot[1] = {2}, bad_tri[3] = {0, 1, 5}, rep_tri[3] = {3, 3, 2};
    static const double nan_v[6] = {0, 0, 0, NAN, 0, 0};
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        c = full_change();
        switch (k) {
        case 0: c.to_version = c.from_version; break;
        case 1: c.n_vremove = 2; c.vremove = asc; c.n_vertices_total = 5; break;
        case 2: c.vremove = big; break;
        case 3: c.tremove = trm_eq; break;
        case 4: c.n_vertices_total = 6; break;
        case 5: c.n_triangles_total = 4; break;
        case 6: c.vnew_xyz = nan_v; break;
        case 7: c.tset_index = bad_slot; break;
        case 8: c.tset_tri = bad_tri; break;
        case 9: c.tnew = bad_tri; break;
        case 10: c.tnew = rep_tri; break;
        case 11: c.tremove = NULL; break;
        case 12: c.n_tnew = -1; break;
        case 13: c.vnew_src = src_big; break;
        case 14: c.vnew_src = src_neg; break;
        }
        memset(err, 0, sizeof err);
        ENSURE_MSG(cs_topo_check(&c, cases[k].nv, cases[k].nt, err, sizeof err) == -1,
                   "case '%s' accepted", cases[k].why);
        ENSURE_MSG(strstr(err, cases[k].want) != NULL, "case '%s': message '%s' lacks '%s'",
                   cases[k].why, err, cases[k].want);
    }
    ENSURE(cs_topo_check(NULL, 0, 0, err, sizeof err) == -1);
}
