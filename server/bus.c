/*
 * bus.c — the daemon's LCM adapter (see bus.h for ownership and invariants; DESIGN.md "Bus").
 *
 * Inputs are subscribed raw (lcm_subscribe, not the generated typed subscribe) so that a
 * message that does not decode — another type's fingerprint, or truncated bytes — gets our
 * own one-line warning naming the channel instead of LCM's anonymous "error -1 decoding".
 */
#include "bus.h"
#include "number.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <unistd.h>

#include <lcm/lcm.h>

#include "cubesim_ack_t.h"
#include "cubesim_command_t.h"
#include "cubesim_curve_t.h"
#include "cubesim_paint_t.h"
#include "cubesim_pressure_t.h"
#include "cubesim_delta_t.h"
#include "cubesim_pose_t.h"
#include "surface_state.h"
#include "cubesim_force_t.h"
#include "cubesim_snapshot_t.h"
#include "cubesim_status_t.h"
#include "cubesim_topology_t.h"

typedef struct outmsg {
    const char *channel; /* one of the CS_CH_* literals */
    void *data;
    int len;
    int32_t snapshot_id; /* > 0 for snapshot chunks */
} outmsg;

typedef struct sent_object {
    cs_object_id id;
    uint32_t topology_version;
    int nv, nt;
    float *xyz; /* 3·nv: the floats last sent */
    bool settled; /* asleep, and its last motion already compared and sent */
    /* rigid objects: the reference pose last sent (lcmtypes/pose_t.lcm) and the copy then */
    bool has_ref;
    float *ref_xyz;
    double ref_q[4], ref_c[3];
} sent_object;

struct cs_bus {
    lcm_t *lcm;
    lcm_subscription_t *sub_force, *sub_command, *sub_paint, *sub_pressure, *sub_curve;
    cs_dlog *log;
    double max_force;

    /* header context */
    int64_t session_id;
    int32_t epoch;
    int64_t frame;
    double sim_time;
    int64_t seq_snapshot, seq_delta, seq_status, seq_ack, seq_topology, seq_pose;
    int32_t change_id;            /* last topology change sent */

    /* decoded inputs: a ring */
    cs_input *in;
    int in_head, in_count;

    /* outbox: a ring of encoded messages */
    outmsg *out;
    int out_cap, out_head, out_count;
    size_t out_bytes;
    double credit, credit_time;
    double rate;      /* bytes/s of the bucket, set by outbox_push */

    int32_t snapshot_id;          /* last made */
    int32_t pending_snapshot_id;  /* queued, first chunk not yet sent; 0 if none */

    sent_object *sent;
    int n_sent, cap_sent;

    /* scratch reused by deltas */
    int32_t *scratch_index;
    float *scratch_xyz;
    int scratch_cap;
};

void cs_input_clear(cs_input *in)
{
    free(in->object_name);
    free(in->argument);
    free(in->points);
    memset(in, 0, sizeof *in);
}

/* ---------------------------------------------------------------- inputs */

static cs_input *push_input(cs_bus_t *b)
{
    if (b->in_count >= CS_BUS_INPUT_MAX)
        return NULL;
    cs_input *x = &b->in[(b->in_head + b->in_count) % CS_BUS_INPUT_MAX];
    memset(x, 0, sizeof *x);
    b->in_count++;
    return x;
}

int cs_bus_next_input(cs_bus_t *b, cs_input *in)
{
    if (b->in_count == 0)
        return 0;
    *in = b->in[b->in_head];
    memset(&b->in[b->in_head], 0, sizeof b->in[b->in_head]);
    b->in_head = (b->in_head + 1) % CS_BUS_INPUT_MAX;
    b->in_count--;
    return 1;
}

static bool finite3(const double v[3])
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

static char *dup_str(const char *s)
{
    size_t n = s ? strlen(s) : 0;
    char *d = malloc(n + 1);
    if (d) {
        if (n)
            memcpy(d, s, n);
        d[n] = 0;
    }
    return d;
}

/* Refuse the input: its error is acked when the daemon pops it; logged once here. */
static void refuse(cs_bus_t *b, cs_input *x, const char *fmt, const char *detail)
{
    snprintf(x->error, sizeof x->error, fmt, detail);
    /* Limited per client: one noisy client cannot hide another's errors. */
    char key[48];
    snprintf(key, sizeof key, "refused input, client %lld", (long long)x->client_id);
    cs_dlog_warn(b->log, key, "refused %s from client %lld (command %lld): %s",
                 x->request, (long long)x->client_id, (long long)x->command_id, x->error);
}

static void validate_force(cs_bus_t *b, cs_input *x)
{
    char num[64];
    if (x->force_kind != CUBESIM_FORCE_T_POINT && x->force_kind != CUBESIM_FORCE_T_DRAG) {
        snprintf(num, sizeof num, "%d", (int)x->force_kind);
        refuse(b, x, "force: unknown kind %s (0 = point, 1 = drag)", num);
    } else if (x->object_id <= 0 && (!x->object_name || !x->object_name[0])) {
        /* force_t: by object_id when > 0, else by object_name (a negative id included) */
        refuse(b, x, "force: no object given (object_id is not > 0 and object_name empty)%s",
               "");
    } else if (!finite3(x->point)) {
        refuse(b, x, "force: point is not finite%s", "");
    } else if (!isfinite(x->duration)) {
        refuse(b, x, "force: duration is not finite%s", "");
    } else if (x->duration < 0) {
        snprintf(num, sizeof num, "%g", x->duration);
        refuse(b, x, "force: negative duration %s s", num);
    } else if (x->force_kind == CUBESIM_FORCE_T_POINT) {
        if (!finite3(x->force)) {
            refuse(b, x, "force: force vector is not finite%s", "");
        } else {
            /* hypot: the squares of a finite 1e300 N force overflow (the refusal quoted inf) */
            double m = hypot(hypot(x->force[0], x->force[1]), x->force[2]);
            if (m > b->max_force) {
                snprintf(num, sizeof num, "%g N exceeds max_force %g N", m, b->max_force);
                refuse(b, x, "force: |force| = %s", num);
            }
        }
    } else {
        if (!finite3(x->target))
            refuse(b, x, "force: drag target is not finite%s", "");
        else if (!isfinite(x->stiffness))
            refuse(b, x, "force: drag stiffness is not finite%s", "");
        else if (x->stiffness <= 0) {
            snprintf(num, sizeof num, "%g", x->stiffness);
            refuse(b, x, "force: drag stiffness %s N/m is not positive", num);
        }
    }
}

/*
 * lcm-gen's decoders trust a string's length prefix: a negative one makes them memcpy through
 * a NULL malloc, a missing '\0' makes the string unterminated, and a failure after a string
 * leaks it. So the raw bytes are walked first: `layout` lists fixed field sizes in bytes, with
 * -1 for a string (int32 length including '\0', then the bytes, the last one '\0'), ending
 * with 0. The message must be exactly as long as its fields.
 */
static bool well_formed_at(const void *data, uint32_t size, const int *layout, size_t *end);

static bool well_formed(const void *data, uint32_t size, const int *layout)
{
    size_t end = 0;
    return well_formed_at(data, size, layout, &end) && end == size;
}

/* The walk of well_formed, leaving the end of the fields in *end (the message may go on). */
static bool well_formed_at(const void *data, uint32_t size, const int *layout, size_t *end)
{
    const unsigned char *p = data;
    size_t pos = 0;
    for (; *layout; layout++) {
        if (*layout > 0) {
            pos += (size_t)*layout;
            if (pos > size)
                return false;
            continue;
        }
        if (pos + 4 > size)
            return false;
        uint32_t len = ((uint32_t)p[pos] << 24) | ((uint32_t)p[pos + 1] << 16) |
                       ((uint32_t)p[pos + 2] << 8) | (uint32_t)p[pos + 3];
        pos += 4;
        if (len < 1 || len > size - pos || p[pos + len - 1] != 0)
            return false;
        pos += len;
    }
    *end = pos;
    return true;
}

/* force_t: hash, client_id, command_id, object_id, object_name, kind, point, force, target,
 * stiffness, duration. command_t: hash, client_id, command_id, command, count, argument. */
static const int force_layout[] = {8, 8, 8, 4, -1, 1, 24, 24, 24, 8, 8, 0};
static const int command_layout[] = {8, 8, 8, -1, 4, -1, 0};

static void on_force(const lcm_recv_buf_t *rbuf, const char *channel, void *user)
{
    cs_bus_t *b = user;
    cubesim_force_t m;
    memset(&m, 0, sizeof m);
    int rc = -1;
    if (well_formed(rbuf->data, rbuf->data_size, force_layout))
        rc = cubesim_force_t_decode(rbuf->data, 0, (int)rbuf->data_size, &m);
    if (rc < 0) {
        cubesim_force_t_decode_cleanup(&m); /* what a failed decode left behind */
        cs_dlog_warn(b->log, "undecodable " CS_CH_FORCE,
                     "ignored a message on %s that is not a cubesim.force_t (%u bytes: "
                     "another type, truncated or malformed)",
                     channel, (unsigned)rbuf->data_size);
        return;
    }
    cs_input *x = push_input(b);
    if (!x) {
        cs_input tmp;
        memset(&tmp, 0, sizeof tmp);
        tmp.kind = CS_INPUT_FORCE;
        tmp.client_id = m.client_id;
        tmp.command_id = m.command_id;
        snprintf(tmp.request, sizeof tmp.request, "force");
        cs_dlog_warn(b->log, "input queue full", "input queue full: refused a force");
        cs_bus_ack(b, &tmp, false, "daemon input queue full; force dropped");
        cubesim_force_t_decode_cleanup(&m);
        return;
    }
    x->kind = CS_INPUT_FORCE;
    x->client_id = m.client_id;
    x->command_id = m.command_id;
    snprintf(x->request, sizeof x->request, "force");
    x->object_id = m.object_id;
    x->object_name = dup_str(m.object_name);
    x->force_kind = m.kind;
    memcpy(x->point, m.point, sizeof x->point);
    memcpy(x->force, m.force, sizeof x->force);
    memcpy(x->target, m.target, sizeof x->target);
    x->stiffness = m.stiffness;
    x->duration = m.duration;
    if (!x->object_name)
        snprintf(x->error, sizeof x->error, "daemon out of memory");
    else
        validate_force(b, x);
    cubesim_force_t_decode_cleanup(&m);
}

/* paint_t: hash, client_id, command_id, object_id, object_name, centre, radius, which, young,
 * density, damping. pressure_t: hash, ids, object, pressure, duration. curve_t: hash, ids,
 * object, stiffness, duration, n_points, then 24 bytes per point. */
static const int paint_layout[] = {8, 8, 8, 4, -1, 24, 8, 1, 8, 8, 8, 0};
static const int pressure_layout[] = {8, 8, 8, 4, -1, 8, 8, 0};
static const int curve_head_layout[] = {8, 8, 8, 4, -1, 8, 8, 4, 0};

static bool curve_well_formed(const void *data, uint32_t size)
{
    size_t end = 0;
    if (!well_formed_at(data, size, curve_head_layout, &end))
        return false;
    const unsigned char *p = (const unsigned char *)data + end - 4;
    const int32_t n = (int32_t)(((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) |
                                ((uint32_t)p[2] << 8) | (uint32_t)p[3]);
    return n >= 0 && n <= 1 << 16 && end + 24 * (size_t)n == size;
}

/* A slot for a decoded sculpting input of `request`, or NULL after acking "queue full". */
static cs_input *sculpt_slot(cs_bus_t *b, cs_input_kind kind, const char *request,
                             int64_t client_id, int64_t command_id)
{
    cs_input *x = push_input(b);
    if (!x) {
        cs_input tmp;
        memset(&tmp, 0, sizeof tmp);
        tmp.kind = kind;
        tmp.client_id = client_id;
        tmp.command_id = command_id;
        snprintf(tmp.request, sizeof tmp.request, "%s", request);
        cs_dlog_warn(b->log, "input queue full", "input queue full: refused a %s", request);
        cs_bus_ack(b, &tmp, false, "daemon input queue full; input dropped");
        return NULL;
    }
    x->kind = kind;
    x->client_id = client_id;
    x->command_id = command_id;
    snprintf(x->request, sizeof x->request, "%s", request);
    return x;
}

/* The object of a sculpting input; false (and refused) when none is given. */
static bool sculpt_object(cs_bus_t *b, cs_input *x, int32_t object_id, const char *name)
{
    char msg[96];
    x->object_id = object_id;
    x->object_name = dup_str(name);
    if (!x->object_name) {
        snprintf(x->error, sizeof x->error, "daemon out of memory");
        return false;
    }
    /* by object_id when > 0, else by object_name (a negative id included), as the types say */
    if (object_id <= 0 && !x->object_name[0]) {
        snprintf(msg, sizeof msg,
                 "%s: no object given (object_id is not > 0 and object_name empty)", x->request);
        refuse(b, x, "%s", msg);
        return false;
    }
    return true;
}

static void undecodable(cs_bus_t *b, const char *channel, const char *type, uint32_t size)
{
    char key[64];
    snprintf(key, sizeof key, "undecodable %s", channel);
    cs_dlog_warn(b->log, key,
                 "ignored a message on %s that is not a cubesim.%s (%u bytes: another type, "
                 "truncated or malformed)",
                 channel, type, (unsigned)size);
}

static void on_paint(const lcm_recv_buf_t *rbuf, const char *channel, void *user)
{
    cs_bus_t *b = user;
    cubesim_paint_t m;
    memset(&m, 0, sizeof m);
    int rc = -1;
    if (well_formed(rbuf->data, rbuf->data_size, paint_layout))
        rc = cubesim_paint_t_decode(rbuf->data, 0, (int)rbuf->data_size, &m);
    if (rc < 0) {
        cubesim_paint_t_decode_cleanup(&m);
        undecodable(b, channel, "paint_t", rbuf->data_size);
        return;
    }
    cs_input *x = sculpt_slot(b, CS_INPUT_PAINT, "paint", m.client_id, m.command_id);
    if (x && sculpt_object(b, x, m.object_id, m.object_name)) {
        char num[96];
        memcpy(x->point, m.centre, sizeof x->point);
        x->radius = m.radius;
        x->factors = (cs_field_factors){.young = m.young, .density = m.density,
                                        .damping = m.damping, .which = (uint8_t)m.which};
        if (!finite3(m.centre))
            refuse(b, x, "paint: centre is not finite%s", "");
        else if (!(m.radius > 0 && isfinite(m.radius))) {
            snprintf(num, sizeof num, "%g", m.radius);
            refuse(b, x, "paint: radius %s m is not positive and finite", num);
        } else if (!(m.which & 7) || (m.which & ~7)) {
            snprintf(num, sizeof num, "%d", (int)m.which);
            refuse(b, x, "paint: which = %s; give bits 1 (young), 2 (density), 4 (damping)",
                   num);
        }
        /* factor ranges: the engine's one-line message (cs_world_paint) */
    }
    cubesim_paint_t_decode_cleanup(&m);
}

static void on_pressure(const lcm_recv_buf_t *rbuf, const char *channel, void *user)
{
    cs_bus_t *b = user;
    cubesim_pressure_t m;
    memset(&m, 0, sizeof m);
    int rc = -1;
    if (well_formed(rbuf->data, rbuf->data_size, pressure_layout))
        rc = cubesim_pressure_t_decode(rbuf->data, 0, (int)rbuf->data_size, &m);
    if (rc < 0) {
        cubesim_pressure_t_decode_cleanup(&m);
        undecodable(b, channel, "pressure_t", rbuf->data_size);
        return;
    }
    cs_input *x = sculpt_slot(b, CS_INPUT_PRESSURE, "pressure", m.client_id, m.command_id);
    if (x && sculpt_object(b, x, m.object_id, m.object_name)) {
        char num[64];
        x->pressure = m.pressure;
        x->duration = m.duration;
        if (!isfinite(m.pressure))
            refuse(b, x, "pressure: pressure is not finite%s", "");
        else if (!(m.duration >= 0 && isfinite(m.duration))) {
            snprintf(num, sizeof num, "%g", m.duration);
            refuse(b, x, "pressure: duration %s s is negative or not finite", num);
        }
    }
    cubesim_pressure_t_decode_cleanup(&m);
}

static void on_curve(const lcm_recv_buf_t *rbuf, const char *channel, void *user)
{
    cs_bus_t *b = user;
    cubesim_curve_t m;
    memset(&m, 0, sizeof m);
    int rc = -1;
    if (curve_well_formed(rbuf->data, rbuf->data_size))
        rc = cubesim_curve_t_decode(rbuf->data, 0, (int)rbuf->data_size, &m);
    if (rc < 0) {
        cubesim_curve_t_decode_cleanup(&m);
        undecodable(b, channel, "curve_t", rbuf->data_size);
        return;
    }
    cs_input *x = sculpt_slot(b, CS_INPUT_CURVE, "curve", m.client_id, m.command_id);
    if (x && sculpt_object(b, x, m.object_id, m.object_name)) {
        char num[64];
        x->stiffness = m.stiffness;
        x->duration = m.duration;
        bool finite = true;
        if (m.n_points >= 2 && m.n_points <= CS_MAX_CURVE_POINTS) {
            x->points = malloc(sizeof(double) * 3 * (size_t)m.n_points);
            if (!x->points) {
                snprintf(x->error, sizeof x->error, "daemon out of memory");
                cubesim_curve_t_decode_cleanup(&m);
                return;
            }
            x->n_points = m.n_points;
            for (int i = 0; i < m.n_points; i++) {
                memcpy(x->points + 3 * i, m.points[i], 3 * sizeof(double));
                finite = finite && finite3(m.points[i]);
            }
        }
        if (m.n_points < 2 || m.n_points > CS_MAX_CURVE_POINTS) {
            snprintf(num, sizeof num, "%d", (int)m.n_points);
            refuse(b, x, "curve: needs 2 to 64 points, got %s", num);
        } else if (!finite)
            refuse(b, x, "curve: a point is not finite%s", "");
        else if (!(m.stiffness > 0 && isfinite(m.stiffness))) {
            snprintf(num, sizeof num, "%g", m.stiffness);
            refuse(b, x, "curve: stiffness %s N/m is not positive and finite", num);
        } else if (!(m.duration > 0 && isfinite(m.duration))) {
            snprintf(num, sizeof num, "%g", m.duration);
            refuse(b, x, "curve: duration %s s is not positive and finite", num);
        }
    }
    cubesim_curve_t_decode_cleanup(&m);
}

static cs_command command_from_name(const char *s)
{
    static const struct { const char *name; cs_command c; } t[] = {
        {"pause", CS_CMD_PAUSE}, {"resume", CS_CMD_RESUME}, {"step", CS_CMD_STEP},
        {"reset", CS_CMD_RESET}, {"snapshot", CS_CMD_SNAPSHOT}, {"load", CS_CMD_LOAD},
        {"fracture", CS_CMD_FRACTURE},
    };
    for (size_t i = 0; s && i < sizeof t / sizeof t[0]; i++)
        if (strcmp(s, t[i].name) == 0)
            return t[i].c;
    return CS_CMD_UNKNOWN;
}

/*
 * The argument of "fracture": "OBJECT X Y Z NX NY NZ [RADIUS]", separated by blanks. OBJECT is
 * a name without blanks or "#ID". Fills object_id/object_name, point, normal, radius.
 */
static int parse_fracture(cs_input *x, char *why, size_t whylen)
{
    char *tok[9];
    int n = 0;
    char *save = NULL, *arg = dup_str(x->argument);
    if (!arg) {
        snprintf(why, whylen, "out of memory");
        return -1;
    }
    for (char *t = strtok_r(arg, " \t", &save); t; t = strtok_r(NULL, " \t", &save)) {
        if (n == 9)
            break;
        tok[n++] = t;
    }
    int rc = -1;
    double num[7] = {0, 0, 0, 0, 0, 0, 0};
    if (n < 7 || n > 8) {
        snprintf(why, whylen, "argument must be 'OBJECT X Y Z NX NY NZ [RADIUS]', got %d word%s",
                 n, n == 1 ? "" : "s");
        goto out;
    }
    for (int i = 1; i < n; i++) {
        const int e = cs_parse_decimal(tok[i], &num[i - 1]);
        if (e) {
            snprintf(why, whylen, "'%.40s' is not a %s", tok[i],
                     e == -2 ? "finite number (too large for a double)"
                             : "finite number (a decimal such as -0.25 or 1e-3)");
            goto out;
        }
    }
    if (num[3] == 0 && num[4] == 0 && num[5] == 0) {
        snprintf(why, whylen, "the normal is zero");
        goto out;
    }
    if (num[6] < 0) {
        snprintf(why, whylen, "radius %g m is negative", num[6]);
        goto out;
    }
    if (tok[0][0] == '#') {
        char *end = NULL;
        errno = 0;
        long id = strtol(tok[0] + 1, &end, 10);
        if (!end || *end || errno || id < 1 || id > INT32_MAX) {
            snprintf(why, whylen, "'%.40s' is not a valid #id", tok[0]);
            goto out;
        }
        x->object_id = (int32_t)id;
    } else {
        free(x->object_name);
        x->object_name = dup_str(tok[0]);
        if (!x->object_name) {
            snprintf(why, whylen, "out of memory");
            goto out;
        }
    }
    memcpy(x->point, num, sizeof x->point);
    memcpy(x->normal, num + 3, sizeof x->normal);
    x->radius = num[6];
    rc = 0;
out:
    free(arg);
    return rc;
}

static void on_command(const lcm_recv_buf_t *rbuf, const char *channel, void *user)
{
    cs_bus_t *b = user;
    cubesim_command_t m;
    memset(&m, 0, sizeof m);
    int rc = -1;
    if (well_formed(rbuf->data, rbuf->data_size, command_layout))
        rc = cubesim_command_t_decode(rbuf->data, 0, (int)rbuf->data_size, &m);
    if (rc < 0) {
        cubesim_command_t_decode_cleanup(&m);
        cs_dlog_warn(b->log, "undecodable " CS_CH_COMMAND,
                     "ignored a message on %s that is not a cubesim.command_t (%u bytes: "
                     "another type, truncated or malformed)",
                     channel, (unsigned)rbuf->data_size);
        return;
    }
    cs_input tmp;
    cs_input *x = push_input(b);
    bool full = x == NULL;
    if (full) {
        memset(&tmp, 0, sizeof tmp);
        x = &tmp;
    }
    x->kind = CS_INPUT_COMMAND;
    x->client_id = m.client_id;
    x->command_id = m.command_id;
    /* The request name is echoed in the ack; keep it printable. */
    snprintf(x->request, sizeof x->request, "%s", m.command ? m.command : "");
    for (char *p = x->request; *p; p++)
        if ((unsigned char)*p < 32 || (unsigned char)*p > 126)
            *p = '?';
    x->command = command_from_name(m.command);
    x->count = m.count;
    x->argument = dup_str(m.argument);
    if (full) {
        cs_dlog_warn(b->log, "input queue full", "input queue full: refused a command");
        cs_bus_ack(b, x, false, "daemon input queue full; command dropped");
        cs_input_clear(x);
    } else if (!x->argument) {
        snprintf(x->error, sizeof x->error, "daemon out of memory");
    } else if (x->command == CS_CMD_UNKNOWN) {
        refuse(b, x,
               "unknown command '%s' (known: pause, resume, step, reset, snapshot, load, "
               "fracture)", x->request);
    } else if (x->command == CS_CMD_STEP && x->count < 1) {
        char num[32];
        snprintf(num, sizeof num, "%d", (int)x->count);
        refuse(b, x, "step: count %s is less than 1", num);
    } else if (x->command == CS_CMD_LOAD && !x->argument[0]) {
        refuse(b, x, "load: no scene path given (argument is empty)%s", "");
    } else if (x->command == CS_CMD_FRACTURE) {
        char why[200];
        if (parse_fracture(x, why, sizeof why))
            refuse(b, x, "fracture: %s", why);
    }
    cubesim_command_t_decode_cleanup(&m);
}

/* ---------------------------------------------------------------- lifetime */

static int64_t random_session_id(void)
{
    uint64_t r = 0;
    if (getrandom(&r, sizeof r, 0) != (ssize_t)sizeof r)
        r = (uint64_t)cs_dlog_utime() * 6364136223846793005ull ^ (uint64_t)getpid();
    r &= 0x7fffffffffffffffull; /* positive: easier to print and compare */
    return r ? (int64_t)r : 1;
}

int cs_bus_create(const char *url, cs_dlog *log, cs_bus_t **out, char *err, size_t errlen)
{
    *out = NULL;
    cs_bus_t *b = calloc(1, sizeof *b);
    if (!b) {
        snprintf(err, errlen, "out of memory");
        return -1;
    }
    b->log = log;
    b->max_force = 1e9;
    b->session_id = random_session_id();
    b->in = calloc(CS_BUS_INPUT_MAX, sizeof *b->in);
    if (!b->in) {
        snprintf(err, errlen, "out of memory");
        free(b);
        return -1;
    }
    b->lcm = lcm_create(url);
    if (!b->lcm) {
        snprintf(err, errlen, "cannot open the LCM bus at '%s'", url ? url : "(LCM default)");
        cs_bus_destroy(b);
        return -1;
    }
    b->sub_force = lcm_subscribe(b->lcm, CS_CH_FORCE, on_force, b);
    b->sub_command = lcm_subscribe(b->lcm, CS_CH_COMMAND, on_command, b);
    b->sub_paint = lcm_subscribe(b->lcm, CS_CH_PAINT, on_paint, b);
    b->sub_pressure = lcm_subscribe(b->lcm, CS_CH_PRESSURE, on_pressure, b);
    b->sub_curve = lcm_subscribe(b->lcm, CS_CH_CURVE, on_curve, b);
    if (!b->sub_force || !b->sub_command || !b->sub_paint || !b->sub_pressure ||
        !b->sub_curve) {
        snprintf(err, errlen, "cannot subscribe to the input channels (%s, %s, %s, %s, %s)",
                 CS_CH_FORCE, CS_CH_COMMAND, CS_CH_PAINT, CS_CH_PRESSURE, CS_CH_CURVE);
        cs_bus_destroy(b);
        return -1;
    }
    lcm_subscription_set_queue_capacity(b->sub_force, CS_BUS_QUEUE_CAPACITY);
    lcm_subscription_set_queue_capacity(b->sub_command, CS_BUS_QUEUE_CAPACITY);
    lcm_subscription_set_queue_capacity(b->sub_paint, CS_BUS_QUEUE_CAPACITY);
    lcm_subscription_set_queue_capacity(b->sub_pressure, CS_BUS_QUEUE_CAPACITY);
    lcm_subscription_set_queue_capacity(b->sub_curve, CS_BUS_QUEUE_CAPACITY);
    b->credit = CS_BUS_BURST;
    b->credit_time = cs_dlog_now();
    b->rate = CS_BUS_RATE;
    *out = b;
    return 0;
}

static void outbox_clear(cs_bus_t *b)
{
    for (int i = 0; i < b->out_count; i++)
        free(b->out[(b->out_head + i) % b->out_cap].data);
    b->out_head = b->out_count = 0;
    b->out_bytes = 0;
    b->pending_snapshot_id = 0;
}

void cs_bus_forget_objects(cs_bus_t *b)
{
    for (int i = 0; i < b->n_sent; i++) {
        free(b->sent[i].xyz);
        free(b->sent[i].ref_xyz);
    }
    b->n_sent = 0;
}

void cs_bus_destroy(cs_bus_t *b)
{
    if (!b)
        return;
    if (b->lcm) {
        if (b->sub_force)
            lcm_unsubscribe(b->lcm, b->sub_force);
        if (b->sub_command)
            lcm_unsubscribe(b->lcm, b->sub_command);
        if (b->sub_paint)
            lcm_unsubscribe(b->lcm, b->sub_paint);
        if (b->sub_pressure)
            lcm_unsubscribe(b->lcm, b->sub_pressure);
        if (b->sub_curve)
            lcm_unsubscribe(b->lcm, b->sub_curve);
        lcm_destroy(b->lcm);
    }
    if (b->in) {
        cs_input x;
        while (cs_bus_next_input(b, &x))
            cs_input_clear(&x);
        free(b->in);
    }
    outbox_clear(b);
    free(b->out);
    cs_bus_forget_objects(b);
    free(b->sent);
    free(b->scratch_index);
    free(b->scratch_xyz);
    free(b);
}

int cs_bus_fileno(cs_bus_t *b) { return lcm_get_fileno(b->lcm); }

void cs_bus_set_max_force(cs_bus_t *b, double max_force)
{
    if (isfinite(max_force) && max_force > 0)
        b->max_force = max_force;
}

int cs_bus_drain(cs_bus_t *b, int max)
{
    int n = 0;
    while (n < max) {
        int rc = lcm_handle_timeout(b->lcm, 0);
        if (rc < 0)
            return -1;
        if (rc == 0)
            break;
        n++;
    }
    return n;
}

void cs_bus_set_context(cs_bus_t *b, int32_t epoch, int64_t frame, double sim_time)
{
    b->epoch = epoch;
    b->frame = frame;
    b->sim_time = sim_time;
}

int64_t cs_bus_session_id(const cs_bus_t *b) { return b->session_id; }
int32_t cs_bus_last_snapshot_id(const cs_bus_t *b) { return b->snapshot_id; }

static cubesim_header_t header(cs_bus_t *b, int64_t *seq)
{
    cubesim_header_t h;
    h.session_id = b->session_id;
    h.epoch = b->epoch;
    h.frame = b->frame;
    h.seq = (*seq)++;
    h.sim_time = b->sim_time;
    h.utime = cs_dlog_utime();
    return h;
}

/* ---------------------------------------------------------------- acks, status */

int cs_bus_ack(cs_bus_t *b, const cs_input *in, bool ok, const char *message)
{
    char line[512]; /* one line, whatever a client put in a name */
    snprintf(line, sizeof line, "%s", message ? message : "");
    cs_dlog_one_line(line);
    cubesim_ack_t a;
    a.header = header(b, &b->seq_ack);
    a.client_id = in->client_id;
    a.command_id = in->command_id;
    a.request = (char *)in->request;
    a.ok = ok ? 1 : 0;
    a.message = line;
    return cubesim_ack_t_publish(b->lcm, CS_CH_ACK, &a) < 0 ? -1 : 0;
}

int cs_bus_publish_status(cs_bus_t *b, const cs_world_t *w, const cs_bus_status_extra *x)
{
    int n = cs_world_object_ids(w, NULL, 0);
    if (n < 0)
        n = 0;
    cubesim_status_t s;
    memset(&s, 0, sizeof s);
    s.header = header(b, &b->seq_status);
    s.paused = x->paused ? 1 : 0;
    s.dt = cs_world_get_def(w)->dt;
    s.real_time_factor = x->real_time_factor;
    s.step_ms = x->step_ms;
    s.step_ms_avg = x->step_ms_avg;
    const cs_step_stats *st = cs_world_last_stats(w);
    if (st) {
        s.ms_rotations = st->ms_rotations;
        s.ms_rhs = st->ms_rhs;
        s.ms_solve = st->ms_solve;
        s.ms_skin = st->ms_skin;
        s.cg_iterations = st->cg_iterations;
        s.cg_residual = st->cg_residual;
    }
    s.last_snapshot_id = b->snapshot_id;
    /* One block holds every per-object array (freed once below). */
    size_t per = sizeof(cs_object_id) + sizeof(int32_t) * 2 + sizeof(int64_t) + sizeof(int8_t) +
                 sizeof(double) * 3 + sizeof(char *);
    char *blk = calloc((size_t)(n > 0 ? n : 1), per + 8);
    if (!blk)
        return -1;
    double *ke = (double *)blk, *ee = ke + n, *ge = ee + n;
    int64_t *hash = (int64_t *)(ge + n);
    char **names = (char **)(hash + n);
    cs_object_id *ids = (cs_object_id *)(names + n);
    int32_t *oid = (int32_t *)(ids + n), *topo = oid + n;
    int8_t *sleeping = (int8_t *)(topo + n);
    n = cs_world_object_ids(w, ids, n);
    for (int i = 0; i < n; i++) {
        cs_object_info info;
        memset(&info, 0, sizeof info);
        cs_object_get_info(w, ids[i], &info);
        cs_energy e = {0, 0, 0};
        cs_object_energy(w, ids[i], &e);
        oid[i] = (int32_t)ids[i];
        names[i] = (char *)(info.name ? info.name : "");
        topo[i] = (int32_t)info.topology_version;
        hash[i] = (int64_t)cs_object_state_hash(w, ids[i]);
        sleeping[i] = info.sleeping ? 1 : 0;
        ke[i] = e.kinetic;
        ee[i] = e.elastic;
        ge[i] = e.gravity;
    }
    s.n_objects = n;
    s.object_id = oid;
    s.object_name = names;
    s.topology_version = topo;
    s.state_hash = hash;
    s.sleeping = sleeping;
    s.kinetic_energy = ke;
    s.elastic_energy = ee;
    s.gravity_energy = ge;
    int rc = cubesim_status_t_publish(b->lcm, CS_CH_STATUS, &s);
    free(blk);
    return rc < 0 ? -1 : 0;
}

/* ---------------------------------------------------------------- outbox */

static int outbox_push(cs_bus_t *b, const char *channel, void *data, int len, int32_t snap)
{
    if (b->out_count == b->out_cap) {
        int cap = b->out_cap ? 2 * b->out_cap : 64;
        outmsg *o = malloc((size_t)cap * sizeof *o);
        if (!o)
            return -1;
        for (int i = 0; i < b->out_count; i++)
            o[i] = b->out[(b->out_head + i) % b->out_cap];
        free(b->out);
        b->out = o;
        b->out_cap = cap;
        b->out_head = 0;
    }
    outmsg *m = &b->out[(b->out_head + b->out_count) % b->out_cap];
    m->channel = channel;
    m->data = data;
    m->len = len;
    m->snapshot_id = snap;
    b->out_count++;
    b->out_bytes += (size_t)len;
    /* drain the whole backlog within CS_BUS_DRAIN_S, at a rate within the bounds: a frame's
     * deltas leave evenly spread, and a backlog never waits behind a fixed slow rate */
    double r = (double)b->out_bytes / CS_BUS_DRAIN_S;
    b->rate = r < CS_BUS_RATE ? CS_BUS_RATE : r > CS_BUS_RATE_MAX ? CS_BUS_RATE_MAX : r;
    return 0;
}

int cs_bus_pump(cs_bus_t *b, double now, double *next_send)
{
    b->credit += (now - b->credit_time) * b->rate;
    if (b->credit > CS_BUS_BURST)
        b->credit = CS_BUS_BURST;
    b->credit_time = now;
    while (b->out_count > 0) {
        outmsg *m = &b->out[b->out_head];
        if (b->credit < (double)m->len)
            break;
        if (lcm_publish(b->lcm, m->channel, m->data, (unsigned)m->len) < 0)
            cs_dlog_warn(b->log, "publish failed", "lcm_publish on %s failed (%d bytes)",
                         m->channel, m->len);
        if (m->snapshot_id && m->snapshot_id == b->pending_snapshot_id)
            b->pending_snapshot_id = 0; /* it started leaving: no longer coalescible */
        b->credit -= (double)m->len;
        b->out_bytes -= (size_t)m->len;
        free(m->data);
        m->data = NULL;
        b->out_head = (b->out_head + 1) % b->out_cap;
        b->out_count--;
    }
    if (next_send) {
        *next_send = now;
        if (b->out_count > 0) {
            double need = (double)b->out[b->out_head].len - b->credit;
            *next_send = now + (need > 0 ? need / b->rate : 0);
        }
    }
    return b->out_count;
}

/* ---------------------------------------------------------------- snapshots */

static sent_object *find_sent(cs_bus_t *b, cs_object_id id)
{
    for (int i = 0; i < b->n_sent; i++)
        if (b->sent[i].id == id)
            return &b->sent[i];
    return NULL;
}

static sent_object *add_sent(cs_bus_t *b, cs_object_id id)
{
    sent_object *s = find_sent(b, id);
    if (s)
        return s;
    if (b->n_sent == b->cap_sent) {
        int cap = b->cap_sent ? 2 * b->cap_sent : 8;
        sent_object *n = realloc(b->sent, (size_t)cap * sizeof *n);
        if (!n)
            return NULL;
        b->sent = n;
        b->cap_sent = cap;
    }
    s = &b->sent[b->n_sent++];
    memset(s, 0, sizeof *s);
    s->id = id;
    return s;
}

/* Items (vertices or triangles, 12 bytes each) one chunk of this object can carry. */
static int items_per_chunk(const char *name, const char *model)
{
    int fixed = 200 + (int)strlen(name) + (int)strlen(model);
    int k = (CS_BUS_CHUNK_BYTES - fixed) / 12;
    return k < 1 ? 1 : k;
}

static int encode_push(cs_bus_t *b, const char *channel, int32_t snap, int size,
                       int (*enc)(void *, int, int, const void *), const void *msg)
{
    void *buf = malloc((size_t)size);
    if (!buf)
        return -1;
    if (enc(buf, 0, size, msg) != size || outbox_push(b, channel, buf, size, snap) < 0) {
        free(buf);
        return -1;
    }
    return 0;
}

static int enc_snapshot(void *buf, int off, int max, const void *m)
{
    return cubesim_snapshot_t_encode(buf, off, max, m);
}

static int enc_delta(void *buf, int off, int max, const void *m)
{
    return cubesim_delta_t_encode(buf, off, max, m);
}

int32_t cs_bus_queue_snapshot(cs_bus_t *b, const cs_world_t *w, bool coalesce)
{
    if (coalesce && b->pending_snapshot_id)
        return b->pending_snapshot_id;
    int n = cs_world_object_ids(w, NULL, 0);
    if (n < 0)
        n = 0;
    cs_object_id *ids = calloc((size_t)(n > 0 ? n : 1), sizeof *ids);
    if (!ids)
        return -1;
    n = cs_world_object_ids(w, ids, n);

    /* Count the chunks first: every chunk carries n_chunks. */
    int total = 0;
    for (int i = 0; i < n; i++) {
        cs_object_info info;
        memset(&info, 0, sizeof info);
        cs_object_get_info(w, ids[i], &info);
        int k = items_per_chunk(info.name ? info.name : "", cs_model_name(info.model));
        int items = info.n_surface_vertices + info.n_surface_triangles;
        total += items > 0 ? (items + k - 1) / k : 1;
    }
    if (n == 0)
        total = 1;

    int32_t id = ++b->snapshot_id;
    cubesim_snapshot_t s;
    memset(&s, 0, sizeof s);
    s.snapshot_id = id;
    s.n_chunks = total;
    s.n_objects = n;
    int chunk = 0, rc = 0;
    if (n == 0) {
        s.header = header(b, &b->seq_snapshot);
        s.object_name = "";
        s.model = "";
        rc = encode_push(b, CS_CH_SNAPSHOT, id, cubesim_snapshot_t_encoded_size(&s),
                         enc_snapshot, &s);
    }
    for (int i = 0; i < n && rc == 0; i++) {
        cs_object_info info;
        memset(&info, 0, sizeof info);
        cs_object_get_info(w, ids[i], &info);
        const double *v = NULL;
        const int32_t *t = NULL;
        int nv = 0, nt = 0;
        cs_object_surface(w, ids[i], &v, &nv, &t, &nt);
        sent_object *so = add_sent(b, ids[i]);
        float *xyz = so ? realloc(so->xyz, (size_t)(nv > 0 ? nv : 1) * 3 * sizeof(float)) : NULL;
        if (!xyz) {
            rc = -1;
            break;
        }
        so->xyz = xyz;
        so->nv = nv;
        so->nt = nt;
        so->topology_version = info.topology_version;
        so->settled = info.sleeping; /* the snapshot carries its resting surface */
        so->has_ref = false;         /* rigid: a new reference pose follows */
        for (int j = 0; j < 3 * nv; j++)
            xyz[j] = (float)v[j];

        s.object_id = (int32_t)ids[i];
        s.object_name = (char *)(info.name ? info.name : "");
        s.model = (char *)cs_model_name(info.model);
        s.topology_version = (int32_t)info.topology_version;
        s.n_vertices_total = nv;
        s.n_triangles_total = nt;
        int k = items_per_chunk(s.object_name, s.model);
        int items = nv + nt;
        for (int start = 0; rc == 0 && (start < items || (items == 0 && start == 0));
             start += k) {
            int end = start + k < items ? start + k : items;
            int v0 = start < nv ? start : nv, v1 = end < nv ? end : nv;
            int t0 = (start > nv ? start : nv) - nv, t1 = (end > nv ? end : nv) - nv;
            s.header = header(b, &b->seq_snapshot);
            s.chunk = chunk++;
            s.vertex_offset = v0;
            s.n_coords = 3 * (v1 - v0);
            s.xyz = xyz + 3 * v0;
            s.triangle_offset = t0;
            s.n_indices = 3 * (t1 - t0);
            s.indices = (int32_t *)(t + 3 * t0);
            rc = encode_push(b, CS_CH_SNAPSHOT, id, cubesim_snapshot_t_encoded_size(&s),
                             enc_snapshot, &s);
            if (items == 0)
                break;
        }
    }
    free(ids);
    if (rc < 0)
        return -1;
    b->pending_snapshot_id = id;
    return id;
}

/* ---------------------------------------------------------------- deltas */

/* A rigid object's vertex moved by a pose is resent only beyond eps + CS_POSE_ROUND·(|x_r| +
 * |x|) (largest coordinates of its reference copy and of where it is): √3·2⁻²³, twice the
 * float32 rounding of both (cs_bus_queue_deltas). */
#define CS_POSE_ROUND (1.7320508075688772 * 0x1p-23)

static double max_abs3(const double *x)
{
    return fmax(fabs(x[0]), fmax(fabs(x[1]), fabs(x[2])));
}

static double max_abs3f(const float *x)
{
    return fmax(fabs((double)x[0]), fmax(fabs((double)x[1]), fabs((double)x[2])));
}

static int enc_pose(void *buf, int off, int max, const void *m)
{
    return cubesim_pose_t_encode(buf, off, max, m);
}

/*
 * The pose of a rigid object (lcmtypes/pose_t.lcm). The first after a snapshot or topology
 * change is a reference, sent after the object's deltas of that frame (the record, then up to
 * date, is the reference copy); later ones, sent before the deltas, move the record by
 * cs_pose_transform exactly as the receivers do, so the deltas that follow (vertices that
 * moved in the body frame by more than epsilon, followed by a new reference) keep the bound.
 * Returns 0, or -1 out of memory.
 */
static int queue_pose(cs_bus_t *b, sent_object *so, const cs_object_info *info,
                      const cs_rigid_state *rs)
{
    cubesim_pose_t p;
    memset(&p, 0, sizeof p);
    p.object_id = (int32_t)so->id;
    p.topology_version = (int32_t)info->topology_version;
    p.n_vertices_total = so->nv;
    memcpy(p.position, rs->position, sizeof p.position);
    memcpy(p.orientation, rs->orientation, sizeof p.orientation);
    if (!so->has_ref) {
        float *r = realloc(so->ref_xyz, 3 * (size_t)(so->nv > 0 ? so->nv : 1) * sizeof *r);
        if (!r)
            return -1;
        so->ref_xyz = r;
        memcpy(r, so->xyz, 3 * (size_t)so->nv * sizeof *r);
        memcpy(so->ref_q, rs->orientation, sizeof so->ref_q);
        memcpy(so->ref_c, rs->position, sizeof so->ref_c);
        so->has_ref = true;
        p.reference = 1;
    } else {
        cs_pose_transform(so->ref_xyz, so->nv, so->ref_q, so->ref_c, rs->orientation,
                          rs->position, so->xyz);
    }
    p.header = header(b, &b->seq_pose);
    return encode_push(b, CS_CH_POSE, 0, cubesim_pose_t_encoded_size(&p), enc_pose, &p) < 0
               ? -1 : 0;
}

int cs_bus_queue_deltas(cs_bus_t *b, const cs_world_t *w, double eps)
{
    int n = cs_world_object_ids(w, NULL, 0);
    if (n <= 0)
        return 0;
    cs_object_id *ids = calloc((size_t)n, sizeof *ids);
    if (!ids)
        return -1;
    n = cs_world_object_ids(w, ids, n);
    /* exact (eps < 0): every vertex whose float32 differs from the one last sent, of every
     * object (settled ones too), and every vertex of a rigid object, whose receivers move
     * their copies by their own pose arithmetic */
    const bool exact = eps < 0;
    if (!(eps >= 0) || !isfinite(eps))
        eps = 0;
    double eps2 = eps * eps;
    int queued = 0;
    bool need_snapshot = false;
    for (int i = 0; i < n; i++) {
        cs_object_info info;
        memset(&info, 0, sizeof info);
        cs_object_get_info(w, ids[i], &info);
        const double *v = NULL;
        const int32_t *t = NULL;
        int nv = 0, nt = 0;
        cs_object_surface(w, ids[i], &v, &nv, &t, &nt);
        sent_object *so = find_sent(b, ids[i]);
        if (!so || so->nv != nv || so->topology_version != info.topology_version) {
            need_snapshot = true; /* a new object or new topology: deltas cannot say it */
            continue;
        }
        /* An object moves in the step in which it falls asleep: compare it once more,
         * then skip it until it wakes. */
        if (info.sleeping && so->settled && !exact)
            continue;
        so->settled = info.sleeping;
        /* rigid: a pose moves the record (and the receivers' copies) first; the deltas
         * below then carry only what it left farther than eps */
        cs_rigid_state rs;
        const bool rigid = info.model == CS_MODEL_RIGID &&
                           cs_object_rigid_state(w, ids[i], &rs) == CS_OK;
        const bool posed = rigid && so->has_ref && !exact;
        if (rigid && so->has_ref && queue_pose(b, so, &info, &rs) != 0) {
            free(ids);
            return -1;
        }
        if (b->scratch_cap < nv) {
            int32_t *ix = realloc(b->scratch_index, (size_t)nv * sizeof *ix);
            if (ix)
                b->scratch_index = ix;
            float *xf = realloc(b->scratch_xyz, (size_t)nv * 3 * sizeof *xf);
            if (xf)
                b->scratch_xyz = xf;
            if (!ix || !xf) {
                free(ids);
                return -1;
            }
            b->scratch_cap = nv;
        }
        int m = 0;
        for (int j = 0; j < nv; j++) {
            const double *x = v + 3 * j;
            float *s = so->xyz + 3 * j;
            double dx = x[0] - s[0], dy = x[1] - s[1], dz = x[2] - s[2];
            double tol2 = eps2;
            if (posed) {
                /* the record is the pose applied to the float32 reference copy: it carries
                 * that copy's rounding and its own (each at most 2^-24 |x| per coordinate)
                 * even where the vertex did not move in the body frame. A vertex is sent
                 * only when it moved in the body frame by more than eps: beyond eps plus
                 * twice those roundings (room for the double arithmetic). Comparing the
                 * floats alone sent every vertex of a moving rigid body every frame at
                 * publish_epsilon 0, and at any epsilon below a float32 step of its
                 * coordinates (far from the origin). */
                const float *r = so->ref_xyz + 3 * j;
                const double tol = eps + CS_POSE_ROUND * (max_abs3f(r) + max_abs3(x));
                tol2 = tol * tol;
            }
            const bool send = exact ? rigid || (float)x[0] != s[0] || (float)x[1] != s[1] ||
                                          (float)x[2] != s[2]
                                    : dx * dx + dy * dy + dz * dz > tol2;
            if (send) {
                s[0] = (float)x[0];
                s[1] = (float)x[1];
                s[2] = (float)x[2];
                b->scratch_index[m] = j;
                memcpy(b->scratch_xyz + 3 * m, s, 3 * sizeof(float));
                m++;
            }
        }
        /* a rigid object's vertices that moved in its body frame: the record with them
         * becomes the new reference (a reference pose after these deltas), or the next pose,
         * which starts from the reference, would undo them and they would go again */
        if (posed && m > 0)
            so->has_ref = false;
        /* no reference yet (first motion after a snapshot or topology change): the
         * record, brought up to date by this frame's deltas, becomes it, at this pose */
        if (rigid && !so->has_ref && m == 0 && queue_pose(b, so, &info, &rs) != 0) {
            free(ids);
            return -1;
        }
        if (m == 0)
            continue;
        const int per = (CS_BUS_CHUNK_BYTES - 200) / 16;
        int nchunks = (m + per - 1) / per;
        cubesim_delta_t d;
        memset(&d, 0, sizeof d);
        d.object_id = (int32_t)ids[i];
        d.topology_version = (int32_t)info.topology_version;
        d.n_chunks = nchunks;
        d.n_vertices_total = nv;
        for (int c = 0; c < nchunks; c++) {
            int a = c * per, e = a + per < m ? a + per : m;
            d.header = header(b, &b->seq_delta);
            d.chunk = c;
            d.n = e - a;
            d.index = b->scratch_index + a;
            d.n_coords = 3 * d.n;
            d.xyz = b->scratch_xyz + 3 * a;
            if (encode_push(b, CS_CH_DELTA, 0, cubesim_delta_t_encoded_size(&d), enc_delta,
                            &d) < 0) {
                free(ids);
                return -1;
            }
            queued++;
        }
        if (rigid && !so->has_ref && queue_pose(b, so, &info, &rs) != 0) {
            free(ids);
            return -1;
        }
    }
    free(ids);
    if (b->out_bytes > (size_t)CS_BUS_OUTBOX_MAX) {
        /* The bus cannot keep up: drop the backlog (receivers see a seq gap) and resync. */
        cs_dlog_warn(b->log, "outbox overflow",
                     "outbox over %d MiB: dropped %d queued messages, sending a snapshot",
                     CS_BUS_OUTBOX_MAX >> 20, b->out_count);
        outbox_clear(b);
        need_snapshot = true;
    }
    if (need_snapshot && cs_bus_queue_snapshot(b, w, true) < 0)
        return -1;
    return queued;
}

/* ---------------------------------------------------------------- topology */

static int enc_topology(void *buf, int off, int max, const void *m)
{
    return cubesim_topology_t_encode(buf, off, max, m);
}

/* Bytes per item of the five arrays of a change, in their order on the wire (vremove, vnew,
 * tremove, tset, tnew). */
static const int topo_item_bytes[5] = {4, 16, 4, 16, 12}; /* a new vertex: xyz and source */

/*
 * Split a change into chunks: its five arrays laid end to end, each chunk taking the next
 * slice that fits `budget` bytes (>= 16, so every chunk makes progress). If `sl` is not NULL,
 * chunk k's start and count in array a go to sl[k][a][0] and sl[k][a][1]. Returns the number
 * of chunks (1 for an empty change).
 */
static int plan_topology(const int32_t total[5], int budget, int32_t (*sl)[5][2])
{
    int a = 0, n = 0;
    int32_t pos = 0;
    while (a < 5 && total[a] == 0)
        a++;
    do {
        int left = budget;
        int32_t start[5], cnt[5] = {0, 0, 0, 0, 0};
        for (int k = 0; k < 5; k++)
            start[k] = k < a ? total[k] : (k == a ? pos : 0);
        while (a < 5) {
            int32_t m = total[a] - pos, fit = left / topo_item_bytes[a];
            if (m > fit)
                m = fit;
            cnt[a] += m;
            pos += m;
            left -= m * topo_item_bytes[a];
            if (pos < total[a])
                break; /* this chunk is full */
            a++;
            pos = 0;
            while (a < 5 && total[a] == 0)
                a++;
        }
        if (sl)
            for (int k = 0; k < 5; k++) {
                sl[n][k][0] = start[k];
                sl[n][k][1] = cnt[k];
            }
        n++;
    } while (a < 5);
    return n;
}

/* p + off without forming an offset from NULL (empty arrays may be NULL). */
static int32_t *at32(const int32_t *p, int64_t off)
{
    return p ? (int32_t *)p + off : NULL;
}

/* Encode one change as chunks and queue them. Returns the number queued, or -1 (out of
 * memory; chunks already queued stay: receivers see an incomplete change and go stale). */
static int send_change(cs_bus_t *b, const cs_world_t *w, const cs_topo_change *c)
{
    const char *name = c->name ? c->name : "", *model = c->model ? c->model : "";
    cs_object_info info;
    if (c->from_version == 0 && (!c->name || !c->model) &&
        cs_object_get_info(w, (cs_object_id)c->object_id, &info) == CS_OK) {
        if (!c->name && info.name)
            name = info.name;
        if (!c->model)
            model = cs_model_name(info.model);
    }
    int32_t total[5] = {c->n_vremove, c->n_vnew, c->n_tremove, c->n_tset, c->n_tnew};
    int budget = CS_BUS_CHUNK_BYTES - 300 - (int)strlen(name) - (int)strlen(model);
    int nch = plan_topology(total, budget, NULL);
    int32_t(*sl)[5][2] = malloc((size_t)nch * sizeof *sl);
    float *xyz = malloc(3 * (size_t)c->n_vnew * sizeof *xyz + sizeof *xyz);
    if (!sl || !xyz) {
        free(sl);
        free(xyz);
        return -1;
    }
    plan_topology(total, budget, sl);
    for (int64_t k = 0; k < 3 * (int64_t)c->n_vnew; k++)
        xyz[k] = (float)c->vnew_xyz[k];

    cubesim_topology_t m;
    memset(&m, 0, sizeof m);
    m.change_id = ++b->change_id;
    m.n_chunks = nch;
    m.object_id = c->object_id;
    m.parent_id = c->parent_id;
    m.name = (char *)(c->from_version == 0 ? name : "");
    m.model = (char *)(c->from_version == 0 ? model : "");
    m.from_version = (int32_t)c->from_version;
    m.to_version = (int32_t)c->to_version;
    m.n_vertices_total = c->n_vertices_total;
    m.n_triangles_total = c->n_triangles_total;
    m.total_vremove = total[0];
    m.total_vnew = total[1];
    m.total_tremove = total[2];
    m.total_tset = total[3];
    m.total_tnew = total[4];
    int queued = 0;
    for (int k = 0; k < nch; k++) {
        m.header = header(b, &b->seq_topology);
        m.chunk = k;
        m.vremove_offset = sl[k][0][0];
        m.n_vremove = sl[k][0][1];
        m.vremove = at32(c->vremove, m.vremove_offset);
        m.vnew_offset = sl[k][1][0];
        m.n_vnew_coords = 3 * sl[k][1][1];
        m.vnew_xyz = xyz + 3 * (int64_t)m.vnew_offset;
        m.n_vnew_src = c->vnew_src ? sl[k][1][1] : 0;
        m.vnew_src = at32(c->vnew_src, m.vnew_offset);
        m.tremove_offset = sl[k][2][0];
        m.n_tremove = sl[k][2][1];
        m.tremove = at32(c->tremove, m.tremove_offset);
        m.tset_offset = sl[k][3][0];
        m.n_tset = sl[k][3][1];
        m.tset_index = at32(c->tset_index, m.tset_offset);
        m.n_tset_indices = 3 * m.n_tset;
        m.tset_tri = at32(c->tset_tri, 3 * (int64_t)m.tset_offset);
        m.tnew_offset = sl[k][4][0];
        m.n_tnew_indices = 3 * sl[k][4][1];
        m.tnew = at32(c->tnew, 3 * (int64_t)m.tnew_offset);
        if (encode_push(b, CS_CH_TOPOLOGY, 0, cubesim_topology_t_encoded_size(&m), enc_topology,
                        &m) < 0) {
            queued = -1;
            break;
        }
        queued++;
    }
    free(sl);
    free(xyz);
    return queued;
}

/* The last-sent copy follows the change exactly as a client's does (steps 1–2 of topo.h on
 * the floats; the triangles themselves are not kept, only their count). */
static int mirror_change(cs_bus_t *b, const cs_topo_change *c)
{
    sent_object *so = add_sent(b, (cs_object_id)c->object_id);
    if (!so)
        return -1;
    int nv0 = c->from_version == 0 ? 0 : so->nv;
    int cap = nv0 > c->n_vertices_total ? nv0 : c->n_vertices_total;
    float *xyz = realloc(so->xyz, 3 * (size_t)cap * sizeof *xyz + sizeof *xyz);
    if (!xyz)
        return -1;
    so->xyz = xyz;
    int nv = cs_topo_remove_vertices(c, xyz, 3 * sizeof *xyz, nv0);
    for (int64_t k = 0; k < 3 * (int64_t)c->n_vnew; k++)
        xyz[3 * (int64_t)nv + k] = (float)c->vnew_xyz[k];
    so->nv = c->n_vertices_total;
    so->nt = c->n_triangles_total;
    so->topology_version = c->to_version;
    so->settled = false;
    so->has_ref = false;
    return 0;
}

int cs_bus_queue_topology(cs_bus_t *b, const cs_world_t *w, const cs_topo_change *changes,
                          int n)
{
    int queued = 0;
    bool need_snapshot = false, nomem = false;
    for (int i = 0; i < n; i++) {
        const cs_topo_change *c = &changes[i];
        char why[256] = "";
        sent_object *so = c->object_id > 0 ? find_sent(b, (cs_object_id)c->object_id) : NULL;
        int nv0 = 0, nt0 = 0;
        if (c->object_id <= 0)
            snprintf(why, sizeof why, "invalid object id");
        else if (c->from_version == 0 && so)
            snprintf(why, sizeof why, "a new piece with the id of an object already sent");
        else if (c->from_version != 0 && !so)
            snprintf(why, sizeof why, "the object was never sent");
        else if (so && so->topology_version != c->from_version)
            snprintf(why, sizeof why, "the copy last sent has version %u",
                     (unsigned)so->topology_version);
        else if (c->name && strlen(c->name) > 1024)
            snprintf(why, sizeof why, "the piece's name is longer than 1024 bytes");
        else if (so) {
            nv0 = so->nv;
            nt0 = so->nt;
        }
        if (!why[0])
            cs_topo_check(c, nv0, nt0, why, sizeof why);
        if (!why[0]) {
            int r = send_change(b, w, c);
            if (r >= 0) {
                queued += r;
                r = mirror_change(b, c);
            }
            if (r >= 0)
                continue;
            nomem = true;
            snprintf(why, sizeof why, "out of memory");
        }
        cs_dlog_warn(b->log, "topology",
                     "topology change of object %d (version %u -> %u) not sent (%s): "
                     "sending a snapshot instead", (int)c->object_id, (unsigned)c->from_version,
                     (unsigned)c->to_version, why);
        need_snapshot = true;
        if (c->object_id > 0 && (so = find_sent(b, (cs_object_id)c->object_id)) != NULL)
            so->nv = -1; /* never matches the world: deltas wait for the snapshot */
    }
    if (need_snapshot && cs_bus_queue_snapshot(b, w, false) < 0)
        nomem = true;
    return nomem ? -1 : queued;
}
