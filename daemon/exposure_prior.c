/* exposure_prior: the exposure prior of a plan (plan.h struct plan_prior) from the previous auto sweep of the same
 * sample in the database: what the auto exposure chose there, per incidence (see exposure.h). */
#include "daemon/exposure.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/plan/plan.h"
#include "daemon/store.h"

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

static double median_of(double *v, size_t n)
{
	qsort(v, n, sizeof *v, cmp_double);
	return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* One incidence's figures from its points' first exposures first[0..np), the further ones (nx, sum xms), the
 * darks (nd, sum dms) and the rungs its exposures used. */
static void prior_inc(struct plan_prior_inc *q, double theta_i, double *first, size_t np, size_t nx, double xms,
		      size_t nd, double dms, uint64_t rungs)
{
	double sum = 0, lo = INFINITY, hi = 0;
	for (size_t i = 0; i < np; i++) {
		sum += first[i];
		lo = fmin(lo, first[i]);
		hi = fmax(hi, first[i]);
	}
	*q = (struct plan_prior_inc){ .theta_i = theta_i, .points = np, .mean_ms = sum / (double)np,
				      .spread = lo > 0 ? hi / lo : 1, .darks_per_clear = (double)nd,
				      .dark_ms = nd ? dms / (double)nd : 0, .extra_per_point = (double)nx / (double)np,
				      .extra_ms = nx ? xms / (double)nx : 0, .rungs = rungs };
	q->median_ms = median_of(first, np);
	if (np > 1) {
		double ls = 0, lv = 0;
		for (size_t i = 0; i < np; i++)
			ls += log(fmax(first[i], 1e-9));
		ls /= (double)np;
		for (size_t i = 0; i < np; i++)
			lv += (log(fmax(first[i], 1e-9)) - ls) * (log(fmax(first[i], 1e-9)) - ls);
		q->log_var = lv / (double)(np - 1);
	}
}

/* One done point of the prior's sweep, for the host's time per point. */
struct hpt {
	int64_t order;
	double done_at, first_ms, shots_s; /* its commit (wall s), first exposure, its exposures' bench time */
	struct plan_pos pos;
	double theta_i;
	int first_av;                      /* its first exposure's averages (the stored scans, a pooled probe's among them) */
	bool pooled;                       /* its first time is the previous point's: its probe was one of those scans */
};

static int cmp_hpt(const void *a, const void *b)
{
	const struct hpt *x = a, *y = b;
	return (x->order > y->order) - (x->order < y->order);
}

/* Moves shorter than this (degrees) are the arms' positioning noise and backlash, not a move of the plan. */
#define HOST_STILL_DEG 0.05

/* Mark the points (h sorted by order) whose first exposure is at the previous point's first time: the executor's
 * probe was at that time and counted as one of the exposure's scans (executor_acq.c, exp_probe_reusable; a probe
 * that was saturated there is not told apart: rare, it would have led to a shorter time). Per incidence of out the
 * share of its points so marked (pooled_per_point) and their mean first time (pooled_ms: on the green paint's paper
 * plan the pooled points sit at shorter times than the mean, 31.0 s spared against 35.3 s at the mean). */
static void prior_pooled(struct hpt *h, size_t n, struct plan_prior *out)
{
	size_t pooled[PLAN_PRIOR_MAX_INC] = { 0 };
	double ms[PLAN_PRIOR_MAX_INC] = { 0 };
	for (size_t i = 0; i < n; i++) {
		h[i].pooled = i > 0 && h[i].order == h[i - 1].order + 1 &&
			      fabs(h[i].first_ms - h[i - 1].first_ms) <= 1e-9 * fmax(1.0, h[i].first_ms);
		for (size_t k = 0; h[i].pooled && k < out->n_inc; k++)
			if (fabs(out->inc[k].theta_i - h[i].theta_i) < 1e-6) {
				pooled[k]++;
				ms[k] += h[i].first_ms;
				break;
			}
	}
	for (size_t k = 0; k < out->n_inc; k++) {
		out->inc[k].pooled_per_point = out->inc[k].points ? (double)pooled[k] / (double)out->inc[k].points : 0;
		out->inc[k].pooled_ms = pooled[k] ? ms[k] / (double)pooled[k] : 0;
	}
}

/* The host's real seconds per point in the prior's sweep (see exp_prior_build; h sorted by order, prior_pooled
 * marked): for each point that follows its predecessor in the plan's order, the real time between their commits
 * less what the bench took at the time scale (the straight move between the reached angles with its settling and
 * polling, the probe at the previous point's first time, its exposures and darks less the scan a pooled probe
 * spared). The mean over the points within 1 s of the median (a pause or a fault recovery is no host time). */
static void prior_host(struct hpt *h, size_t n, const struct bench_geom *g, const struct plan_timing *t,
		       struct plan_prior *out)
{
	out->host_per_point_s = 0;
	out->host_points = 0;
	if (!g || !t || n < 2 || !(t->time_scale > 0))
		return;
	double *v = malloc(n * sizeof *v), *w = malloc(n * sizeof *w);
	if (!v || !w) {
		free(v);
		free(w);
		return;
	}
	size_t m = 0;
	for (size_t i = 1; i < n; i++) {
		if (h[i].order != h[i - 1].order + 1 || !(h[i].done_at > 0) || !(h[i - 1].done_at > 0))
			continue;
		struct plan_pos a = h[i - 1].pos, b = h[i].pos;
		if (fabs(a.laser_theta - b.laser_theta) < HOST_STILL_DEG)
			b.laser_theta = a.laser_theta;
		if (fabs(a.det_theta - b.det_theta) < HOST_STILL_DEG)
			b.det_theta = a.det_theta;
		if (fabs(a.det_phi - b.det_phi) < HOST_STILL_DEG)
			b.det_phi = a.det_phi;
		double spared = !h[i].pooled ? 0
				: h[i].first_av > 1 ? h[i].first_ms / 1000.0
						    : h[i].first_ms / 1000.0 + g->readout_s + t->exposure_overhead_s;
		double bench = plan_move_time_s(g, t, &a, &b) + h[i].shots_s - spared +
			       h[i - 1].first_ms / 1000.0 + g->readout_s + t->exposure_overhead_s;
		v[m++] = h[i].done_at - h[i - 1].done_at - bench / t->time_scale;
	}
	if (m > 0) {
		memcpy(w, v, m * sizeof *w);
		double med = median_of(w, m), sum = 0;
		size_t k = 0;
		for (size_t i = 0; i < m; i++)
			if (v[i] <= med + 1.0) {
				sum += v[i];
				k++;
			}
		out->host_per_point_s = fmax(0, sum / (double)k);
		out->host_points = k;
	}
	free(v);
	free(w);
}

int exp_prior_build(const struct store_prior_row *rows, size_t n, const struct bench_geom *g,
		    const struct plan_timing *t, struct plan_prior *out)
{
	out->points = out->n_inc = 0;
	out->median_ms = out->spread = out->hdr_fraction = 0;
	double *all = malloc((n ? n : 1) * sizeof *all), *first = malloc((n ? n : 1) * sizeof *first);
	struct hpt *hp = malloc((n ? n : 1) * sizeof *hp);
	size_t nh = 0;
	if (!all || !first || !hp) {
		free(all);
		free(first);
		free(hp);
		return -1;
	}
	double ovh = g ? g->readout_s + (t ? t->exposure_overhead_s : 0) : 0;
	size_t na = 0, n_hdr = 0;
	for (size_t i = 0; i < n;) {
		/* one incidence: rows[i..j) */
		double th = rows[i].theta_i;
		size_t np = 0, nx = 0, nd = 0;
		double xms = 0, dms = 0;
		uint64_t rungs = 0; /* the sample exposures' rungs: the darks the executor needs there */
		size_t j = i;
		while (j < n && fabs(rows[j].theta_i - th) < 1e-6) {
			/* one point: rows[j..k); its first exposure is its shortest (an HDR one is hdr_ratio times longer) */
			int64_t pid = rows[j].point_id;
			size_t ns = 0;
			int lo_av = 1;
			double lo = INFINITY, sum = 0, shots = 0;
			const struct store_prior_row *p0 = &rows[j];
			for (; j < n && rows[j].point_id == pid && fabs(rows[j].theta_i - th) < 1e-6; j++) {
				shots += rows[j].averages * rows[j].integration_ms / 1000.0 + ovh;
				if (rows[j].dark) {
					nd++;
					dms += rows[j].integration_ms;
				} else {
					ns++;
					sum += rows[j].integration_ms;
					if (t)
						rungs |= (uint64_t)1 << plan_rung(t, rows[j].integration_ms);
					if (rows[j].integration_ms < lo)
						lo_av = rows[j].averages;
					lo = fmin(lo, rows[j].integration_ms);
				}
			}
			if (ns == 0)
				continue;
			hp[nh++] = (struct hpt){ p0->order_index, p0->done_at, lo, shots,
						 { p0->arm[0], p0->arm[1], p0->arm[2] }, th, lo_av, false };
			first[np++] = all[na++] = lo;
			nx += ns - 1;
			xms += sum - lo;
			n_hdr += ns > 1;
		}
		if (np > 0 && out->n_inc < PLAN_PRIOR_MAX_INC)
			prior_inc(&out->inc[out->n_inc++], th, first, np, nx, xms, nd, dms, rungs);
		i = j;
	}
	if (na > 0) {
		double lo = INFINITY, hi = 0;
		for (size_t i = 0; i < na; i++) {
			lo = fmin(lo, all[i]);
			hi = fmax(hi, all[i]);
		}
		out->points = na;
		out->spread = lo > 0 ? hi / lo : 1;
		out->hdr_fraction = (double)n_hdr / (double)na;
		out->median_ms = median_of(all, na);
	}
	qsort(hp, nh, sizeof *hp, cmp_hpt);
	prior_pooled(hp, nh, out);
	prior_host(hp, nh, g, t, out);
	free(all);
	free(first);
	free(hp);
	return 0;
}

static int add_row(void *ctx, const struct store_prior_row *r)
{
	struct exp_prior_rows *R = ctx;
	if (R->n == R->cap) {
		size_t cap = R->cap ? 2 * R->cap : 1024;
		struct store_prior_row *v = realloc(R->v, cap * sizeof *v);
		if (!v)
			return 1;
		R->v = v;
		R->cap = cap;
	}
	R->v[R->n++] = *r;
	return 0;
}

/* The prior from rows in R (sweep id of the sample name; NULL: none) into out. */
static int prior_from(const struct exp_prior_rows *R, int64_t id, const char *sample, const struct bench_geom *g,
		      const struct plan_timing *t, struct plan_prior *out, struct acq_err *err)
{
	memset(out, 0, sizeof *out);
	if (exp_prior_build(R->v, R->n, g, t, out))
		return acq_errf(err, ACQ_E_NOMEM, "exposure prior of sweep %lld: out of memory", (long long)id);
	if (out->n_inc > 0) {
		out->sweep = id;
		snprintf(out->sample, sizeof out->sample, "%s", sample ? sample : "");
	}
	return 0;
}

int exp_prior_load(struct store *st, const char *sample, long long exclude, const struct bench_geom *g,
		   const struct plan_timing *t, struct plan_prior *out, struct acq_err *err)
{
	memset(out, 0, sizeof *out);
	struct exp_prior_rows R = { 0 };
	int64_t id = 0;
	int rc = store_prior_each(st, sample, exclude, &id, add_row, &R, err);
	if (rc == 0 && id > 0)
		rc = prior_from(&R, id, sample, g, t, out, err);
	exp_prior_rows_free(&R);
	return rc;
}

void exp_prior_rows_free(struct exp_prior_rows *R)
{
	free(R->v);
	*R = (struct exp_prior_rows){ 0 };
}

/* The rows of the points committed since the last read into R, which stays in store_prior_rows' order (incidence,
 * point, time taken): the new points come after every point read (points are committed in the plan's order and
 * never return to pending), so they merge into R by incidence alone, after R's rows of the same incidence. */
static int rows_update(struct exp_prior_rows *R, struct store *st, long long sweep_id, struct acq_err *err)
{
	struct exp_prior_rows N = { 0 };
	if (store_prior_rows(st, sweep_id, R->next_order, add_row, &N, err)) {
		exp_prior_rows_free(&N);
		return -1;
	}
	if (N.n == 0)
		return 0;
	if (R->n + N.n > R->cap) {
		struct store_prior_row *v = realloc(R->v, (R->n + N.n) * sizeof *v);
		if (!v) {
			exp_prior_rows_free(&N);
			return acq_errf(err, ACQ_E_NOMEM, "exposure prior of sweep %lld: out of memory", sweep_id);
		}
		R->v = v;
		R->cap = R->n + N.n;
	}
	/* merge from the back: of equal incidences R's rows go first */
	size_t i = R->n, j = N.n, k = R->n + N.n;
	while (j > 0)
		R->v[--k] = i > 0 && R->v[i - 1].theta_i > N.v[j - 1].theta_i ? R->v[--i] : N.v[--j];
	R->n += N.n;
	for (size_t m = 0; m < N.n; m++)
		if (N.v[m].order_index >= R->next_order)
			R->next_order = N.v[m].order_index + 1;
	exp_prior_rows_free(&N);
	return 0;
}

int exp_prior_update(struct exp_prior_rows *R, struct store *st, long long sweep_id, const struct bench_geom *g,
		     const struct plan_timing *t, struct plan_prior *out, struct acq_err *err)
{
	memset(out, 0, sizeof *out);
	if (rows_update(R, st, sweep_id, err))
		return -1;
	return R->n > 0 ? prior_from(R, sweep_id, NULL, g, t, out, err) : 0;
}

int exp_prior_load_sweep(struct store *st, long long sweep_id, const struct bench_geom *g,
			 const struct plan_timing *t, struct plan_prior *out, struct acq_err *err)
{
	struct exp_prior_rows R = { 0 };
	int rc = exp_prior_update(&R, st, sweep_id, g, t, out, err);
	exp_prior_rows_free(&R);
	return rc;
}

int exp_host_load(struct store *st, long long exclude, const char *kind, const struct bench_geom *g,
		  const struct plan_timing *t, double *host_s, long long *sweep, struct acq_err *err)
{
	*sweep = 0;
	int64_t id = 0;
	if (store_latest_completed(st, exclude, kind, &id, err))
		return -1;
	return exp_host_load_sweep(st, id, g, t, host_s, sweep, err);
}

int exp_host_load_sweep(struct store *st, long long id, const struct bench_geom *g, const struct plan_timing *t,
			double *host_s, long long *sweep, struct acq_err *err)
{
	*sweep = 0;
	if (id <= 0)
		return 0;
	struct plan_prior pr;
	if (exp_prior_load_sweep(st, id, g, t, &pr, err))
		return -1;
	if (pr.host_points >= EXP_HOST_MIN_POINTS) {
		*host_s = pr.host_per_point_s;
		*sweep = id;
	}
	return 0;
}

void exp_host_cache_drop(struct exp_host_cache *c)
{
	c->valid = false;
}

/* Fill c from the store: the latest sweep of any kind, then of each kind (a sweep already read is not read again). */
static int host_cache_read(struct exp_host_cache *c, struct store *st, long long exclude, const struct bench_geom *g,
			   const struct plan_timing *t, struct acq_err *err)
{
	c->valid = false;
	c->reads++;
	c->n_kind = 0;
	c->any_sweep = 0;
	if (exp_host_load(st, exclude, NULL, g, t, &c->any_s, &c->any_sweep, err))
		return -1;
	for (int i = 0; i < PLAN_HOST_KINDS; i++) {
		struct plan_host_kind *k = &c->kind[c->n_kind];
		plan_kind_name(i, k->kind);
		int64_t id = 0;
		if (store_latest_completed(st, exclude, k->kind, &id, err))
			return -1;
		k->sweep = 0;
		if (id > 0 && id == c->any_sweep) {
			k->sweep = id;
			k->host_s = c->any_s;
		} else if (exp_host_load_sweep(st, id, g, t, &k->host_s, &k->sweep, err)) {
			return -1;
		}
		if (k->sweep > 0)
			c->n_kind++;
	}
	c->gen = store_completed_gen(st);
	c->exclude = exclude;
	c->valid = true;
	return 0;
}

int exp_host_cached(struct exp_host_cache *c, struct store *st, long long exclude, const struct bench_geom *g,
		    struct plan_timing *t, struct acq_err *err)
{
	if (!(c->valid && c->gen == store_completed_gen(st) && c->exclude == exclude) &&
	    host_cache_read(c, st, exclude, g, t, err))
		return -1;
	if (c->any_sweep > 0) {
		t->point_overhead_s = c->any_s;
		t->host_sweep = c->any_sweep;
	}
	memcpy(t->host_kind, c->kind, sizeof t->host_kind);
	t->n_host_kind = c->n_kind;
	return 0;
}
