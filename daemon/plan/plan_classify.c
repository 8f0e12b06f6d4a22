/* plan_classify: a plan spec's requested points (grid or Fibonacci set per incidence, reciprocal partners), their
 * duplicates, and their classification against the blind zones and the axis limits (dropped, or moved to the
 * nearest visible observation direction at the same incidence). Internal to the planner (plan_int.h). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/plan/plan_int.h"

double plan_norm360(double x)
{
	double r = fmod(x, 360.0);
	if (r < 0)
		r += 360.0;
	if (r >= 360.0)
		r = 0;
	return r;
}

int plan_phi_reps(const struct bench_geom *g, double phi, double out[MAX_REPS])
{
	int n = 0;
	for (int k = -3; k <= 3 && n < MAX_REPS; k++) {
		double x = phi + 360.0 * k;
		if (x >= g->detector_phi.min_deg - 1e-9 && x <= g->detector_phi.max_deg + 1e-9)
			out[n++] = fmin(fmax(x, g->detector_phi.min_deg), g->detector_phi.max_deg);
	}
	return n;
}

void plan_dir_of(double theta, double phi, double v[3])
{
	v[0] = sin(theta * DEG) * cos(phi * DEG);
	v[1] = sin(theta * DEG) * sin(phi * DEG);
	v[2] = cos(theta * DEG);
}

static void plan_dir_to_angles(const double v[3], double *theta, double *phi, double phi_hint)
{
	double r = sqrt(v[0] * v[0] + v[1] * v[1]);
	*theta = atan2(r, v[2]) / DEG;
	*phi = r < 1e-12 ? phi_hint : plan_norm360(atan2(v[1], v[0]) / DEG);
}

/* Canonical form: θD ≥ 0, φD in [0, 360). A negative zenith is the other side. */
struct plan_pos plan_canon(struct plan_pos p)
{
	if (p.det_theta < 0) {
		p.det_theta = -p.det_theta;
		p.det_phi += 180.0;
	}
	p.det_phi = plan_norm360(p.det_phi);
	return p;
}

/* Blind reasons of a canonical point, trying each equivalent azimuth for the limits. */
unsigned plan_classify(const struct bench_geom *g, const struct plan_pos *p)
{
	double reps[MAX_REPS];
	int n = plan_phi_reps(g, p->det_phi, reps);
	struct plan_pos q = *p;
	if (n == 0)
		return plan_blind(g, &q) | PLAN_R_LIMITS;
	q.det_phi = reps[0];
	return plan_blind(g, &q);
}

/* Great-circle angle between two unit vectors, degrees. */
static double plan_gc_deg(const double a[3], const double b[3])
{
	double c[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
	return atan2(sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]), a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / DEG;
}

/* Nearest visible observation direction at the same incidence: the blind zones are caps around ωi, so the
 * nearest point outside them lies on the great circle from ωi through ωo just past the largest active
 * half-angle; when that point breaks a limit, candidates on circles around ωi and along the limit
 * zeniths are tried and the nearest visible one wins. Returns false when none is within 30°. */
static bool plan_move_point(const struct bench_geom *g, const struct plan_pos *p, struct plan_pos *out, double *dist)
{
	double m = g->safety_margin_deg, thr = g->laser_body_halfwidth_deg + g->detector_body_halfwidth_deg + m;
	if (g->detector_radius_mm < g->laser_radius_mm)
		thr = fmax(thr, g->detector_body_halfwidth_deg + g->beam_halfwidth_deg + m);
	if (g->laser_radius_mm < g->detector_radius_mm)
		thr = fmax(thr, g->laser_body_halfwidth_deg + g->fov_halfwidth_deg + m);
	double wi[3], wo[3];
	plan_dir_of(p->laser_theta, g->laser_phi_deg, wi);
	plan_dir_of(p->det_theta, p->det_phi, wo);
	/* tangent basis at ωi */
	double ref[3] = { 0, 0, 1 };
	if (fabs(wi[2]) > 0.9) {
		ref[0] = 1;
		ref[2] = 0;
	}
	double e1[3] = { wi[1] * ref[2] - wi[2] * ref[1], wi[2] * ref[0] - wi[0] * ref[2], wi[0] * ref[1] - wi[1] * ref[0] };
	double l = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
	for (int i = 0; i < 3; i++)
		e1[i] /= l;
	double e2[3] = { wi[1] * e1[2] - wi[2] * e1[1], wi[2] * e1[0] - wi[0] * e1[2], wi[0] * e1[1] - wi[1] * e1[0] };
	/* the azimuth of ωo around ωi */
	double u = wo[0] * e1[0] + wo[1] * e1[1] + wo[2] * e1[2], w = wo[0] * e2[0] + wo[1] * e2[1] + wo[2] * e2[2];
	double a0 = (fabs(u) + fabs(w) > 1e-12) ? atan2(w, u) : 0;
	bool found = false;
	double best = 1e9;
	struct plan_pos bp = *p;
	const struct bench_axis *dt = &g->detector_theta;
	for (int ring = 0; ring < 40; ring++) {
		double rho = (thr + 2 * PLAN_EDGE_DEG + ring * 0.5) * DEG;
		if (rho / DEG - thr > 30.0)
			break;
		for (int k = 0; k < 720; k++) {
			double a = a0 + (k % 2 ? -1 : 1) * ((k + 1) / 2) * (M_PI / 360.0);
			double v[3];
			for (int i = 0; i < 3; i++)
				v[i] = cos(rho) * wi[i] + sin(rho) * (cos(a) * e1[i] + sin(a) * e2[i]);
			struct plan_pos q = { p->laser_theta, 0, 0 };
			plan_dir_to_angles(v, &q.det_theta, &q.det_phi, p->det_phi);
			double d = plan_gc_deg(v, wo);
			if (d < best && !plan_classify(g, &q)) {
				best = d;
				bp = q;
				found = true;
			}
		}
		/* points beyond the first ring are only needed when limits cut the cap's rim */
		if (found && best < rho / DEG + 1e-9)
			break;
	}
	/* along the limit zeniths (the cap rim may lie beyond them) */
	double zl[2] = { fmax(dt->min_deg, 0), fmin(dt->max_deg, 90) };
	for (int j = 0; j < 2; j++) {
		for (int k = 0; k < 3600; k++) {
			struct plan_pos q = { p->laser_theta, zl[j], k * 0.1 };
			double v[3];
			plan_dir_of(q.det_theta, q.det_phi, v);
			double d = plan_gc_deg(v, wo);
			if (d < best && !plan_classify(g, &q)) {
				best = d;
				bp = q;
				found = true;
			}
		}
	}
	if (!found || best > 30.0)
		return false;
	*out = plan_canon(bp);
	*dist = best;
	return true;
}

/* ---- expansion, duplicates, classification --------------------------------------------------------- */

int plan_expand(const struct plan_spec *s, struct plan_req **out, size_t *n, struct acq_err *err)
{
	size_t per = s->fib_count ? s->fib_count : s->n_obs_theta * s->n_obs_phi;
	size_t total = per * s->n_incidence;
	struct plan_req *r = calloc(total + s->reciprocal_pairs + 1, sizeof *r);
	if (!r)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory for %zu points", total);
	size_t k = 0;
	const double golden = 180.0 * (3.0 - sqrt(5.0)); /* degrees */
	for (size_t i = 0; i < s->n_incidence; i++) {
		if (s->fib_count) {
			double cmax = cos(s->fib_max_theta_deg * DEG);
			for (size_t j = 0; j < s->fib_count; j++) {
				double c = 1.0 - (1.0 - cmax) * ((double)j + 0.5) / (double)s->fib_count;
				r[k].req = (struct plan_pos){ s->incidence[i], acos(c) / DEG, plan_norm360(golden * (double)j) };
				k++;
			}
		} else {
			for (size_t a = 0; a < s->n_obs_theta; a++)
				for (size_t b = 0; b < s->n_obs_phi; b++) {
					r[k].req = (struct plan_pos){ s->incidence[i], s->obs_theta[a], s->obs_phi[b] };
					k++;
				}
		}
	}
	*out = r;
	*n = k;
	return 0;
}

struct dkey {
	int64_t q[4];
	size_t i;
};

static int cmp_dkey(const void *x, const void *y)
{
	const struct dkey *a = x, *b = y;
	for (int i = 0; i < 4; i++)
		if (a->q[i] != b->q[i])
			return a->q[i] < b->q[i] ? -1 : 1;
	return (a->i > b->i) - (a->i < b->i);
}

/* Mark later requests of an already requested configuration (same θL, same ωo to ~1e-7) duplicates.
 * measured: compare where points are measured (pos) among kept and moved ones, else as requested. */
int plan_mark_duplicates(struct plan_req *r, size_t n, bool measured, struct acq_err *err)
{
	struct dkey *k = malloc((n ? n : 1) * sizeof *k);
	if (!k)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	size_t m = 0;
	for (size_t i = 0; i < n; i++) {
		if (measured && r[i].status != PLAN_KEPT && r[i].status != PLAN_MOVED)
			continue;
		const struct plan_pos *p = measured ? &r[i].pos : &r[i].req;
		double v[3];
		plan_dir_of(p->det_theta, p->det_phi, v);
		k[m].q[0] = llround(p->laser_theta * 1e7);
		for (int j = 0; j < 3; j++)
			k[m].q[j + 1] = llround(v[j] * 1e7);
		k[m].i = i;
		m++;
	}
	qsort(k, m, sizeof *k, cmp_dkey);
	for (size_t i = 1; i < m; i++) {
		if (!memcmp(k[i].q, k[i - 1].q, sizeof k[i].q)) {
			size_t first = k[i - 1].i;
			if (r[first].status == PLAN_DUPLICATE)
				first = r[first].same_as;
			r[k[i].i].status = PLAN_DUPLICATE;
			r[k[i].i].same_as = first;
		}
	}
	free(k);
	return 0;
}

void plan_classify_req(const struct bench_geom *g, struct plan_req *r, enum plan_blind_policy policy)
{
	r->pos = plan_canon(r->req);
	r->reason = plan_classify(g, &r->pos);
	r->moved_deg = 0;
	if (!r->reason) {
		r->status = PLAN_KEPT;
	} else if (policy == PLAN_BLIND_MOVE && r->role == PLAN_ROLE_GRID &&
		   g->laser_theta.min_deg - 1e-9 <= r->pos.laser_theta &&
		   r->pos.laser_theta <= g->laser_theta.max_deg + 1e-9) {
		struct plan_pos q;
		double d;
		if (plan_move_point(g, &r->pos, &q, &d)) {
			r->status = PLAN_MOVED;
			r->pos = q;
			r->moved_deg = d;
		} else {
			r->status = PLAN_DROPPED;
			r->reason |= PLAN_R_NO_NEARBY;
		}
	} else {
		r->status = PLAN_DROPPED;
	}
	r->psi_deg = plan_psi_deg(g, &r->pos);
}

int plan_add_reciprocals(const struct plan_spec *s, const struct bench_geom *g, struct plan_req *r, size_t *n)
{
	size_t ngrid = *n, nvis = 0;
	for (size_t i = 0; i < ngrid; i++)
		nvis += r[i].status == PLAN_KEPT;
	size_t want = s->reciprocal_pairs < nvis ? s->reciprocal_pairs : nvis;
	size_t seen = 0, k = 0;
	for (size_t i = 0; i < ngrid && k < want; i++) {
		if (r[i].status != PLAN_KEPT)
			continue;
		/* evenly spread: take visible point number floor(j·nvis/want) */
		if (seen++ != (k * nvis) / want)
			continue;
		struct plan_req *q = &r[*n];
		memset(q, 0, sizeof *q);
		/* swap ωi and ωo, rotated about the normal so the laser stays at its azimuth (isotropic sample):
		 * the relative azimuth φo − φi changes sign */
		double rel = r[i].pos.det_phi - g->laser_phi_deg;
		q->req = (struct plan_pos){ r[i].pos.det_theta, r[i].pos.laser_theta, g->laser_phi_deg - rel };
		if (q->req.det_theta < 0) {
			q->req.det_theta = -q->req.det_theta;
			q->req.det_phi += 180.0;
		}
		q->req.det_phi = plan_norm360(q->req.det_phi);
		q->role = PLAN_ROLE_RECIPROCAL;
		q->partner = i;
		(*n)++;
		k++;
	}
	return 0;
}
