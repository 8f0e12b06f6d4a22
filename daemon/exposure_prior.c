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

/* One incidence's figures from its points' first exposures first[0..np), the further ones (nx, sum xms) and the
 * darks (nd, sum dms). */
static void prior_inc(struct plan_prior_inc *q, double theta_i, double *first, size_t np, size_t nx, double xms,
		      size_t nd, double dms)
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
				      .extra_ms = nx ? xms / (double)nx : 0 };
	q->median_ms = median_of(first, np);
}

int exp_prior_build(const struct store_prior_row *rows, size_t n, struct plan_prior *out)
{
	out->points = out->n_inc = 0;
	out->median_ms = out->spread = out->hdr_fraction = 0;
	double *all = malloc((n ? n : 1) * sizeof *all), *first = malloc((n ? n : 1) * sizeof *first);
	if (!all || !first) {
		free(all);
		free(first);
		return -1;
	}
	size_t na = 0, n_hdr = 0;
	for (size_t i = 0; i < n;) {
		/* one incidence: rows[i..j) */
		double th = rows[i].theta_i;
		size_t np = 0, nx = 0, nd = 0;
		double xms = 0, dms = 0;
		size_t j = i;
		while (j < n && fabs(rows[j].theta_i - th) < 1e-6) {
			/* one point: rows[j..k); its first exposure is its shortest (an HDR one is hdr_ratio times longer) */
			int64_t pid = rows[j].point_id;
			size_t ns = 0;
			double lo = INFINITY, sum = 0;
			for (; j < n && rows[j].point_id == pid && fabs(rows[j].theta_i - th) < 1e-6; j++) {
				if (rows[j].dark) {
					nd++;
					dms += rows[j].integration_ms;
				} else {
					ns++;
					sum += rows[j].integration_ms;
					lo = fmin(lo, rows[j].integration_ms);
				}
			}
			if (ns == 0)
				continue;
			first[np++] = all[na++] = lo;
			nx += ns - 1;
			xms += sum - lo;
			n_hdr += ns > 1;
		}
		if (np > 0 && out->n_inc < PLAN_PRIOR_MAX_INC)
			prior_inc(&out->inc[out->n_inc++], th, first, np, nx, xms, nd, dms);
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
	free(all);
	free(first);
	return 0;
}

struct rows {
	struct store_prior_row *v;
	size_t n, cap;
};

static int add_row(void *ctx, const struct store_prior_row *r)
{
	struct rows *R = ctx;
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

int exp_prior_load(struct store *st, const char *sample, long long exclude, struct plan_prior *out, struct acq_err *err)
{
	memset(out, 0, sizeof *out);
	struct rows R = { 0 };
	int64_t id = 0;
	int rc = store_prior_each(st, sample, exclude, &id, add_row, &R, err);
	if (rc == 0 && id > 0) {
		if (exp_prior_build(R.v, R.n, out))
			rc = acq_errf(err, ACQ_E_NOMEM, "exposure prior of sample '%s': out of memory", sample);
		else if (out->n_inc > 0) {
			out->sweep = id;
			snprintf(out->sample, sizeof out->sample, "%s", sample);
		}
	}
	free(R.v);
	return rc;
}
