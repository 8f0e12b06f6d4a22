/* select: greedy choice of the next measurements by expected variance reduction of the target per second of
 * bench time, with a rank-one update of the Gaussian-process posterior between picks. */
#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/recon_int.h"
#include "recon/select_int.h"

void select_opts_default(struct select_opts *o)
{
	o->route = NULL;
	o->batch = 16;
	o->ndraws = 16;
	o->seed = 1;
	o->nchan = 24;
	o->nvalue = 0;
	o->reference = 0;
}

void select_result_free(struct select_result *r)
{
	free(r->picks);
	r->picks = NULL;
	r->npicks = 0;
}

/*
 * The criterion's value E (the target's variance above the threshold², summed over incidences or grid points)
 * with candidate j's measurement added (j = SIZE_MAX: as it is), and the predicted per-incidence values.
 */
double sel_excess(const struct sel *s, size_t j, double *per)
{
	double S = j == SIZE_MAX ? 0 : s->Pjj[j] + s->noise, E = 0;
	if (s->t->kind == SELECT_DHR) {
		for (size_t t = 0; t < s->nth; t++) {
			double acc = 0;
			int zero_res = j != SIZE_MAX && s->match[t * s->J + j] && !s->res_done[t];
			for (size_t c = 0; c < s->Lc; c++) {
				size_t f = t * s->Lc + c;
				double v = s->v[f], q = s->qmin[f];
				if (j != SIZE_MAX && S > 0) {
					double z = s->Z[f * s->J + j], a = z / S;
					v -= z * z / S;
					if (s->X)
						q = fmin(q, s->q[f] + a * (a * (s->Yn[j] + s->noise) - 2 * s->X[f * s->J + j]));
				}
				double floor2 = s->sn2[f] * (s->q0[f] > 0 ? fmin(fmax(q / s->q0[f], 0), 1) : 1);
				acc += fmax(floor2, fmax(fmax(v, 0), sel_prior_e2(s, t, c, j))) + s->rest[f] -
				       (zero_res ? s->res2[f] : 0);
			}
			double V = s->kappa[t] * fmax(acc, 0) / (double)s->Lc;
			if (per)
				per[t] = sqrt(V);
			E += fmax(V - s->thr2, 0);
		}
		return E;
	}
	double mx = 0, sum = 0;
	for (size_t x = 0; x < s->F; x++) {
		double v = s->v[x];
		if (j != SIZE_MAX && S > 0) {
			double z = s->Z[x * s->J + j];
			v -= z * z / S;
		}
		v = fmax(v, 0);
		mx = fmax(mx, v);
		sum += v;
		E += s->xw[x] * fmax(v - s->thr2, 0);
	}
	if (s->t->kind == SELECT_RGB) { /* one aggregate: the measure is folded into v */
		if (per)
			per[0] = sqrt(sum);
		return fmax(sum - s->thr2, 0);
	}
	/* ln f: the value is the largest σ; the criterion the variance above the threshold² integrated over the
	 * hemisphere pair under its projected measure (the grid cells' shares xw) */
	if (per)
		per[0] = sqrt(mx);
	return E;
}

/* fmax and fmin with the C library's bits on x86-64 (glibc: the larger/smaller, the second argument on a tie, such as
 * ±0, and the other argument when one is a NaN), inline: the candidates' loop below made ~10⁷ library calls per
 * decision (4 % of select's CPU on the white study's model); test_recon_select test_fast_path compares its bits with
 * sel_excess's, which calls the library. */
static inline double sel_max(double a, double b)
{
	return a > b || b != b ? a : b;
}

static inline double sel_min(double a, double b)
{
	return a < b || b != b ? a : b;
}

/*
 * sel_excess(s, j, NULL) for every candidate j not picked, into ex[j] (ex[j] of a picked one is left as it was; acc:
 * scratch [J]). The same arithmetic in the same order per candidate, so the same bits, but with the candidates in the
 * inner loop: Z and X are read along their rows (sel_excess(j) reads one column of each, J apart) and the loop
 * vectorises. This is what the greedy pick calls (test_recon_select test_excess_all: equal bits to sel_excess).
 */
void sel_excess_all(const struct sel *s, double *ex, double *acc)
{
	size_t J = s->J;
	const unsigned char *done = s->picked;
	for (size_t j = 0; j < J; j++)
		ex[j] = 0;
	if (s->t->kind == SELECT_DHR) {
		const struct sel_prior_view pv = sel_prior_view(s);
		for (size_t t = 0; t < s->nth; t++) {
			const unsigned char *match = s->match + t * J;
			int res_open = !s->res_done[t];
			for (size_t j = 0; j < J; j++)
				acc[j] = 0;
			for (size_t c = 0; c < s->Lc; c++) {
				size_t f = t * s->Lc + c;
				const double *Z = s->Z + f * J, *X = s->X ? s->X + f * J : NULL;
				const double *pj = pv.pj ? pv.pj + t * J : NULL;
				double v0 = s->v[f], q0 = s->qmin[f], qf = s->q[f], sn2 = s->sn2[f], rest = s->rest[f],
				       res2 = s->res2[f], qq0 = s->q0[f], e2 = pv.e2 ? pv.e2[t * pv.Lc + c] : 0,
				       pt = pv.p ? pv.p[t] : 0;
				for (size_t j = 0; j < J; j++) {
					if (done[j])
						continue;
					double S = s->Pjj[j] + s->noise, v = v0, q = q0;
					if (S > 0) {
						double z = Z[j], a = z / S;
						v -= z * z / S;
						if (X)
							q = sel_min(q, qf + a * (a * (s->Yn[j] + s->noise) - 2 * X[j]));
					}
					double floor2 = sn2 * (qq0 > 0 ? sel_min(sel_max(q / qq0, 0), 1) : 1);
					double pe2 = !pj ? 0 : !(pt > 0) ? e2 : e2 * sel_min(pj[j] / pt, 1.0);
					acc[j] += sel_max(floor2, sel_max(sel_max(v, 0), pe2)) + rest - (match[j] && res_open ? res2 : 0);
				}
			}
			for (size_t j = 0; j < J; j++) {
				double V = s->kappa[t] * sel_max(acc[j], 0) / (double)s->Lc;
				ex[j] += sel_max(V - s->thr2, 0);
			}
		}
		return;
	}
	for (size_t j = 0; j < J; j++)
		acc[j] = 0; /* RGB: the sum of the point variances */
	for (size_t x = 0; x < s->F; x++) {
		const double *Z = s->Z + x * J;
		double v0 = s->v[x], w = s->xw[x];
		for (size_t j = 0; j < J; j++) {
			if (done[j])
				continue;
			double S = s->Pjj[j] + s->noise, v = v0;
			if (S > 0) {
				double z = Z[j];
				v -= z * z / S;
			}
			v = sel_max(v, 0);
			acc[j] += v;
			ex[j] += w * sel_max(v - s->thr2, 0);
		}
	}
	if (s->t->kind == SELECT_RGB)
		for (size_t j = 0; j < J; j++)
			ex[j] = sel_max(acc[j] - s->thr2, 0);
}

/* The noise variance's terms after candidate p's measurement (the k-th pick; S its posterior variance + noise):
 * with a_f = cov(f, p)/S and b_j = P(p, j)/S (in s->zp, s->row), the functional's weights become h − a w_p and
 * a on the new sample, candidate j's w_j − b_j w_p and b_j; q, X and Yn follow (M_j = Σ N w_p w_j). */
void sel_update_noise(struct sel *s, size_t p, size_t k, double S)
{
	size_t J = s->J, n = s->n, F = s->F;
	double *M = s->mrow, *gp = s->gp, yp = s->Yn[p] + s->noise;
	for (size_t i = 0; i < n; i++)
		gp[i] = s->Nk[i] * s->Gc[p * n + i];
	cblas_dgemv(CblasRowMajor, CblasNoTrans, (int)J, (int)n, 1.0, s->Gc, (int)n, gp, 1, 0.0, M, 1);
	for (size_t i = 0; i < k; i++)
		cblas_daxpy((int)J, s->noise * s->gn[i * J + p], s->gn + i * J, 1, M, 1);
	for (size_t f = 0; f < F; f++) {
		double a = s->zp[f] / S, xp = s->X[f * J + p];
		s->q[f] += a * (a * yp - 2 * xp);
		s->qmin[f] = fmin(s->qmin[f], s->q[f]);
		double *x = s->X + f * J;
		for (size_t j = 0; j < J; j++) {
			double b = s->row[j] / S;
			x[j] += -a * M[j] - b * xp + a * b * yp;
		}
	}
	for (size_t j = 0; j < J; j++) {
		double b = s->row[j] / S;
		s->Yn[j] += b * (b * yp - 2 * M[j]);
	}
	memcpy(gp, s->Gc + p * n, n * sizeof *gp);
	cblas_dger(CblasRowMajor, (int)J, (int)n, -1.0 / S, s->row, 1, gp, 1, s->Gc, (int)n);
	for (size_t i = 0; i < k; i++) {
		double g = s->gn[i * J + p];
		cblas_daxpy((int)J, -g / S, s->row, 1, s->gn + i * J, 1);
	}
	for (size_t j = 0; j < J; j++)
		s->gn[k * J + j] = s->row[j] / S;
}

double sel_update_row(struct sel *s, size_t p, size_t k)
{
	double *row = s->row;
	const struct recon_model *m = s->m;
	size_t J = s->J, n = s->n;
	/* P(x_p, x_j) = K(p, j) − k_pᵀ A⁻¹ k_j − Σ_i U_i(p) U_i(j) */
	rbf_krow(m->kernel, m->shape, s->cu + 6 * p, J, s->soaJ, row);
	cblas_dgemv(CblasRowMajor, CblasNoTrans, (int)J, (int)n, -1.0, s->Kjn, (int)n, s->G + p * n, 1, 1.0, row, 1);
	for (size_t i = 0; i < k; i++)
		cblas_daxpy((int)J, -s->U[i * J + p], s->U + i * J, 1, row, 1);
	double S = s->Pjj[p] + s->noise;
	return S > 0 ? S : 1e-300;
}

void sel_update_target(struct sel *s, size_t p, size_t k, double S)
{
	double *row = s->row, *zp = s->zp;
	size_t J = s->J, F = s->F;
	for (size_t f = 0; f < F; f++)
		zp[f] = s->Z[f * J + p];
	if (s->X)
		sel_update_noise(s, p, k, S);
	for (size_t f = 0; f < F; f++)
		s->v[f] = fmax(s->v[f] - zp[f] * zp[f] / S, 0);
	cblas_dger(CblasRowMajor, (int)F, (int)J, -1.0 / S, zp, 1, row, 1, s->Z, (int)J);
	if (s->t->kind == SELECT_DHR)
		for (size_t t = 0; t < s->nth; t++)
			if (s->match[t * J + p])
				s->res_done[t] = 1;
	sel_prior_pick(s, p);
}

void sel_update_cands(struct sel *s, size_t p, size_t k, double S)
{
	const double *row = s->row;
	for (size_t j = 0; j < s->J; j++) {
		s->Pjj[j] = fmax(s->Pjj[j] - row[j] * row[j] / S, 0);
		s->U[k * s->J + j] = row[j] / sqrt(S);
	}
	s->picked[p] = 1;
}

/* Add candidate p's measurement to the posterior: the rank-one (Schur complement) update of every tracked
 * covariance, with the k-th pick's scaled row stored in U[k]. */
void sel_update(struct sel *s, size_t p, size_t k)
{
	double S = sel_update_row(s, p, k);
	sel_update_target(s, p, k, S);
	sel_update_cands(s, p, k, S);
}

/* A combined target's value: the larger of each part's value over its threshold. */
static double combined_value(const struct select_target *t, double dhr, double lnf)
{
	return fmax(dhr / t->threshold, lnf / t->lnf_threshold);
}

/* select_batch on a candidate set the lobe gate has passed. */
static int select_set(const struct recon_model *m, size_t nc, const double *ang, const double *cost,
		      const struct select_target *t, const struct select_opts *opts, struct sel_gp *gp,
		      struct select_result *r, struct acq_err *err)
{
	struct select_opts o;
	if (opts)
		o = *opts;
	else
		select_opts_default(&o);
	memset(r, 0, sizeof *r);
	if (!m || !t || (nc && (!ang || !cost)))
		return acq_errf(err, ACQ_E_INVAL, "select: no model, target or candidates");
	if (t->kind == SELECT_DHR && (t->nth == 0 || t->nth > SELECT_MAX_THETA))
		return acq_errf(err, ACQ_E_INVAL, "select: between 1 and %d incidences", SELECT_MAX_THETA);
	if (o.batch > 100000 || o.nchan == 0)
		return acq_errf(err, ACQ_E_INVAL, "select: batch at most 100000, at least one tracked channel");
	bool both = t->lnf_threshold > 0;
	if (both && (t->kind != SELECT_DHR || !(t->threshold > 0)))
		return acq_errf(err, ACQ_E_INVAL, "select: a combined target needs the DHR part's threshold");
	/* the parts: one state each (a combined target: the DHR part, then the ln f part; same candidates) */
	struct select_target tp[2] = { *t, { .kind = SELECT_LNF, .threshold = t->lnf_threshold, .lnf_rad = t->lnf_rad } };
	tp[0].lnf_threshold = 0;
	tp[0].lnf_rad = t->kind == SELECT_LNF ? t->lnf_rad : SELECT_LNF_PROJECTED; /* a combined target: tp[1]'s */
	struct select_result r2 = { 0 };
	struct sel s[2];
	struct sel_route route = { 0 };
	size_t np = both ? 2 : 1;
	double *ex = NULL, *acc = NULL;
	int rc = -1;
	memset(s, 0, sizeof s);
	if (sel_init_part(&s[0], NULL, gp, m, nc, ang, cost, &tp[0], &o, r, err) ||
	    (both && sel_init_part(&s[1], o.reference ? NULL : &s[0], NULL, m, nc, ang, cost, &tp[1], &o, &r2, err)))
		goto out;
	r->nbright = s[np - 1].nbright;
	if (both) {
		r->part[0] = r->value;
		r->part[1] = r2.value;
		r->per[r->nper++] = r2.value;
		memcpy(r->where, r2.where, sizeof r->where);
		r->value = combined_value(t, r->part[0], r->part[1]);
		r->met = r->value <= 1;
	}
	r->picks = calloc(s[0].batch ? s[0].batch : 1, sizeof *r->picks);
	if (!r->picks) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	size_t J = s[0].J;
	if (o.route && (!o.route->pos || !o.route->base || !o.route->open ||
			(o.route->nnodes && (!o.route->nodes || !o.route->point || !o.route->dark || !o.route->rungs ||
					     !o.route->since || !o.route->band_cos)))) {
		acq_errf(err, ACQ_E_INVAL, "select: a route needs the candidates' positions, base and open costs (with band "
				"nodes: point, dark, rungs, since, band_cos)");
		goto out;
	}
	if (o.route && sel_route_init(&route, o.route, s[0].batch)) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	/* each part's criterion with candidate j measured, for every j at once (o.reference: one sel_excess per j) */
	ex = malloc(2 * (J ? J : 1) * sizeof *ex);
	acc = malloc((J ? J : 1) * sizeof *acc);
	if (!ex || !acc) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	double E[2], E0[2], value = r->value, thr = both ? 1.0 : t->threshold;
	for (size_t k = 0; k < np; k++)
		E[k] = E0[k] = sel_excess(&s[k], SIZE_MAX, NULL);
	while (r->npicks < s[0].batch && !(isfinite(thr) && value <= thr)) {
		size_t best = SIZE_MAX, bat = 0;
		double bscore = 0, bgain = 0, bcost = 0;
		for (size_t k = 0; k < np && !o.reference; k++)
			sel_excess_all(&s[k], ex + k * J, acc);
		for (size_t j = 0; j < J; j++) {
			if (s[0].picked[j])
				continue;
			double gain = 0;
			bool any = false;
			for (size_t k = 0; k < np; k++) {
				double g = E[k] - (o.reference ? sel_excess(&s[k], j, NULL) : ex[k * J + j]);
				any |= g > 1e-12 * E0[k];
				gain += both ? (E0[k] > 0 ? g / E0[k] : 0) : g;
			}
			if (!any || !(gain > 0))
				continue;
			size_t at = 0;
			double c = o.route ? sel_route_cost(&route, s[0].rep[j], &at) : s[0].cost[j], score = gain / c;
			if (score > bscore) {
				best = j;
				bscore = score;
				bgain = gain;
				bcost = c;
				bat = at;
			}
		}
		if (best == SIZE_MAX)
			break; /* nothing left reduces the target */
		struct select_pick *pk = &r->picks[r->npicks];
		if (o.reference) {
			for (size_t k = 0; k < np; k++)
				sel_update(&s[k], best, r->npicks);
		} else { /* the parts share the candidates' posterior: its row once, each part's target, then it */
			double S = sel_update_row(&s[0], best, r->npicks);
			for (size_t k = 0; k < np; k++)
				sel_update_target(&s[k], best, r->npicks, S);
			sel_update_cands(&s[0], best, r->npicks, S);
		}
		r->npicks++;
		pk->index = s[0].rep[best];
		pk->gain = bgain;
		pk->gain_per_s = bscore;
		pk->cost = bcost;
		if (o.route)
			sel_route_add(&route, pk->index, bat);
		E[0] = sel_excess(&s[0], SIZE_MAX, pk->predicted_per);
		/* the predicted value: the GP part updated, the other parts as they are (DHR: the largest incidence) */
		value = 0;
		for (size_t i = 0; i < (both ? r->nper - 1 : r->nper); i++)
			value = fmax(value, pk->predicted_per[i]);
		if (both) {
			double lp;
			E[1] = sel_excess(&s[1], SIZE_MAX, &lp);
			pk->predicted_per[r->nper - 1] = lp;
			value = combined_value(t, value, lp);
		}
		pk->predicted = value;
	}
	rc = 0;
out:
	free(ex);
	free(acc);
	sel_route_free(&route);
	if (rc)
		select_result_free(r);
	for (size_t k = 0; k < np; k++)
		sel_free(&s[k]);
	return rc;
}

/* The route's per-candidate arrays of the kept candidates idx[k] (k < nk) into one block b (laid out as the
 * select_route's), out's pointers into it. */
static void route_keep(const struct select_route *in, const size_t *idx, size_t nk, double *b, struct select_route *out)
{
	*out = *in;
	const double *col[7] = { in->base, in->open, in->point, in->dark, in->rungs, in->since, in->band_cos };
	const double **dst[7] = { &out->base, &out->open, &out->point, &out->dark, &out->rungs, &out->since,
				  &out->band_cos };
	for (size_t k = 0; k < nk; k++)
		for (int a = 0; a < 3; a++)
			b[3 * k + a] = in->pos[3 * idx[k] + a];
	out->pos = b;
	b += 3 * nk;
	for (int c = 0; c < 7; c++) {
		if (!col[c])
			continue; /* without band nodes */
		for (size_t k = 0; k < nk; k++)
			b[k] = col[c][idx[k]];
		*dst[c] = b;
		b += nk;
	}
}

int select_batch(const struct recon_model *m, size_t nc, const double *ang, const double *cost,
		 const struct select_target *t, const struct select_opts *opts, struct select_result *r, struct acq_err *err)
{
	if (!t || !(t->lobe_above_deg > 0) || !m || !ang || !cost)
		return select_set(m, nc, ang, cost, t, opts, NULL, r, err);
	memset(r, 0, sizeof *r);
	unsigned char *keep = malloc(nc ? nc : 1);
	size_t nb = 0, na = 0, nk = 0;
	if (!keep)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	struct sel_gp gp = { 0 }; /* the gate's factorisation, taken over by select_set's (one factorisation a call) */
	if (sel_lobe_gate(m, t->lobe_above_deg * M_PI / 180, nc, ang, keep, &nb, &na, &gp, err)) {
		free(keep);
		return -1;
	}
	struct select_target tk = *t;
	tk.lobe_above_deg = 0;
	int rc;
	if (nb == na) { /* nothing left out: the candidates as given */
		free(keep);
		rc = select_set(m, nc, ang, cost, &tk, opts, &gp, r, err);
		sel_gp_free(&gp);
		r->nbeyond = nb;
		r->nadmitted = na;
		return rc;
	}
	const struct select_route *ro = opts ? opts->route : NULL;
	size_t *idx = malloc((nc ? nc : 1) * sizeof *idx);
	double *ak = malloc((nc ? nc : 1) * 4 * sizeof *ak), *ck = malloc((nc ? nc : 1) * sizeof *ck);
	double *rb = ro && ro->pos && ro->base && ro->open ? malloc((nc ? nc : 1) * 10 * sizeof *rb) : NULL;
	if (!idx || !ak || !ck || (ro && ro->pos && ro->base && ro->open && !rb)) {
		rc = acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	for (size_t j = 0; j < nc; j++)
		if (keep[j]) {
			memcpy(ak + 4 * nk, ang + 4 * j, 4 * sizeof *ak);
			ck[nk] = cost[j];
			idx[nk++] = j;
		}
	struct select_opts ok;
	if (opts)
		ok = *opts;
	else
		select_opts_default(&ok);
	struct select_route rk;
	if (rb) {
		route_keep(ro, idx, nk, rb, &rk);
		ok.route = &rk;
	}
	rc = select_set(m, nk, ak, ck, &tk, &ok, &gp, r, err);
	for (size_t i = 0; rc == 0 && i < r->npicks; i++) /* back to the caller's candidates */
		r->picks[i].index = idx[r->picks[i].index];
	r->nbeyond = nb;
	r->nadmitted = na;
out:
	sel_gp_free(&gp);
	free(keep);
	free(idx);
	free(ak);
	free(ck);
	free(rb);
	return rc;
}
