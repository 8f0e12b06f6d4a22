/* spectro_fake: a spectrometer backend without hardware, for unit tests (`backend: fake`): 600 pixels from
 * 350 nm, a flat spectrum of `level` counts (plus the dark offset) after integration × averages on the caller's
 * clock; failures injected, counters kept. A test changes the state between operations. */
#ifndef SPECTRO_FAKE_H
#define SPECTRO_FAKE_H

#include <stdbool.h>

struct spectro_fake {
	double level;         /* counts at the full spectrum (default 20000) */
	bool fail_open;       /* open fails with ACQ_E_DISCONNECTED */
	int fail_io;          /* nonzero: start/fetch fail with this acq_err code */
	int opens, starts, fetches, stops;
};

/* The fake spectrometer's state (one per process). */
struct spectro_fake *spectro_fake_state(void);
/* Back to defaults. */
void spectro_fake_reset(void);

#endif
