/* plan_geom: blind-zone predicates, trapezoidal axis profiles, and the collision-safe move search. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/plan.h"

#define DEG (M_PI / 180.0)

static void unit_dir(double theta_deg, double phi_deg, double v[3])
{
	double st = sin(theta_deg * DEG), ct = cos(theta_deg * DEG);
	v[0] = st * cos(phi_deg * DEG);
	v[1] = st * sin(phi_deg * DEG);
	v[2] = ct;
}

double plan_psi_deg(const struct bench_geom *g, const struct plan_pos *p)
{
	double a[3], b[3];
	unit_dir(p->laser_theta, g->laser_phi_deg, a);
	unit_dir(p->det_theta, p->det_phi, b);
	/* atan2 of |a×b| and a·b is accurate for small and large angles alike */
	double c[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
	double s = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
	double d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
	return atan2(s, d) / DEG;
}

double plan_collision_deg(const struct bench_geom *g)
{
	return g->laser_body_halfwidth_deg + g->detector_body_halfwidth_deg + g->safety_margin_deg;
}

static bool in_axis(const struct bench_axis *a, double x)
{
	return x >= a->min_deg - 1e-9 && x <= a->max_deg + 1e-9;
}

unsigned plan_blind(const struct bench_geom *g, const struct plan_pos *p)
{
	unsigned r = 0;
	double m = g->safety_margin_deg;
	if (!(isfinite(p->laser_theta) && isfinite(p->det_theta) && isfinite(p->det_phi)))
		return PLAN_R_LIMITS;
	if (!in_axis(&g->laser_theta, p->laser_theta) || !in_axis(&g->detector_theta, p->det_theta) ||
	    !in_axis(&g->detector_phi, p->det_phi))
		r |= PLAN_R_LIMITS;
	double psi = plan_psi_deg(g, p);
	if (g->detector_radius_mm < g->laser_radius_mm &&
	    psi < g->detector_body_halfwidth_deg + g->beam_halfwidth_deg + m)
		r |= PLAN_R_BEAM;
	if (g->laser_radius_mm < g->detector_radius_mm && psi < g->laser_body_halfwidth_deg + g->fov_halfwidth_deg + m)
		r |= PLAN_R_VIEW;
	if (psi < plan_collision_deg(g))
		r |= PLAN_R_COLLISION;
	return r;
}

const char *plan_reason_name(unsigned r)
{
	if (r & PLAN_R_LIMITS)
		return "axis-limit";
	if (r & PLAN_R_COLLISION)
		return "collision";
	if (r & PLAN_R_BEAM)
		return "beam-occluded";
	if (r & PLAN_R_VIEW)
		return "view-occluded";
	if (r & PLAN_R_UNREACHABLE)
		return "unreachable";
	if (r & PLAN_R_NO_NEARBY)
		return "no-visible-point-nearby";
	return "none";
}

double plan_axis_time(const struct bench_axis *a, double d)
{
	d = fabs(d);
	if (!(d > 0))
		return 0;
	double v = a->speed_dps, acc = a->accel_dps2;
	if (d >= v * v / acc)
		return d / v + v / acc;
	return 2.0 * sqrt(d / acc);
}

double plan_axis_pos(const struct bench_axis *a, double x0, double x1, double t)
{
	double d = fabs(x1 - x0), sgn = x1 >= x0 ? 1.0 : -1.0;
	double T = plan_axis_time(a, d);
	if (!(t > 0))
		return x0;
	if (t >= T)
		return x1;
	double acc = a->accel_dps2, v = a->speed_dps, s;
	double ta = (d >= v * v / acc) ? v / acc : T / 2; /* end of the acceleration phase */
	double vp = acc * ta;                             /* peak speed */
	if (t <= ta)
		s = 0.5 * acc * t * t;
	else if (t <= T - ta)
		s = 0.5 * acc * ta * ta + vp * (t - ta);
	else {
		double r = T - t;
		s = d - 0.5 * acc * r * r;
	}
	return x0 + sgn * s;
}

double plan_seg_time(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q)
{
	double t = plan_axis_time(&g->laser_theta, q->laser_theta - p->laser_theta);
	t = fmax(t, plan_axis_time(&g->detector_theta, q->det_theta - p->det_theta));
	return fmax(t, plan_axis_time(&g->detector_phi, q->det_phi - p->det_phi));
}

static struct plan_pos seg_at(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q, double t)
{
	struct plan_pos r = {
		plan_axis_pos(&g->laser_theta, p->laser_theta, q->laser_theta, t),
		plan_axis_pos(&g->detector_theta, p->det_theta, q->det_theta, t),
		plan_axis_pos(&g->detector_phi, p->det_phi, q->det_phi, t),
	};
	return r;
}

/* Σ|Δaxis| between two configurations bounds how much ψ can change between them: ωi turns by exactly
 * |ΔθL|, ωo by at most |ΔθD| + sin θD |ΔφD| ≤ |ΔθD| + |ΔφD|, and ψ is 1-Lipschitz in each direction. Each
 * axis is monotonic within a segment, so over a time interval the displacement of every intermediate
 * instant from the interval's midpoint is bounded by the displacement of the interval's ends. */
static double l1(const struct plan_pos *a, const struct plan_pos *b)
{
	return fabs(a->laser_theta - b->laser_theta) + fabs(a->det_theta - b->det_theta) + fabs(a->det_phi - b->det_phi);
}

/* Bisection on time: an interval is proved safe when ψ(mid) minus the Lipschitz bound stays above the
 * threshold; it is unsafe when some sampled ψ is below it, or (conservatively) when the interval shrinks
 * below 1e-6° of travel without a proof. */
static bool interval_safe(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q, double R,
			  double t0, double t1, const struct plan_pos *x0, const struct plan_pos *x1, int depth)
{
	double tm = 0.5 * (t0 + t1);
	struct plan_pos xm = seg_at(g, p, q, tm);
	double psi = plan_psi_deg(g, &xm);
	if (psi < R)
		return false;
	double bound = fmax(l1(x0, &xm), l1(&xm, x1));
	if (psi - bound >= R)
		return true;
	if (bound < 1e-6 || depth > 60)
		return false;
	return interval_safe(g, p, q, R, t0, tm, x0, &xm, depth + 1) &&
	       interval_safe(g, p, q, R, tm, t1, &xm, x1, depth + 1);
}

bool plan_seg_safe(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q)
{
	double R = plan_collision_deg(g);
	double T = plan_seg_time(g, p, q);
	if (!in_axis(&g->laser_theta, p->laser_theta) || !in_axis(&g->laser_theta, q->laser_theta) ||
	    !in_axis(&g->detector_theta, p->det_theta) || !in_axis(&g->detector_theta, q->det_theta) ||
	    !in_axis(&g->detector_phi, p->det_phi) || !in_axis(&g->detector_phi, q->det_phi))
		return false;
	if (plan_psi_deg(g, p) < R || plan_psi_deg(g, q) < R)
		return false;
	if (T <= 0)
		return true;
	return interval_safe(g, p, q, R, 0, T, p, q, 0);
}

/* A candidate path: up to PLAN_MAX_WP configurations after a (the last is b). */
struct cand {
	struct plan_pos p[PLAN_MAX_WP];
	size_t n;
	double t;
};

static double clampd(double x, double lo, double hi)
{
	return x < lo ? lo : x > hi ? hi : x;
}

static void add_cand(struct cand *c, size_t *nc, size_t cap, const struct plan_pos *pts, size_t n)
{
	if (*nc >= cap)
		return;
	struct cand *k = &c[*nc];
	size_t m = 0;
	for (size_t i = 0; i < n; i++) {
		/* drop repeated configurations: they add nothing */
		const struct plan_pos *prev = m ? &k->p[m - 1] : NULL;
		if (prev && l1(prev, &pts[i]) < 1e-12)
			continue;
		k->p[m++] = pts[i];
	}
	if (m == 0)
		return;
	k->n = m;
	(*nc)++;
}

static double settle_of(const struct bench_geom *g, const struct plan_pos *a, const struct cand *c)
{
	bool mv[3] = { false, false, false };
	const struct plan_pos *prev = a;
	for (size_t i = 0; i < c->n; i++) {
		mv[0] |= fabs(c->p[i].laser_theta - prev->laser_theta) > 0;
		mv[1] |= fabs(c->p[i].det_theta - prev->det_theta) > 0;
		mv[2] |= fabs(c->p[i].det_phi - prev->det_phi) > 0;
		prev = &c->p[i];
	}
	double s = 0;
	if (mv[0])
		s = fmax(s, g->laser_theta.settle_s);
	if (mv[1])
		s = fmax(s, g->detector_theta.settle_s);
	if (mv[2])
		s = fmax(s, g->detector_phi.settle_s);
	return s;
}

static int cmp_cand(const void *x, const void *y)
{
	const struct cand *a = x, *b = y;
	return (a->t > b->t) - (a->t < b->t);
}

/* The candidates, cheapest first among the safe ones: the straight move; one arm then the other; and
 * detours through an intermediate detector zenith z (raise or lower the detector clear of the laser's
 * cone, swing the azimuth and/or the laser there, then come back down). The z values put the detector
 * just outside the collision cone of either end's laser direction, or at the detector's limits or zenith.
 * Going round the other way in azimuth is a different axis position of b (a wrap choice), made by the
 * caller, which tries each equivalent azimuth of the destination. */
double plan_move(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b,
		 struct plan_wp wps[PLAN_MAX_WP], size_t *n)
{
	enum { CAP = 64 };
	struct cand c[CAP];
	size_t nc = 0;
	*n = 0;
	if (l1(a, b) == 0) {
		return (plan_psi_deg(g, a) >= plan_collision_deg(g)) ? 0 : -1;
	}
	/* The straight move is never slower than any other path (each axis still covers its distance, and
	 * the trapezoid time is subadditive), so when it is safe it is the answer. */
	if (plan_seg_safe(g, a, b)) {
		wps[0].pos = *b;
		wps[0].duration_s = plan_seg_time(g, a, b);
		*n = 1;
		struct cand one = { .p = { *b }, .n = 1 };
		return wps[0].duration_s + settle_of(g, a, &one);
	}
	struct plan_pos lfirst[2] = { { b->laser_theta, a->det_theta, a->det_phi }, *b };
	struct plan_pos dfirst[2] = { { a->laser_theta, b->det_theta, b->det_phi }, *b };
	add_cand(c, &nc, CAP, lfirst, 2);
	add_cand(c, &nc, CAP, dfirst, 2);
	double R = plan_collision_deg(g), e = 0.5;
	double zs[16];
	size_t nz = 0;
	const struct bench_axis *dt = &g->detector_theta;
	double ls[2] = { fabs(a->laser_theta), fabs(b->laser_theta) };
	for (int i = 0; i < 2; i++) {
		zs[nz++] = ls[i] + R + e;
		zs[nz++] = ls[i] - R - e;
		zs[nz++] = -ls[i] + R + e;
		zs[nz++] = -ls[i] - R - e;
	}
	zs[nz++] = dt->min_deg;
	zs[nz++] = dt->max_deg;
	zs[nz++] = 0;
	for (size_t i = 0; i < nz; i++) {
		double z = clampd(zs[i], dt->min_deg, dt->max_deg);
		double la = a->laser_theta, lb = b->laser_theta, pa = a->det_phi, pb = b->det_phi;
		struct plan_pos v1[3] = { { la, z, pa }, { lb, z, pb }, *b };
		struct plan_pos v2[4] = { { la, z, pa }, { la, z, pb }, { lb, z, pb }, *b };
		struct plan_pos v3[4] = { { la, z, pa }, { lb, z, pa }, { lb, z, pb }, *b };
		add_cand(c, &nc, CAP, v1, 3);
		add_cand(c, &nc, CAP, v2, 4);
		add_cand(c, &nc, CAP, v3, 4);
	}
	for (size_t k = 0; k < nc; k++) {
		double t = 0;
		const struct plan_pos *prev = a;
		for (size_t i = 0; i < c[k].n; i++) {
			t += plan_seg_time(g, prev, &c[k].p[i]);
			prev = &c[k].p[i];
		}
		c[k].t = t + settle_of(g, a, &c[k]);
	}
	qsort(c, nc, sizeof c[0], cmp_cand);
	for (size_t k = 0; k < nc; k++) {
		const struct plan_pos *prev = a;
		bool ok = true;
		for (size_t i = 0; i < c[k].n && ok; i++) {
			ok = plan_seg_safe(g, prev, &c[k].p[i]);
			prev = &c[k].p[i];
		}
		if (!ok)
			continue;
		prev = a;
		for (size_t i = 0; i < c[k].n; i++) {
			wps[i].pos = c[k].p[i];
			wps[i].duration_s = plan_seg_time(g, prev, &c[k].p[i]);
			prev = &c[k].p[i];
		}
		*n = c[k].n;
		return c[k].t;
	}
	return -1;
}
