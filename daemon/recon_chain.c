/* recon_chain: the completion chain of a sweep — its calibrated samples exported as CSV into the state
 * directory (store_export_csv_grid: the angles measured at commit, as every reader) with the reference's noise
 * (recon_refnoise.c), then the reconstruction stages (brdf-recon fit, merl, dhr --plot, render) one after the
 * other in child processes (job.h), each run and output recorded in the store (recon_runs), every step an event. */
#include "daemon/recon_chain.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/recon_refnoise.h"
#include "daemon/store.h"

enum { RC_FIT, RC_MERL, RC_DHR, RC_RENDER, RC__COUNT };

struct recon_chain {
	const struct sweep_env *env; /* the sweep's (its conf follows reloads) */
	int64_t id;                  /* the sweep being reconstructed */
	struct job *job;
	int rstage;
	int64_t run_id;
	char outdir[4096], csv[4096], prog[4096];
	char refn[4096];             /* reference-noise.csv for dhr --ref-noise; "" without a stored reference */
	char files[RC__COUNT][4096];
	int recon_failed;
	bool dhr_noplot;             /* dhr --plot failed: run dhr once more without the plot */
};

static const char *const rc_names[RC__COUNT] = { "fit", "merl", "dhr", "render" };
static const char *const rc_kinds[RC__COUNT] = { "model", "merl", "dhr", "preview" };

struct recon_chain *recon_chain_new(const struct sweep_env *env)
{
	struct recon_chain *ch = calloc(1, sizeof *ch);
	if (ch)
		ch->env = env;
	return ch;
}

void recon_chain_free(struct recon_chain *ch)
{
	if (!ch)
		return;
	if (ch->job) /* the body's job_finish() kills it without calling back */
		store_recon_end(ch->env->store, ch->run_id, "cancelled", 128 + 15, "daemon stopping", ch->env->wallclock(),
				NULL);
	free(ch);
}

bool recon_chain_busy(const struct recon_chain *ch)
{
	return ch->job != NULL;
}

static void chain_emit(struct recon_chain *ch, const char *name, json_t *data)
{
	if (ch->env->emit)
		ch->env->emit(ch->env->emit_ctx, name, data);
	else
		json_decref(data);
}

int recon_find_program(const char *prog, char *out, size_t cap)
{
	if (strchr(prog, '/')) {
		snprintf(out, cap, "%s", prog);
		return access(out, X_OK);
	}
	char self[4096];
	ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
	if (n > 0) {
		self[n] = 0;
		char *slash = strrchr(self, '/');
		if (slash) {
			*slash = 0;
			snprintf(out, cap, "%s/%s", self, prog);
			if (!access(out, X_OK))
				return 0;
		}
	}
	const char *path = getenv("PATH");
	char buf[4096];
	snprintf(buf, sizeof buf, "%s", path ? path : "/usr/bin:/bin");
	for (char *save = NULL, *dir = strtok_r(buf, ":", &save); dir; dir = strtok_r(NULL, ":", &save)) {
		snprintf(out, cap, "%s/%s", dir, prog);
		if (!access(out, X_OK))
			return 0;
	}
	return -1;
}

static void recon_next(struct recon_chain *ch);

static void recon_event(struct recon_chain *ch, const char *kind, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void recon_event(struct recon_chain *ch, const char *kind, const char *fmt, ...)
{
	char msg[1024];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	store_event(ch->env->store, ch->id, kind, "recon", msg, ch->env->wallclock(), NULL);
	log_msg(LOG_NOTICE, "sweep %lld: %s", (long long)ch->id, msg);
	chain_emit(ch, "recon", json_pack("{s:I,s:s,s:s}", "sweep", (json_int_t)ch->id, "state", kind, "message", msg));
}

static const char *relpath(const struct recon_chain *ch, const char *path)
{
	size_t n = strlen(ch->env->conf->d.state_dir);
	if (!strncmp(path, ch->env->conf->d.state_dir, n) && path[n] == '/')
		return path + n + 1;
	return path;
}

static void recon_stage_done(struct job *j, int status, const char *output, size_t len, void *arg)
{
	(void)j;
	(void)len;
	struct recon_chain *ch = arg;
	ch->job = NULL;
	int st = ch->rstage;
	if (status == 0) {
		store_recon_output(ch->env->store, ch->run_id, rc_kinds[st], relpath(ch, ch->files[st]), ch->env->wallclock(),
				   NULL);
		if (st == RC_DHR) {
			char png[4200];
			snprintf(png, sizeof png, "%s/dhr.png", ch->outdir);
			if (!access(png, R_OK))
				store_recon_output(ch->env->store, ch->run_id, "dhr", relpath(ch, png), ch->env->wallclock(), NULL);
		}
	} else {
		/* Keep the tail of the output in the event: the run record keeps the whole. */
		size_t n = strlen(output);
		const char *tail = n > 300 ? output + n - 300 : output;
		recon_event(ch, "info", "brdf-recon %s failed (status %d): %s", rc_names[st], status, tail);
		if (st == RC_DHR && !ch->dhr_noplot) { /* perhaps only the plot is missing: the table alone */
			ch->dhr_noplot = true;
			recon_next(ch);
			return;
		}
		ch->recon_failed++;
		if (st == RC_FIT) { /* nothing else can run without a model */
			store_recon_end(ch->env->store, ch->run_id, "failed", status, output, ch->env->wallclock(), NULL);
			recon_event(ch, "info", "no reconstruction: the fit failed; the calibrated samples are in %s",
				    ch->csv);
			return;
		}
	}
	ch->rstage++;
	recon_next(ch);
}

static void recon_next(struct recon_chain *ch)
{
	struct acq_err err = { 0 };
	char threads[16];
	snprintf(threads, sizeof threads, "%d", ch->env->conf->recon.threads > 0 ? ch->env->conf->recon.threads : 1);
	while (ch->rstage < RC__COUNT) {
		char *argv[24];
		int argc = 0;
		char dhrpng[4200], cmd[16];
		snprintf(cmd, sizeof cmd, "%s", rc_names[ch->rstage]);
		argv[argc++] = ch->prog;
		argv[argc++] = cmd;
		switch (ch->rstage) {
		case RC_FIT:
			argv[argc++] = ch->csv;
			argv[argc++] = "-o";
			argv[argc++] = ch->files[RC_FIT];
			break;
		case RC_MERL:
		case RC_RENDER:
			argv[argc++] = ch->files[RC_FIT];
			argv[argc++] = "-o";
			argv[argc++] = ch->files[ch->rstage];
			argv[argc++] = "--threads";
			argv[argc++] = threads;
			break;
		case RC_DHR:
			snprintf(dhrpng, sizeof dhrpng, "%s/dhr.png", ch->outdir);
			argv[argc++] = ch->files[RC_FIT];
			argv[argc++] = "-o";
			argv[argc++] = ch->files[RC_DHR];
			if (!ch->dhr_noplot) {
				argv[argc++] = "--plot";
				argv[argc++] = dhrpng;
			}
			if (ch->refn[0]) {
				argv[argc++] = "--ref-noise";
				argv[argc++] = ch->refn;
			}
			break;
		}
		argv[argc] = NULL;
		double timeout = ch->env->conf->recon.timeout_s * loop_rate(ch->env->loop); /* real s on the loop's clock */
		if (job_start(argv, ch->outdir, timeout, recon_stage_done, ch, &ch->job, &err) == 0) {
			recon_event(ch, "info", "brdf-recon %s started (pid %d)", rc_names[ch->rstage], (int)job_pid(ch->job));
			return;
		}
		recon_event(ch, "info", "brdf-recon %s could not start: %s", rc_names[ch->rstage], err.msg);
		ch->recon_failed++;
		if (ch->rstage == RC_FIT) {
			store_recon_end(ch->env->store, ch->run_id, "failed", 127, err.msg, ch->env->wallclock(), NULL);
			return;
		}
		ch->rstage++;
	}
	const char *state = ch->recon_failed ? "failed" : "succeeded";
	char summary[8192] = "";
	size_t n = 0;
	for (int i = 0; i < RC__COUNT; i++) {
		bool ok = !access(ch->files[i], R_OK);
		n += (size_t)snprintf(summary + n, sizeof summary - n, "%s%s %s", i ? "; " : "", rc_kinds[i],
				      ok ? ch->files[i] : "(not produced)");
		if (n >= sizeof summary)
			break;
	}
	store_recon_end(ch->env->store, ch->run_id, state, ch->recon_failed, summary, ch->env->wallclock(), NULL);
	recon_event(ch, ch->recon_failed ? "info" : "complete", "reconstruction %s (%d of %d steps failed): %s", state,
		    ch->recon_failed, RC__COUNT, summary);
}

int recon_chain_run(struct recon_chain *ch, int64_t id, bool automatic, int64_t *run_id, struct acq_err *err)
{
	const struct conf *c = ch->env->conf;
	if (run_id)
		*run_id = 0;
	if (ch->job)
		return acq_errf(err, ACQ_E_STATE, "a reconstruction is still running");
	ch->id = id;
	snprintf(ch->outdir, sizeof ch->outdir, "%s/sweep-%lld", c->recon.output_dir, (long long)id);
	mkdir(c->recon.output_dir, 0750);
	mkdir(ch->outdir, 0750);
	snprintf(ch->csv, sizeof ch->csv, "%s/samples.csv", ch->outdir);
	int rows = 0;
	struct store_grid grid; /* the row the export read, on which the reference noise is binned */
	if (store_export_csv_grid(ch->env->store, id, ch->csv, &rows, &grid, err)) {
		recon_event(ch, "info", "exporting the calibrated samples failed: %s; no reconstruction ran", err->msg);
		return -1;
	}
	snprintf(ch->refn, sizeof ch->refn, "%s/reference-noise.csv", ch->outdir);
	unlink(ch->refn); /* a rerun must not use the previous run's file */
	struct acq_err rerr = { 0 };
	struct timespec t0, t1;
	clock_gettime(CLOCK_MONOTONIC, &t0);
	int rn = recon_refnoise_write(ch->env, ch->id, &grid, ch->refn, &rerr);
	clock_gettime(CLOCK_MONOTONIC, &t1);
	free(grid.nm);
	double ms = (double)(t1.tv_sec - t0.tv_sec) * 1e3 + (double)(t1.tv_nsec - t0.tv_nsec) * 1e-6;
	/* one event for both (the kill tests count the chain's events) */
	if (rn == 1)
		recon_event(ch, "info", "%d calibrated samples exported to %s; the white reference's own noise (one "
			    "spectrum, common to all samples) to %s for dhr --ref-noise (%.1f ms)", rows, ch->csv, ch->refn, ms);
	else
		recon_event(ch, "info", "%d calibrated samples exported to %s; no reference noise for the DHR budget (%s): "
			    "dhr runs without --ref-noise", rows, ch->csv,
			    rn == 0 ? "no white reference or direct beam stored for this sweep" : rerr.msg);
	if (rn != 1)
		ch->refn[0] = 0;
	if (automatic && !c->sweep.auto_recon) {
		recon_event(ch, "info", "sweep.auto_recon is off: no reconstruction ran; the samples are in %s", ch->csv);
		return 0;
	}
	if (recon_find_program(c->recon.program, ch->prog, sizeof ch->prog)) {
		recon_event(ch, "info", "no reconstruction ran: '%s' not found (brdf-recon not installed?); the calibrated "
			    "samples are recorded in the database and in %s", c->recon.program, ch->csv);
		return acq_errf(err, ACQ_E_UNSUPPORTED, "reconstruction program '%s' not found", c->recon.program);
	}
	snprintf(ch->files[RC_FIT], sizeof ch->files[0], "%s/model.brdf", ch->outdir);
	snprintf(ch->files[RC_MERL], sizeof ch->files[0], "%s/merl.binary", ch->outdir);
	snprintf(ch->files[RC_DHR], sizeof ch->files[0], "%s/dhr.csv", ch->outdir);
	snprintf(ch->files[RC_RENDER], sizeof ch->files[0], "%s/preview.png", ch->outdir);
	for (int i = 0; i < RC__COUNT; i++)
		unlink(ch->files[i]); /* a rerun must not report the previous run's files */
	char args[8192];
	snprintf(args, sizeof args, "[\"fit %s\", \"merl\", \"dhr --plot%s%s\", \"render\"]", ch->csv,
		 ch->refn[0] ? " --ref-noise " : "", ch->refn);
	if (store_recon_begin(ch->env->store, id, ch->prog, args, ch->env->wallclock(), &ch->run_id, err)) {
		recon_event(ch, "info", "recording the reconstruction failed: %s; none ran", err->msg);
		return -1;
	}
	if (run_id)
		*run_id = ch->run_id;
	if (ch->refn[0])
		store_recon_output(ch->env->store, ch->run_id, "other", relpath(ch, ch->refn), ch->env->wallclock(), NULL);
	ch->rstage = RC_FIT;
	ch->recon_failed = 0;
	ch->dhr_noplot = false;
	recon_next(ch);
	return 0;
}
