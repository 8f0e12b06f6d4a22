/* select_route: a pick's cost as its increment to the batch's route (struct select_route in select.h): the motion of
 * inserting it into the route from the arms through the picks so far, at the cheapest place, plus its measurement
 * and, when it opens an incidence the batch does not visit yet (the arms' own counts as visited: the executor keeps
 * its dark cache while the incidence stays), that incidence's darks; with band nodes, its increment to the picks'
 * exposure seconds as the planner counts them (plan_time.c): its point, its expected dark at the rung decay of its
 * incidence, and the band's widening over every pick. */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "recon/select_int.h"

/* Laser positions this close are the same incidence (degrees). */
#define ROUTE_SAME_INC 1e-6

/* One axis's trapezoidal move over d degrees (the planner's plan_axis_time). */
static double axis_s(double v, double a, double d)
{
	d = fabs(d);
	if (!(d > 0))
		return 0;
	return d >= v * v / a ? d / v + v / a : 2.0 * sqrt(d / a);
}

double sel_route_move(const struct select_route *r, const double *p, const double *q)
{
	double d[3] = { q[0] - p[0], q[1] - p[1], remainder(q[2] - p[2], 360.0) }, t = 0, settle = 0;
	for (int k = 0; k < 3; k++)
		if (fabs(d[k]) > 1e-9) {
			t = fmax(t, axis_s(r->speed[k], r->accel[k], d[k]));
			settle = fmax(settle, r->settle[k]);
		}
	return t > 0 ? t + settle + r->move_s : 0;
}

int sel_route_init(struct sel_route *w, const struct select_route *r, size_t batch)
{
	*w = (struct sel_route){ .r = r, .n = 1, .cmin = INFINITY, .cmax = 0 };
	w->pts = malloc((batch + 1) * 3 * sizeof *w->pts);
	w->inc = malloc((batch + 2) * sizeof *w->inc);
	w->gl = malloc(5 * (batch + 1) * sizeof *w->gl);
	if (!w->pts || !w->inc || !w->gl) {
		sel_route_free(w);
		return -1;
	}
	w->gn = w->gl + (batch + 1);
	w->gs = w->gn + (batch + 1);
	w->gd = w->gs + (batch + 1);
	w->gk = w->gd + (batch + 1);
	for (int k = 0; k < 3; k++)
		w->pts[k] = r->from[k];
	w->inc[w->ng++] = r->from[0]; /* the arms' incidence: the executor keeps its darks there */
	return 0;
}

void sel_route_free(struct sel_route *w)
{
	free(w->pts);
	free(w->inc);
	free(w->gl);
	w->pts = w->inc = w->gl = NULL;
}

/* The band nodes' point, dark and rungs at rho (linear in ln rho between nodes, held beyond them). */
static void band_at(const struct select_route *r, double rho, double *pt, double *dk, double *rg)
{
	const double *v = r->nodes;
	size_t k = 0;
	while (k + 1 < r->nnodes && v[4 * (k + 1)] < rho)
		k++;
	double f = 0;
	if (k + 1 < r->nnodes && rho > v[4 * k])
		f = fmin(1, log(rho / v[4 * k]) / log(v[4 * (k + 1)] / v[4 * k]));
	const double *a = v + 4 * k, *b = k + 1 < r->nnodes ? a + 4 : a;
	*pt = a[1] + f * (b[1] - a[1]);
	*dk = a[2] + f * (b[2] - a[2]);
	*rg = a[3] + f * (b[3] - a[3]);
}

/* The band of cos range [cmin, cmax] (the planner's: none when the smallest cos is ≤ 0.01). */
static double band_rho(double cmin, double cmax)
{
	return cmin > 0.01 && cmax > cmin ? cmax / cmin : 1;
}

/* Expected darks of n points at an incidence after since there, each taking one with probability q^j (j the points
 * before it since the cache was cleared), q = 1 - 1/rungs. */
static double darks(double rungs, double since, double n)
{
	double q = 1 - 1 / fmax(rungs, 1);
	return q > 0 ? pow(q, since) * (1 - pow(q, n)) / (1 - q) : (since > 0 ? 0 : n > 0);
}

/* The incidence group of laser position l among the picks', or ngl. */
static size_t group(const struct sel_route *w, double l)
{
	size_t g = 0;
	while (g < w->ngl && fabs(w->gl[g] - l) > ROUTE_SAME_INC)
		g++;
	return g;
}

/* The picks' exposure seconds (with candidate i added unless i is SIZE_MAX) at band rho. */
static double exposure_s(const struct sel_route *w, size_t i, double rho)
{
	const struct select_route *r = w->r;
	double p0, d0, k0, p, d, k;
	band_at(r, 1, &p0, &d0, &k0);
	band_at(r, rho, &p, &d, &k);
	double fd = d0 > 0 ? d / d0 : 1, fk = k0 > 0 ? k / k0 : 1;
	size_t gi = i == SIZE_MAX ? SIZE_MAX : group(w, r->pos[3 * i]), n = 0;
	double t = w->pt + (i == SIZE_MAX ? 0 : r->point[i]);
	for (size_t g = 0; g < w->ngl; g++) {
		t += w->gd[g] * fd * darks(w->gk[g] * fk, w->gs[g], w->gn[g] + (g == gi));
		n += (size_t)w->gn[g];
	}
	if (gi == w->ngl) /* a new incidence */
		t += r->dark[i] * fd * darks(r->rungs[i] * fk, r->since[i], 1);
	n += i != SIZE_MAX;
	return t + (double)n * (p - p0);
}

/* Whether laser position l is one the batch visits already. */
static int visited(const struct sel_route *w, double l)
{
	for (size_t g = 0; g < w->ng; g++)
		if (fabs(w->inc[g] - l) <= ROUTE_SAME_INC)
			return 1;
	return 0;
}

double sel_route_cost(const struct sel_route *w, size_t i, size_t *at)
{
	const struct select_route *r = w->r;
	const double *q = r->pos + 3 * i;
	double best = INFINITY;
	size_t where = w->n;
	for (size_t k = 0; k < w->n; k++) {
		const double *a = w->pts + 3 * k;
		double d = sel_route_move(r, a, q);
		if (k + 1 < w->n) {
			const double *b = a + 3;
			d += sel_route_move(r, q, b) - sel_route_move(r, a, b);
		}
		if (d < best) {
			best = d;
			where = k + 1;
		}
	}
	if (at)
		*at = where;
	double e;
	if (r->nnodes)
		e = exposure_s(w, i, band_rho(fmin(w->cmin, r->band_cos[i]), fmax(w->cmax, r->band_cos[i]))) - w->T;
	else
		e = r->base[i] + (visited(w, q[0]) ? 0 : r->open[i]);
	return fmax(fmax(best, 0) + e, 1e-9);
}

void sel_route_add(struct sel_route *w, size_t i, size_t at)
{
	const double *q = w->r->pos + 3 * i;
	for (size_t k = w->n; k > at; k--)
		for (int x = 0; x < 3; x++)
			w->pts[3 * k + x] = w->pts[3 * (k - 1) + x];
	for (int x = 0; x < 3; x++)
		w->pts[3 * at + x] = q[x];
	w->n++;
	if (!visited(w, q[0]))
		w->inc[w->ng++] = q[0];
	const struct select_route *r = w->r;
	if (!r->nnodes)
		return;
	size_t g = group(w, q[0]);
	if (g == w->ngl) {
		w->gl[g] = q[0];
		w->gn[g] = 0;
		w->gs[g] = r->since[i];
		w->gd[g] = r->dark[i];
		w->gk[g] = r->rungs[i];
		w->ngl++;
	}
	w->gn[g]++;
	w->pt += r->point[i];
	w->cmin = fmin(w->cmin, r->band_cos[i]);
	w->cmax = fmax(w->cmax, r->band_cos[i]);
	w->T = exposure_s(w, SIZE_MAX, band_rho(w->cmin, w->cmax));
}
