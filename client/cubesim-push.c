/*
 * cubesim-push — send one force or command to cubesimd and wait for its acknowledgement
 * (DESIGN.md "Bus"; lcmtypes/force_t.lcm, command_t.lcm, ack_t.lcm).
 *
 *   cubesim-push force OBJECT --at X Y Z --force FX FY FZ [--for SECONDS]
 *   cubesim-push drag OBJECT --at X Y Z --to X Y Z [--stiffness K] [--for SECONDS]
 *   cubesim-push pause|resume|reset|snapshot
 *   cubesim-push step N
 *   cubesim-push load SCENE
 *   cubesim-push fracture OBJECT --at X Y Z --normal NX NY NZ [--radius R]
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
#include "cubesim_force_t.h"

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
    double radius = 0.0;
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
        } else if (!strcmp(a, "--stiffness") && i + 1 < argc) {
            if (cs_parse_double(argv[++i], &stiffness) || stiffness <= 0) {
                fprintf(stderr, "cubesim-push: --stiffness: '%s' is not a number > 0\n", argv[i]);
                return 2;
            }
        } else if (!strcmp(a, "--for") && i + 1 < argc) {
            if (cs_parse_double(argv[++i], &seconds) || seconds < 0) {
                fprintf(stderr, "cubesim-push: --for: '%s' is not a time >= 0\n", argv[i]);
                return 2;
            }
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
    char fracture_arg[512];
    cubesim_force_t fm;
    cubesim_command_t cm;
    memset(&fm, 0, sizeof fm);
    memset(&cm, 0, sizeof cm);
    int64_t client_id = cs_random_id(), command_id = 1;

    if ((have_normal || have_radius) && !is_fracture) {
        fprintf(stderr, "cubesim-push: --normal and --radius go with fracture\n");
        return 2;
    }
    if (is_fracture) {
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
    int rc = (is_force || is_drag) ? cubesim_force_t_publish(lcm, CS_CH_FORCE, &fm)
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
