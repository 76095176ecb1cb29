/*
 * tests/stress/models.c — cs_stress_models: every model file of a directory tree (by default
 * Debian's assimp-testmodels, /usr/share/assimp/models: ~600 files in 40 formats, including
 * deliberately broken ones) through the daemon's load path, one child process per file so
 * that one crash is one failure, not the end of the sweep.
 *
 *   cs_stress_models [--dir DIR] [--timeout S] [--cubes N] [--list]
 *
 * Per file: cs_mesh_load (assimp) for its extent; then the daemon's path: a scene naming the
 * file, scaled so that its largest extent is 1 m and placed on the ground, parsed
 * (cs_scene_parse: load, place, check, subdivide) and instantiated (corotational, N cubes
 * across, default 8); 5 implicit steps
 * under gravity; one forced fracture through the middle; 2 more steps. Outcomes:
 *   refused   load or add returned an error: the message must be one non-empty line that
 *             names a problem (it is printed);
 *   simulated every node stays finite, every object's surface is closed and consistently
 *             oriented with positive volume after the fracture (cs_watertight_check), and the
 *             objects' volumes add up to the one before within 2 % (closing-surface fans;
 *             the exhaustive-cut bounds are in test_fracture_meshes.c);
 *   FAIL      a check above failed, the child died of a signal (crash, sanitizer abort) or
 *             ran longer than the timeout (default 60 s).
 * Last line: "models: F files, S simulated, R refused, X failed"; exit 1 if any failed.
 */
#define _DEFAULT_SOURCE
#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cjson/cJSON.h>

#include "cubesim.h"
#include "mesh.h"
#include "scene.h"
#include "watertight.h"

enum { OUT_SIMULATED = 0, OUT_FAIL = 1, OUT_REFUSED = 3 };

typedef struct paths {
    char **p;
    int n, cap;
} paths;

static int push_path(paths *ps, const char *s)
{
    if (ps->n == ps->cap) {
        int c = ps->cap ? 2 * ps->cap : 256;
        char **g = realloc(ps->p, (size_t)c * sizeof *g);
        if (!g)
            return -1;
        ps->p = g;
        ps->cap = c;
    }
    if (!(ps->p[ps->n] = strdup(s)))
        return -1;
    ps->n++;
    return 0;
}

static int cmp_str(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Every regular file under dir, except image and documentation folders. */
static int walk(const char *dir, paths *ps)
{
    DIR *d = opendir(dir);
    if (!d)
        return -1;
    struct dirent *e;
    int rc = 0;
    while (rc == 0 && (e = readdir(d))) {
        if (e->d_name[0] == '.' || !strcmp(e->d_name, "ReferenceImages") ||
            !strcmp(e->d_name, "SourceFiles"))
            continue;
        char p[4096];
        if (snprintf(p, sizeof p, "%s/%s", dir, e->d_name) >= (int)sizeof p)
            continue;
        struct stat st;
        if (stat(p, &st) != 0)
            continue;
        if (S_ISDIR(st.st_mode))
            rc = walk(p, ps);
        else if (S_ISREG(st.st_mode))
            rc = push_path(ps, p);
    }
    closedir(d);
    return rc;
}

static bool one_line(const char *s)
{
    return s[0] && !strchr(s, '\n');
}

static double total_volume(cs_world_t *w, int *bad, char *why, size_t whylen)
{
    cs_object_id ids[4096];
    int n = cs_world_object_ids(w, ids, 4096);
    double vol = 0;
    for (int i = 0; i < n && i < 4096; i++) {
        const double *v, *rest;
        const int32_t *t;
        int nv, nt, nn;
        if (cs_object_surface(w, ids[i], &v, &nv, &t, &nt) != CS_OK) {
            *bad = 1;
            snprintf(why, whylen, "object %d: no surface", i);
            continue;
        }
        cs_watertight_report rep;
        char err[256];
        if (!cs_watertight_check(v, nv, t, nt, &rep, err, sizeof err) && !*bad) {
            *bad = 1;
            snprintf(why, whylen, "object %d of %d: %s", i, n, err);
        }
        vol += rep.volume;
        const double *x, *vel;
        if (cs_object_nodes(w, ids[i], &rest, &x, &vel, &nn) == CS_OK)
            for (int k = 0; k < 3 * nn; k++)
                if (!isfinite(x[k]) && !*bad) {
                    *bad = 1;
                    snprintf(why, whylen, "object %d: non-finite node position", i);
                }
    }
    return vol;
}

/* The child's work for one file; returns its exit status. */
static int run_file(const char *path, int cubes)
{
    char err[1024] = "";
    cs_mesh m;
    if (cs_mesh_load(path, &m, err, sizeof err) != 0) {
        if (!one_line(err)) {
            printf("FAIL  %s: load refused without a one-line message\n", path);
            return OUT_FAIL;
        }
        printf("refused %s: %s\n", path, err);
        return OUT_REFUSED;
    }
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < m.nv; i++)
        for (int a = 0; a < 3; a++) {
            lo[a] = fmin(lo[a], m.v[3 * i + a]);
            hi[a] = fmax(hi[a], m.v[3 * i + a]);
        }
    double ext = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    if (!(ext > 0) || !isfinite(ext))
        ext = 1;
    const double s = 1.0 / ext;
    const double pos[3] = {-s * 0.5 * (lo[0] + hi[0]), -s * 0.5 * (lo[1] + hi[1]),
                           0.05 - s * lo[2]};

    cs_mesh_free(&m);
    /* the daemon's path: a scene naming the file, parsed, checked and instantiated */
    char json[8192];
    char *quoted = NULL;
    cJSON *str = cJSON_CreateString(path);
    quoted = str ? cJSON_PrintUnformatted(str) : NULL;
    cJSON_Delete(str);
    if (!quoted) {
        printf("FAIL  %s: out of memory\n", path);
        return OUT_FAIL;
    }
    snprintf(json, sizeof json,
             "{\"dt\": 0.0166667, \"materials\": {\"m\": {\"young\": 1e5, \"poisson\": 0.3, "
             "\"density\": 1000}}, \"objects\": [{\"name\": \"model\", \"model\": "
             "\"corotational\", \"material\": \"m\", \"cube_size\": %.17g, \"mesh\": "
             "{\"file\": %s, \"scale\": %.17g, \"position\": [%.17g, %.17g, %.17g]}}]}",
             1.0 / cubes, quoted, s, pos[0], pos[1], pos[2]);
    cJSON_free(quoted);
    cs_scene sc;
    if (cs_scene_parse(json, NULL, &sc, err, sizeof err) != 0) {
        if (!one_line(err)) {
            printf("FAIL  %s: scene refused without a one-line message\n", path);
            return OUT_FAIL;
        }
        printf("refused %s: %s\n", path, err);
        return OUT_REFUSED;
    }
    cs_world_t *w = NULL;
    int rc = cs_scene_instantiate(&sc, &w, err, sizeof err);
    cs_scene_free(&sc);
    if (rc != 0) {
        if (!one_line(err)) {
            printf("FAIL  %s: add refused without a one-line message\n", path);
            return OUT_FAIL;
        }
        printf("refused %s: %s\n", path, err);
        return OUT_REFUSED;
    }
    cs_object_id id = cs_world_find_object(w, "model");
    int bad = 0;
    char why[1200] = "";
    for (int i = 0; i < 5 && !bad; i++)
        if (cs_world_step(w) != CS_OK) {
            bad = 1;
            snprintf(why, sizeof why, "step %d failed", i);
        }
    double v0 = bad ? 0 : total_volume(w, &bad, why, sizeof why);
    const double mid[3] = {0, 0, 0.55}, normal[3] = {1, 0.3, 0.1};
    if (!bad && cs_world_fracture(w, id, mid, normal, 0, err, sizeof err) != CS_OK) {
        bad = 1;
        snprintf(why, sizeof why, "fracture: %s", err);
    }
    double v1 = bad ? 0 : total_volume(w, &bad, why, sizeof why);
    for (int i = 0; i < 2 && !bad; i++)
        if (cs_world_step(w) != CS_OK) {
            bad = 1;
            snprintf(why, sizeof why, "step after fracture failed");
        }
    int n_obj = cs_world_object_ids(w, NULL, 0);
    if (!bad)
        (void)total_volume(w, &bad, why, sizeof why);
    if (!bad && fabs(v1 - v0) > 0.02 * fabs(v0)) {
        bad = 1;
        snprintf(why, sizeof why, "fracture changed the volume by %.3g %%",
                 100 * (v1 - v0) / v0);
    }
    cs_world_destroy(w);
    if (bad) {
        printf("FAIL  %s: %s\n", path, why);
        return OUT_FAIL;
    }
    printf("ok    %s: %d objects after the fracture, volume change %.2g %%\n", path, n_obj,
           v0 != 0 ? 100 * (v1 - v0) / v0 : 0.0);
    return OUT_SIMULATED;
}

int main(int argc, char **argv)
{
    const char *dir = "/usr/share/assimp/models";
    int timeout = 60, cubes = 8;
    bool list = false;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--dir") && i + 1 < argc)
            dir = argv[++i];
        else if (!strcmp(argv[i], "--timeout") && i + 1 < argc)
            timeout = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--cubes") && i + 1 < argc)
            cubes = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--list"))
            list = true;
        else {
            fprintf(stderr, "usage: cs_stress_models [--dir DIR] [--timeout S] [--cubes N] "
                            "[--list]\n");
            return 2;
        }
    }
    if (timeout < 1 || cubes < 1 || cubes > 64) {
        fprintf(stderr, "cs_stress_models: --timeout must be >= 1 and --cubes in 1..64\n");
        return 2;
    }
    paths ps = {0};
    if (walk(dir, &ps) != 0 || ps.n == 0) {
        fprintf(stderr, "cs_stress_models: no files under %s (install assimp-testmodels)\n", dir);
        return 2;
    }
    qsort(ps.p, (size_t)ps.n, sizeof *ps.p, cmp_str);
    int n_ok = 0, n_ref = 0, n_fail = 0;
    for (int i = 0; i < ps.n; i++) {
        if (list) {
            puts(ps.p[i]);
            continue;
        }
        fflush(stdout);
        pid_t pid = fork();
        if (pid < 0) {
            fprintf(stderr, "cs_stress_models: fork: %s\n", strerror(errno));
            return 2;
        }
        if (pid == 0) {
            alarm((unsigned)timeout);
            int st = run_file(ps.p[i], cubes);
            fflush(stdout);
            _exit(st);
        }
        int status = 0;
        while (waitpid(pid, &status, 0) < 0 && errno == EINTR)
            ;
        if (WIFSIGNALED(status)) {
            int sig = WTERMSIG(status);
            printf("FAIL  %s: %s\n", ps.p[i],
                   sig == SIGALRM ? "timed out" : strsignal(sig));
            n_fail++;
        } else if (WEXITSTATUS(status) == OUT_SIMULATED) {
            n_ok++;
        } else if (WEXITSTATUS(status) == OUT_REFUSED) {
            n_ref++;
        } else {
            if (WEXITSTATUS(status) != OUT_FAIL)
                printf("FAIL  %s: exit status %d\n", ps.p[i], WEXITSTATUS(status));
            n_fail++;
        }
    }
    if (!list)
        printf("models: %d files, %d simulated, %d refused, %d failed\n", ps.n, n_ok, n_ref,
               n_fail);
    for (int i = 0; i < ps.n; i++)
        free(ps.p[i]);
    free(ps.p);
    return n_fail ? 1 : 0;
}
