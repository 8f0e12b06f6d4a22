/* select_prior: the energy prior's σ_E (recon_int.h recon_prior_energy_sd) after picks, for the DHR target of the
 * selection. σ_E = √p · s at each incidence, p = max(U, the mirror direction's unseen-ness): a pick near the
 * mirror direction, or in an unseen part of the hemisphere, lowers p. With candidate j added, U and the mirror's
 * unseen-ness are recomputed from nearest-sample distances at the DHR's fixed rule (the same rule, reach and width
 * as dhr.c), and σ_E² is predicted as σ_E² · p_j / p (s, the energy split's spread, kept: p is what a pick moves
 * most; where the mirror becomes seen p falls from 1 to U). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/rbf.h"
#include "recon/recon_int.h"
#include "recon/select_int.h"

struct sel_prior {
	size_t nth, Q, J, Lc;
	double reach, w;  /* recon_energy_reach of the trend's narrowest feature; the specular lobe's width */
	double *c6, *wt;  /* [nth*Q*6], [nth*Q]: the DHR rule's nodes */
	double *d;        /* [nth*Q] distance to the nearest sample or pick */
	double *mir;      /* [nth*6] the mirror points */
	double *umir;     /* [nth] the mirror direction's unseen-ness with the samples and picks */
	double *p;        /* [nth] p with the samples and picks */
	double *pj;       /* [nth*J] p with candidate j added */
	double *e2;       /* [nth*Lc] σ_E² at p */
};

/* p at incidence t with an extra sample at canonical point x (NULL: none). */
static double p_with(const struct sel_prior *pr, size_t t, const double *x)
{
	double tx[6], U = 0, um = pr->umir[t];
	if (x) {
		rbf_tau(x, tx);
		if (um > 0)
			um = fmin(um, recon_mirror_term(pr->mir + 6 * t, x, tx, pr->w));
	}
	const double *c6 = pr->c6 + t * pr->Q * 6, *d = pr->d + t * pr->Q, *wt = pr->wt + t * pr->Q;
	for (size_t q = 0; q < pr->Q; q++) {
		double dq = d[q];
		if (x && dq > RECON_PRIOR_R0)
			dq = fmin(dq, sqrt(rbf_canon_dist2(c6 + 6 * q, x, tx)));
		U += recon_unseen_energy(dq, pr->reach) * wt[q];
	}
	return fmax(U / M_PI, um);
}

/* Every candidate's p at every incidence. */
static void candidates_p(struct sel_prior *pr, const struct sel *s)
{
	for (size_t t = 0; t < pr->nth; t++)
		for (size_t j = 0; j < pr->J; j++)
			pr->pj[t * pr->J + j] = pr->p[t] > 0 ? p_with(pr, t, s->cu + 6 * j) : 0;
}

void sel_prior_free(struct sel *s)
{
	struct sel_prior *pr = s->prior;
	if (!pr)
		return;
	free(pr->c6);
	free(pr->wt);
	free(pr->d);
	free(pr->mir);
	free(pr->umir);
	free(pr->p);
	free(pr->pj);
	free(pr->e2);
	free(pr);
	s->prior = NULL;
}

int sel_prior_init(struct sel *s, const double *th, const double *se, size_t ldse, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t nth = s->nth, Q = (size_t)SEL_NMU * SEL_NPHI, J = s->J, Lc = s->Lc;
	struct sel_prior *pr = calloc(1, sizeof *pr);
	if (!pr)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	s->prior = pr;
	*pr = (struct sel_prior){ .nth = nth, .Q = Q, .J = J, .Lc = Lc };
	pr->reach = recon_energy_reach(recon_trend_width(m, 0));
	pr->w = recon_trend_width(m, 1);
	pr->c6 = malloc(nth * Q * 6 * sizeof *pr->c6);
	pr->wt = malloc(nth * Q * sizeof *pr->wt);
	pr->d = malloc(nth * Q * sizeof *pr->d);
	pr->mir = malloc(nth * 6 * sizeof *pr->mir);
	pr->umir = malloc(nth * sizeof *pr->umir);
	pr->p = malloc(nth * sizeof *pr->p);
	pr->pj = malloc((J ? nth * J : 1) * sizeof *pr->pj);
	pr->e2 = malloc(nth * Lc * sizeof *pr->e2);
	if (!pr->c6 || !pr->wt || !pr->d || !pr->mir || !pr->umir || !pr->p || !pr->pj || !pr->e2) {
		sel_prior_free(s);
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	}
	for (size_t t = 0; t < nth; t++) {
		if (recon_hemi_nodes(th[t], SEL_NMU, SEL_NPHI, 0, pr->c6 + t * Q * 6, pr->wt + t * Q)) {
			sel_prior_free(s);
			return acq_errf(err, ACQ_E_INVAL, "select: quadrature");
		}
		for (size_t q = 0; q < Q; q++)
			pr->d[t * Q + q] = recon_nearest_centre(m, pr->c6 + (t * Q + q) * 6, NULL);
		rbf_canon(th[t], 0.0, th[t], M_PI, pr->mir + 6 * t);
		pr->umir[t] = recon_mirror_unseen(m, pr->mir + 6 * t, pr->w);
		pr->p[t] = p_with(pr, t, NULL);
		for (size_t c = 0; c < Lc; c++)
			pr->e2[t * Lc + c] = se[t * ldse + s->cpos[c]] * se[t * ldse + s->cpos[c]];
	}
	candidates_p(pr, s);
	return 0;
}

double sel_prior_e2(const struct sel *s, size_t t, size_t c, size_t j)
{
	const struct sel_prior *pr = s->prior;
	if (!pr)
		return 0;
	double e2 = pr->e2[t * pr->Lc + c];
	if (j == SIZE_MAX || !(pr->p[t] > 0))
		return e2;
	return e2 * fmin(pr->pj[t * pr->J + j] / pr->p[t], 1.0);
}

struct sel_prior_view sel_prior_view(const struct sel *s)
{
	const struct sel_prior *pr = s->prior;
	if (!pr)
		return (struct sel_prior_view){ 0 };
	return (struct sel_prior_view){ .e2 = pr->e2, .p = pr->p, .pj = pr->pj, .Lc = pr->Lc };
}

void sel_prior_pick(struct sel *s, size_t p)
{
	struct sel_prior *pr = s->prior;
	if (!pr)
		return;
	const double *x = s->cu + 6 * p;
	double tx[6];
	rbf_tau(x, tx);
	for (size_t t = 0; t < pr->nth; t++) {
		double pold = pr->p[t];
		for (size_t q = 0; q < pr->Q; q++) {
			double *dq = pr->d + t * pr->Q + q;
			*dq = fmin(*dq, sqrt(rbf_canon_dist2(pr->c6 + (t * pr->Q + q) * 6, x, tx)));
		}
		pr->umir[t] = fmin(pr->umir[t], recon_mirror_term(pr->mir + 6 * t, x, tx, pr->w));
		pr->p[t] = p_with(pr, t, NULL);
		double r = pold > 0 ? fmin(pr->p[t] / pold, 1.0) : 0;
		for (size_t c = 0; c < pr->Lc; c++)
			pr->e2[t * pr->Lc + c] *= r;
	}
	candidates_p(pr, s);
}
