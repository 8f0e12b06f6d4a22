/* sim_refdrift: the simulated bench's calibration errors, the truth an uncertainty budget is tested against
 * (issue 13 item 1):
 *  - the white reference standard on the stage is not exactly its certificate: its true reflectance is
 *    rho_true(l) = rho_cert(l) + d(l), d a smooth Gaussian process (squared-exponential correlation of length
 *    correlation_nm across wavelengths, standard deviation u at every wavelength), one draw per seed (one
 *    physical standard per seed). Drawn exactly on nodes every correlation_nm / 8 (at most 5 nm) over
 *    450-1100 nm by a Cholesky factor of the kernel, linear in between (the kink error is < 1 % of u).
 *  - the supercontinuum's output drifts slowly over bench time t (seconds), multiplicatively:
 *    s(l, t) = s(l) (1 + a [h_1(t) + tilt x(l) h_2(t)]), x(l) = (l - 775) / 325 in [-1, 1] (a blue/NIR tilt),
 *    h_k(t) = sum_{j=1..3} c_kj (sin(2 pi t / T_j + p_kj) - sin(p_kj)), T_j = period_s / (1, 1.7, 2.9), phases
 *    uniform and weights c normal from the seed, normalised so that sum c_kj^2 / 2 = 1 (the oscillating part
 *    has rms 1 over long times; the constant offset that makes h(0) = 0 adds to it); h(0) = 0, so the source is nominal at bench time 0 and a reference measured at t_r and a
 *    sample at t_s differ by the ratio of the factors.
 * Stated uncertainties for a budget: the reference deviation's is u (at every wavelength, fully correlated over
 * correlation_nm); the drift's, for a sample at a random time long after the reference, averaged over seeds:
 * amplitude sqrt(2 (1 + tilt^2 / 3)) (the oscillation and the offset each contribute amplitude; the tilt
 * amplitude x tilt x rms of x over 450-1100 nm, 1/sqrt(3)): 0.0074 for amplitude 0.005, tilt 0.5. A DHR averages
 * samples taken at many times, so its drift error is smaller.
 * Both are off by default (u = 0, amplitude = 0): the existing tests compare calibrated values with the
 * certificate's truth at tolerances that a 1-sigma reference error or a 0.5 % drift would eat into.
 * Configuration (the `sim:` section, read by acq-sim's spectrometer):
 *   reference_standard: {u: 0.002, correlation_nm: 100, seed: 1}
 *   source_drift: {amplitude: 0.005, tilt: 0.5, period_s: 3600, seed: 1} */
#ifndef SIM_REFDRIFT_H
#define SIM_REFDRIFT_H

#include <stdint.h>

#include "config/acq_err.h"
#include "config/yconf.h"

struct refdrift_cfg {
	double ref_u;              /* absolute standard deviation of rho_true - rho_cert; 0: exact */
	double ref_corr_nm;        /* correlation length across wavelengths */
	uint64_t ref_seed;
	double drift_amp;          /* rms relative drift of the source power; 0: none */
	double drift_tilt;         /* rms of the spectral tilt relative to drift_amp */
	double drift_period_s;     /* slowest period (bench seconds) */
	uint64_t drift_seed;
};

/* The defaults: both effects off, correlation 100 nm, tilt 0.5, period 3600 s, seeds 1. */
void refdrift_defaults(struct refdrift_cfg *c);
/* Parse `reference_standard` and `source_drift` of the sim mapping (may be NULL) onto c. 0 or -1 with err. */
int refdrift_parse(struct yc_node *simcfg, struct refdrift_cfg *c, struct acq_err *err);
/* The standard's deviation d(wl_k) from its certificate for n wavelengths into d (0 when ref_u is 0). 0 or -1
 * with err (out of memory). */
int refdrift_reference(const struct refdrift_cfg *c, int n, const double *wl, double *d, struct acq_err *err);
/* The source's drift factor at bench time t (seconds) and wavelength wl (1 when drift_amp is 0). */
double refdrift_source(const struct refdrift_cfg *c, double t, double wl);

#endif
