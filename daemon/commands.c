/* commands: what each protocol command does in the daemon (dispatch from server.c; see proto_cmds[]). */
#include "daemon/app.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "acq_version.h"
#include "daemon/devices.h"
#include "daemon/export.h"
#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/plan_worker.h"
#include "daemon/store.h"
#include "daemon/store_adaptive.h"
#include "daemon/sweep.h"

#include "daemon/plan/plan.h"

/* ---- helpers ---- */

static void reply_err(struct app *app, const struct srv_peer *peer, json_t *id, const struct acq_err *err)
{
	server_reply_error(app->srv, peer->serial, id, proto_code_of(err), err->msg);
}

static double num_arg(json_t *req, const char *key, double dflt)
{
	json_t *v = json_object_get(req, key);
	return v ? json_number_value(v) : dflt;
}

static json_t *progress_json(struct app *app)
{
	struct sweep_progress p;
	sweep_get_progress(app->sweep, &p);
	json_t *o = json_pack("{s:s,s:I,s:i,s:i,s:s}", "state", sweep_state_name(p.state), "id", (json_int_t)p.sweep_id,
			      "done", p.points_done, "total", p.points_total, "message", p.message);
	/* wall-clock seconds, only while running: a paused sweep has no ETA that counts down */
	json_object_set_new(o, "eta_s", p.state == SWEEP_RUNNING && isfinite(p.eta_s) ? json_real(p.eta_s) : json_null());
	/* a pause asked while a point is measured takes effect after it (sweep.pause replies by then or after 10 s) */
	json_object_set_new(o, "pause_pending", json_boolean(p.state == SWEEP_RUNNING && p.pause_pending));
	return o;
}

/* ---- plan: dry run against the running configuration's bench, in a child with a deadline ----
 * The planner's cost grows fast with the points (1000 × 10 Fibonacci points took 31 s and 2000 × 10 320 MB on
 * the loop): it runs in a forked child, at most PLAN_CHILDREN at once, killed after PLAN_DEADLINE_S (real
 * seconds) and limited to PLAN_MEM_BYTES of address space, so no request holds the loop or its memory. */
#define PLAN_CHILDREN 2
#define PLAN_DEADLINE_S 10.0
#define PLAN_MEM_BYTES ((size_t)1 << 30)

static int plan_children;

struct plan_job {
	struct app *app;
	uint64_t serial;
	json_t *id;
	/* valid in the child (its copy of memory): */
	const char *text;        /* the request's plan text */
	bool points;             /* the reply lists every step */
	struct plan_timing tm;   /* this daemon's executor timing */
};

/* In the child: plan, print {"plan": {...}, "source": "daemon"} (the same object as the local dry run) or
 * {"code": ..., "message": ...} on fd. */
static int plan_child(void *arg, int fd)
{
	struct plan_job *pj = arg;
	const struct conf *c = pj->app->conf;
	struct acq_err err = { 0 };
	struct plan_spec *spec = NULL;
	struct plan_result *res = NULL;
	json_t *o;
	if (plan_load_string("plan", pj->text, &spec, &err) || plan_make(spec, &c->bench, &res, &err)) {
		o = json_pack("{s:s,s:s}", "code", proto_code_of(&err), "message", err.msg);
	} else {
		json_t *p = plan_dry_run_json(spec, &c->bench, &pj->tm, res, pj->points);
		if (p) {
			json_object_set_new(p, "bench_config", json_string(c->path));
			json_object_set_new(p, "time_scale", json_real(pj->tm.time_scale)); /* bench s per wall s */
		}
		o = json_pack("{s:o,s:s}", "plan", p, "source", "daemon");
	}
	char *line = o ? json_dumps(o, JSON_COMPACT) : NULL;
	if (!line)
		return 3;
	struct acq_err werr;
	return proto_write_all(fd, line, strlen(line), &werr) ? 4 : 0;
}

static void plan_done(struct job *j, int status, const char *output, size_t len, void *arg)
{
	struct plan_job *pj = arg;
	struct app *app = pj->app;
	plan_children--;
	json_t *o = status == 0 && !job_output_truncated(j) ? json_loadb(output, len, 0, NULL) : NULL;
	char msg[200];
	if (o && json_object_get(o, "plan")) {
		server_reply(app->srv, pj->serial, pj->id, json_incref(o));
	} else if (o) {
		server_reply_error(app->srv, pj->serial, pj->id, json_string_value(json_object_get(o, "code")),
				   json_string_value(json_object_get(o, "message")));
	} else {
		if (job_timed_out(j))
			snprintf(msg, sizeof msg, "plan: not planned within %.0f s, the daemon's bound: use fewer points "
				 "or plan it offline (acqctl plan FILE without the daemon)", PLAN_DEADLINE_S);
		else if (job_output_truncated(j))
			snprintf(msg, sizeof msg, "plan: the reply is longer than %zu bytes: ask without points=true or plan "
				 "it offline (acqctl plan FILE without the daemon)",
				 pj->points ? (size_t)PROTO_MAX_REPLY : (size_t)JOB_FORK_OUTPUT_MAX);
		else
			snprintf(msg, sizeof msg, "plan: the planner failed (status %d; memory is bounded to %zu MiB)", status,
				 PLAN_MEM_BYTES >> 20);
		log_msg(LOG_NOTICE, "%s", msg);
		server_reply_error(app->srv, pj->serial, pj->id, PROTO_E_RANGE, msg);
	}
	json_decref(o);
	json_decref(pj->id);
	free(pj);
}

static void cmd_plan(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (plan_children >= PLAN_CHILDREN) {
		acq_errf(&err, ACQ_E_UNSUPPORTED, "plan: %d plans are being computed already; retry later", plan_children);
		return server_reply_error(app->srv, peer->serial, req->id, PROTO_E_UNAVAILABLE, err.msg);
	}
	struct plan_job *pj = calloc(1, sizeof *pj);
	if (!pj) {
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return reply_err(app, peer, req->id, &err);
	}
	*pj = (struct plan_job){ .app = app, .serial = peer->serial, .id = json_incref(req->id),
				 .text = json_string_value(json_object_get(req->root, "plan")),
				 .points = json_is_true(json_object_get(req->root, "points")) };
	sweep_plan_timing(app->sweep, &pj->tm);
	struct plan_spec *spec = NULL; /* the sample's exposure prior needs the database: read here, not in the child */
	if (pj->text && plan_load_string("plan", pj->text, &spec, &err) == 0)
		sweep_plan_prior(app->sweep, spec, 0, &pj->tm);
	plan_spec_free(spec);
	err = (struct acq_err){ 0 }; /* the child reports the plan's errors */
	double rate = app->have_sim && app->sim.time_scale > 0 ? app->sim.time_scale : 1; /* loop seconds per s */
	/* with every step the reply grows with the plan (the paper's 866 points: about 0.3 MB): bounded by what a
	 * client accepts as a reply */
	size_t out_max = pj->points ? PROTO_MAX_REPLY : JOB_FORK_OUTPUT_MAX;
	if (job_fork_out(plan_child, pj, PLAN_MEM_BYTES, out_max, PLAN_DEADLINE_S * rate, plan_done, pj, NULL, &err)) {
		json_decref(pj->id);
		free(pj);
		return reply_err(app, peer, req->id, &err);
	}
	pj->text = NULL; /* the request is freed after this call; the child has its own copy */
	plan_children++;
}

/* A manual move must not make the arms collide, on the way or at the target (straight
 * segment, all axes together — what devices_move() does). Blind zones for the beam or the view are allowed
 * (alignment needs them) and reported in the reply. 0, or -1 with ACQ_E_RANGE. */
static int move_check(struct app *app, const double t[3], const char **warning, struct acq_err *err)
{
	*warning = NULL;
	double cur[3];
	devices_positions(app->dev, cur);
	for (int i = 0; i < 3; i++)
		if (isnan(cur[i]))
			return 0; /* an axis is unavailable: devices_move() refuses the move anyway */
	struct plan_pos a = { cur[0], cur[1], cur[2] };
	struct plan_pos b = { isnan(t[0]) ? cur[0] : t[0], isnan(t[1]) ? cur[1] : t[1], isnan(t[2]) ? cur[2] : t[2] };
	unsigned blind = plan_blind(&app->conf->bench, &b);
	if (blind & (PLAN_R_COLLISION | PLAN_R_LIMITS))
		return acq_errf(err, ACQ_E_RANGE, "move to (%g°, %g°, %g°) refused: %s", b.laser_theta, b.det_theta,
				b.det_phi, plan_reason_name(blind & (PLAN_R_COLLISION | PLAN_R_LIMITS)));
	/* From a position that already violates the clearance (e.g. both arms parked at the zenith) any path
	 * "collides" at its start: then only the target is checked, so the operator can move out. */
	bool stuck = plan_blind(&app->conf->bench, &a) & PLAN_R_COLLISION;
	if (!stuck && !plan_seg_safe(&app->conf->bench, &a, &b))
		return acq_errf(err, ACQ_E_RANGE, "move from (%g°, %g°, %g°) to (%g°, %g°, %g°) refused: the arms would "
				"collide on the way; move one arm first", a.laser_theta, a.det_theta, a.det_phi,
				b.laser_theta, b.det_theta, b.det_phi);
	if (blind)
		*warning = plan_reason_name(blind);
	return 0;
}

/* ---- manual device operations: replies arrive later ---- */
struct pending {
	struct app *app;
	uint64_t serial;
	json_t *id;
	const char *warning;  /* static text added to a successful reply */
	int stopped;          /* >= 0: `stopped` added to a successful reply (stop) */
};

static void pending_done(void *ctx, int rc, const struct acq_err *err, json_t *result)
{
	struct pending *p = ctx;
	if (rc)
		server_reply_error(p->app->srv, p->serial, p->id, proto_code_of(err), err->msg);
	else {
		if (p->warning && json_is_object(result))
			json_object_set_new(result, "warning", json_string(p->warning));
		if (p->stopped >= 0 && json_is_object(result))
			json_object_set_new(result, "stopped", json_boolean(p->stopped));
		server_reply(p->app->srv, p->serial, p->id, result);
	}
	json_decref(p->id);
	free(p);
}

static struct pending *pending_new(struct app *app, const struct srv_peer *peer, json_t *id)
{
	struct pending *p = calloc(1, sizeof *p);
	if (p)
		*p = (struct pending){ .app = app, .serial = peer->serial, .id = json_incref(id), .stopped = -1 };
	return p;
}

static void cmd_move(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep)) {
		acq_errf(&err, ACQ_E_STATE, "a sweep is loaded: pause is not enough, abort it before moving by hand");
		return reply_err(app, peer, req->id, &err);
	}
	/* the axes' one name (laser.theta), or the old one (laser_theta) an older client sends */
	double t[3] = { num_arg(req->root, "laser.theta", num_arg(req->root, "laser_theta", NAN)),
			num_arg(req->root, "detector.theta", num_arg(req->root, "detector_theta", NAN)),
			num_arg(req->root, "detector.phi", num_arg(req->root, "detector_phi", NAN)) };
	const char *warning;
	if (move_check(app, t, &warning, &err))
		return reply_err(app, peer, req->id, &err);
	if (warning)
		log_msg(LOG_NOTICE, "manual move into a blind zone (%s)", warning);
	struct pending *p = pending_new(app, peer, req->id);
	if (!p) {
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return reply_err(app, peer, req->id, &err);
	}
	p->warning = warning;
	if (devices_move(app->dev, t, pending_done, p, &err)) {
		json_decref(p->id);
		free(p);
		reply_err(app, peer, req->id, &err);
	}
}

static void cmd_measure(struct app *app, const struct srv_peer *peer, struct proto_req *req, const char *kind)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep)) {
		acq_errf(&err, ACQ_E_STATE, "a sweep is loaded: abort it before measuring by hand");
		return reply_err(app, peer, req->id, &err);
	}
	double it = num_arg(req->root, "integration_ms", 100);
	int avg = (int)num_arg(req->root, "averages", app->conf->sweep.averages);
	struct pending *p = pending_new(app, peer, req->id);
	if (!p) {
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return reply_err(app, peer, req->id, &err);
	}
	if (devices_measure(app->dev, kind, it, avg, num_arg(req->root, "power_pct", NAN), pending_done, p, &err)) {
		json_decref(p->id);
		free(p);
		reply_err(app, peer, req->id, &err);
	}
}

/* `devices`: the report waits for fresh status reads on the devices' own threads (the loop never does). */
/* Fresh device reads are queued on the devices' threads in front of the sweep's own requests (and of the
 * laser's keep-alive): one query at a time for all clients together; a request arriving while one runs gets
 * what is known now (devices_json: no device I/O). */
static bool devices_query_running;
/* An observer's `devices` reads the hardware at most once per DEVICES_OBSERVER_READ_S (real seconds) and gets
 * the cached view otherwise: clients without control cannot keep the devices' lines busy (a flood of `devices`
 * held the laser's line with status reads, ahead of the sweep's laser commands). Controllers read live. */
#define DEVICES_OBSERVER_READ_S 1.0
static double devices_query_end; /* real (monotonic) seconds the last live read ended */

static void devices_query_done(void *ctx, int rc, const struct acq_err *err, json_t *result)
{
	devices_query_running = false;
	devices_query_end = loop_monotonic(NULL);
	pending_done(ctx, rc, err, result);
}

static void cmd_devices(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	if (devices_query_running || (peer->role != PROTO_CONTROLLER && devices_query_end > 0 &&
				      loop_monotonic(NULL) - devices_query_end < DEVICES_OBSERVER_READ_S)) {
		server_reply(app->srv, peer->serial, req->id, json_pack("{s:o}", "devices", devices_json(app->dev)));
		return;
	}
	struct acq_err err = { 0 };
	struct pending *p = pending_new(app, peer, req->id);
	if (!p) {
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return reply_err(app, peer, req->id, &err);
	}
	if (devices_query(app->dev, devices_query_done, p, &err)) {
		json_decref(p->id);
		free(p);
		reply_err(app, peer, req->id, &err);
		return;
	}
	devices_query_running = true;
}

/* home [axis]: one axis by its name (laser.theta or laser_theta, ...), or all three one after the other
 * (detector.phi first), each only if its way to the home position (0°) is collision-free. */
struct homing {
	struct app *app;
	uint64_t serial;
	json_t *id;
	unsigned todo;       /* axes left, as bits */
	json_t *homed;       /* names homed so far */
};

static void home_next(struct homing *h);

static void home_done(void *ctx, int rc, const struct acq_err *err, json_t *result)
{
	struct homing *h = ctx;
	json_decref(result);
	if (rc) {
		server_reply_error(h->app->srv, h->serial, h->id, proto_code_of(err), err->msg);
		json_decref(h->homed);
		json_decref(h->id);
		free(h);
		return;
	}
	home_next(h);
}

static void home_next(struct homing *h)
{
	static const int order[3] = { CONF_DEV_DETECTOR_PHI, CONF_DEV_LASER_THETA, CONF_DEV_DETECTOR_THETA };
	struct acq_err err = { 0 };
	for (int k = 0; k < 3; k++) {
		int a = order[k];
		if (!(h->todo & (1u << a)))
			continue;
		h->todo &= ~(1u << a);
		double t[3] = { NAN, NAN, NAN };
		t[a] = 0;
		const char *warning;
		if (move_check(h->app, t, &warning, &err)) {
			acq_err_prefix(&err, "home %s: ", conf_dev_name((enum conf_dev)a));
			goto fail;
		}
		if (devices_home(h->app->dev, 1u << a, home_done, h, &err))
			goto fail;
		json_array_append_new(h->homed, json_string(conf_dev_name((enum conf_dev)a)));
		return;
	}
	double pos[3];
	devices_positions(h->app->dev, pos);
	json_t *o = json_pack("{s:O}", "homed", h->homed);
	for (int i = 0; i < 3; i++)
		json_object_set_new(o, conf_dev_name((enum conf_dev)i), isnan(pos[i]) ? json_null() : json_real(pos[i]));
	server_reply(h->app->srv, h->serial, h->id, o);
	goto out;
fail:
	server_reply_error(h->app->srv, h->serial, h->id, proto_code_of(&err), err.msg);
out:
	json_decref(h->homed);
	json_decref(h->id);
	free(h);
}

static void cmd_home(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep) || devices_busy(app->dev)) {
		acq_errf(&err, ACQ_E_STATE, sweep_busy(app->sweep) ? "a sweep is loaded: abort it before homing by hand"
								   : "a manual operation is running (acqctl stop ends it)");
		return reply_err(app, peer, req->id, &err);
	}
	const char *axis = json_string_value(json_object_get(req->root, "axis"));
	unsigned mask = 0;
	if (!axis || !strcmp(axis, "all"))
		mask = 7;
	for (int i = 0; i < 3 && !mask; i++) {
		char alt[32];
		snprintf(alt, sizeof alt, "%s", conf_dev_name((enum conf_dev)i));
		for (char *q = alt; *q; q++)
			if (*q == '.')
				*q = '_';
		if (!strcmp(axis, conf_dev_name((enum conf_dev)i)) || !strcmp(axis, alt))
			mask = 1u << i;
	}
	if (!mask) {
		acq_errf(&err, ACQ_E_INVAL, "home: unknown axis \"%s\" (laser.theta, detector.theta, detector.phi or all)",
			 axis);
		return reply_err(app, peer, req->id, &err);
	}
	struct homing *h = calloc(1, sizeof *h);
	if (!h || !(h->homed = json_array())) {
		free(h);
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return reply_err(app, peer, req->id, &err);
	}
	*h = (struct homing){ .app = app, .serial = peer->serial, .id = json_incref(req->id), .todo = mask,
			      .homed = h->homed };
	home_next(h);
}

/* stop: a manual move, homing or measurement (a sweep is stopped with sweep pause/abort). */
static void cmd_stop(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep)) {
		acq_errf(&err, ACQ_E_STATE, "a sweep is loaded: use sweep pause or sweep abort");
		return reply_err(app, peer, req->id, &err);
	}
	bool stopped = false;
	if (devices_stop(app->dev, &stopped, &err))
		return reply_err(app, peer, req->id, &err);
	/* the positions read after the stops on each axis's thread: where the arms stopped */
	struct pending *p = pending_new(app, peer, req->id);
	if (p)
		p->stopped = stopped ? 1 : 0;
	if (!p || devices_read_positions(app->dev, pending_done, p, &err)) {
		if (p) {
			json_decref(p->id);
			free(p);
		} else {
			acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		}
		reply_err(app, peer, req->id, &err);
	}
}

static void cmd_laser_off(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep))
		acq_errf(&err, ACQ_E_STATE, "a sweep is loaded: sweep pause or sweep abort switches the laser off");
	else if (devices_busy(app->dev))
		acq_errf(&err, ACQ_E_STATE, "a manual measurement is running: acqctl stop ends it with the laser off");
	else {
		/* the laser's own thread switches it off and reads it back; the reply {emission: false} comes then */
		struct pending *p = pending_new(app, peer, req->id);
		if (!p)
			acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		else if (devices_laser_off(app->dev, pending_done, p, &err)) {
			json_decref(p->id);
			free(p);
		} else {
			log_msg(LOG_NOTICE, "laser off requested by the operator (uid %u)", (unsigned)peer->uid);
			return;
		}
	}
	reply_err(app, peer, req->id, &err);
}

static void cmd_spectrum(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	json_t *s = store_spectrum_json(app->store, (int64_t)num_arg(req->root, "spectrum", 0), &err);
	if (!s)
		return reply_err(app, peer, req->id, &err);
	server_reply(app->srv, peer->serial, req->id, json_pack("{s:o}", "spectrum", s));
}

/* ---- sweeps ---- */

/* The reply to sweep.pause/resume/abort once the sweep is in the state the command leads to (paused, running,
 * released), or after 10 s of the loop's clock with the state then: replies show the state after the command. */
struct later {
	struct app *app;
	uint64_t serial;
	json_t *id;
	double deadline;
	uint64_t timer;
	enum sweep_state want;   /* SWEEP_IDLE: released */
};

static bool later_reached(const struct later *l)
{
	struct sweep_progress p;
	sweep_get_progress(l->app->sweep, &p);
	if (l->want == SWEEP_IDLE)
		return !sweep_busy(l->app->sweep);
	/* a fault or the end of the sweep also settles it */
	return p.state == l->want || p.state == SWEEP_FAULTED || !sweep_busy(l->app->sweep);
}

static void later_check(struct loop *lp, void *arg)
{
	struct later *l = arg;
	if (!later_reached(l) && loop_now(lp) < l->deadline)
		return;
	loop_timer_cancel(lp, l->timer);
	server_reply(l->app->srv, l->serial, l->id, json_pack("{s:o}", "progress", progress_json(l->app)));
	json_decref(l->id);
	free(l);
}

static void reply_when(struct app *app, const struct srv_peer *peer, json_t *id, enum sweep_state want)
{
	struct later *l = calloc(1, sizeof *l);
	if (l) {
		*l = (struct later){ .app = app, .serial = peer->serial, .id = json_incref(id),
				     .deadline = loop_now(app->lp) + 10, .want = want };
		if ((l->timer = loop_timer_add(app->lp, 0, 0.02, later_check, l)))
			return;
		json_decref(l->id);
		free(l);
	}
	server_reply(app->srv, peer->serial, id, json_pack("{s:o}", "progress", progress_json(app)));
}
/* ---- sweep.start: planned off the loop (plan_worker.h), then stored and started on the loop ----
 * The plan text is parsed here (bounded by the request line); plan_make runs in a child with the same memory
 * bound as `plan` and a longer deadline (a sweep of many points is worth waiting for; a client's dry run is
 * not). Meanwhile the sweep module counts as busy: no reload, manual operation or second start; sweep.abort
 * kills the child. */
#define START_DEADLINE_S 120.0

struct start_job {
	struct app *app;
	uint64_t serial;
	json_t *id;
	char *text, *name;
	int64_t resume_id;       /* sweep.resume of this stored sweep (0: sweep.start) */
	bool hold;               /* the resume at start-up (serial 0: no client): a sweep paused for the operator
				    stays paused */
	struct plan_spec *spec;
	struct plan_worker *worker;
};

static struct start_job *starting; /* the sweep.start being planned (one at a time) */

/* sweep.resume requests that came while the start-up resume was planned: run once it is (then they resume the
 * loaded sweep, e.g. after the sample swap, instead of failing with "being planned"). */
struct deferred_resume {
	struct srv_peer peer;
	json_t *root;
	struct deferred_resume *next;
};
static struct deferred_resume *after_auto_resume;

static void cmd_sweep_resume(struct app *app, const struct srv_peer *peer, struct proto_req *req);

static void start_planned(void *ctx, int rc, const struct acq_err *perr, struct plan_result *plan)
{
	struct start_job *sj = ctx;
	struct app *app = sj->app;
	starting = NULL;
	sweep_set_planning(app->sweep, false);
	struct acq_err err = { 0 };
	int64_t sid = 0;
	if (rc) {
		err = *perr;
		acq_err_prefix(&err, "sweep.start: ");
		plan_spec_free(sj->spec);
	} else if (sj->resume_id) {
		rc = sweep_resume_planned(app->sweep, sj->resume_id, sj->spec, plan, sj->hold, &err);
	} else {
		rc = sweep_start_planned(app->sweep, sj->text, sj->name, sj->spec, plan, &sid, &err);
	}
	if (!sj->serial) { /* the resume at start-up: no client to answer */
		if (rc)
			log_msg(LOG_WARNING, "interrupted sweep %lld not resumed: %s", (long long)sj->resume_id, err.msg);
		else
			log_msg(LOG_NOTICE, "resuming interrupted sweep %lld (planned off the loop)",
				(long long)sj->resume_id);
	} else if (rc) {
		log_msg(LOG_NOTICE, "%s", err.msg);
		server_reply_error(app->srv, sj->serial, sj->id, proto_code_of(&err), err.msg);
	} else if (sj->resume_id) {
		struct srv_peer pr = { .serial = sj->serial };
		reply_when(app, &pr, sj->id, SWEEP_RUNNING); /* as a resume of a loaded sweep replies */
	} else {
		server_reply(app->srv, sj->serial, sj->id,
			     json_pack("{s:I,s:o}", "sweep", (json_int_t)sid, "progress", progress_json(app)));
	}
	json_decref(sj->id);
	free(sj->text);
	free(sj->name);
	bool auto_resume = !sj->serial;
	free(sj);
	while (auto_resume && after_auto_resume) {
		struct deferred_resume *d = after_auto_resume;
		after_auto_resume = d->next;
		struct proto_req req = { .root = d->root, .id = json_object_get(d->root, "id"), .cmd = "sweep.resume" };
		cmd_sweep_resume(app, &d->peer, &req);
		json_decref(d->root);
		free(d);
	}
}

/* Plan text (named name) in a worker for sweep.start (resume_id 0) or the resume of stored sweep resume_id;
 * the answer goes to client serial with request id (serial 0: logged only). 0 once planning, or -1. */
static int start_job(struct app *app, uint64_t serial, json_t *id, int64_t resume_id, bool hold, const char *text,
		     const char *name, struct acq_err *err)
{
	struct start_job *sj = NULL;
	if (devices_busy(app->dev)) {
		acq_errf(err, ACQ_E_STATE, "a manual move or measurement is running");
		goto fail;
	}
	if (!resume_id && sweep_start_check(app->sweep, err))
		goto fail;
	if (!text) {
		acq_errf(err, ACQ_E_INVAL, "no plan text");
		goto fail;
	}
	if (!(sj = calloc(1, sizeof *sj)) || !(sj->text = strdup(text)) || (name && !(sj->name = strdup(name)))) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto fail;
	}
	sj->resume_id = resume_id;
	sj->hold = hold;
	if (plan_load_string(name && *name ? name : "plan", text, &sj->spec, err))
		goto fail;
	struct plan_timing tm;
	sweep_plan_timing(app->sweep, &tm);
	sweep_plan_prior(app->sweep, sj->spec, resume_id, &tm);
	sj->app = app;
	sj->serial = serial;
	double rate = app->have_sim && app->sim.time_scale > 0 ? app->sim.time_scale : 1; /* loop seconds per s */
	if (plan_worker_start(sj->spec, &app->conf->bench, &tm, PLAN_MEM_BYTES, START_DEADLINE_S * rate,
			      START_DEADLINE_S, start_planned, sj, &sj->worker, err))
		goto fail;
	sj->id = json_incref(id);
	starting = sj;
	sweep_set_planning(app->sweep, true);
	return 0;
fail:
	if (sj) {
		plan_spec_free(sj->spec);
		free(sj->text);
		free(sj->name);
		free(sj);
	}
	return -1;
}

/* sweep.start, or (resume_id) sweep.resume of an interrupted sweep from its stored text and name (taken). */
static void start_planning(struct app *app, const struct srv_peer *peer, struct proto_req *req, int64_t resume_id,
			   char *stored_text, char *stored_name)
{
	struct acq_err err = { 0 };
	const char *text = resume_id ? stored_text : json_string_value(json_object_get(req->root, "plan"));
	const char *name = resume_id ? stored_name : json_string_value(json_object_get(req->root, "name"));
	int rc = start_job(app, peer->serial, req->id, resume_id, false, text, name, &err);
	free(stored_text);
	free(stored_name);
	if (rc)
		reply_err(app, peer, req->id, &err);
}

int commands_auto_resume(struct app *app, int64_t *id, struct acq_err *err)
{
	char *text = NULL, *name = NULL;
	*id = 0;
	int r = sweep_resume_plan_text(app->sweep, 0, id, &text, &name, err);
	if (r)
		return r < 0 ? -1 : 0; /* 1: a sweep is loaded already (not at start-up) */
	r = start_job(app, 0, NULL, *id, true, text, name, err);
	free(text);
	free(name);
	return r;
}

static void cmd_sweep_start(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	start_planning(app, peer, req, 0, NULL, NULL);
}

/* sweep.resume: a loaded sweep resumes at once; an interrupted one is re-planned from its stored text off the
 * loop first (the same plan, deterministic). */
static void cmd_sweep_resume(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (starting && !starting->serial) { /* the start-up resume is being planned: after it */
		struct deferred_resume *d = calloc(1, sizeof *d), **tail = &after_auto_resume;
		if (!d) {
			acq_errf(&err, ACQ_E_NOMEM, "out of memory");
			return reply_err(app, peer, req->id, &err);
		}
		d->peer = *peer;
		d->root = json_incref(req->root);
		while (*tail)
			tail = &(*tail)->next;
		*tail = d;
		return;
	}
	int64_t id = 0;
	char *text = NULL, *name = NULL;
	int r = sweep_resume_plan_text(app->sweep, (int64_t)num_arg(req->root, "sweep", 0), &id, &text, &name, &err);
	if (r < 0)
		return reply_err(app, peer, req->id, &err);
	if (r == 0)
		return start_planning(app, peer, req, id, text, name);
	if (sweep_resume(app->sweep, (int64_t)num_arg(req->root, "sweep", 0), &err))
		return reply_err(app, peer, req->id, &err);
	reply_when(app, peer, req->id, SWEEP_RUNNING);
}

static void cmd_sweep(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	const char *sub = req->cmd + strlen("sweep.");
	json_t *data = NULL;
	int rc = 0;
	if (!strcmp(sub, "list")) {
		data = store_sweep_list(app->store, (int)num_arg(req->root, "limit", 100), &err);
		if (data)
			data = json_pack("{s:o}", "sweeps", data);
		rc = data ? 0 : -1;
	} else if (!strcmp(sub, "show")) {
		json_t *pts = json_object_get(req->root, "points");
		int64_t sid = (int64_t)num_arg(req->root, "sweep", 0);
		data = store_sweep_show(app->store, sid, json_is_true(pts), &err);
		json_t *ad = data ? store_adaptive_show(app->store, sid, &err) : NULL; /* an adaptive sweep's decisions */
		if (data && ad && json_array_size(ad))
			json_object_set_new(data, "adaptive", ad);
		else
			json_decref(ad);
		if (data)
			data = json_pack("{s:o}", "sweep", data);
		rc = data ? 0 : -1;
	} else if (!strcmp(sub, "start")) {
		return cmd_sweep_start(app, peer, req);
	} else if (!strcmp(sub, "pause")) {
		if (!(rc = sweep_pause(app->sweep, &err)))
			return reply_when(app, peer, req->id, SWEEP_PAUSED);
	} else if (!strcmp(sub, "resume")) {
		return cmd_sweep_resume(app, peer, req);
	} else if (!strcmp(sub, "abort")) {
		if (starting) { /* planning: its sweep.start gets "aborted while planning" */
			plan_worker_abort(starting->worker);
			return reply_when(app, peer, req->id, SWEEP_IDLE);
		}
		if (!(rc = sweep_abort(app->sweep, &err)))
			return reply_when(app, peer, req->id, SWEEP_IDLE);
	}
	if (rc)
		return reply_err(app, peer, req->id, &err);
	if (!data)
		data = json_pack("{s:o}", "progress", progress_json(app));
	server_reply(app->srv, peer->serial, req->id, data);
}

/* ---- reconstruction: the executor owns the chain (sweep_recon_start); here the checks and the reply ---- */
static void cmd_recon_start(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	int64_t sweep = (int64_t)num_arg(req->root, "sweep", 0);
	json_t *sw = store_sweep_show(app->store, sweep, false, &err);
	if (!sw)
		return reply_err(app, peer, req->id, &err);
	const char *state = json_string_value(json_object_get(sw, "state"));
	json_int_t ncal = json_integer_value(json_object_get(sw, "calibrated"));
	if (!state || strcmp(state, "completed") || ncal == 0) {
		acq_errf(&err, ACQ_E_STATE, "sweep %lld is %s with %lld calibrated samples: nothing to reconstruct yet",
			 (long long)sweep, state ? state : "?", (long long)ncal);
		json_decref(sw);
		return reply_err(app, peer, req->id, &err);
	}
	json_decref(sw);
	if (sweep_recon_busy(app->sweep)) {
		acq_errf(&err, ACQ_E_STATE, "a reconstruction is already running");
		return reply_err(app, peer, req->id, &err);
	}
	int64_t run = 0;
	if (sweep_recon_start(app->sweep, sweep, &run, &err))
		return reply_err(app, peer, req->id, &err);
	if (run)
		app->recon_run = run;
	app->recon_sweep = sweep;
	log_msg(LOG_INFO, "reconstruction of sweep %lld started (run %lld)", (long long)sweep, (long long)run);
	server_reply(app->srv, peer->serial, req->id,
		     json_pack("{s:I,s:I}", "run", (json_int_t)run, "sweep", (json_int_t)sweep));
}

static void cmd_recon_status(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	int64_t run = (int64_t)num_arg(req->root, "run", 0), sweep = (int64_t)num_arg(req->root, "sweep", 0);
	if (!run && !sweep) {
		/* the latest run, whoever started it (recon.start or the end of a sweep) */
		if (!(run = store_recon_latest(app->store))) {
			acq_errf(&err, ACQ_E_NOTFOUND, "no reconstruction has run yet; give sweep or run");
			return reply_err(app, peer, req->id, &err);
		}
	}
	json_t *r = store_recon_show(app->store, run, sweep, &err);
	if (!r)
		return reply_err(app, peer, req->id, &err);
	server_reply(app->srv, peer->serial, req->id, json_pack("{s:o}", "run", r));
}

/* ---- information ---- */
static json_t *config_json(struct app *app, bool text)
{
	const struct conf *c = app->conf;
	json_t *ctl = json_array(), *obs = json_array(), *notes = json_object();
	for (int i = 0; i < c->d.ncontrollers; i++)
		json_array_append_new(ctl, json_string(c->d.controllers[i]));
	for (int i = 0; i < c->d.nobservers; i++)
		json_array_append_new(obs, json_string(c->d.observers[i]));
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		if (c->devnote[d][0])
			json_object_set_new(notes, conf_dev_name((enum conf_dev)d), json_string(c->devnote[d]));
	char mode[8];
	snprintf(mode, sizeof mode, "%04o", (unsigned)c->d.socket_mode);
	json_t *o = json_pack(
		"{s:s,s:b,s:{s:s,s:s,s:s,s:s,s:s?,s:i,s:o,s:o,s:b,s:f},"
		"s:{s:f,s:i,s:f,s:f,s:f,s:f,s:i,s:i,s:b,s:b},s:{s:s,s:f,s:i,s:s},s:o}",
		"path", c->path, "sim", c->have_sim,
		"daemon", "state_dir", c->d.state_dir, "database", c->d.database, "socket", c->d.socket_path, "socket_mode",
		mode, "socket_group", c->d.socket_group, "tcp_port", c->d.tcp_port, "controllers", ctl, "observers", obs,
		"auto_resume", c->d.auto_resume, "device_retry_s", c->d.device_retry_s,
		"sweep", "move_timeout_s", c->sweep.move_timeout_s, "move_retries", c->sweep.move_retries, "extra_settle_s",
		c->sweep.extra_settle_s, "target_peak", c->sweep.target_peak, "min_integration_ms",
		c->sweep.min_integration_ms, "max_integration_ms", c->sweep.max_integration_ms, "averages",
		c->sweep.averages, "dark_every", c->sweep.dark_every, "auto_resume_faults", c->sweep.auto_resume_faults,
		"auto_recon", c->sweep.auto_recon,
		"recon", "program", c->recon.program, "timeout_s", c->recon.timeout_s, "threads", c->recon.threads,
		"output_dir", c->recon.output_dir,
		"device_notes", notes);
	if (o && text)
		json_object_set_new(o, "text", json_string(c->text));
	return o;
}

static json_t *status_json(struct app *app)
{
	int clients = 0, watchers = 0;
	server_counts(app->srv, &clients, &watchers);
	char line[256];
	app_status_line(app, line, sizeof line);
	struct server_stats ss;
	server_get_stats(app->srv, &ss);
	json_t *srvj = json_pack("{s:I,s:I,s:I,s:I,s:I}", "refused", (json_int_t)ss.refused, "dropped_unread",
				 (json_int_t)ss.dropped_output, "dropped_stalled", (json_int_t)ss.dropped_stalled,
				 "timed_out", (json_int_t)ss.timed_out, "rate_limited", (json_int_t)ss.rate_limited);
	int64_t rrun = store_recon_latest(app->store), rsweep = 0;
	if (rrun) {
		json_t *r = store_recon_show(app->store, rrun, 0, NULL);
		rsweep = (int64_t)json_integer_value(json_object_get(r, "sweep_id"));
		json_decref(r);
	}
	json_t *o = json_pack("{s:s,s:s,s:i,s:f,s:f,s:o,s:{s:i,s:i},s:i,s:i,s:{s:b,s:I,s:I},s:s,s:b}", "daemon", "running",
			 "version", ACQ_VERSION, "pid", (int)getpid(), "uptime_s", app_wallclock() - app->started_wall,
			 "started_at", app->started_wall, "sweep", progress_json(app), "devices", "available",
			 devices_available(app->dev), "total", CONF_DEV__COUNT, "clients", clients, "watchers", watchers,
			 "recon", "running", sweep_recon_busy(app->sweep), "run", (json_int_t)rrun, "sweep", (json_int_t)rsweep,
			 "summary", line, "sim", app->have_sim);
	if (o)
		json_object_set_new(o, "server", srvj);
	else
		json_decref(srvj);
	return o;
}

void commands_handle(void *ctx, const struct srv_peer *peer, struct proto_req *req)
{
	struct app *app = ctx;
	const char *cmd = req->cmd;
	struct acq_err err = { 0 };
	if (!strcmp(cmd, "version")) {
		server_reply(app->srv, peer->serial, req->id,
			     json_pack("{s:s,s:i,s:s,s:i,s:s}", "version", ACQ_VERSION, "protocol", PROTO_VERSION, "server",
				       "acquisitiond", "schema", store_schema_version(app->store), "role",
				       peer->role == PROTO_CONTROLLER ? "controller" : "observer"));
	} else if (!strcmp(cmd, "status")) {
		server_reply(app->srv, peer->serial, req->id, status_json(app));
	} else if (!strcmp(cmd, "devices")) {
		cmd_devices(app, peer, req);
	} else if (!strcmp(cmd, "config")) {
		bool text = json_is_true(json_object_get(req->root, "text"));
		if (text && peer->tcp) /* the file may name users, paths and devices: local users with a uid only */
			server_reply_error(app->srv, peer->serial, req->id, PROTO_E_FORBIDDEN,
					   "config text: not over TCP (no credentials); use the Unix socket");
		else
			server_reply(app->srv, peer->serial, req->id, json_pack("{s:o}", "config", config_json(app, text)));
	} else if (!strcmp(cmd, "plan")) {
		cmd_plan(app, peer, req);
	} else if (!strncmp(cmd, "sweep.", 6)) {
		cmd_sweep(app, peer, req);
	} else if (!strcmp(cmd, "move")) {
		cmd_move(app, peer, req);
	} else if (!strcmp(cmd, "home")) {
		cmd_home(app, peer, req);
	} else if (!strcmp(cmd, "stop")) {
		cmd_stop(app, peer, req);
	} else if (!strcmp(cmd, "laser.off")) {
		cmd_laser_off(app, peer, req);
	} else if (!strcmp(cmd, "spectrum")) {
		cmd_spectrum(app, peer, req);
	} else if (!strcmp(cmd, "measure")) {
		cmd_measure(app, peer, req, "sample");
	} else if (!strcmp(cmd, "dark") || !strcmp(cmd, "reference")) {
		cmd_measure(app, peer, req, cmd);
	} else if (!strcmp(cmd, "recon.start")) {
		cmd_recon_start(app, peer, req);
	} else if (!strcmp(cmd, "recon.status")) {
		cmd_recon_status(app, peer, req);
	} else if (!strcmp(cmd, "export")) {
		export_handle(app, peer, req);
	} else if (!strcmp(cmd, "reload")) {
		if (app_reload(app, &err))
			reply_err(app, peer, req->id, &err);
		else
			server_reply(app->srv, peer->serial, req->id, json_pack("{s:s}", "config", app->conf->path));
	} else {
		server_reply_error(app->srv, peer->serial, req->id, PROTO_E_INTERNAL, "command in the table but not handled");
	}
}
