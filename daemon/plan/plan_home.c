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

int plan_home_order(const struct bench_geom *g, const struct plan_pos *from, const double *park, unsigned mask,
		    struct plan_home_step steps[PLAN_HOME_MAX_STEPS])
{
	if (!isfinite(from->laser_theta) || !isfinite(from->det_theta) || !isfinite(from->det_phi))
		return -1;
	unsigned need = 0;
	for (int a = 0; a < 3; a++)
		if (mask & (1u << a))
			need |= (1u << (2 * a)) | (park ? 1u << (2 * a + 1) : 0);
	int len = 0;
	return search(g, *from, park, need, 0, steps, 0, &len) ? len : -1;
}
