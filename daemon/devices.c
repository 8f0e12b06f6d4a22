/* devices: the bench's devices, each behind its own I/O thread (port.h): requests and their completions,
 * opening, reconnecting, status reports from a cache, the laser's keep-alive (devices.h). A request's driver
 * calls are in devices_io.c, the manual operations in devices_op.c, the executor's operations in devices_ex.c.
 *
 * The loop never calls a driver. Every device call is a request run on the device's port thread; its
 * completion comes back to the loop, updates the slot's cache and continues whoever asked (the device
 * manager, a manual operation, a `devices` query or the executor, which is then kicked). A handle lives on its
 * thread only; the loop knows the slot is available and what it last read. A slot's generation changes when
 * its handle is closed, so completions of requests made for the old handle are recognised and dropped. */
#include "daemon/devices_int.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/cputime.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/store.h"
#include "drivers/axis.h"
#include "drivers/laser.h"
#include "drivers/spectro.h"

static double mono_now(void)
{
	return loop_monotonic(NULL);
}

/* The laser port's periodic job: refresh the keep-alive while the loop is alive (devices_heartbeat). It runs
 * between requests, before any queued one, so a queue of status reads cannot make the laser switch off. */
static void keepalive_tick(void *arg, struct port *p)
{
	(void)p;
	struct devices *dv = arg;
	struct laser *ls = dv->slot[CONF_DEV_LASER].ls; /* the thread's own handle */
	if (!ls)
		return;
	struct keepalive *ka = &dv->ka;
	pthread_mutex_lock(&ka->mu);
	bool alive = mono_now() - ka->loop_alive <= ka->grace;
	if (!alive)
		ka->skipped++;
	pthread_mutex_unlock(&ka->mu);
	if (!alive)
		return;
	struct acq_err e = { 0 };
	struct cputime ct;
	cputime_thread(&ct);
	double t0 = mono_now();
	int rc = laser_keepalive(ls, &e);
	pthread_mutex_lock(&ka->mu);
	if (ka->last_sent > 0 && t0 - ka->last_sent > ka->max_gap) {
		ka->max_gap = t0 - ka->last_sent;
		ka->max_gap_cpu_wait = ct.waiting - ka->last_cpu_wait; /* the thread's wait for a CPU in the gap */
	}
	ka->last_sent = t0;
	ka->last_cpu_wait = ct.waiting;
	if (rc) {
		ka->failures++;
		ka->last_err = e;
	} else {
		ka->refreshes++;
	}
	pthread_mutex_unlock(&ka->mu);
}

void devices_keepalive_armed(struct devices *dv)
{
	struct cputime ct;
	cputime_thread(&ct);
	pthread_mutex_lock(&dv->ka.mu);
	dv->ka.last_sent = mono_now(); /* the open's KEEPALIVE <ms>: the first refresh's gap counts from it */
	dv->ka.last_cpu_wait = ct.waiting;
	pthread_mutex_unlock(&dv->ka.mu);
}

/* ---- on the loop: requests and completions -------------------------------------------------------------- */

static void req_done(struct port_req *pr);

struct req *devices_req_new(struct devices *dv, int d, enum rop op, enum owner owner)
{
	struct req *r = calloc(1, sizeof *r);
	if (!r)
		return NULL;
	r->pr.run = devices_req_run;
	r->pr.done = req_done;
	r->dv = dv;
	r->d = d;
	r->op = op;
	r->owner = owner;
	r->pr.yields = owner == OWN_QUERY; /* a client's status read: the sweep's requests go first (port.h) */
	r->gen = dv->slot[d].gen;
	if (owner == OWN_OP)
		r->seq = dv->op_gen;
	r->pct = NAN;
	r->deadline = INFINITY;
	return r;
}

/* Submit r to its slot's port. -1 (and r freed) when the slot has no port or memory ran out before. */
int devices_req_submit(struct req *r)
{
	if (!r)
		return -1;
	struct dev_slot *s = &r->dv->slot[r->d];
	if (!s->port) {
		free(r->frame);
		free(r);
		return -1;
	}
	port_submit(s->port, &r->pr);
	return 0;
}

static void set_identity(struct dev_slot *s, const char *vendor, const char *model, const char *serial,
			 const char *fw)
{
	snprintf(s->vendor, sizeof s->vendor, "%s", vendor);
	snprintf(s->model, sizeof s->model, "%s", model);
	snprintf(s->serial, sizeof s->serial, "%s", serial);
	snprintf(s->firmware, sizeof s->firmware, "%s", fw);
}

/* A device's note without its own name in front (drivers name the device in their errors; the note is shown and
 * logged after the name already: "laser.theta: cannot connect", not "laser.theta: laser.theta: ..."). */
static const char *unnamed(int d, const char *msg)
{
	size_t n = strlen(dname(d));
	return !strncmp(msg, dname(d), n) && msg[n] == ':' && msg[n + 1] == ' ' ? msg + n + 2 : msg;
}

static void opened(struct devices *dv, struct req *r)
{
	struct dev_slot *s = &dv->slot[r->d];
	s->opening = false;
	if (r->gen != s->gen)
		return; /* closed since (reload): the close queued after it ends that handle */
	if (r->rc) {
		const char *msg = unnamed(r->d, r->err.msg);
		bool changed = strcmp(s->note, msg) != 0;
		snprintf(s->note, sizeof s->note, "%s", msg);
		if (changed && dv->notify)
			dv->notify(dv->ctx, (enum conf_dev)r->d, false, s->note);
		return;
	}
	double now = dv->wallclock();
	struct acq_err err = { 0 };
	if (is_axis(r->d)) {
		set_identity(s, r->aid.vendor, r->aid.model, r->aid.serial, r->aid.firmware);
	} else if (r->d == CONF_DEV_SPECTRO) {
		s->info = r->info;
		set_identity(s, "Avantes", r->info.model, r->info.serial, r->info.firmware);
		if (store_spectrometer_put(dv->st, &r->info, now, &dv->spectro_id, &err))
			snprintf(s->note, sizeof s->note, "recording calibration: %s", err.msg);
	} else {
		set_identity(s, "", r->lid.model, r->lid.serial, r->lid.firmware);
	}
	s->available = true;
	s->note[0] = 0;
	memset(&s->x, 0, sizeof s->x);
	if (r->d != CONF_DEV_SPECTRO)
		store_device_put(dv->st, dname(r->d), s->vendor, s->model, s->serial, s->firmware, now, &s->device_id,
				 NULL);
	if (dv->notify)
		dv->notify(dv->ctx, (enum conf_dev)r->d, true, "connected");
}

static void query_step(struct query *q);
static void call_done(struct req *r);

static void req_done(struct port_req *pr)
{
	struct req *r = (struct req *)pr;
	struct devices *dv = r->dv;
	struct dev_slot *s = &dv->slot[r->d];
	bool current = r->gen == s->gen;
	/* A laser request that holds its thread longer than half the keep-alive delays the refresh (the same
	 * thread): say so, to tell a slow laser from a thread kept off the CPU. */
	if (r->d == CONF_DEV_LASER && dv->ka.period > 0 && r->pr.took_s > 2 * dv->ka.period)
		log_msg(LOG_WARNING, "laser: request %d took %.3f s on its thread (%.3f s running, %.3f s waiting for a "
			"CPU, %.3f s waiting for the laser)%s%s", (int)r->op, r->pr.took_s, r->pr.on_cpu_s,
			r->pr.cpu_wait_s, r->pr.took_s - r->pr.on_cpu_s - r->pr.cpu_wait_s, r->rc ? ": " : "",
			r->rc ? r->err.msg : "");
	if (r->op == R_OPEN)
		opened(dv, r);
	if (current) {
		if (r->have_ast) {
			s->ast = r->ast;
			s->have_status = true;
		}
		if (r->have_lst) {
			s->lst = r->lst;
			s->have_status = true;
		}
		if (r->op == R_STATUS && r->rc)
			s->have_status = false;
	}
	if (r->owner == OWN_EX && current)
		devices_ex_done(dv, r);
	else if (r->owner == OWN_OP)
		devices_op_done(dv, r);
	else if (r->owner == OWN_QUERY)
		query_step(r->q);
	else if (r->owner == OWN_CALL)
		call_done(r);
	else if (r->owner == OWN_MGR && r->rc && (r->op == R_LASER || r->op == R_STOP)) {
		/* the driver's message names the device already ("detector.theta (unit 1 @ ...): link is down") */
		bool named = !strncmp(r->err.msg, dname(r->d), strlen(dname(r->d)));
		log_msg(LOG_ERR, "safe stop: %s%s%s not confirmed: %s", named ? "" : dname(r->d), named ? "" : ": ",
			r->op == R_LASER ? "laser emission off" : "stop", r->err.msg);
	}
	free(r->frame);
	free(r);
}

/* ---- the device manager ------------------------------------------------------------------------------------ */

static const void *cfg_of(const struct conf *c, int d)
{
	return is_axis(d) ? (const void *)c->axis[d] : d == CONF_DEV_SPECTRO ? (const void *)c->spectro
									      : (const void *)c->laser;
}

static void try_open(struct devices *dv, int d)
{
	struct dev_slot *s = &dv->slot[d];
	if (s->opening || s->available || !s->port)
		return;
	struct req *r = devices_req_new(dv, d, R_OPEN, OWN_MGR);
	if (!r)
		return;
	r->cfg = cfg_of(dv->c, d);
	s->opening = true;
	devices_req_submit(r);
}

/* Every absent device is tried on its own thread: an open that times out delays nothing else. */
static void retry_cb(struct loop *lp, void *arg)
{
	(void)lp;
	struct devices *dv = arg;
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		if (dv->slot[d].configured && !dv->slot[d].available)
			try_open(dv, d);
}

static void open_all(struct devices *dv)
{
	const struct conf *c = dv->c;
	for (int d = 0; d < CONF_DEV__COUNT; d++) {
		struct dev_slot *s = &dv->slot[d];
		unsigned gen = s->gen;
		memset(s, 0, sizeof *s);
		s->gen = gen + 1;
		s->configured = cfg_of(c, d) != NULL;
		if (!s->configured) {
			snprintf(s->note, sizeof s->note, "%s", c->devnote[d][0] ? c->devnote[d] : "not configured");
			continue;
		}
		struct acq_err err = { 0 };
		if (port_new(dv->lp, dname(d), &s->port, &err)) {
			snprintf(s->note, sizeof s->note, "%s", unnamed(d, err.msg));
			continue;
		}
		int ka_ms = d == CONF_DEV_LASER ? laser_cfg_keepalive_ms(c->laser) : 0;
		if (ka_ms > 0) {
			pthread_mutex_lock(&dv->ka.mu);
			dv->ka.grace = 3e-3 * ka_ms;
			dv->ka.period = 0.25e-3 * ka_ms;
			dv->ka.last_sent = 0;
			dv->ka.max_gap = 0;
			dv->ka.loop_alive = mono_now();
			pthread_mutex_unlock(&dv->ka.mu);
			port_set_tick(s->port, 0.25e-3 * ka_ms, keepalive_tick, dv);
		}
		try_open(dv, d);
	}
	/* The first attempts run side by side; wait for them, so that what starts next (a sweep resumed at
	 * start-up) finds the devices that answer open. */
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		if (dv->slot[d].port)
			port_flush(dv->slot[d].port);
	dv->retry_timer = loop_timer_add(dv->lp, c->d.device_retry_s, c->d.device_retry_s, retry_cb, dv);
}

static void devices_safe_stop(struct devices *dv);

/* Safe stop, close every handle and end every port (each runs what is queued first). */
static void close_all(struct devices *dv)
{
	devices_safe_stop(dv);
	loop_timer_cancel(dv->lp, dv->retry_timer);
	dv->retry_timer = 0;
	for (int d = 0; d < CONF_DEV__COUNT; d++) {
		struct dev_slot *s = &dv->slot[d];
		if (!s->port)
			continue;
		devices_req_submit(devices_req_new(dv, d, R_CLOSE, OWN_MGR));
		port_free(s->port);
		s->port = NULL;
		s->available = false;
		s->gen++;
		free(s->x.frame);
		s->x.frame = NULL;
	}
	dv->spectro_id = 0;
}

int devices_init(struct loop *lp, struct store *st, const struct conf *c, devices_notify_fn notify, void *ctx,
		 double (*wallclock)(void), struct devices **out, struct acq_err *err)
{
	struct devices *dv = calloc(1, sizeof *dv);
	if (!dv)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	*dv = (struct devices){ .lp = lp, .st = st, .c = c, .notify = notify, .ctx = ctx, .wallclock = wallclock };
	pthread_mutex_init(&dv->ka.mu, NULL);
	open_all(dv);
	*out = dv;
	return 0;
}

int devices_reconfigure(struct devices *dv, const struct conf *c, struct acq_err *err)
{
	if (dv->op_active)
		return acq_errf(err, ACQ_E_STATE, "a manual move or measurement is running");
	close_all(dv);
	dv->c = c;
	open_all(dv);
	return 0;
}

/* Laser emission off, every arm and the spectrometer stopped (queued first on each port, what runs there is
 * interrupted); a failure is logged when it comes back. */
static void devices_safe_stop(struct devices *dv)
{
	if (!dv)
		return;
	for (int d = 0; d < CONF_DEV__COUNT; d++) {
		struct dev_slot *s = &dv->slot[d];
		if (!s->available || !s->port)
			continue;
		if (d == CONF_DEV_LASER) {
			struct req *r = devices_req_new(dv, d, R_LASER, OWN_MGR);
			if (r)
				r->on = false;
			devices_req_submit(r);
		} else {
			port_interrupt(s->port);
			devices_req_submit(devices_req_new(dv, d, is_axis(d) ? R_STOP : R_SPECTRO_STOP, OWN_MGR));
		}
	}
}

void devices_finish(struct devices *dv)
{
	if (!dv)
		return;
	if (dv->op_active) { /* a manual operation is cut short: its requester gets an answer */
		devices_done_fn done = dv->op_done;
		dv->op_done = NULL;
		dv->op_active = false;
		struct acq_err err = { 0 };
		acq_errf(&err, ACQ_E_STATE, "the daemon is stopping: operation interrupted");
		if (done)
			done(dv->op_ctx, -1, &err, NULL);
	}
	close_all(dv);
	pthread_mutex_destroy(&dv->ka.mu);
	free(dv);
}

bool devices_up(const struct devices *dv, enum conf_dev d)
{
	return dv->slot[d].available;
}

int64_t devices_device_id(const struct devices *dv, enum conf_dev d)
{
	return dv->slot[d].available ? dv->slot[d].device_id : 0;
}

long long devices_spectrometer_id(const struct devices *dv)
{
	return dv->spectro_id;
}

void devices_set_kick(struct devices *dv, void (*kick)(void *ctx), void *ctx)
{
	dv->kick = kick;
	dv->kick_ctx = ctx;
}

void devices_lost(struct devices *dv, enum conf_dev d, const char *why)
{
	struct dev_slot *s = &dv->slot[d];
	if (!s->available)
		return; /* already closed (or being opened again) */
	bool was = s->available;
	s->available = false;
	s->have_status = false;
	s->gen++; /* what is still running for the old handle is dropped when it completes */
	free(s->x.frame);
	memset(&s->x, 0, sizeof s->x);
	why = unnamed(d, why);
	snprintf(s->note, sizeof s->note, "%s", why);
	if (s->port) {
		port_interrupt(s->port);
		devices_req_submit(devices_req_new(dv, d, R_CLOSE, OWN_MGR));
	}
	if (was && dv->notify)
		dv->notify(dv->ctx, d, false, why);
}

void devices_positions(struct devices *dv, double pos[3])
{
	for (int i = 0; i < 3; i++) {
		const struct dev_slot *s = &dv->slot[i];
		pos[i] = s->available && s->have_status ? s->ast.position_deg : NAN;
	}
}

int devices_available(const struct devices *dv)
{
	int n = 0;
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		n += dv->slot[d].available;
	return n;
}

bool devices_busy(const struct devices *dv)
{
	return dv->op_active;
}

json_t *devices_json(struct devices *dv)
{
	json_t *arr = json_array();
	for (int d = 0; arr && d < CONF_DEV__COUNT; d++) {
		struct dev_slot *s = &dv->slot[d];
		bool present = s->configured || dv->c->devpresent[d];
		json_t *o = json_pack("{s:s,s:b,s:b,s:s}", "name", dname(d), "configured", present, "available",
				      s->available, "state",
				      s->available ? "connected" : present ? "unavailable" : "not_configured");
		if (!o)
			continue;
		if (s->note[0])
			json_object_set_new(o, "note", json_string(s->note));
		if (s->available)
			json_object_set_new(o, "identity",
					    json_pack("{s:s,s:s,s:s,s:s}", "vendor", s->vendor, "model", s->model, "serial",
						      s->serial, "firmware", s->firmware));
		if (is_axis(d) && dv->c->axis[d]) {
			double lo, hi;
			axis_cfg_limits(dv->c->axis[d], &lo, &hi);
			json_object_set_new(o, "limits_deg", json_pack("[f,f]", lo, hi));
			const struct axis_status *st = &s->ast;
			if (s->available && s->have_status)
				json_object_set_new(o, "status",
						    json_pack("{s:f,s:b,s:b,s:b,s:i}", "position_deg", st->position_deg,
							      "busy", st->busy, "homed", st->homed, "alarm", st->alarm,
							      "alarm_code", st->alarm_code));
		}
		if (d == CONF_DEV_LASER && s->available && s->have_status) {
			const struct laser_status *ls = &s->lst;
			json_object_set_new(o, "status", json_pack("{s:b,s:f,s:b,s:b}", "emission", ls->emission, "power_pct",
								   ls->power_pct, "interlock_ok", ls->interlock_ok, "fault",
								   ls->fault));
		}
		json_array_append_new(arr, o);
	}
	return arr;
}

/* ---- `devices`: fresh status from every available axis and the laser, then the report ---------------------- */

static void query_reply(struct loop *lp, void *arg)
{
	(void)lp;
	struct query *q = arg;
	if (q->positions) {
		double pos[3];
		devices_positions(q->dv, pos);
		json_t *o = json_object();
		for (int i = 0; o && i < 3; i++)
			json_object_set_new(o, dname(i), isnan(pos[i]) ? json_null() : json_real(pos[i]));
		q->done(q->ctx, 0, NULL, o);
	} else {
		q->done(q->ctx, 0, NULL, json_pack("{s:o}", "devices", devices_json(q->dv)));
	}
	free(q);
}

static void query_step(struct query *q)
{
	if (--q->waiting == 0)
		query_reply(NULL, q);
}

static int query(struct devices *dv, bool positions, devices_done_fn done, void *ctx, struct acq_err *err)
{
	struct query *q = calloc(1, sizeof *q);
	if (!q)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	*q = (struct query){ .dv = dv, .positions = positions, .done = done, .ctx = ctx, .waiting = 1 };
	for (int d = 0; d < CONF_DEV__COUNT; d++) {
		if (d == CONF_DEV_SPECTRO || !dv->slot[d].available || (positions && !is_axis(d)))
			continue;
		struct req *r = devices_req_new(dv, d, R_STATUS, OWN_QUERY);
		if (r)
			r->q = q;
		if (devices_req_submit(r) == 0)
			q->waiting++;
	}
	if (--q->waiting == 0 && !loop_timer_add(dv->lp, 0, 0, query_reply, q)) {
		free(q);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	return 0;
}

int devices_query(struct devices *dv, devices_done_fn done, void *ctx, struct acq_err *err)
{
	return query(dv, false, done, ctx, err);
}

int devices_read_positions(struct devices *dv, devices_done_fn done, void *ctx, struct acq_err *err)
{
	return query(dv, true, done, ctx, err);
}

static void call_done(struct req *r)
{
	struct acq_err err = r->err;
	if (!r->rc && r->have_lst && r->lst.emission)
		r->rc = acq_errf(&err, ACQ_E_DEVICE, "emission still reported on after switching it off");
	if (r->rc) {
		acq_err_prefix(&err, "laser: ");
		r->done(r->done_ctx, -1, &err, NULL);
	} else {
		r->done(r->done_ctx, 0, NULL, json_pack("{s:b}", "emission", 0));
	}
}

void devices_heartbeat(struct devices *dv)
{
	struct keepalive *ka = &dv->ka;
	pthread_mutex_lock(&ka->mu);
	ka->loop_alive = mono_now();
	unsigned long nfail = ka->failures - ka->reported_failures, nskip = ka->skipped - ka->reported_skipped;
	struct acq_err e = ka->last_err;
	ka->reported_failures = ka->failures;
	ka->reported_skipped = ka->skipped;
	double gap = ka->max_gap, period = ka->period, gap_wait = ka->max_gap_cpu_wait;
	if (gap > 2 * period)
		ka->max_gap = 0;
	pthread_mutex_unlock(&ka->mu);
	if (gap > 2 * period) /* the laser's thread was held up (a slow laser command, or not scheduled) */
		log_msg(LOG_WARNING, "laser keep-alive: %.3f s between two refreshes (period %.3f s; the laser's thread "
			"waited %.3f s of it for a CPU)", gap, period, gap_wait);
	if (nfail)
		log_msg(LOG_WARNING, "laser keep-alive: %lu failure(s), the last: %s (emission switched off)", nfail, e.msg);
	if (nskip)
		log_msg(LOG_WARNING, "laser keep-alive: not refreshed %lu time(s): the loop was silent for more than %.1f s "
			"(the laser may have switched emission off)", nskip, ka->grace);
}

void devices_keepalive_counts(struct devices *dv, unsigned long *refreshes, unsigned long *failures,
			      unsigned long *skipped)
{
	pthread_mutex_lock(&dv->ka.mu);
	*refreshes = dv->ka.refreshes;
	*failures = dv->ka.failures;
	*skipped = dv->ka.skipped;
	pthread_mutex_unlock(&dv->ka.mu);
}

int devices_laser_off(struct devices *dv, devices_done_fn done, void *ctx, struct acq_err *err)
{
	const struct dev_slot *s = &dv->slot[CONF_DEV_LASER];
	if (!s->available)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "laser: unavailable (%s)", s->note[0] ? s->note : "not configured");
	struct req *r = devices_req_new(dv, CONF_DEV_LASER, R_LASER, OWN_CALL);
	if (r) {
		r->on = false;
		r->done = done;
		r->done_ctx = ctx;
	}
	return devices_req_submit(r) ? acq_errf(err, ACQ_E_NOMEM, "out of memory") : 0;
}
