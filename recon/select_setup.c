/* select_setup: the targets' set-ups of a selection: the DHR's σ and its functionals at its fixed rule, the ln f
 * grid's and the RGB table's point variances, each with its covariances with the candidates. */
#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/bigbuf.h"
#include "recon/colour.h"
#include "recon/merl.h"
#include "recon/recon_int.h"
#include "recon/select_int.h"

/* Z[f, j] = cov(φ_f, g(x_j)) − ... for functionals given by coefficients C[q*F' + f] over points c6[Q] (the
 * amplitude folded in): Z = Cᵀ K_QJ − (A⁻¹ K_nQ C)ᵀ K_nJ, rows f0..f0+F'-1 of s->Z (scratch soaQ[6Q],
 * KJQ[SEL_JB*Q]). */
static int sel_functionals(struct sel *s, size_t Q, const double *c6, const double *KQn, const double *C, size_t Fp,
			   size_t f0, double *soaQ, double *KJQ, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, J = s->J;
	double *B = malloc(Fp * n * sizeof *B); /* row-major F' × n = column-major n × F' */
	if (!B)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	cblas_dgemm(CblasRowMajor, CblasTrans, CblasNoTrans, (int)Fp, (int)n, (int)Q, 1.0, C, (int)Fp, KQn, (int)n, 0.0,
		    B, (int)n);
	if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)Fp, s->A, (lapack_int)n, B, (lapack_int)n)) {
		free(B);
		return acq_errf(err, ACQ_E_NUMERIC, "select: solve failed");
	}
	if (s->X) { /* the noise variance of the functionals and its cross terms with the candidates' weights */
		double *BN = malloc(Fp * n * sizeof *BN);
		if (!BN) {
			free(B);
			return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		}
		for (size_t f = 0; f < Fp; f++) {
			double qq = 0;
			for (size_t k = 0; k < n; k++) {
				BN[f * n + k] = s->Nk[k] * B[f * n + k];
				qq += BN[f * n + k] * B[f * n + k];
			}
			s->q[f0 + f] = s->q0[f0 + f] = s->qmin[f0 + f] = qq;
		}
		if (J)
			cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)Fp, (int)J, (int)n, 1.0, BN, (int)n, s->G,
				    (int)n, 0.0, s->X + f0 * J, (int)J);
		free(BN);
	}
	double *Z = s->Z + f0 * J;
	/* Cᵀ K_QJ by blocks of SEL_JB candidates (their kernel rows against the nodes, K symmetric to the bit): a block
	 * stays in cache and the whole Q × J matrix (25 MB at 2000 candidates) is never written */
	rbf_soa(Q, c6, soaQ);
	for (size_t j0 = 0; j0 < J; j0 += SEL_JB) {
		size_t jb = J - j0 < SEL_JB ? J - j0 : SEL_JB;
		rbf_kmatrix_soa(m->kernel, m->shape, jb, s->cu + 6 * j0, Q, soaQ, KJQ);
		cblas_dgemm(CblasRowMajor, CblasTrans, CblasTrans, (int)Fp, (int)jb, (int)Q, 1.0, C, (int)Fp, KJQ, (int)Q,
			    0.0, Z + j0, (int)J);
	}
	cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)Fp, (int)J, (int)n, -1.0, B, (int)n, s->Kjn, (int)n,
		    1.0, Z, (int)J);
	free(B);
	return 0;
}

/* The DHR's fixed rule at incidence th: its nodes c6[Q*6], weights wt[Q] and kernel rows KQn[Q*n] against the
 * model's centres (what recon_dhr_parts takes as its parts.kq). 0, or -1 with err. */
static int sel_dhr_rows(const struct recon_model *m, double th, double *c6, double *wt, double *KQn,
			struct acq_err *err)
{
	if (recon_hemi_nodes(th, SEL_NMU, SEL_NPHI, 0, c6, wt))
		return acq_errf(err, ACQ_E_INVAL, "select: quadrature");
	rbf_kmatrix_soa(m->kernel, m->shape, (size_t)SEL_NMU * SEL_NPHI, c6, m->n, m->soa, KQn);
	return 0;
}

/* sel_dhr_coef's coefficients C from the rule's nodes c6, weights wt and rows KQn (sel_dhr_rows). */
static void sel_dhr_coef_rows(const struct sel *s, const double *c6, const double *wt, const double *KQn, double *Y,
			      double *Wc, double *C)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, Lc = s->Lc, Q = (size_t)SEL_NMU * SEL_NPHI;
	for (size_t c = 0; c < Lc; c++)
		memcpy(Wc + c * n, m->w + s->chan[c] * n, n * sizeof *Wc);
	cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)Q, (int)Lc, (int)n, 1.0, KQn, (int)n, Wc, (int)n, 0.0,
		    Y, (int)Lc);
	for (size_t q = 0; q < Q; q++) {
		const double *c = c6 + 6 * q;
		double b[TREND_NB], u = recon_unseen(recon_nearest_centre(m, c, NULL));
		trend_at(m, c, b);
		for (size_t k = 0; k < Lc; k++) {
			size_t l = s->chan[k];
			double sc = recon_energy_scale(m, theta_of(c), theta_of(c + 3), l) * wt[q];
			C[q * Lc + k] = sc * untransform_deriv(m->transform, Y[q * Lc + k] + m->mu[l], m->eps[l],
							      trend_factor(m, b, l)) *
					sqrt(s->alpha[l] + u * RECON_PRIOR_ALPHA);
		}
	}
}

/* The DHR functional at incidence th on the tracked channels: the fixed rule's nodes c6[Q*6] and weights wt[Q],
 * the kernel rows KQn[Q*n], and C[q*Lc + c] = weight × energy factor × df̂/dg at the model × √(α_λ + unseen
 * prior), as dhr.c's σ_model (scratch Y[Q*Lc], Wc[Lc*n]). */
int sel_dhr_coef(const struct sel *s, double th, double *c6, double *wt, double *KQn, double *Y, double *Wc,
		 double *C, struct acq_err *err)
{
	if (sel_dhr_rows(s->m, th, c6, wt, KQn, err))
		return -1;
	sel_dhr_coef_rows(s, c6, wt, KQn, Y, Wc, C);
	return 0;
}

/* A view of m on its channels ch[0..k-1] only (the per-channel arrays copied, the directions and the factor's inputs
 * shared): what recon_dhr_parts needs for the value on a channel subset. sub_free releases what it allocated. */
static int sub_model(const struct recon_model *m, const size_t *ch, size_t k, struct recon_model *sub,
		     struct acq_err *err)
{
	size_t n = m->n, nt = m->ntab > 1 ? m->ntab - 1 : 0;
	*sub = *m;
	sub->whole = m->whole ? m->whole : m;
	sub->nwl = k;
	sub->wl = malloc(k * sizeof *sub->wl);
	sub->eps = malloc(k * sizeof *sub->eps);
	sub->mu = malloc(k * sizeof *sub->mu);
	sub->w = malloc(k * n * sizeof *sub->w);
	sub->g = m->g ? malloc(k * n * sizeof *sub->g) : NULL;
	sub->gsig = m->gsig ? malloc(k * n * sizeof *sub->gsig) : NULL;
	sub->tcoef = m->tcoef ? malloc(k * TREND_NB * sizeof *sub->tcoef) : NULL;
	sub->tab_alb = m->tab_alb && nt ? malloc(nt * k * sizeof *sub->tab_alb) : NULL;
	if (!sub->wl || !sub->eps || !sub->mu || !sub->w || (m->g && !sub->g) || (m->gsig && !sub->gsig) ||
	    (m->tcoef && !sub->tcoef) || (m->tab_alb && nt && !sub->tab_alb))
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	for (size_t j = 0; j < k; j++) {
		size_t l = ch[j];
		sub->wl[j] = m->wl[l];
		sub->eps[j] = m->eps[l];
		sub->mu[j] = m->mu[l];
		memcpy(sub->w + j * n, m->w + l * n, n * sizeof *sub->w);
		if (sub->g)
			memcpy(sub->g + j * n, m->g + l * n, n * sizeof *sub->g);
		if (sub->gsig)
			memcpy(sub->gsig + j * n, m->gsig + l * n, n * sizeof *sub->gsig);
		if (sub->tcoef)
			memcpy(sub->tcoef + j * TREND_NB, m->tcoef + l * TREND_NB, TREND_NB * sizeof *sub->tcoef);
		for (size_t t = 0; sub->tab_alb && t < nt; t++)
			sub->tab_alb[t * k + j] = m->tab_alb[t * m->nwl + l];
	}
	return 0;
}

static void sub_free(struct recon_model *sub)
{
	free(sub->wl);
	free(sub->eps);
	free(sub->mu);
	free(sub->w);
	free(sub->g);
	free(sub->gsig);
	free(sub->tcoef);
	free(sub->tab_alb);
}

/* The mean of x[0..n-1]²: an incidence's σ² over its channels (n > 0). */
static double mean_sq(const double *x, size_t n)
{
	double a = 0;
	for (size_t l = 0; l < n; l++)
		a += x[l] * x[l];
	return a / (double)n;
}

/* The DHR value on all channels (the value channels' screening said it is near the threshold; kq: the fixed rule's
 * kernel rows, or NULL): r->per and the value recomputed, each incidence's κ rescaled so predictions aim at the same value; r->value_checked set. 0 or -1. */
static int sel_value_all(struct sel *s, const double *th, const double *kq, const struct select_opts *o,
			 struct select_result *r, struct acq_err *err)
{
	size_t L = s->L, nth = s->nth, NL = nth * L;
	double *dhr = malloc(NL * sizeof *dhr), *sig = malloc(NL * sizeof *sig);
	int rc = -1;
	if (!dhr || !sig) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	struct recon_dhr_parts parts = { .kq = kq };
	if (kq) { /* the fast path lends the factor too */
		parts.gp_A = s->A;
		parts.gp_Ainv = s->Ainv;
	}
	if (recon_dhr_parts(s->m, nth, th, o->ndraws, o->seed, dhr, sig, &parts, NULL, NULL, err))
		goto out;
	r->value = 0;
	for (size_t t = 0; t < nth; t++) {
		double all = mean_sq(sig + t * L, L);
		double sub = r->per[t] * r->per[t];
		if (sub > 0)
			s->kappa[t] *= all / sub;
		r->per[t] = sqrt(all);
		r->value = fmax(r->value, r->per[t]);
	}
	r->value_checked = 1;
	rc = 0;
out:
	free(dhr);
	free(sig);
	return rc;
}

/* The DHR target: the model's σ and its parts (recon_dhr_parts) at every channel, or on the value channels
 * s->vchan only (a sub-model of those channels: the same computation per channel, at LV/L of the cost, the noise
 * part's Monte-Carlo draws then other draws), and the GP functionals on the tracked channels: c_q = weight × energy
 * factor × df̂/dg × √(α_λ + unseen prior) at the DHR's fixed rule. The rule's kernel rows are built once, here, and
 * lent to recon_dhr_parts with the model's factor and inverse (sel_factor's: they do not depend on the channels, so
 * they serve the sub-model too); o->reference: it builds its own, as before. */
int sel_setup_dhr(struct sel *s, const struct select_opts *o, struct select_result *r, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, L = s->LV, nth = s->nth, Lc = s->Lc, J = s->J, Q = (size_t)SEL_NMU * SEL_NPHI;
	struct recon_model sub = { 0 };
	if (s->vchan && sub_model(m, s->vchan, s->LV, &sub, err)) {
		sub_free(&sub);
		return -1;
	}
	double th[SELECT_MAX_THETA];
	for (size_t t = 0; t < nth; t++)
		th[t] = s->t->theta_deg[t] * M_PI / 180;
	size_t NL = nth * L;
	double *dhr = malloc(NL * sizeof *dhr), *sig = malloc(NL * sizeof *sig), *sn = malloc(NL * sizeof *sn);
	double *sm = malloc(NL * sizeof *sm), *sres = malloc(NL * sizeof *sres);
	double *sk = malloc(NL * sizeof *sk), *se = malloc(NL * sizeof *se);
	double *c6 = malloc(nth * Q * 6 * sizeof *c6), *wt = malloc(Q * sizeof *wt);
	double *KQn = recon_big_alloc(nth * Q * n * sizeof *KQn);
	double *Y = malloc(Q * Lc * sizeof *Y), *C = malloc(Q * Lc * sizeof *C), *Wc = malloc(Lc * n * sizeof *Wc);
	double *KJQ = malloc(Q * SEL_JB * sizeof *KJQ), *soaQ = malloc(Q * 6 * sizeof *soaQ);
	int rc = -1;
	if (!dhr || !sig || !sn || !sm || !sres || !sk || !se || !c6 || !wt || !KQn || !Y || !C || !Wc || !KJQ || !soaQ) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	for (size_t t = 0; t < nth; t++) /* the rule's weights are the same at every incidence */
		if (sel_dhr_rows(m, th[t], c6 + t * Q * 6, wt, KQn + t * Q * n, err))
			goto out;
	const double *kq = o->reference ? NULL : KQn;
	struct recon_dhr_parts parts = { .noise = sn, .model = sm, .res = sres, .kriging = sk, .energy = se, .kq = kq,
					 .gp_A = kq ? s->A : NULL, .gp_Ainv = kq ? s->Ainv : NULL };
	if (recon_dhr_parts(s->vchan ? &sub : m, nth, th, o->ndraws, o->seed, dhr, sig, &parts, NULL, NULL, err))
		goto out;
	r->value = 0;
	for (size_t t = 0; t < nth; t++) {
		double all = mean_sq(sig + t * L, L), part = 0;
		for (size_t c = 0; c < Lc; c++) {
			size_t i = t * L + s->cpos[c], f = t * Lc + c;
			double b = fmax(sn[i], sm[i]);
			part += sig[i] * sig[i];
			s->sn2[f] = sn[i] * sn[i];
			s->v[f] = sk[i] * sk[i]; /* the GP part: σ_E (sel_prior_e2) follows the picks apart */
			s->res2[f] = sres[i] * sres[i];
			s->rest[f] = fmax(sig[i] * sig[i] - b * b, 0);
		}
		part /= (double)Lc;
		s->kappa[t] = part > 0 ? all / part : 1.0;
		r->per[t] = sqrt(all);
		r->value = fmax(r->value, r->per[t]);
	}
	r->nper = nth;
	r->nvalue = L;
	if (sel_prior_init(s, th, se, L, err))
		goto out;
	if (s->vchan && isfinite(s->t->threshold) && r->value <= SEL_VALUE_CHECK * s->t->threshold &&
	    sel_value_all(s, th, kq, o, r, err))
		goto out;
	for (size_t t = 0; t < nth; t++) {
		sel_dhr_coef_rows(s, c6 + t * Q * 6, wt, KQn + t * Q * n, Y, Wc, C);
		if (J && sel_functionals(s, Q, c6 + t * Q * 6, KQn + t * Q * n, C, Lc, t * Lc, soaQ, KJQ, err))
			goto out;
	}
	rc = 0;
out:
	sub_free(&sub);
	free(dhr);
	free(sig);
	free(sn);
	free(sm);
	free(sres);
	free(sk);
	free(se);
	free(c6);
	free(wt);
	free(KQn);
	free(Y);
	free(C);
	free(Wc);
	free(KJQ);
	free(soaQ);
	return rc;
}

/* The ln f grid: θi ≤ θo in {0, 10, …, 80°} × Δφ in {0, 20, …, 180°} (one azimuth at θi = 0). */
/* ∫ sinθ cosθ dθ over [a, b] (radians): a θ cell's share of the projected solid angle. */
static double proj_band(double a, double b)
{
	return 0.5 * (sin(b) * sin(b) - sin(a) * sin(a));
}

/* ∫ sinθ dθ over [a, b]: a θ cell's share of the solid angle. */
static double solid_band(double a, double b)
{
	return cos(a) - cos(b);
}

/* sel_lnf_grid with the cells' shares of the projected measure (projected = 1) or of dωi dωo (0); norm = 0: the
 * cells' measures themselves (not divided by their sum). */
static size_t lnf_grid(double *ang, double *w, int projected, int norm)
{
	size_t F = 0;
	double sum = 0, h = 0.5 * LNF_TSTEP * M_PI / 180, tmax = LNF_TMAX * M_PI / 180, dp = LNF_PSTEP * M_PI / 180;
	double (*band)(double, double) = projected ? proj_band : solid_band;
	for (int ti = 0; ti <= LNF_TMAX; ti += LNF_TSTEP)
		for (int to = ti; to <= LNF_TMAX; to += LNF_TSTEP)
			for (int p = 0; p <= 180; p += LNF_PSTEP) {
				if (ti == 0 && p > 0)
					break;
				double a = ti * M_PI / 180, b = to * M_PI / 180;
				if (ang) {
					ang[4 * F] = a;
					ang[4 * F + 1] = 0;
					ang[4 * F + 2] = b;
					ang[4 * F + 3] = p * M_PI / 180;
				}
				/* the node's cell: θ ± half a step within [0, LNF_TMAX], φ ± half a step within [0, π] (the
				 * whole φ range at θi = 0, where φ is moot), × 2 off the diagonal (the reciprocal pair) */
				double wi = band(fmax(a - h, 0), fmin(a + h, tmax)), wo = band(fmax(b - h, 0), fmin(b + h, tmax));
				double wp = ti == 0 ? M_PI : (p == 0 || p == 180 ? 0.5 * dp : dp);
				double x = wi * wo * wp * (to > ti ? 2 : 1);
				if (w)
					w[F] = x;
				sum += x;
				F++;
			}
	for (size_t x = 0; w && norm && x < F; x++)
		w[x] /= sum;
	return F;
}

size_t sel_lnf_grid(double *ang, double *w)
{
	return lnf_grid(ang, w, 1, 1);
}

/*
 * The "lnf:rad" criterion's weights: grid point x's variance v[x] = amp[x]² P(x, x) of g weighs
 *   w[x] = ω_x · mean_λ (d_λ(x) c / (1 + f̂_λ(x) c))² / amp[x]²,   c = cosθi cosθo,
 * ω_x its cell's share of dωi dωo, d_λ = energy factor · df̂/dg · √(α_λ + unseen prior) (f̂'s σ per unit P, as the RGB
 * target's), so that w[x] v[x] is the expected squared error of log(1 + f̂ c) over the cell: the held-out log-RMSE of
 * the time-to-accuracy study (bench_tradeoff.log_rmse: directions uniform in solid angle, mean over wavelengths). Under
 * the projected measure alone (the default) a grazing pair weighs 1/c more than in that error, and a bright region
 * (the backscatter peak, the red half of a red material) no more than a dark one. Normalised to sum 1.
 *
 * "lnf:bright" (SELECT_LNF_BRIGHT, session 16): per cell the larger of the two, in the same unit (a squared error of g per
 * unit P, integrated over the cell's dωi dωo): w[x] = max(∫cell cosθi cosθo dωi dωo, ω_x r[x]), r[x] = the mean above
 * over amp². With g = ln f (df̂/dg ≈ f̂) r ≈ (f̂c / (1 + f̂c))², which exceeds c only where f̂c/(1 + f̂c) > √c, i.e.
 * f̂ ≳ 4–5 sr⁻¹ at any pair (c = 0.07 … 0.5; never at the normal, where r < 1 = c): the model's own lobe. There the
 * study's error (the relative error of f̂, independent of c) replaces the projected weight c, which underweighs the
 * grazing mirror band by 1/c (≈ 14 at 75°/75°); a dim material (f̂ ≲ 1, r/c = f̂² c) keeps the projected weights
 * exactly. Normalised to sum 1.
 */
/* lnf:rad's mean over the channels of (d_λ c / (1 + f̂_λ c))² at canonical point c (above; y[L] the interpolant
 * without its mean there, alpha[L] the channels' GP amplitudes): its weight per unit dωi dωo times amp². */
static double rad_unit(const struct recon_model *m, const double *alpha, const double *c, const double *y)
{
	size_t L = (size_t)m->nwl;
	double b[TREND_NB], u = recon_unseen(recon_nearest_centre(m, c, NULL)), cc = c[2] * c[5], acc = 0;
	trend_at(m, c, b);
	for (size_t l = 0; l < L; l++) {
		double g = y[l] + m->mu[l], tf = trend_factor(m, b, l);
		double sc = recon_energy_scale(m, theta_of(c), theta_of(c + 3), l);
		double f = sc * untransform(m->transform, g, m->eps[l], tf);
		double d = sc * untransform_deriv(m->transform, g, m->eps[l], tf) * sqrt(alpha[l] + u * RECON_PRIOR_ALPHA);
		double e = d * cc / (1 + f * cc);
		acc += e * e;
	}
	return acc / (double)L;
}

static int lnf_rad_weights(struct sel *s, const double *c6, const double *amp, const double *KXn, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, L = s->L, F = s->F;
	double *Y = malloc(F * L * sizeof *Y), *pw = NULL;
	int rc = -1;
	if (!Y) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	lnf_grid(NULL, s->xw, 0, 0);
	if (s->t->lnf_rad == SELECT_LNF_BRIGHT && !(pw = malloc(F * sizeof *pw))) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	if (pw)
		lnf_grid(NULL, pw, 1, 0);
	/* the interpolant (without its mean) at the grid points, every channel; KXn = K(c6, centres) */
	cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)F, (int)L, (int)n, 1.0, KXn, (int)n, m->w, (int)n, 0.0,
		    Y, (int)L);
	double sum = 0;
	for (size_t x = 0; x < F; x++) {
		double a2 = amp[x] * amp[x], wx = a2 > 0 ? s->xw[x] * rad_unit(m, s->alpha, c6 + 6 * x, Y + x * L) / a2 : 0;
		s->xw[x] = isfinite(wx) ? wx : 0;
		if (pw && pw[x] > s->xw[x]) /* lnf:bright: the larger of the two errors per unit dωi dωo */
			s->xw[x] = pw[x];
		else if (pw)
			s->nbright++;
		sum += s->xw[x];
	}
	if (!(sum > 0))
		lnf_grid(NULL, s->xw, 1, 1); /* nothing to weigh: the projected measure */
	else
		for (size_t x = 0; x < F; x++)
			s->xw[x] /= sum;
	rc = 0;
out:
	free(Y);
	free(pw);
	return rc;
}

/*
 * The lobe gate (select_target.lobe_above_deg, session 17): a candidate of incidence θi above the bound is kept only
 * where lnf:bright's rule gives the model's own lobe at the candidate's pair itself, i.e. where lnf:rad's weight per
 * unit dωi dωo, r = mean_λ (d_λ c/(1 + f̂_λ c))²/amp², exceeds the projected measure's, c = cosθi cosθo (the two
 * weights lnf:bright compares per cell; amp as the ln f target's). No threshold of its own: for g = ln f r ≈
 * (f̂c/(1 + f̂c))², above c only where f̂ ≳ 4–5 sr⁻¹ (c ≤ 0.07 at 75°/75°: f̂ ≳ 5). A dim model keeps none.
 */
int sel_lobe_gate(const struct recon_model *m, double above, size_t nc, const double *ang, unsigned char *keep,
		  size_t *nbeyond, size_t *nadmit, struct sel_gp *gp, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl, nb = 0;
	*nbeyond = *nadmit = 0;
	for (size_t j = 0; j < nc; j++) {
		keep[j] = !(ang[4 * j] > above);
		nb += !keep[j];
	}
	if (!nb)
		return 0;
	size_t *idx = malloc(nb * sizeof *idx);
	double *A = recon_big_alloc(n * n * sizeof *A), *Ainv = recon_big_alloc(n * n * sizeof *Ainv);
	double *alpha = calloc(L, sizeof *alpha), *c6 = malloc(nb * 6 * sizeof *c6), *K = malloc(nb * n * sizeof *K);
	double *Y = malloc(nb * L * sizeof *Y);
	int rc = -1;
	if (!idx || !A || !Ainv || !alpha || !c6 || !K || !Y) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	if (recon_gp_setup(m, "select", A, Ainv, alpha, err))
		goto out;
	double abar = 0;
	for (size_t l = 0; l < L; l++)
		abar += alpha[l] / (double)L;
	for (size_t j = 0, k = 0; j < nc; j++)
		if (!keep[j]) {
			const double *a = ang + 4 * j;
			rbf_canon(a[0], a[1], a[2], a[3], c6 + 6 * k);
			idx[k++] = j;
		}
	rbf_kmatrix_soa(m->kernel, m->shape, nb, c6, n, m->soa, K);
	cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)nb, (int)L, (int)n, 1.0, K, (int)n, m->w, (int)n, 0.0,
		    Y, (int)L);
	for (size_t k = 0; k < nb; k++) {
		const double *c = c6 + 6 * k;
		double a2 = abar + recon_unseen(recon_nearest_centre(m, c, NULL)) * RECON_PRIOR_ALPHA;
		double r = a2 > 0 ? rad_unit(m, alpha, c, Y + k * L) / a2 : 0;
		if (isfinite(r) && r > c[2] * c[5]) {
			keep[idx[k]] = 1;
			(*nadmit)++;
		}
	}
	*nbeyond = nb;
	rc = 0;
	if (gp) { /* the selection that follows factors the same model: it takes this one */
		*gp = (struct sel_gp){ A, Ainv, alpha };
		A = Ainv = alpha = NULL;
	}
out:
	free(idx);
	free(A);
	free(Ainv);
	free(alpha);
	free(c6);
	free(K);
	free(Y);
	return rc;
}

/*
 * The "lnf:mix" criterion's weights (session 16): each measure's weights over its own criterion before the picks,
 *   w[x] ∝ wp[x] / Ep + wr[x] / Er,   E = Σ w[x] max(v[x] − X², 0),
 * wp the projected measure's shares, wr lnf:rad's (wr[F], normalised), so that a pick's gain is the sum of its
 * relative reductions of both criteria (as a combined target's parts): the coat's grazing mirror band, bright, draws
 * picks as under lnf:rad, while a dim material keeps the projected measure's spread. Either criterion 0: the other's.
 * Normalised to sum 1. s->v must hold the variances.
 */
static void lnf_mix_weights(struct sel *s, const double *wr)
{
	size_t F = s->F;
	double Ep = 0, Er = 0, sum = 0;
	lnf_grid(NULL, s->xw, 1, 1);
	for (size_t x = 0; x < F; x++) {
		double e = fmax(s->v[x] - s->thr2, 0);
		Ep += s->xw[x] * e;
		Er += wr[x] * e;
	}
	for (size_t x = 0; x < F; x++) {
		double w = (Ep > 0 ? s->xw[x] / Ep : 0) + (Er > 0 ? wr[x] / Er : 0);
		s->xw[x] = isfinite(w) ? w : 0;
		sum += s->xw[x];
	}
	if (sum > 0)
		for (size_t x = 0; x < F; x++)
			s->xw[x] /= sum;
	else
		lnf_grid(NULL, s->xw, 1, 1);
}

/* Point targets (ln f, RGB): the posterior variance v[x] = amp[x]² P(x, x) of g at the F points c6 (unit-amplitude
 * posterior P) and their covariances Z[x, j] = amp[x] P(x, candidate j) with the candidates. kxn: the kernel matrix
 * K(c6, centres) [F × n] when the caller has built it already, else NULL. */
static int sel_point_cov(struct sel *s, const double *c6, const double *amp, const double *kxn, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, F = s->F, J = s->J;
	double *own = kxn ? NULL : malloc(F * n * sizeof *own), *GX = malloc(F * n * sizeof *GX);
	int rc = -1;
	if ((!kxn && !own) || !GX) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	if (!kxn)
		rbf_kmatrix_soa(m->kernel, m->shape, F, c6, n, m->soa, own);
	const double *KXn = kxn ? kxn : own;
	if (recon_gp_postvar(m, s->A, F, c6, KXn, GX, s->v, "select", err))
		goto out;
	for (size_t x = 0; x < F; x++)
		s->v[x] *= amp[x] * amp[x];
	if (J) {
		rbf_kmatrix_soa(m->kernel, m->shape, F, c6, J, s->soaJ, s->Z);
		cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)F, (int)J, (int)n, -1.0, GX, (int)n, s->Kjn,
			    (int)n, 1.0, s->Z, (int)J);
		for (size_t x = 0; x < F; x++)
			cblas_dscal((int)J, amp[x], s->Z + x * J, 1);
	}
	rc = 0;
out:
	free(own);
	free(GX);
	return rc;
}

/* The ln f target: the posterior variance of g (RMS amplitude over the channels, unseen prior included) at the
 * grid's points, and their covariances with the candidates. */
int sel_setup_lnf(struct sel *s, struct select_result *r, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t F = s->F;
	double *c6 = calloc(F * 6, sizeof *c6), *amp = calloc(F, sizeof *amp); /* calloc: gcc's maybe-uninitialized */
	double *KXn = s->t->lnf_rad ? malloc(F * s->n * sizeof *KXn) : NULL; /* lnf:rad and the covariances share it */
	double *wr = NULL; /* lnf:mix: the rad weights */
	int rc = -1;
	if (!c6 || !amp || (s->t->lnf_rad && !KXn)) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	double abar = 0;
	for (size_t l = 0; l < s->L; l++)
		abar += s->alpha[l] / (double)s->L;
	for (size_t x = 0; x < F; x++) {
		const double *a = s->xang + 4 * x;
		rbf_canon(a[0], a[1], a[2], a[3], c6 + 6 * x);
		amp[x] = sqrt(abar + recon_unseen(recon_nearest_centre(m, c6 + 6 * x, NULL)) * RECON_PRIOR_ALPHA);
	}
	if (KXn) {
		rbf_kmatrix_soa(m->kernel, m->shape, F, c6, s->n, m->soa, KXn);
		if (lnf_rad_weights(s, c6, amp, KXn, err))
			goto out;
	}
	if (s->t->lnf_rad == SELECT_LNF_MIX && !(wr = malloc(F * sizeof *wr))) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	if (wr)
		memcpy(wr, s->xw, F * sizeof *wr);
	if (sel_point_cov(s, c6, amp, KXn, err))
		goto out;
	if (wr)
		lnf_mix_weights(s, wr);
	r->value = 0;
	for (size_t x = 0; x < F; x++)
		if (sqrt(s->v[x]) > r->value) {
			r->value = sqrt(s->v[x]);
			memcpy(r->where, s->xang + 4 * x, sizeof r->where);
		}
	r->per[0] = r->value;
	r->nper = 1;
	rc = 0;
out:
	free(c6);
	free(amp);
	free(KXn);
	free(wr);
	return rc;
}

/* The RGB target's nodes: MERL cells (iθh, iθd, iφd) = ((k + ½)·N/RGB_NODES) for k < RGB_NODES in each index, those
 * with both directions within LNF_TMAX (80°) of the normal, at the writer's cell centres (merl.h: beyond, no bench
 * reaches and the prior alone speaks, as for ln f; on green paint the grazing Fresnel cells θd > 80° held 97 % of
 * a 10 × 10 × 10 model's squared table error, a region no plan samples); ang[x*4] their pairs (θi, φi, θo,
 * φo) and w[x] the table's projected measure of the block the node stands for: the Rusinkiewicz Jacobian
 * dωi dωo = 4 cosθd sinθh sinθd dθh dθd dφd dφh (φh integrated out: isotropy), × dθh/diθh (θh is quadratic in its
 * index), × cosθi cosθo; normalised to sum 1. Either pointer may be NULL (count only). */
size_t sel_rgb_nodes(double *ang, double *w)
{
	size_t F = 0;
	const double zmin = cos(LNF_TMAX * M_PI / 180);
	double tot = 0;
	for (int a = 0; a < RGB_NODES; a++)
		for (int b = 0; b < RGB_NODES; b++)
			for (int c = 0; c < RGB_NODES; c++) {
				int ih = (int)((a + 0.5) * MERL_N_THETA_H / RGB_NODES);
				int id = (int)((b + 0.5) * MERL_N_THETA_D / RGB_NODES);
				int ip = (int)((c + 0.5) * MERL_N_PHI_D / RGB_NODES);
				double wi[3], wo[3], th, td, pd;
				if (merl_cell_dirs(ih, id, ip, wi, wo) != 1 || wi[2] <= zmin || wo[2] <= zmin)
					continue;
				merl_cell_angles(ih, id, ip, &th, &td, &pd);
				double dth = 2.0 * (ih + 0.5) / (MERL_N_THETA_H * MERL_N_THETA_H) * (M_PI / 2);
				double wx = 4 * cos(td) * sin(th) * sin(td) * dth * wi[2] * wo[2];
				if (ang) {
					ang[4 * F] = acos(fmin(1, wi[2]));
					ang[4 * F + 1] = atan2(wi[1], wi[0]);
					ang[4 * F + 2] = acos(fmin(1, wo[2]));
					ang[4 * F + 3] = atan2(wo[1], wo[0]);
				}
				if (w)
					w[F] = wx;
				tot += wx;
				F++;
			}
	if (w)
		for (size_t x = 0; x < F; x++)
			w[x] /= tot;
	return F;
}

/*
 * The RGB target: the σ of the linear-sRGB BRDF values (sr⁻¹) a MERL table of the model holds, through the outputs'
 * spectra → RGB chain (colour_opts_brdf: D65, Bradford, absolute, linear; colour_weights W[c, λ] at the model's
 * wavelengths), RMS over the three channels and over the table under its projected measure (sel_rgb_nodes). Under the
 * GP reading the error of channel λ at x is √(α_λ + unseen prior) · df̂/dg · energy factor · z(x); the errors of
 * one point are taken as fully correlated across wavelengths (one interpolation error of the shape, the GP's
 * common kernel: a missed lobe is missed at every wavelength), so RGB_c has the amplitude
 *   a_c(x) = |Σ_λ W[c, λ] · s_λ(x) · df̂/dg(x, λ) · √(α_λ + u(x)·prior)|
 * and the value is √(Σ_x w_x P(x, x) Σ_c a_c(x)²). (Independent channels would give a value ~√(visible channels)
 * smaller; test_recon_select checks the value against the error of models of a known truth.)
 */
int sel_setup_rgb(struct sel *s, struct select_result *r, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, L = s->L, F = s->F;
	double *W = malloc(3 * L * sizeof *W), *c6 = malloc(F * 6 * sizeof *c6), *amp = calloc(F, sizeof *amp);
	size_t *vis = malloc(L * sizeof *vis);
	double *Wv = NULL, *KXn = NULL, *Y = NULL;
	int rc = -1;
	if (!W || !c6 || !amp || !vis) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	struct colour_opts co;
	colour_opts_brdf(&co);
	if (colour_weights(&co, m->wl, L, W, err))
		goto out;
	size_t V = 0; /* the channels that carry colour weight */
	for (size_t l = 0; l < L; l++)
		if (W[l] != 0 || W[L + l] != 0 || W[2 * L + l] != 0)
			vis[V++] = l;
	Wv = malloc((V ? V : 1) * n * sizeof *Wv);
	KXn = malloc(F * n * sizeof *KXn);
	Y = malloc(F * (V ? V : 1) * sizeof *Y);
	if (!Wv || !KXn || !Y) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	for (size_t x = 0; x < F; x++) {
		const double *a = s->xang + 4 * x;
		rbf_canon(a[0], a[1], a[2], a[3], c6 + 6 * x);
	}
	if (V) { /* the interpolant (without its mean) at the nodes on the visible channels */
		for (size_t v = 0; v < V; v++)
			memcpy(Wv + v * n, m->w + vis[v] * n, n * sizeof *Wv);
		rbf_kmatrix_soa(m->kernel, m->shape, F, c6, n, m->soa, KXn);
		cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)F, (int)V, (int)n, 1.0, KXn, (int)n, Wv, (int)n,
			    0.0, Y, (int)V);
	}
	for (size_t x = 0; x < F; x++) {
		const double *c = c6 + 6 * x;
		double b[TREND_NB], u = recon_unseen(recon_nearest_centre(m, c, NULL)), ac[3] = { 0, 0, 0 };
		trend_at(m, c, b);
		for (size_t v = 0; v < V; v++) {
			size_t l = vis[v];
			double d = recon_energy_scale(m, theta_of(c), theta_of(c + 3), l) *
				   untransform_deriv(m->transform, Y[x * V + v] + m->mu[l], m->eps[l], trend_factor(m, b, l)) *
				   sqrt(s->alpha[l] + u * RECON_PRIOR_ALPHA);
			for (int k = 0; k < 3; k++)
				ac[k] += W[k * L + l] * d;
		}
		amp[x] = sqrt(ac[0] * ac[0] + ac[1] * ac[1] + ac[2] * ac[2]);
		if (!isfinite(amp[x]))
			amp[x] = 0;
		amp[x] *= sqrt(s->xw[x]); /* the measure folded in: v sums to the value² */
	}
	if (sel_point_cov(s, c6, amp, V ? KXn : NULL, err))
		goto out;
	double sum = 0;
	for (size_t x = 0; x < F; x++)
		sum += s->v[x];
	r->value = r->per[0] = sqrt(sum);
	r->nper = 1;
	rc = 0;
out:
	free(W);
	free(c6);
	free(amp);
	free(vis);
	free(Wv);
	free(KXn);
	free(Y);
	return rc;
}
