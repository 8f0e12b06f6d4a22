/* Unit tests for daemon/executor.c on a fake bench with injected time: a full sweep against known truth,
 * pause/resume, abort, device faults (suspend, backoff, recovery, operator pause), saturation bursts and a
 * resume after a simulated crash, all against a real store in a temporary directory. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include <poll.h>
#include <sqlite3.h>
#include <time.h>
#include <stdlib.h>
#include <unistd.h>

/* The test reaches the executor's internals (to simulate a crash) through its private header. */
#include "daemon/executor_int.h"
#include "daemon/plan/plan.h"
#include "daemon/store.h"
#include "drivers/axis.h"
#include "tests/unit/synth.h"
#include "tests/unit/tmpdir.h"

static uint64_t seed;

/* ---- the fake bench ------------------------------------------------------------------------------ */

enum { NPIX = 600 };
enum sample { S_WHITE, S_PAINT };

struct fake {
	struct synth_rng rng;
	double pos[3], start[3], target[3], t0[3], t1[3];
	bool moving[3], homed[3], alarm[3];
	bool homing[3];
	bool emission, interlock_open;
	enum sample sample;
	struct spectro_info info;
	bool shot;
	struct spectro_meas meas;
	double shot_done;
	bool shot_laser;
	/* fault injection */
	bool axis_down[3];        /* every call fails until reconnect after down_until */
	double down_until[3];
	bool spectro_down;
	double spectro_down_until;
	int spectro_fail_next;    /* the next fetch fails (then down until spectro_down_until) */
	int burst;                /* next N spectra saturate */
	int dark_burst;           /* next N darks saturate */
	int interlock_after_shots; /* open the interlock after N more laser shots (0: never) */
	double interlock_close_at;
	/* an alarm on the detector's θ in the first segment that passes within 3° of the planner's collision limit,
	 * leaving the arms where the axes stopped: closer than the limit (ψ between the bodies' sum and the limit) */
	bool squeeze, squeezed;
	struct plan_pos squeeze_at;
	double now;
	/* audit */
	int laser_on_during_motion, laser_on_during_dark;
	int collisions;           /* arms closer than their bodies allow (ψ < laser_body + detector_body) */
	int out_of_limits;        /* move targets outside the axes' soft limits */
	int shots, darks;
	/* the pooled probe (exp_probe_reusable): each laser shot's first exposure after a probe, one scan fewer exactly
	 * when it is at the probe's time and the probe was unsaturated */
	bool after_probe;
	double probe_ms, probe_peak;
	int probe_nsat;
	int pooled_shots, pool_wrong, pool_missed;
	/* reads answer like the daemon's device threads: EX_PENDING first, the result at the next call */
	bool deferred;
	bool waiting[3][EX_DEV__COUNT];
	int pendings;
	/* the laser as the daemon's laser thread runs it: a command takes effect when the next read completes */
	bool laser_lag, lag_pending, lag_on;
	bool laser_silent;        /* reads fail: the laser does not answer */
	/* the store whose commits the moves are checked against (test_commit_overlaps_fsync; NULL: not checked) */
	struct store *st;
	int moves_undurable;      /* moves begun while a commit was not yet on disk */
};

static struct fake F;

/* In deferred mode, every other call of a read (op, dev) is EX_PENDING. */
static bool defer(int op, int dev)
{
	if (!F.deferred)
		return false;
	F.waiting[op][dev] = !F.waiting[op][dev];
	F.pendings += F.waiting[op][dev];
	return F.waiting[op][dev];
}

static double wl_of(int p)
{
	return 440.0 + 1.1 * p;
}

static double albedo(double lam)
{
	return 0.3 + 0.15 * sin(lam / 90.0); /* the "paint": f = albedo/π · (1 + 0.3 cos θi cos θo) */
}

static double f_paint(double lam, double ti, double to)
{
	return albedo(lam) / M_PI * (1 + 0.3 * cos(ti * M_PI / 180) * cos(to * M_PI / 180));
}

#define RHO_WHITE 0.98
#define K_BEAM 2e5

static double source(double lam)
{
	return 0.5 + 0.5 * exp(-0.5 * ((lam - 650) / 200) * ((lam - 650) / 200));
}

static int f_move_begin(void *ctx, int a, double target, double now, struct acq_err *err)
{
	(void)ctx;
	if (F.axis_down[a])
		return acq_errf(err, ACQ_E_TIMEOUT, "axis %d: no answer", a);
	if (a == 2 && (target < -179 || target > 359)) {
		F.out_of_limits++;
		return acq_errf(err, ACQ_E_RANGE, "detector.phi: target %g outside [-179, 359]", target);
	}
	if (F.emission)
		F.laser_on_during_motion++;
	if (F.st && store_durable(F.st, store_commit_mark(F.st), NULL) == 0)
		F.moves_undurable++;
	F.start[a] = F.pos[a];
	F.target[a] = target;
	F.t0[a] = now;
	F.t1[a] = now + fabs(target - F.pos[a]) / 200.0 + 0.01;
	F.moving[a] = true;
	return 0;
}

static struct bench_geom geom;

static void check_collision(void)
{
	struct plan_pos p = { F.pos[0], F.pos[1], F.pos[2] };
	if (plan_psi_deg(&geom, &p) < geom.laser_body_halfwidth_deg + geom.detector_body_halfwidth_deg)
		F.collisions++;
}

/* The squeeze: the detector's stop nearest to where it is (θ and φ within 3°, 0.25° steps) with the arms
 * closer than the planner allows but not touching (ψ 0.2° inside both bounds); true when it fired. */
static bool squeeze_stop(void)
{
	double lo = geom.laser_body_halfwidth_deg + geom.detector_body_halfwidth_deg + 0.2;
	double hi = plan_collision_deg(&geom) - 0.2, best = INFINITY;
	struct plan_pos p = { F.pos[0], 0, 0 }, at = p;
	for (int i = -12; i <= 12; i++)
		for (int j = -12; j <= 12; j++) {
			p.det_theta = F.pos[1] + 0.25 * i;
			p.det_phi = F.pos[2] + 0.25 * j;
			double psi = plan_psi_deg(&geom, &p), d = i * i + j * j;
			if (psi > lo && psi < hi && d < best && p.det_theta >= 0 && p.det_theta <= 90) {
				best = d;
				at = p;
			}
		}
	if (!(best < INFINITY))
		return false;
	F.pos[1] = at.det_theta;
	F.pos[2] = at.det_phi;
	F.moving[1] = F.moving[2] = false;
	F.alarm[1] = true;
	F.squeezed = true;
	F.squeeze_at = at;
	return true;
}

static int f_move_step(void *ctx, int a, double now, struct acq_err *err)
{
	(void)ctx;
	if (F.axis_down[a])
		return acq_errf(err, ACQ_E_TIMEOUT, "axis %d: no answer", a), AXIS_MOVE_FAILED;
	if (F.emission)
		F.laser_on_during_motion++;
	if (F.homing[a]) {
		if (now >= F.t1[a]) {
			F.homing[a] = false;
			F.homed[a] = true;
			F.pos[a] = F.target[a];
			return AXIS_MOVE_DONE;
		}
		return AXIS_MOVE_RUNNING;
	}
	if (!F.moving[a])
		return AXIS_MOVE_DONE;
	if (now >= F.t1[a]) {
		F.pos[a] = F.target[a];
		F.moving[a] = false;
		return AXIS_MOVE_DONE;
	}
	F.pos[a] = F.start[a] + (F.target[a] - F.start[a]) * (now - F.t0[a]) / (F.t1[a] - F.t0[a]);
	check_collision();
	if (a == 1 && F.squeeze && !F.squeezed && squeeze_stop())
		return acq_errf(err, ACQ_E_DEVICE, "detector.theta: controller alarm 0xe0 mid-move"), AXIS_MOVE_FAILED;
	return AXIS_MOVE_RUNNING;
}

static double f_next_poll(void *ctx, int a)
{
	(void)ctx;
	return F.moving[a] || F.homing[a] ? fmin(F.t1[a], F.now + 0.02) : F.now;
}

static int f_stop(void *ctx, int a, struct acq_err *err)
{
	(void)ctx;
	(void)err;
	F.moving[a] = F.homing[a] = false;
	return 0;
}

static int f_position(void *ctx, int a, double *deg, bool *homed, bool *alarm, struct acq_err *err)
{
	(void)ctx;
	if (defer(0, a))
		return EX_PENDING;
	if (F.axis_down[a])
		return acq_errf(err, ACQ_E_TIMEOUT, "axis %d: no answer", a);
	*deg = F.pos[a];
	*homed = F.homed[a];
	*alarm = F.alarm[a];
	return 0;
}

static int f_home_begin(void *ctx, int a, double now, struct acq_err *err)
{
	(void)ctx;
	(void)err;
	F.homing[a] = true;
	F.target[a] = a == 1 ? 60 : a == 2 ? 180 : 0; /* the fake's home switches keep the arms apart */
	F.t1[a] = now + 0.5;
	return 0;
}

static int f_alarm_reset(void *ctx, int a, struct acq_err *err)
{
	(void)ctx;
	(void)err;
	F.alarm[a] = false;
	return 0;
}

static int f_reconnect(void *ctx, int dev, struct acq_err *err)
{
	(void)ctx;
	if (defer(1, dev))
		return EX_PENDING;
	if (dev <= 2) {
		if (F.axis_down[dev] && F.now >= F.down_until[dev])
			F.axis_down[dev] = false;
		return F.axis_down[dev] ? acq_errf(err, ACQ_E_TIMEOUT, "still down") : 0;
	}
	if (dev == EX_DEV_SPECTRO) {
		if (F.spectro_down && F.now >= F.spectro_down_until)
			F.spectro_down = false;
		return F.spectro_down ? acq_errf(err, ACQ_E_DISCONNECTED, "no spectrometer") : 0;
	}
	if (F.interlock_open && F.interlock_close_at > 0 && F.now >= F.interlock_close_at)
		F.interlock_open = false;
	return 0;
}

static int f_laser_set(void *ctx, bool on, struct acq_err *err)
{
	(void)ctx;
	if (on && F.interlock_open) {
		F.emission = false;
		return acq_errf(err, ACQ_E_DEVICE, "interlock open");
	}
	if (F.laser_lag) {
		F.lag_pending = true;
		F.lag_on = on;
		return 0;
	}
	F.emission = on;
	return 0;
}

static int f_laser_state(void *ctx, bool *emission, bool *ready, struct acq_err *err)
{
	(void)ctx;
	(void)err;
	if (defer(2, EX_DEV_LASER))
		return EX_PENDING;
	if (F.laser_silent)
		return acq_errf(err, ACQ_E_TIMEOUT, "no reply to 'STATUS?' (test)");
	if (F.lag_pending) {
		F.emission = F.lag_on;
		F.lag_pending = false;
	}
	if (F.interlock_open && F.interlock_close_at > 0 && F.now >= F.interlock_close_at)
		F.interlock_open = false;
	*emission = F.emission;
	*ready = !F.interlock_open;
	return 0;
}

static int f_spectro_start(void *ctx, const struct spectro_meas *m, double now, struct acq_err *err)
{
	(void)ctx;
	if (F.spectro_down)
		return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer gone");
	F.shot = true;
	F.meas = *m;
	F.shot_done = now + m->integration_ms * 1e-3 * m->averages + 0.002;
	F.shot_laser = F.emission;
	if (!F.emission)
		F.darks++;
	else
		F.shots++;
	if (F.emission && m->averages == 1) {
		F.after_probe = true;
		F.probe_ms = m->integration_ms;
	} else if (F.emission && F.after_probe) {
		F.after_probe = false;
		bool same = fabs(m->integration_ms - F.probe_ms) <= 1e-9 * F.probe_ms;
		bool clean = F.probe_nsat == 0 && F.probe_peak < 0.9 * 65535;
		if (m->averages == 3) { /* cfg_for_test: 4 averages */
			F.pooled_shots++;
			F.pool_wrong += !same || F.probe_nsat > 0;
		} else
			F.pool_missed += same && clean;
	}
	for (int a = 0; a < 3; a++)
		if (F.moving[a])
			F.laser_on_during_motion += F.emission;
	if (F.emission && F.interlock_after_shots > 0 && --F.interlock_after_shots == 0) {
		F.interlock_open = true; /* opens during this exposure */
		F.emission = false;
		F.interlock_close_at = now + 1.0;
	}
	return 0;
}

static double rate_at(int p)
{
	double lam = wl_of(p);
	double ti = fabs(F.pos[0]), to = fabs(F.pos[1]);
	double omega = 1e-3;
	double f = F.sample == S_WHITE ? RHO_WHITE / M_PI : f_paint(lam, ti, to);
	return K_BEAM * source(lam) * f * cos(to * M_PI / 180) * omega;
}

static int f_spectro_fetch(void *ctx, struct spectro_frame *fr, double now, struct acq_err *err)
{
	(void)ctx;
	if (F.spectro_fail_next) {
		F.spectro_fail_next = 0;
		F.spectro_down = true;
		F.shot = false;
		return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer vanished");
	}
	if (!F.shot)
		return acq_errf(err, ACQ_E_STATE, "no measurement");
	if (now < F.shot_done)
		return 0;
	F.shot = false;
	double t = F.meas.integration_ms;
	unsigned n = F.meas.averages;
	bool lit = F.shot_laser && F.emission;
	bool burst = F.burst > 0; /* like acq-sim: a burst saturates whatever is measured, darks included */
	if (burst)
		F.burst--;
	if (!lit && F.dark_burst > 0) {
		F.dark_burst--;
		burst = true;
	}
	memset(fr, 0, sizeof *fr);
	fr->npix = NPIX;
	fr->meas = F.meas;
	fr->temperature_c = 5.0;
	for (int p = 0; p < NPIX; p++) {
		double sig = lit ? rate_at(p) * t : 0.0;
		double m = 1000 + 0.05 * t + sig;
		double sd = sqrt(64 + sig + 0.05 * t);
		if (burst || m + 3 * sd >= SPECTRO_SATURATED) {
			fr->counts[p] = 65535;
			fr->saturated[p] = 1;
			fr->nsaturated++;
			continue;
		}
		fr->counts[p] = m + sd / sqrt(n) * synth_gauss(&F.rng);
		double chi = 0;
		for (unsigned k = 1; k < n; k++) {
			double g = synth_gauss(&F.rng);
			chi += g * g;
		}
		fr->stddev[p] = n > 1 ? (float)(sd * sqrt(chi / (n - 1))) : 0.0f;
	}
	if (lit && n == 1) {
		F.probe_nsat = fr->nsaturated;
		F.probe_peak = 0;
		for (int p = 0; p < NPIX; p++)
			F.probe_peak = fmax(F.probe_peak, fr->counts[p]);
	}
	return 1;
}

static int f_spectro_stop(void *ctx, struct acq_err *err)
{
	(void)ctx;
	(void)err;
	F.shot = false;
	return 0;
}

static const struct spectro_info *f_info(void *ctx)
{
	(void)ctx;
	return F.spectro_down ? NULL : &F.info;
}

static void f_limits(void *ctx, int a, double *lo, double *hi)
{
	(void)ctx;
	*lo = a == 2 ? -179 : -5;
	*hi = a == 2 ? 359 : 90;
}

static double f_wall(void *ctx)
{
	(void)ctx;
	return 1.7e9 + F.now;
}

static const struct ex_ops fake_ops = {
	.move_begin = f_move_begin, .move_step = f_move_step, .next_poll = f_next_poll, .stop = f_stop,
	.position = f_position, .home_begin = f_home_begin, .alarm_reset = f_alarm_reset, .reconnect = f_reconnect,
	.laser_set = f_laser_set, .laser_state = f_laser_state, .spectro_start = f_spectro_start,
	.spectro_fetch = f_spectro_fetch, .spectro_stop = f_spectro_stop, .spectro_info = f_info, .wall = f_wall,
	.limits = f_limits,
};

/* ---- sink ---------------------------------------------------------------------------------------- */

static char events[256][64];
static int nevents;

static int backoffs; /* "backing off" events */

static void sink_event(void *ctx, int64_t sweep_id, const char *kind, const char *device, const char *message)
{
	(void)ctx;
	(void)sweep_id;
	backoffs += strstr(message, "backing off") != NULL;
	if (nevents < 256)
		snprintf(events[nevents++], sizeof events[0], "%s", kind);
	print_message("  event %s%s%s: %s\n", kind, device ? " " : "", device ? device : "", message);
}

static int count_events(const char *kind)
{
	int n = 0;
	for (int i = 0; i < nevents; i++)
		n += !strcmp(events[i], kind);
	return n;
}

static const struct ex_sink sink = { .event = sink_event };

/* ---- harness ------------------------------------------------------------------------------------- */

static char dir[256], dbpath[300];
static struct plan_result *plan;

static const char *plan_text = "name: small\n"
			       "incidence:\n  theta_deg: [0, 30, 50]\n"
			       "observation:\n  theta_deg: [10, 40, 65]\n  phi_deg: [0, 90, 180, 270]\n"
			       "integration: {mode: auto, target_peak: 0.8, estimate_ms: 10, max_ms: 2000}\n"
			       "averages: 4\nblind_points: drop\n";

static void fake_reset(void)
{
	memset(&F, 0, sizeof F);
	F.rng.s = seed;
	F.pos[0] = 0;
	F.pos[1] = 60;
	F.pos[2] = 180;
	for (int a = 0; a < 3; a++)
		F.homed[a] = true;
	F.sample = S_WHITE;
	snprintf(F.info.model, sizeof F.info.model, "fake");
	F.info.npix = NPIX;
	F.info.wl_coef[0] = 440;
	F.info.wl_coef[1] = 1.1;
	F.info.max_counts = 65535;
	nevents = 0;
	backoffs = 0;
}

static void cfg_for_test(struct ex_cfg *c)
{
	ex_cfg_defaults(c);
	c->pol.min_ms = 0.05;
	c->pol.max_ms = 2000;
	c->pol.probe_ms = 10;
	c->pol.averages = 4;
	c->pol.dark_averages = 4;
	c->pol.max_exposures = 2;
	c->cal.method = CALIB_RELATIVE;
	c->cal.rho_ref.val[0] = RHO_WHITE;
	c->cal.rho_ref.u[0] = 0.0; /* the fake reference is exactly RHO_WHITE: only measured terms remain */
	c->cal.ref_theta_o_deg = NAN;
	c->cal.grid_min_nm = 450;
	c->cal.grid_max_nm = 1000;
	c->cal.grid_step_nm = 5;
	c->fault_backoff_s = 0.2;
	c->fault_backoff_max_s = 1.0;
	c->fault_retries = 4;
	c->home_unhomed = true; /* the fake homes to (0, 60, 180): clear of each other */
	c->home_deg[0] = 0;
	c->home_deg[1] = 60;
	c->home_deg[2] = 180;
}

static int64_t new_sweep(struct store *st)
{
	struct store_point_new *pts = calloc(plan->n_steps, sizeof *pts);
	for (size_t i = 0; i < plan->n_steps; i++) {
		pts[i].order_index = (int)i;
		ex_pos_angles(&geom, &plan->steps[i].pos, &pts[i].theta_i, &pts[i].phi_i, &pts[i].theta_o, &pts[i].phi_o);
	}
	struct store_sweep_new sw = { .name = "t", .plan_text = plan_text, .config_snapshot = "{}",
				      .software_version = "test", .calibration_method = "relative", .created_at = 1.7e9 };
	int64_t id = 0;
	struct acq_err err = { 0 };
	assert_int_equal(store_sweep_create(st, &sw, pts, (int)plan->n_steps, &id, &err), 0);
	free(pts);
	return id;
}

/* Run the executor until it stops or until `until` (injected time); on a pause after the reference, swap
 * the sample and resume. Returns the final time. */
static double drive(struct ex *x, double now, double until, bool swap_on_pause)
{
	struct acq_err err = { 0 };
	for (long it = 0; it < 5000000 && now < until; it++) {
		F.now = now;
		double next = ex_step(x, now);
		enum ex_state s = ex_state(x);
		if (s == EX_PAUSED && swap_on_pause && F.sample == S_WHITE && strstr(ex_reason(x), "place the sample")) {
			F.sample = S_PAINT;
			assert_int_equal(ex_resume(x, now, &err), 0);
			continue;
		}
		if (s != EX_RUNNING && s != EX_SUSPENDED)
			break;
		if (!(next < INFINITY))
			break;
		now = next > now ? next : now + 1e-6;
	}
	F.now = now;
	return now;
}

static struct store *open_store(void)
{
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(dbpath, &st, &err), 0);
	return st;
}

/* A started sweep: a new sweep of the plan in a fresh store and its executor, started at point 0 at time 0 with
 * cfg_for_test's configuration (the pause after the reference as asked); the fake's state F is the caller's to set
 * first. Returns the executor (also in r->x). */
struct run {
	struct store *st;
	int64_t sweep;
	struct ex_cfg cfg;
	struct ex *x;
};

static struct ex *start_sweep(struct run *r, bool pause_after_reference)
{
	struct acq_err err = { 0 };
	r->st = open_store();
	r->sweep = new_sweep(r->st);
	cfg_for_test(&r->cfg);
	r->cfg.pause_after_reference = pause_after_reference;
	r->x = ex_new(&r->cfg, &fake_ops, NULL, &sink, r->st, r->sweep, 0, &geom, plan, &err);
	assert_non_null(r->x);
	assert_int_equal(ex_start(r->x, 0, false, 0, &err), 0);
	return r->x;
}

static long long q1(sqlite3 *db, const char *sql, int64_t sweep)
{
	sqlite3_stmt *s = NULL;
	assert_int_equal(sqlite3_prepare_v2(db, sql, -1, &s, NULL), SQLITE_OK);
	if (sqlite3_bind_parameter_count(s) > 0)
		sqlite3_bind_int64(s, 1, sweep);
	long long v = -1;
	if (sqlite3_step(s) == SQLITE_ROW)
		v = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	return v;
}

/* Every planned point done exactly once with a calibrated sample, every value within its uncertainty of the
 * truth (z-scores), integrity ok. */
static void check_db(int64_t sweep, bool zcheck)
{
	sqlite3 *db = NULL;
	assert_int_equal(sqlite3_open_v2(dbpath, &db, SQLITE_OPEN_READONLY, NULL), SQLITE_OK);
	long long n = (long long)plan->n_steps;
	assert_int_equal(q1(db, "SELECT count(*) FROM points WHERE sweep_id = ? AND state = 'done'", sweep), n);
	/* every exposure stored with the policy's 4 scans (a pooled probe's among them) */
	assert_int_equal(q1(db, "SELECT count(*) FROM spectra WHERE sweep_id = ? AND kind != 'dark' AND averages != 4",
			    sweep), 0);
	assert_int_equal(q1(db, "SELECT count(*) FROM calibrated WHERE sweep_id = ?", sweep), n);
	/* exactly one completing exposure per point: samples of a point come from one acquisition */
	assert_int_equal(q1(db, "SELECT count(*) FROM points p WHERE sweep_id = ? AND "
				"(SELECT count(*) FROM spectra s WHERE s.point_id = p.id AND s.kind = 'sample') NOT BETWEEN 1 AND 2",
			    sweep), 0);
	sqlite3_stmt *s = NULL;
	assert_int_equal(sqlite3_prepare_v2(db, "SELECT result FROM (SELECT integrity_check AS result FROM "
						"pragma_integrity_check)", -1, &s, NULL), SQLITE_OK);
	assert_int_equal(sqlite3_step(s), SQLITE_ROW);
	assert_string_equal((const char *)sqlite3_column_text(s, 0), "ok");
	sqlite3_finalize(s);
	if (zcheck) {
		assert_int_equal(sqlite3_prepare_v2(db, "SELECT p.theta_i, p.theta_o, c.brdf, c.sigma FROM calibrated c "
							"JOIN points p ON p.id = c.point_id WHERE c.sweep_id = ?",
						    -1, &s, NULL), SQLITE_OK);
		sqlite3_bind_int64(s, 1, sweep);
		double sz = 0, sz2 = 0;
		long nz = 0, nan = 0;
		while (sqlite3_step(s) == SQLITE_ROW) {
			double ti = sqlite3_column_double(s, 0), to = sqlite3_column_double(s, 1);
			const float *b = sqlite3_column_blob(s, 2), *u = sqlite3_column_blob(s, 3);
			int nb = sqlite3_column_bytes(s, 2) / 4;
			assert_int_equal(nb, 111);
			for (int k = 0; k < nb; k++) {
				double lam = 450 + 5 * k;
				/* truth of a 5 nm bin: mean over its pixels (1.1 nm apart) */
				double sum = 0;
				int m = 0;
				for (int p = 0; p < NPIX; p++)
					if (wl_of(p) >= lam - 2.5 && wl_of(p) < lam + 2.5)
						sum += f_paint(wl_of(p), ti, to), m++;
				if (!isfinite(b[k])) {
					nan++;
					continue;
				}
				double z = (b[k] - sum / m) / u[k];
				sz += z;
				sz2 += z * z;
				nz++;
			}
		}
		sqlite3_finalize(s);
		double mean = sz / nz, var = sz2 / nz - mean * mean;
		print_message("  calibrated vs truth: %ld values, %ld NaN, z mean %.3f, var %.3f\n", nz, nan, mean, var);
		assert_int_equal(nan, 0);
		assert_true(fabs(mean) < 0.3);
		/* 4 scans per spectrum: the per-pixel std is a rough estimate (t-like tails), and the one reference
		 * is common to every point; measured 0.9-1.2 over seeds */
		assert_true(var > 0.7 && var < 1.5);
	}
	sqlite3_close(db);
}

static int setup(void **state)
{
	(void)state;
	assert_int_equal(ut_tmpdir_make(dir, sizeof dir, "test_executor"), 0);
	snprintf(dbpath, sizeof dbpath, "%s/acq.db", dir);
	unlink(dbpath);
	fake_reset();
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	return ut_tmpdir_remove(dir);
}

/* A whole sweep on the fake bench; deferred: every read answers one step late (as the daemon's device threads
 * do), with an alarm on the detector arm reset and read again first. */
static void full_sweep(bool deferred)
{
	F.deferred = deferred;
	F.alarm[1] = deferred;
	struct run r;
	struct ex *x = start_sweep(&r, true);
	double t = drive(x, 0, 1e5, true);
	print_message("  finished at t=%.1f s: %s %s\n", t, ex_state_name(ex_state(x)), ex_reason(x));
	assert_int_equal(ex_state(x), EX_COMPLETED);
	const struct ex_stats *s = ex_stats(x);
	print_message("  %d points, %d spectra, %d darks, %d probes, %d exposures, %d reads deferred\n", s->points_done,
		      s->spectra, s->darks, s->probes, s->exposures, F.pendings);
	assert_int_equal(s->points_done, (int)plan->n_steps);
	assert_int_equal(F.laser_on_during_motion, 0);
	assert_int_equal(s->laser_on_while_moving, 0);
	assert_int_equal(F.laser_on_during_dark, 0);
	assert_int_equal(F.collisions, 0);
	assert_int_equal(F.out_of_limits, 0);
	assert_false(F.emission); /* off when completed */
	assert_false(F.alarm[1]);
	assert_true(s->darks < s->points_done);     /* darks are reused across points */
	assert_true(s->probes < 2 * s->points_done); /* the previous time seeds the next probe */
	/* a probe at its exposure's time was one of its scans: the exposure took 3 of the 4 averages, never at another
	 * time or after a saturated probe, always when it could; stored as the 4 scans (check_db's z-scores: the
	 * calibrated values stay within their σ of the truth) */
	print_message("  %d probes pooled into their exposure\n", s->probes_pooled);
	assert_true(s->probes_pooled > 0);
	assert_int_equal(F.pooled_shots, s->probes_pooled);
	assert_int_equal(F.pool_wrong, 0);
	assert_int_equal(F.pool_missed, 0);
	if (deferred)
		assert_true(F.pendings > 3 * s->points_done); /* positions after each move, laser checks after each shot */
	assert_int_equal(count_events("reference"), 1);
	assert_int_equal(count_events("complete"), 1);
	ex_free(x, t);
	store_close(r.st);
	check_db(r.sweep, true);
}

static void test_full_sweep(void **state)
{
	(void)state;
	full_sweep(false);
}

/* The same sweep with every read answering one step late. */
static void test_full_sweep_deferred_reads(void **state)
{
	(void)state;
	full_sweep(true);
}

/* The dark schedule, one whole sweep each: with dark_every 0 the cache is cleared at each new incidence, so some
 * integration time's dark is taken again there; with -1 (darks by age and temperature only: the laser is off for a
 * dark, the incidence does not enter it) each time's dark is taken once (ages beyond the sweep here) and serves the
 * later incidences, fewer darks in all, and the calibrated samples stay within their uncertainty of the truth
 * (check_db's z-scores) with darks taken at other incidences. Returns the darks taken; *again: the times that had
 * more than one dark. */
static int sweep_darks(int dark_every, int *again)
{
	fake_reset();
	unlink(dbpath);
	struct run r;
	struct acq_err err = { 0 };
	r.st = open_store();
	r.sweep = new_sweep(r.st);
	cfg_for_test(&r.cfg);
	r.cfg.pause_after_reference = true;
	r.cfg.dark_every = dark_every;
	r.cfg.pol.dark_max_age_s = 1e6;
	r.x = ex_new(&r.cfg, &fake_ops, NULL, &sink, r.st, r.sweep, 0, &geom, plan, &err);
	assert_non_null(r.x);
	assert_int_equal(ex_start(r.x, 0, false, 0, &err), 0);
	double t = drive(r.x, 0, 1e5, true);
	assert_int_equal(ex_state(r.x), EX_COMPLETED);
	int darks = ex_stats(r.x)->darks;
	ex_free(r.x, t);
	store_close(r.st);
	sqlite3 *db = NULL;
	assert_int_equal(sqlite3_open_v2(dbpath, &db, SQLITE_OPEN_READONLY, NULL), SQLITE_OK);
	*again = (int)q1(db, "SELECT count(*) FROM (SELECT integration_ms FROM spectra WHERE sweep_id = ? AND "
			     "kind = 'dark' AND point_id IS NOT NULL GROUP BY integration_ms HAVING count(*) > 1)", r.sweep);
	int stored = (int)q1(db, "SELECT count(*) FROM spectra WHERE sweep_id = ? AND kind = 'dark' AND "
				 "point_id IS NOT NULL", r.sweep);
	sqlite3_close(db);
	print_message("  dark_every %d: %d darks (%d stored with a point), %d times taken more than once\n", dark_every,
		      darks, stored, *again);
	check_db(r.sweep, true);
	return stored;
}

static void test_dark_schedule(void **state)
{
	(void)state;
	int again0, again1;
	int per_incidence = sweep_darks(0, &again0), kept = sweep_darks(-1, &again1);
	assert_true(again0 > 0);
	assert_int_equal(again1, 0);
	assert_true(kept < per_incidence);
}

static void test_pause_resume_abort(void **state)
{
	(void)state;
	F.sample = S_PAINT; /* the reference is then wrong, which does not matter here */
	struct run r;
	struct ex *x = start_sweep(&r, false);
	struct acq_err err = { 0 };
	double t = 0;
	while (ex_current_step(x) < 3) {
		F.now = t;
		double nx = ex_step(x, t);
		t = nx > t ? nx : t + 1e-6;
	}
	assert_int_equal(ex_pause(x, t, &err), 0);
	int at = ex_current_step(x);
	t = drive(x, t, 1e5, false);
	assert_int_equal(ex_state(x), EX_PAUSED);
	assert_true(ex_current_step(x) == at + 1 || ex_current_step(x) == at); /* finishes the point in hand */
	assert_false(F.emission);
	ex_shutdown(x, "test"); /* a daemon stop while paused keeps the pause (and its reason) as the last word */
	assert_int_equal(count_events("stop"), 0);
	assert_int_equal(ex_state(x), EX_PAUSED);
	assert_int_equal(ex_resume(x, t, &err), 0);
	assert_int_equal(ex_state(x), EX_RUNNING);
	for (int i = 0; i < 200; i++) {
		F.now = t;
		double nx = ex_step(x, t);
		t = nx > t ? nx : t + 1e-6;
	}
	ex_shutdown(x, "test stop"); /* running: stops, paused in the store with a 'stop' event */
	assert_int_equal(count_events("stop"), 1);
	assert_int_equal(ex_state(x), EX_PAUSED);
	assert_false(F.emission);
	assert_int_equal(ex_abort(x, "test abort", t, &err), 0);
	assert_int_equal(ex_state(x), EX_ABORTED);
	assert_false(F.emission);
	for (int a = 0; a < 3; a++)
		assert_false(F.moving[a]);
	assert_int_equal(ex_abort(x, "again", t, &err), -1);
	assert_int_equal(err.code, ACQ_E_STATE);
	assert_int_equal(count_events("abort"), 1);
	ex_free(x, t);
	store_close(r.st);
	sqlite3 *db = NULL;
	sqlite3_open(dbpath, &db);
	sqlite3_stmt *s = NULL;
	sqlite3_prepare_v2(db, "SELECT state FROM sweeps WHERE id = ?", -1, &s, NULL);
	sqlite3_bind_int64(s, 1, r.sweep);
	assert_int_equal(sqlite3_step(s), SQLITE_ROW);
	assert_string_equal((const char *)sqlite3_column_text(s, 0), "aborted");
	sqlite3_finalize(s);
	sqlite3_close(db);
}

/* Faults of each device during a sweep: the sweep suspends, recovers by itself and completes, with every
 * point once; a device that stays away pauses the sweep for the operator, who resumes it. */
static void test_faults(void **state)
{
	(void)state;
	struct run r;
	struct ex *x = start_sweep(&r, true);
	struct acq_err err = { 0 };
	double t = 0;
	int injected = 0;
	bool swapped = false;
	for (long it = 0; it < 5000000; it++) {
		F.now = t;
		double nx = ex_step(x, t);
		enum ex_state s = ex_state(x);
		if (s == EX_PAUSED && !swapped) {
			F.sample = S_PAINT;
			swapped = true;
			ex_resume(x, t, &err);
			continue;
		}
		if (s == EX_PAUSED && injected == 4) { /* the operator fixes the axis and resumes */
			assert_non_null(strstr(ex_reason(x), "did not come back"));
			assert_false(F.emission);
			F.down_until[1] = t;
			ex_resume(x, t, &err);
			injected++;
			continue;
		}
		if (s == EX_COMPLETED || s == EX_FAILED || s == EX_ABORTED)
			break;
		int step = ex_current_step(x);
		if (injected == 0 && step == 2) { /* arm stops answering for 1 s */
			F.axis_down[0] = true;
			F.down_until[0] = t + 1.0;
			injected++;
		} else if (injected == 1 && step == 4 && F.shot) { /* spectrometer vanishes mid-exposure for 2 s */
			F.spectro_fail_next = 1;
			F.spectro_down_until = t + 2.0;
			injected++;
		} else if (injected == 2 && step == 6) { /* interlock opens during the next laser shot */
			F.interlock_after_shots = 1;
			injected++;
		} else if (injected == 3 && step == 8) { /* detector arm gone for good: pause for the operator */
			F.axis_down[1] = true;
			F.down_until[1] = 1e9;
			injected++;
		} else if (injected == 5 && step == 10) { /* saturation burst */
			F.burst = 3;
			injected++;
		} else if (injected == 6 && step == 12) { /* the next two darks saturate (stray light) */
			exp_darks_clear(x->darks);
			F.dark_burst = 2;
			injected++;
		}
		if (!(nx < INFINITY))
			break;
		t = nx > t ? nx : t + 1e-6;
	}
	print_message("  ended %s at t=%.1f: %s\n", ex_state_name(ex_state(x)), t, ex_reason(x));
	assert_int_equal(injected, 7);
	assert_int_equal(ex_state(x), EX_COMPLETED);
	const struct ex_stats *s = ex_stats(x);
	print_message("  faults %d, recoveries %d, retries %d, saturated redos %d, darks rejected %d\n", s->faults,
		      s->recoveries, s->retries, s->saturated_redos, s->dark_rejects);
	assert_true(s->faults >= 4);
	assert_true(s->recoveries >= 4);
	assert_true(s->saturated_redos >= 1 && s->dark_rejects >= 1);
	assert_int_equal(F.laser_on_during_motion, 0);
	assert_true(count_events("fault") >= 4 && count_events("recovered") >= 4);
	assert_false(F.emission);
	ex_free(x, t);
	store_close(r.st);
	check_db(r.sweep, true);
}

/* A crash (the executor vanishes without cleaning up) in the middle, then a new executor resumes at the
 * first pending point, with the reference reloaded from the database: nothing lost, nothing twice. */
/* The faults again, every read answering one step late. */
static void test_faults_deferred_reads(void **state)
{
	F.deferred = true;
	test_faults(state);
}

/* An alarm mid-move leaves the arms closer together than any planned path may start (the demo's stall: no
 * collision-free path from there, the sweep paused for the operator): the executor clears the alarm, backs off
 * along the segment it was executing to where that started, plans again from there and completes, with no
 * collision on the way. */
static const char *near_text = "name: near\n"
			       "incidence:\n  theta_deg: [30, 50]\n"
			       "observation:\n  theta_deg: [20, 40, 60]\n  phi_deg: [20, 340, 40, 320]\n"
			       "integration: {mode: auto, target_peak: 0.8, estimate_ms: 10, max_ms: 2000}\n"
			       "averages: 4\nblind_points: drop\n";

static void test_alarm_backs_off(void **state)
{
	(void)state;
	/* a plan whose moves pass close to the laser arm (detector azimuths on both sides of the laser's) */
	struct plan_result *small = plan, *near = NULL;
	struct plan_spec *spec = NULL;
	struct acq_err perr = { 0 };
	assert_int_equal(plan_load_string("near.yaml", near_text, &spec, &perr), 0);
	assert_int_equal(plan_make(spec, &geom, &near, &perr), 0);
	plan_spec_free(spec);
	plan = near;
	F.squeeze = true;
	struct run r;
	struct ex *x = start_sweep(&r, true);
	double t = drive(x, 0, 1e5, true);
	print_message("  finished at t=%.1f s: %s %s\n", t, ex_state_name(ex_state(x)), ex_reason(x));
	assert_true(F.squeezed);
	double psi = plan_psi_deg(&geom, &F.squeeze_at);
	print_message("  alarm stop at (%.2f, %.2f, %.2f), psi %.2f deg (planned paths keep >= %.2f)\n",
		      F.squeeze_at.laser_theta, F.squeeze_at.det_theta, F.squeeze_at.det_phi, psi, plan_clearance_deg(&geom));
	assert_true(psi < plan_clearance_deg(&geom)); /* no planned path can start there */
	struct plan_wp w[PLAN_MAX_WP];
	size_t n = 0;
	assert_true(plan_move(&geom, &F.squeeze_at, &plan->steps[plan->n_steps - 1].pos, w, &n) < 0);
	assert_int_equal(ex_state(x), EX_COMPLETED);
	assert_int_equal(backoffs, 1);
	assert_int_equal(F.collisions, 0);
	assert_int_equal(F.out_of_limits, 0);
	assert_int_equal(F.laser_on_during_motion, 0);
	assert_true(count_events("fault") >= 1 && count_events("recovered") >= 1);
	ex_free(x, t);
	store_close(r.st);
	check_db(r.sweep, true);
	plan = small;
	plan_result_free(near);
}

static void test_crash_resume(void **state)
{
	(void)state;
	struct run r;
	struct ex *x = start_sweep(&r, true);
	struct acq_err err = { 0 };
	double t = 0;
	bool swapped = false;
	int crash_at = (int)(plan->n_steps / 2);
	while (ex_current_step(x) < crash_at || !F.shot) {
		F.now = t;
		double nx = ex_step(x, t);
		if (ex_state(x) == EX_PAUSED && !swapped) {
			F.sample = S_PAINT;
			swapped = true;
			ex_resume(x, t, &err);
			continue;
		}
		t = nx > t ? nx : t + 1e-6;
	}
	/* crash: no cleanup (memory released without touching devices or the store) */
	x->state = EX_IDLE;
	ex_free(x, t);
	store_close(r.st);
	F.emission = false; /* a real laser driver's watchdog / the restart switches it off */
	F.homed[2] = false; /* and the controller lost its reference meanwhile */

	r.st = open_store();
	int64_t found = 0;
	assert_int_equal(store_sweep_interrupted(r.st, &found, &err), 0);
	assert_int_equal(found, r.sweep);
	int oi = -1;
	int64_t pid = 0;
	assert_int_equal(store_sweep_next_point(r.st, r.sweep, &oi, &pid, &err), 0);
	assert_int_equal(oi, crash_at);
	assert_int_equal(store_point_discard_partial(r.st, pid, &err), 0);
	x = ex_new(&r.cfg, &fake_ops, NULL, &sink, r.st, r.sweep, 0, &geom, plan, &err);
	assert_int_equal(ex_start(x, oi, true, t, &err), 0);
	t = drive(x, t, t + 1e5, false);
	assert_int_equal(ex_state(x), EX_COMPLETED);
	assert_int_equal(count_events("reference"), 1); /* not measured again */
	assert_true(F.homed[2]);
	ex_free(x, t);
	store_close(r.st);
	check_db(r.sweep, true);
}

/* The sweep's state of a halt and its event are one transaction: the store refusing the event (a trigger standing
 * for a disk that takes the small row and not the other) keeps neither, and both are stored by the retry once it
 * takes them. With two transactions the row read 'failed' with no 'failed' event. */
/* ---- a point's commit and its fsync ---------------------------------------------------------------- */

static double mono_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* The store's fsync thread holds each fsync this many real ms (a slow disk). */
static int slow_sync(void *ctx, char *why, size_t n)
{
	(void)why;
	(void)n;
	usleep((useconds_t)(*(const int *)ctx * 1000));
	return 0;
}

static struct {
	sqlite3 *db;              /* a reader of the store */
	int64_t sweep;
	int n, last;
	bool out_of_order, not_durable, next_committed;
} P;

/* A point announced: every commit so far on disk (the announced point's too), and no later point committed. */
static void sink_progress(void *ctx, int64_t sweep_id, int done, int total, double eta, const char *phase)
{
	(void)ctx;
	(void)sweep_id;
	(void)total;
	(void)eta;
	(void)phase;
	P.n++;
	P.out_of_order |= done != P.last + 1;
	P.last = done;
	P.not_durable |= store_durable(F.st, store_commit_mark(F.st), NULL) != 1;
	P.next_committed |= q1(P.db, "SELECT count(*) FROM points WHERE sweep_id = ? AND state = 'done'", P.sweep) != done;
}

static const struct ex_sink sink_p = { .event = sink_event, .progress = sink_progress };

/* drive() as the daemon's loop runs a durable_async executor: while it waits for the disk, wait for the store's
 * durable_fd (real time), without advancing the clock. */
static double drive_disk(struct ex *x, struct store *st, double now)
{
	struct acq_err err = { 0 };
	double t_end = mono_s() + 60;
	while (mono_s() < t_end) {
		F.now = now;
		double next = ex_step(x, now);
		enum ex_state s = ex_state(x);
		if (s == EX_PAUSED && F.sample == S_WHITE && strstr(ex_reason(x), "place the sample")) {
			F.sample = S_PAINT;
			assert_int_equal(ex_resume(x, now, &err), 0);
			continue;
		}
		if (s != EX_RUNNING && s != EX_SUSPENDED)
			break;
		if (x->phase == PH_DURABLE) {
			struct pollfd p = { .fd = store_durable_fd(st), .events = POLLIN };
			poll(&p, 1, 100);
			store_durable_drain(st);
			continue;
		}
		if (!(next < INFINITY))
			break;
		now = next > now ? next : now + 1e-6;
	}
	return now;
}

/* With the fsync on the store's thread (durable_async) and a slow disk: the laser off and the next move start
 * while a point's commit is being synced, yet a point is announced (counted, progress) only once on disk, the
 * next point is committed only after that, and every point is stored once. */
static void test_commit_overlaps_fsync(void **state)
{
	(void)state;
	struct run r;
	struct acq_err err = { 0 };
	r.st = open_store();
	assert_true(store_durable_fd(r.st) >= 0);
	static int hold_ms = 5;
	store_sync_set_hook(r.st, slow_sync, &hold_ms);
	r.sweep = new_sweep(r.st);
	cfg_for_test(&r.cfg);
	r.cfg.pause_after_reference = true;
	r.cfg.durable_async = true;
	F.st = r.st;
	memset(&P, 0, sizeof P);
	P.sweep = r.sweep;
	assert_int_equal(sqlite3_open_v2(dbpath, &P.db, SQLITE_OPEN_READONLY, NULL), SQLITE_OK);
	struct ex *x = ex_new(&r.cfg, &fake_ops, NULL, &sink_p, r.st, r.sweep, 0, &geom, plan, &err);
	assert_non_null(x);
	assert_int_equal(ex_start(x, 0, false, 0, &err), 0);
	double t = drive_disk(x, r.st, 0);
	int n = (int)plan->n_steps;
	print_message("  %s at t=%.1f s; %d progress events; %d axis moves begun while a commit was not on disk (%d points)\n",
		      ex_state_name(ex_state(x)), t, P.n, F.moves_undurable, n);
	assert_int_equal(ex_state(x), EX_COMPLETED);
	assert_int_equal(ex_stats(x)->points_done, n);
	assert_int_equal(P.n, n);
	assert_int_equal(P.last, n);
	assert_false(P.out_of_order);
	assert_false(P.not_durable);
	assert_false(P.next_committed);
	/* the overlap: most points' laser off and next move ran during their fsync (5 ms real, the fake's steps
	 * take microseconds); the points' own waits for the disk alone would give none */
	assert_true(F.moves_undurable >= n / 2);
	assert_int_equal(F.laser_on_during_motion, 0);
	F.st = NULL;
	sqlite3_close(P.db);
	ex_free(x, t);
	store_close(r.st);
	check_db(r.sweep, true);
}

static void test_halt_state_and_event_together(void **state)
{
	(void)state;
	struct run r;
	struct ex *x = start_sweep(&r, false);
	sqlite3 *db = NULL;
	assert_int_equal(sqlite3_open(dbpath, &db), SQLITE_OK);
	sqlite3_busy_timeout(db, 2000);
	assert_int_equal(sqlite3_exec(db, "CREATE TRIGGER refuse_failed BEFORE INSERT ON events WHEN NEW.kind = 'failed' "
				      "BEGIN SELECT RAISE(ABORT, 'refused (test)'); END", NULL, NULL, NULL), SQLITE_OK);
	ex_failed(x, "test failure");
	assert_int_equal(ex_state(x), EX_FAILED);
	assert_true(ex_has_unrecorded(x));
	assert_int_equal(count_events("failed"), 1); /* the sink heard it all the same */
	assert_int_equal(q1(db, "SELECT count(*) FROM sweeps WHERE id = ?1 AND state = 'running'", r.sweep), 1);
	assert_int_equal(q1(db, "SELECT count(*) FROM events WHERE sweep_id = ?1 AND kind = 'failed'", r.sweep), 0);
	struct acq_err err = { 0 };
	assert_int_equal(ex_flush_unrecorded(x, &err), -1); /* still refused: still neither */
	assert_int_equal(q1(db, "SELECT count(*) FROM sweeps WHERE id = ?1 AND state = 'running'", r.sweep), 1);
	assert_int_equal(sqlite3_exec(db, "DROP TRIGGER refuse_failed", NULL, NULL, NULL), SQLITE_OK);
	assert_int_equal(ex_flush_unrecorded(x, &err), 0);
	assert_false(ex_has_unrecorded(x));
	assert_int_equal(q1(db, "SELECT count(*) FROM sweeps WHERE id = ?1 AND state = 'failed'", r.sweep), 1);
	assert_int_equal(q1(db, "SELECT count(*) FROM events WHERE sweep_id = ?1 AND kind = 'failed'", r.sweep), 1);
	sqlite3_close(db);
	ex_free(x, 0);
	store_close(r.st);
}

/* Step x until the fake laser emits (the sweep acquiring); the time reached. */
static double until_emitting(struct ex *x, double t)
{
	for (long it = 0; it < 1000000 && !F.emission; it++) {
		F.now = t;
		double next = ex_step(x, t);
		assert_int_equal(ex_state(x), EX_RUNNING);
		t = next > t ? next : t + 1e-6;
	}
	assert_true(F.emission);
	return t;
}

/* A halt queues the laser's emission-off (as the daemon's laser thread runs it, effective at the next read):
 * ex_stopping() holds until a read says off, and is never false while the fake laser emits; a laser that does not
 * answer ends it with an event. With the state reported at once (no confirmation), ex_stopping() is false right
 * after the abort while the laser still emits. */
static void test_halt_waits_for_laser_off(void **state)
{
	(void)state;
	struct run r;
	struct ex *x = start_sweep(&r, false);
	F.deferred = true; /* every read answers EX_PENDING first */
	F.laser_lag = true;
	double t = until_emitting(x, 0);
	struct acq_err err = { 0 };
	assert_int_equal(ex_abort(x, "test", t, &err), 0);
	assert_int_equal(ex_state(x), EX_ABORTED);
	assert_true(F.emission);    /* queued, not done */
	assert_true(ex_stopping(x)); /* so not reported as stopped */
	int steps = 0;
	while (ex_stopping(x) && steps < 10) {
		double next = ex_step(x, t);
		steps++;
		assert_true(ex_stopping(x) || !F.emission);
		if (ex_stopping(x))
			assert_true(next < INFINITY); /* it wants to be stepped again (the read's completion) */
	}
	assert_false(ex_stopping(x));
	assert_false(F.emission);
	ex_free(x, t);
	store_close(r.st);

	/* the laser does not answer: the pause ends anyway, with an event saying so */
	fake_reset();
	x = start_sweep(&r, false);
	F.laser_lag = true;
	t = until_emitting(x, 0);
	F.laser_silent = true;
	int infos = count_events("info");
	ex_pause_now(x, false, "test pause");
	assert_int_equal(ex_state(x), EX_PAUSED);
	assert_true(ex_stopping(x));
	ex_step(x, t);
	assert_false(ex_stopping(x));
	assert_int_equal(count_events("info"), infos + 1);
	ex_free(x, t);
	store_close(r.st);
}

int main(void)
{
	seed = synth_seed("test_executor");
	bench_defaults(&geom);
	struct acq_err err = { 0 };
	struct plan_spec *spec = NULL;
	if (plan_load_string("small.yaml", plan_text, &spec, &err) || plan_make(spec, &geom, &plan, &err)) {
		fprintf(stderr, "plan: %s\n", err.msg);
		return 1;
	}
	plan_spec_free(spec);
	printf("# plan: %zu steps\n", plan->n_steps);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(test_full_sweep, setup, teardown),
		cmocka_unit_test_setup_teardown(test_full_sweep_deferred_reads, setup, teardown),
		cmocka_unit_test_setup_teardown(test_dark_schedule, setup, teardown),
		cmocka_unit_test_setup_teardown(test_pause_resume_abort, setup, teardown),
		cmocka_unit_test_setup_teardown(test_faults, setup, teardown),
		cmocka_unit_test_setup_teardown(test_faults_deferred_reads, setup, teardown),
		cmocka_unit_test_setup_teardown(test_crash_resume, setup, teardown),
		cmocka_unit_test_setup_teardown(test_alarm_backs_off, setup, teardown),
		cmocka_unit_test_setup_teardown(test_commit_overlaps_fsync, setup, teardown),
		cmocka_unit_test_setup_teardown(test_halt_state_and_event_together, setup, teardown),
		cmocka_unit_test_setup_teardown(test_halt_waits_for_laser_off, setup, teardown),
	};
	int rc = cmocka_run_group_tests(tests, NULL, NULL);
	plan_result_free(plan);
	return rc;
}
