/* axis_fake: an axis backend without hardware, for unit tests (link `type: fake`). Each configured axis name
 * has one controllable state: its position, alarm and homed flags, injected failures and counters. A test
 * changes it between operations (the backend takes a lock while it runs). */
#ifndef AXIS_FAKE_H
#define AXIS_FAKE_H

#include <stdbool.h>

struct axis_fake {
	char name[64];
	double pos;          /* degrees */
	bool homed, alarm;
	int alarm_code;
	bool fail_open;      /* open fails with ACQ_E_DISCONNECTED */
	int fail_io;         /* nonzero: every operation fails with this acq_err code (e.g. ACQ_E_TIMEOUT) */
	double move_s;       /* clock seconds a move or homing takes (0: done at the first step) */
	double delay_s;      /* real seconds every call blocks first (a controller that answers late) */
	int opens, moves, stops, resets, homings;
};

/* The state of the fake axis called name (created on first use; at most 8). NULL if the table is full. */
struct axis_fake *axis_fake_get(const char *name);
/* Forget every fake axis (between tests). */
void axis_fake_reset(void);

#endif
