/* commands_sweep: the sweep.* commands and the start-up resume; a start (or the resume of an interrupted sweep)
 * is planned in a worker off the loop, then stored and started on it. */
#include "daemon/commands_int.h"

#include <stdlib.h>
#include <string.h>

#include "daemon/devices.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/plan_worker.h"
#include "daemon/store.h"
#include "daemon/store_adaptive.h"
#include "daemon/sweep.h"

#include "daemon/plan/plan.h"

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
	server_reply(l->app->srv, l->serial, l->id, json_pack("{s:o}", "progress", cmd_progress_json(l->app)));
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
	server_reply(app->srv, peer->serial, id, json_pack("{s:o}", "progress", cmd_progress_json(app)));
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
			     json_pack("{s:I,s:o}", "sweep", (json_int_t)sid, "progress", cmd_progress_json(app)));
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
	double rate = loop_rate(app->lp); /* loop seconds per real second */
	if (plan_worker_start(name && *name ? name : "plan", text, &app->conf->bench, &tm, PLAN_MEM_BYTES, START_DEADLINE_S * rate,
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
		cmd_reply_err(app, peer, req->id, &err);
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
			return cmd_reply_err(app, peer, req->id, &err);
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
	int r = sweep_resume_plan_text(app->sweep, (int64_t)cmd_num_arg(req->root, "sweep", 0), &id, &text, &name, &err);
	if (r < 0)
		return cmd_reply_err(app, peer, req->id, &err);
	if (r == 0)
		return start_planning(app, peer, req, id, text, name);
	if (sweep_resume(app->sweep, (int64_t)cmd_num_arg(req->root, "sweep", 0), &err))
		return cmd_reply_err(app, peer, req->id, &err);
	reply_when(app, peer, req->id, SWEEP_RUNNING);
}

void cmd_sweep_handle(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	const char *sub = req->cmd + strlen("sweep.");
	json_t *data = NULL;
	int rc = 0;
	if (!strcmp(sub, "list")) {
		data = store_sweep_list(app->store, (int)cmd_num_arg(req->root, "limit", 100), &err);
		if (data)
			data = json_pack("{s:o}", "sweeps", data);
		rc = data ? 0 : -1;
	} else if (!strcmp(sub, "show")) {
		json_t *pts = json_object_get(req->root, "points");
		int64_t sid = (int64_t)cmd_num_arg(req->root, "sweep", 0);
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
		return cmd_reply_err(app, peer, req->id, &err);
	if (!data)
		data = json_pack("{s:o}", "progress", cmd_progress_json(app));
	server_reply(app->srv, peer->serial, req->id, data);
}
