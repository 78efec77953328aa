/*
 * SocketCAN back-end of the C controller node: a CAN_RAW socket bound to one interface, with
 * CAN_RAW_FILTER admitting exactly the node's standard IDs (installed before bind, so no other
 * frame is ever queued), and each frame's kernel receive time (SO_TIMESTAMPNS).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <time.h>
#include <unistd.h>

#include "mrs_bus.h"

static int sc_recv(mrs_bus_t *bus, mrs_frame_t *frame, double timeout_s)
{
    struct can_frame cf;
    struct iovec iov;
    struct msghdr msg;
    char ctrl[CMSG_SPACE(sizeof(struct timespec))];
    struct cmsghdr *c;
    ssize_t n;
    if (timeout_s > 0.0) {
        const int w = mrs_bus_wait(bus->fd, timeout_s);
        if (w <= 0) {
            if (w < 0) {
                snprintf(bus->error, sizeof bus->error, "socketcan: %s", strerror(errno));
            }
            return w;
        }
    }
    iov.iov_base = &cf;
    iov.iov_len = sizeof cf;
    memset(&msg, 0, sizeof msg);
    msg.msg_iov = &iov;
    msg.msg_iovlen = 1;
    msg.msg_control = ctrl;
    msg.msg_controllen = sizeof ctrl;
    n = recvmsg(bus->fd, &msg, MSG_DONTWAIT);
    if (n < 0) {
        if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) {
            return 0;
        }
        snprintf(bus->error, sizeof bus->error, "socketcan: receive failed (%s)", strerror(errno));
        return -1;
    }
    if ((size_t)n < sizeof cf) {
        return 0;
    }
    frame->flags = (uint8_t)(((cf.can_id & CAN_EFF_FLAG) ? MRS_FRAME_EXTENDED : 0u) |
                             ((cf.can_id & CAN_RTR_FLAG) ? MRS_FRAME_REMOTE : 0u) |
                             ((cf.can_id & CAN_ERR_FLAG) ? MRS_FRAME_ERROR : 0u));
    frame->id = cf.can_id & ((cf.can_id & CAN_EFF_FLAG) ? CAN_EFF_MASK : CAN_SFF_MASK);
    frame->len = cf.can_dlc > 8u ? 8u : cf.can_dlc;
    memcpy(frame->data, cf.data, frame->len);
    frame->stamp = 0.0;
    for (c = CMSG_FIRSTHDR(&msg); c != NULL; c = CMSG_NXTHDR(&msg, c)) {
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_TIMESTAMPNS) {
            struct timespec ts;
            memcpy(&ts, CMSG_DATA(c), sizeof ts);
            frame->stamp = (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
        }
    }
    return 1;
}

static int sc_send(mrs_bus_t *bus, uint32_t id, const uint8_t *data, uint8_t len)
{
    struct can_frame cf;
    memset(&cf, 0, sizeof cf);
    cf.can_id = id & CAN_SFF_MASK;
    cf.can_dlc = len;
    memcpy(cf.data, data, len);
    for (;;) {
        if (write(bus->fd, &cf, sizeof cf) == (ssize_t)sizeof cf) {
            return 0;
        }
        if (errno != EINTR && errno != ENOBUFS) {
            snprintf(bus->error, sizeof bus->error, "socketcan: send failed (%s)", strerror(errno));
            return -1;
        }
        if (errno == ENOBUFS) {
            /* the interface queue is full: wait a little, as python-can's send does */
            const struct timespec pause = {0, 100000L};
            nanosleep(&pause, NULL);
        }
    }
}

static void sc_close(mrs_bus_t *bus)
{
    if (bus->fd >= 0) {
        close(bus->fd);
        bus->fd = -1;
    }
}

int mrs_bus_open_socketcan(mrs_bus_t *bus, const char *channel, const uint32_t *ids, size_t n_ids, char *err,
                           size_t err_len)
{
    struct sockaddr_can addr;
    struct can_filter filters[16];
    const int on = 1;
    unsigned ifindex;
    size_t i;
    memset(bus, 0, sizeof *bus);
    bus->fd = -1;
    if (n_ids > 16u) {
        snprintf(err, err_len, "too many receive filters");
        return -1;
    }
    ifindex = if_nametoindex(channel);
    if (ifindex == 0u) {
        snprintf(err, err_len, "cannot open CAN bus socketcan:%s: no such CAN interface", channel);
        return -1;
    }
    bus->fd = socket(PF_CAN, SOCK_RAW, CAN_RAW);
    if (bus->fd < 0) {
        snprintf(err, err_len, "cannot open CAN bus socketcan:%s: %s", channel, strerror(errno));
        return -1;
    }
    for (i = 0u; i < n_ids; ++i) {
        filters[i].can_id = ids[i];
        filters[i].can_mask = CAN_SFF_MASK | CAN_EFF_FLAG; /* standard frames of exactly this ID */
    }
    if (setsockopt(bus->fd, SOL_CAN_RAW, CAN_RAW_FILTER, filters, (socklen_t)(n_ids * sizeof filters[0])) != 0 ||
        setsockopt(bus->fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) != 0) {
        snprintf(err, err_len, "cannot open CAN bus socketcan:%s: %s", channel, strerror(errno));
        close(bus->fd);
        bus->fd = -1;
        return -1;
    }
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = (int)ifindex;
    if (bind(bus->fd, (const struct sockaddr *)&addr, sizeof addr) != 0) {
        snprintf(err, err_len, "cannot open CAN bus socketcan:%s: %s", channel, strerror(errno));
        close(bus->fd);
        bus->fd = -1;
        return -1;
    }
    snprintf(bus->info, sizeof bus->info, "socketcan channel '%s'", channel);
    bus->recv = sc_recv;
    bus->send = sc_send;
    bus->close = sc_close;
    return 0;
}
