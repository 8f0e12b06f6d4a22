/* laser_fake: a laser backend without hardware, for unit tests (`backend: fake` in the laser section). One
 * controllable state: emission, power, interlock and fault, injected failures and counters; a test changes it
 * between operations (the backend takes a lock while it runs). */
#ifndef LASER_FAKE_H
#define LASER_FAKE_H

#include <stdbool.h>

struct laser_fake {
	bool emission;
	double power_pct;
	bool interlock_open;  /* emission refused (ERR 3) and dropped while open */
	int fault_code;       /* nonzero: emission refused and dropped */
	bool fail_open;       /* open fails with ACQ_E_DISCONNECTED */
	int fail_io;          /* nonzero: every operation fails with this acq_err code */
	int opens, sets_on, sets_off, power_sets, status_reads;
	double delay_s;       /* every operation takes this long (real time): a slow port */
	/* Keep-alive (armed when the configuration's keepalive_ms is not 0): every command refreshes it, as on
	 * the serial laser. Real monotonic seconds. */
	int keepalives;             /* laser_keepalive() calls */
	double last_keepalive;      /* the last laser_keepalive() (0: none yet) */
	double max_keepalive_gap;   /* the longest time between two laser_keepalive() calls since the reset */
	int reads_since_keepalive;  /* status reads since the last laser_keepalive() */
	int max_reads_between;      /* the most status reads between two laser_keepalive() calls since the reset */
	double last_refresh;        /* the last command (0: none yet) */
	double max_gap;             /* the longest time between two commands since the reset */
	int expired;                /* emission on when a command came later than keepalive_ms: it went off */
};

/* The fake laser's state (one per process). */
struct laser_fake *laser_fake_state(void);
/* Back to defaults: off, 100 %, interlock closed, no fault, counters zero. */
void laser_fake_reset(void);

#endif
