/* sim_physics: the simulated spectrometer's counts from the world's ACTUAL arm positions, laser state and
 * sample: laser spectrum x ground-truth BRDF x geometry x instrument response, occlusion in the blind zones,
 * dark current, shot and read noise, nonlinearity, 16-bit quantisation and saturation, averaging.
 *
 * Signal model (counts per ms above dark, pixel p at wavelength l):
 *   sample:  K * (P/100) * s(l) * QE(l) * f(wi, wo, l) * cos(theta_o) * Omega_det
 *   none:    K * (P/100) * s(l) * QE(l) * overlap(angle between wo and -wi; fov and beam half-widths)
 * K = beam_counts_per_ms (the direct beam at 100 % power), s the supercontinuum's relative spectrum (times the
 * slow drift factor of sim_refdrift.h at the bench time set by phys_set_time), f of the white standard times
 * (rho_cert + d) / rho_cert (its deviation from the certificate, sim_refdrift.h), QE a
 * silicon-like response, Omega_det = 2 pi (1 - cos fov_halfwidth). So the absolute relation of
 * brdf-reconstruction.md holds: f = (S - D) / ((S_beam - D_beam) Omega_det cos(theta_o)).
 * Zero signal when the laser does not emit (or its interlock is open, or it is in fault), and in the blind zones (wi, wo at an angle below
 * detector_body + beam half-widths: the detector body blocks the beam; below laser_body + fov half-widths:
 * the laser arm hides the spot). The 4 first pixels are optically black (dark only).
 * One scan: e = bias + dark(T) t + signal t, noise N(0, (e - bias)/electrons_per_count + read_noise^2),
 * nonlinearity raw = x / (1 + b x / 65535) (correctable exactly by P(raw) = 1 - b raw / 65535, so
 * x = raw / P(raw)), rounded, clipped to [0, 65535]; >= 0xFFFC is saturated. dark(T) = dark_cps_25c *
 * 2^((T - 25) / dark_doubling_c). Averages: mean and sample standard deviation of the scans (above 100
 * scans, drawn from their exact Gaussian distributions instead of scan by scan). */
#ifndef SIM_PHYSICS_H
#define SIM_PHYSICS_H

#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "config/yconf.h"
#include "sim/sim.h"
#include "sim/sim_refdrift.h"
#include "sim/sim_rng.h"

#define PHYS_MAX_PIXELS 4096
#define PHYS_NDARK 4
#define PHYS_FULL_SCALE 65535.0
#define PHYS_SATURATED 0xFFFC

enum { PHYS_OCC_DETECTOR_IN_BEAM = 1, PHYS_OCC_LASER_HIDES_VIEW = 2 };

struct phys_cfg {
	char model[32], serial[32], firmware[32];
	int npix;
	double wl_coef[5];          /* lambda(p) = sum c_i p^i, nm */
	double temperature_c;       /* initial sensor temperature */
	double beam_counts_per_ms;  /* K */
	double dark_cps_25c, dark_doubling_c;
	double bias_counts, read_noise_counts, electrons_per_count;
	double nonlinearity;        /* b: relative compression at full scale */
	struct refdrift_cfg cal;    /* the reference standard's deviation and the source drift (sim_refdrift.h) */
	char merl_file[1024];       /* sim.merl_file: the MERL material's table ("": none; sample merl then
				     * reflects nothing) */
};

struct phys_frame {
	int npix;
	double counts[PHYS_MAX_PIXELS];
	float std[PHYS_MAX_PIXELS];
	unsigned char sat[PHYS_MAX_PIXELS];
	int nsat;
	unsigned occlusion;         /* PHYS_OCC_* bits */
};

struct phys;

/* Default instrument (2048 pixels covering 450-1100 nm from pixel 4 on). */
void phys_defaults(struct phys_cfg *c);
/* Bench time (seconds) of the next measurements, for the source drift. */
void phys_set_time(struct phys *p, double t);
/* The white standard's true reflectance over its certificate's (sim/material.c) at pixel i (1 without a
 * reference deviation). */
double phys_reference_factor(const struct phys *p, int pixel);
/* Parse the `sim.spectrometer` mapping onto c (absent keys keep their value). 0 or -1 with file:line:col. */
int phys_parse(struct yc_node *node, struct phys_cfg *c, struct acq_err *err);
/* Build the model (materials at the pixel wavelengths). NULL with err. */
struct phys *phys_new(const struct phys_cfg *c, struct acq_err *err);
/* Free; NULL is fine. */
void phys_free(struct phys *p);
/* The configuration the model was built with. */
const struct phys_cfg *phys_config(const struct phys *p);
/* Wavelength (nm) of pixel. */
double phys_wavelength(const struct phys_cfg *c, int pixel);
/* The 8 nonlinearity-correction coefficients: x = raw / sum c_i raw^i. */
void phys_nonlin_coef(const struct phys_cfg *c, double coef[8]);
/* Dark current (counts per second) at sensor temperature t. */
double phys_dark_cps(const struct phys_cfg *c, double t);
/* Signal rate above dark (counts per ms) per pixel into rate[npix] for the world's actual state;
 * returns the PHYS_OCC_* bits of the geometry. */
unsigned phys_signal(const struct phys *p, const struct sim_world *w, double *rate);
/* Simulate one measurement of averages scans of integration_ms each into f; gain_boost > 1 multiplies the
 * signal and saturates every pixel but the black ones (a saturation burst). 0 or -1 with err. */
int phys_measure(const struct phys *p, const struct sim_world *w, double integration_ms, unsigned averages,
		 double gain_boost, struct sim_rng *rng, struct phys_frame *f, struct acq_err *err);

/* Sample name (a material name of sim/material.h, or "none") ↔ enum sim_sample; -1 when unknown. */
int phys_sample_from_name(const char *name);
const char *phys_sample_name(int sample);

#endif
