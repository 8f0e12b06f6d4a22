/* material_int: what material.c (the truths' catalogue and evaluation) and material_dhr.c (their DHR quadrature)
 * share: the materials' parameters, the instance and the lobe shapes. Not for other modules. */
#ifndef SIM_MATERIAL_INT_H
#define SIM_MATERIAL_INT_H

#include "recon/merl.h"
#include "sim/mat_lobes.h"
#include "sim/material.h"

#define PAINT_ALPHA 0.12
#define DIEL_N 1.5             /* paint binder, clear coat */
#define METAL_ALPHA 0.15
#define COAT_ALPHA 0.05
#define COAT_BASE_ALPHA 0.30
#define ON_SIGMA 0.5           /* Oren-Nayar roughness (radians) */
#define BS_AMP 1.0             /* backscatter peak height relative to rho / pi */
#define BS_WIDTH_DEG 8.0       /* its Gaussian width in the angle between wi and wo */
#define SHEEN_R 0.3
#define SHEEN_EMAX 0.9         /* the sheen lobe's largest albedo */
#define PHONG_N 250.0
#define PHONG_KS 0.30

struct mat {
	enum mat_id id;
	int nwl;
	double *wl;
	double *rho;               /* diffuse albedo per wavelength (MAT_S_RHO) */
	double *fix2;              /* second fixed spectrum: sheen colour, Phong k_s (MAT_S_FIX2) */
	double *n, *k;             /* conductor index per wavelength (metal, clear coat base) */
	struct lobe_hv lobe;       /* the main half-vector lobe (paint, metal, coat, sheen); alpha 0: none */
	struct lobe_hv base;       /* clear coat: the base seen through the coat */
	struct lobe_etab et;       /* albedo table of the main lobe (paint, clear coat, cloth) */
	double on_a, on_b;         /* Oren-Nayar A, B */
	struct merl_table merl;    /* MERL: the table */
	double *basis[3];          /* MERL: the spectral basis B_r, B_g, B_b per wavelength */
};

/* a · b of two 3-vectors. */
double mat_dot3(const double a[3], const double b[3]);
/* The backscatter peak's shape exp(-gamma^2 / (2 w^2)), gamma the angle between wi and wo. */
double mat_backscatter(const double wi[3], const double wo[3]);
/* The normalised Phong lobe (n + 2) / (2 pi) max(0, wr.wo)^n with wr.wo = 2 mu_i mu_o - wi.wo. */
double mat_phong(double wrwo);
/* The table's linear sRGB at (wi, wo): its reference lookup, "no data" cells and directions below the horizon 0. */
void mat_merl_rgb(const struct mat *m, const double wi[3], const double wo[3], double rgb[3]);

#endif
