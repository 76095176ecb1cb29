/*
 * test_client_url.c — cs_client_url (client/client_util.c): a receiving client's udpm URL gets
 * a 4 MiB recv_buf_size unless it names one; other providers and explicit sizes are kept.
 * And the receive accounting the clients share: cs_msg_header reads every type that carries
 * header_t (pose_t included), cs_seq_table counts a daemon restart once, not once per channel.
 */
#include "check.h"

#include <stdlib.h>
#include <string.h>

#include "client/client_util.h"
#include "common/number.h"
#include "cubesim_delta_t.h"
#include "cubesim_pose_t.h"

static int url_is(const char *in, const char *want)
{
    char *u = cs_client_url(in);
    int ok = u && strcmp(u, want) == 0;
    free(u);
    return ok;
}

TEST(client_url_adds_receive_buffer)
{
    ENSURE(url_is("udpm://239.255.76.67:7667?ttl=0",
                  "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"));
    ENSURE(url_is("udpm://239.255.76.67:7667", "udpm://239.255.76.67:7667?recv_buf_size=4194304"));
    /* an explicit size wins, whatever it is */
    ENSURE(url_is("udpm://239.255.76.67:7667?ttl=0&recv_buf_size=65536",
                  "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=65536"));
    /* other providers have no such option */
    ENSURE(url_is("file:///tmp/x.lcm?mode=w", "file:///tmp/x.lcm?mode=w"));
    ENSURE(url_is("memq://", "memq://"));
}

TEST(client_url_default_and_environment)
{
    char *saved = getenv("LCM_DEFAULT_URL") ? strdup(getenv("LCM_DEFAULT_URL")) : NULL;
    unsetenv("LCM_DEFAULT_URL");
    ENSURE(url_is(NULL, "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"));
    ENSURE(url_is("", "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304"));
    setenv("LCM_DEFAULT_URL", "udpm://239.255.1.2:7000?ttl=1", 1);
    ENSURE(url_is(NULL, "udpm://239.255.1.2:7000?ttl=1&recv_buf_size=4194304"));
    /* an explicit URL wins over the environment */
    ENSURE(url_is("memq://", "memq://"));
    if (saved) {
        setenv("LCM_DEFAULT_URL", saved, 1);
        free(saved);
    } else {
        unsetenv("LCM_DEFAULT_URL");
    }
}

/* A pose carries header_t: cubesim-log tracks its sequence numbers (before, CUBESIM_POSE was
 * "(no sequence numbers)" and a lost pose never asked for a snapshot). */
TEST(client_msg_header_reads_poses)
{
    cubesim_pose_t p;
    memset(&p, 0, sizeof p);
    p.header.session_id = 77;
    p.header.seq = 5;
    p.header.frame = 9;
    p.orientation[0] = 1;
    const int n = cubesim_pose_t_encoded_size(&p);
    void *buf = malloc((size_t)n);
    ENSURE(buf && cubesim_pose_t_encode(buf, 0, n, &p) == n);
    cubesim_header_t h;
    memset(&h, 0, sizeof h);
    ENSURE(cs_msg_header(buf, n, &h) == 1);
    ENSURE(h.session_id == 77 && h.seq == 5 && h.frame == 9);
    /* truncated, or another type's fingerprint: not ours */
    ENSURE(cs_msg_header(buf, 7, &h) == 0);
    ((unsigned char *)buf)[0] ^= 0xff;
    ENSURE(cs_msg_header(buf, n, &h) == 0);
    free(buf);
}

/* One daemon restart seen on three channels is one restart; a gap is lost messages. */
TEST(client_seq_table_counts_a_restart_once)
{
    cs_seq_table tab;
    memset(&tab, 0, sizeof tab);
    const char *ch[3] = {"CUBESIM_DELTA", "CUBESIM_STATUS", "CUBESIM_POSE"};
    cubesim_header_t h;
    memset(&h, 0, sizeof h);
    for (int s = 1; s <= 2; s++)
        for (int k = 0; k < 3; k++) {
            h.session_id = 1000 + s;
            for (h.seq = 1; h.seq <= 4; h.seq++)
                if (!(s == 1 && k == 0 && h.seq == 3)) /* one delta lost */
                    ENSURE(cs_seq_table_note(&tab, ch[k], &h) == 0);
        }
    ENSURE(cs_seq_table_note(&tab, "OTHER", NULL) == 0);
    ENSURE(cs_seq_table_restarts(&tab) == 1);
    int64_t lost = 0;
    for (int i = 0; i < tab.n; i++)
        lost += tab.t[i].lost;
    ENSURE(lost == 1);
    ENSURE(tab.n == 4);
    cs_seq_table_free(&tab);
}

/* The numbers people and clients type (flags, the fracture argument): decimal only. strtod
 * alone read "0x10" as 16, "infinity" and " 1" as numbers, and refused 1e-400 (ERANGE). */
TEST(parse_decimal_takes_decimal_numbers_only)
{
    const struct {
        const char *s;
        int rc;
        double v;
    } c[] = {
        {"0", 0, 0},        {"-0.25", 0, -0.25},  {"+3", 0, 3},        {".5", 0, 0.5},
        {"5.", 0, 5},       {"1e-3", 0, 1e-3},    {"2E+2", 0, 200},    {"1e-400", 0, 0},
        {"1e400", -2, 0},   {"-1e309", -2, 0},    {"0x10", -1, 0},     {"inf", -1, 0},
        {"nan", -1, 0},     {"infinity", -1, 0},  {" 1", -1, 0},       {"1 ", -1, 0},
        {"", -1, 0},        {"-", -1, 0},         {".", -1, 0},        {"1e", -1, 0},
        {"1e+", -1, 0},     {"e5", -1, 0},        {"1.2.3", -1, 0},    {"1,5", -1, 0},
    };
    for (size_t k = 0; k < sizeof c / sizeof c[0]; k++) {
        double v = 42;
        const int rc = cs_parse_decimal(c[k].s, &v);
        if (rc != c[k].rc || (rc == 0 && v != c[k].v) || (rc != 0 && v != 42))
            printf("    '%s': rc %d (want %d), value %g\n", c[k].s, rc, c[k].rc, v);
        ENSURE(rc == c[k].rc);
        ENSURE(rc == 0 ? v == c[k].v : v == 42);
        double w = 42;
        ENSURE((cs_parse_double(c[k].s, &w) == 0) == (c[k].rc == 0));
    }
}
