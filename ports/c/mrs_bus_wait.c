/* Waiting for a bus socket with sub-millisecond resolution (ppoll), shared by both back-ends. */
#define _GNU_SOURCE
#include <errno.h>
#include <poll.h>
#include <time.h>

#include "mrs_bus.h"

int mrs_bus_wait(int fd, double timeout_s)
{
    struct pollfd p;
    struct timespec ts;
    int r;
    if (timeout_s < 0.0) {
        timeout_s = 0.0;
    }
    ts.tv_sec = (time_t)timeout_s;
    ts.tv_nsec = (long)((timeout_s - (double)ts.tv_sec) * 1e9);
    p.fd = fd;
    p.events = POLLIN;
    p.revents = 0;
    r = ppoll(&p, 1, &ts, NULL);
    if (r < 0) {
        return errno == EINTR ? 0 : -1;
    }
    return r > 0 ? 1 : 0;
}
