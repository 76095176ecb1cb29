/*
 * bus.h — the daemon's LCM adapter: inputs in (forces, commands), state out (snapshots,
 * deltas, status, acks). DESIGN.md "Bus"; the engine never sees LCM.
 *
 * Owns: the lcm_t, its subscriptions (force, command, paint, pressure, curve), the queue of decoded inputs, the outbox of encoded
 * snapshot/delta messages waiting for their paced send, and per object a float32 copy of the
 * surface as last sent (what every in-sync client holds).
 *
 * Invariants
 * - Handlers (run inside cs_bus_drain) only decode, validate what needs no world, and queue;
 *   they never touch the world. The daemon applies queued inputs between steps.
 * - Snapshot chunks, topology changes and deltas leave in the order they were made, through
 *   one FIFO outbox,
 *   paced by a byte bucket (bursts up to CS_BUS_BURST) whose rate is set whenever messages
 *   are queued to what drains the whole outbox in CS_BUS_DRAIN_S — within [CS_BUS_RATE,
 *   CS_BUS_RATE_MAX] — so a frame's messages are spread evenly over less than a 60 Hz frame
 *   period instead of leaving back to back (a receiver's socket buffer sees the lowest rate
 *   that keeps up), and a delta is never sent ahead of the snapshot it follows. Nothing in here sleeps. A delta is therefore never ahead of
 *   the topology change it was made for.
 * - The last-sent copy of each object follows every topology change it publishes (the same
 *   common/topo.c steps a client runs), so deltas go on without a snapshot; a change the copy
 *   cannot follow is not sent and a snapshot is queued instead.
 * - Every encoded message is below 64 KiB.
 * - A client's copy of a vertex differs from the daemon's double by at most
 *   max(publish_epsilon, sqrt(3)·2^-24·max|x_i|) (Euclidean): a vertex is resent as soon as it
 *   is more than publish_epsilon from the float last sent.
 */
#ifndef CS_BUS_H
#define CS_BUS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "cubesim.h"
#include "dlog.h"

#define CS_CH_SNAPSHOT "CUBESIM_SNAPSHOT"
#define CS_CH_DELTA "CUBESIM_DELTA"
#define CS_CH_POSE "CUBESIM_POSE"
#define CS_CH_TOPOLOGY "CUBESIM_TOPOLOGY"
#define CS_CH_STATUS "CUBESIM_STATUS"
#define CS_CH_ACK "CUBESIM_ACK"
#define CS_CH_FORCE "CUBESIM_FORCE"
#define CS_CH_COMMAND "CUBESIM_COMMAND"
#define CS_CH_PAINT "CUBESIM_PAINT"
#define CS_CH_PRESSURE "CUBESIM_PRESSURE"
#define CS_CH_CURVE "CUBESIM_CURVE"

#define CS_BUS_CHUNK_BYTES 60000       /* payload budget of one snapshot/delta message */
#define CS_BUS_RATE 48.0e6             /* outbox pacing: the slowest rate [bytes/s] */
#define CS_BUS_RATE_MAX 256.0e6        /* ... and the fastest [bytes/s] */
#define CS_BUS_DRAIN_S 0.012           /* what is queued leaves within this [s] if the rates allow */
#define CS_BUS_BURST (128.0 * 1024.0)  /* bytes the outbox may send back to back */
#define CS_BUS_OUTBOX_MAX (64 << 20)   /* beyond this the outbox is dropped, a snapshot queued */
#define CS_BUS_INPUT_MAX 4096          /* queued inputs; more are refused with an error ack */
#define CS_BUS_QUEUE_CAPACITY 8192     /* LCM subscription queue: twice CS_BUS_INPUT_MAX, so a burst
                                        * the input queue refuses still gets its acks (LCM drops
                                        * silently past it; LCM default 30) */

typedef enum cs_input_kind {
    CS_INPUT_FORCE = 0,
    CS_INPUT_COMMAND = 1,
    CS_INPUT_PAINT = 2,    /* paint_t: point (centre), radius, factors */
    CS_INPUT_PRESSURE = 3, /* pressure_t: pressure, duration */
    CS_INPUT_CURVE = 4     /* curve_t: points, stiffness, duration */
} cs_input_kind;

typedef enum cs_command {
    CS_CMD_PAUSE,
    CS_CMD_RESUME,
    CS_CMD_STEP,
    CS_CMD_RESET,
    CS_CMD_SNAPSHOT,
    CS_CMD_LOAD,
    CS_CMD_FRACTURE,
    CS_CMD_UNKNOWN
} cs_command;

/* One decoded input. Owns object_name, argument and points (freed by cs_input_clear). */
typedef struct cs_input {
    cs_input_kind kind;
    int64_t client_id, command_id;
    char request[32];   /* "force" or the command's name (cut to fit) for the ack */
    char error[256];    /* non-empty: refused on decode; the daemon only acks it */
    /* CS_INPUT_FORCE */
    int32_t object_id;  /* > 0: by id, else by object_name */
    char *object_name;
    int8_t force_kind;  /* cubesim force_t POINT / DRAG */
    double point[3], force[3], target[3], stiffness, duration;
    /* CS_INPUT_COMMAND */
    cs_command command;
    int32_t count;
    char *argument;
    /* CS_CMD_FRACTURE, parsed from argument "OBJECT X Y Z NX NY NZ [RADIUS]" on decode: the
     * object is object_id (> 0, from "#ID") or object_name, the point is `point` [m]. */
    double normal[3];   /* splitting plane normal, finite and non-zero */
    double radius;      /* [m], >= 0; 0: the object's fracture_radius (PAINT: > 0) */
    /* CS_INPUT_PAINT (point is the centre), CS_INPUT_PRESSURE, CS_INPUT_CURVE (object as for
     * forces; stiffness and duration as for a drag) */
    cs_field_factors factors;
    double pressure;
    double *points;     /* 3 per point */
    int n_points;
} cs_input;

void cs_input_clear(cs_input *in);

typedef struct cs_bus cs_bus_t;

/* Open LCM at url (NULL: LCM's default) and subscribe. log is borrowed for the bus' lifetime. */
int cs_bus_create(const char *url, cs_dlog *log, cs_bus_t **out, char *err, size_t errlen);
void cs_bus_destroy(cs_bus_t *b); /* NULL is fine; unsent messages are dropped */

int cs_bus_fileno(cs_bus_t *b);

/* Largest |force| accepted on decode [N] (the world's max_force). */
void cs_bus_set_max_force(cs_bus_t *b, double max_force);

/*
 * Handle every message already received (at most `max` of them, so a flood cannot starve the
 * physics). Returns how many were handled, or -1 if LCM failed.
 */
int cs_bus_drain(cs_bus_t *b, int max);

/* Pop the oldest queued input into *in (caller clears it). Returns 1, or 0 when empty. */
int cs_bus_next_input(cs_bus_t *b, cs_input *in);

/* Header context of every following message. */
void cs_bus_set_context(cs_bus_t *b, int32_t epoch, int64_t frame, double sim_time);
int64_t cs_bus_session_id(const cs_bus_t *b);

/* Acknowledge an input (sent at once). message may be NULL or "" when ok. */
int cs_bus_ack(cs_bus_t *b, const cs_input *in, bool ok, const char *message);

/*
 * Forget every object's last-sent copy (after reset or load); the next cs_bus_queue_snapshot
 * sets them again.
 */
void cs_bus_forget_objects(cs_bus_t *b);

/*
 * Encode a snapshot of every object's surface into chunks, queue them in the outbox, and make
 * it the last-sent state. If `coalesce` and a snapshot is queued none of whose chunks has left
 * yet, nothing is queued (that one will do). Returns the snapshot id, or -1 (out of memory).
 */
int32_t cs_bus_queue_snapshot(cs_bus_t *b, const cs_world_t *w, bool coalesce);
int32_t cs_bus_last_snapshot_id(const cs_bus_t *b);

/*
 * Queue the deltas of one publish frame: per awake object, the surface vertices farther than
 * eps [m] from what was last sent; for a rigid object, its pose first and then only the
 * vertices that moved in its body frame by more than eps (beyond the float32 rounding its
 * pose arithmetic carries: README "CUBESIM_POSE"), followed by a new reference pose; eps < 0:
 * exact (a paused daemon's flush): every vertex whose float32 differs from the one last sent,
 * settled objects included, and every vertex of a rigid object. Returns the number of delta
 * messages queued, or -1. If an
 * object's topology or vertex count no longer matches what was sent (or it is new), a
 * snapshot is queued instead.
 */
int cs_bus_queue_deltas(cs_bus_t *b, const cs_world_t *w, double eps);

/*
 * Queue the topology changes of one step or forced fracture (cs_world_topology_changes), in
 * order, each as one or more CUBESIM_TOPOLOGY chunks, and apply each to the last-sent copy
 * (a new piece gets one). A change the copy cannot follow (unknown object, another version,
 * cs_topo_check fails) is logged and not sent; a snapshot is queued after the others
 * instead. Returns the number of messages queued, or -1 (out of memory: a snapshot was
 * still attempted).
 */
int cs_bus_queue_topology(cs_bus_t *b, const cs_world_t *w, const cs_topo_change *changes,
                          int n);

/* Telemetry of one status message beyond what the world says. */
typedef struct cs_bus_status_extra {
    bool paused;
    double real_time_factor;
    double step_ms, step_ms_avg;
} cs_bus_status_extra;

/* Publish a status message now. */
int cs_bus_publish_status(cs_bus_t *b, const cs_world_t *w, const cs_bus_status_extra *x);

/*
 * Send what the pacing allows from the outbox now. Returns the number of messages still
 * queued; *next_send (monotonic seconds) is when the next one may go (if any).
 */
int cs_bus_pump(cs_bus_t *b, double now, double *next_send);

#endif
