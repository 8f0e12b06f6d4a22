/* select_route: a pick's cost as its increment to the batch's route (struct select_route in select.h): the motion of
 * inserting it into the route from the arms through the picks so far, at the cheapest place, plus its measurement
 * and, when it opens an incidence the batch does not visit yet (the arms' own counts as visited: the executor keeps
 * its dark cache while the incidence stays), that incidence's darks. */
#include <math.h>
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
	w->r = r;
	w->n = 1;
	w->ng = 0;
	w->pts = malloc((batch + 1) * 3 * sizeof *w->pts);
	w->inc = malloc((batch + 2) * sizeof *w->inc);
	if (!w->pts || !w->inc) {
		sel_route_free(w);
		return -1;
	}
	for (int k = 0; k < 3; k++)
		w->pts[k] = r->from[k];
	w->inc[w->ng++] = r->from[0]; /* the arms' incidence: the executor keeps its darks there */
	return 0;
}

void sel_route_free(struct sel_route *w)
{
	free(w->pts);
	free(w->inc);
	w->pts = w->inc = NULL;
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
	double c = fmax(best, 0) + r->base[i] + (visited(w, q[0]) ? 0 : r->open[i]);
	return fmax(c, 1e-9);
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
}
