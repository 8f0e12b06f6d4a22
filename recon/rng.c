/* rng: librecon's interface to the tree's generator (config/acq_rng.h); same streams as before. */
#include "recon/rng.h"

#include <math.h>

void recon_rng_seed(struct recon_rng *r, uint64_t seed)
{
	acq_rng_seed(&r->g, seed);
}

double recon_rng_unif(struct recon_rng *r)
{
	return acq_rng_uniform(&r->g);
}

double recon_rng_normal(struct recon_rng *r)
{
	/* Box-Muller with u clamped away from 0 (librecon's draws; acq_rng_gauss uses 1 - u instead) */
	double u = acq_rng_uniform(&r->g), v = acq_rng_uniform(&r->g);
	if (u < 1e-300)
		u = 1e-300;
	return sqrt(-2.0 * log(u)) * cos(2.0 * M_PI * v);
}
