/* executor: the sweep state machine (moves, acquisition policy, calibration, commits, faults, pause/abort). */
#include "daemon/executor.h"

#include <math.h>
#include <sqlite3.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "daemon/store.h"
#include "drivers/axis.h"

#define EX_MAX_PENDING 24
#define EX_MAX_TIMES 8
#define EX_POS_TOL_DEG 1e-3

enum phase {
	PH_NONE = 0,
	PH_VERIFY,   /* read positions, reset alarms, home what is not homed */
	PH_HOMING,
	PH_MOVE,     /* waypoint segments */
	PH_SETTLE,
	PH_ACQ,      /* acquisition shots */
};

enum shot_kind { SHOT_PROBE, SHOT_DARK, SHOT_EXPOSE };

struct pending {
	const char *kind;            /* "dark", "sample", "reference", "beam" */
	struct spectro_frame *frame;
	double taken_at;
};

struct ex {
	struct ex_cfg cfg;
	struct ex_ops ops;
	void *octx;
	struct ex_sink sink;
	struct store *st;
	int64_t sweep_id, spectro_id;
	struct bench_geom geom;
	const struct plan_result *plan;
	int nsteps;

	enum ex_state state;
	enum phase phase;
	int cur;                     /* step being worked on */
	bool in_reference;           /* the current target is the reference pose */
	bool power_set;              /* the laser's power was set since the last laser fault */
	bool laser_unknown;          /* after a (re)start: switch the laser off whatever we believe */
	bool have_ref;
	bool first_move;             /* next move starts from the measured position (plan_move) */
	bool pause_requested;
	bool paused_by_fault;
	char reason[512];
	char phase_text[96];
	double wake;

	/* motion */
	struct plan_wp wps[PLAN_MAX_WP + 1];
	int n_wps, wp;
	bool moving[3];
	double settle_until;
	struct plan_pos known;       /* last commanded or measured position */
	bool known_valid;
	struct plan_pos actual;      /* measured after settling */
	bool homing[3];

	/* acquisition */
	bool shot_in_flight;
	enum shot_kind shot;
	struct spectro_meas meas;
	struct spectro_frame *frame; /* receive buffer */
	int probe_no;
	double t_probe, t_last;      /* t_last: previous point's base time, the first probe of the next */
	bool have_t0;
	double times[EX_MAX_TIMES];
	int ntimes, e;
	struct exp_rate *rates[EX_MAX_TIMES];
	struct exp_rate *merged, *ref_rate;
	struct pending pend[EX_MAX_PENDING];
	int npend;
	int attempts;                /* acquisitions of this point spoiled by saturation */
	int dark_retries;            /* darks in a row rejected for saturated pixels */
	struct exp_darks *darks;
	double temperature;
	const struct spectro_info *info;
	double wl[SPECTRO_MAX_PIXELS];
	unsigned char roi[SPECTRO_MAX_PIXELS];
	int nroi;
	struct calib_spectrum *cal;
	struct exp_avg *avg;

	/* faults */
	int point_faults;            /* faults since the current point started (reset when it commits) */
	int fault_dev;
	int fault_attempts;
	double backoff, retry_at;
	char fault_msg[512];

	/* progress */
	double point_started, point_avg_s;
	struct ex_stats stats;
};

static const char *const dev_names[EX_DEV__COUNT] = { "laser.theta", "detector.theta", "detector.phi",
						       "spectrometer", "laser" };

void ex_cfg_defaults(struct ex_cfg *c)
{
	memset(c, 0, sizeof *c);
	exp_policy_defaults(&c->pol);
	calib_cfg_defaults(&c->cal);
	c->extra_settle_s = 0.0;
	c->poll_s = 0.01;
	c->ladder_ratio = M_SQRT2;
	c->fault_retries = 5;
	c->fault_backoff_s = 0.5;
	c->fault_backoff_max_s = 8.0;
	c->auto_resume_faults = true;
	c->ref_pose = (struct plan_pos){ 0.0, 45.0, 180.0 };
	c->take_reference = true;
	c->pause_after_reference = true;
	c->max_point_attempts = 3;
	c->max_point_faults = 6;
	c->laser_power_pct = 100.0;
	c->max_invalid_frac = 0.005;
	c->db_path = NULL;
}

const char *ex_state_name(enum ex_state s)
{
	switch (s) {
	case EX_IDLE: return "idle";
	case EX_RUNNING: return "running";
	case EX_PAUSED: return "paused";
	case EX_SUSPENDED: return "suspended";
	case EX_COMPLETED: return "completed";
	case EX_ABORTED: return "aborted";
	case EX_FAILED: return "failed";
	}
	return "unknown";
}

void ex_pos_angles(const struct bench_geom *g, const struct plan_pos *p, double *ti, double *pi, double *to,
		   double *po)
{
	double a = g->laser_phi_deg + (p->laser_theta < 0 ? 180.0 : 0.0);
	double b = p->det_phi + (p->det_theta < 0 ? 180.0 : 0.0);
	a = fmod(a, 360.0);
	b = fmod(b, 360.0);
	*ti = fabs(p->laser_theta);
	*pi = a < 0 ? a + 360.0 : a;
	*to = fabs(p->det_theta);
	*po = b < 0 ? b + 360.0 : b;
}

static double wall_now(struct ex *x)
{
	if (x->ops.wall)
		return x->ops.wall(x->octx);
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Record an event in the store and tell the sink. A store failure here is not fatal (the sink still hears). */
static void event(struct ex *x, const char *kind, const char *device, const char *fmt, ...)
	__attribute__((format(printf, 4, 5)));
static void event(struct ex *x, const char *kind, const char *device, const char *fmt, ...)
{
	char msg[768];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	struct acq_err err = { 0 };
	if (x->st)
		store_event(x->st, x->sweep_id, kind, device, msg, wall_now(x), &err);
	if (x->sink.event)
		x->sink.event(x->sink.ctx, x->sweep_id, kind, device, msg);
}

static void set_db_state(struct ex *x, const char *state)
{
	struct acq_err err = { 0 };
	if (x->st)
		store_sweep_set_state(x->st, x->sweep_id, state, wall_now(x), &err);
}

static void clear_pending(struct ex *x)
{
	for (int i = 0; i < x->npend; i++)
		free(x->pend[i].frame);
	x->npend = 0;
}

/* A point measured again keeps the darks it took (they stay in the cache and must reach the store). */
static void drop_exposures(struct ex *x)
{
	int k = 0;
	for (int i = 0; i < x->npend; i++) {
		if (!strcmp(x->pend[i].kind, "dark"))
			x->pend[k++] = x->pend[i];
		else
			free(x->pend[i].frame);
	}
	x->npend = k;
	x->have_t0 = false;
	x->probe_no = 0;
	x->ntimes = 0;
	x->e = 0;
	x->shot_in_flight = false;
}

/* Pending spectra thrown away: their darks leave the cache too (every dark used is a stored dark). */
static void discard_pending(struct ex *x)
{
	for (int i = 0; i < x->npend; i++)
		if (!strcmp(x->pend[i].kind, "dark"))
			exp_dark_forget(x->darks, x->pend[i].frame->meas.integration_ms);
	clear_pending(x);
}

static void reset_acq(struct ex *x)
{
	discard_pending(x);
	x->have_t0 = false;
	x->probe_no = 0;
	x->ntimes = 0;
	x->e = 0;
	x->shot_in_flight = false;
}

static int laser_off(struct ex *x, struct acq_err *err)
{
	if (!x->ops.laser_set)
		return 0;
	int rc = x->ops.laser_set(x->octx, false, err);
	if (rc == 0)
		x->stats.laser_on = false;
	return rc;
}

/* Best effort: stop the spectrometer and the arms, laser off. */
static void safe_stop(struct ex *x)
{
	struct acq_err err = { 0 };
	if (x->shot_in_flight && x->ops.spectro_stop)
		x->ops.spectro_stop(x->octx, &err);
	x->shot_in_flight = false;
	for (int a = 0; a < 3; a++) {
		if ((x->moving[a] || x->homing[a]) && x->ops.stop)
			x->ops.stop(x->octx, a, &err);
		x->moving[a] = x->homing[a] = false;
	}
	laser_off(x, &err);
	x->stats.laser_on = false; /* the driver switches emission off on its own error paths too */
}

static void set_phase_text(struct ex *x, const char *s)
{
	snprintf(x->phase_text, sizeof x->phase_text, "%s", s);
}

static void ex_failed(struct ex *x, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void ex_failed(struct ex *x, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(x->reason, sizeof x->reason, fmt, ap);
	va_end(ap);
	safe_stop(x);
	reset_acq(x);
	x->state = EX_FAILED;
	x->phase = PH_NONE;
	set_phase_text(x, "failed");
	set_db_state(x, "failed");
	event(x, "failed", NULL, "%s", x->reason);
}

static void pause_now(struct ex *x, bool by_fault, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void pause_now(struct ex *x, bool by_fault, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(x->reason, sizeof x->reason, fmt, ap);
	va_end(ap);
	safe_stop(x);
	reset_acq(x);
	x->state = EX_PAUSED;
	x->paused_by_fault = by_fault;
	x->pause_requested = false;
	x->phase = PH_NONE;
	set_phase_text(x, "paused");
	set_db_state(x, "paused");
	event(x, "pause", by_fault ? dev_names[x->fault_dev] : NULL, "%s", x->reason);
}

/* A device error: the sweep suspends, and retries the device with backoff (or pauses at once). */
static void fault(struct ex *x, int dev, const struct acq_err *err)
{
	x->stats.faults++;
	snprintf(x->fault_msg, sizeof x->fault_msg, "%s", err && err->msg[0] ? err->msg : "device error");
	x->fault_dev = dev;
	if (x->ops.lost)
		x->ops.lost(x->octx, dev, err);
	safe_stop(x);
	reset_acq(x);
	if (dev == EX_DEV_SPECTRO)
		exp_darks_clear(x->darks); /* a reconnected spectrometer starts afresh */
	if (dev <= EX_DEV_DETECTOR_PHI)
		x->known_valid = false;
	if (dev == EX_DEV_LASER)
		x->power_set = false;
	event(x, "fault", dev_names[dev], "%s: %s (%s)", dev_names[dev], x->fault_msg,
	      acq_errname(err ? err->code : ACQ_E_DEVICE));
	if (err && (err->code == ACQ_E_RANGE || err->code == ACQ_E_INVAL || err->code == ACQ_E_UNSUPPORTED)) {
		/* Not a device that went away: retrying cannot help. */
		pause_now(x, true, "%s refused the operation at point %d: %s; fix the plan or the limits, then resume",
			  dev_names[dev], x->cur, x->fault_msg);
		return;
	}
	if (++x->point_faults > x->cfg.max_point_faults) {
		pause_now(x, true, "%d faults at point %d (last on %s: %s): paused for the operator", x->point_faults - 1,
			  x->cur, dev_names[dev], x->fault_msg);
		x->point_faults = 0;
		return;
	}
	if (!x->cfg.auto_resume_faults) {
		pause_now(x, true, "fault on %s: %s; resume when it is fixed", dev_names[dev], x->fault_msg);
		return;
	}
	x->state = EX_SUSPENDED;
	x->phase = PH_NONE;
	x->fault_attempts = 0;
	x->backoff = x->cfg.fault_backoff_s;
	snprintf(x->phase_text, sizeof x->phase_text, "suspended: %s", dev_names[dev]);
	x->retry_at = -1;
}

static double quantize(const struct ex *x, double t)
{
	const struct exp_policy *p = &x->cfg.pol;
	if (!(t > p->min_ms))
		return p->min_ms;
	if (t >= p->max_ms)
		return p->max_ms;
	double r = x->cfg.ladder_ratio > 1.0001 ? x->cfg.ladder_ratio : M_SQRT2;
	double k = floor(log(t / p->min_ms) / log(r) + 1e-9);
	double q = p->min_ms * pow(r, k);
	return q < p->min_ms ? p->min_ms : q > p->max_ms ? p->max_ms : q;
}

static bool want_wl(struct ex *x)
{
	if (x->info)
		return true;
	x->info = x->ops.spectro_info ? x->ops.spectro_info(x->octx) : NULL;
	if (!x->info || x->info->npix <= 0 || x->info->npix > SPECTRO_MAX_PIXELS) {
		x->info = NULL;
		return false;
	}
	const struct calib_cfg *c = &x->cfg.cal;
	double lo = c->grid_min_nm - c->grid_step_nm / 2, hi = c->grid_max_nm + c->grid_step_nm / 2;
	x->nroi = 0;
	for (int p = 0; p < x->info->npix; p++) {
		x->wl[p] = spectro_wavelength(x->info, p);
		x->roi[p] = x->wl[p] >= lo && x->wl[p] < hi;
	}
	for (int i = 0; i < x->info->ndark_pixels && i < 8; i++)
		if (x->info->dark_pixels[i] >= 0 && x->info->dark_pixels[i] < x->info->npix)
			x->roi[x->info->dark_pixels[i]] = 0;
	for (int p = 0; p < x->info->npix; p++)
		x->nroi += x->roi[p];
	return true;
}

struct ex *ex_new(const struct ex_cfg *cfg, const struct ex_ops *ops, void *ops_ctx, const struct ex_sink *sink,
		  struct store *st, int64_t sweep_id, int64_t spectrometer_id, const struct bench_geom *geom,
		  const struct plan_result *plan, struct acq_err *err)
{
	struct acq_err perr = { 0 };
	if (exp_policy_check(&cfg->pol, &perr))
		return acq_errf(err, ACQ_E_CONFIG, "sweep: %s", perr.msg), NULL;
	if (calib_grid_size(&cfg->cal) <= 0)
		return acq_errf(err, ACQ_E_CONFIG, "sweep: bad calibration grid"), NULL;
	if (!plan || !ops || !geom)
		return acq_errf(err, ACQ_E_INVAL, "sweep: missing plan, devices or geometry"), NULL;
	struct ex *x = calloc(1, sizeof *x);
	if (!x)
		return acq_errf(err, ACQ_E_NOMEM, "sweep: out of memory"), NULL;
	x->cfg = *cfg;
	x->ops = *ops;
	x->octx = ops_ctx;
	if (sink)
		x->sink = *sink;
	x->st = st;
	x->sweep_id = sweep_id;
	x->spectro_id = spectrometer_id;
	x->geom = *geom;
	x->plan = plan;
	x->nsteps = (int)plan->n_steps;
	x->frame = malloc(sizeof *x->frame);
	x->merged = malloc(sizeof *x->merged);
	x->ref_rate = malloc(sizeof *x->ref_rate);
	x->darks = calloc(1, sizeof *x->darks);
	x->cal = malloc(sizeof *x->cal);
	x->avg = malloc(sizeof *x->avg);
	bool ok = x->frame && x->merged && x->ref_rate && x->darks && x->cal && x->avg;
	for (int i = 0; i < EX_MAX_TIMES && ok; i++)
		ok = (x->rates[i] = malloc(sizeof(struct exp_rate))) != NULL;
	if (!ok) {
		ex_free(x, 0);
		return acq_errf(err, ACQ_E_NOMEM, "sweep: out of memory"), NULL;
	}
	x->stats.points_total = x->nsteps;
	x->t_last = cfg->pol.probe_ms;
	x->temperature = NAN;
	x->state = EX_IDLE;
	set_phase_text(x, "idle");
	return x;
}

void ex_free(struct ex *x, double now)
{
	(void)now;
	if (!x)
		return;
	if (x->state == EX_RUNNING || x->state == EX_SUSPENDED)
		safe_stop(x);
	clear_pending(x);
	for (int i = 0; i < EX_MAX_TIMES; i++)
		free(x->rates[i]);
	free(x->frame);
	free(x->merged);
	free(x->ref_rate);
	free(x->darks);
	free(x->cal);
	free(x->avg);
	free(x);
}

enum ex_state ex_state(const struct ex *x)
{
	return x->state;
}

const char *ex_phase(const struct ex *x)
{
	return x->phase_text;
}

const struct ex_stats *ex_stats(const struct ex *x)
{
	return &x->stats;
}

const char *ex_reason(const struct ex *x)
{
	return x->reason;
}

int ex_current_step(const struct ex *x)
{
	return x->cur;
}

static void mask_black(const struct ex *x, struct exp_rate *r);

/* ---- reference reload (crash-resume) ------------------------------------------------------------ */

static int blob_floats(sqlite3_stmt *s, int col, int npix, double *dst_d, float *dst_f)
{
	const void *b = sqlite3_column_blob(s, col);
	int n = sqlite3_column_bytes(s, col);
	if (!b || n != 4 * npix)
		return -1;
	const float *f = b;
	for (int i = 0; i < npix; i++) {
		float v;
		memcpy(&v, f + i, sizeof v);
		if (dst_d)
			dst_d[i] = v;
		if (dst_f)
			dst_f[i] = v;
	}
	return 0;
}

/* The reference of this sweep from the database: the spectra listed by the last "reference" event, darks
 * and exposures alike, turned into net rates and merged exactly as when they were taken. 1 loaded, 0 none. */
static int load_reference(struct ex *x, struct acq_err *err)
{
	if (!x->cfg.db_path || !want_wl(x))
		return 0;
	sqlite3 *db = NULL;
	int found = 0;
	if (sqlite3_open_v2(x->cfg.db_path, &db, SQLITE_OPEN_READONLY, NULL) != SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: %s", x->cfg.db_path, db ? sqlite3_errmsg(db) : "cannot open");
		sqlite3_close(db);
		return -1;
	}
	sqlite3_busy_timeout(db, 2000);
	sqlite3_stmt *s = NULL;
	long long lo = 0, hi = 0;
	if (sqlite3_prepare_v2(db, "SELECT message FROM events WHERE sweep_id = ? AND kind = 'reference' "
				   "ORDER BY id DESC LIMIT 1", -1, &s, NULL) != SQLITE_OK)
		goto dberr;
	sqlite3_bind_int64(s, 1, x->sweep_id);
	if (sqlite3_step(s) == SQLITE_ROW) {
		const char *m = (const char *)sqlite3_column_text(s, 0);
		const char *p = m ? strstr(m, "spectra ") : NULL;
		if (!p || sscanf(p, "spectra %lld-%lld", &lo, &hi) != 2)
			lo = hi = 0;
		double lt, dt, dp;
		const char *q = m ? strstr(m, "at (") : NULL;
		if (q && sscanf(q, "at (%lf, %lf, %lf)", &lt, &dt, &dp) == 3)
			x->cfg.cal.ref_theta_o_deg = fabs(dt);
	}
	sqlite3_finalize(s);
	s = NULL;
	if (lo <= 0 || hi < lo)
		goto out;
	if (sqlite3_prepare_v2(db, "SELECT kind, integration_ms, averages, npix, counts, stddev, saturation_mask, "
				   "temperature_c FROM spectra WHERE sweep_id = ? AND id BETWEEN ? AND ? ORDER BY id",
			       -1, &s, NULL) != SQLITE_OK)
		goto dberr;
	sqlite3_bind_int64(s, 1, x->sweep_id);
	sqlite3_bind_int64(s, 2, lo);
	sqlite3_bind_int64(s, 3, hi);
	exp_darks_clear(x->darks);
	int n = 0;
	static _Thread_local float sd[SPECTRO_MAX_PIXELS];
	while (sqlite3_step(s) == SQLITE_ROW && n < EX_MAX_TIMES) {
		const char *kind = (const char *)sqlite3_column_text(s, 0);
		double t = sqlite3_column_double(s, 1);
		int av = sqlite3_column_int(s, 2), npix = sqlite3_column_int(s, 3);
		if (!kind || npix != x->info->npix || av < 1)
			continue;
		exp_avg_init(x->avg, npix, t);
		if (blob_floats(s, 4, npix, x->frame->counts, NULL))
			continue;
		if (sqlite3_column_type(s, 5) == SQLITE_NULL)
			memset(sd, 0, sizeof(float) * (size_t)npix);
		else if (blob_floats(s, 5, npix, NULL, sd))
			continue;
		memset(x->frame->saturated, 0, (size_t)npix);
		if (sqlite3_column_type(s, 6) != SQLITE_NULL && sqlite3_column_bytes(s, 6) == npix)
			memcpy(x->frame->saturated, sqlite3_column_blob(s, 6), (size_t)npix);
		if (!strcmp(kind, "dark")) {
			exp_avg_add(x->avg, x->frame->counts, sd, (unsigned)av, NULL, t, NULL);
			x->avg->temperature_c = sqlite3_column_type(s, 7) == SQLITE_NULL ? NAN : sqlite3_column_double(s, 7);
			exp_dark_store(x->darks, x->avg, -1e300); /* old: never reused for new spectra */
		} else {
			const struct exp_dark *dk = exp_dark_find(x->darks, t);
			if (!dk || exp_net_rate(&x->cfg.pol, x->frame->counts, sd, (unsigned)av, x->frame->saturated, npix,
						t, dk, x->info->max_counts > 0 ? x->info->max_counts : 65535.0,
						x->rates[n], NULL))
				continue;
			n++;
		}
	}
	sqlite3_finalize(s);
	s = NULL;
	exp_darks_clear(x->darks);
	if (n > 0) {
		const struct exp_rate *list[EX_MAX_TIMES];
		for (int i = 0; i < n; i++)
			list[i] = x->rates[i];
		if (exp_merge(list, n, x->ref_rate, err) == 0) {
			mask_black(x, x->ref_rate);
			found = 1;
		}
	}
	goto out;
dberr:
	acq_errf(err, ACQ_E_IO, "%s: %s", x->cfg.db_path, sqlite3_errmsg(db));
	found = -1;
out:
	sqlite3_finalize(s);
	sqlite3_close(db);
	return found;
}

/* ---- control ---------------------------------------------------------------------------------- */

static void begin_segment(struct ex *x, double now)
{
	x->laser_unknown = true;
	x->phase = PH_VERIFY;
	x->first_move = true;
	x->wake = now;
}

int ex_start(struct ex *x, int first_step, bool resumed, double now, struct acq_err *err)
{
	if (x->state != EX_IDLE)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld is %s", (long long)x->sweep_id, ex_state_name(x->state));
	if (first_step < 0 || first_step > x->nsteps)
		return acq_errf(err, ACQ_E_RANGE, "sweep: first step %d outside [0, %d]", first_step, x->nsteps);
	if (x->cfg.take_reference && x->cfg.cal.method == CALIB_RELATIVE) {
		unsigned why = plan_blind(&x->geom, &x->cfg.ref_pose);
		if (why)
			return acq_errf(err, ACQ_E_CONFIG, "sweep.acquisition.reference_pose (%g, %g, %g): %s",
					x->cfg.ref_pose.laser_theta, x->cfg.ref_pose.det_theta, x->cfg.ref_pose.det_phi,
					plan_reason_name(why));
	}
	x->cur = first_step;
	x->stats.points_done = first_step;
	if (x->st) {
		static _Thread_local float grid[CALIB_MAX_GRID];
		int n = calib_grid_size(&x->cfg.cal);
		for (int k = 0; k < n; k++)
			grid[k] = (float)(x->cfg.cal.grid_min_nm + k * x->cfg.cal.grid_step_nm);
		if (store_sweep_set_grid(x->st, x->sweep_id, grid, n, err))
			return -1;
	}
	x->state = EX_RUNNING;
	x->point_avg_s = NAN;
	set_db_state(x, "running");
	if (resumed) {
		struct acq_err lerr = { 0 };
		int r = load_reference(x, &lerr);
		x->have_ref = r == 1;
		event(x, "resume", NULL, "resuming after point %d of %d (%s)", first_step, x->nsteps,
		      x->have_ref ? "reference reloaded from the database"
				  : r < 0 ? lerr.msg : "no complete reference stored: measuring it again");
	} else {
		event(x, "start", NULL, "sweep of %d points started", x->nsteps);
	}
	x->in_reference = x->cfg.take_reference && !x->have_ref;
	if (x->cfg.cal.method == CALIB_RELATIVE && !x->cfg.take_reference && !x->have_ref)
		event(x, "info", NULL, "no reference will be measured: calibrated values need one (take_reference)");
	begin_segment(x, now);
	set_phase_text(x, "verifying positions");
	return 0;
}

int ex_pause(struct ex *x, double now, struct acq_err *err)
{
	(void)now;
	if (x->state == EX_SUSPENDED) {
		pause_now(x, true, "paused by the operator while %s was faulted", dev_names[x->fault_dev]);
		return 0;
	}
	if (x->state != EX_RUNNING)
		return acq_errf(err, ACQ_E_STATE, "sweep is %s, not running", ex_state_name(x->state));
	x->pause_requested = true;
	return 0;
}

int ex_resume(struct ex *x, double now, struct acq_err *err)
{
	if (x->state == EX_SUSPENDED) {
		x->retry_at = now; /* try the device now */
		return 0;
	}
	if (x->state != EX_PAUSED)
		return acq_errf(err, ACQ_E_STATE, "sweep is %s, not paused", ex_state_name(x->state));
	x->reason[0] = '\0';
	set_db_state(x, "running");
	if (x->paused_by_fault) {
		x->state = EX_SUSPENDED;
		x->fault_attempts = 0;
		x->backoff = x->cfg.fault_backoff_s;
		x->retry_at = now;
		event(x, "resume", dev_names[x->fault_dev], "resumed by the operator: trying %s again",
		      dev_names[x->fault_dev]);
		return 0;
	}
	x->state = EX_RUNNING;
	event(x, "resume", NULL, "resumed at point %d of %d", x->cur, x->nsteps);
	begin_segment(x, now);
	return 0;
}

int ex_abort(struct ex *x, const char *why, double now, struct acq_err *err)
{
	(void)now;
	if (x->state == EX_COMPLETED || x->state == EX_ABORTED || x->state == EX_FAILED)
		return acq_errf(err, ACQ_E_STATE, "sweep already %s", ex_state_name(x->state));
	safe_stop(x);
	reset_acq(x);
	snprintf(x->reason, sizeof x->reason, "%s", why && *why ? why : "aborted by the operator");
	x->state = EX_ABORTED;
	x->phase = PH_NONE;
	set_phase_text(x, "aborted");
	set_db_state(x, "aborted");
	event(x, "abort", NULL, "aborted at point %d of %d: %s (laser off, arms stopped)", x->cur, x->nsteps, x->reason);
	return 0;
}

/* ---- motion ----------------------------------------------------------------------------------- */

static const struct plan_pos *target_pos(const struct ex *x)
{
	return x->in_reference ? &x->cfg.ref_pose : &x->plan->steps[x->cur].pos;
}

static double axis_val(const struct plan_pos *p, int a)
{
	return a == 0 ? p->laser_theta : a == 1 ? p->det_theta : p->det_phi;
}

static bool near_pos(const struct plan_pos *a, const struct plan_pos *b)
{
	for (int i = 0; i < 3; i++)
		if (fabs(axis_val(a, i) - axis_val(b, i)) > EX_POS_TOL_DEG)
			return false;
	return true;
}

/* Waypoints to the current target: the planner's own when coming from the previous planned point, else a
 * fresh collision-free path from where the arms are. */
/* φ is periodic: bring a detector azimuth inside the axis's soft limits by whole turns when it is outside. */
static double wrap_phi(const struct ex *x, double phi)
{
	if (!x->ops.limits)
		return phi;
	double lo = -INFINITY, hi = INFINITY;
	x->ops.limits(x->octx, EX_DEV_DETECTOR_PHI, &lo, &hi);
	for (int i = 0; i < 4 && phi > hi; i++)
		phi -= 360.0;
	for (int i = 0; i < 4 && phi < lo; i++)
		phi += 360.0;
	return phi;
}

/* The turn of φ (within the soft limits) nearest to where the detector is. */
static double nearest_phi(const struct ex *x, double phi, double from)
{
	double lo = -INFINITY, hi = INFINITY, best = wrap_phi(x, phi);
	if (x->ops.limits)
		x->ops.limits(x->octx, EX_DEV_DETECTOR_PHI, &lo, &hi);
	for (int k = -2; k <= 2; k++) {
		double c = phi + 360.0 * k;
		if (c >= lo && c <= hi && fabs(c - from) < fabs(best - from))
			best = c;
	}
	return best;
}

/* Waypoints to the current target: the planner's own when the arms are where the planner left them (the
 * previous step) and its path stays inside the soft limits; else a fresh collision-free path from where the
 * arms are, to the turn of φ nearest to the detector. */
static int plan_path(struct ex *x)
{
	struct plan_pos t = *target_pos(x);
	x->n_wps = 0;
	x->wp = 0;
	if (!x->first_move && !x->in_reference && x->cur > 0 && x->known_valid &&
	    near_pos(&x->known, &x->plan->steps[x->cur - 1].pos)) {
		const struct plan_step *s = &x->plan->steps[x->cur];
		bool inside = true;
		for (size_t i = 0; i < s->n_wp && i < PLAN_MAX_WP + 1; i++) {
			x->wps[x->n_wps] = x->plan->wps[s->first_wp + i];
			double p = x->wps[x->n_wps].pos.det_phi;
			inside = inside && wrap_phi(x, p) == p;
			x->n_wps++;
		}
		if (x->n_wps > 0 && inside)
			return 0;
		x->n_wps = 0;
	}
	if (x->known_valid)
		t.det_phi = nearest_phi(x, t.det_phi, x->known.det_phi);
	else
		t.det_phi = wrap_phi(x, t.det_phi);
	if (x->known_valid && near_pos(&x->known, &t))
		return 0;
	size_t n = 0;
	struct plan_wp w[PLAN_MAX_WP];
	if (plan_move(&x->geom, &x->known, &t, w, &n) < 0)
		return -1;
	for (size_t i = 0; i < n; i++) {
		if (wrap_phi(x, w[i].pos.det_phi) != w[i].pos.det_phi)
			return -1;
		x->wps[x->n_wps++] = w[i];
	}
	return 0;
}

/* Start every axis of the current segment that has to move. 0, or -1 with the failing axis in *dev. */
static int start_segment(struct ex *x, double now, int *dev, struct acq_err *err)
{
	const struct plan_pos *p = &x->wps[x->wp].pos;
	for (int a = 0; a < 3; a++) {
		double tgt = axis_val(p, a);
		x->moving[a] = false;
		if (x->known_valid && fabs(axis_val(&x->known, a) - tgt) <= 1e-9)
			continue;
		if (x->ops.move_begin(x->octx, a, tgt, now, err)) {
			*dev = a;
			return -1;
		}
		x->moving[a] = true;
	}
	return 0;
}

/* Start the first waypoint segment of the current move, or go straight to settling when there is none. */
static void begin_waypoints(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	if (x->n_wps == 0) {
		x->phase = PH_SETTLE;
		x->settle_until = now;
		x->wake = now;
		return;
	}
	int dev = 0;
	if (start_segment(x, now, &dev, &err)) {
		fault(x, dev, &err);
		return;
	}
	x->wake = now;
}

static void run_verify(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	set_phase_text(x, "verifying positions");
	double pos[3];
	bool homed[3];
	for (int a = 0; a < 3; a++) {
		bool alarm = false;
		homed[a] = true;
		if (x->ops.position(x->octx, a, &pos[a], &homed[a], &alarm, &err)) {
			fault(x, a, &err);
			return;
		}
		if (alarm) {
			if (x->ops.alarm_reset(x->octx, a, &err)) {
				fault(x, a, &err);
				return;
			}
			event(x, "info", dev_names[a], "alarm cleared on %s before moving", dev_names[a]);
		}
	}
	/* Homing, when configured: one axis at a time, only when its way home is collision-free. */
	for (int a = 0; a < 3 && x->cfg.home_unhomed; a++) {
		if (homed[a])
			continue;
		struct plan_pos from = { pos[0], pos[1], pos[2] }, to = from;
		if (a == 0)
			to.laser_theta = x->cfg.home_deg[0];
		else if (a == 1)
			to.det_theta = x->cfg.home_deg[1];
		else
			to.det_phi = x->cfg.home_deg[2];
		if (!plan_seg_safe(&x->geom, &from, &to)) {
			pause_now(x, false, "%s is not homed and homing it from (%.2f, %.2f, %.2f) could collide: home it by "
				  "hand and resume", dev_names[a], pos[0], pos[1], pos[2]);
			return;
		}
		if (x->ops.home_begin(x->octx, a, now, &err)) {
			fault(x, a, &err);
			return;
		}
		x->homing[a] = true;
		event(x, "info", dev_names[a], "%s not homed: homing", dev_names[a]);
		x->phase = PH_HOMING;
		set_phase_text(x, "homing");
		x->wake = now;
		return;
	}
	x->known = (struct plan_pos){ pos[0], pos[1], pos[2] };
	x->known_valid = true;
	/* Laser off before any motion (also when a crashed predecessor may have left it on). */
	if ((x->stats.laser_on || x->laser_unknown) && laser_off(x, &err)) {
		fault(x, EX_DEV_LASER, &err);
		return;
	}
	x->laser_unknown = false;
	if (plan_path(x)) {
		pause_now(x, false, "no collision-free path from (%.2f, %.2f, %.2f) to the next point: move the arms and "
			  "resume", pos[0], pos[1], pos[2]);
		return;
	}
	x->first_move = false;
	x->phase = PH_MOVE;
	x->point_started = now;
	set_phase_text(x, x->in_reference ? "moving to the reference pose" : "moving");
	begin_waypoints(x, now);
}

/* Step every axis flagged in active[] (a move or a homing): clears the flag of an axis that arrived and
 * lowers *wake to the earliest next poll. 1 while any is still busy, 0 when all arrived, -1 after a fault
 * (already reported through fault()). */
static int step_axes(struct ex *x, bool active[3], double now, double *wake)
{
	struct acq_err err = { 0 };
	int busy = 0;
	for (int a = 0; a < 3; a++) {
		if (!active[a])
			continue;
		double np = x->ops.next_poll(x->octx, a);
		if (now + 1e-12 < np) {
			busy = 1;
			*wake = fmin(*wake, np);
			continue;
		}
		int r = x->ops.move_step(x->octx, a, now, &err);
		if (r == AXIS_MOVE_FAILED) {
			fault(x, a, &err);
			return -1;
		}
		if (r == AXIS_MOVE_DONE) {
			active[a] = false;
			continue;
		}
		busy = 1;
		*wake = fmin(*wake, x->ops.next_poll(x->octx, a));
	}
	return busy;
}

static void run_homing(struct ex *x, double now)
{
	double wake = INFINITY;
	int busy = step_axes(x, x->homing, now, &wake);
	if (busy < 0)
		return;
	if (!busy) {
		x->phase = PH_VERIFY;
		x->wake = now;
		return;
	}
	x->wake = fmax(now, wake);
}

static void run_move(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	if (x->stats.laser_on)
		x->stats.laser_on_while_moving++;
	double wake = INFINITY;
	int busy = step_axes(x, x->moving, now, &wake);
	if (busy < 0)
		return;
	if (busy) {
		x->wake = fmax(now, wake);
		return;
	}
	x->known = x->wps[x->wp].pos;
	x->known_valid = true;
	if (++x->wp < x->n_wps) {
		int dev = 0;
		if (start_segment(x, now, &dev, &err)) {
			fault(x, dev, &err);
			return;
		}
		x->wake = now;
		return;
	}
	x->phase = PH_SETTLE;
	x->settle_until = now + x->cfg.extra_settle_s;
	set_phase_text(x, "settling");
	x->wake = x->settle_until;
}

static void run_settle(struct ex *x, double now)
{
	if (now + 1e-12 < x->settle_until) {
		x->wake = x->settle_until;
		return;
	}
	struct acq_err err = { 0 };
	double pos[3];
	for (int a = 0; a < 3; a++) {
		bool homed, alarm;
		if (x->ops.position(x->octx, a, &pos[a], &homed, &alarm, &err)) {
			fault(x, a, &err);
			return;
		}
		if (alarm) {
			acq_errf(&err, ACQ_E_DEVICE, "%s in alarm after the move", dev_names[a]);
			fault(x, a, &err);
			return;
		}
	}
	x->actual = (struct plan_pos){ pos[0], pos[1], pos[2] };
	if (!want_wl(x)) {
		acq_errf(&err, ACQ_E_DISCONNECTED, "spectrometer information unavailable");
		fault(x, EX_DEV_SPECTRO, &err);
		return;
	}
	x->phase = PH_ACQ;
	reset_acq(x);
	x->attempts = 0;
	set_phase_text(x, x->in_reference ? "reference" : "acquiring");
	x->wake = now;
}

/* ---- acquisition ------------------------------------------------------------------------------ */

static const char *expose_kind(const struct ex *x)
{
	if (!x->in_reference)
		return "sample";
	return x->cfg.cal.method == CALIB_ABSOLUTE ? "beam" : "reference";
}

static int want_laser(struct ex *x, bool on, struct acq_err *err, int *dev)
{
	*dev = EX_DEV_LASER;
	if (on == x->stats.laser_on && !on)
		return 0;
	if (on && !x->power_set && x->ops.laser_power) {
		if (x->ops.laser_power(x->octx, x->cfg.laser_power_pct, err))
			return -1;
		x->power_set = true;
	}
	if (on != x->stats.laser_on) {
		if (x->ops.laser_set(x->octx, on, err))
			return -1;
		x->stats.laser_on = on;
	}
	if (on) {
		bool emission = false, ready = false;
		if (x->ops.laser_state(x->octx, &emission, &ready, err))
			return -1;
		if (!emission || !ready)
			return acq_errf(err, ACQ_E_DEVICE, "laser not emitting (interlock open or laser fault)");
	}
	return 0;
}

static void start_shot(struct ex *x, enum shot_kind k, double t, double now)
{
	struct acq_err err = { 0 };
	int dev = EX_DEV_LASER;
	if (want_laser(x, k != SHOT_DARK, &err, &dev)) {
		fault(x, dev, &err);
		return;
	}
	x->shot = k;
	x->meas.integration_ms = t;
	x->meas.averages = k == SHOT_PROBE ? 1 : k == SHOT_DARK ? x->cfg.pol.dark_averages : x->cfg.pol.averages;
	x->meas.saturation_detection = true;
	if (x->ops.spectro_start(x->octx, &x->meas, now, &err)) {
		fault(x, EX_DEV_SPECTRO, &err);
		return;
	}
	x->shot_in_flight = true;
	/* First look when the exposures should be over, then every poll_s (the fetch deadline is the driver's). */
	x->wake = now + fmax(t * 1e-3 * x->meas.averages, 1e-4);
}

static int keep_frame(struct ex *x, const char *kind, double taken_at)
{
	if (x->npend >= EX_MAX_PENDING)
		return -1;
	struct spectro_frame *f = malloc(sizeof *f);
	if (!f)
		return -1;
	memcpy(f, x->frame, sizeof *f);
	x->pend[x->npend++] = (struct pending){ kind, f, taken_at };
	return 0;
}

/* The sensor's optically black pixels carry no light: never used as data. */
static void mask_black(const struct ex *x, struct exp_rate *r)
{
	for (int i = 0; x->info && i < x->info->ndark_pixels && i < 8; i++) {
		int p = x->info->dark_pixels[i];
		if (p >= 0 && p < r->npix && r->valid[p]) {
			r->valid[p] = 0;
			r->rate[p] = r->u_noise[p] = r->u_dark[p] = NAN;
			r->ninvalid++;
		}
	}
}

static double full_scale(const struct ex *x)
{
	return x->info && x->info->max_counts > 0 ? x->info->max_counts : 65535.0;
}

static void commit_point(struct ex *x, double now);

/* The shot just finished: digest it and choose the next one. */
static void after_shot(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	struct spectro_frame *f = x->frame;
	double t = x->meas.integration_ms;
	if (f->npix != x->info->npix) {
		acq_errf(&err, ACQ_E_PROTO, "spectrometer returned %d pixels, expected %d", f->npix, x->info->npix);
		fault(x, EX_DEV_SPECTRO, &err);
		return;
	}
	if (!(f->meas.integration_ms > 0))
		f->meas = x->meas; /* what was asked is what was measured */
	if (!f->meas.averages)
		f->meas.averages = x->meas.averages;
	if (isfinite(f->temperature_c))
		x->temperature = f->temperature_c;
	if (x->shot != SHOT_DARK) {
		/* The laser must still be emitting: an interlock opened during the exposure spoils it. */
		bool emission = false, ready = false;
		if (x->ops.laser_state(x->octx, &emission, &ready, &err)) {
			fault(x, EX_DEV_LASER, &err);
			return;
		}
		if (!emission || !ready) {
			acq_errf(&err, ACQ_E_DEVICE, "laser stopped emitting during the exposure (interlock or fault)");
			fault(x, EX_DEV_LASER, &err);
			return;
		}
	}
	switch (x->shot) {
	case SHOT_PROBE: {
		x->stats.probes++;
		const struct exp_dark *dk = exp_dark_find(x->darks, t);
		double next = t;
		int r = exp_probe_next(&x->cfg.pol, f, dk ? dk->mean : NULL, full_scale(x), x->probe_no, &next, &err);
		if (r < 0) {
			fault(x, EX_DEV_SPECTRO, &err);
			return;
		}
		if (r == EXP_PROBE_AGAIN) {
			x->t_probe = next;
			break;
		}
		x->have_t0 = true;
		x->times[0] = quantize(x, next);
		x->ntimes = 1;
		x->e = 0;
		break;
	}
	case SHOT_DARK: {
		/* A dark with saturated pixels (stray light, a burst) is no dark: take it again. */
		int nsat = 0;
		for (int p = 0; p < f->npix; p++)
			nsat += f->saturated[p] || !(f->counts[p] < x->cfg.pol.sat_frac * full_scale(x));
		if (nsat > 0) {
			if (++x->dark_retries > x->cfg.max_point_attempts) {
				acq_errf(&err, ACQ_E_DEVICE, "%d darks in a row with saturated pixels (%d at %.3g ms)",
					 x->dark_retries, nsat, t);
				x->dark_retries = 0;
				fault(x, EX_DEV_SPECTRO, &err);
				return;
			}
			x->stats.dark_rejects++;
			event(x, "info", dev_names[EX_DEV_SPECTRO], "dark at %.3g ms has %d saturated pixels: taken again", t,
			      nsat);
			break;
		}
		x->dark_retries = 0;
		x->stats.darks++;
		exp_avg_init(x->avg, f->npix, t);
		if (exp_avg_add(x->avg, f->counts, f->stddev, f->meas.averages ? f->meas.averages : x->meas.averages,
				f->saturated, t, &err)) {
			fault(x, EX_DEV_SPECTRO, &err);
			return;
		}
		x->avg->temperature_c = f->temperature_c;
		exp_dark_store(x->darks, x->avg, now);
		if (keep_frame(x, "dark", wall_now(x))) {
			ex_failed(x, "out of memory keeping spectra");
			return;
		}
		break;
	}
	case SHOT_EXPOSE: {
		x->stats.exposures++;
		const struct exp_dark *dk = exp_dark_find(x->darks, t);
		unsigned n = f->meas.averages ? f->meas.averages : x->meas.averages;
		if (exp_net_rate(&x->cfg.pol, f->counts, f->stddev, n, f->saturated, f->npix, t, dk, full_scale(x),
				 x->rates[x->e], &err)) {
			ex_failed(x, "net rate: %s", err.msg);
			return;
		}
		if (keep_frame(x, expose_kind(x), wall_now(x))) {
			ex_failed(x, "out of memory keeping spectra");
			return;
		}
		if (x->e == 0 && !x->cfg.fixed_integration) {
			double tt[EX_MAX_TIMES];
			int m = exp_plan_times(&x->cfg.pol, x->rates[0], x->roi, x->times[0], tt, EX_MAX_TIMES);
			x->ntimes = 1;
			for (int k = 1; k < m; k++) {
				double q = quantize(x, tt[k]);
				if (q <= x->times[x->ntimes - 1] * 1.0001)
					break;
				x->times[x->ntimes++] = q;
			}
		}
		x->e++;
		break;
	}
	}
	if (x->state != EX_RUNNING)
		return;
	if (x->have_t0 && x->e >= x->ntimes) {
		commit_point(x, now);
		return;
	}
	x->wake = now;
}

static void run_acq(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	if (x->shot_in_flight) {
		int r = x->ops.spectro_fetch(x->octx, x->frame, now, &err);
		if (r < 0) {
			fault(x, EX_DEV_SPECTRO, &err);
			return;
		}
		if (r == 0) {
			x->wake = now + x->cfg.poll_s;
			return;
		}
		x->shot_in_flight = false;
		after_shot(x, now);
		return;
	}
	if (!x->have_t0) {
		if (x->cfg.fixed_integration) {
			x->have_t0 = true;
			x->times[0] = x->cfg.fixed_ms;
			x->ntimes = 1;
			x->e = 0;
		} else {
			if (x->probe_no == 0)
				x->t_probe = x->t_last;
			x->probe_no++;
			start_shot(x, SHOT_PROBE, x->t_probe, now);
			return;
		}
	}
	double t = x->times[x->e];
	enum exp_dark_need need = exp_dark_check(x->darks, &x->cfg.pol, t, now, x->temperature);
	if (need != EXP_DARK_FRESH) {
		start_shot(x, SHOT_DARK, t, now);
		return;
	}
	start_shot(x, SHOT_EXPOSE, t, now);
}

static int put_spectrum(struct ex *x, const struct pending *p, int64_t point_id, bool completes, int64_t *id,
			struct acq_err *err)
{
	static _Thread_local float counts[SPECTRO_MAX_PIXELS];
	const struct spectro_frame *f = p->frame;
	for (int i = 0; i < f->npix; i++)
		counts[i] = (float)f->counts[i];
	struct store_spectrum sp = {
		.sweep_id = x->sweep_id,
		.point_id = point_id,
		.kind = p->kind,
		.spectrometer_id = x->spectro_id,
		.integration_ms = f->meas.integration_ms,
		.averages = (int)(f->meas.averages ? f->meas.averages : 1),
		.npix = f->npix,
		.counts = counts,
		.stddev = f->stddev,
		.saturated_count = f->nsaturated,
		.saturated = f->saturated,
		.temperature_c = f->temperature_c,
		.taken_at = p->taken_at,
		.completes_point = completes,
		.laser_theta = x->actual.laser_theta,
		.detector_theta = x->actual.det_theta,
		.detector_phi = x->actual.det_phi,
	};
	return store_spectrum_add(x->st, &sp, id, err);
}

static void progress(struct ex *x, double now)
{
	double dt = now - x->point_started;
	x->point_avg_s = isfinite(x->point_avg_s) ? 0.9 * x->point_avg_s + 0.1 * dt : dt;
	double eta = x->point_avg_s * (x->nsteps - x->cur);
	if (x->sink.progress)
		x->sink.progress(x->sink.ctx, x->sweep_id, x->stats.points_done, x->nsteps, eta, x->phase_text);
}

static void finish_sweep(struct ex *x)
{
	struct acq_err err = { 0 };
	laser_off(x, &err);
	x->state = EX_COMPLETED;
	x->phase = PH_NONE;
	set_phase_text(x, "completed");
	set_db_state(x, "completed");
	event(x, "complete", NULL, "all %d points measured and calibrated (%s method); %d faults, %d recovered",
	      x->nsteps, calib_method_name(x->cfg.cal.method), x->stats.faults, x->stats.recoveries);
}

/* The point's exposures are in: merge, check saturation, calibrate, commit, go on. */
static void commit_point(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	const struct exp_rate *list[EX_MAX_TIMES];
	for (int i = 0; i < x->ntimes; i++)
		list[i] = x->rates[i];
	if (exp_merge(list, x->ntimes, x->merged, &err)) {
		ex_failed(x, "merge: %s", err.msg);
		return;
	}
	x->stats.merges++;
	mask_black(x, x->merged);
	int bad = 0;
	for (int p = 0; p < x->merged->npix; p++)
		bad += x->roi[p] && !x->merged->valid[p];
	x->t_last = x->times[0];
	if (x->nroi > 0 && bad > x->cfg.max_invalid_frac * x->nroi) {
		if (x->times[0] > x->cfg.pol.min_ms * 1.0001 && ++x->attempts < x->cfg.max_point_attempts) {
			/* Saturated even at the shortest exposure: something changed (or a burst); probe again. */
			x->stats.saturated_redos++;
			event(x, "info", dev_names[EX_DEV_SPECTRO],
			      "%d of %d pixels saturated at %.3g ms: measuring the point again", bad, x->nroi, x->times[0]);
			double t0 = x->times[0];
			drop_exposures(x);
			x->t_last = fmax(x->cfg.pol.min_ms, t0 / x->cfg.pol.max_step);
			x->wake = now;
			return;
		}
		event(x, "info", dev_names[EX_DEV_SPECTRO],
		      "%d of %d pixels saturated at the shortest usable exposure %.3g ms: they stay unmeasured", bad,
		      x->nroi, x->times[0]);
	} else if (!x->cfg.fixed_integration && x->times[0] < x->cfg.pol.max_ms / 1.0001 &&
		   x->attempts + 1 < x->cfg.max_point_attempts) {
		/* Far below the target: the probe was misled (a transient, e.g. a saturation burst): probe again
		 * from this exposure, which extrapolates to the right time. */
		double peak = 0;
		for (int p = 0; p < x->rates[0]->npix; p++)
			if (x->roi[p] && x->rates[0]->valid[p] && x->rates[0]->rate[p] > peak)
				peak = x->rates[0]->rate[p];
		double target = x->cfg.pol.target_frac * full_scale(x);
		if (peak * x->times[0] < 0.2 * target && x->nroi > 0) {
			x->attempts++;
			x->stats.saturated_redos++;
			event(x, "info", dev_names[EX_DEV_SPECTRO],
			      "exposure %.3g ms reached %.0f counts, far below the target %.0f: measuring the point again",
			      x->times[0], peak * x->times[0], target);
			double t0 = x->times[0];
			drop_exposures(x);
			x->t_last = t0;
			x->wake = now;
			return;
		}
	}
	if (x->in_reference) {
		int64_t first = 0, last = 0;
		for (int i = 0; i < x->npend; i++) {
			int64_t id = 0;
			if (put_spectrum(x, &x->pend[i], 0, false, &id, &err)) {
				ex_failed(x, "storing the reference: %s", err.msg);
				return;
			}
			if (!first)
				first = id;
			last = id;
			x->stats.spectra++;
		}
		/* Paused in the store before the marker: a crash in between measures the reference again. */
		if (x->cfg.pause_after_reference)
			set_db_state(x, "paused");
		memcpy(x->ref_rate, x->merged, sizeof *x->ref_rate);
		x->have_ref = true;
		x->cfg.cal.ref_theta_o_deg = fabs(x->actual.det_theta);
		x->in_reference = false;
		clear_pending(x);
		event(x, "reference", NULL, "%s measured at (%.4f, %.4f, %.4f): spectra %lld-%lld",
		      x->cfg.cal.method == CALIB_ABSOLUTE ? "direct beam" : "white reference", x->actual.laser_theta,
		      x->actual.det_theta, x->actual.det_phi, (long long)first, (long long)last);
		if (x->cfg.pause_after_reference) {
			pause_now(x, false, "%s measured: place the sample on the stage, then resume",
				  x->cfg.cal.method == CALIB_ABSOLUTE ? "direct beam" : "reference");
			return;
		}
		if (x->pause_requested) {
			pause_now(x, false, "paused by the operator after the reference");
			return;
		}
		begin_segment(x, now);
		return;
	}
	/* Calibrate at the measured angles. */
	double ti, pi, to, po;
	ex_pos_angles(&x->geom, &x->actual, &ti, &pi, &to, &po);
	struct calib_geom g = { ti, to };
	bool calibrated = false;
	if (x->have_ref) {
		if (calib_spectrum(&x->cfg.cal, x->wl, x->merged, x->ref_rate, &g, x->cal, &err) == 0)
			calibrated = true;
		else
			event(x, "info", NULL, "point %d not calibrated: %s", x->cur, err.msg);
	}
	int oi = -1;
	int64_t pid = 0;
	if (store_sweep_next_point(x->st, x->sweep_id, &oi, &pid, &err)) {
		ex_failed(x, "reading the next point: %s", err.msg);
		return;
	}
	if (oi != x->cur || pid <= 0) {
		ex_failed(x, "the database's next pending point is %d, the executor is at %d", oi, x->cur);
		return;
	}
	for (int i = 0; i + 1 < x->npend; i++) {
		if (put_spectrum(x, &x->pend[i], pid, false, NULL, &err)) {
			ex_failed(x, "storing point %d: %s", x->cur, err.msg);
			return;
		}
		x->stats.spectra++;
	}
	if (calibrated) {
		static _Thread_local float fb[CALIB_MAX_GRID], fs[CALIB_MAX_GRID];
		for (int k = 0; k < x->cal->n; k++) {
			fb[k] = (float)x->cal->f[k];
			fs[k] = (float)x->cal->u[k];
		}
		if (store_calibrated_put(x->st, x->sweep_id, pid, fb, fs, x->cal->n, &err)) {
			ex_failed(x, "storing the calibrated sample of point %d: %s", x->cur, err.msg);
			return;
		}
	}
	if (x->npend > 0) {
		if (put_spectrum(x, &x->pend[x->npend - 1], pid, true, NULL, &err)) {
			ex_failed(x, "completing point %d: %s", x->cur, err.msg);
			return;
		}
		x->stats.spectra++;
	}
	clear_pending(x);
	x->point_faults = 0;
	x->stats.points_done++;
	x->cur++;
	/* Dark schedule (sweep.dark_every): every N points, or whenever the incidence changes. */
	if (x->cur < x->nsteps) {
		bool refresh = x->cfg.dark_every > 0
				       ? x->stats.points_done % x->cfg.dark_every == 0
				       : fabs(x->plan->steps[x->cur].pos.laser_theta - x->plan->steps[x->cur - 1].pos.laser_theta) > 1e-6;
		if (refresh)
			exp_darks_clear(x->darks);
	}
	progress(x, now);
	if (x->cur >= x->nsteps) {
		finish_sweep(x);
		return;
	}
	if (x->pause_requested) {
		pause_now(x, false, "paused by the operator after point %d", x->cur);
		return;
	}
	x->phase = PH_MOVE;
	x->first_move = false;
	x->point_started = now;
	if (x->stats.laser_on && laser_off(x, &err)) {
		fault(x, EX_DEV_LASER, &err);
		return;
	}
	if (plan_path(x)) {
		pause_now(x, false, "no collision-free path to point %d: move the arms and resume", x->cur);
		return;
	}
	set_phase_text(x, "moving");
	begin_waypoints(x, now);
}

/* ---- faults ----------------------------------------------------------------------------------- */

static void run_suspended(struct ex *x, double now)
{
	if (x->retry_at < 0)
		x->retry_at = now + x->backoff;
	if (now + 1e-12 < x->retry_at) {
		x->wake = x->retry_at;
		return;
	}
	struct acq_err err = { 0 };
	x->fault_attempts++;
	x->stats.retries++;
	int dev = x->fault_dev;
	int rc = x->ops.reconnect(x->octx, dev, &err);
	if (rc == 0 && dev == EX_DEV_LASER) {
		bool emission = false, ready = false;
		rc = x->ops.laser_state(x->octx, &emission, &ready, &err);
		if (rc == 0 && !ready)
			rc = acq_errf(&err, ACQ_E_DEVICE, "laser not ready (interlock open or fault)");
	}
	if (rc == 0 && dev == EX_DEV_SPECTRO) {
		x->info = NULL;
		if (!want_wl(x))
			rc = acq_errf(&err, ACQ_E_DISCONNECTED, "spectrometer information unavailable");
	}
	if (rc == 0) {
		x->stats.recoveries++;
		x->state = EX_RUNNING;
		event(x, "recovered", dev_names[dev], "%s answers again after %d attempt%s: point %d restarts", dev_names[dev],
		      x->fault_attempts, x->fault_attempts == 1 ? "" : "s", x->cur);
		begin_segment(x, now);
		return;
	}
	if (x->fault_attempts >= x->cfg.fault_retries) {
		pause_now(x, true, "%s did not come back after %d attempts (%s): paused for the operator", dev_names[dev],
			  x->fault_attempts, err.msg);
		return;
	}
	x->backoff = fmin(x->backoff * 2, x->cfg.fault_backoff_max_s);
	x->retry_at = now + x->backoff;
	x->wake = x->retry_at;
}

double ex_step(struct ex *x, double now)
{
	/* Bounded work per call: a few transitions, then hand back to the loop. */
	for (int guard = 0; guard < 16; guard++) {
		x->wake = INFINITY;
		if (x->state == EX_SUSPENDED) {
			run_suspended(x, now);
		} else if (x->state == EX_RUNNING) {
			switch (x->phase) {
			case PH_VERIFY: run_verify(x, now); break;
			case PH_HOMING: run_homing(x, now); break;
			case PH_MOVE: run_move(x, now); break;
			case PH_SETTLE: run_settle(x, now); break;
			case PH_ACQ: run_acq(x, now); break;
			case PH_NONE: break;
			}
		} else {
			return INFINITY;
		}
		/* A transition that scheduled nothing (e.g. into suspended) runs the new state at once. */
		if (x->wake == INFINITY && (x->state == EX_RUNNING || x->state == EX_SUSPENDED))
			continue;
		if (x->wake > now)
			return x->wake;
	}
	return now;
}

/* ---- configuration and shutdown ---------------------------------------------------------------- */

int ex_cfg_parse(struct yc_node *acq, struct yc_node *cal, struct ex_cfg *c, struct acq_err *err)
{
	struct ex_cfg q = *c;
	if (acq) {
		if (exp_policy_parse(acq, &q.pol, err))
			return -1;
		long long retries = q.fault_retries, attempts = q.max_point_attempts;
		struct yc_node *pose = yc_get(acq, "reference_pose");
		if (yc_bool(acq, "take_reference", false, &q.take_reference, err) ||
		    yc_bool(acq, "pause_after_reference", false, &q.pause_after_reference, err) ||
		    yc_int(acq, "fault_retries", false, 0, 1000, &retries, err) ||
		    yc_double(acq, "fault_backoff_s", false, 0.001, 3600, &q.fault_backoff_s, err) ||
		    yc_double(acq, "fault_backoff_max_s", false, 0.001, 86400, &q.fault_backoff_max_s, err) ||
		    yc_double(acq, "ladder_ratio", false, 1.01, 10, &q.ladder_ratio, err) ||
		    yc_double(acq, "poll_s", false, 1e-4, 10, &q.poll_s, err) ||
		    yc_int(acq, "max_point_attempts", false, 1, 20, &attempts, err) ||
		    yc_double(acq, "max_invalid_frac", false, 0, 1, &q.max_invalid_frac, err) ||
		    yc_bool(acq, "home_unhomed", false, &q.home_unhomed, err) ||
		    yc_double(acq, "laser_power_pct", false, 0, 100, &q.laser_power_pct, err))
			return -1;
		struct yc_node *home = yc_get(acq, "home_deg");
		if (home) {
			if (yc_expect_seq(home, "sweep.acquisition.home_deg", err))
				return -1;
			if (home->n != 3)
				return yc_errf(err, home, "home_deg: expected [laser_theta, detector_theta, detector_phi]");
			for (int i = 0; i < 3; i++)
				if (yc_node_double(home->items[i], "home_deg angle", -360, 720, &q.home_deg[i], err))
					return -1;
		}
		if (pose) {
			double v[3];
			if (yc_expect_seq(pose, "sweep.acquisition.reference_pose", err))
				return -1;
			if (pose->n != 3)
				return yc_errf(err, pose, "reference_pose: expected [laser_theta, detector_theta, detector_phi]");
			for (int i = 0; i < 3; i++)
				if (yc_node_double(pose->items[i], "reference_pose angle", -360, 720, &v[i], err))
					return -1;
			q.ref_pose = (struct plan_pos){ v[0], v[1], v[2] };
		}
		if (yc_check_unknown(acq, "sweep.acquisition", err))
			return -1;
		q.fault_retries = (int)retries;
		q.max_point_attempts = (int)attempts;
	}
	if (cal && calib_cfg_parse(cal, &q.cal, err))
		return -1;
	*c = q;
	return 0;
}

void ex_shutdown(struct ex *x, const char *why)
{
	if (!x || !(x->state == EX_RUNNING || x->state == EX_SUSPENDED || x->state == EX_PAUSED))
		return;
	if (x->state == EX_PAUSED) { /* already paused (and why is in the log): it stays so after the restart */
		safe_stop(x);
		return;
	}
	safe_stop(x);
	reset_acq(x);
	x->state = EX_PAUSED;
	set_db_state(x, "paused");
	event(x, "stop", NULL, "%s: the sweep stays resumable after point %d of %d", why && *why ? why : "daemon stopping",
	      x->cur, x->nsteps);
}

void ex_hold(struct ex *x, const char *why)
{
	if (!x || x->state != EX_RUNNING)
		return;
	pause_now(x, false, "still paused after a restart: %s", why && *why ? why : "paused by the operator");
}
