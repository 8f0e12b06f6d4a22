/* commands_manual: manual device operations (move, measure/dark/reference, devices, home, stop, laser.off);
 * refused while a sweep is loaded, answered when the devices' threads have done them. */
#include "daemon/commands_int.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/devices.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/sweep.h"

#include "daemon/plan/plan.h"
#include "daemon/plan/plan_home.h"

/* A manual move must not make the arms collide, on the way or at the target (plan_home_move_verdict: straight
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
	const struct bench_geom *g = &app->conf->bench;
	const struct bench_axis *ax[3] = { &g->laser_theta, &g->detector_theta, &g->detector_phi };
	const double bt[3] = { b.laser_theta, b.det_theta, b.det_phi };
	for (int i = 0; i < 3; i++) /* the axis and its range, as the soft limits' refusal says them */
		if (!(bt[i] >= ax[i]->min_deg && bt[i] <= ax[i]->max_deg))
			return acq_errf(err, ACQ_E_RANGE, "%s: %g° is outside the bench's range [%g°, %g°] (bench: %s)",
					conf_dev_name((enum conf_dev)i), bt[i], ax[i]->min_deg, ax[i]->max_deg,
					conf_dev_name((enum conf_dev)i));
	unsigned verdict = plan_home_move_verdict(g, &a, &b);
	if (verdict & (PLAN_R_COLLISION | PLAN_R_LIMITS))
		return acq_errf(err, ACQ_E_RANGE, "%s at laser.theta %g°, detector.theta %g°, detector.phi %g°",
				verdict & PLAN_R_COLLISION ? "collision: the arms would meet" : plan_reason_name(verdict),
				b.laser_theta, b.det_theta, b.det_phi);
	if (verdict)
		return acq_errf(err, ACQ_E_RANGE, "move from (%g°, %g°, %g°) to (%g°, %g°, %g°) refused: the arms would "
				"collide on the way; move one arm first", a.laser_theta, a.det_theta, a.det_phi,
				b.laser_theta, b.det_theta, b.det_phi);
	unsigned blind = plan_blind(&app->conf->bench, &b);
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

void cmd_manual_move(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep)) {
		acq_errf(&err, ACQ_E_STATE, "a sweep is loaded: pause is not enough, abort it before moving by hand");
		return cmd_reply_err(app, peer, req->id, &err);
	}
	/* the axes' one name (laser.theta), or the old one (laser_theta) an older client sends */
	double t[3] = { cmd_num_arg(req->root, "laser.theta", cmd_num_arg(req->root, "laser_theta", NAN)),
			cmd_num_arg(req->root, "detector.theta", cmd_num_arg(req->root, "detector_theta", NAN)),
			cmd_num_arg(req->root, "detector.phi", cmd_num_arg(req->root, "detector_phi", NAN)) };
	const char *warning;
	if (move_check(app, t, &warning, &err))
		return cmd_reply_err(app, peer, req->id, &err);
	if (warning)
		log_msg(LOG_NOTICE, "manual move into a blind zone (%s)", warning);
	struct pending *p = pending_new(app, peer, req->id);
	if (!p) {
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return cmd_reply_err(app, peer, req->id, &err);
	}
	p->warning = warning;
	if (devices_move(app->dev, t, pending_done, p, &err)) {
		json_decref(p->id);
		free(p);
		cmd_reply_err(app, peer, req->id, &err);
	}
}

void cmd_manual_measure(struct app *app, const struct srv_peer *peer, struct proto_req *req, const char *kind)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep)) {
		acq_errf(&err, ACQ_E_STATE, "a sweep is loaded: abort it before measuring by hand");
		return cmd_reply_err(app, peer, req->id, &err);
	}
	double it = cmd_num_arg(req->root, "integration_ms", 100);
	int avg = (int)cmd_num_arg(req->root, "averages", app->conf->sweep.averages);
	struct pending *p = pending_new(app, peer, req->id);
	if (!p) {
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return cmd_reply_err(app, peer, req->id, &err);
	}
	if (devices_measure(app->dev, kind, it, avg, cmd_num_arg(req->root, "power_pct", NAN), pending_done, p, &err)) {
		json_decref(p->id);
		free(p);
		cmd_reply_err(app, peer, req->id, &err);
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

void cmd_manual_devices(struct app *app, const struct srv_peer *peer, struct proto_req *req)
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
		return cmd_reply_err(app, peer, req->id, &err);
	}
	if (devices_query(app->dev, devices_query_done, p, &err)) {
		json_decref(p->id);
		free(p);
		cmd_reply_err(app, peer, req->id, &err);
		return;
	}
	devices_query_running = true;
}

/* home [axis]: one axis by its name (laser.theta or laser_theta, ...), only if its way to the home position (0°)
 * is collision-free; or all three: each referenced at 0° and then moved to its park (home.park in the
 * configuration), in an order (plan_home_order) where every single-axis move is collision-free, after one or two
 * moves that take the arms apart when every home from where they are would close them in. Every step goes through
 * move_check, as a manual move does; the first refusal or failure ends the homing, naming the axes homed. */
struct homing {
	struct app *app;
	uint64_t serial;
	json_t *id;
	struct plan_home_step steps[PLAN_HOME_MAX_STEPS];
	int nsteps, next;
	json_t *homed;       /* names homed so far */
	json_t *apart;       /* the apart moves done: {"axis": name, "to": degrees} */
	bool parked;         /* the parks were part of the sequence */
};

static void home_next(struct homing *h);

static const char *home_verb(const struct plan_home_step *s)
{
	return s->apart ? "move apart" : s->park ? "park" : "home";
}

static void home_free(struct homing *h)
{
	json_decref(h->homed);
	json_decref(h->apart);
	json_decref(h->id);
	free(h);
}

/* Reply err, naming the axes homed before it (the reply shows the state after the command), and end h. */
static void home_refused(struct homing *h, const struct acq_err *err)
{
	char msg[sizeof err->msg + 128];
	size_t n = (size_t)snprintf(msg, sizeof msg, "%s", err->msg);
	for (size_t i = 0; i < json_array_size(h->homed) && n < sizeof msg; i++)
		n += (size_t)snprintf(msg + n, sizeof msg - n, "%s%s", i ? ", " : "; homed before: ",
				      json_string_value(json_array_get(h->homed, i)));
	server_reply_error(h->app->srv, h->serial, h->id, proto_code_of(err), msg);
	home_free(h);
}

static void home_done(void *ctx, int rc, const struct acq_err *err, json_t *result)
{
	struct homing *h = ctx;
	json_decref(result);
	const struct plan_home_step *s = &h->steps[h->next - 1];
	if (rc) {
		struct acq_err e = *err;
		acq_err_prefix(&e, "%s %s: ", home_verb(s), conf_dev_name((enum conf_dev)s->axis));
		return home_refused(h, &e);
	}
	if (s->apart)
		json_array_append_new(h->apart, json_pack("{s:s, s:f}", "axis", conf_dev_name((enum conf_dev)s->axis),
							  "to", s->target));
	else if (!s->park)
		json_array_append_new(h->homed, json_string(conf_dev_name((enum conf_dev)s->axis)));
	home_next(h);
}

static void home_next(struct homing *h)
{
	struct acq_err err = { 0 };
	if (h->next < h->nsteps) {
		const struct plan_home_step *s = &h->steps[h->next++];
		const char *verb = home_verb(s);
		double t[3] = { NAN, NAN, NAN };
		t[s->axis] = s->target;
		const char *warning;
		if (move_check(h->app, t, &warning, &err)) {
			acq_err_prefix(&err, "%s %s: ", verb, conf_dev_name((enum conf_dev)s->axis));
			return home_refused(h, &err);
		}
		if (s->park || s->apart ? devices_move(h->app->dev, t, home_done, h, &err)
			    : devices_home(h->app->dev, 1u << s->axis, home_done, h, &err)) {
			acq_err_prefix(&err, "%s %s: ", verb, conf_dev_name((enum conf_dev)s->axis));
			return home_refused(h, &err);
		}
		return;
	}
	double pos[3];
	devices_positions(h->app->dev, pos);
	json_t *o = json_pack("{s:O, s:b}", "homed", h->homed, "parked", h->parked);
	if (json_array_size(h->apart))
		json_object_set(o, "apart", h->apart);
	for (int i = 0; i < 3; i++)
		json_object_set_new(o, conf_dev_name((enum conf_dev)i), isnan(pos[i]) ? json_null() : json_real(pos[i]));
	server_reply(h->app->srv, h->serial, h->id, o);
	home_free(h);
}

/* The steps of an all-axes home from the arms' positions now: 0, or -1 with err saying why none is safe. */
static int home_plan_all(struct homing *h, struct acq_err *err)
{
	const struct conf *c = h->app->conf;
	double cur[3];
	devices_positions(h->app->dev, cur);
	for (int a = 0; a < 3; a++)
		if (isnan(cur[a]))
			return acq_errf(err, ACQ_E_STATE, "home: %s is unavailable (acqctl devices)",
					conf_dev_name((enum conf_dev)a));
	struct plan_pos from = { cur[0], cur[1], cur[2] };
	h->parked = c->have_park;
	h->nsteps = plan_home_order(&c->bench, &from, c->have_park ? c->park : NULL, 7, h->steps);
	if (h->nsteps >= 0)
		return 0;
	if (!c->have_park)
		return acq_errf(err, ACQ_E_RANGE, "home: the arms cannot all be at their homes (0°, 0°, 0°) at once "
				"(a collision): set home.park in %s (where each axis waits after its home)", c->path);
	return acq_errf(err, ACQ_E_RANGE, "home: no order of single-axis moves from (%g°, %g°, %g°), even with two "
			"moves apart first, homes every axis and parks it at (%g°, %g°, %g°) without a collision; move the "
			"arms apart by hand first",
			cur[0], cur[1], cur[2], c->park[0], c->park[1], c->park[2]);
}

void cmd_manual_home(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep) || devices_busy(app->dev)) {
		acq_errf(&err, ACQ_E_STATE, sweep_busy(app->sweep) ? "a sweep is loaded: abort it before homing by hand"
								   : "a manual operation is running (acqctl stop ends it)");
		return cmd_reply_err(app, peer, req->id, &err);
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
		return cmd_reply_err(app, peer, req->id, &err);
	}
	struct homing *h = calloc(1, sizeof *h);
	if (!h || !(h->homed = json_array()) || !(h->apart = json_array())) {
		if (h)
			json_decref(h->homed);
		free(h);
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return cmd_reply_err(app, peer, req->id, &err);
	}
	*h = (struct homing){ .app = app, .serial = peer->serial, .id = json_incref(req->id), .homed = h->homed,
			      .apart = h->apart };
	if (mask != 7) {
		int a = mask == 1 ? 0 : mask == 2 ? 1 : 2;
		h->steps[0] = (struct plan_home_step){ .axis = a, .park = false, .target = 0 };
		h->nsteps = 1;
	} else if (home_plan_all(h, &err)) {
		home_free(h);
		return cmd_reply_err(app, peer, req->id, &err);
	}
	home_next(h);
}

/* stop: a manual move, homing or measurement (a sweep is stopped with sweep pause/abort). */
void cmd_manual_stop(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (sweep_busy(app->sweep)) {
		acq_errf(&err, ACQ_E_STATE, "a sweep is loaded: use sweep pause or sweep abort");
		return cmd_reply_err(app, peer, req->id, &err);
	}
	bool stopped = false;
	if (devices_stop(app->dev, &stopped, &err))
		return cmd_reply_err(app, peer, req->id, &err);
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
		cmd_reply_err(app, peer, req->id, &err);
	}
}

void cmd_manual_laser_off(struct app *app, const struct srv_peer *peer, struct proto_req *req)
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
	cmd_reply_err(app, peer, req->id, &err);
}
