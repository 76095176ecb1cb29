/*
 * test_bus_sculpt.c — the daemon's decoding of paint_t, pressure_t and curve_t (server/bus.c)
 * through LCM's file:// provider: messages published into an event log are read back by a
 * bus, which queues each as an input with its values, or refused with a one-line message
 * naming the problem (NaN, bad counts, no object); bytes that are not the type are dropped.
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
#include "cubesim_curve_t.h"
#include "cubesim_paint_t.h"
#include "cubesim_pressure_t.h"
#include "server/bus.h"

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

    snprintf(url, sizeof url, "file://%s?mode=r&speed=0", path);
    cs_dlog dl;
    memset(&dl, 0, sizeof dl);
    dl.quiet = true;
    cs_bus_t *b = NULL;
    char err[256];
    ENSURE_MSG(cs_bus_create(url, &dl, &b, err, sizeof err) == 0, "%s", err);
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
