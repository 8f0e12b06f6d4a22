/* gp: the Gaussian-process reading of a fitted model (g − μ ~ GP(0, α_λ K), noise α_λ ηΛ) that its uncertainties
 * share — the factorisation of K + ηΛ, the leave-one-out amplitude α_λ, the posterior variance at query points
 * (gp.c; the DHR's σ_model, the slices' band and the selection's targets use it). Not an API of librecon. */
#ifndef RECON_GP_H
#define RECON_GP_H

#include <stddef.h>

#include "config/acq_err.h"
#include "recon/recon.h"

/* The Gaussian-process set-up shared by the DHR's and the slices' uncertainty: A[n*n] receives the lower
 * Cholesky factor of K + ηΛ (the fit's system, column-major), alpha[L] the leave-one-out amplitude of every
 * channel, α_λ = mean_k w_k²/(A⁻¹)_kk (Ainv[n*n] is scratch). Errors name the caller `who`. 0 ok, −1 error. */
int recon_gp_setup(const struct recon_model *m, const char *who, double *A, double *Ainv, double *alpha,
		   struct acq_err *err);
/* alpha[L], the leave-one-out amplitude of every channel, from recon_gp_setup's Ainv (its diagonal). */
void recon_gp_alpha(const struct recon_model *m, const double *Ainv, double *alpha);
/* v[q] = max(K(x_q, x_q) − k_qᵀ A⁻¹ k_q, 0), the unit-amplitude posterior variance at nq canonical points
 * c6[6 nq], from their kernel rows Kq[q*n + k] and A, recon_gp_setup's factor; G[nq*n] receives A⁻¹ k_q (row q).
 * 0, or −1 with err naming `who`. */
int recon_gp_postvar(const struct recon_model *m, const double *A, size_t nq, const double *c6, const double *Kq,
		     double *G, double *v, const char *who, struct acq_err *err);

#endif
