/*
 * main.c — cubesimd: command line, the single-threaded event loop, and the exit outputs
 * (--dump-nodes, --export). DESIGN.md "Contracts"; STYLE.md habit 7.
 *
 * Owns: the scene, the world, the bus and the daemon's run state (paused, step budget, epoch,
 * schedules). One loop iteration:
 *   poll LCM's fd (timeout: 0 when running as fast as possible, else the next deadline of a
 *   step, a status, a key frame or a paced send) → drain every pending message (handlers only
 *   decode, validate and queue) → apply queued inputs, ack each → step if due → queue deltas
 *   at the scene's publish_hz of simulated time → while paused, the current frame's deltas
 *   once if the surfaces may be ahead of them → status / key frame if due → paced sends.
 * Signals only set a flag: a step is never interrupted; SIGINT/SIGTERM end the loop, the
 * outputs are written, everything is freed and the exit status is 0.
 * Exit status: 0 done, 1 a runtime failure (output not written, static solve not converged,
 * bus failure), 2 bad command line or bad scene.
 */
#include <errno.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "bus.h"
#include "client/client_util.h"
#include "cubesim.h"
#include "dlog.h"
#include "mesh.h"
#include "number.h"
#include "scene.h"

typedef struct options {
    const char *scene;
    const char *lcm_url;
    long long steps;   /* 0: unlimited */
    double duration;   /* 0: unlimited; simulated seconds */
    bool realtime;
    bool static_solve;
    const char *dump_nodes;
    const char *export_path;
    bool quiet;
} options;

typedef struct cs_daemon {
    options opt;
    cs_dlog log;
    cs_scene scene;
    bool have_scene;
    cs_world_t *world;
    cs_bus_t *bus;

    bool paused;
    long long step_budget;  /* > 0: steps left of a "step N" command, then pause */
    int diverged_run;       /* diverged steps since the last accepted input (do_step) */
    bool diverged_stop;     /* a --steps/--duration run ended by a second diverged step */
    long long steps_limit;  /* from --steps/--duration; 0: none */
    long long steps_done;   /* by this process, all epochs */
    int32_t epoch;
    bool diverged_logged;
    bool fractured;         /* the world's topology changed since it was built from the scene */
    bool painted;           /* material fields were painted since it was built from the scene */
    bool unpublished;       /* the surfaces may be ahead of what the bus last queued: a step
                               off the publish grid, a forced fracture or a paint since the
                               last deltas; sent at once while paused (publish_paused) */

    double next_step;       /* monotonic s (realtime) */
    double next_publish;    /* simulated s */
    double next_status;     /* monotonic s */
    double next_keyframe;   /* monotonic s */

    /* status period accumulators */
    double period_wall0, period_sim0, period_step_ms;
    long long period_steps;
    double last_step_ms;
} cs_daemon;

static volatile sig_atomic_t g_stop; /* the one global: written by the signal handler only */

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

/* cs_world_set_cancel's question: a SIGINT or SIGTERM stops a long --static solve too */
static bool stop_asked(void *ctx)
{
    (void)ctx;
    return g_stop != 0;
}

static void usage(FILE *f)
{
    fputs("usage: cubesimd --scene FILE [--lcm URL] [--steps N | --duration S] [--realtime]\n"
          "                [--static] [--dump-nodes FILE.csv] [--export FILE] [--quiet]\n"
          "  --scene FILE        scene (JSON, SI units) to simulate\n"
          "  --lcm URL           LCM provider URL (default: LCM's, udpm://239.255.76.67:7667?ttl=0)\n"
          "  --steps N           stop after N physics steps (N >= 1)\n"
          "  --duration S        stop after S simulated seconds (S > 0)\n"
          "  --realtime          pace steps to the wall clock (one dt per step)\n"
          "  --static            solve for static equilibrium, write outputs, exit (no bus)\n"
          "  --dump-nodes FILE   at exit: CSV x,y,z,ux,uy,uz of every cube-mesh node\n"
          "  --export FILE       at exit: every object's surface via assimp (format by extension)\n"
          "  --quiet             no event lines on stderr (warnings and errors still)\n"
          "  --help              this text\n"
          "Without --steps/--duration it runs until SIGINT or SIGTERM.\n",
          f);
}

static int bad_cli(const char *fmt, const char *a, const char *b)
{
    fprintf(stderr, "cubesimd: ");
    fprintf(stderr, fmt, a, b);
    fprintf(stderr, " (try --help)\n");
    return 2;
}

/* Returns 0 ok, 1 --help shown, 2 bad (message printed). */
static int parse_cli(int argc, char **argv, options *o)
{
    memset(o, 0, sizeof *o);
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        bool takes = strcmp(a, "--scene") == 0 || strcmp(a, "--lcm") == 0 ||
                     strcmp(a, "--steps") == 0 || strcmp(a, "--duration") == 0 ||
                     strcmp(a, "--dump-nodes") == 0 || strcmp(a, "--export") == 0;
        const char *val = NULL;
        if (takes) {
            if (i + 1 >= argc || argv[i + 1][0] == '\0')
                return bad_cli("option %s needs a value%s", a, "");
            val = argv[++i];
        }
        if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            usage(stdout);
            return 1;
        } else if (strcmp(a, "--scene") == 0) {
            o->scene = val;
        } else if (strcmp(a, "--lcm") == 0) {
            o->lcm_url = val;
        } else if (strcmp(a, "--steps") == 0) {
            char *end = NULL;
            errno = 0;
            long long n = strtoll(val, &end, 10);
            if (errno || !end || *end || n < 1)
                return bad_cli("--steps '%s' is not a whole number >= 1%s", val, "");
            o->steps = n;
        } else if (strcmp(a, "--duration") == 0) {
            double d = 0;
            if (cs_parse_decimal(val, &d) || d <= 0)
                return bad_cli("--duration '%s' is not a finite number of seconds > 0%s", val,
                               "");
            o->duration = d;
        } else if (strcmp(a, "--realtime") == 0) {
            o->realtime = true;
        } else if (strcmp(a, "--static") == 0) {
            o->static_solve = true;
        } else if (strcmp(a, "--dump-nodes") == 0) {
            o->dump_nodes = val;
        } else if (strcmp(a, "--export") == 0) {
            o->export_path = val;
        } else if (strcmp(a, "--quiet") == 0) {
            o->quiet = true;
        } else {
            return bad_cli("unknown %s '%s'", a[0] == '-' ? "option" : "argument", a);
        }
    }
    if (!o->scene)
        return bad_cli("--scene FILE is required%s%s", "", "");
    if (o->steps && o->duration > 0)
        return bad_cli("--steps and --duration exclude each other%s%s", "", "");
    if (o->static_solve && (o->steps || o->duration > 0 || o->realtime))
        return bad_cli("--static cannot be combined with --steps, --duration or --realtime%s%s",
                       "", "");
    /* outputs are written at the end of a run: what can be known now is checked now */
    if (o->export_path && cs_mesh_export_format(o->export_path) != 0) {
        const char *dot = strrchr(o->export_path, '.');
        return bad_cli("--export '%s': no assimp exporter for the extension '%s'",
                       o->export_path, dot ? dot : "(none)");
    }
    const char *outs[2] = {o->export_path, o->dump_nodes};
    for (int k = 0; k < 2; k++) {
        if (!outs[k])
            continue;
        char dir[4096];
        snprintf(dir, sizeof dir, "%s", outs[k]);
        char *slash = strrchr(dir, '/');
        if (slash)
            slash[slash == dir ? 1 : 0] = 0;
        else
            snprintf(dir, sizeof dir, ".");
        if (access(dir, W_OK) != 0)
            return bad_cli(k ? "--dump-nodes: cannot write in '%s': %s"
                             : "--export: cannot write in '%s': %s",
                           dir, strerror(errno));
    }
    return 0;
}

/* ---------------------------------------------------------------- outputs */

static int write_dump_nodes(const cs_world_t *w, const char *path, char *err, size_t errlen)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        snprintf(err, errlen, "--dump-nodes: cannot write '%s': %s", path, strerror(errno));
        return -1;
    }
    fprintf(f, "x,y,z,ux,uy,uz\n");
    int n = cs_world_object_ids(w, NULL, 0);
    cs_object_id *ids = calloc((size_t)(n > 0 ? n : 1), sizeof *ids);
    if (!ids) {
        fclose(f);
        snprintf(err, errlen, "--dump-nodes: out of memory");
        return -1;
    }
    n = cs_world_object_ids(w, ids, n);
    for (int i = 0; i < n; i++) {
        const double *rest = NULL, *pos = NULL, *vel = NULL;
        int nn = 0;
        if (cs_object_nodes(w, ids[i], &rest, &pos, &vel, &nn) != CS_OK)
            continue;
        for (int j = 0; j < nn; j++) {
            const double *r = rest + 3 * j, *p = pos + 3 * j;
            fprintf(f, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", r[0], r[1], r[2], p[0] - r[0],
                    p[1] - r[1], p[2] - r[2]);
        }
    }
    free(ids);
    if (ferror(f) | (fclose(f) != 0)) {
        snprintf(err, errlen, "--dump-nodes: error writing '%s'", path);
        return -1;
    }
    return 0;
}

static int write_export(const cs_world_t *w, const char *path, char *err, size_t errlen)
{
    int n = cs_world_object_ids(w, NULL, 0);
    size_t cnt = (size_t)(n > 0 ? n : 1);
    cs_object_id *ids = calloc(cnt, sizeof *ids);
    cs_mesh *pieces = calloc(cnt, sizeof *pieces);
    const char **names = calloc(cnt, sizeof *names);
    int rc = -1;
    if (!ids || !pieces || !names) {
        snprintf(err, errlen, "--export: out of memory");
        goto done;
    }
    n = cs_world_object_ids(w, ids, n);
    for (int i = 0; i < n; i++) {
        const double *v = NULL;
        const int32_t *t = NULL;
        int nv = 0, nt = 0;
        cs_object_info info;
        memset(&info, 0, sizeof info);
        cs_object_get_info(w, ids[i], &info);
        names[i] = info.name ? info.name : "object";
        cs_object_surface(w, ids[i], &v, &nv, &t, &nt);
        /* Copies: cs_mesh owns its arrays, and the export must not alias engine memory. */
        pieces[i].v = malloc((size_t)(nv > 0 ? nv : 1) * 3 * sizeof(double));
        pieces[i].t = malloc((size_t)(nt > 0 ? nt : 1) * 3 * sizeof(int32_t));
        if (!pieces[i].v || !pieces[i].t) {
            snprintf(err, errlen, "--export: out of memory");
            goto done;
        }
        if (nv)
            memcpy(pieces[i].v, v, (size_t)nv * 3 * sizeof(double));
        if (nt)
            memcpy(pieces[i].t, t, (size_t)nt * 3 * sizeof(int32_t));
        pieces[i].nv = nv;
        pieces[i].nt = nt;
    }
    rc = cs_mesh_export(path, pieces, names, n, err, errlen);
done:
    if (pieces)
        for (int i = 0; i < n; i++)
            cs_mesh_free(&pieces[i]);
    free(pieces);
    free(names);
    free(ids);
    return rc;
}

/* Write --dump-nodes and --export. Returns 0, or 1 if one failed (reported). */
static int write_outputs(cs_daemon *d)
{
    char err[512];
    int rc = 0;
    if (d->opt.dump_nodes) {
        if (write_dump_nodes(d->world, d->opt.dump_nodes, err, sizeof err) < 0) {
            cs_dlog_warn(&d->log, NULL, "%s", err);
            rc = 1;
        } else {
            cs_dlog_info(&d->log, "wrote nodes to %s", d->opt.dump_nodes);
        }
    }
    if (d->opt.export_path) {
        if (write_export(d->world, d->opt.export_path, err, sizeof err) < 0) {
            cs_dlog_warn(&d->log, NULL, "--export: %s", err);
            rc = 1;
        } else {
            cs_dlog_info(&d->log, "exported surfaces to %s", d->opt.export_path);
        }
    }
    return rc;
}

/* ---------------------------------------------------------------- world life */

/* Load and instantiate a scene into scene and world; on error nothing is kept. */
static int load_scene(const char *path, cs_scene *scene, cs_world_t **world, char *err,
                      size_t errlen)
{
    memset(scene, 0, sizeof *scene);
    *world = NULL;
    if (cs_scene_load(path, scene, err, errlen) != 0)
        return -1;
    if (cs_scene_instantiate(scene, world, err, errlen) != 0) {
        cs_scene_free(scene);
        memset(scene, 0, sizeof *scene);
        *world = NULL;
        return -1;
    }
    return 0;
}

/* One warning per object of the scene voxelized coarsely (cs_scene_coarse_object), per
 * object that starts below the ground (cs_scene_below_ground_object) and per mesh whose
 * inside-out shells were turned outward (cs_scene_turned_shells). */
static void warn_scene(cs_dlog *log, const cs_scene *scene, const cs_world_t *world)
{
    char msg[512];
    for (int i = 0; i < scene->n_objects; i++) {
        if (cs_scene_coarse_object(scene, world, i, msg, sizeof msg))
            cs_dlog_warn(log, NULL, "%s", msg);
        if (cs_scene_below_ground_object(scene, world, i, msg, sizeof msg))
            cs_dlog_warn(log, NULL, "%s", msg);
        if (cs_scene_turned_shells(scene, i, msg, sizeof msg))
            cs_dlog_warn(log, NULL, "%s", msg);
    }
}

static double publish_period(const cs_daemon *d)
{
    double hz = d->scene.publish_hz;
    return (isfinite(hz) && hz > 0) ? 1.0 / hz : 0.0;
}

static void sync_context(cs_daemon *d)
{
    cs_bus_set_context(d->bus, d->epoch, cs_world_frame(d->world), cs_world_time(d->world));
}

/* A new epoch began (start, reset, load): resend everything. */
static void new_epoch(cs_daemon *d, double now)
{
    cs_bus_forget_objects(d->bus);
    cs_bus_set_max_force(d->bus, cs_world_get_def(d->world)->max_force);
    sync_context(d);
    if (cs_bus_queue_snapshot(d->bus, d->world, false) < 0)
        cs_dlog_warn(&d->log, "snapshot", "could not queue a snapshot (out of memory)");
    d->next_publish = cs_world_time(d->world) + publish_period(d);
    double ks = d->scene.keyframe_s;
    d->next_keyframe = now + ((isfinite(ks) && ks > 0) ? ks : 2.0);
    d->next_step = now;
    d->diverged_logged = false;
    d->unpublished = false; /* the snapshot just queued is the current state */
}

/* One info line per fracture event of the last step or forced fracture. */
static void log_events(cs_daemon *d)
{
    int ne = 0;
    const cs_event *ev = cs_world_events(d->world, &ne);
    for (int i = 0; ev && i < ne; i++) {
        const cs_event *e = &ev[i];
        cs_object_info info, pinfo;
        memset(&info, 0, sizeof info);
        memset(&pinfo, 0, sizeof pinfo);
        cs_object_get_info(d->world, e->object, &info);
        if (e->kind == CS_EVENT_FRACTURE) {
            cs_dlog_info(&d->log,
                         "fracture: object %u '%s' at frame %lld, point (%.4g, %.4g, %.4g) m, "
                         "normal (%.3g, %.3g, %.3g), stress %.4g Pa, %d faces cut, %d closing "
                         "triangles, %d loops closed by fans, %d pieces rebuilt from cubes, "
                         "%d grazing cubes dropped", (unsigned)e->object,
                         info.name ? info.name : "?", (long long)e->frame, e->point[0],
                         e->point[1], e->point[2], e->normal[0], e->normal[1], e->normal[2],
                         e->stress, e->faces_cut, e->closing_triangles, e->fallback_loops,
                         e->rebuilt_pieces, e->dropped_pieces);
        } else if (e->kind == CS_EVENT_NEW_PIECE) {
            cs_object_get_info(d->world, e->parent, &pinfo);
            cs_dlog_info(&d->log, "fracture: new piece %u '%s' broke off object %u '%s' at "
                         "frame %lld (%d cells)", (unsigned)e->object,
                         info.name ? info.name : "?", (unsigned)e->parent,
                         pinfo.name ? pinfo.name : "?", (long long)e->frame, info.n_cells);
        }
    }
    if (ne > 0)
        d->fractured = true;
}

/*
 * After a step or a forced fracture: log its fracture events and queue its topology changes
 * (before any delta of this frame, so no delta is ever ahead of its topology).
 */
static void publish_topology(cs_daemon *d)
{
    log_events(d);
    int n = 0;
    const cs_topo_change *tc = cs_world_topology_changes(d->world, &n);
    if (!tc || n <= 0)
        return;
    d->fractured = true;
    sync_context(d);
    if (cs_bus_queue_topology(d->bus, d->world, tc, n) < 0)
        cs_dlog_warn(&d->log, "topology", "could not queue topology changes (out of memory)");
}

/* ---------------------------------------------------------------- inputs */

static void apply_force(cs_daemon *d, const cs_input *in, char *msg, size_t msglen)
{
    cs_object_id id = in->object_id > 0 ? (cs_object_id)in->object_id
                                        : cs_world_find_object(d->world, in->object_name);
    if (id == CS_NULL_OBJECT) {
        snprintf(msg, msglen, "force: no object named '%s'", in->object_name);
        return;
    }
    cs_object_info info;
    if (cs_object_get_info(d->world, id, &info) != CS_OK) {
        snprintf(msg, msglen, "force: unknown object id %u", (unsigned)id);
        return;
    }
    char err[256] = "";
    int rc;
    if (in->force_kind == 0)
        rc = cs_world_apply_force(d->world, id, in->point, in->force, in->duration, err,
                                  sizeof err);
    else
        rc = cs_world_drag(d->world, id, in->point, in->target, in->stiffness, in->duration,
                           err, sizeof err);
    if (rc != CS_OK)
        snprintf(msg, msglen, "force: %s", err[0] ? err : cs_status_str(rc));
}

/* Paint, pressure and curve inputs (seed 001 §4.1): the object as for forces, the engine's
 * one-line refusal as the ack's message. */
static void apply_sculpt(cs_daemon *d, const cs_input *in, char *msg, size_t msglen)
{
    cs_object_id id = in->object_id > 0 ? (cs_object_id)in->object_id
                                        : cs_world_find_object(d->world, in->object_name);
    cs_object_info info;
    if (id == CS_NULL_OBJECT) {
        snprintf(msg, msglen, "%s: no object named '%s'", in->request, in->object_name);
        return;
    }
    if (cs_object_get_info(d->world, id, &info) != CS_OK) {
        snprintf(msg, msglen, "%s: unknown object id %u", in->request, (unsigned)id);
        return;
    }
    char err[256] = "";
    int rc = CS_ERR_INVALID, touched = 0;
    if (in->kind == CS_INPUT_PAINT)
        rc = cs_world_paint(d->world, id, in->point, in->radius, &in->factors, &touched, err,
                            sizeof err);
    else if (in->kind == CS_INPUT_PRESSURE)
        rc = cs_world_pressure(d->world, id, in->pressure, in->duration, err, sizeof err);
    else if (in->kind == CS_INPUT_CURVE)
        rc = cs_world_drag_curve(d->world, id, in->points, in->n_points, in->stiffness,
                                 in->duration, err, sizeof err);
    if (rc != CS_OK) {
        snprintf(msg, msglen, "%s: %s", in->request, err[0] ? err : cs_status_str(rc));
        return;
    }
    if (in->kind == CS_INPUT_PAINT && touched > 0) {
        d->painted = true;
        d->unpublished = true; /* a rigid object is refitted to its new mass properties */
    }
    if (in->kind == CS_INPUT_PAINT)
        cs_dlog_info(&d->log, "paint of object %u '%s': %d Gauss points", (unsigned)id,
                     info.name, touched);
}

static void apply_command(cs_daemon *d, const cs_input *in, double now, char *msg, size_t msglen)
{
    switch (in->command) {
    case CS_CMD_PAUSE:
        d->paused = true;
        d->step_budget = 0;
        cs_dlog_info(&d->log, "paused at frame %lld", (long long)cs_world_frame(d->world));
        break;
    case CS_CMD_RESUME:
        d->paused = false;
        d->step_budget = 0;
        d->next_step = now;
        cs_dlog_info(&d->log, "resumed at frame %lld", (long long)cs_world_frame(d->world));
        break;
    case CS_CMD_STEP:
        d->paused = false;
        d->step_budget = in->count;
        d->next_step = now;
        cs_dlog_info(&d->log, "stepping %d steps", (int)in->count);
        break;
    case CS_CMD_RESET:
        if (d->fractured || d->painted) {
            /* Pieces cannot be put back together, and painting changed the material: rebuild
             * the world from the scene as it was loaded (the same objects, ids, rest shapes
             * and design fields a fresh start would have). */
            cs_world_t *world = NULL;
            char err[400] = "";
            if (cs_scene_instantiate(&d->scene, &world, err, sizeof err) != 0) {
                snprintf(msg, msglen, "reset: cannot rebuild the scene: %s", err);
                break; /* the old world stays */
            }
            cs_world_destroy(d->world);
            d->world = world;
            d->fractured = false;
            d->painted = false;
        } else {
            cs_world_reset(d->world);
        }
        d->epoch++;
        d->step_budget = 0;
        new_epoch(d, now);
        cs_dlog_info(&d->log, "reset: epoch %d", (int)d->epoch);
        break;
    case CS_CMD_SNAPSHOT: {
        sync_context(d);
        int32_t id = cs_bus_queue_snapshot(d->bus, d->world, true);
        if (id < 0)
            snprintf(msg, msglen, "snapshot: out of memory");
        else
            cs_dlog_info(&d->log, "snapshot %d queued on request", (int)id);
        break;
    }
    case CS_CMD_LOAD: {
        cs_scene scene;
        cs_world_t *world = NULL;
        char err[400] = "";
        if (load_scene(in->argument, &scene, &world, err, sizeof err) != 0) {
            snprintf(msg, msglen, "load: %s", err);
            break; /* the old world stays, untouched */
        }
        cs_world_destroy(d->world);
        cs_scene_free(&d->scene);
        d->scene = scene;
        d->world = world;
        d->fractured = false;
        d->painted = false;
        d->epoch++;
        d->step_budget = 0;
        new_epoch(d, now);
        cs_dlog_info(&d->log, "loaded scene %s: epoch %d, %d objects", in->argument,
                     (int)d->epoch, d->scene.n_objects);
        warn_scene(&d->log, &d->scene, d->world);
        break;
    }
    case CS_CMD_FRACTURE: {
        cs_object_id id = in->object_id > 0 ? (cs_object_id)in->object_id
                                            : cs_world_find_object(d->world, in->object_name);
        cs_object_info info;
        if (id == CS_NULL_OBJECT) {
            snprintf(msg, msglen, "fracture: no object named '%s'", in->object_name);
            break;
        }
        if (cs_object_get_info(d->world, id, &info) != CS_OK) {
            snprintf(msg, msglen, "fracture: unknown object id %u", (unsigned)id);
            break;
        }
        char err[300] = "";
        int rc = cs_world_fracture(d->world, id, in->point, in->normal, in->radius, err,
                                   sizeof err);
        if (rc != CS_OK) {
            snprintf(msg, msglen, "fracture: %s", err[0] ? err : cs_status_str(rc));
            break;
        }
        int ne = 0;
        cs_world_events(d->world, &ne);
        cs_dlog_info(&d->log, "fracture of object %u '%s' forced at frame %lld: %d events",
                     (unsigned)id, info.name ? info.name : "?",
                     (long long)cs_world_frame(d->world), ne);
        publish_topology(d);
        d->unpublished = true; /* while paused: the deltas follow (publish_paused) */
        break;
    }
    case CS_CMD_UNKNOWN:
        snprintf(msg, msglen, "unknown command '%s'", in->request);
        break;
    }
}

static void apply_inputs(cs_daemon *d, double now)
{
    cs_input in;
    while (cs_bus_next_input(d->bus, &in)) {
        char msg[512] = "";
        if (in.error[0]) {
            snprintf(msg, sizeof msg, "%s", in.error); /* logged when it was refused */
        } else {
            if (in.kind == CS_INPUT_FORCE)
                apply_force(d, &in, msg, sizeof msg);
            else if (in.kind == CS_INPUT_COMMAND)
                apply_command(d, &in, now, msg, sizeof msg);
            else
                apply_sculpt(d, &in, msg, sizeof msg);
            if (!msg[0])
                d->diverged_run = 0; /* a client changed the world: its next divergence is new */
            char key[48];
            snprintf(key, sizeof key, "refused input, client %lld", (long long)in.client_id);
            if (msg[0])
                cs_dlog_warn(&d->log, key,
                             "refused %s from client %lld (command %lld): %s", in.request,
                             (long long)in.client_id, (long long)in.command_id, msg);
            else if (in.kind != CS_INPUT_COMMAND) {
                /* a client streaming drags at 60 Hz, or a burst, would flood the log */
                snprintf(key, sizeof key, "applied input, client %lld", (long long)in.client_id);
                cs_dlog_event(&d->log, key, "%s from client %lld (command %lld) applied",
                              in.request, (long long)in.client_id, (long long)in.command_id);
            }
        }
        sync_context(d);
        cs_bus_ack(d->bus, &in, msg[0] == 0, msg);
        cs_input_clear(&in);
    }
}

/* ---------------------------------------------------------------- stepping */

/* One physics step and what follows it. Returns false if the run must stop. */
/* The current frame's deltas (and rigid poses) into the send queue. An exact one (every
 * vertex whose float32 changed, every vertex of a rigid object) makes the clients current
 * (d->unpublished cleared) unless memory ran out (warned); a regular one, within
 * publish_epsilon and with rigid objects by their poses (whose float32 rebuild is a rounding
 * off the daemon's vertices, even at publish_epsilon 0), does not: a pause at that frame still
 * flushes (publish_paused; until session 32 a pause landing on a publish frame left the
 * clients' rigid surfaces a rounding off the status' hashes). */
static void queue_deltas(cs_daemon *d, bool exact)
{
    sync_context(d);
    if (cs_bus_queue_deltas(d->bus, d->world, exact ? -1.0 : d->scene.publish_epsilon) < 0)
        cs_dlog_warn(&d->log, "deltas", "could not queue deltas (out of memory)");
    else if (exact)
        d->unpublished = false;
}

static void do_step(cs_daemon *d)
{
    double t0 = cs_dlog_now();
    int rc = cs_world_step(d->world);
    double ms = 1e3 * (cs_dlog_now() - t0);
    d->last_step_ms = ms;
    d->period_step_ms += ms;
    d->period_steps++;
    d->steps_done++;
    publish_topology(d);
    /* Counted since the last accepted input, not reset by a step that did not diverge: a
     * step from rest can succeed where the next, from the speed it gave, diverges again (a
     * scene load of 600 m/s per step on a rigid body, whose limit is 1 km/s: frames 2, 4, 6,
     * ... diverged, never two in a row, and a --steps run ended with exit status 0). */
    if (rc == CS_ERR_DIVERGED)
        d->diverged_run++;
    if (rc == CS_ERR_DIVERGED && d->diverged_run == 1) {
        /* The engine undid the object's step, dropped its inputs and left it at rest where it
         * was: what made it diverge (one client's absurd force, say) is gone, so the run goes
         * on for every other client. */
        cs_dlog_warn(&d->log, NULL,
                     "step diverged at frame %lld (undone: the object's inputs dropped, "
                     "left at rest)", (long long)cs_world_frame(d->world));
    } else if (rc == CS_ERR_DIVERGED && d->steps_limit > 0) {
        /* Again without new inputs (a scene load too large, say), in a run of --steps or
         * --duration: no client will resume it, so it ends, exit status 1 (pausing left such
         * a run waiting for ever) */
        d->diverged_stop = true;
        d->steps_limit = d->steps_done;
        cs_dlog_warn(&d->log, NULL, "step diverged again at frame %lld (undone): run stopped",
                     (long long)cs_world_frame(d->world));
    } else if (rc == CS_ERR_DIVERGED) {
        /* Again without new inputs: stepping on would only repeat it. */
        d->paused = true;
        d->step_budget = 0;
        cs_dlog_warn(&d->log, NULL, "step diverged again at frame %lld (undone): paused",
                     (long long)cs_world_frame(d->world));
    } else if (rc == CS_ERR_NOT_CONVERGED) {
        cs_dlog_warn(&d->log, "not converged", "frame %lld: solver did not converge",
                     (long long)cs_world_frame(d->world));
    } else if (rc != CS_OK) {
        cs_dlog_warn(&d->log, "step failed", "step failed: %s", cs_status_str(rc));
    }
    if (d->step_budget > 0 && --d->step_budget == 0) {
        d->paused = true;
        cs_dlog_info(&d->log, "step command done: paused at frame %lld",
                     (long long)cs_world_frame(d->world));
    }
    double t = cs_world_time(d->world), period = publish_period(d);
    d->unpublished = true;
    if (t + 1e-9 * (period > 0 ? period : 1) >= d->next_publish) {
        queue_deltas(d, false);
        d->next_publish += period;
        if (d->next_publish <= t)
            d->next_publish = t + period;
    }
}

/*
 * While paused, bring the clients up to the world as it is: the deltas (and rigid poses) of
 * the current frame, queued behind whatever the FIFO holds (a forced fracture's topology
 * changes go first, so every delta finds the topology it was made for). Without this, a
 * daemon paused off the publish grid (publish_hz below the step rate) leaves its clients at
 * the last publish frame, behind its status' state_hash, until it steps again or the next
 * key frame. After a forced fracture or a paint it is a guarantee rather than a repair: the
 * change sends every new vertex where it is and moves none it had, and a rigid object's
 * refit (cs_rigid_sync, cs_rigid_fields_changed) re-skins by double round-off only — none of
 * it visible in float32 as measured (README CUBESIM_TOPOLOGY). next_publish stays.
 */
static void publish_paused(cs_daemon *d)
{
    if (d->paused && d->unpublished)
        queue_deltas(d, true); /* if out of memory: tried again on the next loop iteration */
}

static void publish_status(cs_daemon *d, double now)
{
    cs_bus_status_extra x;
    memset(&x, 0, sizeof x);
    x.paused = d->paused;
    x.step_ms = d->last_step_ms;
    x.step_ms_avg = d->period_steps ? d->period_step_ms / (double)d->period_steps : 0;
    double wall = now - d->period_wall0;
    double sim = cs_world_time(d->world) - d->period_sim0;
    x.real_time_factor = !d->paused && wall > 0 && sim > 0 ? sim / wall : 0;
    sync_context(d);
    if (cs_bus_publish_status(d->bus, d->world, &x) < 0)
        cs_dlog_warn(&d->log, "status", "could not publish status");
    d->period_wall0 = now;
    d->period_sim0 = cs_world_time(d->world);
    d->period_step_ms = 0;
    d->period_steps = 0;
}

static double status_period(const cs_daemon *d)
{
    double hz = d->scene.status_hz;
    return (isfinite(hz) && hz > 0) ? 1.0 / hz : 0.25;
}

static bool limit_reached(const cs_daemon *d)
{
    return d->steps_limit > 0 && d->steps_done >= d->steps_limit;
}

static int run_loop(cs_daemon *d)
{
    double now = cs_dlog_now();
    d->period_wall0 = now;
    d->period_sim0 = cs_world_time(d->world);
    new_epoch(d, now);
    publish_status(d, now);
    d->next_status = now + status_period(d);
    struct pollfd pfd = {.fd = cs_bus_fileno(d->bus), .events = POLLIN};

    while (!g_stop && !limit_reached(d)) {
        now = cs_dlog_now();
        double next_send = now;
        int pending = cs_bus_pump(d->bus, now, &next_send);
        bool running = !d->paused;
        double wake = d->next_status < d->next_keyframe ? d->next_status : d->next_keyframe;
        if (pending && next_send < wake)
            wake = next_send;
        if (running && !d->opt.realtime)
            wake = now;
        if (running && d->opt.realtime && d->next_step < wake)
            wake = d->next_step;
        if (wake > now + 0.1)
            wake = now + 0.1; /* signals and the log's summaries get a look in */
        double wait = wake - now;
        struct timespec ts = {0, 0};
        if (wait > 0) {
            ts.tv_sec = (time_t)wait;
            ts.tv_nsec = (long)((wait - (double)ts.tv_sec) * 1e9);
        }
        int pr = ppoll(&pfd, 1, &ts, NULL);
        if (pr < 0 && errno != EINTR) {
            cs_dlog_warn(&d->log, NULL, "poll failed: %s", strerror(errno));
            return 1;
        }
        if (g_stop)
            break;
        if (pr > 0 && cs_bus_drain(d->bus, 10000) < 0) {
            cs_dlog_warn(&d->log, NULL, "LCM failed while receiving");
            return 1;
        }
        now = cs_dlog_now();
        apply_inputs(d, now);

        if (!d->paused) {
            if (!d->opt.realtime) {
                do_step(d);
            } else if (now >= d->next_step) {
                do_step(d);
                d->next_step += cs_world_get_def(d->world)->dt; /* a load may change dt */
                now = cs_dlog_now();
                if (now - d->next_step > 0.5) {
                    cs_dlog_warn(&d->log, "behind", "%.2f s behind real time: skipping ahead",
                                 now - d->next_step);
                    d->next_step = now;
                }
            }
        }
        publish_paused(d); /* paused (now, or by the step just done) with news: send it */
        now = cs_dlog_now();
        if (now >= d->next_keyframe) {
            sync_context(d);
            cs_bus_queue_snapshot(d->bus, d->world, true);
            double ks = d->scene.keyframe_s;
            d->next_keyframe = now + ((isfinite(ks) && ks > 0) ? ks : 2.0);
        }
        if (now >= d->next_status) {
            publish_status(d, now);
            d->next_status += status_period(d);
            if (d->next_status <= now)
                d->next_status = now + status_period(d);
        }
        cs_dlog_flush(&d->log);
    }
    /* Last words: the final state and a status, then a bounded flush of the outbox. */
    now = cs_dlog_now();
    sync_context(d);
    cs_bus_queue_deltas(d->bus, d->world, -1.0); /* exact, as while paused */
    publish_status(d, now);
    double until = now + 1.0;
    for (;;) {
        double next_send = now;
        if (cs_bus_pump(d->bus, now, &next_send) == 0 || now >= until)
            break;
        double wait = next_send - now;
        struct timespec ts = {(time_t)wait, (long)((wait - (double)(time_t)wait) * 1e9)};
        if (wait > 0)
            nanosleep(&ts, NULL);
        now = cs_dlog_now();
    }
    cs_dlog_info(&d->log, "%s after %lld steps (frame %lld, t = %.6g s)",
                 g_stop ? "stopped by signal" : d->diverged_stop ? "diverged" : "done",
                 d->steps_done, (long long)cs_world_frame(d->world), cs_world_time(d->world));
    return d->diverged_stop ? 1 : 0;
}

/* ---------------------------------------------------------------- main */

/* For a static solve that failed: the object nearest incompressibility, if any is near it
 * (ν ≥ 0.49), where cubes lock and the solves' conditioning grows as 1/(1 − 2ν) (README
 * "Statics"), as "; object 'name' has poisson ν: ...", else "". */
static void static_hint(const cs_world_t *w, char *out, size_t len)
{
    const int n = cs_world_object_ids(w, NULL, 0);
    cs_object_id *ids = n > 0 ? malloc((size_t)n * sizeof *ids) : NULL;
    cs_object_info best = {0}, info;
    const int m = ids ? cs_world_object_ids(w, ids, n) : 0;
    for (int i = 0; i < m && i < n; i++)
        if (cs_object_get_info(w, ids[i], &info) == CS_OK && info.model != CS_MODEL_RIGID &&
            info.n_fixed_nodes > 0 && info.material.poisson > best.material.poisson)
            best = info;
    free(ids);
    if (best.name && best.material.poisson >= 0.49)
        snprintf(out, len, "; object '%.40s' has poisson %g: near incompressibility its cubes "
                 "lock and its solves need far more iterations (README \"Statics\")",
                 best.name, best.material.poisson);
}

/* After a static solve: a line for each object whose equilibrium is unstable (a buckled
 * column held straight by symmetry), and one for each with cubes turned inside out (a solve
 * can converge there: the elastic models are linear in the strain, and a load far beyond what
 * they represent, concentrated on a few cubes, turns them inside out without a word). */
static void warn_static_state(cs_daemon *d)
{
    const int n = cs_world_object_ids(d->world, NULL, 0);
    cs_object_id *ids = n > 0 ? malloc((size_t)n * sizeof *ids) : NULL;
    const int m = ids ? cs_world_object_ids(d->world, ids, n) : 0;
    for (int i = 0; i < m && i < n; i++) {
        cs_object_info info;
        int count = 0;
        double lo = 1;
        bool unstable = false;
        if (cs_object_get_info(d->world, ids[i], &info) != CS_OK || info.model == CS_MODEL_RIGID)
            continue;
        if (cs_object_static_unstable(d->world, ids[i], &unstable) == CS_OK && unstable)
            cs_dlog_warn(&d->log, NULL, "static solve: object '%.40s': the equilibrium found is "
                         "unstable (its tangent stiffness has a direction of negative "
                         "curvature: a column past its buckling load, held straight by "
                         "symmetry); a small disturbance leaves it", info.name);
        if (cs_object_inverted_cells(d->world, ids[i], &count, &lo) == CS_OK && count > 0)
            cs_dlog_warn(&d->log, NULL, "static solve: object '%.40s': %d of %d cubes turned "
                         "inside out (smallest corner volume ratio %.3g): its loads are beyond "
                         "what the model represents there", info.name, count, info.n_cells, lo);
    }
    free(ids);
}

int main(int argc, char **argv)
{
    cs_daemon d;
    memset(&d, 0, sizeof d);
    int pc = parse_cli(argc, argv, &d.opt);
    if (pc == 1)
        return 0;
    if (pc)
        return 2;
    d.log.quiet = d.opt.quiet;

    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);

    char err[512] = "";
    if (load_scene(d.opt.scene, &d.scene, &d.world, err, sizeof err) != 0) {
        /* cs_scene_load's messages usually begin with the path already, as cs_msg_path
         * shows it (a long one cut to its end). */
        char shown[CS_MSG_SCENE_PATH + 1];
        cs_msg_path(d.opt.scene, shown, sizeof shown);
        if (strncmp(err, shown, strlen(shown)) == 0)
            fprintf(stderr, "cubesimd: %s\n", err);
        else
            fprintf(stderr, "cubesimd: scene %s: %s\n", shown, err);
        return 2;
    }
    d.have_scene = true;
    const cs_world_def *wd = cs_world_get_def(d.world);
    if (d.opt.steps)
        d.steps_limit = d.opt.steps;
    else if (d.opt.duration > 0) {
        /* 1e15 steps (about 500 years of 1/60 s steps at a million a second) is beyond any
         * run; past 9.2e18 the count would not fit (it used to wrap and run one step) */
        const double nsteps = ceil(d.opt.duration / wd->dt - 1e-9);
        if (!(nsteps <= 1e15)) {
            fprintf(stderr, "cubesimd: --duration %g s is %.3g steps of dt = %g s; at most 1e15 "
                            "(leave --duration out to run until stopped)\n",
                    d.opt.duration, nsteps, wd->dt);
            cs_world_destroy(d.world);
            cs_scene_free(&d.scene);
            return 2;
        }
        d.steps_limit = (long long)nsteps;
    }
    if (d.opt.duration > 0 && d.steps_limit < 1)
        d.steps_limit = 1;
    cs_dlog_info(&d.log, "scene %s: %d objects, dt = %g s", d.opt.scene, d.scene.n_objects,
                 wd->dt);
    warn_scene(&d.log, &d.scene, d.world);

    int rc = 0;
    if (d.opt.static_solve) {
        double t0 = cs_dlog_now();
        cs_world_set_cancel(d.world, stop_asked, NULL);
        int sr = cs_world_solve_static(d.world);
        const cs_step_stats *st = cs_world_last_stats(d.world);
        if (sr == CS_ERR_CANCELLED) {
            cs_dlog_warn(&d.log, NULL, "static solve stopped by signal after %.1f s and %d "
                         "iterations; objects left at their last load level reached",
                         cs_dlog_now() - t0, st ? st->cg_iterations : -1);
            rc = 1;
        } else if (sr != CS_OK) {
            char hint[200] = "";
            static_hint(d.world, hint, sizeof hint);
            cs_dlog_warn(&d.log, NULL, "static solve: %s (residual %.3g of the loads after %d "
                         "iterations)%s", cs_status_str(sr), st ? st->cg_residual : NAN,
                         st ? st->cg_iterations : -1, hint);
            rc = 1;
        } else {
            cs_dlog_info(&d.log, "static solve converged in %.1f ms (%d iterations)",
                         1e3 * (cs_dlog_now() - t0), st ? st->cg_iterations : -1);
        }
        warn_static_state(&d);
    } else {
        /* the daemon receives too (inputs, bursts of them, a load's long argument): its udpm
         * socket gets the clients' 4 MiB receive buffer unless the URL names one */
        char *url = cs_client_url(d.opt.lcm_url);
        if (!url || cs_bus_create(url, &d.log, &d.bus, err, sizeof err) != 0) {
            fprintf(stderr, "cubesimd: %s\n", url ? err : "out of memory");
            free(url);
            cs_world_destroy(d.world);
            cs_scene_free(&d.scene);
            return 2;
        }
        cs_dlog_info(&d.log, "session %lld on %s, %s", (long long)cs_bus_session_id(d.bus), url,
                     d.opt.realtime ? "real time" : "as fast as possible");
        free(url);
        rc = run_loop(&d);
    }
    if (write_outputs(&d) != 0 && rc == 0)
        rc = 1;
    cs_bus_destroy(d.bus);
    cs_world_destroy(d.world);
    cs_scene_free(&d.scene);
    return rc;
}
