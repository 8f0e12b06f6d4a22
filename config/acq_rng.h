/* acq_rng: the one seeded random-number generator of the tree (xoshiro256**, seeded by splitmix64); the state
 * is the caller's. The simulator, the tests and the reconstruction draw from it (sim/sim_rng.h names it for
 * the simulator). */
#ifndef ACQ_RNG_H
#define ACQ_RNG_H

#include <math.h>
#include <stdint.h>

struct acq_rng {
	uint64_t s[4];
};

/* Seed the generator from one 64-bit value (any value, 0 included). */
static inline void acq_rng_seed(struct acq_rng *r, uint64_t seed)
{
	for (int i = 0; i < 4; i++) {
		uint64_t z = (seed += 0x9e3779b97f4a7c15ULL);
		z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
		z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
		r->s[i] = z ^ (z >> 31);
	}
}

static inline uint64_t acq_rng_rotl(uint64_t x, int k)
{
	return (x << k) | (x >> (64 - k));
}

/* Next 64 random bits. */
static inline uint64_t acq_rng_next(struct acq_rng *r)
{
	uint64_t *s = r->s, out = acq_rng_rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
	s[2] ^= s[0];
	s[3] ^= s[1];
	s[1] ^= s[2];
	s[0] ^= s[3];
	s[2] ^= t;
	s[3] = acq_rng_rotl(s[3], 45);
	return out;
}

/* Uniform in [0, 1). */
static inline double acq_rng_uniform(struct acq_rng *r)
{
	return (double)(acq_rng_next(r) >> 11) * 0x1.0p-53;
}

/* Standard normal (Box-Muller). */
static inline double acq_rng_gauss(struct acq_rng *r)
{
	double u = 1.0 - acq_rng_uniform(r), v = acq_rng_uniform(r);
	return sqrt(-2.0 * log(u)) * cos(2.0 * M_PI * v);
}

#endif
