/* bench: the geometry and kinematics of the gonioscatterometer, shared by the planner, the daemon and the
 * simulator (one `bench:` section of the configuration).
 *
 * Frame: sample normal +z, azimuth from +x. The laser arm has one zenith axis and stays at azimuth
 * laser_phi_deg, so the incident direction is ωi = (θL, laser_phi). The detector arm has a zenith and an
 * azimuth axis: ωo = (θD, φD). Arm bodies, the beam and the detector's field of view are modelled as
 * cones around their direction, with the angular half-widths below (seen from the sample). */
#ifndef BENCH_H
#define BENCH_H

#include "config/acq_err.h"
#include "config/yconf.h"

struct bench_axis {
	double min_deg, max_deg;   /* hard travel limits of the axis (soft limits live in the driver config) */
	double speed_dps;          /* max speed, degrees per second */
	double accel_dps2;         /* acceleration = deceleration, degrees per second² */
	double settle_s;           /* settling time after a move */
	double backlash_deg;       /* mechanical backlash (the simulator models it, the driver compensates) */
	double noise_deg;          /* positioning noise, standard deviation (simulator) */
};

struct bench_geom {
	double laser_radius_mm;        /* distance sample → laser arm head */
	double detector_radius_mm;     /* distance sample → detector head */
	double laser_phi_deg;          /* fixed azimuth of the laser arm */
	double laser_body_halfwidth_deg;
	double detector_body_halfwidth_deg;
	double beam_halfwidth_deg;     /* incident beam (spot + divergence) */
	double fov_halfwidth_deg;      /* detector field of view */
	struct bench_axis laser_theta, detector_theta, detector_phi;
	double readout_s;              /* spectrometer read-out overhead per exposure */
	double safety_margin_deg;      /* planner: added to every blind-zone and collision half-angle */
	char deprecated[160];          /* old key names the section used (accepted; the caller warns), or "" */
};

/* Fill g with the example bench's values (config/bench-sim.yaml documents the same numbers). */
void bench_defaults(struct bench_geom *g);
/* Parse a `bench:` mapping onto g (absent keys keep their values; g unchanged on error). The axes are keyed by
 * their one name (laser.theta, detector.theta, detector.phi); the old keys (laser_theta, ...) are accepted and
 * listed in g->deprecated for the caller to warn about. 0 or -1. */
int bench_parse(struct yc_node *node, struct bench_geom *g, struct acq_err *err);

#endif
