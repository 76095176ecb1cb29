/*
 * test_client_url.c — cs_client_url (client/client_util.c): a receiving client's udpm URL gets
 * a 4 MiB recv_buf_size unless it names one; other providers and explicit sizes are kept.
 */
#include "check.h"

#include <stdlib.h>
#include <string.h>

#include "client/client_util.h"

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
