/* plan_home: ordering the steps of an all-axes home so that each single-axis move is collision-free. */
#include "daemon/plan/plan_home.h"

#include <math.h>

unsigned plan_home_move_verdict(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b)
{
	unsigned blind = plan_blind(g, b) & (PLAN_R_COLLISION | PLAN_R_LIMITS);
	if (blind)
		return blind;
	if (plan_blind(g, a) & PLAN_R_COLLISION)
		return 0; /* stuck inside the cone: only the target counts (the way out) */
	return plan_seg_safe(g, a, b) ? 0 : PLAN_R_UNREACHABLE;
}

bool plan_home_move_ok(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b)
{
	return plan_home_move_verdict(g, a, b) == 0;
}

static double *pos_axis(struct plan_pos *p, int axis)
{
	return axis == 0 ? &p->laser_theta : axis == 1 ? &p->det_theta : &p->det_phi;
}

/* Depth-first search over the remaining steps: state bit 2a = axis a homed, bit 2a+1 = parked. */
static bool search(const struct bench_geom *g, struct plan_pos p, const double *park, unsigned need, unsigned done,
		   struct plan_home_step *steps, int n, int *len)
{
	if (done == need) {
		*len = n;
		return true;
	}
	for (int a = 0; a < 3; a++) {
		for (int k = 1; k >= 0; k--) { /* a park (after its home) before the next home: the arm out of the way */
			unsigned bit = 1u << (2 * a + k);
			if (!(need & bit) || (done & bit) || (k == 1 && !(done & (1u << (2 * a)))))
				continue;
			struct plan_pos q = p;
			double target = k ? park[a] : 0;
			*pos_axis(&q, a) = target;
			if (!plan_home_move_ok(g, &p, &q))
				continue;
			steps[n] = (struct plan_home_step){ .axis = a, .park = k == 1, .target = target };
			if (search(g, q, park, need, done | bit, steps, n + 1, len))
				return true;
		}
	}
	return false;
}

static const struct bench_axis *axis_of(const struct bench_geom *g, int axis)
{
	return axis == 0 ? &g->laser_theta : axis == 1 ? &g->detector_theta : &g->detector_phi;
}

/* `depth` apart moves from p into steps[n..], then the homes' order: the first move tried by size (k steps of
 * PLAN_HOME_APART_STEP_DEG, the axes of mask in order, up then down), each allowed by plan_home_move_ok. */
static bool apart(const struct bench_geom *g, struct plan_pos p, const double *park, unsigned mask, unsigned need,
		  int depth, struct plan_home_step *steps, int n, int *len)
{
	if (depth == 0)
		return search(g, p, park, need, 0, steps, n, len);
	double span = 0;
	for (int a = 0; a < 3; a++)
		span = fmax(span, axis_of(g, a)->max_deg - axis_of(g, a)->min_deg);
	for (int k = 1; k * PLAN_HOME_APART_STEP_DEG <= span; k++)
		for (int a = 0; a < 3; a++)
			for (int sgn = 1; sgn >= -1 && (mask & (1u << a)); sgn -= 2) {
				const struct bench_axis *ax = axis_of(g, a);
				struct plan_pos q = p;
				double *v = pos_axis(&q, a);
				*v += sgn * k * PLAN_HOME_APART_STEP_DEG;
				if (*v < ax->min_deg || *v > ax->max_deg || !plan_home_move_ok(g, &p, &q))
					continue;
				steps[n] = (struct plan_home_step){ .axis = a, .apart = true, .target = *v };
				if (apart(g, q, park, mask, need, depth - 1, steps, n + 1, len))
					return true;
			}
	return false;
}

int plan_home_order(const struct bench_geom *g, const struct plan_pos *from, const double *park, unsigned mask,
		    struct plan_home_step steps[PLAN_HOME_MAX_STEPS])
{
	if (!isfinite(from->laser_theta) || !isfinite(from->det_theta) || !isfinite(from->det_phi))
		return -1;
	unsigned need = 0;
	for (int a = 0; a < 3; a++)
		if (mask & (1u << a))
			need |= (1u << (2 * a)) | (park ? 1u << (2 * a + 1) : 0);
	/* where the steps end: no order when that pose itself is a collision (all homes at 0° without parks) */
	struct plan_pos end = *from;
	for (int a = 0; a < 3; a++)
		if (mask & (1u << a))
			*pos_axis(&end, a) = park ? park[a] : 0;
	if (plan_blind(g, &end) & (PLAN_R_COLLISION | PLAN_R_LIMITS))
		return -1;
	int len = 0;
	for (int depth = 0; depth <= PLAN_HOME_MAX_APART; depth++)
		if (apart(g, *from, park, mask, need, depth, steps, 0, &len))
			return len;
	return -1;
}
