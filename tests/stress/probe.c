/*
 * tests/stress/probe.c — cs_stress_probe: the stress suite's own LCM client (tests/stress.sh).
 * It owns the two things the shell and the existing tools cannot do: publish valid forces as
 * fast as a bounded rate allows while counting every acknowledgement, and watch the energies
 * in the daemon's status messages. Not part of any paper section: a test harness.
 *
 *   cs_stress_probe [--lcm URL] flood --name OBJ --point x,y,z --force x,y,z
 *                   [--count N] [--rate R] [--seconds S] [--linger L]
 *       publish up to N forces (command ids 1..N, one client id) at most R a second
 *       (R = 0: no pacing) for at most S wall seconds, then wait L seconds for acks; prints
 *       "flood sent=N acks=A ok=O full=F busy=B other=X dup=D stray=Y seconds=T" where
 *       full counts "input queue full" refusals (the daemon's input queue), busy "already
 *       has N active inputs" refusals (the engine's per-object cap), other any other
 *       refusal, dup acks seen twice for one id, stray acks with an id never sent.
 *   cs_stress_probe [--lcm URL] energy [--frame F] [--seconds S]
 *       read statuses until one reports frame >= F (or S seconds pass); prints
 *       "energy statuses=N nonfinite=K frame=F first=E0 last=E1 max=EMAX ke_max=K1 ke_last=K2"
 *       with E the total (kinetic + elastic + gravity, summed over objects) in joules and
 *       nonfinite the number of statuses holding a NaN or infinite energy.
 * Exit status: 0 done, 2 usage, 3 nothing arrived (energy) / no ack at all (flood), 1 LCM.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <lcm/lcm.h>

#include "../it/tools/tool_util.h"
#include "cubesim_ack_t.h"
#include "cubesim_force_t.h"
#include "cubesim_status_t.h"

typedef struct probe {
    int64_t client_id;
    int64_t sent;
    unsigned char *seen; /* per command id 1..count: acks received */
    int64_t count;
    int64_t acks, ok, full, busy, other, dup, stray;
    char first_other[160];
    /* energy */
    int64_t want_frame, statuses, nonfinite, frame;
    int have_e;
    double e_first, e_last, e_max, ke_max, ke_last;
    int done;
} probe;

static void on_ack(const lcm_recv_buf_t *rb, const char *ch, const cubesim_ack_t *a, void *u)
{
    probe *p = u;
    if (a->client_id != p->client_id)
        return;
    p->acks++;
    if (a->command_id < 1 || a->command_id > p->sent) {
        p->stray++;
        return;
    }
    if (p->seen[a->command_id - 1]++)
        p->dup++;
    if (a->ok)
        p->ok++;
    else if (a->message && strstr(a->message, "input queue full"))
        p->full++;
    else if (a->message && strstr(a->message, "active inputs"))
        p->busy++;
    else {
        if (!p->other++)
            snprintf(p->first_other, sizeof p->first_other, "%s", a->message ? a->message : "");
    }
}

static void on_status(const lcm_recv_buf_t *rb, const char *ch, const cubesim_status_t *s,
                      void *u)
{
    probe *p = u;
    double e = 0, ke = 0;
    int bad = 0;
    for (int i = 0; i < s->n_objects; i++) {
        double k = s->kinetic_energy[i], el = s->elastic_energy[i], g = s->gravity_energy[i];
        if (!isfinite(k) || !isfinite(el) || !isfinite(g))
            bad = 1;
        e += k + el + g;
        ke += k;
    }
    p->nonfinite += bad;
    if (!bad) {
        if (!p->have_e || e > p->e_max)
            p->e_max = e;
        if (!p->have_e)
            p->e_first = e;
        p->have_e = 1;
        if (ke > p->ke_max)
            p->ke_max = ke;
        p->e_last = e;
        p->ke_last = ke;
    }
    p->statuses++;
    p->frame = s->header.frame;
    if (p->want_frame > 0 && s->header.frame >= p->want_frame)
        p->done = 1;
}

static int usage(void)
{
    fprintf(stderr, "usage: cs_stress_probe [--lcm URL] flood --name OBJ --point x,y,z "
                    "--force x,y,z [--count N] [--rate R] [--seconds S] [--linger L]\n"
                    "       cs_stress_probe [--lcm URL] energy [--frame F] [--seconds S]\n");
    return 2;
}

/* Handle what arrives for up to `seconds`; stop early once p->done. */
static int pump(lcm_t *lcm, probe *p, double seconds)
{
    double end = now_s() + seconds;
    while (!p->done) {
        double left = end - now_s();
        if (left <= 0)
            return 0;
        if (lcm_handle_timeout(lcm, (int)(left * 1000) + 1) < 0)
            return 1;
    }
    return 0;
}

static int run_flood(lcm_t *lcm, probe *p, int argc, char **argv, int i)
{
    cubesim_force_t f;
    memset(&f, 0, sizeof f);
    f.object_name = "";
    double rate = 5000, seconds = 10, linger = 3;
    p->count = 50000;
    for (; i + 1 < argc; i += 2) {
        const char *k = argv[i], *v = argv[i + 1];
        int bad = 0;
        if (strcmp(k, "--name") == 0) f.object_name = (char *)v;
        else if (strcmp(k, "--point") == 0) bad = parse3(v, f.point);
        else if (strcmp(k, "--force") == 0) bad = parse3(v, f.force);
        else if (strcmp(k, "--count") == 0) bad = (p->count = atoll(v)) < 1;
        else if (strcmp(k, "--rate") == 0) bad = (rate = atof(v)) < 0;
        else if (strcmp(k, "--seconds") == 0) bad = (seconds = atof(v)) <= 0;
        else if (strcmp(k, "--linger") == 0) bad = (linger = atof(v)) < 0;
        else bad = 1;
        if (bad) {
            fprintf(stderr, "cs_stress_probe: bad option %s %s\n", k, v);
            return 2;
        }
    }
    if (i < argc || !f.object_name[0])
        return usage();
    p->seen = calloc((size_t)p->count, 1);
    if (!p->seen) {
        fprintf(stderr, "cs_stress_probe: out of memory\n");
        return 1;
    }
    cubesim_ack_t_subscription_t *sub = cubesim_ack_t_subscribe(lcm, "CUBESIM_ACK", on_ack, p);
    cubesim_ack_t_subscription_set_queue_capacity(sub, 200000);
    f.client_id = p->client_id;
    double t0 = now_s(), end = t0 + seconds;
    int rc = 0;
    while (p->sent < p->count && now_s() < end) {
        /* Send what the rate allows by now, then read acks until the next one is due. */
        int64_t due = rate > 0 ? (int64_t)((now_s() - t0) * rate) + 1 : p->sent + 64;
        if (due > p->count)
            due = p->count;
        while (p->sent < due) {
            f.command_id = p->sent + 1;
            if (cubesim_force_t_publish(lcm, "CUBESIM_FORCE", &f) < 0) {
                rc = 1;
                break;
            }
            p->sent++;
        }
        if (rc)
            break;
        while (lcm_handle_timeout(lcm, 0) > 0) {
        }
        if (rate > 0 && p->sent < p->count) {
            double next = t0 + (double)(p->sent + 1) / rate - now_s();
            if (next > 0.0005 && lcm_handle_timeout(lcm, (int)(next * 1000)) < 0)
                rc = 1;
        }
    }
    double elapsed = now_s() - t0;
    if (!rc)
        rc = pump(lcm, p, linger);
    printf("flood sent=%lld acks=%lld ok=%lld full=%lld busy=%lld other=%lld dup=%lld "
           "stray=%lld seconds=%.2f\n",
           (long long)p->sent, (long long)p->acks, (long long)p->ok, (long long)p->full,
           (long long)p->busy, (long long)p->other, (long long)p->dup, (long long)p->stray, elapsed);
    if (p->other)
        printf("first other refusal: %s\n", p->first_other);
    cubesim_ack_t_unsubscribe(lcm, sub);
    free(p->seen);
    return rc ? rc : p->acks ? 0 : 3;
}

static int run_energy(lcm_t *lcm, probe *p, int argc, char **argv, int i)
{
    double seconds = 60;
    for (; i + 1 < argc; i += 2) {
        if (strcmp(argv[i], "--frame") == 0)
            p->want_frame = atoll(argv[i + 1]);
        else if (strcmp(argv[i], "--seconds") == 0)
            seconds = atof(argv[i + 1]);
        else
            return usage();
    }
    if (i < argc)
        return usage();
    cubesim_status_t_subscription_t *sub =
        cubesim_status_t_subscribe(lcm, "CUBESIM_STATUS", on_status, p);
    cubesim_status_t_subscription_set_queue_capacity(sub, 10000);
    int rc = pump(lcm, p, seconds);
    printf("energy statuses=%lld nonfinite=%lld frame=%lld first=%.9g last=%.9g max=%.9g "
           "ke_max=%.9g ke_last=%.9g\n",
           (long long)p->statuses, (long long)p->nonfinite, (long long)p->frame, p->e_first,
           p->e_last, p->e_max, p->ke_max, p->ke_last);
    cubesim_status_t_unsubscribe(lcm, sub);
    return rc ? rc : p->statuses ? 0 : 3;
}

int main(int argc, char **argv)
{
    const char *url = NULL;
    int i = 1;
    if (i + 1 < argc && strcmp(argv[i], "--lcm") == 0) {
        url = argv[i + 1];
        i += 2;
    }
    if (i >= argc)
        return usage();
    const char *verb = argv[i++];
    if (strcmp(verb, "flood") != 0 && strcmp(verb, "energy") != 0)
        return usage();
    lcm_t *lcm = lcm_create(url);
    if (!lcm) {
        fprintf(stderr, "cs_stress_probe: cannot open LCM %s\n", url ? url : "(default)");
        return 1;
    }
    probe p;
    memset(&p, 0, sizeof p);
    p.client_id = ((int64_t)getpid() << 20) ^ (int64_t)time(NULL);
    int rc = verb[0] == 'f' ? run_flood(lcm, &p, argc, argv, i)
                            : run_energy(lcm, &p, argc, argv, i);
    fflush(stdout);
    lcm_destroy(lcm);
    return rc;
}
