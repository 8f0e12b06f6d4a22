/* commands_plan: the `plan` command, a dry run against the running configuration's bench in a forked child. */
#include "daemon/commands_int.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/sweep.h"

#include "daemon/plan/plan.h"

/* ---- plan: dry run against the running configuration's bench, in a child with a deadline ----
 * The planner's cost grows fast with the points (1000 × 10 Fibonacci points took 31 s and 2000 × 10 320 MB on
 * the loop): it runs in a forked child, at most PLAN_CHILDREN at once, killed after PLAN_DEADLINE_S (real
 * seconds) and limited to PLAN_MEM_BYTES of address space, so no request holds the loop or its memory. */
#define PLAN_CHILDREN 2
#define PLAN_DEADLINE_S 10.0

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

void cmd_plan_handle(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (plan_children >= PLAN_CHILDREN) {
		acq_errf(&err, ACQ_E_UNSUPPORTED, "plan: %d plans are being computed already; retry later", plan_children);
		return server_reply_error(app->srv, peer->serial, req->id, PROTO_E_UNAVAILABLE, err.msg);
	}
	struct plan_job *pj = calloc(1, sizeof *pj);
	if (!pj) {
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return cmd_reply_err(app, peer, req->id, &err);
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
		return cmd_reply_err(app, peer, req->id, &err);
	}
	pj->text = NULL; /* the request is freed after this call; the child has its own copy */
	plan_children++;
}
