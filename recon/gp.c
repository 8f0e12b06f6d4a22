/* gp: the Gaussian-process reading of a fitted model that its uncertainties share (gp.h): the factorisation of
 * K + ηΛ with the leave-one-out amplitude α_λ (moved from dhr.c), and the posterior variance at query points (was
 * written three times: slices' band, the selection's point targets and its candidates). */
#include "recon/gp.h"

#include <cblas.h>
#include <lapacke.h>
#include <string.h>

#include "recon/rbf.h"

/* The leave-one-out amplitude of every channel, α_λ = mean_k w_k²/(A⁻¹)_kk, from recon_gp_setup's Ainv. */
void recon_gp_alpha(const struct recon_model *m, const double *Ainv, double *alpha)
{
	size_t n = m->n;
	for (size_t l = 0; l < m->nwl; l++) {
		double acc = 0;
		for (size_t k = 0; k < n; k++)
			acc += m->w[l * n + k] * m->w[l * n + k] / Ainv[k * n + k];
		alpha[l] = acc / (double)n;
	}
}

int recon_gp_setup(const struct recon_model *m, const char *who, double *A, double *Ainv, double *alpha,
		   struct acq_err *err)
{
	size_t n = m->n;
	for (size_t j = 0; j < n; j++)
		for (size_t i = j; i < n; i++) {
			double v = rbf_kernel(m->kernel, m->shape, m->ctr + 6 * i, m->ctr + 6 * j, m->tctr + 6 * j);
			A[j * n + i] = A[i * n + j] = v;
		}
	for (size_t k = 0; k < n; k++)
		A[k * n + k] += m->eta * m->lam[k];
	if (LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', (lapack_int)n, A, (lapack_int)n) != 0)
		return acq_errf(err, ACQ_E_NUMERIC, "%s: refactorisation of the model's system failed (not positive definite)",
				who);
	memcpy(Ainv, A, n * n * sizeof *Ainv);
	if (LAPACKE_dpotri(LAPACK_COL_MAJOR, 'L', (lapack_int)n, Ainv, (lapack_int)n) != 0)
		return acq_errf(err, ACQ_E_NUMERIC, "%s: inverse of the model's system failed", who);
	recon_gp_alpha(m, Ainv, alpha);
	return 0;
}

int recon_gp_postvar(const struct recon_model *m, const double *A, size_t nq, const double *c6, const double *Kq,
		     double *G, double *v, const char *who, struct acq_err *err)
{
	size_t n = m->n;
	memcpy(G, Kq, nq * n * sizeof *G);
	if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)nq, A, (lapack_int)n, G, (lapack_int)n))
		return acq_errf(err, ACQ_E_NUMERIC, "%s: solve failed", who);
	for (size_t q = 0; q < nq; q++) {
		double tc[6];
		rbf_tau(c6 + 6 * q, tc);
		double p = rbf_kernel(m->kernel, m->shape, c6 + 6 * q, c6 + 6 * q, tc) -
			   cblas_ddot((int)n, Kq + q * n, 1, G + q * n, 1);
		v[q] = p > 0 ? p : 0;
	}
	return 0;
}
