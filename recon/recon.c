/* recon: the model's life cycle (options, names, release, derived centres). The reconstruction itself is
 * split by concern: fit.c (the fit as named steps), eval.c (evaluation with the energy factor), quad.c
 * (hemisphere quadrature), energy.c (the energy table), dhr.c (DHR and its uncertainty), check.c (checker). */
#include "recon/recon.h"

#include <stdlib.h>
#include <string.h>

#include "recon/recon_int.h"

void recon_fit_opts_default(struct recon_fit_opts *o)
{
	memset(o, 0, sizeof *o);
	o->kernel = RBF_K_WENDLAND;
	o->transform = RECON_T_LOG;
	o->shape = 0;
	o->smoothing = -1;
	o->max_cond = 1e12;
	o->trend = -1; /* GGX with the log transform, none with sqrt */
}

const char *recon_transform_name(int t)
{
	return t == RECON_T_LOG ? "log" : t == RECON_T_SQRT ? "sqrt" : NULL;
}

int recon_transform_from_name(const char *name)
{
	if (!name)
		return -1;
	if (!strcmp(name, "log"))
		return RECON_T_LOG;
	if (!strcmp(name, "sqrt"))
		return RECON_T_SQRT;
	return -1;
}

void recon_model_free(struct recon_model *m)
{
	if (!m)
		return;
	free(m->wl);
	free(m->eps);
	free(m->mu);
	free(m->ang);
	free(m->ctr);
	free(m->tctr);
	free(m->soa);
	free(m->lam);
	free(m->w);
	free(m->g);
	free(m->gsig);
	free(m->tcoef);
	free(m->tab_theta);
	free(m->tab_alb);
	free(m);
}

int recon_model_derive(struct recon_model *m, struct acq_err *err)
{
	free(m->ctr);
	free(m->tctr);
	free(m->soa);
	m->ctr = malloc(m->n * 6 * sizeof *m->ctr);
	m->tctr = malloc(m->n * 6 * sizeof *m->tctr);
	m->soa = malloc(m->n * 6 * sizeof *m->soa);
	if (!m->ctr || !m->tctr || !m->soa)
		return acq_errf(err, ACQ_E_NOMEM, "model: out of memory for %zu centres", m->n);
	for (size_t k = 0; k < m->n; k++) {
		const double *a = m->ang + 4 * k;
		rbf_canon(a[0], a[1], a[2], a[3], m->ctr + 6 * k);
		rbf_tau(m->ctr + 6 * k, m->tctr + 6 * k);
	}
	rbf_soa(m->n, m->ctr, m->soa);
	return 0;
}

