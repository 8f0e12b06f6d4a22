/* executor acquisition: per point the auto-exposure probe, darks with the laser off, exposures with the laser
 * on, the merge, the calibration and the commit to the store; the white reference reload after a crash. */
#include "daemon/executor_int.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/crashpoint.h"
#include "daemon/stall.h"
#include "daemon/store.h"

/* The point's acquisition starts over: no probe, no exposure times, no shot (its pending spectra untouched). */
static void restart_point(struct ex *x)
{
	x->have_t0 = false;
	x->probe_no = 0;
	x->probe_pooled = false;
	x->ntimes = 0;
	x->e = 0;
	x->shot_in_flight = false;
	x->shot_landed = false;
}

void ex_reset_acq(struct ex *x)
{
	/* pending spectra thrown away: their darks leave the cache too (every dark used is a stored dark) */
	for (int i = 0; i < x->npend; i++)
		if (!strcmp(x->pend[i].kind, "dark"))
			exp_dark_forget(x->darks, x->pend[i].frame->meas.integration_ms);
	ex_clear_pending(x);
	restart_point(x);
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
	restart_point(x);
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

bool ex_want_wl(struct ex *x)
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

static double full_scale(const struct ex *x)
{
	return exp_full_scale(x->info);
}

/* ---- reference reload (crash-resume; the reconstruction's reference noise) ------------------------- */

/* The reload's working buffers: the executor's own (ex_load_reference) or a caller's (ex_reference_rate). */
struct ref_load {
	const struct exp_policy *pol;
	int npix;
	double full_scale;
	struct exp_darks *darks;   /* cleared before and after */
	struct exp_avg *avg;
	struct exp_rate **rates;   /* [EX_MAX_TIMES] */
	int n;                     /* exposures reloaded so far */
};

/* One stored reference spectrum: darks back into the dark cache (never reused for new spectra), exposures
 * into net rates, exactly as when they were taken. */
static int reload_one(void *ctx, const struct store_ref_spectrum *sp)
{
	struct ref_load *L = ctx;
	double t = sp->integration_ms;
	unsigned av = sp->averages > 0 ? (unsigned)sp->averages : 0;
	if (sp->npix != L->npix || av < 1 || L->n >= EX_MAX_TIMES)
		return 0;
	if (!strcmp(sp->kind, "dark")) {
		exp_avg_init(L->avg, sp->npix, t);
		exp_avg_add(L->avg, sp->counts, sp->stddev, av, NULL, t, NULL);
		L->avg->temperature_c = sp->temperature_c;
		exp_dark_store(L->darks, L->avg, -1e300); /* old: never reused for new spectra */
		return 0;
	}
	const struct exp_dark *dk = exp_dark_find(L->darks, t);
	if (dk && !exp_net_rate(L->pol, sp->counts, sp->stddev, av, sp->saturated, sp->npix, t, dk, L->full_scale,
				L->rates[L->n], NULL))
		L->n++;
	return 0;
}

/* The spectra listed by the sweep's last "reference" event, darks and exposures alike, turned into net rates
 * and merged into out exactly as when they were taken; *dt as store_reference_each. 1 loaded, 0 none, -1. */
static int ref_load_merge(struct store *st, int64_t sweep_id, struct ref_load *L, double *dt, struct exp_rate *out,
			  struct acq_err *err)
{
	exp_darks_clear(L->darks);
	L->n = 0;
	int n = store_reference_each(st, sweep_id, dt, reload_one, L, err);
	exp_darks_clear(L->darks);
	if (n < 0)
		return -1;
	if (L->n == 0)
		return 0;
	const struct exp_rate *list[EX_MAX_TIMES];
	for (int i = 0; i < L->n; i++)
		list[i] = L->rates[i];
	return exp_merge(list, L->n, out, err) ? 0 : 1;
}

/* The reference of this sweep from the store (ref_load_merge in the executor's buffers). 1 loaded, 0 none. */
int ex_load_reference(struct ex *x, struct acq_err *err)
{
	if (!x->st || !ex_want_wl(x))
		return 0;
	double dt = NAN;
	struct ref_load L = { .pol = &x->cfg.pol, .npix = x->info->npix, .full_scale = full_scale(x), .darks = x->darks,
			      .avg = x->avg, .rates = x->rates };
	int r = ref_load_merge(x->st, x->sweep_id, &L, &dt, x->ref_rate, err);
	x->nref = L.n;
	if (r < 0)
		return -1;
	if (isfinite(dt))
		x->cfg.cal.ref_theta_o_deg = fabs(dt);
	if (r == 0)
		return 0;
	exp_mask_black(x->info, x->ref_rate); /* no light: never used as data */
	return 1;
}

int ex_reference_rate(struct store *st, int64_t sweep_id, const struct exp_policy *pol, int npix, double full_scale,
		      struct exp_rate *out, double *detector_theta, struct acq_err *err)
{
	if (npix <= 0 || npix > SPECTRO_MAX_PIXELS)
		return acq_errf(err, ACQ_E_INVAL, "reference: %d pixels", npix);
	struct exp_rate *rates[EX_MAX_TIMES] = { 0 };
	struct ref_load L = { .pol = pol, .npix = npix, .full_scale = full_scale, .darks = malloc(sizeof *L.darks),
			      .avg = malloc(sizeof *L.avg), .rates = rates };
	bool ok = L.darks && L.avg;
	for (int i = 0; ok && i < EX_MAX_TIMES; i++)
		ok = (rates[i] = malloc(sizeof *rates[i])) != NULL;
	int r = ok ? ref_load_merge(st, sweep_id, &L, detector_theta, out, err)
		   : acq_errf(err, ACQ_E_NOMEM, "reference: out of memory");
	for (int i = 0; i < EX_MAX_TIMES; i++)
		free(rates[i]);
	free(L.darks);
	free(L.avg);
	return r;
}

/* ---- acquisition ------------------------------------------------------------------------------ */

static const char *expose_kind(const struct ex *x)
{
	if (!x->in_reference)
		return "sample";
	return x->cfg.cal.method == CALIB_ABSOLUTE ? "beam" : "reference";
}

/* The laser as the next shot needs it: 0, EX_PENDING (its state is being read), or -1 with err. A command
 * that changed it is confirmed by a read of the state before the shot. */
static int want_laser(struct ex *x, bool on, struct acq_err *err)
{
	if (on == x->stats.laser_on && !on && !x->laser_confirm)
		return 0;
	if (on && !x->power_set && x->ops.laser_power) {
		if (x->ops.laser_power(x->octx, x->cfg.laser_power_pct, err))
			return -1;
		x->power_set = true;
		x->laser_confirm = true;
	}
	if (on != x->stats.laser_on) {
		if (x->ops.laser_set(x->octx, on, err))
			return -1;
		x->stats.laser_on = on;
		x->laser_confirm = true;
	}
	bool emission = false, ready = false;
	int rc = x->ops.laser_state(x->octx, &emission, &ready, err);
	if (rc)
		return rc;
	x->laser_confirm = false;
	if (on && (!emission || !ready))
		return acq_errf(err, ACQ_E_DEVICE, "laser not emitting (interlock open or laser fault)");
	if (!on && emission)
		return acq_errf(err, ACQ_E_DEVICE, "laser still emitting after emission off");
	return 0;
}

/* Start a shot of kind k at t ms: 0 started, EX_PENDING (waiting for the laser), -1 after a fault. */
static int start_shot(struct ex *x, enum shot_kind k, double t, double now)
{
	struct acq_err err = { 0 };
	int rc = want_laser(x, k != SHOT_DARK, &err);
	if (rc == EX_PENDING) {
		ex_io_wait(x, now);
		return EX_PENDING;
	}
	if (rc) {
		ex_fault(x, EX_DEV_LASER, &err);
		return -1;
	}
	x->shot = k;
	x->meas.integration_ms = t;
	x->meas.averages = k == SHOT_PROBE ? 1 : k == SHOT_DARK ? x->cfg.pol.dark_averages : x->cfg.pol.averages;
	if (k == SHOT_EXPOSE && x->e == 0 && x->probe_pooled)
		x->meas.averages--; /* the probe is the first scan (ex_run_acq: none left to take when averages is 1) */
	x->meas.saturation_detection = true;
	if (x->ops.spectro_start(x->octx, &x->meas, now, &err)) {
		ex_fault(x, EX_DEV_SPECTRO, &err);
		return -1;
	}
	if (k == SHOT_PROBE)
		x->probe_no++;
	x->shot_in_flight = true;
	/* First look when the exposures should be over, then every poll_s (the fetch deadline is the driver's). */
	x->wake = now + fmax(t * 1e-3 * x->meas.averages, 1e-4);
	return 0;
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



static void commit_point(struct ex *x, double now);

/* The shot just finished: digest it and choose the next one. */
static void after_shot(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	struct spectro_frame *f = x->frame;
	double t = x->meas.integration_ms;
	if (f->npix != x->info->npix) {
		acq_errf(&err, ACQ_E_PROTO, "spectrometer returned %d pixels, expected %d", f->npix, x->info->npix);
		ex_fault(x, EX_DEV_SPECTRO, &err);
		return;
	}
	if (!(f->meas.integration_ms > 0))
		f->meas = x->meas; /* what was asked is what was measured */
	if (!f->meas.averages)
		f->meas.averages = x->meas.averages;
	if (isfinite(f->temperature_c))
		x->temperature = f->temperature_c;
	if (x->meas.averages > 0) /* 0: the pooled probe alone, no shot (ex_run_acq) */
		x->shots_s += x->meas.averages * t / 1000.0 + x->geom.readout_s + x->cfg.poll_s / 2;
	switch (x->shot) {
	case SHOT_PROBE: {
		x->stats.probes++;
		const struct exp_dark *dk = exp_dark_find(x->darks, t);
		double next = t;
		int r = exp_probe_next(&x->cfg.pol, f, dk ? dk->mean : NULL, full_scale(x), x->probe_no, &next, &err);
		if (r < 0) {
			ex_fault(x, EX_DEV_SPECTRO, &err);
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
		/* A probe at the time it leads to (the previous point's, most points) is a scan of the exposure there:
		 * the laser on at the same power, the same dark subtracted later, unsaturated; it counts as the first
		 * of the averages (exp_frame_pool), so the exposure takes one scan fewer (README "How long a sweep
		 * takes", session 17). */
		x->probe_pooled = exp_probe_reusable(&x->cfg.pol, f, full_scale(x), x->times[0]);
		if (x->probe_pooled)
			memcpy(x->probe, f, sizeof *f);
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
				ex_fault(x, EX_DEV_SPECTRO, &err);
				return;
			}
			x->stats.dark_rejects++;
			ex_event(x, "info", ex_dev_names[EX_DEV_SPECTRO], "dark at %.3g ms has %d saturated pixels: taken again", t,
			      nsat);
			break;
		}
		x->dark_retries = 0;
		x->stats.darks++;
		exp_avg_init(x->avg, f->npix, t);
		if (exp_avg_add(x->avg, f->counts, f->stddev, f->meas.averages ? f->meas.averages : x->meas.averages,
				f->saturated, t, &err)) {
			ex_fault(x, EX_DEV_SPECTRO, &err);
			return;
		}
		x->avg->temperature_c = f->temperature_c;
		exp_dark_store(x->darks, x->avg, now);
		if (keep_frame(x, "dark", ex_wall_now(x))) {
			ex_failed(x, "out of memory keeping spectra");
			return;
		}
		break;
	}
	case SHOT_EXPOSE: {
		x->stats.exposures++;
		if (x->e == 0 && x->probe_pooled) {
			if (x->meas.averages > 0 && exp_frame_pool(x->avg, f, x->probe, &err)) {
				ex_failed(x, "pooling the probe: %s", err.msg);
				return;
			}
			x->stats.probes_pooled++;
		}
		const struct exp_dark *dk = exp_dark_find(x->darks, t);
		unsigned n = f->meas.averages ? f->meas.averages : x->meas.averages;
		if (exp_net_rate(&x->cfg.pol, f->counts, f->stddev, n, f->saturated, f->npix, t, dk, full_scale(x),
				 x->rates[x->e], &err)) {
			ex_failed(x, "net rate: %s", err.msg);
			return;
		}
		if (keep_frame(x, expose_kind(x), ex_wall_now(x))) {
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

void ex_run_acq(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	if (x->shot_in_flight) {
		int r = x->ops.spectro_fetch(x->octx, x->frame, now, &err);
		if (r < 0) {
			ex_fault(x, EX_DEV_SPECTRO, &err);
			return;
		}
		if (r == 0) {
			x->wake = now + x->cfg.poll_s;
			return;
		}
		x->shot_in_flight = false;
		x->shot_landed = true;
	}
	if (x->shot_landed) {
		if (x->shot != SHOT_DARK) {
			/* The laser must still be emitting: an interlock opened during the exposure spoils it. */
			bool emission = false, ready = false;
			int rc = x->ops.laser_state(x->octx, &emission, &ready, &err);
			if (rc == EX_PENDING) {
				ex_io_wait(x, now);
				return;
			}
			if (rc == 0 && (!emission || !ready))
				rc = acq_errf(&err, ACQ_E_DEVICE,
					      "laser stopped emitting during the exposure (interlock or fault)");
			if (rc) {
				ex_fault(x, EX_DEV_LASER, &err);
				return;
			}
		}
		x->shot_landed = false;
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
			start_shot(x, SHOT_PROBE, x->t_probe, now);
			return;
		}
	}
	double t = x->times[x->e];
	enum exp_dark_need need = exp_dark_check(x->darks, &x->cfg.pol, t, now, x->temperature);
	if (need == EXP_DARK_FRESH && x->e == 0 && x->probe_pooled && x->cfg.pol.averages <= 1) {
		/* one scan per exposure: the pooled probe is the exposure, no shot is taken */
		memcpy(x->frame, x->probe, sizeof *x->frame);
		x->shot = SHOT_EXPOSE;
		x->meas.integration_ms = t;
		x->meas.averages = 0;
		after_shot(x, now);
		return;
	}
	start_shot(x, need != EXP_DARK_FRESH ? SHOT_DARK : SHOT_EXPOSE, t, now);
}

static int put_spectrum(struct ex *x, const struct pending *p, int64_t point_id, bool completes, int64_t *id,
			struct acq_err *err)
{
	float *counts = x->scratch;
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
	ex_pos_angles(&x->geom, &x->actual, &sp.theta_i, &sp.phi_i, &sp.theta_o, &sp.phi_o);
	return store_spectrum_add(x->st, &sp, id, err);
}

/* The point's cycle (from the previous point's going on to this one's), for the executor's own ETA. */
static void point_timed(struct ex *x, double now)
{
	double dt = now - x->point_started;
	x->point_avg_s = isfinite(x->point_avg_s) ? 0.9 * x->point_avg_s + 0.1 * dt : dt;
}

static void progress(struct ex *x, const char *text)
{
	double eta = x->point_avg_s * (x->nsteps - x->cur);
	if (x->sink.progress)
		x->sink.progress(x->sink.ctx, x->sweep_id, x->stats.points_done, x->nsteps, eta, text);
}

static void finish_sweep(struct ex *x)
{
	struct acq_err err = { 0 };
	ex_laser_off(x, &err);
	x->state = EX_COMPLETED;
	x->phase = PH_NONE;
	ex_set_phase_text(x, "completed");
	/* The store's count, not this run's: points of an earlier run (before a crash) count too. */
	int64_t ncal = store_calibrated_count(x->st, x->sweep_id, &err);
	if (ncal == x->nsteps)
		ex_state_event(x, "completed", "complete", NULL,
			       "all %d points measured and calibrated (%s method); %d faults, %d recovered", x->nsteps,
			       calib_method_name(x->cfg.cal.method), x->stats.faults, x->stats.recoveries);
	else
		ex_state_event(x, "completed", "complete", NULL,
			       "all %d points measured, %lld of them calibrated (%s method%s); %d faults, %d recovered",
			       x->nsteps, (long long)(ncal < 0 ? 0 : ncal), calib_method_name(x->cfg.cal.method),
			       x->have_ref ? "" : ", no reference", x->stats.faults, x->stats.recoveries);
}

void ex_wait_batch(struct ex *x)
{
	struct acq_err err = { 0 };
	if (ex_laser_off(x, &err))
		ex_event(x, "info", NULL, "switching the laser off between batches: %s", err.msg);
	x->state = EX_WAITING;
	x->phase = PH_NONE;
	x->pause_requested = false;
	ex_set_phase_text(x, "waiting for the next batch");
}

/* The dark schedule (sweep.dark_every), its one owner: whether the dark cache is cleared before point x->cur, the
 * next one, after `done` points. Every dark_every points, or whenever the incidence changes (0); -1: never (each
 * time's dark is kept until it ages or the sensor's temperature moves, exp_dark_check: the laser is off for a dark,
 * so the incidence does not enter it). At a batch's start (ex_extend: batch_start) the incidence rule as between the
 * points of one plan; dark_every > 0 keeps its own count (the points' commits, go_on), none at the batch's start. */
static bool darks_due(const struct ex *x, int done, bool batch_start)
{
	if (x->cur <= 0 || x->cur >= x->nsteps || x->cfg.dark_every < 0)
		return false;
	if (x->cfg.dark_every > 0)
		return !batch_start && done % x->cfg.dark_every == 0;
	return fabs(x->plan->steps[x->cur].pos.laser_theta - x->plan->steps[x->cur - 1].pos.laser_theta) > 1e-6;
}

int ex_extend(struct ex *x, const struct plan_result *plan, double now, struct acq_err *err)
{
	if (x->state != EX_WAITING && x->state != EX_PAUSED)
		return acq_errf(err, ACQ_E_STATE, "sweep is %s: only a waiting or paused sweep takes more steps",
				ex_state_name(x->state));
	if (!plan || (int)plan->n_steps < x->nsteps)
		return acq_errf(err, ACQ_E_INVAL, "sweep: the extended plan has fewer steps than the sweep so far");
	x->plan = plan;
	x->nsteps = (int)plan->n_steps;
	x->stats.points_total = x->nsteps;
	if (x->state == EX_PAUSED || x->cur >= x->nsteps)
		return 0;
	if (darks_due(x, 0, true))
		exp_darks_clear(x->darks);
	x->state = EX_RUNNING;
	x->point_started = now;
	ex_event(x, "info", NULL, "batch: points %d to %d of %d", x->cur + 1, x->nsteps, x->nsteps);
	ex_begin_segment(x, now);
	ex_set_phase_text(x, "verifying positions");
	return 0;
}

int ex_finish(struct ex *x, const char *why, struct acq_err *err)
{
	if (!(x->state == EX_WAITING || (x->state == EX_PAUSED && x->cur >= x->nsteps)))
		return acq_errf(err, ACQ_E_STATE, "sweep is %s at point %d of %d: it cannot complete now",
				ex_state_name(x->state), x->cur, x->nsteps);
	snprintf(x->reason, sizeof x->reason, "%s", why && *why ? why : "no more batches");
	ex_event(x, "info", NULL, "%s", x->reason);
	finish_sweep(x);
	return 0;
}

/* The reference (or direct beam) is in: store its spectra, keep its merged rate, then pause for the sample swap
 * or go on to the first point. */
static void commit_reference(struct ex *x, double now)
{
	struct acq_err err = { 0 };
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
		ex_set_db_state(x, "paused");
	crash_point("reference_stored"); /* the window the kill tests probe: spectra in, marker not */
	ex_stall_reset(x);
	memcpy(x->ref_rate, x->merged, sizeof *x->ref_rate);
	x->have_ref = true;
	x->cfg.cal.ref_theta_o_deg = fabs(x->actual.det_theta);
	x->in_reference = false;
	ex_clear_pending(x);
	ex_event(x, "reference", NULL, "%s measured at (%.4f, %.4f, %.4f): spectra %lld-%lld",
	      x->cfg.cal.method == CALIB_ABSOLUTE ? "direct beam" : "white reference", x->actual.laser_theta,
	      x->actual.det_theta, x->actual.det_phi, (long long)first, (long long)last);
	if (x->cfg.pause_after_reference) {
		ex_pause_now(x, false, "%s measured: place the sample on the stage, then resume",
			  x->cfg.cal.method == CALIB_ABSOLUTE ? "direct beam" : "reference");
		return;
	}
	if (x->pause_requested) {
		ex_pause_now(x, false, "paused by the operator after the reference");
		return;
	}
	ex_begin_segment(x, now);
	return;
}

/* The point's rows inside the store's group: the spectra, the calibrated sample, the completing spectrum (the
 * point done). 0, or -1 with err and *what (the step that failed). */
static int store_point(struct ex *x, int64_t pid, bool calibrated, const char **what, struct acq_err *err)
{
	for (int i = 0; i + 1 < x->npend; i++) {
		if (put_spectrum(x, &x->pend[i], pid, false, NULL, err))
			return -1;
		x->stats.spectra++;
	}
	if (calibrated) {
		float *fb = x->scratch, *fs = x->scratch + CALIB_MAX_GRID;
		for (int k = 0; k < x->cal->n; k++) {
			fb[k] = (float)x->cal->f[k];
			fs[k] = (float)x->cal->u[k];
		}
		*what = "storing the calibrated sample of point";
		if (store_calibrated_put(x->st, x->sweep_id, pid, fb, fs, x->cal->n, err))
			return -1;
	}
	if (x->npend > 0) {
		*what = "completing point";
		if (put_spectrum(x, &x->pend[x->npend - 1], pid, true, NULL, err))
			return -1;
		x->stats.spectra++;
	}
	return 0;
}

static void go_on(struct ex *x, double now, bool deferred);

/* On to PH_DURABLE: wait until point's commit is on disk (commit_waits: the previous point's, before this one's). */
static void wait_for_disk(struct ex *x, double now, int point, bool commit_waits)
{
	x->commit_waits = commit_waits;
	x->phase = PH_DURABLE;
	char text[64];
	snprintf(text, sizeof text, "storing point %d: waiting for the disk", point);
	ex_set_phase_text(x, text);
	ex_run_durable(x, now);
}

/* The point's exposures are in: merge, check saturation, calibrate, commit, go on. */
static void commit_point(struct ex *x, double now)
{
	if (x->ack_pending) { /* the previous point on disk first: a point is never committed before the one before */
		wait_for_disk(x, now, x->ack_point, true);
		return;
	}
	x->commit_waits = false;
	struct acq_err err = { 0 };
	const struct exp_rate *list[EX_MAX_TIMES];
	for (int i = 0; i < x->ntimes; i++)
		list[i] = x->rates[i];
	if (exp_merge(list, x->ntimes, x->merged, &err)) {
		ex_failed(x, "merge: %s", err.msg);
		return;
	}
	x->stats.merges++;
	exp_mask_black(x->info, x->merged);
	int bad = 0;
	for (int p = 0; p < x->merged->npix; p++)
		bad += x->roi[p] && !x->merged->valid[p];
	x->t_last = x->times[0];
	if (x->nroi > 0 && bad > x->cfg.max_invalid_frac * x->nroi) {
		if (x->times[0] > x->cfg.pol.min_ms * 1.0001 && ++x->attempts < x->cfg.max_point_attempts) {
			/* Saturated even at the shortest exposure: something changed (or a burst); probe again. */
			x->stats.saturated_redos++;
			ex_event(x, "info", ex_dev_names[EX_DEV_SPECTRO],
			      "%d of %d pixels saturated at %.3g ms: measuring the point again", bad, x->nroi, x->times[0]);
			double t0 = x->times[0];
			drop_exposures(x);
			x->t_last = fmax(x->cfg.pol.min_ms, t0 / x->cfg.pol.max_step);
			x->wake = now;
			return;
		}
		ex_event(x, "info", ex_dev_names[EX_DEV_SPECTRO],
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
			ex_event(x, "info", ex_dev_names[EX_DEV_SPECTRO],
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
		commit_reference(x, now);
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
			ex_event(x, "info", NULL, "point %d not calibrated: %s", x->cur, err.msg);
	}
	int oi = -1;
	int64_t pid = 0;
	double t_store = stall_now();
	if (store_sweep_next_point(x->st, x->sweep_id, &oi, &pid, &err)) {
		ex_failed(x, "reading the next point: %s", err.msg);
		return;
	}
	if (oi != x->cur || pid <= 0) {
		ex_failed(x, "the database's next pending point is %d, the executor is at %d", oi, x->cur);
		return;
	}
	/* One transaction for the point, stored whole or not at all; the commit returns before its fsync, which the
	 * store's thread runs: the sweep goes on once the point is on disk (PH_DURABLE), the loop serving meanwhile. */
	const char *what = "storing point";
	int rc = store_group_begin(x->st, &err);
	if (!rc)
		rc = store_point(x, pid, calibrated, &what, &err);
	struct acq_err gerr = { 0 };
	if (store_group_end(x->st, rc, rc ? NULL : &gerr) || rc) {
		ex_failed(x, "%s %d: %s", rc ? what : "committing point", x->cur, rc ? err.msg : gerr.msg);
		return;
	}
	stall_store(stall_now() - t_store);
	ex_clear_pending(x);
	x->durable_mark = store_commit_mark(x->st);
	if (x->cfg.durable_async && x->cur + 1 < x->nsteps && !x->pause_requested) {
		/* Go on at once: the laser off and the next move overlap the fsync; the point is counted and
		 * announced once on disk (ex_ack_step), and the next point's commit waits for that. A crash before
		 * the fsync loses nothing (the commit is in the WAL); a power loss at most this point, measured again
		 * at the resume (store_sweep_next_point). The last point and a pause wait for the disk as before. */
		x->ack_pending = true;
		x->ack_mark = x->durable_mark;
		x->ack_point = x->cur;
		x->ack_shots_s = x->shots_s;
		go_on(x, now, true);
		return;
	}
	wait_for_disk(x, now, x->cur, false);
}

int ex_ack_step(struct ex *x)
{
	if (!x->ack_pending)
		return 1;
	struct acq_err err = { 0 };
	int r = store_durable(x->st, x->ack_mark, &err);
	if (r == 0)
		return 0;
	x->ack_pending = false;
	bool live = x->state == EX_RUNNING || x->state == EX_SUSPENDED;
	if (r < 0) {
		if (live || x->state == EX_PAUSED)
			ex_failed(x, "point %d is stored but not known to be on disk: %s", x->ack_point, err.msg);
		return -1;
	}
	x->stats.points_done++;
	x->stats.shots_s = x->ack_shots_s;
	/* announced while the sweep runs (a progress event says `running`); after a halt the count is the store's */
	if (live) {
		char text[64];
		snprintf(text, sizeof text, "point %d stored", x->ack_point);
		progress(x, text);
	}
	return 1;
}

void ex_run_durable(struct ex *x, double now)
{
	if (x->commit_waits) {
		int r = ex_ack_step(x);
		if (r < 0)
			return;
		if (r == 0) {
			ex_io_wait(x, now); /* store_durable_fd's kick steps it sooner */
			return;
		}
		x->commit_waits = false;
		x->phase = PH_ACQ;
		commit_point(x, now);
		return;
	}
	struct acq_err err = { 0 };
	int r = x->cfg.durable_async ? store_durable(x->st, x->durable_mark, &err)
				     : store_durable_wait(x->st, x->durable_mark, &err);
	if (r < 0) {
		ex_failed(x, "point %d is stored but not known to be on disk: %s", x->cur, err.msg);
		return;
	}
	if (r == 0) {
		ex_io_wait(x, now); /* store_durable_fd's kick steps it sooner */
		return;
	}
	go_on(x, now, false);
}

/* The point x->cur is committed (deferred: not yet on disk, ex_ack_step counts and announces it later; else on
 * disk: counted and announced now): on to the next point, or the end of the sweep or batch, or the pause. */
static void go_on(struct ex *x, double now, bool deferred)
{
	struct acq_err err = { 0 };
	char text[64];
	snprintf(text, sizeof text, deferred ? "point %d committed" : "point %d stored", x->cur);
	ex_set_phase_text(x, text);
	ex_stall_report(x, x->cur);
	x->point_faults = 0;
	if (!deferred) {
		x->stats.points_done++;
		x->stats.shots_s = x->shots_s;
	}
	int done = x->stats.points_done + (deferred ? 1 : 0);
	x->cur++;
	if (darks_due(x, done, false))
		exp_darks_clear(x->darks);
	point_timed(x, now);
	if (!deferred)
		progress(x, x->phase_text);
	else if (ex_ack_step(x) < 0)
		return;
	if (x->cur >= x->nsteps) {
		if (x->cfg.hold_at_end)
			ex_wait_batch(x);
		else
			finish_sweep(x);
		return;
	}
	if (x->pause_requested) {
		ex_pause_now(x, false, "paused by the operator after point %d", x->cur);
		return;
	}
	x->first_move = false;
	x->point_started = now;
	if (x->stats.laser_on) {
		if (ex_laser_off(x, &err)) {
			ex_fault(x, EX_DEV_LASER, &err);
			return;
		}
		x->laser_confirm = true;
	}
	x->move_from_verify = false;
	x->phase = PH_LASER_OFF;
	x->wake = now;
}
