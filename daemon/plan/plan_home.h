#ifndef DAEMON_PLAN_PLAN_HOME_H
#define DAEMON_PLAN_PLAN_HOME_H
/* plan_home: the order of the steps of an all-axes home (reference each axis at 0°, then move it to its park)
 * that keeps every single-axis move collision-free, checked as a manual move is (daemon/commands_manual.c). */
#include <stdbool.h>

#include "daemon/plan/plan.h"

/* One step: home `axis` (move to 0° and reference it) or move it to its park. axis: 0 laser.theta,
 * 1 detector.theta, 2 detector.phi (enum conf_dev's order). */
struct plan_home_step {
	int axis;
	bool park;
	double target; /* 0 for a home, the park otherwise */
};

#define PLAN_HOME_MAX_STEPS 6

/* The rule of a manual move from a to b: 0 when allowed; else b's PLAN_R_COLLISION | PLAN_R_LIMITS bits, or
 * PLAN_R_UNREACHABLE when b is allowed but the straight segment collides (only b is checked when a is already
 * inside the collision cone, so the arms can move out). */
unsigned plan_home_move_verdict(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b);

/* True when plan_home_move_verdict allows the move. */
bool plan_home_move_ok(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b);

/* Steps homing every axis of mask (bits 1 << axis) from `from` and, when park is non-NULL, moving each to park[axis]
 * after its home; every step is one axis's move, allowed by plan_home_move_ok from the pose the steps before leave.
 * The first such order found in the preference laser.theta, detector.theta, detector.phi (each axis's park as early
 * as possible) is written to steps; its length returned, or -1 when no order exists (or from is not finite). */
int plan_home_order(const struct bench_geom *g, const struct plan_pos *from, const double *park, unsigned mask,
		    struct plan_home_step steps[PLAN_HOME_MAX_STEPS]);

#endif
