#ifndef DAEMON_PLAN_PLAN_HOME_H
#define DAEMON_PLAN_PLAN_HOME_H
/* plan_home: the order of the steps of an all-axes home (reference each axis at 0°, then move it to its park)
 * that keeps every single-axis move collision-free, checked as a manual move is (daemon/commands_manual.c). */
#include <stdbool.h>

#include "daemon/plan/plan.h"

/* One step: home `axis` (move to 0° and reference it), move it to its park, or (apart) move it out of the other
 * arm's way before any home. axis: 0 laser.theta, 1 detector.theta, 2 detector.phi (enum conf_dev's order). */
struct plan_home_step {
	int axis;
	bool park;
	bool apart;    /* a move to target before the homes: the arms apart first */
	double target; /* 0 for a home, the park or the apart move's target otherwise */
};

/* At most this many apart moves open an order (from the shipped benches' clear poses one is enough). */
#define PLAN_HOME_MAX_APART 2
/* The apart moves' targets: the axis's position now ± k times this, within the axis's limits. */
#define PLAN_HOME_APART_STEP_DEG 5.0
#define PLAN_HOME_MAX_STEPS (6 + PLAN_HOME_MAX_APART)

/* The rule of a manual move from a to b: 0 when allowed; else b's PLAN_R_COLLISION | PLAN_R_LIMITS bits, or
 * PLAN_R_UNREACHABLE when b is allowed but the straight segment collides (only b is checked when a is already
 * inside the collision cone, so the arms can move out). */
unsigned plan_home_move_verdict(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b);

/* True when plan_home_move_verdict allows the move. */
bool plan_home_move_ok(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b);

/* Steps homing every axis of mask (bits 1 << axis) from `from` and, when park is non-NULL, moving each to park[axis]
 * after its home; every step is one axis's move, allowed by plan_home_move_ok from the pose the steps before leave.
 * The first such order found in the preference laser.theta, detector.theta, detector.phi (each axis's park as early
 * as possible) is written to steps. When none exists from `from` itself (the arms low and close: every home would
 * close them in), apart moves come first: one when one opens an order (the smallest: by a multiple of
 * PLAN_HOME_APART_STEP_DEG, the laser first at equal size), else two (the first as small as possible), each one
 * axis of mask moved within its limits, as plan_home_move_ok allows. Returns the length, or -1 when no order exists (or
 * from is not finite). */
int plan_home_order(const struct bench_geom *g, const struct plan_pos *from, const double *park, unsigned mask,
		    struct plan_home_step steps[PLAN_HOME_MAX_STEPS]);

#endif
