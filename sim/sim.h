/* sim: the simulated bench's shared world and the seam between its services (arm controllers over Modbus,
 * laser on a pty, spectrometer, fault injection). One process, one poll loop (sim/acq_sim_main.c).
 *
 * Time: bench time runs `scale` times faster than the monotonic clock; every model (motion, settling,
 * integration) works in bench seconds, so reported times stay in bench time. */
#ifndef SIM_H
#define SIM_H

#include <poll.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "config/bench.h"
#include "config/yconf.h"

enum sim_arm_id { SIM_ARM_LASER = 0, SIM_ARM_DETECTOR = 1 };

/* What sits on the sample stage (config `sim.sample`, control command `sample`): a material of sim/material.h
 * (the values are its enum mat_id; sim_physics.c checks the correspondence), or NONE: empty holder, the
 * detector can see the direct beam (absolute calibration). */
enum sim_sample {
	SIM_SAMPLE_GREEN_PAINT = 0,
	SIM_SAMPLE_WHITE,
	SIM_SAMPLE_METAL,
	SIM_SAMPLE_CLEAR_COAT,
	SIM_SAMPLE_ROUGH_BACKSCATTER,
	SIM_SAMPLE_CLOTH_SHEEN,
	SIM_SAMPLE_SHARP_LOBE,
	SIM_SAMPLE_NARROW_LINES,
	SIM_SAMPLE_MERL,            /* the material of sim.merl_file */
	SIM_SAMPLE_NONE,
	SIM_SAMPLE__COUNT
};

/* Faults, set by the control socket or the seeded schedule, consumed by the services. */
struct sim_faults {
	bool modbus_timeout[2];     /* controller stops answering (per arm) */
	bool drop_connection[2];    /* controller closes its client connections once */
	bool alarm_mid_move[2];     /* next move raises an alarm half way */
	bool stall[2];              /* next move stops short and stays busy */
	bool spectro_disconnect;    /* spectrometer vanishes during the next read */
	int saturation_burst;       /* next N spectra are saturated */
	bool laser_interlock_open;  /* interlock open: emission forced off */
	bool laser_fault;           /* laser reports a fault, emission forced off */
	int laser_delay_ms;         /* the laser acts on and answers each command this many real ms after it arrives */
};

struct sim_world {
	double scale;               /* bench seconds per monotonic second */
	double t0_mono;             /* monotonic seconds at bench time 0 */
	struct bench_geom geom;
	/* actual positions (degrees), written by the arm services, read by the spectrometer model */
	double laser_theta_deg;
	double detector_theta_deg, detector_phi_deg;
	bool collision;             /* arms in contact: both controllers in alarm */
	unsigned long collisions;   /* contacts since start (the control socket's status shows them) */
	/* laser state, written by the laser service */
	bool laser_emission;
	double laser_power_pct;
	unsigned long laser_status_reads; /* STATUS? commands answered (the ctl status shows the device traffic) */
	struct sim_faults faults;
	uint64_t seed;
	/* spectrometer side (sim/sim_spectro.c, sim/sim_control.c) */
	int sample;                 /* enum sim_sample */
	double sensor_temp_c;       /* spectrometer sensor temperature (TEC set point by default) */
	double spectro_offline_until; /* bench time until which the spectrometer refuses connections */
	double lag_s;               /* real seconds the main loop's 1 ms waits ended late (the host's load), summed */
};

#define SIM_LAG_SLACK_S 0.0005      /* a wait ending this much late is not counted (timer slack, wake-up) */

/* A service of the simulator: owns file descriptors and advances its model with bench time. */
struct sim_service {
	const char *name;
	void *self;
	/* Fill up to max pollfds; return how many. */
	int (*pollfds)(void *self, struct pollfd *fds, int max);
	/* Handle the revents of the fds this service filled (same order and count). */
	void (*handle)(void *self, const struct pollfd *fds, int n, double now);
	/* Advance the model to bench time now (called every loop turn). */
	void (*tick)(void *self, double now);
	/* Write this service's endpoints as JSON members, e.g. "laser_arm": {"port": 40123}; may be NULL. */
	void (*describe)(void *self, char *buf, size_t len);
	/* Free everything, the struct sim_service itself included (embed it in self). */
	void (*destroy)(void *self);
};

/* Listen on a Unix stream socket at path (a stale socket file is replaced), non-blocking. fd or -1 with err. */
int sim_listen_unix(const char *path, struct acq_err *err);
/* Remove from dir the default socket files (acq-sim.<pid>.<service>.sock) whose simulator is gone (no process
 * <pid>; sockets of this user only). Returns how many were removed (sim_stale.c). */
int sim_stale_sockets_remove(const char *dir);

/* Service constructors (each in its own file). node: the device's config mapping; simcfg: the `sim:`
 * mapping (may be NULL). NULL with err on failure. */
struct sim_service *sim_arm_new(struct sim_world *w, enum sim_arm_id arm, struct yc_node *node,
				struct yc_node *maps, struct yc_node *simcfg, struct acq_err *err);
struct sim_service *sim_laser_new(struct sim_world *w, struct yc_node *node, struct yc_node *simcfg,
				  struct acq_err *err);
struct sim_service *sim_spectro_new(struct sim_world *w, struct yc_node *node, struct yc_node *simcfg,
				    struct acq_err *err);
/* Control socket for fault injection and the seeded fault schedule. */
struct sim_service *sim_control_new(struct sim_world *w, struct yc_node *simcfg, const char *socket_path,
				    struct acq_err *err);

/* `acq-sim ctl ...` (argv[0] is "ctl"): one command to the control socket of a running acq-sim; exit status. */
int simctl_main(int argc, char **argv);
/* `acq-sim truth ...` (argv[0] is "truth"): the ground-truth export (sim_truthcli.c); exit status. */
int simtruth_main(int argc, char **argv);

#endif
