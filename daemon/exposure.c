/* exposure: auto-exposure, multi-exposure merge, darks per integration time, averaging, net count rates. */
#include "daemon/exposure.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void exp_policy_defaults(struct exp_policy *p)
{
	memset(p, 0, sizeof *p);
	p->target_frac = 0.80;
	p->sat_frac = 0.95;
	p->min_ms = 0.01;
	p->max_ms = 10000.0;
	p->probe_ms = 10.0;
	p->max_step = 100.0;
	p->max_probes = 4;
	p->max_exposures = 3;
	p->hdr_ratio = 8.0;
	p->low_counts = 2000.0;
	p->low_quantile = 0.05;
	p->averages = 10;
	p->dark_averages = 10;
	p->dark_max_age_s = 600.0;
	p->dark_max_dtemp_c = 1.0;
}

int exp_policy_check(const struct exp_policy *p, struct acq_err *err)
{
	if (!(p->target_frac > 0 && p->target_frac < p->sat_frac && p->sat_frac <= 1.0))
		return acq_errf(err, ACQ_E_CONFIG, "acquisition: need 0 < target_frac (%g) < sat_frac (%g) <= 1",
				p->target_frac, p->sat_frac);
	if (!(p->min_ms > 0 && p->min_ms <= p->max_ms))
		return acq_errf(err, ACQ_E_CONFIG, "acquisition: need 0 < min_ms (%g) <= max_ms (%g)", p->min_ms,
				p->max_ms);
	if (!(p->probe_ms >= p->min_ms && p->probe_ms <= p->max_ms))
		return acq_errf(err, ACQ_E_CONFIG, "acquisition: probe_ms (%g) outside [min_ms, max_ms]", p->probe_ms);
	if (!(p->max_step > 1) || !(p->hdr_ratio > 1) || p->max_exposures < 1 || p->max_probes < 1)
		return acq_errf(err, ACQ_E_CONFIG,
				"acquisition: need max_step > 1, hdr_ratio > 1, max_exposures >= 1, max_probes >= 1");
	if (p->averages < 1 || p->dark_averages < 1)
		return acq_errf(err, ACQ_E_CONFIG, "acquisition: averages and dark_averages must be >= 1");
	if (!(p->low_quantile >= 0 && p->low_quantile < 1) || !(p->low_counts >= 0))
		return acq_errf(err, ACQ_E_CONFIG, "acquisition: need 0 <= low_quantile < 1 and low_counts >= 0");
	return 0;
}

int exp_policy_parse(struct yc_node *node, struct exp_policy *p, struct acq_err *err)
{
	if (!node)
		return 0;
	if (yc_expect_map(node, "acquisition", err))
		return -1;
	struct exp_policy q = *p;
	long long probes = q.max_probes, nexp = q.max_exposures, av = q.averages, dav = q.dark_averages;
	if (yc_double(node, "target_frac", false, 0.01, 1, &q.target_frac, err) ||
	    yc_double(node, "sat_frac", false, 0.01, 1, &q.sat_frac, err) ||
	    yc_double(node, "min_ms", false, 1e-3, 6e5, &q.min_ms, err) ||
	    yc_double(node, "max_ms", false, 1e-3, 6e5, &q.max_ms, err) ||
	    yc_double(node, "probe_ms", false, 1e-3, 6e5, &q.probe_ms, err) ||
	    yc_double(node, "max_step", false, 1.01, 1e6, &q.max_step, err) ||
	    yc_int(node, "max_probes", false, 1, 20, &probes, err) ||
	    yc_int(node, "max_exposures", false, 1, 8, &nexp, err) ||
	    yc_double(node, "hdr_ratio", false, 1.01, 1e4, &q.hdr_ratio, err) ||
	    yc_double(node, "low_counts", false, 0, 1e7, &q.low_counts, err) ||
	    yc_double(node, "low_quantile", false, 0, 0.99, &q.low_quantile, err) ||
	    yc_int(node, "averages", false, 1, 5000, &av, err) ||
	    yc_int(node, "dark_averages", false, 1, 5000, &dav, err) ||
	    yc_double(node, "dark_max_age_s", false, 0, 1e7, &q.dark_max_age_s, err) ||
	    yc_double(node, "dark_max_dtemp_c", false, 0, 100, &q.dark_max_dtemp_c, err))
		return -1;
	q.max_probes = (int)probes;
	q.max_exposures = (int)nexp;
	q.averages = (unsigned)av;
	q.dark_averages = (unsigned)dav;
	struct acq_err cerr = { 0 };
	if (exp_policy_check(&q, &cerr))
		return yc_errf(err, node, "%s", cerr.msg);
	*p = q;
	return 0;
}

static double clampd(double v, double lo, double hi)
{
	return v < lo ? lo : v > hi ? hi : v;
}

/* The time that puts every pixel at or below target: for pixel p with net counts n_p over a dark D_p at the
 * probe time, t_p = t_probe · (target − D_p)/n_p; the minimum over pixels wins. A saturated probe gives no
 * scale (the true peak is unknown), so the time shrinks by max_step and the probe is repeated. */
int exp_probe_next(const struct exp_policy *p, const struct spectro_frame *probe, const double *dark,
		   double full_scale, int probe_no, double *next_ms, struct acq_err *err)
{
	double t = probe->meas.integration_ms;
	if (!(t > 0) || probe->npix <= 0 || probe->npix > SPECTRO_MAX_PIXELS || !(full_scale > 0))
		return acq_errf(err, ACQ_E_INVAL, "auto-exposure: bad probe (t %g ms, %d pixels, full scale %g)", t,
				probe->npix, full_scale);
	double target = p->target_frac * full_scale, sat = p->sat_frac * full_scale;
	bool saturated = false;
	double best = INFINITY;
	for (int i = 0; i < probe->npix; i++) {
		double s = probe->counts[i];
		if (!isfinite(s))
			continue;
		if (probe->saturated[i] || s >= sat) {
			saturated = true;
			continue;
		}
		double d = dark ? dark[i] : 0.0;
		double net = s - d;
		if (net <= 0)
			continue;
		double room = target - d;
		if (room <= 0)
			room = 0.01 * target; /* the dark alone is near the target: aim very short */
		double tp = t * room / net;
		if (tp < best)
			best = tp;
	}
	if (saturated) {
		double nt = clampd(t / p->max_step, p->min_ms, p->max_ms);
		if (nt >= t || probe_no >= p->max_probes) {
			*next_ms = nt; /* cannot go shorter: use the shortest time, saturated pixels stay unused */
			return EXP_PROBE_DONE;
		}
		*next_ms = nt;
		return EXP_PROBE_AGAIN;
	}
	if (!isfinite(best)) /* no signal at all: longest allowed step */
		best = t * p->max_step;
	double nt = clampd(best, p->min_ms, p->max_ms);
	if (nt > t * p->max_step) { /* a long extrapolation from a weak probe: confirm with another probe */
		nt = clampd(t * p->max_step, p->min_ms, p->max_ms);
		if (probe_no < p->max_probes) {
			*next_ms = nt;
			return EXP_PROBE_AGAIN;
		}
	}
	*next_ms = nt;
	return EXP_PROBE_DONE;
}

bool exp_probe_reusable(const struct exp_policy *p, const struct spectro_frame *probe, double full_scale, double t_ms)
{
	double t = probe->meas.integration_ms;
	if (!(t > 0) || fabs(t - t_ms) > 1e-9 * fmax(1.0, t_ms) || probe->meas.averages > 1 || probe->nsaturated > 0 ||
	    probe->npix <= 0 || probe->npix > SPECTRO_MAX_PIXELS)
		return false;
	double sat = p->sat_frac * full_scale;
	for (int i = 0; i < probe->npix; i++)
		if (probe->saturated[i] || !(probe->counts[i] < sat))
			return false;
	return true;
}

int exp_frame_pool(struct exp_avg *a, struct spectro_frame *f, const struct spectro_frame *probe, struct acq_err *err)
{
	double t = f->meas.integration_ms;
	unsigned n = f->meas.averages ? f->meas.averages : 1;
	if (f->npix != probe->npix || f->npix <= 0 || f->npix > SPECTRO_MAX_PIXELS)
		return acq_errf(err, ACQ_E_INVAL, "pool: probe of %d pixels into a frame of %d", probe->npix, f->npix);
	bool std_known = n < 2;
	for (int i = 0; i < f->npix && !std_known; i++)
		std_known = f->stddev[i] > 0;
	exp_avg_init(a, f->npix, t);
	if (exp_avg_add(a, probe->counts, NULL, 1, probe->saturated, probe->meas.integration_ms, err) ||
	    exp_avg_add(a, f->counts, f->stddev, n, f->saturated, t, err))
		return -1;
	f->nsaturated = 0;
	for (int i = 0; i < f->npix; i++) {
		f->counts[i] = a->mean[i];
		f->stddev[i] = std_known ? (float)exp_avg_std(a, i) : 0.0f;
		f->saturated[i] = a->saturated[i];
		f->nsaturated += a->saturated[i];
	}
	f->dark_pixel_level = (f->dark_pixel_level * n + probe->dark_pixel_level) / (n + 1);
	f->meas.averages = a->n;
	return 0;
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

int exp_plan_times(const struct exp_policy *p, const struct exp_rate *base, const unsigned char *roi,
		   double base_ms, double *times, int max)
{
	if (max < 1)
		return 0;
	times[0] = base_ms;
	int limit = p->max_exposures < max ? p->max_exposures : max;
	if (limit <= 1 || !base)
		return 1;
	double *r = malloc(sizeof(double) * (size_t)(base->npix > 0 ? base->npix : 1));
	if (!r)
		return 1;
	int n = 0;
	for (int i = 0; i < base->npix; i++)
		if (base->valid[i] && (!roi || roi[i]) && base->rate[i] > 0 && isfinite(base->rate[i]))
			r[n++] = base->rate[i];
	int count = 1;
	if (n > 0) {
		qsort(r, (size_t)n, sizeof *r, cmp_double);
		double weak = r[(int)floor(p->low_quantile * (n - 1))];
		double need_ms = p->low_counts / weak;
		double t = base_ms;
		while (count < limit && t < need_ms && t < p->max_ms) {
			t = clampd(t * p->hdr_ratio, p->min_ms, p->max_ms);
			times[count++] = t;
		}
	}
	free(r);
	return count;
}

void exp_avg_init(struct exp_avg *a, int npix, double t_ms)
{
	a->npix = npix;
	a->n = 0;
	a->t_ms = t_ms;
	a->temperature_c = NAN;
	int m = npix > 0 && npix <= SPECTRO_MAX_PIXELS ? npix : 0;
	memset(a->mean, 0, sizeof(double) * (size_t)m);
	memset(a->m2, 0, sizeof(double) * (size_t)m);
	memset(a->saturated, 0, (size_t)m);
}

/* Chan et al.: merging (n_a, mean_a, M2_a) with (n_b, mean_b, M2_b), where an averaged frame with sample
 * std s over n scans contributes M2_b = s²·(n − 1). */
int exp_avg_add(struct exp_avg *a, const double *counts, const float *stddev, unsigned n,
		const unsigned char *saturated, double t_ms, struct acq_err *err)
{
	if (a->npix <= 0 || a->npix > SPECTRO_MAX_PIXELS || n < 1)
		return acq_errf(err, ACQ_E_INVAL, "average: bad frame (%d pixels, %u scans)", a->npix, n);
	if (fabs(t_ms - a->t_ms) > 1e-9 * fmax(1.0, a->t_ms))
		return acq_errf(err, ACQ_E_INVAL, "average: frame at %g ms added to an average at %g ms", t_ms, a->t_ms);
	double na = a->n, nb = n, nab = na + nb;
	for (int i = 0; i < a->npix; i++) {
		double mb = counts[i];
		double s = stddev ? (double)stddev[i] : 0.0;
		double m2b = n > 1 ? s * s * (nb - 1) : 0.0;
		double delta = mb - a->mean[i];
		a->mean[i] += delta * nb / nab;
		a->m2[i] += m2b + delta * delta * na * nb / nab;
		if (saturated && saturated[i])
			a->saturated[i] = 1;
	}
	a->n += n;
	return 0;
}

double exp_avg_std(const struct exp_avg *a, int p)
{
	if (a->n < 2 || p < 0 || p >= a->npix)
		return 0.0;
	double v = a->m2[p] / (double)(a->n - 1);
	return v > 0 ? sqrt(v) : 0.0;
}

int exp_net_rate(const struct exp_policy *p, const double *counts, const float *stddev, unsigned ns,
		 const unsigned char *saturated, int npix, double t_ms, const struct exp_dark *dark,
		 double full_scale, struct exp_rate *out, struct acq_err *err)
{
	if (npix <= 0 || npix > SPECTRO_MAX_PIXELS || !(t_ms > 0) || ns < 1)
		return acq_errf(err, ACQ_E_INVAL, "net rate: bad spectrum (%d pixels, %g ms, %u scans)", npix, t_ms, ns);
	if (!dark || dark->npix != npix)
		return acq_errf(err, ACQ_E_INVAL, "net rate: no dark with %d pixels", npix);
	if (fabs(dark->t_ms - t_ms) > 1e-9 * fmax(1.0, t_ms))
		return acq_errf(err, ACQ_E_INVAL, "net rate: dark at %g ms for a spectrum at %g ms", dark->t_ms, t_ms);
	double sat = p->sat_frac * full_scale;
	out->npix = npix;
	out->ninvalid = 0;
	double sq_s = sqrt((double)ns), sq_d = sqrt((double)(dark->averages ? dark->averages : 1));
	for (int i = 0; i < npix; i++) {
		out->t_ms[i] = t_ms;
		bool bad = (saturated && saturated[i]) || !(counts[i] < sat) || !isfinite(counts[i]) ||
			   !isfinite(dark->mean[i]) || !(dark->mean[i] < sat);
		if (bad) {
			out->valid[i] = 0;
			out->rate[i] = out->u_noise[i] = out->u_dark[i] = NAN;
			out->ninvalid++;
			continue;
		}
		out->valid[i] = 1;
		out->rate[i] = (counts[i] - dark->mean[i]) / t_ms;
		out->u_noise[i] = (stddev ? (double)stddev[i] : 0.0) / sq_s / t_ms;
		out->u_dark[i] = (double)dark->stddev[i] / sq_d / t_ms;
	}
	return 0;
}

int exp_merge(const struct exp_rate *const *in, int n, struct exp_rate *out, struct acq_err *err)
{
	if (n < 1 || !in[0])
		return acq_errf(err, ACQ_E_INVAL, "merge: no exposure");
	int npix = in[0]->npix;
	for (int k = 1; k < n; k++)
		if (!in[k] || in[k]->npix != npix)
			return acq_errf(err, ACQ_E_INVAL, "merge: exposure %d has a different pixel count", k);
	out->npix = npix;
	out->ninvalid = 0;
	for (int i = 0; i < npix; i++) {
		int best = -1;
		for (int k = 0; k < n; k++)
			if (in[k]->valid[i] && (best < 0 || in[k]->t_ms[i] > in[best]->t_ms[i]))
				best = k;
		if (best < 0) {
			out->valid[i] = 0;
			out->rate[i] = out->u_noise[i] = out->u_dark[i] = NAN;
			out->t_ms[i] = in[0]->t_ms[i];
			out->ninvalid++;
			continue;
		}
		out->valid[i] = 1;
		out->rate[i] = in[best]->rate[i];
		out->u_noise[i] = in[best]->u_noise[i];
		out->u_dark[i] = in[best]->u_dark[i];
		out->t_ms[i] = in[best]->t_ms[i];
	}
	return 0;
}

void exp_darks_clear(struct exp_darks *d)
{
	memset(d->used, 0, sizeof d->used);
}

static int dark_slot(const struct exp_darks *d, double t_ms)
{
	for (int i = 0; i < EXP_DARK_SLOTS; i++)
		if (d->used[i] && fabs(d->slot[i].t_ms - t_ms) <= 1e-9 * fmax(1.0, t_ms))
			return i;
	return -1;
}

const struct exp_dark *exp_dark_find(const struct exp_darks *d, double t_ms)
{
	int i = dark_slot(d, t_ms);
	return i < 0 ? NULL : &d->slot[i];
}

enum exp_dark_need exp_dark_check(const struct exp_darks *d, const struct exp_policy *p, double t_ms,
				  double now, double temp_c)
{
	const struct exp_dark *k = exp_dark_find(d, t_ms);
	if (!k)
		return EXP_DARK_MISSING;
	if (!(now - k->taken_at <= p->dark_max_age_s))
		return EXP_DARK_AGED;
	/* An unknown temperature on either side cannot show a drift; age alone decides then. */
	if (isfinite(temp_c) && isfinite(k->temperature_c) && fabs(temp_c - k->temperature_c) > p->dark_max_dtemp_c)
		return EXP_DARK_TEMP;
	return EXP_DARK_FRESH;
}

const struct exp_dark *exp_dark_store(struct exp_darks *d, const struct exp_avg *a, double now)
{
	int i = dark_slot(d, a->t_ms);
	if (i < 0) {
		for (int j = 0; j < EXP_DARK_SLOTS && i < 0; j++)
			if (!d->used[j])
				i = j;
	}
	if (i < 0) { /* evict the oldest */
		i = 0;
		for (int j = 1; j < EXP_DARK_SLOTS; j++)
			if (d->slot[j].taken_at < d->slot[i].taken_at)
				i = j;
	}
	struct exp_dark *k = &d->slot[i];
	d->used[i] = true;
	k->t_ms = a->t_ms;
	k->taken_at = now;
	k->temperature_c = a->temperature_c;
	k->averages = a->n ? a->n : 1;
	k->npix = a->npix;
	for (int p = 0; p < a->npix; p++) {
		k->mean[p] = a->mean[p];
		k->stddev[p] = (float)exp_avg_std(a, p);
	}
	return k;
}

void exp_dark_forget(struct exp_darks *d, double t_ms)
{
	int i = dark_slot(d, t_ms);
	if (i >= 0)
		d->used[i] = false;
}

const char *exp_dark_need_name(enum exp_dark_need n)
{
	switch (n) {
	case EXP_DARK_FRESH: return "fresh";
	case EXP_DARK_MISSING: return "missing";
	case EXP_DARK_AGED: return "aged";
	case EXP_DARK_TEMP: return "temperature";
	}
	return "unknown";
}

double exp_full_scale(const struct spectro_info *info)
{
	return info && info->max_counts > 0 ? info->max_counts : 65535.0;
}

void exp_mask_black(const struct spectro_info *info, struct exp_rate *r)
{
	for (int i = 0; info && i < info->ndark_pixels && i < 8; i++) {
		int p = info->dark_pixels[i];
		if (p >= 0 && p < r->npix && r->valid[p]) {
			r->valid[p] = 0;
			r->rate[p] = r->u_noise[p] = r->u_dark[p] = NAN;
			r->ninvalid++;
		}
	}
}
