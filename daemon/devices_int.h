/* devices_int: the device layer's internals shared by devices.c (requests, completions, manager, queries,
 * keep-alive), devices_io.c (a request's driver calls on its port's thread), devices_op.c (manual operations)
 * and devices_ex.c (the sweep executor's operations). Not for other modules. */
#ifndef DEVICES_INT_H
#define DEVICES_INT_H

#include <pthread.h>
#include <stdint.h>

#include "daemon/devices.h"
#include "daemon/port.h"
#include "drivers/axis.h"
#include "drivers/laser.h"
#include "drivers/spectro.h"

enum rop { R_OPEN, R_CLOSE, R_STATUS, R_MOVE, R_HOME, R_STOP, R_ALARM_RESET, R_LASER, R_POWER, R_MEASURE,
	   R_SPECTRO_STOP };

/* The executor's view of a slot: one move (or homing), one read, one measurement at a time; seq ties a
 * completion to the call that wants it. */
enum xwait { XW_IDLE = 0, XW_RUNNING, XW_READY, XW_FAILED };
struct xview {
	unsigned seq;
	enum xwait move;
	unsigned move_seq;
	struct acq_err move_err;
	enum xwait read;
	unsigned read_seq;
	unsigned cmd_seq;              /* the latest command queued (ex_command): a read queued before it is stale */
	unsigned lcmd_seq;             /* a laser switch in flight (0: none): it reads the laser back, so a read asked
					* while it is the latest command takes its read-back (one request, not two) */
	double read_real;              /* real time the read completed */
	int read_rc;
	struct acq_err read_err;
	struct axis_status ast;
	struct laser_status lst;
	bool sticky;                   /* a laser command failed: the next laser read reports it */
	struct acq_err sticky_err;
	enum xwait meas;
	unsigned meas_seq;
	struct acq_err meas_err;
	struct spectro_frame *frame;
};

struct dev_slot {
	bool configured, available;
	bool opening;            /* an open request is queued */
	unsigned gen;            /* bumped when the handle is closed */
	char note[512];          /* why unavailable / last error */
	char vendor[64], model[64], serial[64], firmware[64];
	struct port *port;
	/* on the port's thread only */
	struct axis *ax;
	struct spectro *sp;
	struct laser *ls;
	/* cache, on the loop */
	int64_t device_id;       /* its row in the store's devices table (0: not recorded) */
	bool have_status;
	struct axis_status ast;
	struct laser_status lst;
	struct spectro_info info;
	struct xview x;
};

/* The laser's keep-alive, refreshed by the laser port's own periodic job (port_set_tick) while the loop shows it
 * is alive; shared by the loop and the laser's thread (the mutex). */
struct keepalive {
	pthread_mutex_t mu;
	double loop_alive;             /* real (monotonic) seconds of the loop's last devices_heartbeat() */
	double grace;                  /* refresh only while the loop was alive this recently (real s) */
	unsigned long refreshes, failures, skipped, reported_failures, reported_skipped;
	double period;                 /* the tick's period (real s) */
	double last_sent, max_gap;     /* real s: the last refresh sent; the longest gap since the last report */
	double last_cpu_wait;          /* the thread's total wait for a CPU at the last refresh (cputime.h) */
	double max_gap_cpu_wait;       /* of max_gap, the seconds the thread waited for a CPU */
	struct acq_err last_err;       /* of the last failure */
};

struct devices {
	struct keepalive ka;
	struct loop *lp;
	struct store *st;
	const struct conf *c;
	devices_notify_fn notify;
	void *ctx;
	double (*wallclock)(void);
	struct dev_slot slot[CONF_DEV__COUNT];
	int64_t spectro_id;
	uint64_t retry_timer;
	void (*kick)(void *ctx);
	void *kick_ctx;
	/* manual operation in progress */
	bool op_active;
	devices_done_fn op_done;
	void *op_ctx;
	int op_waiting;          /* move: axes still moving */
	int op_rc;
	struct acq_err op_err;
	char op_kind[16];
	bool op_laser;           /* the laser was switched on for this measurement: off at its end */
	unsigned op_gen;         /* the operation's number: completions of an ended one are dropped */
	double op_power;
};

/* On the laser's thread, after the driver opened the laser and armed its keep-alive: the refresh gaps count
 * from now (a daemon held up before its first refresh is seen too). */
void devices_keepalive_armed(struct devices *dv);

enum owner { OWN_MGR, OWN_EX, OWN_OP, OWN_QUERY, OWN_CALL };

struct query {
	struct devices *dv;
	bool positions;          /* devices_read_positions: the axes' positions, not the whole report */
	int waiting;
	devices_done_fn done;
	void *ctx;
	uint64_t timer;
};

struct req {
	struct port_req pr;
	struct devices *dv;
	int d;
	enum rop op;
	enum owner owner;
	unsigned gen, seq;
	const void *cfg;         /* the device's configuration (open) */
	double target, deadline, pct;
	bool on;
	struct spectro_meas meas;
	/* results */
	int rc;
	struct acq_err err;
	bool have_ast, have_lst, have_info;
	struct axis_status ast;
	struct laser_status lst;
	struct spectro_info info;
	struct axis_identity aid;
	struct laser_identity lid;
	struct spectro_frame *frame;
	struct query *q;
	devices_done_fn done;    /* OWN_CALL: who gets the result */
	void *done_ctx;
};

static inline const char *dname(int d)
{
	return conf_dev_name((enum conf_dev)d);
}

static inline bool is_axis(int d)
{
	return d <= CONF_DEV_DETECTOR_PHI;
}

/* A request of device d (op) for owner, on the slot's current handle. NULL when out of memory. */
struct req *devices_req_new(struct devices *dv, int d, enum rop op, enum owner owner);
/* Queue r on its slot's port. -1 (r freed) when the slot has no port or r is NULL. */
int devices_req_submit(struct req *r);
/* On the port's thread: run r's driver calls (devices_io.c); results in r, the time taken in r->pr (port.h). */
void devices_req_run(struct port_req *pr, struct port *p);
/* On the loop: continue the manual operation r belongs to (devices_op.c); stale completions are dropped. */
void devices_op_done(struct devices *dv, struct req *r);
/* An executor request completed (on the loop): record its result for the next call, kick the executor. */
void devices_ex_done(struct devices *dv, struct req *r);

#endif
