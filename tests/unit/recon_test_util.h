/* recon_test_util: shared helpers of the recon unit tests (seed, xorshift, synthetic ground truth). */
#ifndef RECON_TEST_UTIL_H
#define RECON_TEST_UTIL_H

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon/recon.h"

static uint64_t rt_state = 88172645463325252ull;

/* Seed the generator as ACQ_SEED=v would (a test's fixed counter-example). */
static inline void rt_seed_value(uint64_t v)
{
	rt_state = v * 2654435761ull + 88172645463325252ull;
	if (!rt_state)
		rt_state = 1;
}

/* Seed from ACQ_SEED (printed, so a failure can be replayed). */
static inline uint64_t rt_seed(void)
{
	const char *s = getenv("ACQ_SEED");
	uint64_t v = s && *s ? strtoull(s, NULL, 10) : 1;
	printf("ACQ_SEED=%llu\n", (unsigned long long)v);
	rt_seed_value(v);
	return v;
}

static inline double rt_unif(void)
{
	rt_state ^= rt_state << 13;
	rt_state ^= rt_state >> 7;
	rt_state ^= rt_state << 17;
	return (double)(rt_state >> 11) * 0x1.0p-53;
}

static inline double rt_normal(void)
{
	double u = rt_unif(), v = rt_unif();
	if (u < 1e-300)
		u = 1e-300;
	return sqrt(-2 * log(u)) * cos(2 * M_PI * v);
}

/* Ground truth: Lambertian ρ(λ)/π + a normalised Phong lobe about the mirror direction (reciprocal),
 * ks(λ) (n+2)/(2π) cosⁿ α. Albedo < 1 for the parameters used. */
static inline double rt_truth(const double a[4], double wl, double scale)
{
	double rho = 0.15 + 0.5 * exp(-(wl - 550) * (wl - 550) / (2 * 60.0 * 60.0));
	double ks = 0.15 + 0.1 * (wl - 450) / 650;
	double ni = 20;
	double wi[3] = { sin(a[0]) * cos(a[1]), sin(a[0]) * sin(a[1]), cos(a[0]) };
	double wo[3] = { sin(a[2]) * cos(a[3]), sin(a[2]) * sin(a[3]), cos(a[2]) };
	double r[3] = { -wi[0], -wi[1], wi[2] }; /* mirror of wi */
	double c = r[0] * wo[0] + r[1] * wo[1] + r[2] * wo[2];
	double lobe = c > 0 ? pow(c, ni) : 0;
	return scale * (rho / M_PI + ks * (ni + 2) / (2 * M_PI) * lobe);
}

/* s emptied, then its arrays allocated for n direction pairs on nwl wavelengths (sig too when with_sig). */
static inline void rt_samples_alloc(struct recon_samples *s, size_t n, size_t nwl, int with_sig)
{
	memset(s, 0, sizeof *s);
	s->n = n;
	s->nwl = nwl;
	s->wl = malloc(nwl * sizeof *s->wl);
	s->ang = malloc(n * 4 * sizeof *s->ang);
	s->deg = malloc(n * 4 * sizeof *s->deg);
	s->val = malloc(n * nwl * sizeof *s->val);
	if (with_sig)
		s->sig = malloc(n * nwl * sizeof *s->sig);
}

/* A ni × no × np sampling (θi 0..75°, θo 5..80°, φo every 360/np °, φi = 0) with relative noise. */
static inline void rt_samples_grid(struct recon_samples *s, int ni, int no, int np, size_t nwl, double noise,
				   double scale)
{
	rt_samples_alloc(s, (size_t)(ni * no * np), nwl, 1);
	for (size_t l = 0; l < nwl; l++)
		s->wl[l] = nwl > 1 ? 450 + 650.0 * (double)l / (double)(nwl - 1) : 550;
	size_t k = 0;
	for (int i = 0; i < ni; i++)
		for (int o = 0; o < no; o++)
			for (int p = 0; p < np; p++, k++) {
				double *a = s->ang + 4 * k;
				a[0] = (75.0 * i / (ni - 1)) * M_PI / 180;
				a[1] = 0;
				a[2] = (5 + 75.0 * o / (no - 1)) * M_PI / 180;
				a[3] = (360.0 * p / np) * M_PI / 180;
				for (int c = 0; c < 4; c++)
					s->deg[4 * k + c] = a[c] * 180 / M_PI;
				for (size_t l = 0; l < nwl; l++) {
					double f = rt_truth(a, s->wl[l], scale);
					double sg = noise * f + 1e-4;
					s->val[k * nwl + l] = f + sg * rt_normal();
					s->sig[k * nwl + l] = sg;
				}
			}
}

/* The paper's 10 × 10 × 10 sampling. */
static inline void rt_samples(struct recon_samples *s, size_t nwl, double noise, double scale)
{
	rt_samples_grid(s, 10, 10, 10, nwl, noise, scale);
}

/* A random direction pair, cosθ uniform in [0.05, 1]. */
static inline void rt_random_pair(double a[4])
{
	a[0] = acos(0.05 + 0.95 * rt_unif());
	a[1] = 2 * M_PI * rt_unif();
	a[2] = acos(0.05 + 0.95 * rt_unif());
	a[3] = 2 * M_PI * rt_unif();
}

/* n samples at random direction pairs (cosθ uniform in [0, 1]) with log-uniform values over 12 decades
 * (1e-8 to 1e4) on nwl wavelengths 450, 550, ... nm, from the generator's state: the extreme input of the
 * reconstruction's tests (no physical material; the energy table's work budget and the check's bound). */
static inline void rt_samples_log_uniform(struct recon_samples *s, size_t n, size_t nwl)
{
	rt_samples_alloc(s, n, nwl, 0);
	for (size_t l = 0; l < nwl; l++)
		s->wl[l] = 450 + 100.0 * (double)l;
	for (size_t k = 0; k < n; k++) {
		double *q = s->ang + 4 * k;
		q[0] = acos(rt_unif());
		q[1] = 2 * M_PI * rt_unif();
		q[2] = acos(rt_unif());
		q[3] = 2 * M_PI * rt_unif();
		for (int c = 0; c < 4; c++)
			s->deg[4 * k + c] = q[c] * 180 / M_PI;
		for (size_t l = 0; l < nwl; l++)
			s->val[k * nwl + l] = pow(10, -8 + 12 * rt_unif());
	}
}

#endif
