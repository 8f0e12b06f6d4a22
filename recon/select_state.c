/* select_state: a selection's working state before the first pick: the model's factor, the distinct candidates
 * with their posterior rows, the target's points and functionals (select_setup.c), the noise-tracking arrays. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/bigbuf.h"
#include "recon/recon_int.h"
#include "recon/select_int.h"

void sel_free(struct sel *s)
{
	if (!s->shared) { /* the candidates' arrays (a shared state's are its owner's) */
		free(s->A);
		free(s->Ainv);
		free(s->alpha);
		free(s->cu);
		free(s->soaJ);
		free(s->rep);
		free(s->cost);
		free(s->Kjn);
		free(s->G);
		free(s->Pjj);
		free(s->U);
		free(s->picked);
		free(s->row);
	}
	free(s->chan);
	free(s->vchan);
	free(s->cpos);
	free(s->Z);
	free(s->v);
	sel_prior_free(s);
	free(s->match);
	free(s->sn2);
	free(s->rest);
	free(s->res2);
	free(s->kappa);
	free(s->res_done);
	free(s->xang);
	free(s->xw);
	free(s->zp);
	free(s->Nk);
	free(s->q);
	free(s->q0);
	free(s->qmin);
	free(s->X);
	free(s->Yn);
	free(s->Gc);
	free(s->gn);
	free(s->mrow);
	free(s->gp);
}

void sel_gp_free(struct sel_gp *gp)
{
	free(gp->A);
	free(gp->Ainv);
	free(gp->alpha);
	*gp = (struct sel_gp){ 0 };
}

/* Factor K + ηΛ of the model, its inverse and the leave-one-out amplitude α_λ of every channel (as dhr.c, to which
 * sel_setup_dhr lends the factor and the inverse). */
static int sel_factor(struct sel *s, struct sel_gp *gp, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, L = s->L;
	if (gp && gp->A && gp->Ainv && gp->alpha) { /* the lobe gate's, of the same model */
		s->A = gp->A;
		s->Ainv = gp->Ainv;
		s->alpha = gp->alpha;
		*gp = (struct sel_gp){ 0 };
	} else {
		s->Ainv = recon_big_alloc(n * n * sizeof *s->Ainv);
		s->A = recon_big_alloc(n * n * sizeof *s->A);
		s->alpha = calloc(L, sizeof *s->alpha);
		if (!s->Ainv || !s->A || !s->alpha)
			return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		if (recon_gp_setup(m, "select", s->A, s->Ainv, s->alpha, err))
			return -1;
	}
	double *r = malloc(n * sizeof *r);
	if (!r)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	memcpy(r, m->lam, n * sizeof *r);
	for (size_t i = 1; i < n; i++) /* insertion sort: n is a few thousand at most, once */
		for (size_t k = i; k > 0 && r[k - 1] > r[k]; k--) {
			double x = r[k];
			r[k] = r[k - 1];
			r[k - 1] = x;
		}
	s->noise = m->eta * (n % 2 ? r[n / 2] : 0.5 * (r[n / 2 - 1] + r[n / 2]));
	free(r);
	return 0;
}

static double dist2(const double *a, const double *b)
{
	double d = 0;
	for (int i = 0; i < 6; i++)
		d += (a[i] - b[i]) * (a[i] - b[i]);
	return d;
}

/* Validate the candidates, merge coincident ones (cheapest kept), and set up their kernel rows, A⁻¹k_j and the
 * posterior variance at each. */
static int sel_candidates(struct sel *s, size_t nc, const double *ang, const double *cost, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n;
	for (size_t j = 0; j < nc; j++) {
		const double *a = ang + 4 * j;
		if (!(a[0] >= 0 && a[0] <= M_PI / 2 && a[2] >= 0 && a[2] <= M_PI / 2) || !isfinite(a[1]) || !isfinite(a[3]))
			return acq_errf(err, ACQ_E_RANGE, "select: candidate %zu: zenith angles must be in [0, 90] degrees and "
					"azimuths finite", j + 1);
		if (!(cost[j] > 0) || !isfinite(cost[j]))
			return acq_errf(err, ACQ_E_RANGE, "select: candidate %zu: cost must be a positive number of seconds", j + 1);
	}
	double *c6 = malloc((nc ? nc : 1) * 12 * sizeof *c6);
	s->cu = malloc((nc ? nc : 1) * 6 * sizeof *s->cu);
	s->rep = malloc((nc ? nc : 1) * sizeof *s->rep);
	s->cost = malloc((nc ? nc : 1) * sizeof *s->cost);
	if (!c6 || !s->cu || !s->rep || !s->cost) {
		free(c6);
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	}
	size_t J = 0;
	for (size_t j = 0; j < nc; j++) {
		const double *a = ang + 4 * j;
		double *c = c6 + 12 * j, *tc = c + 6;
		rbf_canon(a[0], a[1], a[2], a[3], c);
		rbf_tau(c, tc);
		size_t u = J;
		for (size_t i = 0; i < J; i++) { /* the same measurement: the same canonical point, or its τ image */
			const double *b = s->cu + 6 * i;
			if (dist2(c, b) < SEL_SAME * SEL_SAME || dist2(tc, b) < SEL_SAME * SEL_SAME) {
				u = i;
				break;
			}
		}
		if (u == J) {
			memcpy(s->cu + 6 * J, c, 6 * sizeof *c);
			s->rep[J] = j;
			s->cost[J] = cost[j];
			J++;
		} else if (cost[j] < s->cost[u]) {
			s->rep[u] = j;
			s->cost[u] = cost[j];
		}
	}
	free(c6);
	s->J = J;
	size_t Jp = J ? J : 1;
	if ((double)J * (double)(SEL_NMU * SEL_NPHI + 2 * n + SELECT_MAX_THETA * s->Lc + 400) * 8.0 > 4e9)
		return acq_errf(err, ACQ_E_RANGE, "select: %zu distinct candidates × %zu centres need too much memory", J, n);
	s->soaJ = malloc(6 * Jp * sizeof *s->soaJ);
	s->Kjn = recon_big_alloc(Jp * n * sizeof *s->Kjn); /* the candidates' rows on huge pages (bigbuf.c) */
	s->G = recon_big_alloc(Jp * n * sizeof *s->G);
	s->Pjj = malloc(Jp * sizeof *s->Pjj);
	s->picked = calloc(Jp, 1);
	if (!s->soaJ || !s->Kjn || !s->G || !s->Pjj || !s->picked)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory for %zu candidates", J);
	if (!J)
		return 0;
	rbf_soa(J, s->cu, s->soaJ);
	rbf_kmatrix_soa(m->kernel, m->shape, J, s->cu, n, m->soa, s->Kjn);
	return recon_gp_postvar(m, s->A, J, s->cu, s->Kjn, s->G, s->Pjj, "select", err);
}

/* Borrow own's factor and candidates' arrays (sel_free leaves them to own). */
static void sel_share(struct sel *s, const struct sel *own)
{
	s->shared = 1;
	s->A = own->A;
	s->Ainv = own->Ainv;
	s->alpha = own->alpha;
	s->noise = own->noise;
	s->J = own->J;
	s->cu = own->cu;
	s->soaJ = own->soaJ;
	s->rep = own->rep;
	s->cost = own->cost;
	s->Kjn = own->Kjn;
	s->G = own->G;
	s->Pjj = own->Pjj;
	s->U = own->U;
	s->picked = own->picked;
	s->row = own->row;
}

int sel_init(struct sel *s, const struct recon_model *m, size_t nc, const double *ang, const double *cost,
		    const struct select_target *t, const struct select_opts *o, struct select_result *r, struct acq_err *err)
{
	return sel_init_part(s, NULL, NULL, m, nc, ang, cost, t, o, r, err);
}

int sel_init_part(struct sel *s, const struct sel *own, struct sel_gp *gp, const struct recon_model *m, size_t nc,
		  const double *ang,
		  const double *cost, const struct select_target *t, const struct select_opts *o, struct select_result *r,
		  struct acq_err *err)
{
	*s = (struct sel){ .m = m, .t = t, .n = m->n, .L = m->nwl, .nth = t->kind == SELECT_DHR ? t->nth : 0 };
	s->thr2 = isfinite(t->threshold) ? t->threshold * t->threshold : 0;
	s->Lc = s->L < o->nchan ? s->L : o->nchan;
	s->LV = s->L;
	if (t->kind == SELECT_DHR && o->nvalue && s->L > o->nvalue) { /* the value on nvalue channels, evenly spread */
		s->LV = o->nvalue > s->Lc ? o->nvalue : s->Lc;
		if (!(s->vchan = malloc(s->LV * sizeof *s->vchan)))
			return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		for (size_t v = 0; v < s->LV; v++)
			s->vchan[v] = s->LV > 1 ? v * (s->L - 1) / (s->LV - 1) : s->L / 2;
	}
	s->chan = malloc(s->Lc * sizeof *s->chan);
	s->cpos = malloc(s->Lc * sizeof *s->cpos);
	if (!s->chan || !s->cpos)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	for (size_t c = 0; c < s->Lc; c++) { /* the tracked channels, among the value channels */
		s->cpos[c] = s->Lc > 1 ? c * (s->LV - 1) / (s->Lc - 1) : s->LV / 2;
		s->chan[c] = s->vchan ? s->vchan[s->cpos[c]] : s->cpos[c];
	}
	if (own)
		sel_share(s, own);
	else if (sel_factor(s, gp, err) || sel_candidates(s, nc, ang, cost, err))
		return -1;
	r->nunique = s->J;
	size_t J = s->J, Jp = J ? J : 1;
	s->batch = o->batch < J ? o->batch : J;
	if (t->kind == SELECT_DHR) {
		s->F = s->nth * s->Lc;
	} else if (t->kind == SELECT_LNF) {
		s->F = sel_lnf_grid(NULL, NULL);
		s->xang = malloc(s->F * 4 * sizeof *s->xang);
		s->xw = malloc(s->F * sizeof *s->xw);
		if (!s->xang || !s->xw)
			return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		sel_lnf_grid(s->xang, s->xw);
	} else {
		s->F = sel_rgb_nodes(NULL, NULL);
		s->xang = malloc(s->F * 4 * sizeof *s->xang);
		s->xw = malloc(s->F * sizeof *s->xw);
		if (!s->xang || !s->xw)
			return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		sel_rgb_nodes(s->xang, s->xw);
	}
	size_t F = s->F;
	if ((double)F * (double)Jp * 8.0 > 4e9)
		return acq_errf(err, ACQ_E_RANGE, "select: %zu distinct candidates × %zu target points need too much memory",
				J, F);
	s->Z = malloc(F * Jp * sizeof *s->Z);
	s->v = calloc(F, sizeof *s->v);
	if (!own) {
		s->U = malloc((s->batch ? s->batch : 1) * Jp * sizeof *s->U);
		s->row = malloc(Jp * sizeof *s->row);
	}
	s->match = calloc((s->nth ? s->nth : 1) * Jp, 1);
	s->sn2 = calloc(F, sizeof *s->sn2);
	s->rest = calloc(F, sizeof *s->rest);
	s->res2 = calloc(F, sizeof *s->res2);
	s->kappa = calloc(SELECT_MAX_THETA, sizeof *s->kappa);
	s->res_done = calloc(SELECT_MAX_THETA, 1);
	s->zp = malloc(F * sizeof *s->zp);
	if (!s->Z || !s->v || !s->U || !s->match || !s->sn2 || !s->rest || !s->res2 || !s->kappa || !s->res_done ||
	    !s->row || !s->zp)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	s->q = calloc(F, sizeof *s->q);
	s->q0 = calloc(F, sizeof *s->q0);
	s->qmin = calloc(F, sizeof *s->qmin);
	if (!s->q || !s->q0 || !s->qmin)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	if (t->kind == SELECT_DHR) { /* the noise part's fall with n (sel_update_noise) */
		size_t n = s->n;
		s->Nk = malloc(n * sizeof *s->Nk);
		s->X = calloc(F * Jp, sizeof *s->X);
		s->Yn = calloc(Jp, sizeof *s->Yn);
		s->Gc = recon_big_alloc(Jp * n * sizeof *s->Gc);
		s->gn = calloc((s->batch ? s->batch : 1) * Jp, sizeof *s->gn);
		s->mrow = malloc(Jp * sizeof *s->mrow);
		s->gp = malloc(n * sizeof *s->gp);
		if (!s->Nk || !s->X || !s->Yn || !s->Gc || !s->gn || !s->mrow || !s->gp)
			return acq_errf(err, ACQ_E_NOMEM, "select: out of memory for %zu candidates", J);
		for (size_t k = 0; k < n; k++)
			s->Nk[k] = m->eta * m->lam[k];
		memcpy(s->Gc, s->G, J * n * sizeof *s->Gc);
		for (size_t j = 0; j < J; j++) {
			double y = 0;
			for (size_t k = 0; k < n; k++)
				y += s->Nk[k] * s->Gc[j * n + k] * s->Gc[j * n + k];
			s->Yn[j] = y;
		}
	}
	if (t->kind == SELECT_DHR ? sel_setup_dhr(s, o, r, err)
				  : t->kind == SELECT_LNF ? sel_setup_lnf(s, r, err) : sel_setup_rgb(s, r, err))
		return -1;
	for (size_t tt = 0; tt < s->nth; tt++) { /* candidates at a target incidence (they zero its resolution term) */
		double th = t->theta_deg[tt] * M_PI / 180;
		for (size_t j = 0; j < J; j++) {
			const double *a = ang + 4 * s->rep[j];
			s->match[tt * J + j] = fabs(a[0] - th) <= SEL_RES_TOL || fabs(a[2] - th) <= SEL_RES_TOL;
		}
	}
	r->met = isfinite(t->threshold) && r->value <= t->threshold;
	return 0;
}
