/* rng: librecon's draws from the tree's one generator (config/acq_rng.h: xoshiro256**, seeded by splitmix64):
 * Monte-Carlo draws of the DHR, the checker's random pairs, the RGB path's construction-time measurements.
 * Reproducible per seed. */
#ifndef RECON_RNG_H
#define RECON_RNG_H

#include <stdint.h>

#include "config/acq_rng.h"

struct recon_rng {
	struct acq_rng g;
};

/* Seed the state from one 64-bit value (splitmix64: any seed, 0 included, gives a good state). */
void recon_rng_seed(struct recon_rng *r, uint64_t seed);
/* Uniform in [0, 1) with 53 random bits. */
double recon_rng_unif(struct recon_rng *r);
/* Standard normal (Box-Muller, one value per call; u clamped away from 0 so the result is finite). */
double recon_rng_normal(struct recon_rng *r);

#endif
