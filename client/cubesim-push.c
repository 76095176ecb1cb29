/*
 * cubesim-push — send one force or command to cubesimd and wait for its acknowledgement
 * (DESIGN.md "Bus"; lcmtypes/force_t.lcm, command_t.lcm, paint_t.lcm, pressure_t.lcm,
 * curve_t.lcm, ack_t.lcm). Sculpting values are sent as given: the daemon checks them and
 * answers a bad one with a one-line error ack.
 *
 *   cubesim-push force OBJECT --at X Y Z --force FX FY FZ [--for SECONDS]
 *   cubesim-push drag OBJECT --at X Y Z --to X Y Z [--stiffness K] [--for SECONDS]
 *   cubesim-push pause|resume|reset|snapshot
 *   cubesim-push step N
 *   cubesim-push load SCENE
 *   cubesim-push fracture OBJECT --at X Y Z --normal NX NY NZ [--radius R]
 *   cubesim-push paint OBJECT --at X Y Z --radius R [--young F] [--density F] [--damping F]
 *   cubesim-push pressure OBJECT --pressure P [--for SECONDS]
 *   cubesim-push curve OBJECT --point X Y Z --point X Y Z [--point ...] --for SECONDS
 *                [--stiffness K]
 *   options: --lcm URL, --timeout S (default 2), --no-wait
 *
 * OBJECT is a name or #id. The client id is random per run, command ids count up from 1.
 * Exit: 0 ok ack (or sent with --no-wait), 1 error ack, 2 usage or bus error, 3 no ack in time.
 * The ack subscription is made before publishing so that a fast daemon's answer is not missed.
 */
#include <inttypes.h>
#include <lcm/lcm.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client_util.h"
#include "cubesim_ack_t.h"
#include "cubesim_command_t.h"
#include "cubesim_curve_t.h"
#include "cubesim_force_t.h"
#include "cubesim_paint_t.h"
#include "cubesim_pressure_t.h"

#define MAX_POINTS 64

typedef struct push_wait {
    int64_t client_id, command_id;
    int got, ok;
    char message[512];
} push_wait;

static void on_ack(const lcm_recv_buf_t *rbuf, const char *channel, const cubesim_ack_t *a,
                   void *user)
{
    push_wait *w = user;
    if (a->client_id != w->client_id || a->command_id != w->command_id || w->got)
        return;
    w->got = 1;
    w->ok = a->ok != 0;
    snprintf(w->message, sizeof w->message, "%s", a->message ? a->message : "");
}

static void usage(FILE *f)
{
    fprintf(f,
            "usage: cubesim-push force OBJECT --at X Y Z --force FX FY FZ [--for SECONDS]\n"
            "       cubesim-push drag OBJECT --at X Y Z --to X Y Z [--stiffness K] [--for SECONDS]\n"
            "       cubesim-push pause|resume|reset|snapshot\n"
            "       cubesim-push step N\n"
            "       cubesim-push load SCENE\n"
            "       cubesim-push fracture OBJECT --at X Y Z --normal NX NY NZ [--radius R]\n"
            "       cubesim-push paint OBJECT --at X Y Z --radius R [--young F] [--density F]"
            " [--damping F]\n"
            "       cubesim-push pressure OBJECT --pressure P [--for SECONDS]\n"
            "       cubesim-push curve OBJECT --point X Y Z --point X Y Z [--point ...]"
            " --for SECONDS [--stiffness K]\n"
            "options: --lcm URL  --timeout S (default 2)  --no-wait\n"
            "OBJECT is a name or #id. Exit 0 ok, 1 error ack, 2 usage/bus error, 3 no ack.\n");
}

static int parse3(char **argv, int argc, int *i, double v[3], const char *flag)
{
    if (*i + 3 >= argc) {
        fprintf(stderr, "cubesim-push: %s needs three numbers\n", flag);
        return -1;
    }
    for (int k = 0; k < 3; k++) {
        if (cs_parse_double(argv[*i + 1 + k], &v[k])) {
            fprintf(stderr, "cubesim-push: %s: '%s' is not a finite number\n", flag,
                    argv[*i + 1 + k]);
            return -1;
        }
    }
    *i += 3;
    return 0;
}

int main(int argc, char **argv)
{
    const char *url = NULL, *verb = NULL, *object = NULL, *arg = NULL;
    double timeout = 2.0, at[3], force[3], to[3], normal[3], stiffness = 100.0, seconds = 0.0;
    double radius = 0.0, pressure = 0.0, factor[3] = {0, 0, 0}, points[3 * MAX_POINTS];
    int have_factor[3] = {0, 0, 0}, have_pressure = 0, n_points = 0, have_stiffness = 0,
        have_for = 0;
    int have_at = 0, have_force = 0, have_to = 0, have_normal = 0, have_radius = 0, no_wait = 0;
    long count = 0;

    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(a, "--lcm") && i + 1 < argc) {
            url = argv[++i];
        } else if (!strcmp(a, "--timeout") && i + 1 < argc) {
            if (cs_parse_double(argv[++i], &timeout) || timeout < 0) {
                fprintf(stderr, "cubesim-push: --timeout: '%s' is not a time >= 0\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(a, "--no-wait")) {
            no_wait = 1;
        } else if (!strcmp(a, "--at")) {
            if (parse3(argv, argc, &i, at, a))
                return 2;
            have_at = 1;
        } else if (!strcmp(a, "--force")) {
            if (parse3(argv, argc, &i, force, a))
                return 2;
            have_force = 1;
        } else if (!strcmp(a, "--to")) {
            if (parse3(argv, argc, &i, to, a))
                return 2;
            have_to = 1;
        } else if (!strcmp(a, "--normal")) {
            if (parse3(argv, argc, &i, normal, a))
                return 2;
            have_normal = 1;
        } else if (!strcmp(a, "--radius") && i + 1 < argc) {
            if (cs_parse_double(argv[++i], &radius) || radius < 0) {
                fprintf(stderr, "cubesim-push: --radius: '%s' is not a distance >= 0\n", argv[i]);
                return 2;
            }
            have_radius = 1;
        } else if ((!strcmp(a, "--young") || !strcmp(a, "--density") ||
                    !strcmp(a, "--damping")) && i + 1 < argc) {
            const int k = a[2] == 'y' ? 0 : a[3] == 'e' ? 1 : 2;
            if (cs_parse_double(argv[++i], &factor[k])) {
                fprintf(stderr, "cubesim-push: %s: '%s' is not a finite number\n", a, argv[i]);
                return 2;
            }
            have_factor[k] = 1;
        } else if (!strcmp(a, "--pressure") && i + 1 < argc) {
            if (cs_parse_double(argv[++i], &pressure)) {
                fprintf(stderr, "cubesim-push: --pressure: '%s' is not a finite number\n",
                        argv[i]);
                return 2;
            }
            have_pressure = 1;
        } else if (!strcmp(a, "--point")) {
            if (n_points == MAX_POINTS) {
                fprintf(stderr, "cubesim-push: at most %d --point\n", MAX_POINTS);
                return 2;
            }
            if (parse3(argv, argc, &i, points + 3 * n_points, a))
                return 2;
            n_points++;
        } else if (!strcmp(a, "--stiffness") && i + 1 < argc) {
            have_stiffness = 1;
            if (cs_parse_double(argv[++i], &stiffness) || stiffness <= 0) {
                fprintf(stderr, "cubesim-push: --stiffness: '%s' is not a number > 0\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(a, "--for") && i + 1 < argc) {
            if (cs_parse_double(argv[++i], &seconds) || seconds < 0) {
                fprintf(stderr, "cubesim-push: --for: '%s' is not a time >= 0\n", argv[i]);
                return 2;
            }
            have_for = 1;
        } else if (a[0] == '-' && a[1] == '-') {
            fprintf(stderr, "cubesim-push: unknown option or missing value: %s\n", a);
            return 2;
        } else if (!verb) {
            verb = a;
        } else if (!arg) {
            arg = a;
        } else {
            fprintf(stderr, "cubesim-push: unexpected argument '%s'\n", a);
            return 2;
        }
    }
    if (!verb) {
        usage(stderr);
        return 2;
    }

    int is_force = !strcmp(verb, "force"), is_drag = !strcmp(verb, "drag");
    int is_fracture = !strcmp(verb, "fracture");
    int is_paint = !strcmp(verb, "paint"), is_pressure = !strcmp(verb, "pressure");
    int is_curve = !strcmp(verb, "curve");
    const int is_sculpt = is_paint || is_pressure || is_curve;
    char fracture_arg[512];
    cubesim_force_t fm;
    cubesim_command_t cm;
    cubesim_paint_t pm;
    cubesim_pressure_t prm;
    cubesim_curve_t cvm;
    double *cv_rows[MAX_POINTS];
    memset(&fm, 0, sizeof fm);
    memset(&cm, 0, sizeof cm);
    memset(&pm, 0, sizeof pm);
    memset(&prm, 0, sizeof prm);
    memset(&cvm, 0, sizeof cvm);
    int64_t client_id = cs_random_id(), command_id = 1;

    if (have_normal && !is_fracture) {
        fprintf(stderr, "cubesim-push: --normal goes with fracture\n");
        return 2;
    }
    if (have_radius && !is_fracture && !is_paint) {
        fprintf(stderr, "cubesim-push: --radius goes with fracture and paint\n");
        return 2;
    }
    if ((have_factor[0] || have_factor[1] || have_factor[2]) && !is_paint) {
        fprintf(stderr, "cubesim-push: --young, --density and --damping go with paint\n");
        return 2;
    }
    if (have_pressure && !is_pressure) {
        fprintf(stderr, "cubesim-push: --pressure goes with pressure\n");
        return 2;
    }
    if (n_points > 0 && !is_curve) {
        fprintf(stderr, "cubesim-push: --point goes with curve\n");
        return 2;
    }
    if (is_sculpt) {
        object = arg;
        if (!object || !*object) {
            fprintf(stderr, "cubesim-push: %s needs an OBJECT (name or #id)\n", verb);
            return 2;
        }
        int32_t oid = 0;
        char *oname = "";
        if (object[0] == '#') {
            long id;
            if (cs_parse_int(object + 1, 1, INT32_MAX, &id)) {
                fprintf(stderr, "cubesim-push: '%s' is not a valid #id (a positive integer)\n",
                        object);
                return 2;
            }
            oid = (int32_t)id;
        } else {
            oname = (char *)object;
        }
        if (have_force || have_to || (have_at && !is_paint)) {
            fprintf(stderr, "cubesim-push: %s takes no --force/--to%s\n", verb,
                    is_paint ? "" : "/--at");
            return 2;
        }
        if (is_paint) {
            if (!have_at || !have_radius ||
                !(have_factor[0] || have_factor[1] || have_factor[2])) {
                fprintf(stderr, "cubesim-push: paint needs --at X Y Z, --radius R and at least "
                                "one of --young, --density, --damping\n");
                return 2;
            }
            pm = (cubesim_paint_t){.client_id = client_id, .command_id = command_id,
                                   .object_id = oid, .object_name = oname, .radius = radius,
                                   .young = factor[0], .density = factor[1],
                                   .damping = factor[2]};
            memcpy(pm.centre, at, sizeof at);
            pm.which = (int8_t)((have_factor[0] ? CUBESIM_PAINT_T_YOUNG : 0) |
                                (have_factor[1] ? CUBESIM_PAINT_T_DENSITY : 0) |
                                (have_factor[2] ? CUBESIM_PAINT_T_DAMPING : 0));
        } else if (is_pressure) {
            if (!have_pressure) {
                fprintf(stderr, "cubesim-push: pressure needs --pressure P (Pa; > 0 inflates, "
                                "< 0 deflates)\n");
                return 2;
            }
            prm = (cubesim_pressure_t){.client_id = client_id, .command_id = command_id,
                                       .object_id = oid, .object_name = oname,
                                       .pressure = pressure, .duration = seconds};
        } else {
            if (n_points < 2 || !have_for) {
                fprintf(stderr, "cubesim-push: curve needs at least two --point X Y Z and "
                                "--for SECONDS\n");
                return 2;
            }
            for (int k = 0; k < n_points; k++)
                cv_rows[k] = points + 3 * k;
            cvm = (cubesim_curve_t){.client_id = client_id, .command_id = command_id,
                                    .object_id = oid, .object_name = oname,
                                    .stiffness = have_stiffness ? stiffness : 100.0,
                                    .duration = seconds, .n_points = n_points,
                                    .points = cv_rows};
        }
    } else if (is_fracture) {
        object = arg;
        if (!object || !*object || strpbrk(object, " \t\n")) {
            fprintf(stderr, "cubesim-push: fracture needs an OBJECT (a name without blanks, or "
                            "#id)\n");
            return 2;
        }
        if (!have_at || !have_normal || have_force || have_to) {
            fprintf(stderr, "cubesim-push: fracture needs --at X Y Z and --normal NX NY NZ (and "
                            "no --force/--to)\n");
            return 2;
        }
        if (normal[0] == 0 && normal[1] == 0 && normal[2] == 0) {
            fprintf(stderr, "cubesim-push: fracture: --normal must not be zero\n");
            return 2;
        }
        int len = snprintf(fracture_arg, sizeof fracture_arg,
                           "%s %.17g %.17g %.17g %.17g %.17g %.17g %.17g", object, at[0], at[1],
                           at[2], normal[0], normal[1], normal[2], radius);
        if (len < 0 || len >= (int)sizeof fracture_arg) {
            fprintf(stderr, "cubesim-push: fracture: the object name is too long\n");
            return 2;
        }
        cm.client_id = client_id;
        cm.command_id = command_id;
        cm.command = "fracture";
        cm.argument = fracture_arg;
    } else if (is_force || is_drag) {
        object = arg;
        if (!object || !*object) {
            fprintf(stderr, "cubesim-push: %s needs an OBJECT (name or #id)\n", verb);
            return 2;
        }
        if (!have_at) {
            fprintf(stderr, "cubesim-push: %s needs --at X Y Z\n", verb);
            return 2;
        }
        if (is_force && (!have_force || have_to)) {
            fprintf(stderr, "cubesim-push: force needs --force FX FY FZ (and no --to)\n");
            return 2;
        }
        if (is_drag && (!have_to || have_force)) {
            fprintf(stderr, "cubesim-push: drag needs --to X Y Z (and no --force)\n");
            return 2;
        }
        fm.client_id = client_id;
        fm.command_id = command_id;
        fm.object_name = "";
        if (object[0] == '#') {
            long id;
            if (cs_parse_int(object + 1, 1, INT32_MAX, &id)) {
                fprintf(stderr, "cubesim-push: '%s' is not a valid #id (a positive integer)\n",
                        object);
                return 2;
            }
            fm.object_id = (int32_t)id;
        } else {
            fm.object_name = (char *)object;
        }
        fm.kind = is_force ? CUBESIM_FORCE_T_POINT : CUBESIM_FORCE_T_DRAG;
        memcpy(fm.point, at, sizeof at);
        if (is_force)
            memcpy(fm.force, force, sizeof force);
        else
            memcpy(fm.target, to, sizeof to);
        fm.stiffness = is_drag ? stiffness : 0.0;
        fm.duration = seconds;
    } else if (!strcmp(verb, "pause") || !strcmp(verb, "resume") || !strcmp(verb, "reset") ||
               !strcmp(verb, "snapshot") || !strcmp(verb, "step") || !strcmp(verb, "load")) {
        if (have_at || have_force || have_to) {
            fprintf(stderr, "cubesim-push: %s takes no --at/--force/--to\n", verb);
            return 2;
        }
        if (!strcmp(verb, "step")) {
            if (!arg || cs_parse_int(arg, 1, INT32_MAX, &count)) {
                fprintf(stderr, "cubesim-push: step needs a count N >= 1\n");
                return 2;
            }
        } else if (!strcmp(verb, "load")) {
            if (!arg || !*arg) {
                fprintf(stderr, "cubesim-push: load needs a SCENE path (on the daemon's machine)\n");
                return 2;
            }
        } else if (arg) {
            fprintf(stderr, "cubesim-push: %s takes no argument ('%s')\n", verb, arg);
            return 2;
        }
        cm.client_id = client_id;
        cm.command_id = command_id;
        cm.command = (char *)verb;
        cm.count = (int32_t)count;
        cm.argument = (char *)(!strcmp(verb, "load") ? arg : "");
    } else {
        fprintf(stderr, "cubesim-push: unknown command '%s'\n", verb);
        usage(stderr);
        return 2;
    }

    lcm_t *lcm = lcm_create(url);
    if (!lcm) {
        fprintf(stderr, "cubesim-push: cannot open the bus %s\n", url ? url : "(LCM default)");
        return 2;
    }
    push_wait w = {client_id, command_id, 0, 0, {0}};
    cubesim_ack_t_subscription_t *sub = NULL;
    if (!no_wait)
        sub = cubesim_ack_t_subscribe(lcm, CS_CH_ACK, on_ack, &w);
    int rc = is_paint      ? cubesim_paint_t_publish(lcm, CS_CH_PAINT, &pm)
             : is_pressure ? cubesim_pressure_t_publish(lcm, CS_CH_PRESSURE, &prm)
             : is_curve    ? cubesim_curve_t_publish(lcm, CS_CH_CURVE, &cvm)
             : (is_force || is_drag) ? cubesim_force_t_publish(lcm, CS_CH_FORCE, &fm)
                                     : cubesim_command_t_publish(lcm, CS_CH_COMMAND, &cm);
    if (rc != 0) {
        fprintf(stderr, "cubesim-push: publishing failed\n");
        if (sub)
            cubesim_ack_t_unsubscribe(lcm, sub);
        lcm_destroy(lcm);
        return 2;
    }
    int status = 0;
    if (!no_wait) {
        double deadline = cs_mono_s() + timeout;
        int fd = lcm_get_fileno(lcm);
        while (!w.got) {
            double left = deadline - cs_mono_s();
            if (left <= 0)
                break;
            struct pollfd pfd = {fd, POLLIN, 0};
            int ms = (int)(left * 1000) + 1;
            if (poll(&pfd, 1, ms) > 0 && (pfd.revents & POLLIN))
                lcm_handle(lcm);
        }
        if (!w.got) {
            printf("no ack within %g s (is cubesimd running on this bus?)\n", timeout);
            status = 3;
        } else if (w.ok) {
            printf("ok\n");
        } else {
            printf("%s\n", w.message[0] ? w.message : "error (no message)");
            status = 1;
        }
        cubesim_ack_t_unsubscribe(lcm, sub);
    }
    lcm_destroy(lcm);
    return status;
}
