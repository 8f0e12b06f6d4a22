/* recon: the reconstruction library. Radial basis functions on S²₊ × S²₊ with a provably positive-definite,
 * reciprocal kernel; non-negativity, reciprocity and energy conservation by construction; DHR(θi, λ) with
 * uncertainty; a versioned model file. No global state, no logging: errors come back in struct acq_err. */
#ifndef RECON_RECON_H
#define RECON_RECON_H

#include <stddef.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "recon/csvio.h"
#include "recon/rbf.h"
#include "recon/trend.h"

/* Transform interpolated instead of f, so that the map back is non-negative. */
enum recon_transform {
	RECON_T_LOG = 0,  /* default: g = ln(f + ε); f̂ = max(0, e^g − ε) */
	RECON_T_SQRT = 1, /* g = sqrt(max(f, 0)); f̂ = g² */
	RECON_T__COUNT
};

#define RECON_SMOOTHING_SIGMA (-2.0)

/* Progress report of a long step: stage name and fraction done in [0, 1]. */
typedef void (*recon_progress_fn)(void *ctx, const char *stage, double frac);

struct recon_fit_opts {
	int kernel;          /* enum rbf_kernel (default RBF_K_WENDLAND) */
	int transform;       /* enum recon_transform (default RECON_T_LOG) */
	double shape;        /* > 0: fixed shape parameter; 0: chosen by Rippa's leave-one-out over a grid */
	double smoothing;    /* >= 0: fixed η in (K + η·diag(r)) w = g; RECON_SMOOTHING_SIGMA: Λ from the
			      * uncertainties alone; other < 0: chosen by leave-one-out */
	double max_cond;     /* largest accepted 1-norm condition number of K + Λ (default 1e12) */
	int trend;           /* enum recon_trend: mean function (default GGX with the log transform, else none) */
	recon_progress_fn progress;
	void *progress_ctx;
	const char *source;  /* recorded in the model's metadata (may be NULL) */
};

/* A fitted model. Fields are read-only for users; recon_model_free releases it. Arrays of wavelength-
 * dependent data are channel-major: x[l*n + k] for channel l, sample k. */
struct recon_model {
	int kernel, transform;
	double shape, eta;   /* kernel shape; smoothing multiplier (Λ = η·diag(lam)) */
	size_t n, nwl;       /* merged sample directions; wavelengths */
	double *wl;          /* [nwl] nm */
	double *eps;         /* [nwl] offset of the log transform (0 for sqrt) */
	double *mu;          /* [nwl] mean of the transformed data (the constant term of the interpolant) */
	double *ang;         /* [n*4] merged sample directions, radians */
	double *ctr, *tctr;  /* [n*6] canonical points and their τ images (derived from ang) */
	double *soa;         /* [6*n] the canonical points as structure of arrays (derived, rbf_krow) */
	double *lam;         /* [n] relative noise pattern r_k of the smoothing term (mean 1) */
	double *w;           /* [nwl*n] weights */
	double *g;           /* [nwl*n] transformed data (with imputed values), for Monte Carlo */
	double *gsig;        /* [nwl*n] standard uncertainty of g (delta method, or LOO RMS without sigmas) */
	int trend;           /* enum recon_trend; g, w and mu are relative to it: g = ln(f + ε) − ln(T + ε) */
	double trend_alpha;  /* roughness of the trend (the coat kind: its narrow lobe) */
	double trend_alpha2; /* the coat kind's second roughness (its broad base lobe); 0 for the other kinds */
	double *tcoef;       /* [nwl*TREND_NB] non-negative trend coefficients (all 0 without a trend) */
	size_t ntab;         /* albedo table: A(θ, λ) ≥ albedo of the unscaled interpolant on [θ_t, θ_t+1] */
	double *tab_theta;   /* [ntab] increasing nodes from 0 to π/2 (10° apart, bisected where needed) */
	double *tab_alb;     /* [(ntab-1)*nwl] upper bound of the albedo on each interval, row-major */
	double alb_margin;   /* largest quadrature-error margin included in tab_alb (albedo units) */
	int tab_capped;      /* the table reached its work budget (energy.c; fit only, not stored) */
	double loo_rms;      /* leave-one-out RMS residual in the transformed space (all channels) */
	double rcond;        /* reciprocal condition number estimate of K + Λ (dpocon) */
	const struct recon_model *whole; /* a view of some of a model's channels (select's value channels): that
					  * model, whose model-wide choices (dhr.c's width search) the view keeps;
					  * NULL for a model of its own (not stored) */
	char meta[2048];     /* key=value lines: source, sizes, merges, imputations, version, time */
};

/* Defaults: Wendland kernel, log transform, shape and smoothing chosen by leave-one-out, cond ≤ 1e12. */
void recon_fit_opts_default(struct recon_fit_opts *o);
/* Fit a model to samples; *out is a new model (recon_model_free), or NULL with err filled. */
int recon_fit(const struct recon_samples *s, const struct recon_fit_opts *o, struct recon_model **out,
	      struct acq_err *err);
/* Release a model (NULL is fine). */
void recon_model_free(struct recon_model *m);

/* Evaluate the final BRDF (sr⁻¹, energy-scaled) at m directions ang[q*4..] (θi,φi,θo,φo radians) into
 * out[q*nwl + l]. All outputs are finite and ≥ 0. */
int recon_eval(const struct recon_model *m, size_t nq, const double *ang, double *out, struct acq_err *err);
/* Same at one pair of unit vectors (z up; below-horizon components are clamped to the horizon). */
int recon_eval_dirs(const struct recon_model *m, const double wi[3], const double wo[3], double *out,
		    struct acq_err *err);
/* Evaluate at m canonical points (rbf_canon) into out[q*nwl + l]; scaled = apply the energy factor.
 * work must hold recon_eval_work_size(m) doubles. */
void recon_eval_canon(const struct recon_model *m, size_t nq, const double *c6, int scaled, double *out,
		      double *work);
/* Size in doubles of the work buffer of recon_eval_canon for up to RECON_EVAL_BLOCK queries. */
size_t recon_eval_work_size(const struct recon_model *m);
#define RECON_EVAL_BLOCK 256

/* Index t of the albedo-table interval [tab_theta[t], tab_theta[t+1]) holding θ (the last one for π/2). */
size_t recon_tab_interval(const struct recon_model *m, double theta);
/* Energy factor s(θi, θo, λ) = 1 / max(1, A(θi, λ), A(θo, λ)) of channel l. */
double recon_energy_scale(const struct recon_model *m, double ti, double to, size_t l);

/* Albedo a(θi, λ) = ∫ f cosθo dωo of the model (scaled or not) with a Gauss-Legendre(nmu, in cosθo) ×
 * midpoint(nphi, azimuth over [0, π], doubled by the mirror) rule, doubled per channel until two rules
 * agree to 1e-3 (relative) or nmu would pass 256; out[nwl]. */
int recon_albedo(const struct recon_model *m, double theta_i, int nmu, int nphi, int scaled, double *out,
		 struct acq_err *err);

/* DHR(θi, λ) of the final model at nth incidences (radians) into dhr[t*nwl + l], with standard uncertainty
 * sig[...]: ndraws Monte-Carlo redraws of the data through the one stored factorisation (seeded), combined
 * with the interpolation-error term (recon_dhr_ex). */
int recon_dhr(const struct recon_model *m, size_t nth, const double *theta, int ndraws, uint64_t seed,
	      double *dhr, double *sig, recon_progress_fn progress, void *pctx, struct acq_err *err);
/* The parts of the DHR's standard uncertainty, each [nth*nwl] like the DHR (any may be NULL); recon_dhr's σ is
 * √(max(noise, model)² + quad² + misfit² + res²) (dhr.c, recon/reconstruction.md):
 *  noise  the samples' uncertainties propagated by Monte Carlo through the one factorisation;
 *  model  the interpolation error between samples (GP posterior variance, amplitude from the leave-one-out
 *         residuals) including the prior on the unseen part of the hemisphere: max(kriging ⊕ σ_w, energy), σ_w
 *         the lobe's width where the fit's admissibility rule rather than the data set it (dhr.c width_sd; not a
 *         part of its own);
 *  kriging, energy  its terms: the GP's posterior σ (with the extrapolation term σ_X beyond the plan's last
 *                   zenith in quadrature: recon_int.h, recon_edge_size), and the energy-bounded prior σ_E (recon_int.h);
 *  quad   the quadrature error (last refinement step plus any overshoot above 1);
 *  misfit the data the final model does not honour (nearest-neighbour quadrature of its significant
 *         differences from the samples: smoothing, energy scaling);
 *  res    resolution in θi: distance of the DHR from the line between the DHRs at the bracketing sampled
 *         incidences (a lobe narrower than the incidence spacing). σ adds misfit² + res² to the above. */
struct recon_dhr_parts {
	double *noise, *model, *quad, *misfit, *res;
	double *kriging, *energy;
	/* in (NULL: built here): the kernel rows at the fixed rule, kq[(t*Q + q)*n + k] = kernel of node q of
	 * recon_hemi_nodes(theta[t], 32, 48, 0) with centre k (rbf_kmatrix_soa on m->soa; Q = 32 · 48), from a caller
	 * that builds them anyway (select) */
	const double *kq;
	/* in (both NULL: built here): recon_gp_setup's A (the Cholesky factor of K + ηΛ) and Ainv (the inverse's lower
	 * triangle) for a model with m's centres, kernel, shape, η and λ (they do not depend on the channels), from a
	 * caller that built them (select) */
	const double *gp_A, *gp_Ainv;
};
/* recon_dhr with its uncertainty split into parts (may be NULL). */
int recon_dhr_parts(const struct recon_model *m, size_t nth, const double *theta, int ndraws, uint64_t seed,
		    double *dhr, double *sig, const struct recon_dhr_parts *parts, recon_progress_fn progress, void *pctx,
		    struct acq_err *err);
/* recon_dhr_parts with the noise, model and quadrature parts as separate arrays (each may be NULL). */
int recon_dhr_ex(const struct recon_model *m, size_t nth, const double *theta, int ndraws, uint64_t seed,
		 double *dhr, double *sig, double *sig_noise, double *sig_model, double *sig_quad,
		 recon_progress_fn progress, void *pctx, struct acq_err *err);

/* Result of recon_check: worst violations of the three properties. */
struct recon_check_report {
	size_t npairs, nalb;      /* random pairs and random incidences tested */
	double min_value;         /* smallest f over all pairs and channels (must be ≥ 0) */
	double max_recip_abs;     /* largest |f(ωi,ωo) − f(ωo,ωi)| */
	double max_recip_rel;     /* same relative to max(|f|, 1e-300) */
	double max_albedo;        /* largest albedo found (must be ≤ 1) */
	double max_albedo_theta;  /* where (radians) */
	double max_albedo_wl;     /* at which wavelength (nm) */
	double max_albedo_qerr;   /* the check's own quadrature uncertainty there: 2 × its last rule difference */
	double energy_excess;     /* largest albedo − 2 × its rule difference − 1 over every incidence and channel:
				   * > 0 is a violation beyond the check's quadrature uncertainty */
	size_t nonfinite;         /* non-finite outputs (must be 0) */
	size_t alb_unresolved;    /* channel × incidence albedos the check's cubature left above its error target
				   * (1e-3 relative): their energy verdict is only as good as that estimate */
};
/* Verify non-negativity and reciprocity at npairs random pairs, and the albedo at nalb random incidences
 * (plus 0 and 90°) with an independent quadrature (adaptive cubature over cells of cosθo × azimuth). */
int recon_check(const struct recon_model *m, size_t npairs, size_t nalb, uint64_t seed,
		struct recon_check_report *rep, recon_progress_fn progress, void *pctx, struct acq_err *err);

/* Write a model file (format in rmodel.c); refuses non-finite data. Atomic (temporary file + rename). */
int recon_model_save(const struct recon_model *m, const char *path, struct acq_err *err);
/* Read and validate a model file; *out is a new model or NULL with a message naming the bad field. */
int recon_model_load(const char *path, struct recon_model **out, struct acq_err *err);
/* Same from a memory buffer (name is used in messages). */
int recon_model_load_mem(const char *name, const unsigned char *buf, size_t len, struct recon_model **out,
			 struct acq_err *err);
/* Derive ctr/tctr from ang (used by fit and load); returns -1 on allocation failure. */
int recon_model_derive(struct recon_model *m, struct acq_err *err);

/* Load the calibrated samples of one sweep from the daemon's SQLite database (schema version 1, opened
 * read-only; dbload.c): planned angles, float32 BRDF and sigma blobs over the sweep's wavelength grid. */
int recon_load_db(const char *db_path, long long sweep_id, struct recon_samples *s, struct acq_err *err);

/* Name of a transform ("log", "sqrt") or NULL; and back (−1 if unknown). */
const char *recon_transform_name(int t);
int recon_transform_from_name(const char *name);

#endif
