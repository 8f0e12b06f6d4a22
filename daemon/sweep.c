/* sweep: the daemon's sweep executor behind sweep.h — plans, stores and runs a sweep with daemon/executor.c
 * on the loop over the real device handles, resumes interrupted sweeps, and on completion exports the
 * calibrated samples as CSV and runs the reconstruction chain (brdf-recon fit, merl, dhr --plot, render). */
#include "daemon/sweep.h"

#include <errno.h>
#include <math.h>
#include <sqlite3.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "daemon/devices.h"
#include "daemon/executor.h"
#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/plan.h"
#include "daemon/store.h"
#include "drivers/axis.h"
#include "drivers/laser.h"
#include "drivers/spectro.h"

enum { RC_FIT, RC_MERL, RC_DHR, RC_RENDER, RC__COUNT };

struct sweep {
	struct sweep_env env;
	struct ex_cfg cfg;
	struct ex *ex;
	struct plan_spec *spec;
	struct plan_result *plan;
	int64_t id;
	uint64_t timer;
	double started_wall;
	struct sweep_progress last;  /* kept after the executor is gone */
	char point_text[128];
	/* completion: export + reconstruction chain */
	int64_t done_id;
	uint64_t done_timer;
	struct job *job;
	int rstage;
	int64_t run_id;
	char outdir[4096], csv[4096], prog[4096];
	char files[RC__COUNT][4096];
	int recon_failed;
	bool dhr_noplot;             /* dhr --plot failed: run dhr once more without the plot */
};

static const char *const rc_names[RC__COUNT] = { "fit", "merl", "dhr", "render" };
static const char *const rc_kinds[RC__COUNT] = { "model", "merl", "dhr", "preview" };

/* ---- device operations over the daemon's handles -------------------------------------------------- */

static struct axis *ax_of(struct sweep *sw, int a, struct acq_err *err)
{
	struct axis *ax = devices_axis(sw->env.devices, (enum conf_dev)a);
	if (!ax)
		acq_errf(err, ACQ_E_DISCONNECTED, "%s unavailable", conf_dev_name((enum conf_dev)a));
	return ax;
}

static int o_move_begin(void *ctx, int a, double target, double now, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_move_begin(ax, target, now, err) : -1;
}

static int o_move_step(void *ctx, int a, double now, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_move_step(ax, now, err) : AXIS_MOVE_FAILED;
}

static double o_next_poll(void *ctx, int a)
{
	struct sweep *sw = ctx;
	struct axis *ax = devices_axis(sw->env.devices, (enum conf_dev)a);
	return ax ? axis_next_poll(ax) : loop_now(sw->env.loop);
}

static int o_stop(void *ctx, int a, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_stop(ax, err) : -1;
}

static int o_position(void *ctx, int a, double *deg, bool *homed, bool *alarm, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	struct axis_status st;
	if (!ax || axis_read_status(ax, &st, err))
		return -1;
	*deg = st.position_deg;
	*homed = st.homed;
	*alarm = st.alarm;
	return 0;
}

static int o_home_begin(void *ctx, int a, double now, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_home_begin(ax, now, err) : -1;
}

static int o_alarm_reset(void *ctx, int a, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_alarm_reset(ax, err) : -1;
}

static int o_laser_set(void *ctx, bool on, struct acq_err *err)
{
	struct sweep *sw = ctx;
	struct laser *l = devices_laser(sw->env.devices);
	if (!l)
		return on ? acq_errf(err, ACQ_E_DISCONNECTED, "laser unavailable") : 0; /* absent = dark */
	return laser_set_emission(l, on, err);
}

static int o_laser_power(void *ctx, double pct, struct acq_err *err)
{
	struct sweep *sw = ctx;
	struct laser *l = devices_laser(sw->env.devices);
	if (!l)
		return acq_errf(err, ACQ_E_DISCONNECTED, "laser unavailable");
	return laser_set_power(l, pct, err);
}

static int o_laser_state(void *ctx, bool *emission, bool *ready, struct acq_err *err)
{
	struct sweep *sw = ctx;
	struct laser *l = devices_laser(sw->env.devices);
	struct laser_status st;
	if (!l)
		return acq_errf(err, ACQ_E_DISCONNECTED, "laser unavailable");
	if (laser_status(l, &st, err))
		return -1;
	*emission = st.emission;
	*ready = st.interlock_ok && !st.fault;
	return 0;
}

/* The daemon's device manager reconnects on its own timer; here: is the device back and answering? */
static int o_reconnect(void *ctx, int dev, struct acq_err *err)
{
	struct sweep *sw = ctx;
	if (dev <= EX_DEV_DETECTOR_PHI) {
		bool homed, alarm;
		double d;
		return o_position(ctx, dev, &d, &homed, &alarm, err);
	}
	if (dev == EX_DEV_SPECTRO) {
		struct spectro *s = devices_spectro(sw->env.devices);
		return s && spectro_info(s) ? 0 : acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer unavailable");
	}
	bool e, r;
	return o_laser_state(ctx, &e, &r, err);
}

static int o_spectro_start(void *ctx, const struct spectro_meas *m, double now, struct acq_err *err)
{
	struct sweep *sw = ctx;
	struct spectro *s = devices_spectro(sw->env.devices);
	if (!s)
		return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer unavailable");
	return spectro_start(s, m, now, err);
}

static int o_spectro_fetch(void *ctx, struct spectro_frame *f, double now, struct acq_err *err)
{
	struct sweep *sw = ctx;
	struct spectro *s = devices_spectro(sw->env.devices);
	if (!s)
		return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer unavailable");
	return spectro_fetch(s, f, now, err);
}

static int o_spectro_stop(void *ctx, struct acq_err *err)
{
	struct sweep *sw = ctx;
	struct spectro *s = devices_spectro(sw->env.devices);
	return s ? spectro_stop(s, err) : 0;
}

static const struct spectro_info *o_spectro_info(void *ctx)
{
	struct sweep *sw = ctx;
	struct spectro *s = devices_spectro(sw->env.devices);
	return s ? spectro_info(s) : NULL;
}

static double o_wall(void *ctx)
{
	struct sweep *sw = ctx;
	return sw->env.wallclock();
}

/* A link-level failure hands the device back to the manager (close, reconnect on its timer); a device that
 * answered with an error (alarm, interlock) keeps its handle. */
static void o_lost(void *ctx, int dev, const struct acq_err *err)
{
	struct sweep *sw = ctx;
	int code = err ? err->code : ACQ_E_DEVICE;
	if (code == ACQ_E_TIMEOUT || code == ACQ_E_DISCONNECTED || code == ACQ_E_IO || code == ACQ_E_PROTO)
		if (dev != EX_DEV_SPECTRO || devices_spectro(sw->env.devices))
			devices_lost(sw->env.devices, (enum conf_dev)dev, err ? err->msg : "device error");
}

static void o_limits(void *ctx, int a, double *lo, double *hi)
{
	struct sweep *sw = ctx;
	const struct axis_cfg *c = a >= 0 && a < 3 ? sw->env.conf->axis[a] : NULL;
	if (c)
		axis_cfg_limits(c, lo, hi);
}

static const struct ex_ops dev_ops = {
	.move_begin = o_move_begin, .move_step = o_move_step, .next_poll = o_next_poll, .stop = o_stop,
	.position = o_position, .home_begin = o_home_begin, .alarm_reset = o_alarm_reset, .reconnect = o_reconnect,
	.laser_set = o_laser_set, .laser_power = o_laser_power, .laser_state = o_laser_state, .spectro_start = o_spectro_start,
	.spectro_fetch = o_spectro_fetch, .spectro_stop = o_spectro_stop, .spectro_info = o_spectro_info,
	.wall = o_wall, .lost = o_lost, .limits = o_limits,
};

/* ---- events --------------------------------------------------------------------------------------- */

static enum sweep_state map_state(enum ex_state s)
{
	switch (s) {
	case EX_RUNNING: return SWEEP_RUNNING;
	case EX_PAUSED: return SWEEP_PAUSED;
	case EX_SUSPENDED: return SWEEP_FAULTED;
	default: return SWEEP_IDLE;
	}
}

static void emit(struct sweep *sw, const char *name, json_t *data)
{
	if (sw->env.emit)
		sw->env.emit(sw->env.emit_ctx, name, data);
	else
		json_decref(data);
}

static void on_event(void *ctx, int64_t sweep_id, const char *kind, const char *device, const char *message)
{
	struct sweep *sw = ctx;
	bool bad = !strcmp(kind, "fault") || !strcmp(kind, "failed") || !strcmp(kind, "abort");
	log_msg(bad ? LOG_WARNING : LOG_NOTICE, "sweep %lld: %s%s%s: %s", (long long)sweep_id, kind,
		device ? " " : "", device ? device : "", message);
	if (!strcmp(kind, "fault")) {
		emit(sw, "sweep.fault", json_pack("{s:I,s:s,s:s}", "sweep", (json_int_t)sweep_id, "device",
						  device ? device : "", "message", message));
		return;
	}
	const char *state = sw->ex ? ex_state_name(ex_state(sw->ex)) : "idle";
	emit(sw, "sweep.state", json_pack("{s:I,s:s,s:s,s:s}", "sweep", (json_int_t)sweep_id, "state", state, "event",
					  kind, "reason", message));
}

static void on_progress(void *ctx, int64_t sweep_id, int done, int total, double eta, const char *phase)
{
	struct sweep *sw = ctx;
	sw->last.eta_s = eta;
	json_t *d = json_pack("{s:I,s:s,s:i,s:i,s:s}", "sweep", (json_int_t)sweep_id, "state", "running", "done", done,
			      "total", total, "point", phase);
	if (d && isfinite(eta))
		json_object_set_new(d, "eta_s", json_real(eta));
	emit(sw, "sweep.progress", d);
}

/* ---- completion: export and reconstruction -------------------------------------------------------- */

/* One row per calibrated point: sweep angles from the measured axis positions (zeniths ≥ 0, azimuths in
 * [0, 360)), the grid's values, then their sigma_<nm> columns; NaN as an empty field. */
static int export_csv(struct sweep *sw, int64_t id, const char *path, int *nrows, struct acq_err *err)
{
	*nrows = 0;
	sqlite3 *db = NULL;
	FILE *f = NULL;
	sqlite3_stmt *s = NULL;
	float *grid = NULL;
	int rc = -1;
	if (sqlite3_open_v2(sw->env.conf->d.database, &db, SQLITE_OPEN_READONLY, NULL) != SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: %s", sw->env.conf->d.database, db ? sqlite3_errmsg(db) : "cannot open");
		goto out;
	}
	sqlite3_busy_timeout(db, 5000);
	if (sqlite3_prepare_v2(db, "SELECT wavelength_grid FROM sweeps WHERE id = ?", -1, &s, NULL) != SQLITE_OK)
		goto dberr;
	sqlite3_bind_int64(s, 1, id);
	if (sqlite3_step(s) != SQLITE_ROW || sqlite3_column_bytes(s, 0) <= 0 || sqlite3_column_bytes(s, 0) % 4) {
		acq_errf(err, ACQ_E_STATE, "sweep %lld has no wavelength grid", (long long)id);
		goto out;
	}
	int nb = sqlite3_column_bytes(s, 0), n = nb / 4;
	grid = malloc((size_t)nb);
	if (!grid) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto out;
	}
	memcpy(grid, sqlite3_column_blob(s, 0), (size_t)nb);
	sqlite3_finalize(s);
	s = NULL;
	char tmp[4200];
	snprintf(tmp, sizeof tmp, "%s.tmp", path);
	if (!(f = fopen(tmp, "w"))) {
		acq_errf(err, ACQ_E_IO, "%s: %s", tmp, strerror(errno));
		goto out;
	}
	fprintf(f, "# acquisitiond sweep %lld: calibrated spectral BRDF samples (sr^-1) with standard uncertainty\n",
		(long long)id);
	fprintf(f, "# calibration: %s method; angles from the measured axis positions\n",
		calib_method_name(sw->cfg.cal.method));
	fputs("theta_i,phi_i,theta_o,phi_o", f);
	for (int k = 0; k < n; k++)
		fprintf(f, ",%g", (double)grid[k]);
	for (int k = 0; k < n; k++)
		fprintf(f, ",sigma_%g", (double)grid[k]);
	fputc('\n', f);
	if (sqlite3_prepare_v2(db, "SELECT coalesce(p.laser_theta, p.theta_i), coalesce(p.detector_theta, p.theta_o), "
				   "coalesce(p.detector_phi, p.phi_o), c.brdf, c.sigma, p.laser_theta IS NULL FROM calibrated c "
				   "JOIN points p ON p.id = c.point_id WHERE c.sweep_id = ? AND p.state = 'done' "
				   "ORDER BY p.order_index", -1, &s, NULL) != SQLITE_OK)
		goto dberr;
	sqlite3_bind_int64(s, 1, id);
	while (sqlite3_step(s) == SQLITE_ROW) {
		if (sqlite3_column_bytes(s, 3) != nb || sqlite3_column_bytes(s, 4) != nb)
			continue;
		struct plan_pos p = { sqlite3_column_double(s, 0), sqlite3_column_double(s, 1), sqlite3_column_double(s, 2) };
		double ti, pi, to, po;
		ex_pos_angles(&sw->env.conf->bench, &p, &ti, &pi, &to, &po);
		fprintf(f, "%.6f,%.6f,%.6f,%.6f", ti, pi, to, po);
		const unsigned char *b = sqlite3_column_blob(s, 3), *u = sqlite3_column_blob(s, 4);
		for (int pass = 0; pass < 2; pass++)
			for (int k = 0; k < n; k++) {
				float v;
				memcpy(&v, (pass ? u : b) + 4 * k, 4);
				if (isfinite(v))
					fprintf(f, ",%.7g", (double)v);
				else
					fputc(',', f);
			}
		fputc('\n', f);
		(*nrows)++;
	}
	if (fclose(f) != 0) {
		f = NULL;
		acq_errf(err, ACQ_E_IO, "%s: %s", tmp, strerror(errno));
		goto out;
	}
	f = NULL;
	if (rename(tmp, path)) {
		acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(errno));
		goto out;
	}
	rc = 0;
	goto out;
dberr:
	acq_errf(err, ACQ_E_IO, "%s: %s", sw->env.conf->d.database, sqlite3_errmsg(db));
out:
	if (f)
		fclose(f);
	sqlite3_finalize(s);
	sqlite3_close(db);
	free(grid);
	return rc;
}

/* brdf-recon: an absolute path, next to acquisitiond, or in PATH. 0 or -1. */
static int find_program(const char *prog, char *out, size_t cap)
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

static void recon_next(struct sweep *sw);

static void recon_event(struct sweep *sw, const char *kind, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void recon_event(struct sweep *sw, const char *kind, const char *fmt, ...)
{
	char msg[1024];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	store_event(sw->env.store, sw->done_id, kind, "recon", msg, sw->env.wallclock(), NULL);
	log_msg(LOG_NOTICE, "sweep %lld: %s", (long long)sw->done_id, msg);
	emit(sw, "recon", json_pack("{s:I,s:s,s:s}", "sweep", (json_int_t)sw->done_id, "state", kind, "message", msg));
}

static const char *relpath(const struct sweep *sw, const char *path)
{
	size_t n = strlen(sw->env.conf->d.state_dir);
	if (!strncmp(path, sw->env.conf->d.state_dir, n) && path[n] == '/')
		return path + n + 1;
	return path;
}

static void recon_stage_done(struct job *j, int status, const char *output, size_t len, void *arg)
{
	(void)j;
	(void)len;
	struct sweep *sw = arg;
	sw->job = NULL;
	int st = sw->rstage;
	if (status == 0) {
		store_recon_output(sw->env.store, sw->run_id, rc_kinds[st], relpath(sw, sw->files[st]), sw->env.wallclock(),
				   NULL);
		if (st == RC_DHR) {
			char png[4200];
			snprintf(png, sizeof png, "%s/dhr.png", sw->outdir);
			if (!access(png, R_OK))
				store_recon_output(sw->env.store, sw->run_id, "dhr", relpath(sw, png), sw->env.wallclock(), NULL);
		}
	} else {
		/* Keep the tail of the output in the event: the run record keeps the whole. */
		size_t n = strlen(output);
		const char *tail = n > 300 ? output + n - 300 : output;
		recon_event(sw, "info", "brdf-recon %s failed (status %d): %s", rc_names[st], status, tail);
		if (st == RC_DHR && !sw->dhr_noplot) { /* perhaps only the plot is missing: the table alone */
			sw->dhr_noplot = true;
			recon_next(sw);
			return;
		}
		sw->recon_failed++;
		if (st == RC_FIT) { /* nothing else can run without a model */
			store_recon_end(sw->env.store, sw->run_id, "failed", status, output, sw->env.wallclock(), NULL);
			recon_event(sw, "info", "no reconstruction: the fit failed; the calibrated samples are in %s",
				    sw->csv);
			return;
		}
	}
	sw->rstage++;
	recon_next(sw);
}

static void recon_next(struct sweep *sw)
{
	struct acq_err err = { 0 };
	char threads[16];
	snprintf(threads, sizeof threads, "%d", sw->env.conf->recon.threads > 0 ? sw->env.conf->recon.threads : 1);
	while (sw->rstage < RC__COUNT) {
		char *argv[24];
		int argc = 0;
		char dhrpng[4200], cmd[16];
		snprintf(cmd, sizeof cmd, "%s", rc_names[sw->rstage]);
		argv[argc++] = sw->prog;
		argv[argc++] = cmd;
		switch (sw->rstage) {
		case RC_FIT:
			argv[argc++] = sw->csv;
			argv[argc++] = "-o";
			argv[argc++] = sw->files[RC_FIT];
			break;
		case RC_MERL:
		case RC_RENDER:
			argv[argc++] = sw->files[RC_FIT];
			argv[argc++] = "-o";
			argv[argc++] = sw->files[sw->rstage];
			argv[argc++] = "--threads";
			argv[argc++] = threads;
			break;
		case RC_DHR:
			snprintf(dhrpng, sizeof dhrpng, "%s/dhr.png", sw->outdir);
			argv[argc++] = sw->files[RC_FIT];
			argv[argc++] = "-o";
			argv[argc++] = sw->files[RC_DHR];
			if (!sw->dhr_noplot) {
				argv[argc++] = "--plot";
				argv[argc++] = dhrpng;
			}
			break;
		}
		argv[argc] = NULL;
		if (job_start(argv, sw->outdir, sw->env.conf->recon.timeout_s, recon_stage_done, sw, &sw->job, &err) == 0) {
			recon_event(sw, "info", "brdf-recon %s started (pid %d)", rc_names[sw->rstage], (int)job_pid(sw->job));
			return;
		}
		recon_event(sw, "info", "brdf-recon %s could not start: %s", rc_names[sw->rstage], err.msg);
		sw->recon_failed++;
		if (sw->rstage == RC_FIT) {
			store_recon_end(sw->env.store, sw->run_id, "failed", 127, err.msg, sw->env.wallclock(), NULL);
			return;
		}
		sw->rstage++;
	}
	const char *state = sw->recon_failed ? "failed" : "succeeded";
	char summary[8192] = "";
	size_t n = 0;
	for (int i = 0; i < RC__COUNT; i++) {
		bool ok = !access(sw->files[i], R_OK);
		n += (size_t)snprintf(summary + n, sizeof summary - n, "%s%s %s", i ? "; " : "", rc_kinds[i],
				      ok ? sw->files[i] : "(not produced)");
		if (n >= sizeof summary)
			break;
	}
	store_recon_end(sw->env.store, sw->run_id, state, sw->recon_failed, summary, sw->env.wallclock(), NULL);
	recon_event(sw, sw->recon_failed ? "info" : "complete", "reconstruction %s (%d of %d steps failed): %s", state,
		    sw->recon_failed, RC__COUNT, summary);
}

/* The completion chain of sweep id: its calibrated samples as CSV into the state directory, then the
 * reconstruction stages if wanted (automatic: sweep.auto_recon) and brdf-recon is present. 0 or -1. */
static int run_chain(struct sweep *sw, int64_t id, bool automatic, int64_t *run_id, struct acq_err *err)
{
	const struct conf *c = sw->env.conf;
	if (run_id)
		*run_id = 0;
	if (sw->job)
		return acq_errf(err, ACQ_E_STATE, "a reconstruction is still running");
	sw->done_id = id;
	snprintf(sw->outdir, sizeof sw->outdir, "%s/sweep-%lld", c->recon.output_dir, (long long)id);
	mkdir(c->recon.output_dir, 0750);
	mkdir(sw->outdir, 0750);
	snprintf(sw->csv, sizeof sw->csv, "%s/samples.csv", sw->outdir);
	int rows = 0;
	if (export_csv(sw, id, sw->csv, &rows, err)) {
		recon_event(sw, "info", "exporting the calibrated samples failed: %s; no reconstruction ran", err->msg);
		return -1;
	}
	recon_event(sw, "info", "%d calibrated samples exported to %s", rows, sw->csv);
	if (automatic && !c->sweep.auto_recon) {
		recon_event(sw, "info", "sweep.auto_recon is off: no reconstruction ran; the samples are in %s", sw->csv);
		return 0;
	}
	if (find_program(c->recon.program, sw->prog, sizeof sw->prog)) {
		recon_event(sw, "info", "no reconstruction ran: '%s' not found (brdf-recon not installed?); the calibrated "
			    "samples are recorded in the database and in %s", c->recon.program, sw->csv);
		return acq_errf(err, ACQ_E_UNSUPPORTED, "reconstruction program '%s' not found", c->recon.program);
	}
	snprintf(sw->files[RC_FIT], sizeof sw->files[0], "%s/model.brdf", sw->outdir);
	snprintf(sw->files[RC_MERL], sizeof sw->files[0], "%s/merl.binary", sw->outdir);
	snprintf(sw->files[RC_DHR], sizeof sw->files[0], "%s/dhr.csv", sw->outdir);
	snprintf(sw->files[RC_RENDER], sizeof sw->files[0], "%s/preview.png", sw->outdir);
	for (int i = 0; i < RC__COUNT; i++)
		unlink(sw->files[i]); /* a rerun must not report the previous run's files */
	char args[8192];
	snprintf(args, sizeof args, "[\"fit %s\", \"merl\", \"dhr --plot\", \"render\"]", sw->csv);
	if (store_recon_begin(sw->env.store, id, sw->prog, args, sw->env.wallclock(), &sw->run_id, err)) {
		recon_event(sw, "info", "recording the reconstruction failed: %s; none ran", err->msg);
		return -1;
	}
	if (run_id)
		*run_id = sw->run_id;
	sw->rstage = RC_FIT;
	sw->recon_failed = 0;
	sw->dhr_noplot = false;
	recon_next(sw);
	return 0;
}

/* The sweep completed (timer, so it runs outside the executor's step). */
static void on_completed(struct loop *lp, void *arg)
{
	(void)lp;
	struct sweep *sw = arg;
	sw->done_timer = 0;
	struct acq_err err = { 0 };
	if (run_chain(sw, sw->done_id, true, NULL, &err) && err.code != ACQ_E_UNSUPPORTED)
		log_msg(LOG_WARNING, "sweep %lld: completion: %s", (long long)sw->done_id, err.msg);
}

int sweep_recon_start(struct sweep *sw, int64_t sweep_id, int64_t *run_id, struct acq_err *err)
{
	*run_id = 0;
	if (sw->ex)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld is %s: reconstruct when no sweep runs", (long long)sw->id,
				ex_state_name(ex_state(sw->ex)));
	if (sw->job)
		return acq_errf(err, ACQ_E_STATE, "a reconstruction is still running");
	json_t *js = store_sweep_show(sw->env.store, sweep_id, false, err);
	if (!js)
		return -1;
	json_decref(js);
	return run_chain(sw, sweep_id, false, run_id, err);
}

bool sweep_recon_busy(const struct sweep *sw)
{
	return sw->job != NULL;
}

/* ---- the executor on the loop --------------------------------------------------------------------- */

static void schedule(struct sweep *sw, double when);

static void release(struct sweep *sw)
{
	ex_free(sw->ex, loop_now(sw->env.loop));
	sw->ex = NULL;
	plan_result_free(sw->plan);
	sw->plan = NULL;
	plan_spec_free(sw->spec);
	sw->spec = NULL;
}

static void snapshot(struct sweep *sw)
{
	struct sweep_progress *p = &sw->last;
	if (!sw->ex)
		return;
	const struct ex_stats *st = ex_stats(sw->ex);
	p->state = map_state(ex_state(sw->ex));
	p->sweep_id = sw->id;
	p->points_done = st->points_done;
	p->points_total = st->points_total;
	p->started_at = sw->started_wall;
	const char *r = ex_reason(sw->ex);
	snprintf(p->message, sizeof p->message, "%s%s%s", ex_phase(sw->ex), r[0] ? ": " : "", r);
}

static void tick(struct loop *lp, void *arg)
{
	struct sweep *sw = arg;
	sw->timer = 0;
	if (!sw->ex)
		return;
	double now = loop_now(lp);
	double next = ex_step(sw->ex, now);
	snapshot(sw);
	enum ex_state s = ex_state(sw->ex);
	if (s == EX_COMPLETED || s == EX_ABORTED || s == EX_FAILED) {
		sw->last.state = SWEEP_IDLE;
		snprintf(sw->last.message, sizeof sw->last.message, "sweep %lld %s%s%s", (long long)sw->id,
			 ex_state_name(s), ex_reason(sw->ex)[0] ? ": " : "", ex_reason(sw->ex));
		if (s == EX_COMPLETED) {
			sw->done_id = sw->id;
			sw->done_timer = loop_timer_add(lp, 0, 0, on_completed, sw);
		}
		release(sw);
		return;
	}
	schedule(sw, next);
}

static void schedule(struct sweep *sw, double when)
{
	if (sw->timer)
		loop_timer_cancel(sw->env.loop, sw->timer);
	sw->timer = 0;
	if (!sw->ex || !(when < INFINITY))
		return;
	double d = when - loop_now(sw->env.loop);
	sw->timer = loop_timer_add(sw->env.loop, d > 0 ? d : 0, 0, tick, sw);
}

static void kick(struct sweep *sw)
{
	schedule(sw, loop_now(sw->env.loop));
}

static int load_cfg(const struct conf *c, struct ex_cfg *cfg, struct acq_err *err)
{
	ex_cfg_defaults(cfg);
	cfg->pol.target_frac = c->sweep.target_peak;
	cfg->pol.min_ms = c->sweep.min_integration_ms;
	cfg->pol.max_ms = c->sweep.max_integration_ms;
	if (cfg->pol.probe_ms < cfg->pol.min_ms)
		cfg->pol.probe_ms = cfg->pol.min_ms;
	if (cfg->pol.probe_ms > cfg->pol.max_ms)
		cfg->pol.probe_ms = cfg->pol.max_ms;
	cfg->pol.averages = (unsigned)c->sweep.averages;
	cfg->extra_settle_s = c->sweep.extra_settle_s;
	cfg->dark_every = c->sweep.dark_every;
	cfg->auto_resume_faults = c->sweep.auto_resume_faults;
	if (ex_cfg_parse(c->sweep.acquisition, c->sweep.calibration, cfg, err))
		return -1;
	cfg->db_path = c->d.database;
	return exp_policy_check(&cfg->pol, err);
}

int sweep_init(const struct sweep_env *env, struct sweep **out, struct acq_err *err)
{
	struct sweep *sw = calloc(1, sizeof *sw);
	if (!sw)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	sw->env = *env;
	if (load_cfg(env->conf, &sw->cfg, err)) {
		free(sw);
		return -1;
	}
	sw->last.eta_s = NAN;
	*out = sw;
	return 0;
}

void sweep_finish(struct sweep *sw)
{
	if (!sw)
		return;
	if (sw->timer)
		loop_timer_cancel(sw->env.loop, sw->timer);
	if (sw->done_timer)
		loop_timer_cancel(sw->env.loop, sw->done_timer);
	if (sw->ex)
		ex_shutdown(sw->ex, "daemon stopping");
	if (sw->job) /* the body's job_finish() kills it without calling back */
		store_recon_end(sw->env.store, sw->run_id, "cancelled", 128 + 15, "daemon stopping", sw->env.wallclock(),
				NULL);
	release(sw);
	free(sw);
}

/* Plan the text against the bench; the spec's integration settings override the configuration's. */
static int make_plan(struct sweep *sw, const char *text, const char *name, struct ex_cfg *cfg, struct acq_err *err)
{
	if (!text)
		return acq_errf(err, ACQ_E_INVAL, "no plan text");
	if (plan_load_string(name && *name ? name : "plan", text, &sw->spec, err))
		return -1;
	if (plan_make(sw->spec, &sw->env.conf->bench, &sw->plan, err))
		return -1;
	if (sw->plan->n_steps == 0)
		return acq_errf(err, ACQ_E_INVAL, "the plan has no visible point");
	*cfg = sw->cfg;
	if (sw->spec->averages > 0)
		cfg->pol.averages = (unsigned)sw->spec->averages;
	if (sw->spec->integ_mode == PLAN_INTEG_FIXED) {
		cfg->fixed_integration = true;
		cfg->fixed_ms = sw->spec->integ_ms;
	} else {
		if (sw->spec->target_peak > 0 && sw->spec->target_peak < cfg->pol.sat_frac)
			cfg->pol.target_frac = sw->spec->target_peak;
		if (sw->spec->max_integ_ms > 0 && sw->spec->max_integ_ms < cfg->pol.max_ms)
			cfg->pol.max_ms = fmax(sw->spec->max_integ_ms, cfg->pol.min_ms);
		if (sw->spec->integ_ms > 0)
			cfg->pol.probe_ms = fmin(fmax(sw->spec->integ_ms, cfg->pol.min_ms), cfg->pol.max_ms);
	}
	return exp_policy_check(&cfg->pol, err);
}

static struct ex_sink sink_of(struct sweep *sw)
{
	return (struct ex_sink){ .event = on_event, .progress = on_progress, .ctx = sw };
}

int sweep_start(struct sweep *sw, const char *plan_text, const char *name, int64_t *id, struct acq_err *err)
{
	*id = 0;
	if (sw->ex)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld is %s", (long long)sw->id, ex_state_name(ex_state(sw->ex)));
	char missing[256] = "";
	for (int d = 0; d < CONF_DEV__COUNT; d++) {
		bool ok = d <= CONF_DEV_DETECTOR_PHI ? devices_axis(sw->env.devices, (enum conf_dev)d) != NULL
			  : d == CONF_DEV_SPECTRO   ? devices_spectro(sw->env.devices) != NULL
						    : devices_laser(sw->env.devices) != NULL;
		if (!ok)
			snprintf(missing + strlen(missing), sizeof missing - strlen(missing), "%s%s", missing[0] ? ", " : "",
				 conf_dev_name((enum conf_dev)d));
	}
	if (missing[0])
		return acq_errf(err, ACQ_E_DISCONNECTED, "cannot start a sweep: unavailable: %s", missing);
	struct ex_cfg cfg;
	if (make_plan(sw, plan_text, name, &cfg, err))
		goto fail;
	size_t n = sw->plan->n_steps;
	struct store_point_new *pts = calloc(n, sizeof *pts);
	if (!pts) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto fail;
	}
	for (size_t i = 0; i < n; i++) {
		pts[i].order_index = (int)i;
		ex_pos_angles(&sw->env.conf->bench, &sw->plan->steps[i].pos, &pts[i].theta_i, &pts[i].phi_i,
			      &pts[i].theta_o, &pts[i].phi_o);
	}
	char method[128];
	snprintf(method, sizeof method, "%s-v1", calib_method_name(cfg.cal.method));
	struct store_sweep_new nw = {
		.name = name && *name ? name : sw->spec->name,
		.plan_text = plan_text,
		.config_snapshot = sw->env.conf->text ? sw->env.conf->text : "",
		.software_version = sw->env.software_version,
		.calibration_method = method,
		.spectrometer_id = devices_spectrometer_id(sw->env.devices),
		.created_at = sw->env.wallclock(),
	};
	int rc = store_sweep_create(sw->env.store, &nw, pts, (int)n, &sw->id, err);
	free(pts);
	if (rc)
		goto fail;
	struct ex_sink sk = sink_of(sw);
	sw->ex = ex_new(&cfg, &dev_ops, sw, &sk, sw->env.store, sw->id, nw.spectrometer_id, &sw->env.conf->bench,
			sw->plan, err);
	if (!sw->ex)
		goto fail;
	sw->started_wall = sw->env.wallclock();
	if (ex_start(sw->ex, 0, false, loop_now(sw->env.loop), err))
		goto fail;
	*id = sw->id;
	snapshot(sw);
	kick(sw);
	return 0;
fail:
	release(sw);
	return -1;
}

int sweep_pause(struct sweep *sw, struct acq_err *err)
{
	if (!sw->ex)
		return acq_errf(err, ACQ_E_STATE, "no sweep is running");
	if (ex_pause(sw->ex, loop_now(sw->env.loop), err))
		return -1;
	snapshot(sw);
	kick(sw);
	return 0;
}

/* Resume interrupted sweep id from the store: re-plan its stored plan text (deterministic), check it matches
 * the stored points, discard a partial point and start after the last committed one. */
static int recover_id(struct sweep *sw, int64_t id, bool hold, struct acq_err *err)
{
	json_t *js = store_sweep_show(sw->env.store, id, false, err);
	if (!js)
		return -1;
	const char *state = json_string_value(json_object_get(js, "state"));
	const char *text = json_string_value(json_object_get(js, "plan_text"));
	const char *name = json_string_value(json_object_get(js, "name"));
	json_int_t total = json_integer_value(json_object_get(js, "points_total"));
	int rc = -1;
	struct ex_cfg cfg;
	if (!state || (strcmp(state, "running") && strcmp(state, "paused"))) {
		acq_errf(err, ACQ_E_STATE, "sweep %lld is %s: only a running or paused sweep can be resumed",
			 (long long)id, state ? state : "?");
		goto out;
	}
	if (make_plan(sw, text, name, &cfg, err))
		goto out;
	if ((json_int_t)sw->plan->n_steps != total) {
		acq_errf(err, ACQ_E_STATE, "sweep %lld: its plan now gives %zu points, %lld were stored (bench changed?)",
			 (long long)id, sw->plan->n_steps, (long long)total);
		goto out;
	}
	int oi = -1;
	int64_t pid = 0;
	if (store_sweep_next_point(sw->env.store, id, &oi, &pid, err))
		goto out;
	if (oi < 0)
		oi = (int)sw->plan->n_steps; /* everything committed: completes at once */
	else if (store_point_discard_partial(sw->env.store, pid, err))
		goto out;
	sw->id = id;
	struct ex_sink sk = sink_of(sw);
	sw->ex = ex_new(&cfg, &dev_ops, sw, &sk, sw->env.store, id, devices_spectrometer_id(sw->env.devices),
			&sw->env.conf->bench, sw->plan, err);
	if (!sw->ex)
		goto out;
	sw->started_wall = sw->env.wallclock();
	if (ex_start(sw->ex, oi, true, loop_now(sw->env.loop), err))
		goto out;
	if (hold && !strcmp(state, "paused")) {
		/* Paused for the operator (sample swap, fault, pause command) before the restart: stays paused. */
		json_t *evs = json_object_get(js, "events");
		for (size_t i = 0; i < json_array_size(evs); i++) {
			json_t *e = json_array_get(evs, i);
			const char *k = json_string_value(json_object_get(e, "kind"));
			if (!k || (strcmp(k, "pause") && strcmp(k, "resume") && strcmp(k, "start") && strcmp(k, "stop")))
				continue;
			if (!strcmp(k, "pause"))
				ex_hold(sw->ex, json_string_value(json_object_get(e, "message")));
			break;
		}
	}
	snapshot(sw);
	kick(sw);
	rc = 0;
out:
	json_decref(js);
	if (rc)
		release(sw);
	return rc;
}

int sweep_resume(struct sweep *sw, int64_t id, struct acq_err *err)
{
	if (sw->ex) {
		if (id && id != sw->id)
			return acq_errf(err, ACQ_E_STATE, "sweep %lld is loaded; finish or abort it first", (long long)sw->id);
		if (ex_resume(sw->ex, loop_now(sw->env.loop), err))
			return -1;
		snapshot(sw);
		kick(sw);
		return 0;
	}
	if (!id && store_sweep_interrupted(sw->env.store, &id, err))
		return -1;
	if (!id)
		return acq_errf(err, ACQ_E_NOTFOUND, "no paused or interrupted sweep to resume");
	return recover_id(sw, id, false, err);
}

int sweep_abort(struct sweep *sw, struct acq_err *err)
{
	if (!sw->ex)
		return acq_errf(err, ACQ_E_STATE, "no sweep is running");
	if (ex_abort(sw->ex, "aborted by the operator", loop_now(sw->env.loop), err))
		return -1;
	kick(sw); /* the tick releases it */
	return 0;
}

int sweep_recover(struct sweep *sw, int64_t *id, struct acq_err *err)
{
	*id = 0;
	if (sw->ex)
		return acq_errf(err, ACQ_E_STATE, "a sweep is already loaded");
	int64_t found = 0;
	if (store_sweep_interrupted(sw->env.store, &found, err))
		return -1;
	if (!found)
		return 0;
	if (recover_id(sw, found, true, err))
		return -1;
	*id = found;
	return 0;
}

void sweep_device_back(struct sweep *sw, enum conf_dev dev)
{
	(void)dev;
	if (sw->ex && ex_state(sw->ex) == EX_SUSPENDED) {
		ex_resume(sw->ex, loop_now(sw->env.loop), NULL); /* retry now */
		kick(sw);
	}
}

void sweep_conf_changed(struct sweep *sw, const struct conf *c)
{
	struct ex_cfg cfg;
	struct acq_err err = { 0 };
	sw->env.conf = c;
	if (load_cfg(c, &cfg, &err))
		log_msg(LOG_ERR, "sweep configuration after reload: %s (keeping the previous one)", err.msg);
	else
		sw->cfg = cfg;
}

void sweep_get_progress(const struct sweep *sw, struct sweep_progress *p)
{
	*p = sw->last;
	if (!sw->ex) {
		p->state = SWEEP_IDLE;
		p->eta_s = NAN;
	}
}

bool sweep_busy(const struct sweep *sw)
{
	return sw->ex != NULL;
}

const char *sweep_state_name(enum sweep_state s)
{
	static const char *const names[] = { "idle", "running", "paused", "faulted", "stopping" };
	return (unsigned)s < 5 ? names[s] : "?";
}
