/* budget: the DHR's uncertainty budget beyond the reconstruction (the instrument's systematic components) and
 * the comparison with a reference measurement (paper Fig. 4, a spectrophotometer's DHR at 8°). */
#ifndef RECON_BUDGET_H
#define RECON_BUDGET_H

#include <stddef.h>

#include "config/acq_err.h"

/* The systematic components, none of which the sample file or the database carries (recon/reconstruction.md:
 * what is assumed). Each is 0 unless given. */
struct recon_budget_opts {
	double cert_rel;   /* relative standard uncertainty of the white standard's certified reflectance (all λ) */
	const double *cert_wl, *cert_rho, *cert_u; /* or a certificate: [ncert] nm, ρ, u(ρ) (u/ρ interpolated) */
	size_t ncert;
	double drift_rel;  /* relative standard uncertainty of the source between reference and samples */
	double wl_cal_nm;  /* standard uncertainty of the wavelength calibration (nm): |dDHR/dλ|·δλ */
	double nonlin_rel; /* relative residual of the detector's nonlinearity correction */
};

/* The budget of nth DHR curves dhr[t*L + l] over wavelengths wl[L] with the reconstruction's σ sig[...]: the
 * components cert, drift, wlcal, nonlin (each [nth*L], may be NULL) and the total
 * √(sig² + cert² + drift² + wlcal² + nonlin²). cert and drift are one common factor across wavelengths and
 * incidences (correlation 1: a scale error of the reference or the source); wlcal is correlated across
 * neighbouring wavelengths. Returns 0 or -1 with err (bad options). */
int recon_budget(size_t nth, size_t L, const double *wl, const double *dhr, const double *sig,
		 const struct recon_budget_opts *o, double *cert, double *drift, double *wlcal, double *nonlin,
		 double *total, struct acq_err *err);

/* Agreement of a DHR curve (model: value md, total σ ms, its correlated part mc — cert and drift, fully correlated
 * across wavelengths — at each reference wavelength) with a reference (rv ± rs, independent per wavelength). */
struct recon_agreement {
	size_t n, within2;   /* wavelengths compared; |z| <= 2 among them, z = (md − rv)/√(ms² + rs²) */
	double rms_z, max_z, max_z_wl;
	double chi2_n;       /* χ²/n with the correlated part as one common factor (Sherman-Morrison) */
};
/* Compare at n reference wavelengths (arrays [n]); z[n] (may be NULL) receives the per-wavelength z. */
void recon_agreement(size_t n, const double *wl, const double *md, const double *ms, const double *mc,
		     const double *rv, const double *rs, double *z, struct recon_agreement *a);

#endif
