/* conf: the daemon's whole configuration file, validated before use (bench, devices, sim, daemon, sweep,
 * recon), with --sim endpoint overrides; every error names file:line:col and the expected form. */
#ifndef CONF_H
#define CONF_H

#include <stdbool.h>
#include <stddef.h>
#include <sys/types.h>

#include "config/acq_err.h"
#include "config/bench.h"
#include "config/yconf.h"

struct axis_cfg;
struct spectro_cfg;
struct laser_cfg;

/* Device slots, in a fixed order (also the order of `acqctl devices`). */
enum conf_dev { CONF_DEV_LASER_THETA, CONF_DEV_DETECTOR_THETA, CONF_DEV_DETECTOR_PHI, CONF_DEV_SPECTRO,
		CONF_DEV_LASER, CONF_DEV__COUNT };

#define CONF_MAX_PRINCIPALS 16
/* Defaults of daemon.observer_rate / observer_burst: a status panel or a script polling a few times a second
 * stays far below them; a flood of one observer costs the loop at most this many requests a second. */
#define CONF_OBSERVER_RATE 20.0
#define CONF_OBSERVER_BURST 40.0
/* Defaults of daemon.plan_cpu_s / plan_deadline_s: a `plan` request's child is stopped after this much CPU, or
 * after this many real seconds when it hardly gets the CPU (daemon/commands_plan.c says why both). */
#define CONF_PLAN_CPU_S 10
#define CONF_PLAN_DEADLINE_S 30.0

struct conf_daemon {
	const char *state_dir;     /* absolute; requests' paths are confined to it */
	const char *database;      /* absolute (relative names in the file are under state_dir) */
	const char *socket_path;   /* absolute */
	mode_t socket_mode;
	const char *socket_group;  /* NULL: leave the group */
	int tcp_port;              /* loopback TCP listener, 0 = none */
	const char *controllers[CONF_MAX_PRINCIPALS];  /* "name" = user, "@name" = group */
	int ncontrollers;
	const char *observers[CONF_MAX_PRINCIPALS];
	int nobservers;
	int log_level;             /* syslog priority */
	bool auto_resume;          /* resume an interrupted sweep at start-up */
	double device_retry_s;     /* period of reconnection attempts for unavailable devices */
	double watchdog_s;         /* 0 = from WATCHDOG_USEC only */
	double observer_rate;      /* requests per second of one observer (a uid; all TCP peers together); 0 = no limit */
	double observer_burst;     /* requests an observer may send at once beyond the rate (the bucket's size) */
	int plan_cpu_s;            /* CPU seconds a `plan` request may take (its child's RLIMIT_CPU) */
	double plan_deadline_s;    /* real seconds a client waits for a `plan` reply at most */
};

struct conf_sweep {
	double move_timeout_s;     /* one arm move, including settling */
	int move_retries;
	double extra_settle_s;     /* added to the bench's settle time */
	double target_peak;        /* fraction of full scale aimed at by auto-exposure (0.1..0.95) */
	double min_integration_ms, max_integration_ms;
	int averages;              /* default averages per spectrum */
	int dark_every;            /* a dark every N points (0 = once per incidence angle; -1: by age/temperature) */
	bool auto_resume_faults;   /* resume by itself when a faulted device comes back */
	bool auto_recon;           /* start the reconstruction when a sweep completes */
	struct yc_node *acquisition; /* sweep.acquisition mapping or NULL (parsed by daemon/executor.c) */
	struct yc_node *calibration; /* sweep.calibration mapping or NULL (parsed by daemon/calib.c) */
};

struct conf_recon {
	const char *program;       /* brdf-recon executable (absolute, or found next to acquisitiond) */
	double timeout_s;          /* kill the child after this long */
	int threads;
	const char *output_dir;    /* under state_dir */
	const char *extra_args[8]; /* passed verbatim after the standard arguments */
	int nextra;
};

/* Endpoints of the simulated bench (acq-sim's ports file), overriding the device sections. */
struct conf_sim {
	int laser_arm_port, detector_arm_port;   /* 0 = absent */
	char laser_device[256];
	char spectro_socket[256];
	char control_socket[256];
	double time_scale;                       /* bench seconds per real second (1 when absent) */
};

struct conf {
	char *path;                /* the file, as given */
	char *text;                /* its text (the snapshot stored with each sweep) */
	struct yc_doc *doc, *simdoc;
	struct bench_geom bench;
	struct axis_cfg *axis[3];  /* CONF_DEV_LASER_THETA.. DETECTOR_PHI */
	struct spectro_cfg *spectro;
	struct laser_cfg *laser;
	/* Why a device has no parsed configuration (its driver says "not implemented"); "" when parsed. */
	char devnote[CONF_DEV__COUNT][256];
	/* The device has a section in the file (its driver may still be missing: then it has a devnote). */
	bool devpresent[CONF_DEV__COUNT];
	struct conf_daemon d;
	struct conf_sweep sweep;
	struct conf_recon recon;
	struct conf_sim sim;
	bool have_sim;
	double park[3];            /* home.park: CONF_DEV_LASER_THETA.. DETECTOR_PHI, degrees (when have_park) */
	bool have_park;
};

/* Read a simulator ports file (JSON) into sim. 0 or -1 naming the file and the offending key. */
int conf_sim_read(const char *path, struct conf_sim *sim, struct acq_err *err);
/* Load and validate path (sim may be NULL). Driver parsers answering ACQ_E_UNSUPPORTED leave the device
 * unconfigured with a note; every other error fails the load. *out allocated; 0 or -1 with err. */
int conf_load(const char *path, const struct conf_sim *sim, struct conf **out, struct acq_err *err);
/* The same from text in memory; name is used in messages and as the path. */
int conf_load_text(const char *name, const char *text, size_t len, const struct conf_sim *sim, struct conf **out,
		   struct acq_err *err);
/* Free a configuration. NULL is fine. */
void conf_free(struct conf *c);
/* Stable device name of a slot ("laser.theta", "detector.theta", "detector.phi", "spectrometer", "laser"). */
const char *conf_dev_name(enum conf_dev d);

#endif
