/* plan_worker: a sweep's plan made in a child of the job helper and sent back whole (plan_worker.h). */
#include "daemon/plan_worker.h"

#include <errno.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "daemon/job.h"
#include "daemon/plan/plan.h"

/* The child's reply: this header, then on success the struct plan_result (its pointers meaningless) and its
 * three arrays; on failure the error message. The same program on both ends (the helper is the daemon run again),
 * so raw structs are fine. */
#define PW_MAGIC "acqplan1"
#define PW_MAX_ITEMS ((uint64_t)1 << 24)  /* far above the planner's 50,000 points: a sanity bound */
#define PW_OUT_MAX ((size_t)256 << 20)    /* reply bound: 50,000 points are about 20 MB */

struct pw_header {
	char magic[8];
	uint32_t ok, code;                    /* ok 0: code is the acq_err code, the message follows */
	uint64_t n_req, n_steps, n_wps;
	uint64_t size_res, size_req, size_step, size_wp;
};

struct plan_worker {
	struct job *job;
	double real_deadline_s;
	plan_worker_done_fn done;
	void *ctx;
	bool aborted;
};

/* The child's request: this, then the plan's name and text (job_msg_pack). */
struct pw_msg {
	struct bench_geom g;
	struct plan_timing tm;
};

static int write_all(int fd, const void *buf, size_t n)
{
	const char *p = buf;
	while (n) {
		ssize_t w = write(fd, p, n);
		if (w < 0 && errno == EINTR)
			continue;
		if (w <= 0)
			return -1;
		p += w;
		n -= (size_t)w;
	}
	return 0;
}

static struct pw_header header(void)
{
	struct pw_header h = { .size_res = sizeof(struct plan_result), .size_req = sizeof(struct plan_req),
			       .size_step = sizeof(struct plan_step), .size_wp = sizeof(struct plan_wp) };
	memcpy(h.magic, PW_MAGIC, sizeof h.magic);
	return h;
}

int plan_worker_encode(const struct plan_result *r, int fd)
{
	struct pw_header h = header();
	h.ok = 1;
	h.n_req = r->n_req;
	h.n_steps = r->n_steps;
	h.n_wps = r->n_wps;
	struct plan_result flat = *r;
	flat.req = NULL;
	flat.steps = NULL;
	flat.wps = NULL;
	return write_all(fd, &h, sizeof h) || write_all(fd, &flat, sizeof flat) ||
			       write_all(fd, r->req, r->n_req * sizeof *r->req) ||
			       write_all(fd, r->steps, r->n_steps * sizeof *r->steps) ||
			       write_all(fd, r->wps, r->n_wps * sizeof *r->wps)
		       ? -1
		       : 0;
}

static int encode_error(const struct acq_err *err, int fd)
{
	struct pw_header h = header();
	h.code = (uint32_t)err->code;
	return write_all(fd, &h, sizeof h) || write_all(fd, err->msg, strlen(err->msg)) ? -1 : 0;
}

int plan_worker_decode(const char *buf, size_t len, struct plan_result **out, struct acq_err *err)
{
	*out = NULL;
	struct pw_header h, want = header();
	if (len < sizeof h)
		return acq_errf(err, ACQ_E_PROTO, "plan worker: a reply of %zu bytes, shorter than its header", len);
	memcpy(&h, buf, sizeof h);
	if (memcmp(h.magic, want.magic, sizeof h.magic) || h.size_res != want.size_res || h.size_req != want.size_req ||
	    h.size_step != want.size_step || h.size_wp != want.size_wp)
		return acq_errf(err, ACQ_E_PROTO, "plan worker: not a plan reply of this program");
	buf += sizeof h;
	len -= sizeof h;
	if (!h.ok) {
		char msg[sizeof err->msg];
		size_t n = len < sizeof msg - 1 ? len : sizeof msg - 1;
		memcpy(msg, buf, n);
		msg[n] = '\0';
		return acq_errf(err, h.code ? (enum acq_errcode)h.code : ACQ_E_INVAL, "%s", msg);
	}
	if (h.n_req > PW_MAX_ITEMS || h.n_steps > PW_MAX_ITEMS || h.n_wps > PW_MAX_ITEMS ||
	    len != sizeof(struct plan_result) + h.n_req * h.size_req + h.n_steps * h.size_step + h.n_wps * h.size_wp)
		return acq_errf(err, ACQ_E_PROTO, "plan worker: a reply of %zu bytes does not hold %llu points, %llu steps "
				"and %llu waypoints", len, (unsigned long long)h.n_req, (unsigned long long)h.n_steps,
				(unsigned long long)h.n_wps);
	struct plan_result *r = calloc(1, sizeof *r);
	if (!r)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	memcpy(r, buf, sizeof *r);
	buf += sizeof *r;
	r->n_req = (size_t)h.n_req;
	r->n_steps = (size_t)h.n_steps;
	r->n_wps = (size_t)h.n_wps;
	r->req = malloc(r->n_req * sizeof *r->req + 1);
	r->steps = malloc(r->n_steps * sizeof *r->steps + 1);
	r->wps = malloc(r->n_wps * sizeof *r->wps + 1);
	if (!r->req || !r->steps || !r->wps) {
		plan_result_free(r);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	memcpy(r->req, buf, r->n_req * sizeof *r->req);
	buf += r->n_req * sizeof *r->req;
	memcpy(r->steps, buf, r->n_steps * sizeof *r->steps);
	buf += r->n_steps * sizeof *r->steps;
	memcpy(r->wps, buf, r->n_wps * sizeof *r->wps);
	for (size_t i = 0; i < r->n_steps; i++) {
		const struct plan_step *s = &r->steps[i];
		if (s->req >= r->n_req || s->first_wp > r->n_wps || s->n_wp > r->n_wps - s->first_wp) {
			plan_result_free(r);
			return acq_errf(err, ACQ_E_PROTO, "plan worker: step %zu refers outside the plan", i);
		}
	}
	*out = r;
	return 0;
}

/* In the child: parse, plan, reply. */
static int child(const char *payload, size_t len, int fd)
{
	struct pw_msg m;
	char *name = NULL;
	const char *text = NULL;
	if (job_msg_unpack(payload, len, &m, sizeof m, &name, &text))
		return 5;
	struct acq_err err = { 0 };
	struct plan_spec *spec = NULL;
	struct plan_result *r = NULL;
	if (plan_load_string(name, text, &spec, &err) || plan_make(spec, &m.g, &r, &err))
		return encode_error(&err, fd) ? 4 : 0;
	/* a first auto sweep measures its survey first (plan_survey_apply: the prior in m.tm decides) */
	if (plan_survey_apply(spec, &m.g, &m.tm, r, &err))
		return encode_error(&err, fd) ? 4 : 0;
	plan_time_apply(spec, &m.g, &m.tm, r);
	return plan_worker_encode(r, fd) ? 4 : 0;
}

const struct job_kind plan_worker_kind = { "sweep-plan", child };

static void on_done(struct job *j, int status, const char *output, size_t len, void *arg)
{
	struct plan_worker *w = arg;
	struct acq_err err = { 0 };
	struct plan_result *r = NULL;
	int rc = -1;
	if (w->aborted)
		acq_errf(&err, ACQ_E_STATE, "aborted while planning");
	else if (job_lost(j))
		acq_errf(&err, ACQ_E_UNSUPPORTED, "the planner's process was lost (the job helper died; it is restarted): "
			 "retry");
	else if (job_timed_out(j))
		acq_errf(&err, ACQ_E_RANGE, "not planned within %.0f s, the daemon's bound: use fewer points (acqctl plan "
			 "FILE without the daemon shows the planner's time)", w->real_deadline_s);
	else if (job_output_truncated(j))
		acq_errf(&err, ACQ_E_RANGE, "the plan is larger than %zu MiB", PW_OUT_MAX >> 20);
	else if (status != 0)
		acq_errf(&err, ACQ_E_RANGE, "the planner failed (status %d: out of its bounded memory?)", status);
	else
		rc = plan_worker_decode(output, len, &r, &err);
	plan_worker_done_fn done = w->done;
	void *ctx = w->ctx;
	free(w);
	done(ctx, rc, rc ? &err : NULL, r);
}

int plan_worker_start(const char *name, const char *text, const struct bench_geom *g, const struct plan_timing *tm,
		      size_t mem_bytes, double deadline_s, double real_deadline_s, plan_worker_done_fn done, void *ctx,
		      struct plan_worker **out, struct acq_err *err)
{
	if (out)
		*out = NULL;
	struct pw_msg m = { .g = *g, .tm = *tm };
	size_t len = 0;
	struct plan_worker *w = calloc(1, sizeof *w);
	char *msg = w ? job_msg_pack(&m, sizeof m, name, text, &len) : NULL;
	if (!msg) {
		free(w);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	*w = (struct plan_worker){ .real_deadline_s = real_deadline_s, .done = done, .ctx = ctx };
	int rc = job_fork_msg(&plan_worker_kind, msg, len, mem_bytes, PW_OUT_MAX, deadline_s, on_done, w, &w->job, err);
	free(msg);
	if (rc) {
		free(w);
		return -1;
	}
	if (out)
		*out = w;
	return 0;
}

void plan_worker_abort(struct plan_worker *w)
{
	if (!w)
		return;
	w->aborted = true;
	job_kill(w->job);
}
