/*
 * scene.c — scene files: JSON in SI units (DESIGN.md "Contracts", README.md "Scene files") parsed with
 * cJSON into a cs_world_def and an array of cs_object_def ready for the engine.
 *
 * Owns: every byte an object def points to (names, mesh arrays, cells, fixed boxes, loads) —
 * one cs_scene_object_store per object, released by cs_scene_free. cJSON's tree lives only
 * during cs_scene_parse.
 *
 * Strictness is the point of this file: every key is checked against the list of the object it
 * sits in, every value for its type, finiteness and range, and the first problem is reported
 * with its JSON path ("objects[0].box.size[1]: ..."). Ranges match what cs_world_create and
 * cs_world_add_object accept, so a scene that parses is refused by the engine only for
 * geometric reasons (or a model not built yet).
 *
 * Mesh objects follow seed 000: load (assimp, common/mesh_io.c), place, check closed
 * (common/watertight.c), subdivide edges to at most h (§3.3, server/engine/voxelize.c); the
 * engine voxelizes (§2.1). Boxes become explicit cells.
 *
 * cJSON's global error pointer is not used: parse errors come from cJSON_ParseWithOpts'
 * return_parse_end, so parsing keeps no global state of ours.
 */
#include "scene.h"

#include <cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh.h"
#include "watertight.h"
#include "../server/engine/voxelize.h"

#define SC_PATH 320                /* longest JSON path we print */
#define SC_MAX_NAME 255            /* object name bytes (the engine's limit) */
#define SC_MAX_PER_AXIS 1024       /* cubes along one axis of a box, cell set or mesh */
/* cubes in one box or cell set, and in all of a scene's boxes and cell sets (2^24 until session
 * 31 would have taken 28 GB and the out-of-memory killer the daemon) */
#define SC_MAX_CELLS CS_MAX_SCENE_CUBES
#define SC_MAX_FILE (64L << 20)    /* scene file bytes */
#define SC_MAX_INDEX ((1 << 20) - 2) /* |i|, |j|, |k| of an explicit cell (the engine's lattice) */

struct cs_scene_object_store {
    char *name;
    double *mesh_v;
    int32_t *mesh_t;
    int32_t *ijk;
    cs_aabb *fixed;
    cs_load *loads;
    cs_field_region *fields;
    int shells, shells_turned; /* a mesh's shells and those wound inside out, turned */
};

typedef struct {
    char *err;
    size_t errlen;
} sc_ctx;

typedef struct {
    const char *name; /* points into the cJSON tree */
    cs_material m;
} sc_named_material;

/* Names to indices (open addressing, FNV-1a): duplicate names and material lookups in O(1)
 * each, so a scene of 400 000 materials or 8 000 objects parses in linear time (the pairwise
 * checks before took hours on the first). The names point into the cJSON tree. */
typedef struct {
    const char **key;
    int *val;
    size_t mask;
} sc_names;

static int names_init(sc_names *t, int n)
{
    size_t cap = 16;
    while (cap < 2 * (size_t)(n > 0 ? n : 1))
        cap *= 2;
    t->key = calloc(cap, sizeof *t->key);
    t->val = calloc(cap, sizeof *t->val);
    t->mask = cap - 1;
    return t->key && t->val ? 0 : -1;
}

static void names_free(sc_names *t)
{
    free(t->key);
    free(t->val);
    memset(t, 0, sizeof *t);
}

static size_t names_slot(const sc_names *t, const char *k)
{
    uint64_t h = 14695981039346656037ULL;
    for (const unsigned char *q = (const unsigned char *)k; *q; q++)
        h = (h ^ *q) * 1099511628211ULL;
    size_t i = (size_t)h & t->mask;
    while (t->key[i] && strcmp(t->key[i], k) != 0)
        i = (i + 1) & t->mask;
    return i;
}

/* The index stored under k, or -1. */
static int names_find(const sc_names *t, const char *k)
{
    if (!t->key)
        return -1;
    const size_t i = names_slot(t, k);
    return t->key[i] ? t->val[i] : -1;
}

/* Store k -> v unless k is there: returns the index already stored, or -1 (stored). The table
 * holds at most the n it was made for. */
static int names_add(sc_names *t, const char *k, int v)
{
    const size_t i = names_slot(t, k);
    if (t->key[i])
        return t->val[i];
    t->key[i] = k;
    t->val[i] = v;
    return -1;
}

/* ---------------------------------------------------------------- messages and paths */

/* How much of a name or other word from the file a message shows whole (bytes), and of the
 * scene file's own path. File paths in messages (meshes: CS_MSG_PATH, mesh.h) keep their end
 * when cut, names their start. The bounds keep both paths of the longest message that names
 * them and a name — "SCENE: objects[N] 'NAME': mesh 'MESH' is refused: WHY" — within the
 * daemon's 400-byte load acknowledgement (120 + 64 + 160 + 40 bytes of framing); only WHY
 * may be cut, and only when all three are at their bounds. */
#define SC_SHOW_NAME 64
#define SC_SHOW_SCENE CS_MSG_SCENE_PATH

/* s for a one-line message: whole up to SC_SHOW_NAME bytes, else its start and "…" (cut
 * between UTF-8 characters); control bytes become '?'. */
static const char *show(const char *s, char buf[SC_SHOW_NAME + 1])
{
    return cs_msg_text(s, buf, SC_SHOW_NAME + 1, 0);
}

static int fail(sc_ctx *c, const char *path, const char *fmt, ...)
{
    char msg[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (c->err && c->errlen) {
        if (path && path[0])
            snprintf(c->err, c->errlen, "%s: %s", path, msg);
        else
            snprintf(c->err, c->errlen, "%s", msg);
    }
    return -1;
}

/* A JSON path, truncated to SC_PATH bytes (vsnprintf: truncation here is intended). */
static void pathf(char out[SC_PATH], const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(out, SC_PATH, fmt, ap);
    va_end(ap);
}

static void join_key(char out[SC_PATH], const char *parent, const char *key)
{
    char b[SC_SHOW_NAME + 1];
    if (parent && parent[0])
        pathf(out, "%s.%s", parent, show(key, b));
    else
        pathf(out, "%s", show(key, b));
}

static void join_index(char out[SC_PATH], const char *parent, int i)
{
    pathf(out, "%s[%d]", parent, i);
}

static const char *type_name(const cJSON *it)
{
    if (cJSON_IsNumber(it))
        return "a number";
    if (cJSON_IsString(it))
        return "a string";
    if (cJSON_IsBool(it))
        return "a boolean";
    if (cJSON_IsNull(it))
        return "null";
    if (cJSON_IsArray(it))
        return "an array";
    if (cJSON_IsObject(it))
        return "an object";
    return "an invalid value";
}

/* Is b a near miss of a (a typo worth suggesting in an "unknown field" message)? Damerau-
 * Levenshtein distance at most 1 for short names, 2 for longer ones. */
static int near_miss(const char *a, const char *b)
{
    size_t la = strlen(a), lb = strlen(b), shorter = la < lb ? la : lb;
    int limit = shorter <= 5 ? 1 : 2;
    if (la > 40 || lb > 40 || (size_t)limit >= shorter + (shorter == 1) ||
        (la > lb ? la - lb : lb - la) > (size_t)limit)
        return 0;
    int d[41][41];
    for (size_t i = 0; i <= la; i++)
        d[i][0] = (int)i;
    for (size_t j = 0; j <= lb; j++)
        d[0][j] = (int)j;
    for (size_t i = 1; i <= la; i++)
        for (size_t j = 1; j <= lb; j++) {
            int best = d[i - 1][j - 1] + (a[i - 1] != b[j - 1]);
            if (d[i - 1][j] + 1 < best)
                best = d[i - 1][j] + 1;
            if (d[i][j - 1] + 1 < best)
                best = d[i][j - 1] + 1;
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] &&
                d[i - 2][j - 2] + 1 < best)
                best = d[i - 2][j - 2] + 1; /* transposition */
            d[i][j] = best;
        }
    return d[la][lb] <= limit;
}

/* Every key of obj must be in `allowed` (NULL-terminated) and appear once. */
static int check_keys(sc_ctx *c, const cJSON *obj, const char *path, const char *const *allowed)
{
    for (const cJSON *it = obj->child; it; it = it->next) {
        char p[SC_PATH];
        join_key(p, path, it->string);
        int known = 0;
        for (int i = 0; allowed[i]; i++)
            if (!strcmp(allowed[i], it->string))
                known = 1;
        if (!known) {
            for (int i = 0; allowed[i]; i++)
                if (near_miss(it->string, allowed[i]))
                    return fail(c, p, "unknown field (did you mean '%s'?)", allowed[i]);
            return fail(c, p, "unknown field");
        }
        for (const cJSON *q = obj->child; q != it; q = q->next)
            if (!strcmp(q->string, it->string))
                return fail(c, p, "duplicate field");
    }
    return 0;
}

/* ---------------------------------------------------------------- typed getters */

enum { LO_NONE, LO_GE, LO_GT };
enum { HI_NONE, HI_LE, HI_LT };

typedef struct {
    int lo_kind;
    double lo;
    int hi_kind;
    double hi;
} sc_range;

static const sc_range ANY = {LO_NONE, 0, HI_NONE, 0};
static const sc_range POSITIVE = {LO_GT, 0, HI_NONE, 0};
static const sc_range NONNEG = {LO_GE, 0, HI_NONE, 0};

static int check_range(sc_ctx *c, const char *path, double v, sc_range r)
{
    int lo_ok = r.lo_kind == LO_NONE || (r.lo_kind == LO_GE ? v >= r.lo : v > r.lo);
    int hi_ok = r.hi_kind == HI_NONE || (r.hi_kind == HI_LE ? v <= r.hi : v < r.hi);
    if (lo_ok && hi_ok)
        return 0;
    if (r.lo_kind != LO_NONE && r.hi_kind != HI_NONE)
        return fail(c, path, "must be in %c%g, %g%c, got %g", r.lo_kind == LO_GE ? '[' : '(',
                    r.lo, r.hi, r.hi_kind == HI_LE ? ']' : ')', v);
    if (r.lo_kind != LO_NONE)
        return fail(c, path, "must be %s %g, got %g", r.lo_kind == LO_GE ? ">=" : ">", r.lo, v);
    return fail(c, path, "must be %s %g, got %g", r.hi_kind == HI_LE ? "<=" : "<", r.hi, v);
}

static int number_value(sc_ctx *c, const cJSON *it, const char *path, double *out, sc_range r)
{
    if (!cJSON_IsNumber(it))
        return fail(c, path, "expected a number, got %s", type_name(it));
    if (!isfinite(it->valuedouble))
        return fail(c, path, "must be finite");
    if (check_range(c, path, it->valuedouble, r))
        return -1;
    *out = it->valuedouble;
    return 0;
}

/* Absent key: *out untouched, 0 (or an error if required). */
static int get_number(sc_ctx *c, const cJSON *obj, const char *path, const char *key,
                      double *out, sc_range r, int required)
{
    char p[SC_PATH];
    join_key(p, path, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it)
        return required ? fail(c, p, "missing required field") : 0;
    return number_value(c, it, p, out, r);
}

static int int_value(sc_ctx *c, const cJSON *it, const char *path, int *out, long lo, long hi)
{
    if (!cJSON_IsNumber(it))
        return fail(c, path, "expected an integer, got %s", type_name(it));
    double v = it->valuedouble;
    if (!isfinite(v) || v != floor(v))
        return fail(c, path, "expected an integer, got %g", v);
    if (v < (double)lo || v > (double)hi)
        return fail(c, path, "must be in [%ld, %ld], got %g", lo, hi, v);
    *out = (int)v;
    return 0;
}

static int get_int(sc_ctx *c, const cJSON *obj, const char *path, const char *key, int *out,
                   long lo, long hi)
{
    char p[SC_PATH];
    join_key(p, path, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it)
        return 0;
    return int_value(c, it, p, out, lo, hi);
}

static int get_bool(sc_ctx *c, const cJSON *obj, const char *path, const char *key, bool *out)
{
    char p[SC_PATH];
    join_key(p, path, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it)
        return 0;
    if (!cJSON_IsBool(it))
        return fail(c, p, "expected true or false, got %s", type_name(it));
    *out = cJSON_IsTrue(it);
    return 0;
}

/* An array of exactly n finite numbers, each in range r. */
static int vec_value(sc_ctx *c, const cJSON *it, const char *path, double *out, int n,
                     sc_range r)
{
    if (!cJSON_IsArray(it))
        return fail(c, path, "expected an array of %d numbers, got %s", n, type_name(it));
    if (cJSON_GetArraySize(it) != n)
        return fail(c, path, "expected an array of %d numbers, got %d elements", n,
                    cJSON_GetArraySize(it));
    int i = 0;
    for (const cJSON *e = it->child; e; e = e->next, i++) {
        char p[SC_PATH];
        join_index(p, path, i);
        if (number_value(c, e, p, &out[i], r))
            return -1;
    }
    return 0;
}

static int get_vec(sc_ctx *c, const cJSON *obj, const char *path, const char *key, double *out,
                   int n, sc_range r, int required)
{
    char p[SC_PATH];
    join_key(p, path, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it)
        return required ? fail(c, p, "missing required field") : 0;
    double tmp[8];
    if (vec_value(c, it, p, tmp, n, r))
        return -1;
    memcpy(out, tmp, (size_t)n * sizeof *out);
    return 0;
}

/* An object-valued field: *out is NULL when absent (and not required). */
static int get_object(sc_ctx *c, const cJSON *obj, const char *path, const char *key,
                      const cJSON **out, int required)
{
    char p[SC_PATH];
    join_key(p, path, key);
    *out = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!*out)
        return required ? fail(c, p, "missing required field") : 0;
    if (!cJSON_IsObject(*out))
        return fail(c, p, "expected an object, got %s", type_name(*out));
    return 0;
}

static int get_array(sc_ctx *c, const cJSON *obj, const char *path, const char *key,
                     const cJSON **out, int required)
{
    char p[SC_PATH];
    join_key(p, path, key);
    *out = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!*out)
        return required ? fail(c, p, "missing required field") : 0;
    if (!cJSON_IsArray(*out))
        return fail(c, p, "expected an array, got %s", type_name(*out));
    return 0;
}

/* ---------------------------------------------------------------- world-level sections */

static int parse_material(sc_ctx *c, const cJSON *m, const char *path, cs_material *out)
{
    static const char *const keys[] = {"young", "poisson", "density", "damping", "strength",
                                       "restitution", "friction", NULL};
    if (!cJSON_IsObject(m))
        return fail(c, path, "expected an object, got %s", type_name(m));
    if (check_keys(c, m, path, keys))
        return -1;
    cs_material r = cs_material_default();
    if (get_number(c, m, path, "young", &r.young, POSITIVE, 0) ||
        get_number(c, m, path, "poisson", &r.poisson, (sc_range){LO_GE, 0, HI_LT, 0.5}, 0) ||
        get_number(c, m, path, "density", &r.density, POSITIVE, 0) ||
        get_vec(c, m, path, "damping", r.damping, 2, NONNEG, 0) ||
        get_number(c, m, path, "strength", &r.strength, POSITIVE, 0) ||
        get_number(c, m, path, "restitution", &r.restitution, (sc_range){LO_GE, 0, HI_LE, 1}, 0) ||
        get_number(c, m, path, "friction", &r.friction, (sc_range){LO_GE, 0, HI_LE, 100}, 0))
        return -1;
    *out = r;
    return 0;
}

static int parse_materials(sc_ctx *c, const cJSON *root, sc_named_material **out, int *n,
                           sc_names *index)
{
    const cJSON *mats;
    *out = NULL;
    *n = 0;
    if (get_object(c, root, "", "materials", &mats, 0))
        return -1;
    if (!mats)
        return 0;
    int count = cJSON_GetArraySize(mats);
    if (count == 0)
        return 0;
    sc_named_material *m = calloc((size_t)count, sizeof *m);
    if (!m || names_init(index, count)) {
        free(m);
        names_free(index);
        return fail(c, "materials", "out of memory");
    }
    int i = 0;
    for (const cJSON *it = mats->child; it; it = it->next, i++) {
        char p[SC_PATH];
        join_key(p, "materials", it->string);
        if (!it->string[0]) {
            free(m);
            return fail(c, p, "a material name must not be empty");
        }
        if (names_add(index, it->string, i) >= 0) {
            free(m);
            return fail(c, p, "duplicate material");
        }
        m[i].name = it->string;
        if (parse_material(c, it, p, &m[i].m)) {
            free(m);
            return -1;
        }
    }
    *out = m;
    *n = count;
    return 0;
}

static int parse_world(sc_ctx *c, const cJSON *root, cs_scene *s)
{
    cs_world_def *w = &s->world;
    const cJSON *o;
    if (get_number(c, root, "", "dt", &w->dt, (sc_range){LO_GT, 0, HI_LE, 1}, 0) ||
        get_vec(c, root, "", "gravity", w->gravity, 3, ANY, 0) ||
        get_number(c, root, "", "publish_hz", &s->publish_hz, POSITIVE, 0) ||
        get_number(c, root, "", "keyframe_s", &s->keyframe_s, POSITIVE, 0) ||
        get_number(c, root, "", "status_hz", &s->status_hz, POSITIVE, 0) ||
        get_number(c, root, "", "publish_epsilon", &s->publish_epsilon, NONNEG, 0) ||
        get_number(c, root, "", "max_force", &w->max_force, POSITIVE, 0) ||
        get_int(c, root, "", "max_fractures", &w->max_fractures, 1, 1000000))
        return -1;
    double g = sqrt(w->gravity[0] * w->gravity[0] + w->gravity[1] * w->gravity[1] +
                    w->gravity[2] * w->gravity[2]);
    if (g > 1e4)
        return fail(c, "gravity", "magnitude must be <= 1e4 m/s^2, got %g", g);

    if (get_object(c, root, "", "ground", &o, 0))
        return -1;
    if (o) {
        static const char *const keys[] = {"height", "friction", NULL};
        w->has_ground = true;
        if (check_keys(c, o, "ground", keys) ||
            get_number(c, o, "ground", "height", &w->ground_height, ANY, 0) ||
            get_number(c, o, "ground", "friction", &w->ground_friction,
                       (sc_range){LO_GE, 0, HI_LE, 100}, 0))
            return -1;
    }
    if (get_object(c, root, "", "solver", &o, 0))
        return -1;
    if (o) {
        static const char *const keys[] = {"tolerance", "max_iterations", "threads",
                                           "preconditioner", "relative_to", "simd_width", NULL};
        if (check_keys(c, o, "solver", keys) ||
            get_number(c, o, "solver", "tolerance", &w->cg_tolerance,
                       (sc_range){LO_GT, 0, HI_LT, 1}, 0) ||
            get_int(c, o, "solver", "max_iterations", &w->cg_max_iterations, 1, 1000000) ||
            get_int(c, o, "solver", "threads", &w->threads, 0, 256) ||
            get_int(c, o, "solver", "simd_width", &w->simd_width, 0, 512))
            return -1;
        if (w->simd_width != 0 && w->simd_width != 256 && w->simd_width != 512)
            return fail(c, "solver.simd_width", "must be 0, 256 or 512, got %d", w->simd_width);
        const cJSON *pc = cJSON_GetObjectItemCaseSensitive(o, "preconditioner");
        if (pc) {
            char b[SC_SHOW_NAME + 1];
            if (!cJSON_IsString(pc))
                return fail(c, "solver.preconditioner", "expected a string, got %s",
                            type_name(pc));
            if (cs_preconditioner_from_name(pc->valuestring, &w->preconditioner) != 0)
                return fail(c, "solver.preconditioner",
                            "unknown preconditioner '%s' (auto, jacobi, multigrid)",
                            show(pc->valuestring, b));
        }
        const cJSON *rt = cJSON_GetObjectItemCaseSensitive(o, "relative_to");
        if (rt) {
            char b[SC_SHOW_NAME + 1];
            if (!cJSON_IsString(rt))
                return fail(c, "solver.relative_to", "expected a string, got %s", type_name(rt));
            if (cs_cg_relative_from_name(rt->valuestring, &w->cg_relative_to) != 0)
                return fail(c, "solver.relative_to", "unknown value '%s' (step, rhs)",
                            show(rt->valuestring, b));
        }
    }
    if (get_object(c, root, "", "sleep", &o, 0))
        return -1;
    if (o) {
        static const char *const keys[] = {"speed", "steps", NULL};
        if (check_keys(c, o, "sleep", keys) ||
            get_number(c, o, "sleep", "speed", &w->sleep_speed, NONNEG, 0) ||
            get_int(c, o, "sleep", "steps", &w->sleep_steps, 0, INT32_MAX))
            return -1;
    }
    /* active regions inside awake objects (cubesim.h active_steps, active_speed) */
    if (get_object(c, root, "", "active", &o, 0))
        return -1;
    if (o) {
        static const char *const keys[] = {"steps", "speed", NULL};
        if (check_keys(c, o, "active", keys) ||
            get_int(c, o, "active", "steps", &w->active_steps, 0, INT32_MAX) ||
            get_number(c, o, "active", "speed", &w->active_speed, POSITIVE, 0))
            return -1;
    }
    return 0;
}

/* ---------------------------------------------------------------- geometry */

static int parse_box(sc_ctx *c, const cJSON *box, const char *path, double h,
                     cs_object_def *d, cs_scene_object_store *st)
{
    static const char *const keys[] = {"min", "size", NULL};
    double mn[3], size[3];
    long n[3];
    if (check_keys(c, box, path, keys) || get_vec(c, box, path, "min", mn, 3, ANY, 1) ||
        get_vec(c, box, path, "size", size, 3, POSITIVE, 1))
        return -1;
    double total = 1;
    for (int a = 0; a < 3; a++) {
        char p[SC_PATH];
        pathf(p, "%s.size[%d]", path, a);
        double cubes = size[a] / h, r = round(cubes);
        if (!(r >= 1) || fabs(cubes - r) > 1e-6 * r)
            return fail(c, p, "%g m is not a whole number of cubes of %g m (%.9g cubes)", size[a],
                        h, cubes);
        if (r > SC_MAX_PER_AXIS)
            return fail(c, p, "%.16g cubes along this side; at most %d", r, SC_MAX_PER_AXIS);
        n[a] = (long)r;
        total *= r;
    }
    if (total > SC_MAX_CELLS)
        return fail(c, path, "%.16g cubes; at most %d", total, SC_MAX_CELLS);
    st->ijk = malloc((size_t)total * 3 * sizeof *st->ijk);
    if (!st->ijk)
        return fail(c, path, "out of memory for %.16g cubes", total);
    size_t q = 0;
    for (long k = 0; k < n[2]; k++)
        for (long j = 0; j < n[1]; j++)
            for (long i = 0; i < n[0]; i++) {
                st->ijk[q++] = (int32_t)i;
                st->ijk[q++] = (int32_t)j;
                st->ijk[q++] = (int32_t)k;
            }
    d->geometry = CS_GEOMETRY_CELLS;
    memcpy(d->cells_origin, mn, sizeof mn);
    d->cells_ijk = st->ijk;
    d->n_cells = (int)total;
    return 0;
}

typedef struct {
    int32_t v[3];
    int index;
} sc_cell_sort;

static int cmp_cell(const void *pa, const void *pb)
{
    const sc_cell_sort *a = pa, *b = pb;
    for (int k = 0; k < 3; k++)
        if (a->v[k] != b->v[k])
            return a->v[k] < b->v[k] ? -1 : 1;
    return a->index - b->index;
}

static int parse_cells(sc_ctx *c, const cJSON *cells, const char *path, cs_object_def *d,
                       cs_scene_object_store *st)
{
    static const char *const keys[] = {"origin", "ijk", NULL};
    double origin[3];
    const cJSON *ijk;
    char p[SC_PATH];
    if (check_keys(c, cells, path, keys) || get_vec(c, cells, path, "origin", origin, 3, ANY, 1) ||
        get_array(c, cells, path, "ijk", &ijk, 1))
        return -1;
    join_key(p, path, "ijk");
    int n = cJSON_GetArraySize(ijk);
    if (n == 0)
        return fail(c, p, "no cells given");
    if (n > SC_MAX_CELLS)
        return fail(c, p, "%d cells; at most %d", n, SC_MAX_CELLS);
    st->ijk = malloc((size_t)n * 3 * sizeof *st->ijk);
    sc_cell_sort *sorted = malloc((size_t)n * sizeof *sorted);
    if (!st->ijk || !sorted) {
        free(sorted);
        return fail(c, p, "out of memory for %d cells", n);
    }
    int lo[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, hi[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
    int i = 0;
    for (const cJSON *e = ijk->child; e; e = e->next, i++) {
        char pe[SC_PATH];
        join_index(pe, p, i);
        if (!cJSON_IsArray(e) || cJSON_GetArraySize(e) != 3) {
            free(sorted);
            return fail(c, pe, "expected an array of 3 integers, got %s", type_name(e));
        }
        int a = 0;
        for (const cJSON *x = e->child; x; x = x->next, a++) {
            char px[SC_PATH];
            int v = 0;
            join_index(px, pe, a);
            if (int_value(c, x, px, &v, -SC_MAX_INDEX, SC_MAX_INDEX)) {
                free(sorted);
                return -1;
            }
            st->ijk[3 * i + a] = sorted[i].v[a] = v;
            if (v < lo[a])
                lo[a] = v;
            if (v > hi[a])
                hi[a] = v;
        }
        sorted[i].index = i;
    }
    for (int a = 0; a < 3; a++)
        if (hi[a] - lo[a] + 1 > SC_MAX_PER_AXIS) {
            free(sorted);
            return fail(c, p, "cells span %d cubes along axis %c; at most %d", hi[a] - lo[a] + 1,
                        'x' + a, SC_MAX_PER_AXIS);
        }
    qsort(sorted, (size_t)n, sizeof *sorted, cmp_cell);
    for (int k = 1; k < n; k++)
        if (!memcmp(sorted[k].v, sorted[k - 1].v, sizeof sorted[k].v)) {
            char pe[SC_PATH];
            join_index(pe, p, sorted[k].index);
            int first = sorted[k - 1].index;
            int32_t v0 = sorted[k].v[0], v1 = sorted[k].v[1], v2 = sorted[k].v[2];
            free(sorted);
            return fail(c, pe, "duplicate cell [%d, %d, %d] (also at index %d)", (int)v0,
                        (int)v1, (int)v2, first);
        }
    free(sorted);
    d->geometry = CS_GEOMETRY_CELLS;
    memcpy(d->cells_origin, origin, sizeof origin);
    d->cells_ijk = st->ijk;
    d->n_cells = n;
    return 0;
}

static int parse_mesh(sc_ctx *c, const cJSON *mesh, const char *path, const char *base_dir,
                      int index, const char *name, double h, cs_object_def *d,
                      cs_scene_object_store *st)
{
    static const char *const keys[] = {"file", "scale", "position", "rotation_deg", NULL};
    double scale = 1, pos[3] = {0, 0, 0}, rot[3] = {0, 0, 0};
    char p[SC_PATH], b1[SC_SHOW_NAME + 1], b2[CS_MSG_PATH + 1];
    if (check_keys(c, mesh, path, keys))
        return -1;
    join_key(p, path, "file");
    const cJSON *file = cJSON_GetObjectItemCaseSensitive(mesh, "file");
    if (!file)
        return fail(c, p, "missing required field");
    if (!cJSON_IsString(file))
        return fail(c, p, "expected a string, got %s", type_name(file));
    if (!file->valuestring[0])
        return fail(c, p, "must not be empty");
    if (get_number(c, mesh, path, "scale", &scale, POSITIVE, 0) ||
        get_vec(c, mesh, path, "position", pos, 3, ANY, 0) ||
        get_vec(c, mesh, path, "rotation_deg", rot, 3, ANY, 0))
        return -1;

    const char *fname = file->valuestring;
    size_t need = strlen(fname) + (base_dir ? strlen(base_dir) : 0) + 2;
    char *full = malloc(need);
    if (!full)
        return fail(c, p, "out of memory");
    if (fname[0] == '/' || !base_dir || !base_dir[0])
        snprintf(full, need, "%s", fname);
    else
        snprintf(full, need, "%s/%s", base_dir, fname);

    char msg[400];
    cs_mesh m = {0};
    int rc = cs_mesh_load(full, &m, msg, sizeof msg);
    free(full);
    if (rc != 0)
        return fail(c, p, "%s", msg);
    cs_mesh_transform(&m, scale, rot, pos);

    /* Refuse before subdividing: a huge mesh at a tiny h would make billions of triangles. */
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < m.nv; i++)
        for (int a = 0; a < 3; a++) {
            double v = m.v[3 * i + a];
            if (!isfinite(v)) {
                cs_mesh_free(&m);
                return fail(c, path, "vertex %d is not finite after placing", i);
            }
            lo[a] = v < lo[a] ? v : lo[a];
            hi[a] = v > hi[a] ? v : hi[a];
        }
    for (int a = 0; a < 3; a++)
        if (m.nv > 0 && (hi[a] - lo[a]) / h > SC_MAX_PER_AXIS) {
            double span = (hi[a] - lo[a]) / h;
            cs_mesh_free(&m);
            pathf(p, "objects[%d].cube_size", index);
            return fail(c, p, "the mesh spans %.16g cubes of %g m along %c; at most %d", span, h,
                        'x' + a, SC_MAX_PER_AXIS);
        }

    cs_watertight_report rep;
    int closed = cs_watertight_check(m.v, m.nv, m.t, m.nt, &rep, msg, sizeof msg);
    if (!rep.boundary_edges && !rep.nonmanifold_edges && !rep.misoriented_edges &&
        !rep.degenerate_triangles) {
        /* closed and consistently oriented. Wound clockwise seen from outside as a whole (as
         * some formats import, e.g. DirectX .x): the orientation is unambiguous, so turn it
         * out. Then a shell wound inside out where no other encloses it (a part written with
         * the other winding, a mirrored glTF node, which assimp does not turn) is turned out
         * too; a cavity's wall, inward inside another shell, is kept. */
        if (rep.volume < 0)
            for (int i = 0; i < m.nt; i++) {
                int32_t tmp = m.t[3 * i + 1];
                m.t[3 * i + 1] = m.t[3 * i + 2];
                m.t[3 * i + 2] = tmp;
            }
        st->shells_turned = cs_mesh_orient_shells(m.v, m.nv, m.t, m.nt, &st->shells);
        if (st->shells_turned < 0) {
            cs_mesh_free(&m);
            return fail(c, "", "objects[%d] '%s': mesh '%s': out of memory", index,
                        show(name, b1), cs_msg_path(fname, b2, sizeof b2));
        }
        closed = cs_watertight_check(m.v, m.nv, m.t, m.nt, &rep, msg, sizeof msg);
    }
    if (closed != 1) {
        cs_mesh_free(&m);
        return fail(c, "", "objects[%d] '%s': mesh '%s' is refused: %s", index, show(name, b1),
                    cs_msg_path(fname, b2, sizeof b2), msg);
    }
    /* Far from the origin double precision spaces positions too coarsely for the cubes: at
     * 6e14 m they are 0.125 m apart, no edge there can be halved, and the subdivision ran
     * 15 s and took 3.5 GB before it gave up on its triangle bound (an outside check). */
    double far = 0; /* from the placed mesh's bounds above */
    for (int a = 0; a < 3; a++)
        far = fmax(far, fmax(fabs(lo[a]), fabs(hi[a])));
    if (nextafter(far, INFINITY) - far > h / 1024) {
        cs_mesh_free(&m);
        return fail(c, "", "objects[%d] '%s': mesh '%s' lies %.3g m from the origin, where "
                    "positions are %.3g m apart, more than cube_size/1024 (%g m): place it "
                    "nearer the origin", index, show(name, b1), cs_msg_path(fname, b2, sizeof b2),
                    far, nextafter(far, INFINITY) - far, h / 1024);
    }
    if (cs_subdivide_edges(&m.v, &m.nv, &m.t, &m.nt, h, msg, sizeof msg) != 0) {
        cs_mesh_free(&m);
        return fail(c, "", "objects[%d] '%s': mesh '%s': %s", index, show(name, b1),
                    cs_msg_path(fname, b2, sizeof b2), msg);
    }
    /* Subdivision must keep the surface closed (§3.3); check rather than trust. */
    if (cs_watertight_check(m.v, m.nv, m.t, m.nt, &rep, msg, sizeof msg) != 1) {
        cs_mesh_free(&m);
        return fail(c, "", "objects[%d] '%s': mesh '%s' is no longer closed after edge "
                    "subdivision: %s", index, show(name, b1), cs_msg_path(fname, b2, sizeof b2),
                    msg);
    }
    st->mesh_v = m.v;
    st->mesh_t = m.t;
    d->geometry = CS_GEOMETRY_MESH;
    d->mesh_vertices = m.v;
    d->n_mesh_vertices = m.nv;
    d->mesh_triangles = m.t;
    d->n_mesh_triangles = m.nt;
    return 0;
}

/* ---------------------------------------------------------------- boxes: fixed and loads */

static int parse_aabb(sc_ctx *c, const cJSON *e, const char *path, cs_aabb *out)
{
    if (get_vec(c, e, path, "min", out->min, 3, ANY, 1) ||
        get_vec(c, e, path, "max", out->max, 3, ANY, 1))
        return -1;
    for (int a = 0; a < 3; a++)
        if (out->min[a] > out->max[a])
            return fail(c, path, "min[%d] = %g is greater than max[%d] = %g", a, out->min[a], a,
                        out->max[a]);
    return 0;
}

/* One entry of "fixed" (a box) or of "loads" (a box and a force); item points at the
 * entry's slot in the array being filled. */
typedef int (*sc_entry_fn)(sc_ctx *c, const cJSON *e, const char *path, void *item);

static int parse_fixed_entry(sc_ctx *c, const cJSON *e, const char *path, void *item)
{
    return parse_aabb(c, e, path, item);
}

static int parse_load_entry(sc_ctx *c, const cJSON *e, const char *path, void *item)
{
    cs_load *ld = item;
    return parse_aabb(c, e, path, &ld->box) || get_vec(c, e, path, "force", ld->force, 3, ANY, 1)
               ? -1
               : 0;
}

/*
 * The optional array `key` of objects, each holding only `keys`: allocates *out (n elements
 * of `size` bytes, owned by the caller's store; NULL when absent or empty), sets *n, and
 * parses every entry with `entry`.
 */
static int parse_entries(sc_ctx *c, const cJSON *obj, const char *path, const char *key,
                         const char *const *keys, size_t size, sc_entry_fn entry, void **out,
                         int *n)
{
    const cJSON *arr;
    char p[SC_PATH];
    *n = 0;
    if (get_array(c, obj, path, key, &arr, 0))
        return -1;
    if (!arr || cJSON_GetArraySize(arr) == 0)
        return 0;
    join_key(p, path, key);
    const int count = cJSON_GetArraySize(arr);
    char *items = calloc((size_t)count, size);
    if (!items)
        return fail(c, p, "out of memory");
    *out = items;
    int i = 0;
    for (const cJSON *e = arr->child; e; e = e->next, i++) {
        char pe[SC_PATH];
        join_index(pe, p, i);
        if (!cJSON_IsObject(e))
            return fail(c, pe, "expected an object, got %s", type_name(e));
        if (check_keys(c, e, pe, keys) || entry(c, e, pe, items + (size_t)i * size))
            return -1;
    }
    *n = count;
    return 0;
}

static int parse_fixed(sc_ctx *c, const cJSON *obj, const char *path, cs_object_def *d,
                       cs_scene_object_store *st)
{
    static const char *const keys[] = {"min", "max", NULL};
    void *items = NULL;
    int rc = parse_entries(c, obj, path, "fixed", keys, sizeof *st->fixed, parse_fixed_entry,
                           &items, &d->n_fixed);
    st->fixed = items;
    d->fixed = st->fixed;
    return rc;
}

static int parse_loads(sc_ctx *c, const cJSON *obj, const char *path, cs_object_def *d,
                       cs_scene_object_store *st)
{
    static const char *const keys[] = {"min", "max", "force", NULL};
    void *items = NULL;
    int rc = parse_entries(c, obj, path, "loads", keys, sizeof *st->loads, parse_load_entry,
                           &items, &d->n_loads);
    st->loads = items;
    d->loads = st->loads;
    return rc;
}

/* One entry of "fields": {"shape": "sphere"|"box"|"gradient"|"radial", its geometry,
 * and at least one of "young", "density", "damping" (factors on the material)}. */
static int parse_field_entry(sc_ctx *c, const cJSON *e, const char *path, void *item)
{
    static const char *const shapes[] = {"sphere", "box", "gradient", "radial"};
    /* geometry keys each shape needs; every other geometry key is refused */
    static const char *const need[4][2] = {
        {"centre", "radius"}, {"min", "max"}, {"from", "to"}, {"centre", "radius"}};
    static const char *const geo_keys[] = {"centre", "radius", "min", "max", "from", "to"};
    cs_field_region *r = item;
    char p[SC_PATH], b[SC_SHOW_NAME + 1];
    join_key(p, path, "shape");
    const cJSON *sh = cJSON_GetObjectItemCaseSensitive(e, "shape");
    if (!sh)
        return fail(c, p, "missing required field (sphere, box, gradient or radial)");
    if (!cJSON_IsString(sh))
        return fail(c, p, "expected a string, got %s", type_name(sh));
    int k = -1;
    for (int i = 0; i < 4; i++)
        if (!strcmp(sh->valuestring, shapes[i]))
            k = i;
    if (k < 0)
        return fail(c, p, "unknown shape '%s' (sphere, box, gradient, radial)",
                    show(sh->valuestring, b));
    r->shape = (cs_field_shape)k;
    for (int g = 0; g < 6; g++) {
        const bool wanted = !strcmp(geo_keys[g], need[k][0]) || !strcmp(geo_keys[g], need[k][1]);
        const bool given = cJSON_GetObjectItemCaseSensitive(e, geo_keys[g]) != NULL;
        if (given && !wanted) {
            join_key(p, path, geo_keys[g]);
            return fail(c, p, "does not apply to shape '%s' (it takes %s and %s)", shapes[k],
                        need[k][0], need[k][1]);
        }
    }
    int rc = 0;
    switch (r->shape) {
    case CS_FIELD_SPHERE:
    case CS_FIELD_RADIAL:
        rc = get_vec(c, e, path, "centre", r->centre, 3, ANY, 1) ||
             get_number(c, e, path, "radius", &r->radius, POSITIVE, 1);
        break;
    case CS_FIELD_BOX:
        rc = parse_aabb(c, e, path, &r->box);
        break;
    case CS_FIELD_GRADIENT:
        rc = get_vec(c, e, path, "from", r->from, 3, ANY, 1) ||
             get_vec(c, e, path, "to", r->to, 3, ANY, 1);
        if (!rc && r->from[0] == r->to[0] && r->from[1] == r->to[1] && r->from[2] == r->to[2])
            return fail(c, path, "gradient 'from' and 'to' must differ");
        break;
    }
    if (rc)
        return -1;
    static const sc_range FACTOR = {LO_GE, 1e-6, HI_LE, 1e6};
    static const sc_range DAMPING_FACTOR = {LO_GE, 0, HI_LE, 1e6};
    cs_field_factors *f = &r->factors;
    static const char *const fk[] = {"young", "density", "damping"};
    double *fv[] = {&f->young, &f->density, &f->damping};
    for (int i = 0; i < 3; i++) {
        if (!cJSON_GetObjectItemCaseSensitive(e, fk[i]))
            continue;
        if (get_number(c, e, path, fk[i], fv[i], i == 2 ? DAMPING_FACTOR : FACTOR, 1))
            return -1;
        f->which |= 1u << i;
    }
    if (!f->which)
        return fail(c, path, "give at least one factor: young, density or damping");
    return 0;
}

static int parse_fields(sc_ctx *c, const cJSON *obj, const char *path, cs_object_def *d,
                        cs_scene_object_store *st)
{
    static const char *const keys[] = {"shape", "centre", "radius", "min", "max", "from",
                                       "to", "young", "density", "damping", NULL};
    void *items = NULL;
    int rc = parse_entries(c, obj, path, "fields", keys, sizeof *st->fields, parse_field_entry,
                           &items, &d->n_fields);
    st->fields = items;
    d->fields = st->fields;
    return rc;
}

/* "constraints": "remove" (default) or "penalty"; "penalty_stiffness" [N/m] (penalty only). */
static int parse_constraints(sc_ctx *c, const cJSON *o, const char *path, cs_object_def *d)
{
    char p[SC_PATH], b[SC_SHOW_NAME + 1];
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(o, "constraints");
    if (it) {
        join_key(p, path, "constraints");
        if (!cJSON_IsString(it))
            return fail(c, p, "expected a string, got %s", type_name(it));
        if (!strcmp(it->valuestring, "remove"))
            d->constraints = CS_CONSTRAINT_REMOVE;
        else if (!strcmp(it->valuestring, "penalty"))
            d->constraints = CS_CONSTRAINT_PENALTY;
        else
            return fail(c, p, "unknown mode '%s' (remove, penalty)", show(it->valuestring, b));
    }
    if (cJSON_GetObjectItemCaseSensitive(o, "penalty_stiffness")) {
        join_key(p, path, "penalty_stiffness");
        if (d->constraints != CS_CONSTRAINT_PENALTY)
            return fail(c, p, "only applies with \"constraints\": \"penalty\"");
        static const sc_range PEN = {LO_GT, 0, HI_LE, 1e15};
        if (get_number(c, o, path, "penalty_stiffness", &d->penalty_stiffness, PEN, 1))
            return -1;
    }
    return 0;
}

/* ---------------------------------------------------------------- objects */

/* "strain_limit": 0 (none) or in [CS_STRAIN_LIMIT_MIN, CS_STRAIN_LIMIT_MAX]. */
static int parse_strain_limit(sc_ctx *c, const cJSON *o, const char *path, cs_object_def *d)
{
    static const sc_range R = {LO_GE, 0, HI_LE, CS_STRAIN_LIMIT_MAX};
    char p[SC_PATH];
    if (get_number(c, o, path, "strain_limit", &d->strain_limit, R, 0))
        return -1;
    if (d->strain_limit != 0 && d->strain_limit < CS_STRAIN_LIMIT_MIN) {
        join_key(p, path, "strain_limit");
        return fail(c, p, "must be 0 (none) or in [%g, %g], got %g", CS_STRAIN_LIMIT_MIN,
                    CS_STRAIN_LIMIT_MAX, d->strain_limit);
    }
    return 0;
}

static int parse_object(sc_ctx *c, const cJSON *o, int index, const char *base_dir,
                        const sc_named_material *mats, const sc_names *mat_index,
                        sc_names *obj_index, cs_object_def *d, cs_scene_object_store *st)
{
    static const char *const keys[] = {"name",  "model", "integrator", "material", "cube_size",
                                       "fracture", "fracture_radius", "box", "mesh", "cells",
                                       "fixed", "loads", "fields", "constraints",
                                       "penalty_stiffness", "strain_limit", NULL};
    char path[SC_PATH], p[SC_PATH], b[SC_SHOW_NAME + 1];
    join_index(path, "objects", index);
    if (!cJSON_IsObject(o))
        return fail(c, path, "expected an object, got %s", type_name(o));
    if (check_keys(c, o, path, keys))
        return -1;
    *d = cs_object_def_default();

    join_key(p, path, "name");
    const cJSON *name = cJSON_GetObjectItemCaseSensitive(o, "name");
    if (!name)
        return fail(c, p, "missing required field");
    if (!cJSON_IsString(name))
        return fail(c, p, "expected a string, got %s", type_name(name));
    size_t len = strlen(name->valuestring);
    if (len == 0 || len > SC_MAX_NAME)
        return fail(c, p, "must have 1 to %d bytes, got %zu", SC_MAX_NAME, len);
    /* Names travel in one-line messages and on the bus: no control characters. */
    for (size_t i = 0; i < len; i++)
        if ((unsigned char)name->valuestring[i] < 0x20 || name->valuestring[i] == 0x7f)
            return fail(c, p, "must not contain control characters");
    const int other = names_add(obj_index, name->valuestring, index);
    if (other >= 0)
        return fail(c, p, "duplicate object name '%s' (also objects[%d])",
                    show(name->valuestring, b), other);
    st->name = strdup(name->valuestring);
    if (!st->name)
        return fail(c, p, "out of memory");
    d->name = st->name;

    const cJSON *it = cJSON_GetObjectItemCaseSensitive(o, "model");
    if (it) {
        join_key(p, path, "model");
        if (!cJSON_IsString(it))
            return fail(c, p, "expected a string, got %s", type_name(it));
        if (cs_model_from_name(it->valuestring, &d->model) != 0)
            return fail(c, p, "unknown model '%s' (linear, corotational, mss, localframe, rigid)",
                        show(it->valuestring, b));
    }

    it = cJSON_GetObjectItemCaseSensitive(o, "integrator");
    if (it) {
        join_key(p, path, "integrator");
        if (!cJSON_IsString(it))
            return fail(c, p, "expected a string, got %s", type_name(it));
        if (cs_integrator_from_name(it->valuestring, &d->integrator) != 0)
            return fail(c, p,
                        "unknown integrator '%s' (default, implicit_euler, symplectic_euler, "
                        "verlet, central_difference, newmark)",
                        show(it->valuestring, b));
    }

    it = cJSON_GetObjectItemCaseSensitive(o, "material");
    if (it) {
        join_key(p, path, "material");
        if (cJSON_IsString(it)) {
            const int found = names_find(mat_index, it->valuestring);
            if (found < 0)
                return fail(c, p, "unknown material '%s'", show(it->valuestring, b));
            d->material = mats[found].m;
        } else if (cJSON_IsObject(it)) {
            if (parse_material(c, it, p, &d->material))
                return -1;
        } else {
            return fail(c, p, "expected a material name or an object, got %s", type_name(it));
        }
    }
    if (get_number(c, o, path, "cube_size", &d->cube_size, POSITIVE, 0) ||
        get_bool(c, o, path, "fracture", &d->fracture) ||
        get_number(c, o, path, "fracture_radius", &d->fracture_radius, NONNEG, 0) ||
        parse_strain_limit(c, o, path, d) ||
        parse_fixed(c, o, path, d, st) ||
        parse_loads(c, o, path, d, st) ||
        parse_fields(c, o, path, d, st) ||
        parse_constraints(c, o, path, d))
        return -1;

    static const char *const geo[] = {"box", "mesh", "cells"};
    const cJSON *g[3];
    int ng = 0;
    for (int k = 0; k < 3; k++) {
        if (get_object(c, o, path, geo[k], &g[k], 0))
            return -1;
        ng += g[k] != NULL;
    }
    if (ng == 0)
        return fail(c, path, "missing geometry: give one of \"box\", \"mesh\" or \"cells\"");
    if (ng > 1)
        return fail(c, path, "give exactly one of \"box\", \"mesh\" or \"cells\", not %d", ng);
    if (g[0]) {
        join_key(p, path, "box");
        return parse_box(c, g[0], p, d->cube_size, d, st);
    }
    if (g[1]) {
        join_key(p, path, "mesh");
        return parse_mesh(c, g[1], p, base_dir, index, d->name, d->cube_size, d, st);
    }
    join_key(p, path, "cells");
    return parse_cells(c, g[2], p, d, st);
}

/* ---------------------------------------------------------------- entry points */

static void sc_defaults(cs_scene *s)
{
    memset(s, 0, sizeof *s);
    s->world = cs_world_def_default();
    s->publish_hz = 60;
    s->keyframe_s = 2;
    s->status_hz = 4;
    s->publish_epsilon = 1e-6;
}

void cs_scene_free(cs_scene *s)
{
    if (!s)
        return;
    if (s->store) {
        for (int i = 0; i < s->n_objects; i++) {
            cs_scene_object_store *st = &s->store[i];
            free(st->name);
            free(st->mesh_v);
            free(st->mesh_t);
            free(st->ijk);
            free(st->fixed);
            free(st->loads);
            free(st->fields);
        }
    }
    free(s->store);
    free(s->objects);
    memset(s, 0, sizeof *s);
}

static int parse_error(sc_ctx *c, const char *json, const char *at)
{
    size_t len = strlen(json);
    size_t off = at && at >= json && (size_t)(at - json) <= len ? (size_t)(at - json) : len;
    int line = 1, col = 1;
    for (size_t i = 0; i < off; i++) {
        if (json[i] == '\n') {
            line++;
            col = 1;
        } else {
            col++;
        }
    }
    if (len == 0)
        return fail(c, "", "malformed JSON at line 1, column 1: the text is empty");
    char near[SC_SHOW_NAME + 1];
    char tmp[24];
    snprintf(tmp, sizeof tmp, "%.20s", json + off);
    if (off >= len)
        return fail(c, "", "malformed JSON at line %d, column %d: unexpected end of text", line,
                    col);
    return fail(c, "", "malformed JSON at line %d, column %d near '%s'", line, col,
                show(tmp, near));
}

int cs_scene_parse(const char *json, const char *base_dir, cs_scene *out, char *err,
                   size_t errlen)
{
    sc_ctx ctx = {err, errlen}, *c = &ctx;
    static const char *const keys[] = {"dt",         "gravity",   "publish_hz",
                                       "ground",     "solver",    "materials",
                                       "objects",    "keyframe_s", "status_hz",
                                       "publish_epsilon", "sleep", "max_force",
                                       "max_fractures", "active", NULL};
    if (err && errlen)
        err[0] = '\0';
    if (!out)
        return fail(c, "", "no output scene given");
    sc_defaults(out);
    if (!json)
        return fail(c, "", "no scene text given");

    const char *end = NULL;
    cJSON *root = cJSON_ParseWithOpts(json, &end, 1);
    if (!root)
        return parse_error(c, json, end);
    sc_named_material *mats = NULL;
    sc_names mat_index = {0}, obj_index = {0};
    int n_mats = 0, rc = -1;
    const cJSON *objs;
    if (!cJSON_IsObject(root)) {
        fail(c, "", "the scene must be a JSON object, got %s", type_name(root));
        goto done;
    }
    if (check_keys(c, root, "", keys) || parse_world(c, root, out) ||
        parse_materials(c, root, &mats, &n_mats, &mat_index) ||
        get_array(c, root, "", "objects", &objs, 1))
        goto done;

    int n = cJSON_GetArraySize(objs);
    if (n > 0) {
        out->objects = calloc((size_t)n, sizeof *out->objects);
        out->store = calloc((size_t)n, sizeof *out->store);
        if (!out->objects || !out->store || names_init(&obj_index, n)) {
            fail(c, "objects", "out of memory");
            goto done;
        }
    }
    int i = 0;
    double cubes = 0; /* of the boxes and cell sets so far */
    for (const cJSON *o = objs->child; o; o = o->next, i++) {
        /* Count the object before parsing so cs_scene_free releases its partial storage. */
        out->n_objects = i + 1;
        if (parse_object(c, o, i, base_dir, mats, &mat_index, &obj_index, &out->objects[i],
                         &out->store[i]))
            goto done;
        if (out->objects[i].geometry == CS_GEOMETRY_CELLS)
            cubes += out->objects[i].n_cells;
        if (cubes > SC_MAX_CELLS) {
            char p[SC_PATH];
            pathf(p, "objects[%d]", i);
            fail(c, p, "the scene's boxes and cell sets hold %.16g cubes with this one; at most "
                       "%d in all (about 7 GB)", cubes, SC_MAX_CELLS);
            goto done;
        }
    }
    rc = 0;
done:
    free(mats);
    names_free(&mat_index);
    names_free(&obj_index);
    cJSON_Delete(root);
    if (rc != 0) {
        cs_scene_free(out);
        sc_defaults(out);
    }
    return rc;
}

int cs_scene_load(const char *path, cs_scene *out, char *err, size_t errlen)
{
    sc_ctx ctx = {err, errlen}, *c = &ctx;
    if (out)
        sc_defaults(out);
    if (!path || !out)
        return fail(c, "", "no scene path or output given");
    char shown[SC_SHOW_SCENE + 1]; /* the path as its messages name it */
    cs_msg_path(path, shown, sizeof shown);
    FILE *f = fopen(path, "rb");
    if (!f)
        return fail(c, shown, "cannot open: %s", strerror(errno));
    char *text = NULL;
    size_t len = 0, cap = 0;
    for (;;) {
        if (len + 4096 + 1 > cap) {
            cap = cap ? 2 * cap : 16384;
            char *t = realloc(text, cap);
            if (!t) {
                free(text);
                fclose(f);
                return fail(c, shown, "out of memory reading the file");
            }
            text = t;
        }
        size_t got = fread(text + len, 1, cap - len - 1, f);
        len += got;
        if (got == 0)
            break;
        if ((long)len > SC_MAX_FILE) {
            free(text);
            fclose(f);
            return fail(c, shown, "larger than %ld bytes: not a scene", SC_MAX_FILE);
        }
    }
    int rerr = ferror(f);
    fclose(f);
    if (rerr) {
        free(text);
        return fail(c, shown, "read error");
    }
    text[len] = '\0';
    if (memchr(text, '\0', len)) {
        free(text);
        return fail(c, shown, "contains a NUL byte: not a JSON text");
    }

    /* Meshes are found relative to the scene file's folder. */
    char *dir = strdup(path);
    if (!dir) {
        free(text);
        return fail(c, shown, "out of memory");
    }
    char *slash = strrchr(dir, '/');
    if (slash == dir)
        slash[1] = '\0'; /* "/scene.json": the root folder */
    else if (slash)
        *slash = '\0';
    else
        strcpy(dir, ".");

    char msg[512];
    int rc = cs_scene_parse(text, dir, out, msg, sizeof msg);
    free(dir);
    free(text);
    if (rc != 0)
        return fail(c, shown, "%s", msg);
    return 0;
}

int cs_scene_instantiate(const cs_scene *s, cs_world_t **out, char *err, size_t errlen)
{
    sc_ctx ctx = {err, errlen}, *c = &ctx;
    char msg[400], b[SC_SHOW_NAME + 1];
    cs_world_t *w = NULL;
    if (out)
        *out = NULL;
    if (!s || !out)
        return fail(c, "", "no scene or output given");
    if (cs_world_create(&s->world, &w, msg, sizeof msg) != 0)
        return fail(c, "", "world: %s", msg);
    for (int i = 0; i < s->n_objects; i++) {
        cs_object_id id;
        if (cs_world_add_object(w, &s->objects[i], &id, msg, sizeof msg) != 0) {
            cs_world_destroy(w);
            return fail(c, "", "objects[%d] '%s': %s", i, show(s->objects[i].name, b), msg);
        }
    }
    *out = w;
    return 0;
}

int cs_scene_coarse_object(const cs_scene *s, const cs_world_t *w, int i, char *msg, size_t n)
{
    if (!s || !w || i < 0 || i >= s->n_objects)
        return 0;
    const cs_object_def *o = &s->objects[i];
    cs_object_info info;
    const cs_object_id id = cs_world_find_object(w, o->name);
    if (o->geometry != CS_GEOMETRY_MESH || id == CS_NULL_OBJECT ||
        cs_object_get_info(w, id, &info) != CS_OK)
        return 0;
    const double mv = cs_mesh_volume(o->mesh_vertices, o->mesh_triangles, o->n_mesh_triangles);
    if (!(mv > 0) || !(info.volume >= CS_SCENE_COARSE_RATIO * mv))
        return 0;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int v = 0; v < o->n_mesh_vertices; v++)
        for (int a = 0; a < 3; a++) {
            lo[a] = fmin(lo[a], o->mesh_vertices[3 * v + a]);
            hi[a] = fmax(hi[a], o->mesh_vertices[3 * v + a]);
        }
    char b[SC_SHOW_NAME + 1];
    snprintf(msg, n,
             "objects[%d] '%s': its %d cube%s of %g m hold%s %.3g m^3, %.3g times the %.3g m^3 "
             "its mesh encloses (%.3g x %.3g x %.3g m): cube_size is coarse for this mesh, its "
             "mass and stiffness are the cubes'",
             i, show(o->name, b), info.n_cells, info.n_cells == 1 ? "" : "s", info.cube_size,
             info.n_cells == 1 ? "s" : "", info.volume, info.volume / mv, mv, hi[0] - lo[0],
             hi[1] - lo[1], hi[2] - lo[2]);
    return 1;
}

int cs_scene_turned_shells(const cs_scene *s, int i, char *msg, size_t n)
{
    if (!s || i < 0 || i >= s->n_objects || !s->store || s->store[i].shells_turned <= 0)
        return 0;
    const cs_scene_object_store *st = &s->store[i];
    char b[SC_SHOW_NAME + 1];
    snprintf(msg, n,
             "objects[%d] '%s': %d of its mesh's %d shells %s wound inside out (a part's outer "
             "wall and what lies in it): turned outward (a cavity's wall, inward inside another "
             "shell, is kept)",
             i, show(s->objects[i].name, b), st->shells_turned, st->shells,
             st->shells_turned == 1 ? "was" : "were");
    return 1;
}

int cs_scene_below_ground_object(const cs_scene *s, const cs_world_t *w, int i, char *msg,
                                 size_t n)
{
    if (!s || !w || i < 0 || i >= s->n_objects || !s->world.has_ground)
        return 0;
    const cs_object_def *o = &s->objects[i];
    const cs_object_id id = cs_world_find_object(w, o->name);
    cs_object_info info;
    const double *rest, *x, *v;
    int nn;
    if (id == CS_NULL_OBJECT || cs_object_get_info(w, id, &info) != CS_OK ||
        cs_object_nodes(w, id, &rest, &x, &v, &nn) != CS_OK || nn <= 0)
        return 0;
    double zmin = INFINITY;
    for (int k = 0; k < nn; k++)
        zmin = fmin(zmin, x[3 * k + 2]);
    const double depth = s->world.ground_height - zmin;
    if (!(depth > 1e-3 * info.cube_size))
        return 0;
    char b[SC_SHOW_NAME + 1];
    snprintf(msg, n,
             "objects[%d] '%s': starts %.3g m below the ground (z = %g): it is pushed up onto "
             "the plane (%s), place it on or above the ground",
             i, show(o->name, b), depth, s->world.ground_height,
             info.model == CS_MODEL_RIGID ? "by its contacts, a little each step"
                                          : "in its first step, compressed and thrown up by "
                                            "the depth");
    return 1;
}
