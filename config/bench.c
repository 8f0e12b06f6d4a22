/* bench: parse the bench geometry and kinematics section. */
#include "config/bench.h"

#include <stdio.h>
#include <string.h>

static const struct bench_axis default_laser_theta = { -5.0, 90.0, 10.0, 20.0, 0.3, 0.02, 0.005 };
static const struct bench_axis default_detector_theta = { -5.0, 90.0, 20.0, 60.0, 0.2, 0.02, 0.005 };
static const struct bench_axis default_detector_phi = { -180.0, 360.0, 30.0, 90.0, 0.2, 0.02, 0.005 };

void bench_defaults(struct bench_geom *g)
{
	memset(g, 0, sizeof *g);
	g->laser_radius_mm = 400.0;
	g->detector_radius_mm = 300.0;
	g->laser_phi_deg = 0.0;
	g->laser_body_halfwidth_deg = 6.0;
	g->detector_body_halfwidth_deg = 5.0;
	g->beam_halfwidth_deg = 0.5;
	g->fov_halfwidth_deg = 1.5;
	g->laser_theta = default_laser_theta;
	g->detector_theta = default_detector_theta;
	g->detector_phi = default_detector_phi;
	g->readout_s = 0.01;
	g->safety_margin_deg = 1.0;
}

/* The axis under its one name, or under its old name (noted in g->deprecated). */
static int parse_axis(struct yc_node *map, const char *key, const char *old, struct bench_axis *a,
		      struct bench_geom *g, struct acq_err *err)
{
	struct yc_node *n = yc_get(map, key), *o = yc_get(map, old);
	if (n && o)
		return yc_errf(err, o, "bench: %s and its old name %s both given (keep %s)", key, old, key);
	if (o) {
		size_t l = strlen(g->deprecated);
		snprintf(g->deprecated + l, sizeof g->deprecated - l, "%sbench.%s is now bench.%s", l ? "; " : "", old,
			 key);
		n = o;
		key = old;
	}
	if (!n)
		return 0;
	if (yc_expect_map(n, key, err))
		return -1;
	if (yc_double(n, "min_deg", false, -360, 360, &a->min_deg, err) ||
	    yc_double(n, "max_deg", false, -360, 720, &a->max_deg, err) ||
	    yc_double(n, "speed_dps", false, 1e-3, 1e4, &a->speed_dps, err) ||
	    yc_double(n, "accel_dps2", false, 1e-3, 1e6, &a->accel_dps2, err) ||
	    yc_double(n, "settle_s", false, 0, 600, &a->settle_s, err) ||
	    yc_double(n, "backlash_deg", false, 0, 10, &a->backlash_deg, err) ||
	    yc_double(n, "noise_deg", false, 0, 10, &a->noise_deg, err))
		return -1;
	if (a->min_deg >= a->max_deg)
		return yc_errf(err, n, "%s: min_deg (%g) must be below max_deg (%g)", key, a->min_deg, a->max_deg);
	return yc_check_unknown(n, key, err);
}

int bench_parse(struct yc_node *node, struct bench_geom *out, struct acq_err *err)
{
	struct bench_geom copy = *out, *g = &copy; /* *out changes only on success */
	g->deprecated[0] = 0;
	if (yc_expect_map(node, "bench", err))
		return -1;
	if (yc_double(node, "laser_radius_mm", false, 1, 1e4, &g->laser_radius_mm, err) ||
	    yc_double(node, "detector_radius_mm", false, 1, 1e4, &g->detector_radius_mm, err) ||
	    yc_double(node, "laser_phi_deg", false, -360, 360, &g->laser_phi_deg, err) ||
	    yc_double(node, "laser_body_halfwidth_deg", false, 0, 45, &g->laser_body_halfwidth_deg, err) ||
	    yc_double(node, "detector_body_halfwidth_deg", false, 0, 45, &g->detector_body_halfwidth_deg, err) ||
	    yc_double(node, "beam_halfwidth_deg", false, 0, 45, &g->beam_halfwidth_deg, err) ||
	    yc_double(node, "fov_halfwidth_deg", false, 0, 45, &g->fov_halfwidth_deg, err) ||
	    yc_double(node, "readout_s", false, 0, 60, &g->readout_s, err) ||
	    yc_double(node, "safety_margin_deg", false, 0, 30, &g->safety_margin_deg, err) ||
	    parse_axis(node, "laser.theta", "laser_theta", &g->laser_theta, g, err) ||
	    parse_axis(node, "detector.theta", "detector_theta", &g->detector_theta, g, err) ||
	    parse_axis(node, "detector.phi", "detector_phi", &g->detector_phi, g, err))
		return -1;
	if (yc_check_unknown(node, "bench", err))
		return -1;
	*out = copy;
	return 0;
}
