/*
 * test_bus_sculpt.c — the daemon's decoding of paint_t, pressure_t and curve_t (server/bus.c)
 * through LCM's file:// provider: messages published into an event log are read back by a
 * bus, which queues each as an input with its values, or refused with a one-line message
 * naming the problem (NaN, bad counts, no object); bytes that are not the type are dropped.
 * And the input queue's limit: a burst past it refused, the queue usable again after.
 */
#include "check.h"

#include <lcm/lcm.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "cubesim.h"
#include "cubesim_command_t.h"
#include "cubesim_curve_t.h"
#include "cubesim_force_t.h"
#include "cubesim_paint_t.h"
#include "cubesim_pressure_t.h"
#include "server/bus.h"

/* A bus reading the event log at path as fast as it can (NULL, with err, if it cannot). */
static cs_bus_t *log_bus(const char *path, cs_dlog *dl, char *err, size_t errlen)
{
    char url[128];
    snprintf(url, sizeof url, "file://%s?mode=r&speed=0", path);
    memset(dl, 0, sizeof *dl);
    dl->quiet = true;
    cs_bus_t *b = NULL;
    return cs_bus_create(url, dl, &b, err, errlen) == 0 ? b : NULL;
}

TEST(bus_sculpt_inputs_decoded_and_refused)
{
    char path[64], url[128];
    snprintf(path, sizeof path, "/tmp/cs_unit_sculpt_%d.lcm", (int)getpid());
    snprintf(url, sizeof url, "file://%s?mode=w", path);
    lcm_t *lw = lcm_create(url);
    ENSURE(lw);
    /* object_id not > 0 names the object by object_name, a negative one too (the types say
     * so; until session 30 a negative id was refused) */
    cubesim_paint_t pm = {.client_id = 7, .command_id = 1, .object_id = -5, .object_name = "blob",
                          .centre = {0.1, 0.2, 0.3}, .radius = 0.05, .which = 3, .young = 2,
                          .density = 4, .damping = 0};
    ENSURE(cubesim_paint_t_publish(lw, CS_CH_PAINT, &pm) == 0);
    pm.command_id = 2;
    pm.centre[1] = NAN;
    ENSURE(cubesim_paint_t_publish(lw, CS_CH_PAINT, &pm) == 0);
    pm.command_id = 3;
    pm.centre[1] = 0.2;
    pm.which = 0;
    ENSURE(cubesim_paint_t_publish(lw, CS_CH_PAINT, &pm) == 0);
    cubesim_pressure_t prm = {.client_id = 7, .command_id = 4, .object_id = 3,
                              .object_name = "", .pressure = -25, .duration = 1};
    ENSURE(cubesim_pressure_t_publish(lw, CS_CH_PRESSURE, &prm) == 0);
    prm.command_id = 5;
    prm.pressure = NAN;
    ENSURE(cubesim_pressure_t_publish(lw, CS_CH_PRESSURE, &prm) == 0);
    prm.command_id = 6;
    prm.pressure = 1;
    prm.object_id = -1; /* and no name */
    ENSURE(cubesim_pressure_t_publish(lw, CS_CH_PRESSURE, &prm) == 0);
    double p0[3] = {0, 0, 0}, p1[3] = {1, 0, 0}, p2[3] = {1, INFINITY, 0};
    double *rows[3] = {p0, p1, p2};
    cubesim_curve_t cm = {.client_id = 7, .command_id = 7, .object_name = "blob",
                          .stiffness = 50, .duration = 2, .n_points = 2, .points = rows};
    ENSURE(cubesim_curve_t_publish(lw, CS_CH_CURVE, &cm) == 0);
    cm.command_id = 8;
    cm.n_points = 3;
    ENSURE(cubesim_curve_t_publish(lw, CS_CH_CURVE, &cm) == 0);
    cm.command_id = 9;
    cm.n_points = 1;
    ENSURE(cubesim_curve_t_publish(lw, CS_CH_CURVE, &cm) == 0);
    /* a pressure_t on the paint channel: not decodable there */
    prm.command_id = 10;
    ENSURE(cubesim_pressure_t_publish(lw, CS_CH_PAINT, &prm) == 0);
    lcm_destroy(lw);

    cs_dlog dl;
    char err[256];
    cs_bus_t *b = log_bus(path, &dl, err, sizeof err);
    ENSURE_MSG(b, "%s", err);
    cs_input in[16];
    int n = 0;
    for (int tries = 0; tries < 400 && n < 9; tries++) {
        cs_bus_drain(b, 100);
        while (n < 16 && cs_bus_next_input(b, &in[n]))
            n++;
        if (n < 9)
            nanosleep(&(struct timespec){0, 5000000}, NULL);
    }
    cs_bus_destroy(b);
    unlink(path);
    ENSURE_MSG(n == 9, "%d inputs decoded, want 9 (the foreign message dropped)", n);
    /* 1: a good paint */
    ENSURE(in[0].kind == CS_INPUT_PAINT && !in[0].error[0] && !strcmp(in[0].request, "paint"));
    ENSURE(!strcmp(in[0].object_name, "blob") && in[0].radius == 0.05 && in[0].point[2] == 0.3);
    ENSURE(in[0].factors.which == (CS_FIELD_YOUNG | CS_FIELD_DENSITY) &&
           in[0].factors.young == 2 && in[0].factors.density == 4);
    ENSURE_MSG(strstr(in[1].error, "centre is not finite"), "'%s'", in[1].error);
    ENSURE_MSG(strstr(in[2].error, "which = 0"), "'%s'", in[2].error);
    ENSURE(in[3].kind == CS_INPUT_PRESSURE && !in[3].error[0] && in[3].object_id == 3 &&
           in[3].pressure == -25 && in[3].duration == 1);
    ENSURE_MSG(strstr(in[4].error, "pressure is not finite"), "'%s'", in[4].error);
    ENSURE_MSG(strstr(in[5].error, "pressure: no object given"), "'%s'", in[5].error);
    ENSURE(in[6].kind == CS_INPUT_CURVE && !in[6].error[0] && in[6].n_points == 2 &&
           in[6].points[3] == 1 && in[6].stiffness == 50 && in[6].duration == 2);
    ENSURE_MSG(strstr(in[7].error, "curve: a point is not finite"), "'%s'", in[7].error);
    ENSURE_MSG(strstr(in[8].error, "2 to 64 points, got 1"), "'%s'", in[8].error);
    for (int i = 0; i < n; i++) {
        ENSURE(in[i].command_id == i + 1 && in[i].client_id == 7);
        ENSURE(!strchr(in[i].error, '\n'));
        cs_input_clear(&in[i]);
    }
}

/*
 * The input queue's limit (CS_BUS_INPUT_MAX): a burst larger than it is taken up to the limit
 * and the rest refused (acked "input queue full", one rate-limited warning key), whatever the
 * input's type; once the daemon has taken inputs out, new ones are queued again behind the
 * old ones (the ring wraps) in arrival order. 5000 forces and 200 commands from a log: handle
 * 4300 of them (4096 queued, 204 refused), take 1000 out, handle the other 900 (all queued).
 */
/* Handle messages until `handled` reaches want exactly (the log's reader may lag behind:
 * poll, up to 2 s); returns the count reached (-1 on a bus error). */
static int drain_to(cs_bus_t *b, int handled, int want)
{
    for (int tries = 0; handled < want && tries < 2000; tries++) {
        const int n = cs_bus_drain(b, want - handled);
        if (n < 0)
            return -1;
        handled += n;
        if (handled < want)
            nanosleep(&(struct timespec){0, 1000000}, NULL);
    }
    return handled;
}

TEST(bus_input_queue_full_refuses_the_rest_and_recovers)
{
    enum { NF = 5000, NC = 200, FIRST = 4300, TAKEN = 1000 };
    char path[64], url[128];
    snprintf(path, sizeof path, "/tmp/cs_unit_queue_%d.lcm", (int)getpid());
    snprintf(url, sizeof url, "file://%s?mode=w", path);
    lcm_t *lw = lcm_create(url);
    ENSURE(lw);
    /* ids 1..5200: the commands at 2001..2200, among the forces */
    for (int i = 1; i <= NF + NC; i++) {
        if (i > 2000 && i <= 2000 + NC) {
            cubesim_command_t c = {.client_id = 3, .command_id = i, .command = "pause",
                                   .count = 0, .argument = ""};
            ENSURE(cubesim_command_t_publish(lw, CS_CH_COMMAND, &c) == 0);
        } else {
            cubesim_force_t f = {.client_id = 3, .command_id = i, .object_id = 1,
                                 .object_name = "", .kind = CUBESIM_FORCE_T_POINT,
                                 .point = {0, 0, 0}, .force = {1, 0, 0}, .duration = 0};
            ENSURE(cubesim_force_t_publish(lw, CS_CH_FORCE, &f) == 0);
        }
    }
    lcm_destroy(lw);

    cs_dlog dl;
    char err[256];
    cs_bus_t *b = log_bus(path, &dl, err, sizeof err);
    ENSURE_MSG(b, "%s", err);
    int handled = drain_to(b, 0, FIRST);
    ENSURE_MSG(handled == FIRST, "handled %d of %d", handled, FIRST);
    int64_t *ids = malloc(sizeof *ids * (NF + NC));
    ENSURE(ids);
    int got = 0;
    cs_input in;
    for (int k = 0; k < TAKEN && cs_bus_next_input(b, &in); k++) {
        ids[got++] = in.command_id;
        cs_input_clear(&in);
    }
    ENSURE(got == TAKEN);
    handled = drain_to(b, handled, NF + NC);
    ENSURE_MSG(handled == NF + NC, "handled %d of %d", handled, NF + NC);
    while (cs_bus_next_input(b, &in)) {
        if (got < NF + NC)
            ids[got] = in.command_id;
        got++;
        cs_input_clear(&in);
    }
    /* the refusals' warning key: 5 lines a second at most, the rest counted (in the last
     * second's window: a slow run, under valgrind, may have summarised earlier ones) */
    int printed = -1;
    int64_t refused = -1;
    for (int i = 0; i < CS_DLOG_KEYS; i++)
        if (!strcmp(dl.slot[i].key, "input queue full")) {
            printed = dl.slot[i].printed;
            refused = dl.slot[i].printed + dl.slot[i].suppressed;
        }
    cs_bus_destroy(b);
    unlink(path);
    const int queued_first = CS_BUS_INPUT_MAX, rest = NF + NC - FIRST;
    ENSURE_MSG(got == queued_first + rest, "%d inputs queued, want %d", got,
               queued_first + rest);
    ENSURE_MSG(printed >= 1 && printed <= CS_DLOG_BURST && refused >= 1 &&
                   refused <= FIRST - queued_first,
               "%d lines, %lld refusals logged, want 1..%d of %d", printed, (long long)refused,
               CS_DLOG_BURST, FIRST - queued_first);
    /* in arrival order: 1..4096, then 4301..5200 (4097..4300 refused) */
    bool order = true;
    for (int k = 0; k < got; k++)
        order &= ids[k] == (k < queued_first ? k + 1 : FIRST + 1 + (k - queued_first));
    free(ids);
    ENSURE(order);
}
