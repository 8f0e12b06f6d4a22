/* recon_select: an adaptive sweep's decision between batches (see recon_select.h) — samples exported and candidates
 * (both written by one child of the job helper), brdf-recon fit (warm when possible) and brdf-recon select in child processes, one
 * after the other; the loop is only called back. */
#include "daemon/recon_select.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "daemon/executor.h"
#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/recon_chain.h"
#include "daemon/store.h"

enum { RS_INPUTS, RS_PROBE, RS_FIT, RS_SELECT };
/* brdf-recon select --value-channels: the DHR target's value (and the σ parts the selection holds) on this many
 * evenly spread channels; all when the model has no more (the simulated bench's 651 wavelengths: 3.9 → 0.6 s CPU
 * per decision for three incidences, value within -5.5 %..+0.8 % of all channels', select's help) */
#define RSEL_VALUE_CHANNELS "64"

struct rsel {
	const struct sweep_env *env;
	struct job *job;
	int stage;
	int warm_ok;                    /* brdf-recon fit has --warm: -1 not known yet, 0, 1 */
	rsel_done_fn done;
	void *ctx;
	const struct plan_spec *spec;
	char target[256], batch[16], prev[4096], prog[4096], route[PLAN_ROUTE_SPEC_LEN];
	char samples[4200], cand[4200], out[4200];
	struct rsel_res res;
	double t0;
};

struct rsel *rsel_new(const struct sweep_env *env)
{
	struct rsel *r = calloc(1, sizeof *r);
	if (r) {
		r->env = env;
		r->warm_ok = -1;
	}
	return r;
}

void rsel_free(struct rsel *r)
{
	free(r);
}

bool rsel_busy(const struct rsel *r)
{
	return r->job != NULL || r->done != NULL;
}

static void finish(struct rsel *r, bool ok, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void finish(struct rsel *r, bool ok, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(r->res.msg, sizeof r->res.msg, fmt, ap);
	va_end(ap);
	r->res.ok = ok;
	rsel_done_fn done = r->done;
	void *ctx = r->ctx;
	r->done = NULL;
	r->spec = NULL;
	if (done)
		done(ctx, &r->res);
	json_decref(r->res.out);
	r->res.out = NULL;
}

/* The tail of a child's output for a message (its whole output is in the log). */
static const char *tail(const char *s)
{
	size_t n = strlen(s);
	return n > 400 ? s + n - 400 : s;
}

static void next(struct rsel *r);

/* The inputs child's request (job_fork_msg): this, then the n_done positions measured or planned so far, then the
 * plan's text (text_len bytes; the payload's NUL after it). */
struct inputs_msg {
	int64_t sweep_id;
	char database[4096], samples[4200], cand[4200];
	struct bench_geom g;
	struct plan_timing timing;
	struct plan_pos from;
	uint64_t n_done, text_len;
};

/* In a child of the job helper (a process that never held the daemon's database: SQLite's state of the daemon's
 * connection is not inherited, which a read-only connection opened in a fork of the daemon trips over: "locking
 * protocol"): the reachable candidates from the arms' position for the plan's text written to m.cand, the sweep's
 * samples so far exported to m.samples through a read-only connection; prints the candidates' count. */
static int inputs_child(const char *payload, size_t len, int fd)
{
	struct inputs_msg m;
	if (len < sizeof m)
		return 5;
	memcpy(&m, payload, sizeof m);
	if (m.n_done > (len - sizeof m) / sizeof(struct plan_pos) ||
	    m.text_len != len - sizeof m - m.n_done * sizeof(struct plan_pos))
		return 5;
	const char *text = payload + sizeof m + m.n_done * sizeof(struct plan_pos); /* NUL-terminated (job_msg_fn) */
	if (strlen(text) != m.text_len)
		return 5;
	struct plan_pos *done = malloc(m.n_done * sizeof *done + 1);
	if (!done)
		return 3;
	memcpy(done, payload + sizeof m, m.n_done * sizeof *done);
	struct acq_err err = { 0 };
	struct store *st = NULL;
	struct plan_spec *spec = NULL;
	struct plan_cand *c = NULL;
	size_t n = 0;
	int rows = 0, rc = 1;
	if (plan_load_string("plan", text, &spec, &err) || !spec->adaptive) {
		if (spec && !spec->adaptive)
			acq_errf(&err, ACQ_E_INVAL, "sweep %lld's plan is not adaptive", (long long)m.sweep_id);
		goto out;
	}
	if (plan_adaptive_candidates(spec, &m.g, &m.timing, &m.from, done, (size_t)m.n_done, &c, &n, &err) ||
	    rsel_write_candidates(m.cand, &m.g, c, n, &err))
		goto out;
	if (store_open_reader(m.database, &st, &err))
		goto out;
	if (store_export_csv_file(st, m.sweep_id, m.samples, &rows, &err)) {
		char why[sizeof err.msg];
		snprintf(why, sizeof why, "%s", err.msg);
		acq_errf(&err, err.code, "exporting the samples: %s", why);
		goto out;
	}
	rc = dprintf(fd, "%zu\n", n) < 0;
out:
	if (rc)
		dprintf(fd, "%s\n", err.msg);
	free(c);
	plan_spec_free(spec);
	store_close(st);
	free(done);
	return rc;
}

const struct job_kind rsel_inputs_kind = { "select-inputs", inputs_child };

static void stage_done(struct job *j, int status, const char *output, size_t len, void *arg)
{
	struct rsel *r = arg;
	r->job = NULL;
	double dt = loop_now(r->env->loop) - r->t0;
	switch (r->stage) {
	case RS_INPUTS:
		if (status != 0)
			return finish(r, false, "the samples and candidates child failed (status %d%s): %s", status,
				      job_lost(j) ? ", its job helper lost" : "", tail(output));
		r->res.n_candidates = (size_t)strtoull(output, NULL, 10);
		r->stage = RS_PROBE;
		break;
	case RS_PROBE:
		r->warm_ok = status == 0 && strstr(output, "--warm") != NULL;
		log_msg(LOG_NOTICE, "%s fit %s --warm: refits between batches are %s (status %d, %zu bytes of help)",
			r->prog, r->warm_ok ? "has" : "has no", r->warm_ok ? "warm-started" : "cold", status, len);
		r->stage = RS_FIT;
		break;
	case RS_FIT:
		r->res.fit_s = dt;
		if (status != 0)
			return finish(r, false, "brdf-recon fit failed (status %d): %s", status, tail(output));
		r->stage = RS_SELECT;
		break;
	case RS_SELECT: {
		r->res.select_s = dt;
		if (status != 0)
			return finish(r, false, "brdf-recon select failed (status %d): %s", status, tail(output));
		json_error_t je;
		json_t *o = json_load_file(r->out, 0, &je);
		json_t *t = o ? json_object_get(o, "target") : NULL;
		if (!o || !json_is_object(t) || !json_is_array(json_object_get(o, "picks")) ||
		    !json_is_number(json_object_get(t, "value"))) {
			json_decref(o);
			return finish(r, false, "brdf-recon select: %s: %s", r->out,
				      o ? "no target {value} or picks [] (see the select contract)" : je.text);
		}
		r->res.out = o;
		return finish(r, true, "selected");
	}
	}
	next(r);
}

int rsel_write_candidates(const char *path, const struct bench_geom *g, const struct plan_cand *c, size_t n,
			  struct acq_err *err)
{
	FILE *f = fopen(path, "w");
	if (!f)
		return acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(errno));
	fprintf(f, "id,theta_i,phi_i,theta_o,phi_o,cost_s,base_s,open_s,laser_deg,det_theta_deg,det_phi_deg,point_s,dark_s,"
		   "rungs,since,band_cos\n");
	for (size_t i = 0; i < n; i++) {
		double ti, pi, to, po;
		ex_pos_angles(g, &c[i].pos, &ti, &pi, &to, &po);
		fprintf(f, "%zu,%.9g,%.9g,%.9g,%.9g,%.6g,%.6g,%.6g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", c[i].id, ti, pi,
			to, po, c[i].cost_s, c[i].base_s, c[i].open_s, c[i].pos.laser_theta, c[i].pos.det_theta,
			c[i].pos.det_phi, c[i].point_s, c[i].dark_s, c[i].rungs, c[i].since, c[i].band_cos);
	}
	bool bad = ferror(f) != 0;
	if (fclose(f) || bad)
		return acq_errf(err, ACQ_E_IO, "%s: write failed", path);
	return 0;
}

static void next(struct rsel *r)
{
	struct acq_err err = { 0 };
	double timeout = r->env->conf->recon.timeout_s * loop_rate(r->env->loop);
	char *argv[20];
	int argc = 0;
	if (r->stage == RS_PROBE && r->warm_ok >= 0)
		r->stage = RS_FIT;
	if (r->stage == RS_FIT)
		r->res.warm = r->warm_ok == 1 && r->prev[0] && access(r->prev, R_OK) == 0;
	argv[argc++] = r->prog;
	switch (r->stage) {
	case RS_PROBE:
		argv[argc++] = "fit";
		argv[argc++] = "--help";
		break;
	case RS_FIT:
		argv[argc++] = "fit";
		argv[argc++] = r->samples;
		argv[argc++] = "-o";
		argv[argc++] = r->res.model;
		if (r->res.warm) {
			argv[argc++] = "--warm";
			argv[argc++] = r->prev;
		}
		break;
	case RS_SELECT:
		argv[argc++] = "select";
		argv[argc++] = r->res.model;
		argv[argc++] = "--candidates";
		argv[argc++] = r->cand;
		argv[argc++] = "--route"; /* each pick charged its increment to the batch's route from the arms */
		argv[argc++] = r->route;
		argv[argc++] = "--target";
		argv[argc++] = r->target;
		argv[argc++] = "--batch";
		argv[argc++] = r->batch;
		argv[argc++] = "--value-channels"; /* a DHR target's value on 64 channels: 6.6x cheaper at 651 (cmd_select) */
		argv[argc++] = RSEL_VALUE_CHANNELS;
		argv[argc++] = "-o";
		argv[argc++] = r->out;
		break;
	}
	argv[argc] = NULL;
	r->t0 = loop_now(r->env->loop);
	if (r->stage == RS_PROBE)
		timeout = 60 * loop_rate(r->env->loop);
	if (job_start(argv, r->res.dir, timeout, stage_done, r, &r->job, &err))
		finish(r, false, "brdf-recon %s could not start: %s", argv[1], err.msg);
}

static int mkdirs(const char *path)
{
	char p[4096];
	snprintf(p, sizeof p, "%s", path);
	for (char *s = p + 1; *s; s++) {
		if (*s != '/')
			continue;
		*s = '\0';
		if (mkdir(p, 0750) && errno != EEXIST)
			return -1;
		*s = '/';
	}
	return mkdir(p, 0750) && errno != EEXIST ? -1 : 0;
}

int rsel_start(struct rsel *r, const struct rsel_req *q, rsel_done_fn done, void *ctx, struct acq_err *err)
{
	const struct conf *c = r->env->conf;
	if (rsel_busy(r))
		return acq_errf(err, ACQ_E_STATE, "a batch is being chosen already");
	if (!q->spec || !q->spec->adaptive || !q->plan_text)
		return acq_errf(err, ACQ_E_INVAL, "not an adaptive plan");
	if (recon_find_program(c->recon.program, r->prog, sizeof r->prog))
		return acq_errf(err, ACQ_E_UNSUPPORTED, "reconstruction program '%s' not found", c->recon.program);
	memset(&r->res, 0, sizeof r->res);
	snprintf(r->res.dir, sizeof r->res.dir, "%s/sweep-%lld/batch-%d", c->recon.output_dir, (long long)q->sweep_id,
		 q->batch);
	if (mkdirs(r->res.dir))
		return acq_errf(err, ACQ_E_IO, "%s: %s", r->res.dir, strerror(errno));
	snprintf(r->samples, sizeof r->samples, "%s/samples.csv", r->res.dir);
	snprintf(r->cand, sizeof r->cand, "%s/candidates.csv", r->res.dir);
	snprintf(r->out, sizeof r->out, "%s/select.json", r->res.dir);
	snprintf(r->res.model, sizeof r->res.model, "%s/model.brdf", r->res.dir);
	snprintf(r->prev, sizeof r->prev, "%s", q->prev_model ? q->prev_model : "");
	snprintf(r->batch, sizeof r->batch, "%zu", q->batch_size);
	plan_adaptive_target_spec(q->spec->adaptive, r->target, sizeof r->target);
	plan_adaptive_route_spec(q->spec, &c->bench, &q->timing, &q->from, r->route, sizeof r->route);
	unlink(r->out); /* a decision made again must not read the previous answer */
	r->spec = q->spec;
	r->stage = RS_INPUTS;
	r->t0 = loop_now(r->env->loop);
	size_t text_len = strlen(q->plan_text), len = sizeof(struct inputs_msg) + q->n_done * sizeof *q->done + text_len;
	struct inputs_msg *m = calloc(1, len);
	if (!m)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	*m = (struct inputs_msg){ .sweep_id = q->sweep_id, .g = c->bench, .timing = q->timing, .from = q->from,
				  .n_done = q->n_done, .text_len = text_len };
	snprintf(m->database, sizeof m->database, "%s", c->d.database);
	snprintf(m->samples, sizeof m->samples, "%s", r->samples);
	snprintf(m->cand, sizeof m->cand, "%s", r->cand);
	if (q->n_done)
		memcpy(m + 1, q->done, q->n_done * sizeof *q->done);
	memcpy((char *)(m + 1) + q->n_done * sizeof *q->done, q->plan_text, text_len);
	double timeout = 60 * loop_rate(r->env->loop); /* real seconds on the loop's clock */
	int rc = job_fork_msg(&rsel_inputs_kind, m, len, 0, JOB_FORK_OUTPUT_MAX, timeout, stage_done, r, &r->job,
			      err);
	free(m);
	if (rc)
		return -1;
	r->done = done;
	r->ctx = ctx;
	return 0;
}
