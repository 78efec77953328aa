/*
 * The CAN bus of the C controller node: a SocketCAN raw socket (mrs_bus_socketcan.c) or a client
 * of the mrsteer fallback bus (mrs_bus_fallback.c, the protocol of docs/can-runtime.md). Either
 * way the receive filters admit exactly the given standard IDs, and every received frame carries
 * the time it was put on the bus (epoch seconds: the kernel's or the broker's stamp).
 */
#ifndef MRS_BUS_H
#define MRS_BUS_H

#include <stddef.h>
#include <stdint.h>

#define MRS_FRAME_EXTENDED 0x01u
#define MRS_FRAME_REMOTE 0x02u
#define MRS_FRAME_ERROR 0x04u

typedef struct {
    uint32_t id;
    uint8_t flags; /* MRS_FRAME_* */
    uint8_t len;
    uint8_t data[64];
    double stamp; /* epoch s when it was on the bus, 0 if unknown */
} mrs_frame_t;

#define MRS_BUS_EARLY_MAX 64

typedef struct mrs_bus mrs_bus_t;
struct mrs_bus {
    int fd;
    char info[300]; /* what the ready line says the bus is */
    char error[256]; /* why the last call failed */
    /* 1 with a frame, 0 with none within timeout_s (or on a signal), -1 when the bus failed. */
    int (*recv)(mrs_bus_t *bus, mrs_frame_t *frame, double timeout_s);
    int (*send)(mrs_bus_t *bus, uint32_t id, const uint8_t *data, uint8_t len); /* 0 or -1 */
    void (*close)(mrs_bus_t *bus);
    /* fallback bus: frames that arrived before the broker's ack */
    uint8_t early[MRS_BUS_EARLY_MAX][80];
    size_t early_len[MRS_BUS_EARLY_MAX];
    unsigned early_head, early_n;
};

/* 0, or -1 with a one-line reason in err. */
int mrs_bus_open_socketcan(mrs_bus_t *bus, const char *channel, const uint32_t *ids, size_t n_ids, char *err,
                           size_t err_len);
int mrs_bus_open_fallback(mrs_bus_t *bus, const char *channel, const uint32_t *ids, size_t n_ids, char *err,
                          size_t err_len);

/* Waits until fd is readable or timeout_s passed: 1 readable, 0 not (or interrupted), -1 error. */
int mrs_bus_wait(int fd, double timeout_s);

#endif
