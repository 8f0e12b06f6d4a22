/* sim_truth: the simulator's ground truth exported, so accuracy is measured, not assumed (the library part of
 * `acq-sim truth`; its command line is in sim/sim_truthcli.c): DHR(theta_i, lambda) with its quadrature error
 * bound, evaluation at given directions, noisy sparse samples on a plan-like grid (the CSV interchange format of
 * docs/design.md, with the bench's systematic errors if asked), a MERL table, and a simulated spectrophotometer
 * measurement of the DHR at 8 deg. Each writer takes a stream the caller opened and returns 0, or -1 with err;
 * nothing is printed here. */
#ifndef SIM_TRUTH_H
#define SIM_TRUTH_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "config/acq_err.h"
#include "recon/colour.h"
#include "sim/material.h"
#include "sim/sim_refdrift.h"

#define TRUTH_MAX_WL 100000
#define TRUTH_MAX_THETAS 64

/* The --grid sampling: NI incidences, NO observation zeniths in (0, 80) deg at cell centres, NP azimuths; noise
 * value x (1 + rel N) + floor N; the bench's systematic errors (sim_refdrift.h), sample k at bench time k point_s. */
struct truth_grid {
	int ni, no, np;
	double rel, floor_;
	uint64_t seed;
	bool keep_blind;
	struct refdrift_cfg cal;
	double point_s;
};

/* "A:B:STEP" (or one value) within 450..1100 nm into a new array (free()). 0 or -1 with err. */
int truth_wavelengths(const char *spec, double **wl, int *n, struct acq_err *err);
/* Comma-separated zeniths in [0, 90] degrees (at most TRUTH_MAX_THETAS) into th. 0 or -1 with err. */
int truth_thetas(const char *list, double *th, int *n, struct acq_err *err);
/* "NIxNOxNP" into g (the other fields untouched). 0 or -1 with err. */
int truth_grid_size(const char *spec, struct truth_grid *g, struct acq_err *err);

/* DHR table: columns theta_i,wavelength_nm,dhr,sigma (sigma: quadrature bound) after two # lines. */
int truth_write_dhr(FILE *f, const struct mat *m, const double *th, int nth, int level, const double *wl, int nwl,
		    struct acq_err *err);
/* f at the theta_i,phi_i,theta_o,phi_o (degrees) rows of the CSV file queries (read by recon/csvio.c),
 * one column per wavelength (1/sr). */
int truth_write_eval(FILE *f, const struct mat *m, const char *queries, const double *wl, int nwl,
		     struct acq_err *err);
/* Noisy samples on the grid (blind zones dropped unless keep_blind); *rows and *dropped counted. */
int truth_write_grid(FILE *f, const struct mat *m, const struct truth_grid *g, const double *wl, int nwl, int *rows,
		     int *dropped, struct acq_err *err);
/* MERL table at path in linear sRGB, 1/sr (colour_opts_brdf); the colour decisions and statistics into o, st. */
int truth_write_merl(const char *path, const struct mat *m, const double *wl, int nwl, struct colour_opts *o,
		     struct colour_stats *st, struct acq_err *err);
/* Simulated spectrophotometer (sim/sim_sphere.h): columns wavelength_nm,dhr,sigma, nothing else. */
int truth_write_sphere(FILE *f, const struct mat *m, uint64_t seed, const double *wl, int nwl, struct acq_err *err);

#endif
