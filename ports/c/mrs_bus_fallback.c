/*
 * Client of the mrsteer fallback bus (firmware_py/platform/fallback_*.py), the protocol that
 * docs/can-runtime.md ("Fallback bus: the wire protocol") specifies for any language:
 * a SOCK_SEQPACKET Unix socket at $MRSTEER_BUS_DIR/<channel>.sock (default directory
 * /tmp/mrsteer-bus-<uid>), one packet per message, little-endian:
 *   'O' receive_own(u8)                         client -> broker, first: options; answered by 'A'
 *   'A'                                         broker -> client: the client is on the bus now
 *   'S' {can_id u32, can_mask u32, extended i8}* client -> broker: receive filters (none: all)
 *   'F' flags(u8) stamp(f64) id(u32) dlc(u8) n(u8) data[n]   a frame, either way
 * The broker stamps every frame with the time it put it on the bus (epoch s). This client does
 * not start a broker (the Python client does): the HIL runner and the fault matrix start one.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include "mrs_bus.h"

#define FRAME_HEAD 16u /* 'F', flags, stamp, id, dlc, n */
#define PACKET_MAX (FRAME_HEAD + 64u)
#define F_EXTENDED 1u
#define F_REMOTE 2u
#define F_ERROR 4u
#define HANDSHAKE_S 5.0

static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static void put_u32(uint8_t *p, uint32_t x)
{
    p[0] = (uint8_t)x;
    p[1] = (uint8_t)(x >> 8);
    p[2] = (uint8_t)(x >> 16);
    p[3] = (uint8_t)(x >> 24);
}

static double get_f64(const uint8_t *p)
{
    uint64_t bits = 0u;
    double x;
    int i;
    for (i = 7; i >= 0; --i) {
        bits = (bits << 8) | p[i];
    }
    memcpy(&x, &bits, sizeof x);
    return x;
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

/* A frame packet into frame; 0, or -1 if it is not one. */
static int unpack(const uint8_t *p, size_t n, mrs_frame_t *frame)
{
    uint8_t flags, len;
    if (n < FRAME_HEAD || p[0] != 'F') {
        return -1;
    }
    flags = p[1];
    len = p[15];
    if (len > 64u || FRAME_HEAD + len > n) {
        return -1;
    }
    frame->flags = (uint8_t)(((flags & F_EXTENDED) ? MRS_FRAME_EXTENDED : 0u) |
                             ((flags & F_REMOTE) ? MRS_FRAME_REMOTE : 0u) | ((flags & F_ERROR) ? MRS_FRAME_ERROR : 0u));
    frame->stamp = get_f64(p + 2);
    frame->id = get_u32(p + 10);
    frame->len = len;
    memcpy(frame->data, p + FRAME_HEAD, len);
    return 0;
}

static int fb_recv(mrs_bus_t *bus, mrs_frame_t *frame, double timeout_s)
{
    uint8_t p[PACKET_MAX];
    ssize_t n;
    if (bus->early_n > 0u) {
        const unsigned i = bus->early_head;
        bus->early_head = (bus->early_head + 1u) % MRS_BUS_EARLY_MAX;
        --bus->early_n;
        return unpack(bus->early[i], bus->early_len[i], frame) == 0 ? 1 : 0;
    }
    if (timeout_s > 0.0) {
        const int w = mrs_bus_wait(bus->fd, timeout_s);
        if (w <= 0) {
            if (w < 0) {
                snprintf(bus->error, sizeof bus->error, "fallback bus: %s", strerror(errno));
            }
            return w;
        }
    }
    n = recv(bus->fd, p, sizeof p, MSG_DONTWAIT);
    if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) {
            return 0;
        }
        snprintf(bus->error, sizeof bus->error, "fallback bus: broker connection lost (%s)", strerror(errno));
        return -1;
    }
    if (n == 0) {
        snprintf(bus->error, sizeof bus->error, "fallback bus: the broker closed the connection");
        return -1;
    }
    return unpack(p, (size_t)n, frame) == 0 ? 1 : 0;
}

static int fb_send(mrs_bus_t *bus, uint32_t id, const uint8_t *data, uint8_t len)
{
    uint8_t p[PACKET_MAX];
    memset(p, 0, FRAME_HEAD);
    p[0] = 'F';
    put_u32(p + 10, id);
    p[14] = len;
    p[15] = len;
    memcpy(p + FRAME_HEAD, data, len);
    if (send(bus->fd, p, FRAME_HEAD + len, MSG_NOSIGNAL) < 0) {
        snprintf(bus->error, sizeof bus->error, "fallback bus: broker connection lost (%s)", strerror(errno));
        return -1;
    }
    return 0;
}

/* End our side, let the broker read everything we sent and hang up, then close: closing with
 * frames unread in our queue would reset the connection and lose our last frames. */
static void fb_close(mrs_bus_t *bus)
{
    uint8_t p[PACKET_MAX];
    const double until = now_s() + 1.0;
    if (bus->fd < 0) {
        return;
    }
    shutdown(bus->fd, SHUT_WR);
    while (now_s() < until && mrs_bus_wait(bus->fd, 0.2) > 0 && recv(bus->fd, p, sizeof p, MSG_DONTWAIT) > 0) {
    }
    close(bus->fd);
    bus->fd = -1;
}

static int socket_path(const char *channel, char *path, size_t n, char *err, size_t err_len)
{
    const char *dir = getenv("MRSTEER_BUS_DIR");
    char fallback[64];
    if (channel[0] == '\0' || strchr(channel, '/') != NULL || channel[0] == '.') {
        snprintf(err, err_len, "invalid fallback-bus channel name '%s'", channel);
        return -1;
    }
    if (dir == NULL || dir[0] == '\0') {
        snprintf(fallback, sizeof fallback, "/tmp/mrsteer-bus-%lu", (unsigned long)getuid());
        dir = fallback;
    }
    if ((size_t)snprintf(path, n, "%s/%s.sock", dir, channel) >= n) {
        snprintf(err, err_len, "fallback-bus socket path too long for channel '%s'", channel);
        return -1;
    }
    return 0;
}

/* Options, then the ack (frames before it kept in order), then the filters. */
static int handshake(mrs_bus_t *bus, const uint32_t *ids, size_t n_ids, char *err, size_t err_len)
{
    const uint8_t options[2] = {'O', 0u};
    uint8_t p[PACKET_MAX];
    uint8_t rows[1u + 9u * 16u];
    const double until = now_s() + HANDSHAKE_S;
    size_t i;
    if (n_ids > 16u || send(bus->fd, options, sizeof options, MSG_NOSIGNAL) < 0) {
        snprintf(err, err_len, "fallback bus: cannot talk to the broker (%s)", strerror(errno));
        return -1;
    }
    for (;;) {
        ssize_t n;
        if (mrs_bus_wait(bus->fd, until - now_s()) <= 0) {
            if (now_s() < until) {
                continue;
            }
            snprintf(err, err_len, "fallback bus: no answer from the broker on %s", bus->info);
            return -1;
        }
        n = recv(bus->fd, p, sizeof p, MSG_DONTWAIT);
        if (n <= 0) {
            snprintf(err, err_len, "fallback bus: the broker closed the connection");
            return -1;
        }
        if (n == 1 && p[0] == 'A') {
            break;
        }
        if (bus->early_n < MRS_BUS_EARLY_MAX) {
            const unsigned j = (bus->early_head + bus->early_n) % MRS_BUS_EARLY_MAX;
            memcpy(bus->early[j], p, (size_t)n);
            bus->early_len[j] = (size_t)n;
            ++bus->early_n;
        }
    }
    rows[0] = 'S';
    for (i = 0u; i < n_ids; ++i) {
        put_u32(rows + 1u + 9u * i, ids[i]);
        put_u32(rows + 5u + 9u * i, 0x7FFu);
        rows[9u + 9u * i] = 0u; /* standard IDs only */
    }
    if (send(bus->fd, rows, 1u + 9u * n_ids, MSG_NOSIGNAL) < 0) {
        snprintf(err, err_len, "fallback bus: cannot set the filters (%s)", strerror(errno));
        return -1;
    }
    return 0;
}

int mrs_bus_open_fallback(mrs_bus_t *bus, const char *channel, const uint32_t *ids, size_t n_ids, char *err,
                          size_t err_len)
{
    struct sockaddr_un addr;
    char path[sizeof addr.sun_path];
    memset(bus, 0, sizeof *bus);
    bus->fd = -1;
    if (socket_path(channel, path, sizeof path, err, err_len) != 0) {
        return -1;
    }
    snprintf(bus->info, sizeof bus->info, "mrsteer fallback bus %s (%s)", channel, path);
    bus->fd = socket(AF_UNIX, SOCK_SEQPACKET, 0);
    if (bus->fd < 0) {
        snprintf(err, err_len, "cannot open CAN bus mrsteer:%s: %s", channel, strerror(errno));
        return -1;
    }
    memset(&addr, 0, sizeof addr);
    addr.sun_family = AF_UNIX;
    memcpy(addr.sun_path, path, strlen(path) + 1u);
    if (connect(bus->fd, (const struct sockaddr *)&addr, sizeof addr) != 0) {
        snprintf(err, err_len, "cannot open CAN bus mrsteer:%s: no fallback-bus broker on %s (start one with "
                 "`mrsteer bus --channel %s`)", channel, path, channel);
        close(bus->fd);
        bus->fd = -1;
        return -1;
    }
    if (handshake(bus, ids, n_ids, err, err_len) != 0) {
        close(bus->fd);
        bus->fd = -1;
        return -1;
    }
    bus->recv = fb_recv;
    bus->send = fb_send;
    bus->close = fb_close;
    return 0;
}
