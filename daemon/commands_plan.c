/* commands_plan: the `plan` command, a dry run against the running configuration's bench in a forked child. */
#include "daemon/commands_int.h"

#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/sweep.h"

#include "daemon/plan/plan.h"

/* ---- plan: dry run against the running configuration's bench, in a child with a deadline ----
 * The planner's cost grows fast with the points (1000 × 10 Fibonacci points took 31 s and 2000 × 10 320 MB on
 * the loop): it runs in a child of the job helper (job_fork_msg: the loop writes the request's bytes, never
 * forks the daemon nor parses the plan), at most PLAN_CHILDREN at once, stopped after daemon.plan_cpu_s seconds of
 * CPU (RLIMIT_CPU; default 10) or daemon.plan_deadline_s real seconds (default 30), and limited to PLAN_MEM_BYTES of address space, so no request
 * holds the loop or its memory. The work is bounded in CPU time, not real time: the child runs at nice +10, and
 * at load 13 a plan of 0.1 s of CPU waited more than the 10 real seconds that were its only bound until session
 * 14 (test_acqctl.py failed); the real-time bound (3× that) only ends a child that hardly gets the CPU at all. It
 * is not longer: a client waits for it, and at nice +10 beside two busy processes the child gets about a tenth of
 * a core, so a plan that needs its 10 s of CPU is ended by this bound, not by RLIMIT_CPU (test_client_limits.py's
 * huge plan at CI's load: 120 s would hold its client two minutes).
 * An auto plan naming its sample needs that sample's exposure prior from the database: the child answers
 * {"need_prior": sample} and the loop asks again with the prior read (a second child). */
#define PLAN_CHILDREN 2

static int plan_children;

/* The child's request: this header, then the configuration's path and the plan's text (job_msg_pack). */
struct plan_msg {
	struct bench_geom g;
	struct plan_timing tm;   /* this daemon's executor timing */
	bool points;             /* the reply lists every step */
	bool prior_given;        /* tm holds the sample's prior (the second request) */
};

struct plan_job {
	struct app *app;
	uint64_t serial;
	json_t *id;
	char *msg;               /* struct plan_msg and its strings */
	size_t msg_len;
};

/* The child's answer: one tag byte, then for PLAN_OUT_PLAN the reply's fields {"plan": {...}, "source": "daemon"}
 * (the same object as the local dry run; passed to the client as it is, not parsed on the loop), for
 * PLAN_OUT_PRIOR the sample's name, for PLAN_OUT_ERROR {"code": ..., "message": ...}. */
#define PLAN_OUT_PLAN 'P'
#define PLAN_OUT_PRIOR 'N'
#define PLAN_OUT_ERROR 'E'

static json_t *plan_reply(const struct plan_msg *m, const char *path, const char *text, char *tag)
{
	struct acq_err err = { 0 };
	struct plan_spec *spec = NULL;
	struct plan_result *res = NULL;
	json_t *o = NULL;
	*tag = PLAN_OUT_ERROR;
	if (plan_load_string("plan", text, &spec, &err)) {
		o = json_pack("{s:s,s:s}", "code", proto_code_of(&err), "message", err.msg);
	} else if (!m->prior_given && spec->integ_mode == PLAN_INTEG_AUTO && spec->sample[0]) {
		*tag = PLAN_OUT_PRIOR;
		o = json_string(spec->sample);
	} else if (plan_make(spec, &m->g, &res, &err)) {
		o = json_pack("{s:s,s:s}", "code", proto_code_of(&err), "message", err.msg);
	} else {
		json_t *p = plan_dry_run_json(spec, &m->g, &m->tm, res, m->points);
		if (p) {
			json_object_set_new(p, "bench_config", json_string(path));
			json_object_set_new(p, "time_scale", json_real(m->tm.time_scale)); /* bench s per wall s */
		}
		*tag = PLAN_OUT_PLAN;
		o = json_pack("{s:o,s:s}", "plan", p, "source", "daemon");
	}
	plan_result_free(res);
	plan_spec_free(spec);
	return o;
}

/* In the child: plan, write the tagged answer on fd. */
static int plan_child(const char *payload, size_t len, int fd)
{
	struct plan_msg m;
	char *path = NULL, tag;
	const char *text = NULL;
	if (job_msg_unpack(payload, len, &m, sizeof m, &path, &text))
		return 5;
	json_t *o = plan_reply(&m, path, text, &tag);
	char *line = !o ? NULL
		     : tag == PLAN_OUT_PRIOR ? strdup(json_string_value(o))
					     : json_dumps(o, JSON_COMPACT | JSON_ENSURE_ASCII);
	if (!line)
		return 3;
	struct acq_err werr;
	return proto_write_all(fd, &tag, 1, &werr) || proto_write_all(fd, line, strlen(line), &werr) ? 4 : 0;
}

const struct job_kind commands_plan_kind = { "plan", plan_child };

static void plan_done(struct job *j, int status, const char *output, size_t len, void *arg);

/* Ask the helper (again) for pj's plan; 0 or -1 with err. */
static int plan_submit(struct plan_job *pj, struct acq_err *err)
{
	const struct plan_msg *m = (const struct plan_msg *)pj->msg;
	double rate = loop_rate(pj->app->lp); /* loop s per real s */
	/* with every step the reply grows with the plan (the paper's 866 points: about 0.3 MB): bounded by what a
	 * client accepts as a reply */
	size_t out_max = m->points ? PROTO_MAX_REPLY : JOB_FORK_OUTPUT_MAX;
	const struct conf_daemon *d = &pj->app->conf->d;
	if (job_fork_msg_cpu(&commands_plan_kind, pj->msg, pj->msg_len, PLAN_MEM_BYTES, (unsigned)d->plan_cpu_s, out_max,
			     d->plan_deadline_s * rate, plan_done, pj, NULL, err))
		return -1;
	plan_children++;
	return 0;
}

static void plan_job_free(struct plan_job *pj)
{
	json_decref(pj->id);
	free(pj->msg);
	free(pj);
}

static void plan_done(struct job *j, int status, const char *output, size_t len, void *arg)
{
	struct plan_job *pj = arg;
	struct app *app = pj->app;
	struct plan_msg *m = (struct plan_msg *)pj->msg;
	plan_children--;
	bool ok = status == 0 && !job_output_truncated(j) && len > 1;
	char tag = ok ? output[0] : 0;
	json_t *o = tag == PLAN_OUT_ERROR ? json_loadb(output + 1, len - 1, 0, NULL) : NULL;
	struct acq_err err = { 0 };
	char msg[200];
	if (tag == PLAN_OUT_PRIOR && !m->prior_given) { /* the sample's prior, read on the loop; then again */
		sweep_plan_prior_of(app->sweep, output + 1, 0, &m->tm);
		m->prior_given = true;
		if (plan_submit(pj, &err) == 0)
			return;
		server_reply_error(app->srv, pj->serial, pj->id, proto_code_of(&err), err.msg);
	} else if (tag == PLAN_OUT_PLAN) {
		server_reply_raw(app->srv, pj->serial, pj->id, output + 1, len - 1);
	} else if (json_string_value(json_object_get(o, "code"))) {
		server_reply_error(app->srv, pj->serial, pj->id, json_string_value(json_object_get(o, "code")),
				   json_string_value(json_object_get(o, "message")));
	} else {
		if (job_lost(j))
			snprintf(msg, sizeof msg, "plan: the planner's process was lost (the job helper died; it is "
				 "restarted): retry");
		else if (job_timed_out(j))
			snprintf(msg, sizeof msg, "plan: not planned within %.0f s, the daemon's bound: use fewer points "
				 "or plan it offline (acqctl plan FILE without the daemon)", app->conf->d.plan_deadline_s);
		else if (status == 128 + SIGXCPU)
			snprintf(msg, sizeof msg, "plan: not planned within %d s of CPU, the daemon's bound: use fewer "
				 "points or plan it offline (acqctl plan FILE without the daemon)", app->conf->d.plan_cpu_s);
		else if (job_output_truncated(j))
			snprintf(msg, sizeof msg, "plan: the reply is longer than %zu bytes: ask without points=true or plan "
				 "it offline (acqctl plan FILE without the daemon)",
				 m->points ? (size_t)PROTO_MAX_REPLY : (size_t)JOB_FORK_OUTPUT_MAX);
		else
			snprintf(msg, sizeof msg, "plan: the planner failed (status %d; memory is bounded to %zu MiB)", status,
				 PLAN_MEM_BYTES >> 20);
		log_msg(LOG_NOTICE, "%s", msg);
		server_reply_error(app->srv, pj->serial, pj->id, job_lost(j) ? PROTO_E_UNAVAILABLE : PROTO_E_RANGE, msg);
	}
	json_decref(o);
	plan_job_free(pj);
}

void cmd_plan_handle(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	if (plan_children >= PLAN_CHILDREN) {
		acq_errf(&err, ACQ_E_UNSUPPORTED, "plan: %d plans are being computed already; retry later", plan_children);
		return server_reply_error(app->srv, peer->serial, req->id, PROTO_E_UNAVAILABLE, err.msg);
	}
	const char *text = json_string_value(json_object_get(req->root, "plan"));
	const char *path = app->conf->path ? app->conf->path : "";
	if (!text)
		text = ""; /* the child's parse says what is missing */
	struct plan_msg m = { .g = app->conf->bench, .points = json_is_true(json_object_get(req->root, "points")) };
	sweep_plan_timing(app->sweep, &m.tm);
	sweep_plan_prior_of(app->sweep, "", 0, &m.tm); /* the host's figure; the sample's prior if the plan asks */
	struct plan_job *pj = calloc(1, sizeof *pj);
	size_t len = 0;
	char *msg = pj ? job_msg_pack(&m, sizeof m, path, text, &len) : NULL;
	if (!msg) {
		free(pj);
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		return cmd_reply_err(app, peer, req->id, &err);
	}
	*pj = (struct plan_job){ .app = app, .serial = peer->serial, .id = json_incref(req->id), .msg = msg,
				 .msg_len = len };
	if (plan_submit(pj, &err)) {
		plan_job_free(pj);
		return cmd_reply_err(app, peer, req->id, &err);
	}
}
