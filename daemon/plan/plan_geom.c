/* plan_geom: blind-zone predicates, trapezoidal axis profiles, and the collision-safe move search. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/plan/plan.h"

#define DEG (M_PI / 180.0)

double plan_psi_deg(const struct bench_geom *g, const struct plan_pos *p)
{
	/* spherical law of cosines; ωi sits at azimuth laser_phi (a negative θL flips it through the normal) */
	double c = cos(p->laser_theta * DEG) * cos(p->det_theta * DEG) +
		   sin(p->laser_theta * DEG) * sin(p->det_theta * DEG) * cos((p->det_phi - g->laser_phi_deg) * DEG);
	return acos(c > 1 ? 1 : c < -1 ? -1 : c) / DEG;
}

double plan_collision_deg(const struct bench_geom *g)
{
	return g->laser_body_halfwidth_deg + g->detector_body_halfwidth_deg + g->safety_margin_deg;
}

double plan_clearance_deg(const struct bench_geom *g)
{
	double m = g->safety_margin_deg, t = plan_collision_deg(g);
	if (g->detector_radius_mm < g->laser_radius_mm)
		t = fmax(t, g->detector_body_halfwidth_deg + g->beam_halfwidth_deg + m);
	if (g->laser_radius_mm < g->detector_radius_mm)
		t = fmax(t, g->laser_body_halfwidth_deg + g->fov_halfwidth_deg + m);
	return t;
}

static bool in_axis(const struct bench_axis *a, double x)
{
	return x >= a->min_deg - 1e-9 && x <= a->max_deg + 1e-9;
}

unsigned plan_blind(const struct bench_geom *g, const struct plan_pos *p)
{
	unsigned r = 0;
	double m = g->safety_margin_deg + PLAN_EDGE_DEG; /* a point on the edge counts as blind */
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
	if (psi < plan_collision_deg(g) + PLAN_EDGE_DEG)
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

static double l1(const struct plan_pos *a, const struct plan_pos *b)
{
	return fabs(a->laser_theta - b->laser_theta) + fabs(a->det_theta - b->det_theta) + fabs(a->det_phi - b->det_phi);
}

static double peak_speed(const struct bench_axis *a, double d)
{
	d = fabs(d);
	return d >= a->speed_dps * a->speed_dps / a->accel_dps2 ? a->speed_dps : sqrt(a->accel_dps2 * d);
}

/* Why the advance below is sound: ωi turns at exactly |dθL/dt|; ωo moves at most at |dθD/dt| +
 * |sin θD|·|dφD/dt| (the path's length element is √(dθ² + sin²θ dφ²)); ψ is 1-Lipschitz in each direction.
 * Within a segment every axis is monotonic, so θD stays between its ends and |sin θD| ≤ sin(max |θD| of
 * the ends) (or 1 past 90°); no axis exceeds its peak speed of this segment's trapezoid.
 *
 * Safe advance along time: at an instant where ψ exceeds the threshold by gap, ψ cannot fall below it for
 * gap / rate seconds, rate bounding dψ/dt (the axes' peak speeds in this segment, the azimuth's weighted by
 * the largest |sin θD| on the way). A gap under PLAN_EDGE_DEG counts as unsafe: a conservative answer, never a
 * false "safe". */
static bool advance_safe(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q, double R)
{
	double T = plan_seg_time(g, p, q);
	double tmax = fmax(fabs(p->det_theta), fabs(q->det_theta));
	double smax = tmax >= 90.0 ? 1.0 : sin(tmax * DEG);
	double rate = peak_speed(&g->laser_theta, q->laser_theta - p->laser_theta) +
		      peak_speed(&g->detector_theta, q->det_theta - p->det_theta) +
		      smax * peak_speed(&g->detector_phi, q->det_phi - p->det_phi);
	if (!(rate > 0))
		return plan_psi_deg(g, p) >= R;
	double t = 0;
	for (long it = 0; it < 10000000; it++) {
		struct plan_pos x = seg_at(g, p, q, t);
		double gap = plan_psi_deg(g, &x) - R;
		if (gap < PLAN_EDGE_DEG)
			return false;
		t += gap / rate;
		if (t >= T)
			return true;
	}
	return false;
}

/* With the laser still, a segment stays inside the box θD ∈ [t1, t2], φD ∈ [p1, p2] (monotonic axes).
 * For fixed θD, ψ grows with the azimuth separation Δ from the laser's plane (θL, θD in [0, 90]); for fixed
 * Δ, ψ along the meridian is unimodal with its minimum at tan θ* = tan θL cos Δ. So the box's smallest ψ
 * is at (clamp(θ*), smallest Δ): an exact, cheap proof for most moves inside an incidence group. */
static double box_min_psi(const struct bench_geom *g, double tl, double t1, double t2, double p1, double p2)
{
	double lo = fmin(p1, p2), hi = fmax(p1, p2), d;
	double k = ceil((lo - g->laser_phi_deg) / 360.0);
	if (g->laser_phi_deg + 360.0 * k <= hi)
		d = 0; /* the box spans the laser's azimuth */
	else {
		double a = fmod(fabs(lo - g->laser_phi_deg), 360.0), b = fmod(fabs(hi - g->laser_phi_deg), 360.0);
		a = fmin(a, 360.0 - a);
		b = fmin(b, 360.0 - b);
		d = fmin(a, b);
	}
	double ts = atan(tan(tl * DEG) * cos(d * DEG)) / DEG;
	double th = ts < fmin(t1, t2) ? fmin(t1, t2) : ts > fmax(t1, t2) ? fmax(t1, t2) : ts;
	struct plan_pos x = { tl, th, g->laser_phi_deg + d };
	return plan_psi_deg(g, &x);
}

static bool seg_check(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q, double R)
{
	double T = plan_seg_time(g, p, q);
	if (!in_axis(&g->laser_theta, p->laser_theta) || !in_axis(&g->laser_theta, q->laser_theta) ||
	    !in_axis(&g->detector_theta, p->det_theta) || !in_axis(&g->detector_theta, q->det_theta) ||
	    !in_axis(&g->detector_phi, p->det_phi) || !in_axis(&g->detector_phi, q->det_phi))
		return false;
	if (plan_psi_deg(g, p) < R || plan_psi_deg(g, q) < R)
		return false;
	if (T <= 0)
		return true;
	if (p->laser_theta == q->laser_theta && p->laser_theta >= 0 && p->laser_theta < 90 &&
	    p->det_theta >= 0 && p->det_theta <= 90 && q->det_theta >= 0 && q->det_theta <= 90 &&
	    box_min_psi(g, p->laser_theta, p->det_theta, q->det_theta, p->det_phi, q->det_phi) >= R + PLAN_EDGE_DEG)
		return true;
	return advance_safe(g, p, q, R);
}

bool plan_seg_safe(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q)
{
	return seg_check(g, p, q, plan_collision_deg(g));
}

bool plan_seg_clear(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q)
{
	return seg_check(g, p, q, plan_clearance_deg(g));
}

bool plan_seg_keeps(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q, double psi_min)
{
	return seg_check(g, p, q, psi_min);
}

/* A candidate path: up to BASIC_WP configurations after a (the last is b). */
#define BASIC_WP 4
struct cand {
	struct plan_pos p[BASIC_WP];
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
static double move_basic(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b,
			 struct plan_wp wps[BASIC_WP], size_t *n)
{
	enum { CAP = 128 };
	struct cand c[CAP];
	size_t nc = 0;
	*n = 0;
	if (l1(a, b) == 0) {
		return (plan_psi_deg(g, a) >= plan_clearance_deg(g)) ? 0 : -1;
	}
	/* The straight move is never slower than any other path (each axis still covers its distance, and
	 * the trapezoid time is subadditive), so when it is safe it is the answer. */
	if (plan_seg_clear(g, a, b)) {
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
	double R = plan_clearance_deg(g), e = 0.5;
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
	/* park the laser at the normal while the detector goes to b, then raise it: the way to a point near the
	 * laser's plane on the detector's soft limits, which every other path reaches by sweeping past the laser */
	{
		double l0 = clampd(0, g->laser_theta.min_deg, g->laser_theta.max_deg);
		struct plan_pos park[3] = { { l0, a->det_theta, a->det_phi }, { l0, b->det_theta, b->det_phi }, *b };
		add_cand(c, &nc, CAP, park, 3);
	}
	/* azimuth escapes: swing the detector clear of the laser's plane, move the laser, come back */
	const struct bench_axis *dp = &g->detector_phi;
	for (int side = 0; side < 4; side++) {
		double p0 = g->laser_phi_deg + (side < 2 ? 90.0 : 180.0) * (side % 2 ? -1 : 1);
		for (int k = -3; k <= 3; k++) {
			double p = p0 + 360.0 * k;
			if (p < dp->min_deg || p > dp->max_deg)
				continue;
			double la = a->laser_theta, lb = b->laser_theta, da = a->det_theta, db = b->det_theta;
			struct plan_pos w1[3] = { { la, da, p }, { lb, da, p }, *b };
			struct plan_pos w2[3] = { { la, da, p }, { lb, db, p }, *b };
			add_cand(c, &nc, CAP, w1, 3);
			add_cand(c, &nc, CAP, w2, 3);
		}
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
			ok = plan_seg_clear(g, prev, &c[k].p[i]);
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

/* The settle-inclusive time of a waypoint list starting at a. */
static double list_time(const struct bench_geom *g, const struct plan_pos *a, const struct plan_wp *w, size_t n)
{
	double segs = 0;
	bool mv[3] = { false, false, false };
	const struct plan_pos *prev = a;
	for (size_t i = 0; i < n; i++) {
		segs += w[i].duration_s;
		mv[0] |= w[i].pos.laser_theta != prev->laser_theta;
		mv[1] |= w[i].pos.det_theta != prev->det_theta;
		mv[2] |= w[i].pos.det_phi != prev->det_phi;
		prev = &w[i].pos;
	}
	return segs + fmax(mv[0] ? g->laser_theta.settle_s : 0,
			   fmax(mv[1] ? g->detector_theta.settle_s : 0, mv[2] ? g->detector_phi.settle_s : 0));
}

/* p's observation direction pushed away from the laser's direction by delta degrees along the great
 * circle through both, its zenith clamped to the detector's limits (false when the azimuth leaves its
 * limits or nothing moves); the azimuth stays near p's. */
static bool push_away(const struct bench_geom *g, const struct plan_pos *p, double delta, struct plan_pos *out)
{
	double wi[3] = { sin(p->laser_theta * DEG) * cos(g->laser_phi_deg * DEG),
			 sin(p->laser_theta * DEG) * sin(g->laser_phi_deg * DEG), cos(p->laser_theta * DEG) };
	double v[3] = { sin(p->det_theta * DEG) * cos(p->det_phi * DEG), sin(p->det_theta * DEG) * sin(p->det_phi * DEG),
			cos(p->det_theta * DEG) };
	double c = wi[0] * v[0] + wi[1] * v[1] + wi[2] * v[2], t[3], l = 0;
	for (int k = 0; k < 3; k++) {
		t[k] = v[k] * c - wi[k];
		l += t[k] * t[k];
	}
	l = sqrt(l);
	if (l < 1e-9)
		return false;
	double w[3];
	for (int k = 0; k < 3; k++)
		w[k] = cos(delta * DEG) * v[k] + sin(delta * DEG) * t[k] / l;
	double r = sqrt(w[0] * w[0] + w[1] * w[1]);
	double th = atan2(r, w[2]) / DEG, ph = r < 1e-12 ? p->det_phi : atan2(w[1], w[0]) / DEG;
	ph = p->det_phi + remainder(ph - p->det_phi, 360.0);
	/* against a zenith limit, slide along it instead */
	th = clampd(th, g->detector_theta.min_deg, g->detector_theta.max_deg);
	*out = (struct plan_pos){ p->laser_theta, th, ph };
	return in_axis(&g->detector_phi, ph) && l1(p, out) > 1e-9;
}

/* Template moves, else through approach points: configurations pushed straight away from the laser's
 * cone, reached (or left) by a single segment, so a point tucked against the cone's edge is approached
 * from outside rather than along the edge. Up to MID_WP waypoints. */
#define MID_WP (BASIC_WP + 2)
static double move_mid(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b,
		       struct plan_wp wps[MID_WP], size_t *n)
{
	double t = move_basic(g, a, b, wps, n);
	if (t >= 0)
		return t;
	static const double deltas[] = { 5, 10, 20, 40 };
	double best = -1;
	struct plan_wp w[BASIC_WP], tmp[MID_WP];
	size_t nw;
	for (size_t i = 0; i < sizeof deltas / sizeof deltas[0]; i++) {
		for (size_t j = 0; j <= sizeof deltas / sizeof deltas[0]; j++) {
			/* leave a through ca (j == 0: straight from a), reach b through cb (i) */
			struct plan_pos ca = *a, cb;
			if (!push_away(g, b, deltas[i], &cb) || !plan_seg_clear(g, &cb, b))
				continue;
			if (j > 0 && (!push_away(g, a, deltas[j - 1], &ca) || !plan_seg_clear(g, a, &ca)))
				continue;
			if (move_basic(g, &ca, &cb, w, &nw) < 0)
				continue;
			size_t m = 0;
			if (j > 0) {
				tmp[m].pos = ca;
				tmp[m++].duration_s = plan_seg_time(g, a, &ca);
			}
			for (size_t k = 0; k < nw; k++)
				tmp[m++] = w[k];
			tmp[m].pos = *b;
			tmp[m++].duration_s = plan_seg_time(g, &cb, b);
			double tt = list_time(g, a, tmp, m);
			if (best < 0 || tt < best) {
				best = tt;
				memcpy(wps, tmp, m * sizeof *tmp);
				*n = m;
			}
		}
		if (best >= 0)
			break; /* the smallest detour that works */
	}
	return best;
}

/* When no single template works (e.g. both arms high, near each other, on both sides of the laser's
 * plane), go through a parking configuration: the detector at zenith z in the plane perpendicular to the
 * laser's (azimuth laser_phi ± 90°), where cos ψ = cos θL cos z, so ψ ≥ z for every laser position: the
 * laser can then move freely. Each leg to and from the park is itself a template move. */
double plan_move(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b,
		 struct plan_wp wps[PLAN_MAX_WP], size_t *n)
{
	double t = move_mid(g, a, b, wps, n);
	if (t >= 0)
		return t;
	const struct bench_axis *dt = &g->detector_theta, *dp = &g->detector_phi;
	double R = plan_clearance_deg(g);
	double zs[] = { 45, 60, 30, 75, 90, R + 1.0 };
	double best = -1;
	struct plan_wp w1[MID_WP], w3[MID_WP];
	size_t n1, n3;
	for (size_t iz = 0; iz < sizeof zs / sizeof zs[0]; iz++) {
		double z = zs[iz];
		if (z <= R || z < dt->min_deg || z > dt->max_deg)
			continue;
		for (int side = -1; side <= 1; side += 2) {
			for (int k = -3; k <= 3; k++) {
				double p = g->laser_phi_deg + 90.0 * side + 360.0 * k;
				if (p < dp->min_deg || p > dp->max_deg)
					continue;
				struct plan_pos pa = { a->laser_theta, z, p }, pb = { b->laser_theta, z, p };
				double t1 = move_mid(g, a, &pa, w1, &n1);
				if (t1 < 0 || !plan_seg_clear(g, &pa, &pb))
					continue;
				double t3 = move_mid(g, &pb, b, w3, &n3);
				if (t3 < 0)
					continue;
				struct plan_wp tmp[PLAN_MAX_WP];
				size_t m = 0;
				for (size_t i = 0; i < n1; i++)
					tmp[m++] = w1[i];
				if (pb.laser_theta != pa.laser_theta) {
					tmp[m].pos = pb;
					tmp[m++].duration_s = plan_seg_time(g, &pa, &pb);
				}
				for (size_t i = 0; i < n3; i++)
					tmp[m++] = w3[i];
				/* settling happens once, at the end: count it over the whole move */
				double segs = 0;
				bool mv[3] = { false, false, false };
				const struct plan_pos *prev = a;
				for (size_t i = 0; i < m; i++) {
					segs += tmp[i].duration_s;
					mv[0] |= tmp[i].pos.laser_theta != prev->laser_theta;
					mv[1] |= tmp[i].pos.det_theta != prev->det_theta;
					mv[2] |= tmp[i].pos.det_phi != prev->det_phi;
					prev = &tmp[i].pos;
				}
				double settle = fmax(mv[0] ? g->laser_theta.settle_s : 0,
						     fmax(mv[1] ? g->detector_theta.settle_s : 0,
							  mv[2] ? g->detector_phi.settle_s : 0));
				double tt = segs + settle;
				if (best >= 0 && tt >= best)
					continue;
				best = tt;
				memcpy(wps, tmp, m * sizeof *tmp);
				*n = m;
			}
		}
	}
	return best;
}

double plan_escape(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b,
		   struct plan_wp wps[PLAN_MAX_WP + 1], size_t *n)
{
	double psi = plan_psi_deg(g, a), R = plan_clearance_deg(g);
	double keep = fmin(plan_collision_deg(g), psi) - 2 * PLAN_EDGE_DEG;
	/* the smallest step out of the clearance first, then wider ones (a zenith limit can eat part of a step) */
	double deltas[] = { R - psi + 0.5, R - psi + 2, 5, 10, 20, 40 };
	*n = 0;
	if (psi >= R)
		return -1;
	for (size_t i = 0; i < sizeof deltas / sizeof deltas[0]; i++) {
		struct plan_pos e;
		struct plan_wp w[PLAN_MAX_WP];
		size_t m = 0;
		if (deltas[i] <= 0 || !push_away(g, a, deltas[i], &e) || plan_psi_deg(g, &e) < R + PLAN_EDGE_DEG ||
		    !plan_seg_keeps(g, a, &e, keep))
			continue;
		double t = plan_move(g, &e, b, w, &m);
		if (t < 0)
			continue;
		wps[0].pos = e;
		wps[0].duration_s = plan_seg_time(g, a, &e);
		memcpy(wps + 1, w, m * sizeof *w);
		*n = m + 1;
		return wps[0].duration_s + t;
	}
	return -1;
}
