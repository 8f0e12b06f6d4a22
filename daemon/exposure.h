/* exposure: the acquisition policy of one spectrum: auto-exposure from a probe, multi-exposure merge across
 * saturation, dark management (one dark per integration time, refreshed by age or sensor temperature drift),
 * averaging with the per-pixel standard deviation kept, and net count rates with their uncertainty.
 *
 * Pure functions over spectro_frame data: no device access, no logging, no clock of its own (callers pass
 * `now`). Counts are normalised by integration time: a "rate" is net counts per millisecond. */
#ifndef EXPOSURE_H
#define EXPOSURE_H

#include <stdbool.h>

#include "config/acq_err.h"
#include "config/yconf.h"
#include "daemon/plan/plan.h"
#include "drivers/spectro.h"

struct exp_policy {
	double target_frac;      /* auto-exposure: the peak (raw counts) aims at this fraction of full scale */
	double sat_frac;         /* raw counts ≥ sat_frac · full scale count as saturated (nonlinear region) */
	double min_ms, max_ms;   /* integration time limits (device limits ∩ configured) */
	double probe_ms;         /* first probe integration time */
	double max_step;         /* largest factor by which one probe may lengthen the time */
	int max_probes;          /* probes before taking the best estimate */
	int max_exposures;       /* exposures merged per spectrum (1 = never merge) */
	double hdr_ratio;        /* factor between successive exposures of a merge */
	double low_counts;       /* net counts wanted for the weak end of the spectrum */
	double low_quantile;     /* the weak end: this quantile of the positive net rates */
	unsigned averages;       /* scans averaged per sample exposure */
	unsigned dark_averages;  /* scans averaged per dark */
	double dark_max_age_s;   /* a dark older than this is refreshed */
	double dark_max_dtemp_c; /* a dark is refreshed when the sensor temperature moved more than this */
};

/* Net count rate of one spectrum on detector pixels (from one exposure or a merge). */
struct exp_rate {
	int npix;
	double rate[SPECTRO_MAX_PIXELS];    /* (S − D)/t, counts per ms; NaN where !valid */
	double u_noise[SPECTRO_MAX_PIXELS]; /* standard uncertainty from the sample's scan noise, counts/ms */
	double u_dark[SPECTRO_MAX_PIXELS];  /* standard uncertainty from the dark's noise, counts/ms */
	double t_ms[SPECTRO_MAX_PIXELS];    /* integration time the pixel's value comes from */
	unsigned char valid[SPECTRO_MAX_PIXELS]; /* 0: saturated in every exposure (never used) */
	int ninvalid;
};

/* Running mean and variance of counts over scans or averaged frames (Chan's parallel update). */
struct exp_avg {
	int npix;
	unsigned n;                          /* scans accumulated */
	double mean[SPECTRO_MAX_PIXELS];
	double m2[SPECTRO_MAX_PIXELS];       /* sum of squared deviations */
	unsigned char saturated[SPECTRO_MAX_PIXELS];
	double t_ms;
	double temperature_c;
};

/* One stored dark. */
struct exp_dark {
	double t_ms;
	double taken_at;         /* caller's clock, seconds */
	double temperature_c;    /* NaN if unknown */
	unsigned averages;
	int npix;
	double mean[SPECTRO_MAX_PIXELS];
	float stddev[SPECTRO_MAX_PIXELS];
};

/* Enough for every rung a sample uses (0.01 to 10000 ms on the √2 ladder is 41 rungs): with dark_every -1 the cache
 * is kept across incidences, and an evicted dark would be taken again (the oldest goes when full). */
#define EXP_DARK_SLOTS 48

/* Darks by integration time; the oldest is evicted when full. */
struct exp_darks {
	struct exp_dark slot[EXP_DARK_SLOTS];
	bool used[EXP_DARK_SLOTS];
};

enum exp_dark_need {
	EXP_DARK_FRESH = 0,  /* a usable dark exists */
	EXP_DARK_MISSING,    /* none at this integration time */
	EXP_DARK_AGED,       /* older than dark_max_age_s */
	EXP_DARK_TEMP,       /* the sensor temperature drifted more than dark_max_dtemp_c */
};

/* Outcome of exp_probe_next(). */
enum exp_probe_result {
	EXP_PROBE_DONE = 0,  /* *next_ms is the integration time to use */
	EXP_PROBE_AGAIN = 1, /* probe again at *next_ms */
};

/* Fill p with the defaults (80 % of full scale, up to 3 exposures, 10 averages, darks every 600 s / 1 °C). */
void exp_policy_defaults(struct exp_policy *p);
/* Parse an `acquisition:` mapping onto p (absent keys keep their values). 0 or -1 with file:line:col. */
int exp_policy_parse(struct yc_node *node, struct exp_policy *p, struct acq_err *err);
/* Check a policy's consistency (limits ordered, fractions in range). 0 or -1. */
int exp_policy_check(const struct exp_policy *p, struct acq_err *err);

/* Auto-exposure step: from a probe frame taken at probe->meas.integration_ms (dark: counts at that time or
 * NULL), choose the time that puts the highest pixel at target_frac of full_scale, clamped to the limits.
 * probe_no counts probes already taken (1 for the first). Returns enum exp_probe_result, or -1 on bad input. */
int exp_probe_next(const struct exp_policy *p, const struct spectro_frame *probe, const double *dark,
		   double full_scale, int probe_no, double *next_ms, struct acq_err *err);

/* Whether a probe frame counts as one scan of the exposure at t_ms that follows it (the executor then takes one scan
 * fewer, exp_frame_pool): taken at t_ms itself (the exposure's rung), one scan, no pixel saturated (flagged or raw
 * ≥ sat_frac · full_scale: saturation is then decided by the exposure's scans alone, as without the probe). */
bool exp_probe_reusable(const struct exp_policy *p, const struct spectro_frame *probe, double full_scale, double t_ms);

/* Pool probe (one scan, exp_probe_reusable) into f, a mean of f->meas.averages scans at the same integration time
 * and laser state: f becomes the mean and sample std of all the scans (Chan's update, exp_avg_add; a is scratch),
 * its averages one more, its saturated flags either's. f's std unknown (all 0 with averages > 1) stays unknown.
 * 0, or -1 if the pixel counts or times differ. */
int exp_frame_pool(struct exp_avg *a, struct spectro_frame *f, const struct spectro_frame *probe, struct acq_err *err);

/* Integration times of a multi-exposure set starting at base_ms (times[0] = base_ms, then × hdr_ratio) so the
 * weak end (low_quantile of the positive net rates in rate, over pixels where roi is nonzero or roi NULL)
 * reaches low_counts; at most max_exposures and max_ms. Returns the number of times (≥ 1). */
int exp_plan_times(const struct exp_policy *p, const struct exp_rate *base, const unsigned char *roi,
		   double base_ms, double *times, int max);

/* Start an average of npix pixels at integration time t_ms. */
void exp_avg_init(struct exp_avg *a, int npix, double t_ms);
/* Add a frame that is itself a mean of n scans with per-pixel std (n = 1, std NULL for a single scan).
 * 0, or -1 if npix or integration time do not match. */
int exp_avg_add(struct exp_avg *a, const double *counts, const float *stddev, unsigned n,
		const unsigned char *saturated, double t_ms, struct acq_err *err);
/* Per-pixel sample standard deviation of the scans (0 when n < 2). */
double exp_avg_std(const struct exp_avg *a, int p);

/* Net rate of one exposure: sample mean/std over ns scans minus the dark, over t. A pixel is invalid when
 * flagged saturated or its raw mean is ≥ sat_frac · full_scale. 0 or -1 on mismatched inputs. */
int exp_net_rate(const struct exp_policy *p, const double *counts, const float *stddev, unsigned ns,
		 const unsigned char *saturated, int npix, double t_ms, const struct exp_dark *dark,
		 double full_scale, struct exp_rate *out, struct acq_err *err);

/* Merge n exposures of the same spectrum: each pixel takes the longest exposure in which it is valid
 * (highest signal-to-noise), so saturated pixels come from shorter exposures scaled by their own time.
 * Pixels saturated everywhere stay invalid. 0 or -1. */
int exp_merge(const struct exp_rate *const *in, int n, struct exp_rate *out, struct acq_err *err);

/* Empty the dark store. */
void exp_darks_clear(struct exp_darks *d);
/* The detector's full scale in counts: info's max_counts, 65535 when unknown (info NULL or no figure). */
double exp_full_scale(const struct spectro_info *info);
/* Mark info's optically black pixels (they carry no light) invalid in r; info NULL: none. */
void exp_mask_black(const struct spectro_info *info, struct exp_rate *r);
/* Whether a dark at t_ms can be used at time now with sensor temperature temp_c (NaN: unknown). */
enum exp_dark_need exp_dark_check(const struct exp_darks *d, const struct exp_policy *p, double t_ms,
				  double now, double temp_c);
/* The stored dark at t_ms, or NULL. */
const struct exp_dark *exp_dark_find(const struct exp_darks *d, double t_ms);
/* Store (or replace) the dark at a->t_ms from an average; taken at now. Returns the stored dark. */
const struct exp_dark *exp_dark_store(struct exp_darks *d, const struct exp_avg *a, double now);
/* Forget the dark at t_ms (it was never stored, so it must not be used). */
void exp_dark_forget(struct exp_darks *d, double t_ms);
/* Short name of a dark decision ("fresh", "missing", "aged", "temperature"). */
const char *exp_dark_need_name(enum exp_dark_need n);

/* ---- exposure priors (exposure_prior.c) */
struct bench_geom;
struct plan_prior;
struct plan_timing;
struct store;
struct store_prior_row;
/* The exposure prior (plan.h) of one sweep from its exposures (store_prior_each's rows, in incidence, point and time
 * order): per incidence the points' first exposures (median, mean, longest/shortest), the darks taken there (count,
 * mean time) and the further (HDR) exposures per point (count, mean time); over the sweep the median, spread and
 * the fraction of points with an HDR exposure; per incidence also the share of points whose first time was their
 * predecessor's (pooled_per_point: their probe was one of its scans, exp_probe_reusable). Incidences past
 * PLAN_PRIOR_MAX_INC are left out of the rows (counted
 * over the sweep); with g and t (the bench and the executor's timing, time scale included) also the host's real
 * seconds per point there (host_per_point_s, host_points: what the sweep took between commits beyond the bench's
 * part). sweep and sample are not set. 0, or -1 out of memory. */
int exp_prior_build(const struct store_prior_row *rows, size_t n, const struct bench_geom *g,
		    const struct plan_timing *t, struct plan_prior *out);
/* The exposure prior of a plan naming sample: from the latest completed auto sweep of that sample in st other than
 * exclude (0: none), the host's time per point priced with g and t (NULL: none); out->sweep 0 when there is none
 * (or it has no done point). 0, or -1 with err. */
int exp_prior_load(struct store *st, const char *sample, long long exclude, const struct bench_geom *g,
		   const struct plan_timing *t, struct plan_prior *out, struct acq_err *err);
/* The exposure prior of sweep_id's own done points so far (a running sweep re-timing the rest of its plan, see
 * sweep.c): as exp_prior_load, out->sweep = sweep_id when it has a done point, sample empty. 0, or -1 with err. */
int exp_prior_load_sweep(struct store *st, long long sweep_id, const struct bench_geom *g,
			 const struct plan_timing *t, struct plan_prior *out, struct acq_err *err);
/* A running sweep's exposure rows read so far (exp_prior_update; zero-initialised: none read). */
struct exp_prior_rows {
	struct store_prior_row *v;
	size_t n, cap;
	long long next_order;       /* the points before this order index are read */
};
/* exp_prior_load_sweep() reading only the points committed since R's last update (their rows kept in R): the same
 * prior as reading them all, for the cost of the new ones' query (O(new) rows read instead of O(done); the figures
 * are still computed over every row). 0, or -1 with err (R then holds the rows read before). */
int exp_prior_update(struct exp_prior_rows *R, struct store *st, long long sweep_id, const struct bench_geom *g,
		     const struct plan_timing *t, struct plan_prior *out, struct acq_err *err);
/* Free R's rows; R is then empty (none read). */
void exp_prior_rows_free(struct exp_prior_rows *R);
/* Sweeps with fewer points measured between commits than this do not time the host (the quick plan's 15 points at
 * time scale 1 gave -27 to +5 ms per point: the bench's own jitter). */
#define EXP_HOST_MIN_POINTS 50
/* The host's real seconds per point as the latest completed sweep other than exclude of plan kind `kind` (NULL: any
 * kind; plan_kind_of) measured it (any sample; exp_prior_build's host figure with g and t): *host_s and *sweep (0,
 * *host_s unchanged: none, or fewer than EXP_HOST_MIN_POINTS measured). 0, or -1 with err. */
int exp_host_load(struct store *st, long long exclude, const char *kind, const struct bench_geom *g,
		  const struct plan_timing *t, double *host_s, long long *sweep, struct acq_err *err);
/* exp_host_load's figure of sweep id (found by the caller; id <= 0: none, *sweep 0). 0, or -1 with err. */
int exp_host_load_sweep(struct store *st, long long id, const struct bench_geom *g, const struct plan_timing *t,
			double *host_s, long long *sweep, struct acq_err *err);

/* The host figures exp_host_load gives (of any kind and of each plan kind), read once and kept until a sweep
 * completes in the store (store_completed_gen), exclude changes, or exp_host_cache_drop (a new configuration):
 * reading one is ~0.75 ms of the loop for the paper plan's sweep, and every `plan` request asked for it. */
struct exp_host_cache {
	bool valid;
	unsigned long gen;          /* store_completed_gen when read */
	long long exclude;
	double any_s;               /* the latest sweep's of any kind (when any_sweep > 0) */
	long long any_sweep;
	struct plan_host_kind kind[PLAN_HOST_KINDS];
	int n_kind;
	unsigned long reads;        /* times it read the database (tests) */
};
/* t's host figures (point_overhead_s and host_sweep when a sweep of any kind measured them, host_kind[]) from c,
 * read again first when stale. 0, or -1 with err (t's figures then as they were). */
int exp_host_cached(struct exp_host_cache *c, struct store *st, long long exclude, const struct bench_geom *g,
		    struct plan_timing *t, struct acq_err *err);
/* Forget what c holds (the next exp_host_cached reads again). */
void exp_host_cache_drop(struct exp_host_cache *c);

#endif
