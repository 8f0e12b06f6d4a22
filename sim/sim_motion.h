/* sim_motion: pure kinematics of one simulated rotation axis in bench time: trapezoidal profile (with an
 * initial speed, for decelerating stops), hard limits, backlash play between motor and load, positioning
 * noise, and scheduled halts (alarm half way, stall) used for fault injection. No I/O. */
#ifndef SIM_MOTION_H
#define SIM_MOTION_H

#include <stdbool.h>
#include <stdint.h>

#include "config/acq_rng.h"

#include "config/bench.h"

enum simmot_event {
	SIMMOT_NONE = 0,
	SIMMOT_DONE,        /* the profile ended at its target */
	SIMMOT_LIMIT_POS,   /* hit the + hard limit: stopped there */
	SIMMOT_LIMIT_NEG,   /* hit the - hard limit */
	SIMMOT_ALARMED,     /* scheduled alarm reached: stopped abruptly */
	SIMMOT_STALL,       /* scheduled stall reached: stopped short, the controller stays busy */
};

enum simmot_halt { SIMMOT_HALT_NONE = 0, SIMMOT_HALT_ALARM, SIMMOT_HALT_STALL };

struct simmot {
	struct bench_axis k;   /* limits, speed, accel, backlash, noise */
	double motor;          /* motor (encoder) position: what the controller reports */
	double load;           /* load position: what the arm really points at */
	bool moving;
	/* current profile */
	double t0, p0, p1, dir, v0, vmax, acc, dec;
	double ta, tc, td;     /* accel, cruise, decel durations */
	double halt_frac;      /* fraction of the distance where a scheduled halt happens */
	int halt_kind;         /* enum simmot_halt */
	bool add_noise;        /* noise added when the profile ends (not for stops) */
	int bias_moves;        /* test hook: the next bias_moves moves end bias_deg past their target */
	double bias_deg;
	struct acq_rng rng;   /* position noise */
};

/* Initialise at position pos (motor = load), with the axis's kinematics and a random seed. */
void simmot_init(struct simmot *m, const struct bench_axis *k, double pos, uint64_t seed);
/* Duration (s) of a profile over |dist| starting at speed v0 (≥ 0, towards the target), max speed vmax. */
double simmot_duration(double dist, double v0, double vmax, double acc, double dec);
/* Start an absolute move at bench time now (speed/accel ≤ 0 → the axis's own; clipped to them). */
void simmot_start(struct simmot *m, double target, double now, double speed, double accel, double decel);
/* Schedule a halt at fraction frac of the current move's distance. */
void simmot_schedule_halt(struct simmot *m, int kind, double frac);
/* Advance to bench time now; returns what happened (enum simmot_event). */
int simmot_advance(struct simmot *m, double now);
/* Decelerating stop from the current speed (call simmot_advance first). */
void simmot_stop(struct simmot *m, double now);
/* Abrupt stop where it is. */
void simmot_halt(struct simmot *m);
/* Current speed (deg/s, signed) at bench time now. */
double simmot_speed(const struct simmot *m, double now);
/* Great-circle angle (degrees) between the laser-arm direction (θL at azimuth laser_phi; θL < 0 means
 * azimuth + 180°) and the detector direction (θD, φD). */
double simmot_arm_separation(double theta_l, double laser_phi, double theta_d, double phi_d);

#endif
