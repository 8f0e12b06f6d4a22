/* synth: seeded synthetic spectrometer scans for the exposure and calibration unit tests (header-only). */
#ifndef SYNTH_H
#define SYNTH_H

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "daemon/exposure.h"

struct synth_rng {
	uint64_t s;
	int have;
	double spare;
};

static inline uint64_t synth_next(struct synth_rng *r)
{
	uint64_t z = (r->s += 0x9E3779B97F4A7C15ull);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
	return z ^ (z >> 31);
}

static inline double synth_unif(struct synth_rng *r)
{
	return ((double)(synth_next(r) >> 11) + 0.5) * (1.0 / 9007199254740992.0);
}

static inline double synth_gauss(struct synth_rng *r)
{
	if (r->have) {
		r->have = 0;
		return r->spare;
	}
	double u = synth_unif(r), v = synth_unif(r), m = sqrt(-2 * log(u));
	r->spare = m * sin(2 * M_PI * v);
	r->have = 1;
	return m * cos(2 * M_PI * v);
}

/* The seed of a run: ACQ_SEED (printed) or 1. */
static inline uint64_t synth_seed(const char *what)
{
	const char *e = getenv("ACQ_SEED");
	uint64_t s = e ? strtoull(e, NULL, 10) : 1;
	printf("# %s: seed %llu\n", what, (unsigned long long)s);
	return s;
}

/* A detector: dark = offset + dc·t, read noise, shot noise (gain 1 count per electron), 16-bit clip. */
struct synth_det {
	int npix;
	double offset, dc_per_ms, read_sigma, full;
};

/* Average `scans` scans of a spectrum whose signal rate (counts/ms) per pixel is rate[] (NULL: dark). */
static inline void synth_take(struct synth_rng *r, const struct synth_det *d, const double *rate, double t_ms,
			      unsigned scans, struct exp_avg *a)
{
	static double c[SPECTRO_MAX_PIXELS];
	static unsigned char sat[SPECTRO_MAX_PIXELS];
	exp_avg_init(a, d->npix, t_ms);
	for (unsigned k = 0; k < scans; k++) {
		for (int p = 0; p < d->npix; p++) {
			double sig = rate ? rate[p] * t_ms : 0.0;
			double mean = d->offset + d->dc_per_ms * t_ms + sig;
			double sd = sqrt(d->read_sigma * d->read_sigma + (sig > 0 ? sig : 0) + d->dc_per_ms * t_ms);
			double v = mean + sd * synth_gauss(r);
			if (v >= d->full) {
				v = d->full;
			}
			v = floor(v + 0.5);
			sat[p] = v >= SPECTRO_SATURATED;
			c[p] = v;
		}
		exp_avg_add(a, c, NULL, 1, sat, t_ms, NULL);
	}
}

/* Mean and std of an average as float arrays for exp_net_rate. */
static inline void synth_frame(const struct exp_avg *a, float *sd)
{
	for (int p = 0; p < a->npix; p++)
		sd[p] = (float)exp_avg_std(a, p);
}

#endif
