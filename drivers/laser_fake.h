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
};

/* The fake laser's state (one per process). */
struct laser_fake *laser_fake_state(void);
/* Back to defaults: off, 100 %, interlock closed, no fault, counters zero. */
void laser_fake_reset(void);

#endif
