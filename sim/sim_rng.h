/* sim_rng: the simulator's name for the tree's one generator (config/acq_rng.h): same algorithm, same streams. */
#ifndef SIM_RNG_H
#define SIM_RNG_H

#include "config/acq_rng.h"

#define sim_rng acq_rng
#define sim_rng_seed acq_rng_seed
#define sim_rng_next acq_rng_next
#define sim_rng_uniform acq_rng_uniform
#define sim_rng_gauss acq_rng_gauss

#endif
