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
	/* the white reference's own measurement noise, relative, per wavelength: [nrefn] nm, u_rel (linear in λ,
	 * the nearest end outside); one spectrum shared by every sample of the sweep, so common to all samples and
	 * incidences but independent from one wavelength to the next */
	const double *refn_wl, *refn_u;
	size_t nrefn;
};

/* The budget of nth DHR curves dhr[t*L + l] over wavelengths wl[L] with the reconstruction's σ sig[...]: the
 * components cert, drift, wlcal, nonlin, refnoise (= |DHR|·u_rel(λ) of the reference's noise; each [nth*L], may
 * be NULL) and the total √(sig² + cert² + drift² + wlcal² + nonlin² + refnoise²). cert and drift are one common
 * factor across wavelengths and incidences (correlation 1: a scale error of the reference or the source); wlcal is
 * correlated across neighbouring wavelengths; refnoise is common to the incidences, independent across
 * wavelengths. Returns 0 or -1 with err (bad options). */
int recon_budget(size_t nth, size_t L, const double *wl, const double *dhr, const double *sig,
		 const struct recon_budget_opts *o, double *cert, double *drift, double *wlcal, double *nonlin,
		 double *refnoise, double *total, struct acq_err *err);

/* Agreement of a DHR curve (model: value md, total σ ms, its correlated part mc — cert and drift, fully correlated
 * across wavelengths — at each reference wavelength) with a reference (rv ± rs, independent per wavelength). */
struct recon_agreement {
	size_t n, within2;   /* wavelengths compared; |z| <= 2 among them, z = (md − rv)/√(ms² + rs²) */
	double rms_z, max_z, max_z_wl;
	double chi2_n;       /* χ²/n with the correlated part as one common factor (Sherman-Morrison); with the
			      * reference's correlated part (recon_agreement_ref) from the full covariance */
	double chi2_p;       /* P(χ²_n ≥ χ²): the probability of a χ² this large if both agree within their σ */
	int ref_corr;        /* the reference's correlated calibration part was given */
};
/* Compare at n reference wavelengths (arrays [n]); z[n] (may be NULL) receives the per-wavelength z. */
void recon_agreement(size_t n, const double *wl, const double *md, const double *ms, const double *mc,
		     const double *rv, const double *rs, double *z, struct recon_agreement *a);
/* The same, where the reference's stated σ holds a calibration part correlated across wavelengths (a sphere's
 * calibration against its white standard): relative standard uncertainty ref_u of the reference's value, squared-
 * exponential correlation exp(−Δλ²/(2ℓ²)) of length ref_len_nm. χ² = rᵀC⁻¹r with C = the independent parts
 * (model σ minus its common factor, reference σ minus ref_u·rv) + the model's common factor (rank one) + the
 * reference's correlated part, by Cholesky. ref_u = 0 and ip NULL: recon_agreement. 0, or −1 with err (C not positive
 * definite, out of memory). */
/* How the model's curve was taken to the reference wavelengths (optional): value i = (1 − u[i])·y[j[i]] +
 * u[i]·y[j[i] + 1] on the model's grid, whose independent σ (total minus the common factor) is node_sig[]; the
 * model's independent errors at two reference wavelengths between the same nodes are then correlated, as they
 * are (a reference on a 5 nm grid against a model on 10 nm: χ² 3× too large when taken as independent). */
struct recon_ref_interp {
	const size_t *j;
	const double *u;
	const double *node_sig;
	const double *interp_sig; /* [n] the interpolation's own error at each compared wavelength (independent) */
	size_t L;
};
int recon_agreement_ref(size_t n, const double *wl, const double *md, const double *ms, const double *mc,
			const double *rv, const double *rs, double ref_u, double ref_len_nm,
			const struct recon_ref_interp *ip, double *z, struct recon_agreement *a, struct acq_err *err);

#endif
