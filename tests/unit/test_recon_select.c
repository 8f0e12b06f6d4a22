/* Unit tests of the measurement selection (recon/select*.c, internals via select_int.h) on a small fitted model:
 *  - the rank-one (Schur complement) update: after 1-3 picks the tracked posterior variances equal a full
 *    refactorisation of the system with the picks appended (ln f points and the DHR functionals), to 1e-9 of the
 *    functional's prior variance; before any pick the DHR functional's variance equals dhr.c's σ_model²;
 *  - a candidate already in the data gains little, and is not chosen over one in a gap;
 *  - the cost weighting: a candidate made expensive enough loses to the second best;
 *  - reciprocity: a pair and its swap are one candidate with the same gain;
 *  - extremes: no candidates, duplicates, all costs equal, normal/grazing candidates; the threshold stops picking;
 *  - the RGB (MERL table) target: its value equals a direct computation (brute-force posterior, colour weights
 *    applied to the model's own evaluation), its rank-one update equals a refactorisation, and on models of a
 *    known truth (rt_truth) it is within a factor 3 of the table's actual output-weighted error;
 *  - the DHR value on a channel subset equals the RMS of recon_dhr's σ over those channels;
 *  - the target's specification parser;
 *  - the route increment: a candidate on the batch's route (at a pick's incidence, next to it) is chosen over an
 *    equally informative one the old rule (cost from the arms alone) prefers, and is charged exactly its increment;
 *  - the ln f criterion under the projected measure: the grid's weights, Σ w v, a mid-angle pick over a grazing one;
 *  - "lnf:rad": the same value and posterior, weights = the expected squared error of log(1 + f̂ cosθi cosθo) under
 *    dωi dωo (the study's held-out log-RMSE), equal to a direct computation through recon_eval;
 *  - the energy prior's σ_E after a pick at an unseen mirror direction (test_prior_after_pick, prior's);
 *  - the factor select lends recon_dhr_parts: the same σ as its own, a perturbed one seen (test_lent_factor). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>
#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon_test_util.h"
#include "recon/bigbuf.h"
#include "recon/colour.h"
#include "recon/recon_int.h"
#include "recon/select_int.h"

#define NWL 4

/* The model of smp fitted with o (NULL: the defaults); smp freed. */
static struct recon_model *fit_free(struct recon_samples *smp, const struct recon_fit_opts *o)
{
	struct recon_fit_opts d;
	if (!o) {
		recon_fit_opts_default(&d);
		o = &d;
	}
	struct recon_model *m = NULL;
	struct acq_err e = { 0 };
	assert_int_equal(recon_fit(smp, o, &m, &e), 0);
	csvio_samples_free(smp);
	return m;
}

static struct recon_model *toy_model(void)
{
	struct recon_samples s;
	rt_samples_grid(&s, 4, 4, 6, NWL, 0.01, 1.0);
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	o.smoothing = 1e-3; /* a moderate condition number, so that the brute force is itself accurate to ~1e-12 */
	return fit_free(&s, &o);
}

/* Random candidate pairs (degrees → radians inside), θ ≤ 75°. */
static void random_cands(size_t nc, double *ang, double *cost)
{
	for (size_t j = 0; j < nc; j++) {
		ang[4 * j] = acos(0.26 + 0.74 * rt_unif());
		ang[4 * j + 1] = 0;
		ang[4 * j + 2] = acos(0.26 + 0.74 * rt_unif());
		ang[4 * j + 3] = 2 * M_PI * rt_unif();
		cost[j] = 5 + 10 * rt_unif();
	}
}

static double kern(const struct recon_model *m, const double *a, const double *b)
{
	double tb[6];
	rbf_tau(b, tb);
	return rbf_kernel(m->kernel, m->shape, a, b, tb);
}

/* The extended system A' = [K + ηΛ, K_np; K_pn, K_pp + noise·I] over the centres and the picks' points, factored. */
static double *extended_factor(const struct sel *s, const size_t *picks, size_t k, double **pts)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, N = n + k;
	double *P = malloc(N * 6 * sizeof *P), *A = malloc(N * N * sizeof *A);
	memcpy(P, m->ctr, n * 6 * sizeof *P);
	for (size_t i = 0; i < k; i++)
		memcpy(P + 6 * (n + i), s->cu + 6 * picks[i], 6 * sizeof *P);
	for (size_t i = 0; i < N; i++)
		for (size_t j = 0; j < N; j++)
			A[j * N + i] = kern(m, P + 6 * i, P + 6 * j);
	for (size_t i = 0; i < N; i++)
		A[i * N + i] += i < n ? m->eta * m->lam[i] : s->noise;
	assert_int_equal(LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', (lapack_int)N, A, (lapack_int)N), 0);
	*pts = P;
	return A;
}

/* Posterior covariance φᵀ(K_QQ − K_QN A'⁻¹ K_NQ)φ of a functional φ[Q] over points c6[Q], by brute force. */
static double brute_var(const struct sel *s, const double *A, const double *P, size_t N, size_t Q, const double *c6,
			const double *phi, size_t stride)
{
	const struct recon_model *m = s->m;
	double *b = calloc(N ? N : 1, sizeof *b), prior = 0;
	for (size_t q = 0; q < Q; q++) {
		if (phi[q * stride] == 0)
			continue;
		for (size_t i = 0; i < N; i++)
			b[i] += kern(m, c6 + 6 * q, P + 6 * i) * phi[q * stride];
		for (size_t r = 0; r < Q; r++)
			if (phi[r * stride] != 0)
				prior += phi[q * stride] * kern(m, c6 + 6 * q, c6 + 6 * r) * phi[r * stride];
	}
	double *x = malloc((N ? N : 1) * sizeof *x);
	memcpy(x, b, N * sizeof *x);
	if (N) /* N = 0: the prior variance */
		assert_int_equal(LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)N, 1, A, (lapack_int)N, x, (lapack_int)N), 0);
	double v = prior;
	for (size_t i = 0; i < N; i++)
		v -= b[i] * x[i];
	free(b);
	free(x);
	return v;
}

/* The tests' common start: the seed from ACQ_SEED, the toy model and nc ≤ 64 random candidates (in that order, so
 * the draws are the ones each test made itself before). */
struct toy {
	struct recon_model *m;
	size_t nc;
	double ang[64 * 4], cost[64];
};

static struct recon_model *toy_start(struct toy *t, size_t nc)
{
	assert_true(nc <= 64);
	rt_seed();
	t->m = toy_model();
	t->nc = nc;
	random_cands(nc, t->ang, t->cost);
	return t->m;
}

/* A selection state with what it points to: struct sel keeps pointers to the target, the options and the result,
 * so the four live together. fix_spec parses the target and takes the default options (a test then changes what it
 * needs); fix_sel builds the state on the candidates; fix_free undoes both. */
struct fix {
	struct select_target t;
	struct select_opts o;
	struct select_result r;
	struct sel s;
	struct acq_err e;
};

static void fix_spec(struct fix *f, const char *spec)
{
	memset(f, 0, sizeof *f);
	assert_int_equal(select_target_parse(spec, &f->t, &f->e), 0);
	select_opts_default(&f->o);
}

static void fix_sel(struct fix *f, const struct recon_model *m, size_t nc, const double *ang, const double *cost)
{
	assert_int_equal(sel_init(&f->s, m, nc, ang, cost, &f->t, &f->o, &f->r, &f->e), 0);
}

static void fix_free(struct fix *f)
{
	sel_free(&f->s);
	select_result_free(&f->r);
}

/* The selection state on the candidates for spec with batch picks (fix_spec, the batch, fix_sel). */
static void fix_make(struct fix *f, const struct recon_model *m, size_t nc, const double *ang, const double *cost,
		     const char *spec, size_t batch)
{
	fix_spec(f, spec);
	f->o.batch = batch;
	fix_sel(f, m, nc, ang, cost);
}

/* toy_start's model and nc candidates, and f the selection of spec on them (batch). */
static struct recon_model *toy_fix(struct toy *ty, size_t nc, struct fix *f, const char *spec, size_t batch)
{
	struct recon_model *m = toy_start(ty, nc);
	fix_make(f, m, ty->nc, ty->ang, ty->cost, spec, batch);
	return m;
}

static void test_rank_one_lnf(void **state)
{
	(void)state;
	struct toy ty;
	struct fix f;
	struct recon_model *m = toy_fix(&ty, 60, &f, "lnf", 3);
	struct sel *s = &f.s;
	/* the amplitude² of each grid point: v / (prior posterior variance by brute force) */
	size_t F = s->F, picks[3] = { 0, 0, 0 };
	double *amp2 = malloc(F * sizeof *amp2), *c6 = malloc(F * 6 * sizeof *c6), *P, *A = extended_factor(s, picks, 0, &P);
	double one = 1;
	for (size_t x = 0; x < F; x++) {
		const double *a = s->xang + 4 * x;
		rbf_canon(a[0], a[1], a[2], a[3], c6 + 6 * x);
		double p0 = brute_var(s, A, P, s->n, 1, c6 + 6 * x, &one, 1);
		amp2[x] = s->v[x] / p0;
		assert_true(fabs(s->v[x] - amp2[x] * p0) <= 1e-12 * s->v[x]);
	}
	free(A);
	free(P);
	double worst = 0;
	for (size_t k = 0; k < 3; k++) {
		picks[k] = (k * 17 + 5) % s->J;
		sel_update(s, picks[k], k);
		A = extended_factor(s, picks, k + 1, &P);
		for (size_t x = 0; x < F; x++) {
			double bf = amp2[x] * brute_var(s, A, P, s->n + k + 1, 1, c6 + 6 * x, &one, 1);
			double prior = amp2[x] * kern(m, c6 + 6 * x, c6 + 6 * x);
			worst = fmax(worst, fabs(s->v[x] - bf) / prior);
		}
		free(A);
		free(P);
	}
	printf("ln f points: largest |rank-one − refactorisation| / prior variance = %.3g\n", worst);
	assert_true(worst <= 1e-9);
	free(amp2);
	free(c6);
	fix_free(&f);
	recon_model_free(m);
}

/* The DHR functional's coefficients at incidence th (degrees) on the tracked channels (sel_dhr_coef's arrays). */
struct dcoef {
	double *c6, *wt, *KQn, *Y, *Wc, *C;
};

static void dcoef_make(struct dcoef *d, const struct sel *s, double th, struct acq_err *e)
{
	size_t Q = (size_t)SEL_NMU * SEL_NPHI, Lc = s->Lc, n = s->n;
	d->c6 = malloc(Q * 6 * sizeof *d->c6);
	d->wt = malloc(Q * sizeof *d->wt);
	d->KQn = malloc(Q * n * sizeof *d->KQn);
	d->Y = malloc(Q * Lc * sizeof *d->Y);
	d->Wc = malloc(Lc * n * sizeof *d->Wc);
	d->C = malloc(Q * Lc * sizeof *d->C);
	assert_int_equal(sel_dhr_coef(s, th * M_PI / 180, d->c6, d->wt, d->KQn, d->Y, d->Wc, d->C, e), 0);
}

static void dcoef_free(struct dcoef *d)
{
	free(d->c6);
	free(d->wt);
	free(d->KQn);
	free(d->Y);
	free(d->Wc);
	free(d->C);
}

static void test_rank_one_dhr(void **state)
{
	(void)state;
	struct toy ty;
	struct fix f;
	struct recon_model *m = toy_fix(&ty, 40, &f, "dhr:30", 2);
	struct sel *s = &f.s;
	size_t Q = (size_t)SEL_NMU * SEL_NPHI, Lc = s->Lc, n = s->n;
	struct dcoef dc;
	dcoef_make(&dc, s, 30, &f.e);
	const double *c6 = dc.c6, *C = dc.C;
	size_t picks[2] = { 3, 11 }, np = 0;
	double worst = 0;
	for (;;) {
		double *P, *A = extended_factor(s, picks, np, &P);
		for (size_t c = 0; c < Lc; c++) {
			double bf = brute_var(s, A, P, n + np, Q, c6, C + c, Lc);
			double prior = brute_var(s, A, P, 0, Q, c6, C + c, Lc);
			double d = fabs(s->v[c] - bf) / prior;
			printf("  %zu picks, channel %zu: tracked %.10g, refactorised %.10g (prior %.4g)\n", np, s->chan[c], s->v[c],
			       bf, prior);
			worst = fmax(worst, d);
		}
		free(A);
		free(P);
		if (np == 2)
			break;
		sel_update(s, picks[np], np);
		np++;
	}
	printf("DHR functional: largest |tracked − refactorisation| / prior variance = %.3g (0 picks: dhr.c's σ_model²)\n",
	       worst);
	assert_true(worst <= 1e-9);
	dcoef_free(&dc);
	fix_free(&f);
	recon_model_free(m);
}

/* Gain of each candidate (criterion without → with it) on a fresh selection state. */
static void gains(const struct recon_model *m, size_t nc, const double *ang, const double *cost, const char *spec,
		  double *g, size_t *nunique)
{
	struct fix f;
	fix_spec(&f, spec);
	fix_sel(&f, m, nc, ang, cost);
	struct sel *s = &f.s;
	double E = sel_excess(s, SIZE_MAX, NULL);
	for (size_t j = 0; j < nc; j++)
		g[j] = NAN;
	for (size_t j = 0; j < s->J; j++)
		g[s->rep[j]] = E - sel_excess(s, j, NULL);
	if (nunique)
		*nunique = s->J;
	fix_free(&f);
}

static size_t pick1(const struct recon_model *m, size_t nc, const double *ang, const double *cost, const char *spec,
		    size_t batch, struct select_result *r)
{
	struct fix f;
	fix_spec(&f, spec);
	f.o.batch = batch;
	assert_int_equal(select_batch(m, nc, ang, cost, &f.t, &f.o, r, &f.e), 0);
	return r->npicks ? r->picks[0].index : SIZE_MAX;
}

/* The candidate farthest from every sample among random ones (θ ≤ 60°). */
static void gap_pair(const struct recon_model *m, double a[4])
{
	double best = -1;
	for (int i = 0; i < 400; i++) {
		double b[4] = { acos(0.5 + 0.5 * rt_unif()), 0, acos(0.5 + 0.5 * rt_unif()), 2 * M_PI * rt_unif() }, c[6];
		rbf_canon(b[0], b[1], b[2], b[3], c);
		double d = recon_nearest_centre(m, c, NULL);
		if (d > best) {
			best = d;
			memcpy(a, b, sizeof b);
		}
	}
}

static void test_known_information(void **state)
{
	(void)state;
	rt_seed();
	struct recon_model *m = toy_model();
	enum { NR = 200 };
	double ang[(NR + 1) * 4], cost[NR + 1], g[NR + 1];
	static const char *const specs[2] = { "lnf", "dhr:8,30,60" };
	for (int sp = 0; sp < 2; sp++) {
		/* a pair of the model's data against random pairs: it informs little, and is not chosen */
		memcpy(ang, m->ang + 4 * (size_t)(rt_unif() * (double)m->n), 4 * sizeof *ang);
		random_cands(NR, ang + 4, cost + 1);
		for (int j = 0; j <= NR; j++)
			cost[j] = 10;
		gains(m, NR + 1, ang, cost, specs[sp], g, NULL);
		double best = 0;
		for (int j = 1; j <= NR; j++)
			best = fmax(best, isnan(g[j]) ? 0 : g[j]);
		printf("%s: gain of a measured pair %.3g, best of %d random pairs %.3g\n", specs[sp], g[0], NR, best);
		assert_true(g[0] >= 0 && g[0] < 0.5 * best);
		struct select_result r;
		assert_true(pick1(m, NR + 1, ang, cost, specs[sp], 1, &r) != 0);
		select_result_free(&r);
		/* a pair next to one already picked in the batch: its information is in the data now */
		double a2[12], c2[3] = { 10, 10, 10 }, g2[3];
		gap_pair(m, a2);
		memcpy(a2 + 4, a2, 4 * sizeof *a2);
		a2[5] += 0.5 * M_PI / 180; /* half a degree away: a distinct candidate */
		gap_pair(m, a2 + 8);
		gains(m, 3, a2, c2, specs[sp], g2, NULL);
		struct fix f;
		fix_spec(&f, specs[sp]);
		fix_sel(&f, m, 3, a2, c2);
		assert_int_equal(f.s.J, 3);
		sel_update(&f.s, 0, 0);
		double E = sel_excess(&f.s, SIZE_MAX, NULL), after = E - sel_excess(&f.s, 1, NULL);
		printf("  neighbour of a pick: gain %.3g before, %.3g after the pick\n", g2[1], after);
		assert_true(after >= 0 && after < 0.15 * g2[1]); /* measured ≤ 0.063 over 30 seeds; a missing update gives ~1 */
		fix_free(&f);
	}
	recon_model_free(m);
}

static void test_cost_weighting(void **state)
{
	(void)state;
	struct toy ty;
	struct recon_model *m = toy_start(&ty, 30);
	size_t nc = ty.nc;
	double *ang = ty.ang, *cost = ty.cost, g[30];
	for (size_t j = 0; j < nc; j++)
		cost[j] = 10;
	gains(m, nc, ang, cost, "dhr:8,30,60", g, NULL);
	size_t a = 0, b = SIZE_MAX;
	for (size_t j = 1; j < nc; j++)
		if (g[j] > g[a])
			a = j;
	for (size_t j = 0; j < nc; j++)
		if (j != a && (b == SIZE_MAX || g[j] > g[b]))
			b = j;
	struct select_result r;
	assert_int_equal(pick1(m, nc, ang, cost, "dhr:8,30,60", 1, &r), a);
	select_result_free(&r);
	/* a costs 2× its gain advantage: the second best wins; at 0.5× of it a still wins */
	cost[a] = 10 * 2 * g[a] / g[b];
	assert_int_equal(pick1(m, nc, ang, cost, "dhr:8,30,60", 1, &r), b);
	assert_true(fabs(r.picks[0].gain_per_s - g[b] / 10) <= 1e-9 * r.picks[0].gain_per_s);
	select_result_free(&r);
	cost[a] = 10 * 0.5 * g[a] / g[b];
	cost[a] = fmax(cost[a], 10); /* never cheaper than the others: still chosen for its gain */
	assert_int_equal(pick1(m, nc, ang, cost, "dhr:8,30,60", 1, &r), a);
	select_result_free(&r);
	printf("best gain %.3g, second %.3g; the choice follows gain/cost\n", g[a], g[b]);
	recon_model_free(m);
}

static void test_reciprocity(void **state)
{
	(void)state;
	rt_seed();
	struct recon_model *m = toy_model();
	double a[4];
	gap_pair(m, a);
	double ang[8] = { a[0], a[1], a[2], a[3], a[2], a[3] + 0.7, a[0], a[1] + 0.7 }; /* swapped and rotated */
	double cost[2] = { 12, 7 }, g[2], gs[2];
	size_t nu;
	gains(m, 2, ang, cost, "dhr:8,30,60", g, &nu);
	assert_int_equal(nu, 1);
	assert_true(isnan(g[0]) && g[1] > 0); /* the cheaper one represents both */
	gains(m, 1, ang, cost, "dhr:8,30,60", gs, NULL);
	printf("gain of a pair %.12g, of its reciprocal %.12g\n", gs[0], g[1]);
	assert_true(fabs(gs[0] - g[1]) <= 1e-12 * g[1]);
	struct select_result r;
	assert_int_equal(pick1(m, 2, ang, cost, "lnf", 4, &r), 1);
	assert_int_equal(r.npicks, 1);
	select_result_free(&r);
	recon_model_free(m);
}

static void test_extremes(void **state)
{
	(void)state;
	rt_seed();
	struct recon_model *m = toy_model();
	struct select_result r;
	/* no candidates: the target's value, no pick */
	assert_int_equal(pick1(m, 0, NULL, NULL, "dhr:8,30,60", 8, &r), SIZE_MAX);
	assert_true(r.value > 0 && isfinite(r.value) && r.nper == 3 && r.nunique == 0);
	select_result_free(&r);
	/* five copies of one pair: one candidate, one pick at most */
	double a[4], ang[20 * 4], cost[20];
	gap_pair(m, a);
	for (int j = 0; j < 5; j++) {
		memcpy(ang + 4 * j, a, sizeof a);
		cost[j] = 9 - j;
	}
	assert_int_equal(pick1(m, 5, ang, cost, "lnf", 5, &r), 4);
	assert_int_equal(r.npicks, 1);
	assert_int_equal(r.nunique, 1);
	select_result_free(&r);
	/* all costs equal: the order does not depend on their common value */
	random_cands(20, ang, cost);
	for (int j = 0; j < 20; j++)
		cost[j] = 3;
	struct select_result r2;
	pick1(m, 20, ang, cost, "dhr:8,30,60", 6, &r);
	for (int j = 0; j < 20; j++)
		cost[j] = 300;
	pick1(m, 20, ang, cost, "dhr:8,30,60", 6, &r2);
	assert_int_equal(r.npicks, r2.npicks);
	for (size_t k = 0; k < r.npicks; k++) {
		assert_int_equal(r.picks[k].index, r2.picks[k].index);
		assert_true(k == 0 || r.picks[k].predicted <= r.picks[k - 1].predicted * (1 + 1e-12));
	}
	select_result_free(&r2);
	/* normal incidence, the pole of both, and grazing: finite gains, no failure */
	double pg[12] = { 0, 0, 0, 0, 0, 1.0, 40 * M_PI / 180, 2.0, M_PI / 2, 0, M_PI / 2, 3.0 }, pc[3] = { 4, 4, 4 };
	for (int sp = 0; sp < 2; sp++) {
		double g[3];
		gains(m, 3, pg, pc, sp ? "lnf" : "dhr:0,60", g, NULL);
		for (int j = 0; j < 3; j++)
			assert_true(isfinite(g[j]) && g[j] >= 0);
		struct select_result r3;
		pick1(m, 3, pg, pc, sp ? "lnf" : "dhr:0,60", 3, &r3);
		for (size_t k = 0; k < r3.npicks; k++)
			assert_true(isfinite(r3.picks[k].predicted) && r3.picks[k].predicted >= 0);
		select_result_free(&r3);
	}
	/* the threshold: met already → no pick; just below the value → picks until the prediction reaches it */
	char spec[64];
	snprintf(spec, sizeof spec, "dhr:8,30,60:le=%.17g", r.value * 1.01);
	struct select_result r4;
	assert_int_equal(pick1(m, 20, ang, cost, spec, 6, &r4), SIZE_MAX);
	assert_true(r4.met);
	select_result_free(&r4);
	double thr = r.npicks >= 2 ? 0.5 * (r.picks[0].predicted + r.picks[1].predicted) : r.value;
	snprintf(spec, sizeof spec, "dhr:8,30,60:le=%.17g", thr);
	pick1(m, 20, ang, cost, spec, 6, &r4);
	assert_false(r4.met);
	if (r.npicks >= 2) { /* (the excess above the threshold may choose differently from the plain variance) */
		assert_true(r4.npicks >= 1 && r4.npicks <= 2);
		assert_true(r4.picks[r4.npicks - 1].predicted <= thr);
		for (size_t k = 0; k + 1 < r4.npicks; k++)
			assert_true(r4.picks[k].predicted > thr);
	}
	select_result_free(&r4);
	select_result_free(&r);
	recon_model_free(m);
}

/* A model of rt_truth on an ni × no × np grid with nwl wavelengths across 450–1100 nm (the colour chain's range). */
static struct recon_model *rgb_model(int ni, int no, int np, size_t nwl)
{
	struct recon_samples smp;
	rt_samples_grid(&smp, ni, no, np, nwl, 0.01, 1.0);
	return fit_free(&smp, NULL);
}

/* The RGB target on models of rt_truth: (1) its value equals a direct computation: per node the brute-force
 * posterior variance of the extended system times Σ_c (Σ_λ W[c,λ] (f_λ + s_λ ε_λ) √(α_λ + u·prior))², f_λ the
 * model's own (energy-scaled) evaluation (for the log transform df̂/dg = f̂ + ε), weighted by the table's measure;
 * (2) after two picks the tracked variances still sum to the refactorised system's; (3) the actual error of the
 * model's table against the truth's (the same chain, the same measure) is within [1/3, 3] of the value (measured
 * 0.51–1.01 for the 4×4×6, 6×6×8 and 8×8×10 grids, seeds 1–6), and the value falls as the grid grows. With 16
 * wavelengths (3–4 visible) the reading of the wavelengths' errors (fully correlated, or independent: printed)
 * moves the value by ×0.84 only; on acq-sim's materials at 66 wavelengths see notes/README. */
static void test_rgb_target(void **state)
{
	(void)state;
	rt_seed();
	static const int grids[3][3] = { { 4, 4, 6 }, { 6, 6, 8 }, { 8, 8, 10 } };
	double prev = INFINITY;
	for (int gi = 0; gi < 3; gi++) {
		size_t L = 16;
		struct recon_model *m = rgb_model(grids[gi][0], grids[gi][1], grids[gi][2], L);
		size_t nc = 40;
		double ang[40 * 4], cost[40];
		random_cands(nc, ang, cost);
		struct fix fx;
		fix_make(&fx, m, nc, ang, cost, "rgb", 2);
		struct sel *s = &fx.s;
		struct select_result *r = &fx.r;
		struct acq_err *e = &fx.e;
		size_t F = s->F, picks[2] = { 3, 11 };
		assert_true(F > 500);
		double *W = malloc(3 * L * sizeof *W), *f = malloc(F * L * sizeof *f), *amp2 = malloc(F * sizeof *amp2);
		double *c6 = malloc(F * 6 * sizeof *c6), *P, *A = extended_factor(s, picks, 0, &P), one = 1;
		struct colour_opts co;
		colour_opts_brdf(&co);
		assert_int_equal(colour_weights(&co, m->wl, L, W, e), 0);
		assert_int_equal(recon_eval(m, F, s->xang, f, e), 0);
		double direct = 0, truth_err = 0, wsum = 0, indep = 0;
		for (size_t x = 0; x < F; x++) {
			const double *a = s->xang + 4 * x;
			rbf_canon(a[0], a[1], a[2], a[3], c6 + 6 * x);
			double u = recon_unseen(recon_nearest_centre(m, c6 + 6 * x, NULL)), ac[3] = { 0, 0, 0 }, ai = 0;
			double rm[3] = { 0, 0, 0 }, rtr[3] = { 0, 0, 0 };
			for (size_t l = 0; l < L; l++) {
				double sc = recon_energy_scale(m, a[0], a[2], l);
				double d = (f[x * L + l] + sc * m->eps[l]) * sqrt(s->alpha[l] + u * RECON_PRIOR_ALPHA);
				double tr = rt_truth(a, m->wl[l], 1.0);
				for (int c = 0; c < 3; c++) {
					ac[c] += W[c * L + l] * d;
					ai += W[c * L + l] * d * W[c * L + l] * d;
					rm[c] += W[c * L + l] * f[x * L + l];
					rtr[c] += W[c * L + l] * tr;
				}
			}
			amp2[x] = s->xw[x] * (ac[0] * ac[0] + ac[1] * ac[1] + ac[2] * ac[2]);
			double p0 = brute_var(s, A, P, s->n, 1, c6 + 6 * x, &one, 1);
			direct += amp2[x] * p0;
			indep += s->xw[x] * ai * p0;
			for (int c = 0; c < 3; c++)
				truth_err += s->xw[x] * (rm[c] - rtr[c]) * (rm[c] - rtr[c]);
			wsum += s->xw[x];
		}
		free(A);
		free(P);
		direct = sqrt(direct);
		truth_err = sqrt(truth_err);
		assert_true(fabs(wsum - 1) <= 1e-12);
		printf("rgb target, %dx%dx%d grid: value %.6g, direct %.6g, actual table error %.6g (ratio %.3f; with "
		       "independent wavelengths the value would be %.6g)\n", grids[gi][0], grids[gi][1], grids[gi][2], r->value,
		       direct, truth_err, truth_err / r->value, sqrt(indep));
		assert_true(fabs(r->value - direct) <= 1e-9 * direct);
		assert_true(truth_err >= r->value / 3 && truth_err <= 3 * r->value);
		assert_true(r->value < prev); /* more data, a smaller σ */
		prev = r->value;
		/* the rank-one update: after two picks, the sum over nodes equals the refactorised system's */
		double worst = 0;
		for (size_t k = 0; k < 2; k++) {
			sel_update(s, picks[k], k);
			A = extended_factor(s, picks, k + 1, &P);
			double sum = 0, bf = 0;
			for (size_t x = 0; x < F; x++) {
				sum += s->v[x];
				bf += amp2[x] * brute_var(s, A, P, s->n + k + 1, 1, c6 + 6 * x, &one, 1);
			}
			worst = fmax(worst, fabs(sum - bf) / (direct * direct));
			free(A);
			free(P);
		}
		assert_true(worst <= 1e-9);
		free(W);
		free(f);
		free(amp2);
		free(c6);
		fix_free(&fx);
		recon_model_free(m);
	}
}

/* The DHR target's value on a channel subset (--value-channels): without noise draws it is exactly the RMS over
 * those channels of recon_dhr's σ on the whole model (the sub-model holds the same per-channel data: weights,
 * trend, energy table), and with as many channels as the model has it is the whole computation. */
static void test_value_channels(void **state)
{
	(void)state;
	rt_seed();
	size_t L = 40, LV = 30; /* at least the 24 tracked channels */
	struct recon_model *m = rgb_model(4, 4, 6, L);
	struct select_target t;
	struct acq_err e = { 0 };
	assert_int_equal(select_target_parse("dhr:8,40", &t, &e), 0);
	struct select_opts o;
	select_opts_default(&o);
	o.batch = 0;
	o.ndraws = 0;
	o.nvalue = LV;
	struct select_result r = { 0 }, ra = { 0 };
	assert_int_equal(select_batch(m, 0, NULL, NULL, &t, &o, &r, &e), 0);
	assert_int_equal(r.nvalue, LV);
	double th[2] = { 8 * M_PI / 180, 40 * M_PI / 180 }, dhr[2 * 40], sig[2 * 40];
	assert_int_equal(recon_dhr(m, 2, th, 0, 1, dhr, sig, NULL, NULL, &e), 0);
	for (size_t k = 0; k < 2; k++) {
		double acc = 0;
		for (size_t v = 0; v < LV; v++) {
			double x = sig[k * L + v * (L - 1) / (LV - 1)];
			acc += x * x;
		}
		printf("dhr %g: value on %zu of %zu channels %.9g, RMS of recon_dhr's σ there %.9g\n", t.theta_deg[k], LV, L,
		       r.per[k], sqrt(acc / LV));
		assert_true(fabs(r.per[k] - sqrt(acc / LV)) <= 1e-12 * r.per[k]);
	}
	o.nvalue = L; /* no fewer channels than the model's: all of them */
	assert_int_equal(select_batch(m, 0, NULL, NULL, &t, &o, &ra, &e), 0);
	assert_int_equal(ra.nvalue, L);
	for (size_t k = 0; k < 2; k++) {
		double acc = 0;
		for (size_t l = 0; l < L; l++)
			acc += sig[k * L + l] * sig[k * L + l];
		assert_true(fabs(ra.per[k] - sqrt(acc / L)) <= 1e-12 * ra.per[k]);
	}
	/* with a threshold: a subset value near it is recomputed on all channels, so met is decided on all; far above
	 * it (more than SEL_VALUE_CHECK = 4x) the subset's value stands */
	double all = fmax(ra.per[0], ra.per[1]);
	for (int near = 0; near < 2; near++) {
		char spec[64];
		double thr = near ? all * 1.001 : r.value / 5;
		snprintf(spec, sizeof spec, "dhr:8,40:le=%.17g", thr);
		struct select_target tt;
		struct select_result rc = { 0 };
		assert_int_equal(select_target_parse(spec, &tt, &e), 0);
		o.nvalue = LV;
		assert_int_equal(select_batch(m, 0, NULL, NULL, &tt, &o, &rc, &e), 0);
		printf("threshold %.6g: value %.9g (subset %.9g, all %.9g), checked on all %d, met %d\n", thr, rc.value,
		       r.value, all, rc.value_checked, rc.met);
		assert_int_equal(rc.value_checked, near);
		assert_int_equal(rc.nvalue, LV);
		for (size_t k = 0; k < 2; k++)
			assert_true(fabs(rc.per[k] - (near ? ra.per[k] : r.per[k])) <= 1e-12 * rc.per[k]);
		assert_int_equal(rc.met, near);
		select_result_free(&rc);
	}
	select_result_free(&r);
	select_result_free(&ra);
	recon_model_free(m);
}

static void test_target_parse(void **state)
{
	(void)state;
	struct select_target t;
	struct acq_err e = { 0 };
	assert_int_equal(select_target_parse("dhr:8,30,60", &t, &e), 0);
	assert_int_equal(t.kind, SELECT_DHR);
	assert_int_equal(t.nth, 3);
	assert_true(isnan(t.threshold));
	assert_int_equal(select_target_parse("dhr:8:le=0.002", &t, &e), 0);
	assert_true(t.nth == 1 && t.theta_deg[0] == 8 && t.threshold == 0.002);
	assert_int_equal(select_target_parse("lnf:le=0.1", &t, &e), 0);
	assert_true(t.kind == SELECT_LNF && t.threshold == 0.1);
	assert_int_equal(select_target_parse("lnf:rad:le=0.1", &t, &e), 0);
	assert_true(t.kind == SELECT_LNF && t.threshold == 0.1 && t.lnf_rad == 1);
	assert_int_equal(select_target_parse("dhr:8:le=0.002+lnf:rad:le=0.1", &t, &e), 0);
	assert_true(t.kind == SELECT_DHR && t.lnf_threshold == 0.1 && t.lnf_rad == 1);
	assert_int_equal(select_target_parse("dhr:8:le=0.002+lnf:mix:le=0.1", &t, &e), 0);
	assert_true(t.kind == SELECT_DHR && t.lnf_threshold == 0.1 && t.lnf_rad == 2);
	assert_int_equal(select_target_parse("lnf:mix", &t, &e), 0);
	assert_true(t.kind == SELECT_LNF && t.lnf_rad == 2);
	assert_int_equal(select_target_parse("dhr:8:le=0.002+lnf:bright:le=0.1", &t, &e), 0);
	assert_true(t.kind == SELECT_DHR && t.lnf_threshold == 0.1 && t.lnf_rad == 3);
	assert_int_equal(select_target_parse("dhr:8:le=0.002+lnf:le=0.1", &t, &e), 0);
	assert_true(t.lnf_rad == 0);
	assert_int_equal(select_target_parse("dhr:8,30:le=0.002+lnf:bright:le=0.1:lobe_above=70", &t, &e), 0);
	assert_true(t.kind == SELECT_DHR && t.nth == 2 && t.threshold == 0.002 && t.lnf_threshold == 0.1 && t.lnf_rad == 3 &&
		    t.lobe_above_deg == 70);
	assert_int_equal(select_target_parse("lnf:lobe_above=72.5", &t, &e), 0);
	assert_true(t.kind == SELECT_LNF && t.lnf_rad == 0 && isnan(t.threshold) && t.lobe_above_deg == 72.5);
	assert_true(select_target_parse("dhr:8", &t, &e) == 0 && t.lobe_above_deg == 0);
	assert_int_equal(select_target_parse("rgb:le=0.01", &t, &e), 0);
	assert_true(t.kind == SELECT_RGB && t.threshold == 0.01);
	static const char *const bad[] = { "", "dhr", "dhr:", "dhr:8,", "dhr:91", "dhr:-1", "dhr:x", "lnf:le=0",
					   "lnf:le=-1", "lnf:le=", "lnfx", "lnf:radx", "lnf:rad:", "lnf:mixx", "lnf:mix:", "lnf:brightx", "lnf:bright:", "lnf:", "lnf:lobe_above=0", "lnf:lobe_above=90", "lnf:lobe_above=x",
					   "lnf:lobe_above=", "lnf:lobe_above=70:le=1", ":lobe_above=70", "dhr:8:lobe_above=70+lnf:le=1", "rgb:rad", "mse:8", "dhr:8:le=abc", "rgb:8", "rgbx", "rgb:le=0",
					   "dhr:1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17" };
	for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
		e.msg[0] = '\0';
		assert_int_equal(select_target_parse(bad[i], &t, &e), -1);
		assert_true(strlen(e.msg) > 10);
	}
}

/* The noise part's fall with n (sel_update_noise): after 0-3 picks the tracked noise variance q of each DHR
 * functional equals Σ_k N_k h_k² with h = A'⁻¹b' of the refactorised extended system (N = η λ on the model's
 * samples, the new samples' noise on the picks), to 1e-9 of q; and on a model whose DHR σ sits on its noise floor
 * the picks still reduce the criterion (before, the floor was held and every gain was ~0). */
static void test_noise_fall(void **state)
{
	(void)state;
	struct toy ty;
	struct fix f;
	struct recon_model *m = toy_fix(&ty, 40, &f, "dhr:30", 3);
	struct sel s = f.s;
	size_t Q = (size_t)SEL_NMU * SEL_NPHI, Lc = s.Lc, n = s.n;
	struct dcoef dc;
	dcoef_make(&dc, &s, 30, &f.e);
	const double *c6 = dc.c6, *C = dc.C;
	size_t picks[3], np = 0;
	for (size_t i = 0; i < 3; i++)
		picks[i] = (size_t)(rt_unif() * (double)s.J) % s.J;
	if (picks[1] == picks[0])
		picks[1] = (picks[0] + 1) % s.J;
	if (picks[2] == picks[0] || picks[2] == picks[1])
		picks[2] = (picks[1] + 1) % s.J == picks[0] ? (picks[1] + 2) % s.J : (picks[1] + 1) % s.J;
	double worst = 0, q0 = 0, q3 = 0;
	for (;;) {
		double *P, *A = extended_factor(&s, picks, np, &P);
		size_t N = n + np;
		for (size_t c = 0; c < Lc; c++) {
			double *b = calloc(N, sizeof *b), q = 0;
			for (size_t qq = 0; qq < Q; qq++)
				for (size_t i = 0; i < N; i++)
					b[i] += kern(m, c6 + 6 * qq, P + 6 * i) * C[qq * Lc + c];
			assert_int_equal(LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)N, 1, A, (lapack_int)N, b,
							(lapack_int)N), 0);
			for (size_t i = 0; i < N; i++)
				q += (i < n ? m->eta * m->lam[i] : s.noise) * b[i] * b[i];
			double d = fabs(s.q[c] - q) / q;
			worst = fmax(worst, d);
			if (c == 0 && np == 0)
				q0 = q;
			if (c == 0 && np == 3)
				q3 = q;
			free(b);
		}
		free(A);
		free(P);
		if (np == 3)
			break;
		sel_update(&s, picks[np], np);
		np++;
	}
	printf("noise variance of the DHR functional: largest |tracked − refactorisation| / q = %.3g (channel %zu: "
	       "q %.4g → %.4g after 3 picks)\n", worst, s.chan[0], q0, q3);
	assert_true(worst <= 1e-9); /* (q need not fall for any pick: a smoother's weights can spread onto noisier data) */
	f.s = s;
	fix_free(&f);

	/* on the noise floor: the floor dominates every tracked channel, yet the best pick's gain is not ~0 and the
	 * predicted value falls with it */
	fix_make(&f, m, ty.nc, ty.ang, ty.cost, "dhr:30", 3);
	s = f.s;
	for (size_t x = 0; x < s.F; x++)
		s.sn2[x] = 100 * (s.v[x] + 1e-30);
	double E = sel_excess(&s, SIZE_MAX, NULL), best = 0;
	for (size_t j = 0; j < s.J; j++)
		best = fmax(best, E - sel_excess(&s, j, NULL));
	printf("on the noise floor: criterion %.4g, best gain %.4g (%.2g of it)\n", E, best, best / E);
	assert_true(best > 1e-3 * E);
	f.s = s;
	fix_free(&f);
	dcoef_free(&dc);
	recon_model_free(m);
}

/* The combined target (dhr + lnf, both must be met): its parts' values are the single targets' values, its value
 * the larger ratio to the thresholds; a batch is chosen while either part is unmet (a met DHR part alone would
 * pick nothing), the first pick maximises the sum of the parts' relative reductions per second; the parser wants
 * both thresholds. */
static void test_combined_target(void **state)
{
	(void)state;
	struct toy ty;
	struct recon_model *m = toy_start(&ty, 60);
	size_t nc = ty.nc;
	double *ang = ty.ang, *cost = ty.cost;
	struct acq_err e = { 0 };
	struct select_target td, tl, tc;
	assert_int_equal(select_target_parse("dhr:8,30", &td, &e), 0);
	assert_int_equal(select_target_parse("lnf", &tl, &e), 0);
	struct select_opts o;
	select_opts_default(&o);
	o.batch = 0;
	struct select_result rd, rl, rc;
	assert_int_equal(select_batch(m, nc, ang, cost, &td, &o, &rd, &e), 0);
	assert_int_equal(select_batch(m, nc, ang, cost, &tl, &o, &rl, &e), 0);
	/* thresholds: the DHR part met (2x its value), ln f not (half its value) */
	char spec[128];
	snprintf(spec, sizeof spec, "dhr:8,30:le=%.17g+lnf:le=%.17g", 2 * rd.value, 0.5 * rl.value);
	assert_int_equal(select_target_parse(spec, &tc, &e), 0);
	assert_true(tc.kind == SELECT_DHR && tc.nth == 2 && tc.lnf_threshold == 0.5 * rl.value);
	o.batch = 4;
	assert_int_equal(select_batch(m, nc, ang, cost, &tc, &o, &rc, &e), 0);
	printf("combined: dhr part %.6g (alone %.6g), lnf part %.6g (alone %.6g), value %.4g, %zu picks\n", rc.part[0],
	       rd.value, rc.part[1], rl.value, rc.value, rc.npicks);
	assert_true(fabs(rc.part[0] - rd.value) <= 1e-12 * rd.value && fabs(rc.part[1] - rl.value) <= 1e-12 * rl.value);
	assert_true(fabs(rc.value - 2.0) < 1e-12 && !rc.met);
	assert_int_equal(rc.nper, 3);
	assert_true(rc.npicks > 0);
	struct select_result r1;
	struct select_target t1 = td;
	t1.threshold = 2 * rd.value;
	assert_int_equal(select_batch(m, nc, ang, cost, &t1, &o, &r1, &e), 0);
	assert_int_equal(r1.npicks, 0); /* the DHR part alone is met */
	select_result_free(&r1);
	/* the first pick: the largest (ΔE_dhr/E_dhr + ΔE_lnf/E_lnf) / cost, from the parts' own states */
	struct select_target p0 = td, p1 = tl;
	p0.threshold = 2 * rd.value;
	p1.threshold = 0.5 * rl.value;
	struct sel a, b;
	struct select_result ra = { 0 }, rb = { 0 };
	assert_int_equal(sel_init(&a, m, nc, ang, cost, &p0, &o, &ra, &e), 0);
	assert_int_equal(sel_init(&b, m, nc, ang, cost, &p1, &o, &rb, &e), 0);
	double Ea = sel_excess(&a, SIZE_MAX, NULL), Eb = sel_excess(&b, SIZE_MAX, NULL), best = -1;
	size_t bj = SIZE_MAX;
	for (size_t j = 0; j < a.J; j++) {
		double g = (Ea > 0 ? (Ea - sel_excess(&a, j, NULL)) / Ea : 0) + (Eb - sel_excess(&b, j, NULL)) / Eb;
		if (g / a.cost[j] > best) {
			best = g / a.cost[j];
			bj = a.rep[j];
		}
	}
	assert_int_equal(rc.picks[0].index, bj);
	assert_true(fabs(rc.picks[0].gain_per_s - best) <= 1e-9 * best);
	sel_free(&a);
	sel_free(&b);
	/* both met: no pick; the parser */
	snprintf(spec, sizeof spec, "dhr:8,30:le=%.17g+lnf:le=%.17g", 2 * rd.value, 2 * rl.value);
	select_result_free(&rc);
	assert_int_equal(select_target_parse(spec, &tc, &e), 0);
	assert_int_equal(select_batch(m, nc, ang, cost, &tc, &o, &rc, &e), 0);
	assert_true(rc.met && rc.npicks == 0);
	assert_int_equal(select_target_parse("dhr:8+lnf:le=1", &tc, &e), -1);
	assert_non_null(strstr(e.msg, "both"));
	assert_int_equal(select_target_parse("lnf:le=1+dhr:8:le=1", &tc, &e), -1);
	assert_int_equal(select_target_parse("dhr:8:le=1+rgb:le=1", &tc, &e), -1);
	select_result_free(&rc);
	select_result_free(&rd);
	select_result_free(&rl);
	recon_model_free(m);
}

/* Select with the route r (NULL: costs from the arms alone) on candidates ang/cost, batch 2, target lnf: the picks'
 * input indices into got[2]; the result in *res (select_result_free). */
static size_t picks2(const struct recon_model *m, const double *ang, const double *cost, const struct select_route *rt,
		     size_t got[2], struct select_result *res)
{
	struct fix f;
	fix_spec(&f, "lnf");
	f.o.batch = 2;
	f.o.route = rt;
	assert_int_equal(select_batch(m, 3, ang, cost, &f.t, &f.o, res, &f.e), 0);
	for (size_t k = 0; k < 2; k++)
		got[k] = k < res->npicks ? res->picks[k].index : SIZE_MAX;
	return res->npicks;
}

/* The route increment: the arms are at incidence 0°, candidate B at 30°, the most informative candidate P at 60°, and
 * A, a twin of B in information (B's pair half a degree away) but at P's incidence next to P. Charged from the arms
 * alone (the old rule) B is cheaper than A (the laser's 30° instead of 60°), so the batch is P, B: two incidences,
 * two darks, the laser to 60° and 30°. Charged its increment to the batch's route, A after P costs its measurement and
 * a 2° detector move, B its incidence's darks and a detour of the laser: the batch is P then A, and A's charge is
 * exactly that increment. A candidate at the arms' incidence is charged no darks (the executor keeps them). */
static void test_route_increment(void **state)
{
	(void)state;
	struct toy ty;
	struct recon_model *m = toy_start(&ty, 30);
	double ang[12], g[31], gall[31 * 4];
	gap_pair(m, gall);
	memcpy(gall + 4, ty.ang, 30 * 4 * sizeof *gall);
	double c31[31];
	for (int j = 0; j < 31; j++)
		c31[j] = 10;
	gains(m, 31, gall, c31, "lnf", g, NULL);
	size_t P = 0, B = SIZE_MAX;
	for (size_t j = 1; j < 31; j++)
		if (g[j] > g[P])
			P = j;
	for (size_t j = 0; j < 31; j++) /* B: informative, but clearly less than P */
		if (j != P && g[j] <= 0.5 * g[P] && (B == SIZE_MAX || g[j] > g[B]))
			B = j;
	assert_true(B != SIZE_MAX && g[B] > 0.05 * g[P]);
	memcpy(ang, gall + 4 * P, 4 * sizeof *ang);      /* 0: P */
	memcpy(ang + 4, gall + 4 * B, 4 * sizeof *ang);  /* 1: A, B's twin */
	ang[4 + 2] = fmin(ang[4 + 2] + 0.5 * M_PI / 180, 0.5 * M_PI - 0.01);
	memcpy(ang + 8, gall + 4 * B, 4 * sizeof *ang);  /* 2: B */
	double ga[3], c3[3] = { 10, 10, 10 };
	gains(m, 3, ang, c3, "lnf", ga, NULL);
	printf("route: gains P %.3g, A %.3g, B %.3g\n", ga[0], ga[1], ga[2]);
	assert_true(fabs(ga[1] - ga[2]) <= 0.1 * ga[2]); /* equally informative, to 10 % */
	/* bench positions (laser θ, detector θ, detector φ): P and A at laser 60°, 2° apart; B at 30°; the arms at 0° */
	double pos[9] = { 60, 40, 100, 60, 42, 100, 30, 40, 100 }, base[3] = { 2, 2, 2 }, open[3] = { 3, 3, 3 };
	struct select_route rt = { .pos = pos, .base = base, .open = open, .from = { 0, 40, 100 },
				   .speed = { 10, 20, 30 }, .accel = { 20, 60, 90 }, .settle = { 0.3, 0.2, 0.2 },
				   .move_s = 0.075 };
	/* the old rule: each from the arms (its incidence's darks and the laser's move) */
	double old[3];
	for (int j = 0; j < 3; j++)
		old[j] = 2 + 3 + sel_route_move(&rt, rt.from, pos + 3 * j);
	size_t got[2];
	struct select_result r;
	assert_int_equal(picks2(m, ang, old, NULL, got, &r), 2);
	printf("route: old rule picks %zu, %zu (costs %.2f %.2f %.2f)\n", got[0], got[1], old[0], old[1], old[2]);
	assert_int_equal(got[0], 0);
	assert_int_equal(got[1], 2);
	select_result_free(&r);
	/* the increment: P first (from the arms: its darks and the laser's move), then A (no dark, a 2° detector move) */
	assert_int_equal(picks2(m, ang, old, &rt, got, &r), 2);
	printf("route: increment rule picks %zu, %zu (charged %.3f, %.3f s)\n", got[0], got[1], r.picks[0].cost,
	       r.picks[1].cost);
	assert_int_equal(got[0], 0);
	assert_int_equal(got[1], 1);
	double dA = 2 * sqrt(2.0 / 60) + 0.2 + 0.075; /* detector θ: a 2° trapezoid (no cruise), its settle, polling */
	assert_true(fabs(r.picks[0].cost - (2 + 3 + sel_route_move(&rt, rt.from, pos))) < 1e-12);
	assert_true(fabs(r.picks[1].cost - (2 + dA)) < 1e-12);
	select_result_free(&r);
	/* B after P: its incidence is new to the batch (its darks), the cheapest insertion is before P (arms → B → P) */
	struct sel_route w;
	assert_int_equal(sel_route_init(&w, &rt, 2), 0);
	sel_route_add(&w, 0, 1);
	size_t at;
	double cB = sel_route_cost(&w, 2, &at);
	double ins = sel_route_move(&rt, rt.from, pos + 6) + sel_route_move(&rt, pos + 6, pos) - sel_route_move(&rt, rt.from, pos);
	assert_int_equal(at, 1);
	assert_true(fabs(cB - (2 + 3 + ins)) < 1e-12);
	assert_true(cB < 2 + 3 + sel_route_move(&rt, pos, pos + 6)); /* inserting beats appending (the laser's way back) */
	sel_route_free(&w);
	/* from the arms at B's incidence B is charged no darks, only its move */
	rt.from[0] = 30;
	rt.from[1] = 30;
	assert_int_equal(sel_route_init(&w, &rt, 2), 0);
	assert_true(fabs(sel_route_cost(&w, 2, &at) - (2 + sel_route_move(&rt, rt.from, pos + 6))) < 1e-12);
	sel_route_free(&w);
	/* the azimuth modulo 360°: 359° from 1° is a 2° move */
	double p1[3] = { 0, 0, 1 }, p2[3] = { 0, 0, 359 }, p3[3] = { 0, 0, 3 };
	assert_true(fabs(sel_route_move(&rt, p1, p2) - sel_route_move(&rt, p1, p3)) < 1e-12);
	recon_model_free(m);
}

/* ∫ g cosθi cosθo dωi dωo / ∫ cosθi cosθo dωi dωo over θi, θo ≤ 80° for g = cos²θi cos²θo (exact: each factor
 * ∫ cos³θ sinθ dθ / ∫ cosθ sinθ dθ = (1 − c⁴)/4 / ((1 − c²)/2), c = cos 80°). */
static double proj_mean_cos2(void)
{
	double c = cos(80 * M_PI / 180), one = (1 - pow(c, 4)) / 4 / ((1 - c * c) / 2);
	return one * one;
}

/* The ln f criterion integrates the posterior variance over the hemisphere pair under its projected measure: the
 * grid's weights are a quadrature of that measure (cos²θi cos²θo's mean within 3 %: a 10° midpoint rule), the
 * criterion is Σ w v, and of two candidates the one
 * whose gain lies where the measure is large wins over one near grazing whose unweighted gain (the rule before: the
 * grid's plain mean) is larger. */
static void test_lnf_measure(void **state)
{
	(void)state;
	size_t F = sel_lnf_grid(NULL, NULL);
	double *ang = malloc(F * 4 * sizeof *ang), *w = malloc(F * sizeof *w), sw = 0, sg = 0, su = 0;
	sel_lnf_grid(ang, w);
	for (size_t x = 0; x < F; x++) {
		assert_true(w[x] > 0);
		double g = pow(cos(ang[4 * x]) * cos(ang[4 * x + 2]), 2);
		sw += w[x];
		sg += w[x] * g;
		su += g / (double)F;
	}
	printf("lnf measure: weights sum %.15g; mean of cos²θi cos²θo %.4f (uniform weights %.4f), exact %.4f\n", sw, sg,
	       su, proj_mean_cos2());
	assert_true(fabs(sw - 1) < 1e-12);
	assert_true(fabs(sg - proj_mean_cos2()) <= 0.03 * proj_mean_cos2());
	free(ang);
	free(w);
	/* two candidates, equal cost: M in a gap of the toy model's samples at mid angles, G near grazing */
	rt_seed();
	struct recon_model *m = toy_model();
	double deg[2][4] = { { 37.5, 0, 42.5, 30 }, { 80, 0, 80, 150 } }, ca[8], cost[2] = { 1, 1 };
	for (int j = 0; j < 2; j++)
		for (int c = 0; c < 4; c++)
			ca[4 * j + c] = deg[j][c] * M_PI / 180;
	struct fix f;
	fix_make(&f, m, 2, ca, cost, "lnf", 1);
	struct sel *s = &f.s;
	assert_int_equal(s->J, 2);
	double E = sel_excess(s, SIZE_MAX, NULL), Ew = 0, gw[2], gu[2];
	for (size_t x = 0; x < s->F; x++)
		Ew += s->xw[x] * s->v[x];
	assert_true(fabs(E - Ew) <= 1e-12 * Ew);
	for (size_t j = 0; j < 2; j++) {
		double S = s->Pjj[j] + s->noise;
		gu[s->rep[j]] = 0;
		for (size_t x = 0; x < s->F; x++) {
			double z = s->Z[x * s->J + j];
			gu[s->rep[j]] += fmin(z * z / S, s->v[x]) / (double)s->F;
		}
		gw[s->rep[j]] = E - sel_excess(s, j, NULL);
	}
	printf("lnf measure: gains M %.4g, G %.4g (the grid's plain mean: M %.4g, G %.4g)\n", gw[0], gw[1], gu[0], gu[1]);
	assert_true(gu[1] > gu[0]); /* the rule before would choose G */
	assert_true(gw[0] > gw[1]);
	fix_free(&f);
	struct select_result r;
	assert_int_equal(pick1(m, 2, ca, cost, "lnf", 1, &r), 0);
	select_result_free(&r);
	recon_model_free(m);
}

/* "lnf:rad" (session 15): the ln f target's value, grid and posterior are "lnf"'s (the same bits); only the criterion's
 * weights change: w[x] ∝ ω_x · mean_λ (d_λ c / (1 + f̂_λ c))² / amp[x]², ω_x the grid cell's share of dωi dωo (a
 * quadrature of that measure: cos²θi cos²θo's mean within 3 % of the exact one), c = cosθi cosθo, f̂ the model's own
 * evaluation (recon_eval, energy-scaled), d_λ = (f̂_λ + s_λ ε_λ) √(α_λ + u·prior) (for the log transform df̂/dg =
 * f̂ + ε; s the energy factor), amp² = mean α + u·prior: w v is then the expected squared error of log(1 + f̂ c), the
 * study's held-out log-RMSE. Equal to 1e-9 relative (select computes f̂ through its own kernel rows and weights, not
 * recon_eval); the near-normal pairs (θi, θo ≤ 30°) weigh more than under the projected measure (c² f̂² against c). */
static double solid_mean_cos2(void)
{
	double c = cos(80 * M_PI / 180), one = (1 - c * c * c) / 3 / (1 - c);
	return one * one;
}

/* The fixtures of the lnf weights' tests on m: nc random candidates, lnf's selection (fp) and spec's (fx), batch 2. */
static void lnf_pair(const struct recon_model *m, size_t nc, double *ang, double *cost, struct fix *fp, struct fix *fx,
		     const char *spec)
{
	random_cands(nc, ang, cost);
	fix_make(fp, m, nc, ang, cost, "lnf", 2);
	fix_make(fx, m, nc, ang, cost, spec, 2);
}

static void test_lnf_rad(void **state)
{
	(void)state;
	rt_seed();
	size_t L = 16, nc = 40;
	struct recon_model *m = rgb_model(4, 4, 6, L);
	double ang[40 * 4], cost[40];
	struct fix fp, fr;
	lnf_pair(m, nc, ang, cost, &fp, &fr, "lnf:rad");
	struct sel *s = &fr.s;
	size_t F = s->F;
	assert_true(fr.t.lnf_rad == 1 && fp.t.lnf_rad == 0 && F == fp.s.F);
	assert_true(fr.r.value == fp.r.value);
	for (size_t x = 0; x < F; x++)
		assert_true(s->v[x] == fp.s.v[x]);
	double *f = malloc(F * L * sizeof *f), *want = malloc(F * sizeof *want), abar = 0, sw = 0, om = 0, omg = 0;
	double h = 5 * M_PI / 180, tmax = 80 * M_PI / 180, dp = 20 * M_PI / 180, near_r = 0, near_p = 0;
	assert_int_equal(recon_eval(m, F, s->xang, f, &fr.e), 0);
	for (size_t l = 0; l < L; l++)
		abar += s->alpha[l] / (double)L;
	for (size_t x = 0; x < F; x++) {
		const double *a = s->xang + 4 * x;
		double c6[6];
		rbf_canon(a[0], a[1], a[2], a[3], c6);
		double wi = cos(fmax(a[0] - h, 0)) - cos(fmin(a[0] + h, tmax)), wo = cos(fmax(a[2] - h, 0)) - cos(fmin(a[2] + h, tmax));
		double wp = a[0] == 0 ? M_PI : (fabs(a[3]) < 1e-12 || fabs(a[3] - M_PI) < 1e-12 ? 0.5 * dp : dp);
		double omega = wi * wo * wp * (a[2] > a[0] + 1e-12 ? 2 : 1), c = cos(a[0]) * cos(a[2]);
		double u = recon_unseen(recon_nearest_centre(m, c6, NULL)), acc = 0;
		for (size_t l = 0; l < L; l++) {
			double fl = f[x * L + l], sc = recon_energy_scale(m, a[0], a[2], l);
			double e = (fl + sc * m->eps[l]) * sqrt(s->alpha[l] + u * RECON_PRIOR_ALPHA) * c / (1 + fl * c);
			acc += e * e / (double)L;
		}
		want[x] = omega * acc / (abar + u * RECON_PRIOR_ALPHA);
		sw += want[x];
		om += omega;
		omg += omega * c * c;
	}
	double worst = 0;
	for (size_t x = 0; x < F; x++) {
		const double *a = s->xang + 4 * x;
		worst = fmax(worst, fabs(s->xw[x] - want[x] / sw) / (want[x] / sw));
		if (a[0] <= 30 * M_PI / 180 + 1e-9 && a[2] <= 30 * M_PI / 180 + 1e-9) {
			near_r += s->xw[x];
			near_p += fp.s.xw[x];
		}
	}
	printf("lnf:rad: weights vs the direct formula: largest relative difference %.3g; mean of cos²θi cos²θo under the "
	       "cells' dωi dωo %.4f, exact %.4f; weight of θi, θo ≤ 30°: %.3f (projected measure %.3f)\n", worst, omg / om,
	       solid_mean_cos2(), near_r, near_p);
	assert_true(worst <= 1e-9);
	assert_true(fabs(omg / om - solid_mean_cos2()) <= 0.03 * solid_mean_cos2());
	assert_true(near_r > near_p);
	/* the criterion is Σ w v, and a batch is chosen */
	double E = sel_excess(s, SIZE_MAX, NULL), Ew = 0;
	for (size_t x = 0; x < F; x++)
		Ew += s->xw[x] * s->v[x];
	assert_true(fabs(E - Ew) <= 1e-12 * Ew);
	free(f);
	free(want);
	fix_free(&fp);
	fix_free(&fr);
	struct select_result r;
	size_t p0 = pick1(m, nc, ang, cost, "lnf:rad", 2, &r);
	assert_true(p0 < nc && r.npicks == 2);
	select_result_free(&r);
	recon_model_free(m);
}

/* lnf:mix (session 16): the projected measure's and lnf:rad's weights, each over its own criterion Σ w v before the
 * picks, summed and normalised; the value and variances are lnf's. Seen failing with the two weights summed without
 * their criteria (largest relative difference 0.115). */
static void test_lnf_mix(void **state)
{
	(void)state;
	rt_seed();
	size_t L = 16, nc = 40;
	struct recon_model *m = rgb_model(4, 4, 6, L);
	double ang[40 * 4], cost[40];
	struct fix fp, fr, fm;
	lnf_pair(m, nc, ang, cost, &fp, &fr, "lnf:rad");
	fix_make(&fm, m, nc, ang, cost, "lnf:mix", 2);
	size_t F = fm.s.F;
	assert_true(fm.t.lnf_rad == 2 && F == fp.s.F && fm.r.value == fp.r.value);
	double Ep = 0, Er = 0, sum = 0, worst = 0;
	for (size_t x = 0; x < F; x++) {
		assert_true(fm.s.v[x] == fp.s.v[x]);
		Ep += fp.s.xw[x] * fp.s.v[x];
		Er += fr.s.xw[x] * fr.s.v[x];
	}
	assert_true(Ep > 0 && Er > 0);
	for (size_t x = 0; x < F; x++)
		sum += fp.s.xw[x] / Ep + fr.s.xw[x] / Er;
	for (size_t x = 0; x < F; x++) {
		double want = (fp.s.xw[x] / Ep + fr.s.xw[x] / Er) / sum;
		if (want > 0)
			worst = fmax(worst, fabs(fm.s.xw[x] - want) / want);
		else
			assert_true(fm.s.xw[x] == 0);
	}
	/* a pick's relative reduction of the mix = the mean of its relative reductions of the two criteria */
	double Em = sel_excess(&fm.s, SIZE_MAX, NULL);
	printf("lnf:mix: weights vs (wp/Ep + wr/Er) normalised: largest relative difference %.3g; Ep %.4g, Er %.4g, "
	       "mix %.4g (2/sum %.4g)\n", worst, Ep, Er, Em, 2 / sum);
	assert_true(worst <= 1e-12);
	assert_true(fabs(Em - 2 / sum) <= 1e-12 * Em);
	fix_free(&fp);
	fix_free(&fr);
	fix_free(&fm);
	struct select_result r;
	size_t p0 = pick1(m, nc, ang, cost, "lnf:mix", 2, &r);
	assert_true(p0 < nc && r.npicks == 2);
	select_result_free(&r);
	recon_model_free(m);
}

/* A glossy truth for lnf:bright: 0.1/π + a normalised Phong lobe, exponent 100, ks 0.6 (peak ≈ 9.8 sr⁻¹, width
 * ≈ 8°; albedo < 0.7), sampled at θi, θo ∈ {0, 20, 40, 60, 75°} × φo every 30° (the mirror included), 1 % noise. */
static void lobe_samples(struct recon_samples *s, size_t nwl)
{
	static const double th[5] = { 0, 20, 40, 60, 75 };
	rt_samples_alloc(s, 5 * 5 * 12, nwl, 1);
	for (size_t l = 0; l < nwl; l++)
		s->wl[l] = 450 + 650.0 * (double)l / (double)(nwl - 1);
	size_t k = 0;
	for (int i = 0; i < 5; i++)
		for (int o = 0; o < 5; o++)
			for (int p = 0; p < 12; p++, k++) {
				double *a = s->ang + 4 * k;
				a[0] = th[i] * M_PI / 180;
				a[1] = 0;
				a[2] = th[o] * M_PI / 180;
				a[3] = 30.0 * p * M_PI / 180;
				for (int c = 0; c < 4; c++)
					s->deg[4 * k + c] = a[c] * 180 / M_PI;
				double cm = -sin(a[0]) * sin(a[2]) * cos(a[3]) + cos(a[0]) * cos(a[2]); /* wo · mirror(wi) */
				double f = 0.1 / M_PI + 0.6 * 102 / (2 * M_PI) * (cm > 0 ? pow(cm, 100) : 0);
				for (size_t l = 0; l < nwl; l++) {
					double sg = 0.01 * f + 1e-4;
					s->val[k * nwl + l] = f + sg * rt_normal();
					s->sig[k * nwl + l] = sg;
				}
			}
}

/* The fixtures of the lnf:bright and lobe-gate tests, fitted: the dim rt_truth on a 4×4×6 grid (bright 0) or the
 * glossy lobe_samples (bright 1), L wavelengths. */
static struct recon_model *dim_or_glossy_fit(int bright, size_t L)
{
	struct recon_samples smp;
	if (bright)
		lobe_samples(&smp, L);
	else
		rt_samples_grid(&smp, 4, 4, 6, L, 0.01, 1.0);
	return fit_free(&smp, NULL);
}

/* lnf:bright (session 16): per grid cell the larger of the projected measure ∫cell cosθi cosθo dωi dωo and lnf:rad's
 * unnormalised weight ω_x · mean_λ (d_λ c / (1 + f̂_λ c))² / amp[x]² (the formula of test_lnf_rad: both a squared error
 * of g per unit P over the cell), normalised; value and variances are lnf's. rt_truth (f̂ ≤ 1 sr⁻¹) is dim everywhere:
 * the weights are lnf's projected ones (to 1e-12: the same measure, summed in another order); on lobe_samples' glossy
 * model some cells take the rad weight and others not (both branches). Seen
 * failing with the projected measure normalised before the max (largest relative difference 0.26,
 * glossy). */
static void test_lnf_bright(void **state)
{
	(void)state;
	rt_seed();
	size_t L = 16, nc = 40;
	for (int bright = 0; bright < 2; bright++) {
		struct recon_model *m = dim_or_glossy_fit(bright, L);
		double ang[40 * 4], cost[40];
		struct fix fp, fb;
		lnf_pair(m, nc, ang, cost, &fp, &fb, "lnf:bright");
		struct sel *s = &fb.s;
		size_t F = s->F, nrad = 0;
		assert_true(fb.t.lnf_rad == 3 && F == fp.s.F && fb.r.value == fp.r.value);
		for (size_t x = 0; x < F; x++)
			assert_true(s->v[x] == fp.s.v[x]);
		double *f = malloc(F * L * sizeof *f), *want = malloc(F * sizeof *want), abar = 0, sw = 0;
		double h = 5 * M_PI / 180, tmax = 80 * M_PI / 180, dp = 20 * M_PI / 180;
		assert_int_equal(recon_eval(m, F, s->xang, f, &fb.e), 0);
		for (size_t l = 0; l < L; l++)
			abar += s->alpha[l] / (double)L;
		for (size_t x = 0; x < F; x++) {
			const double *a = s->xang + 4 * x;
			double c6[6], lo_i = fmax(a[0] - h, 0), hi_i = fmin(a[0] + h, tmax), lo_o = fmax(a[2] - h, 0),
					hi_o = fmin(a[2] + h, tmax);
			rbf_canon(a[0], a[1], a[2], a[3], c6);
			double wp = a[0] == 0 ? M_PI : (fabs(a[3]) < 1e-12 || fabs(a[3] - M_PI) < 1e-12 ? 0.5 * dp : dp);
			double two = a[2] > a[0] + 1e-12 ? 2 : 1, c = cos(a[0]) * cos(a[2]);
			double omega = (cos(lo_i) - cos(hi_i)) * (cos(lo_o) - cos(hi_o)) * wp * two;
			double proj = 0.25 * (pow(sin(hi_i), 2) - pow(sin(lo_i), 2)) * (pow(sin(hi_o), 2) - pow(sin(lo_o), 2)) * wp * two;
			double u = recon_unseen(recon_nearest_centre(m, c6, NULL)), acc = 0;
			for (size_t l = 0; l < L; l++) {
				double fl = f[x * L + l], sc = recon_energy_scale(m, a[0], a[2], l);
				double e = (fl + sc * m->eps[l]) * sqrt(s->alpha[l] + u * RECON_PRIOR_ALPHA) * c / (1 + fl * c);
				acc += e * e / (double)L;
			}
			double rad = omega * acc / (abar + u * RECON_PRIOR_ALPHA);
			nrad += rad > proj;
			want[x] = fmax(rad, proj);
			sw += want[x];
		}
		double worst = 0, worst_p = 0;
		for (size_t x = 0; x < F; x++) {
			worst = fmax(worst, fabs(s->xw[x] - want[x] / sw) / (want[x] / sw));
			worst_p = fmax(worst_p, fabs(s->xw[x] - fp.s.xw[x]) / fp.s.xw[x]);
		}
		printf("lnf:bright (%s): weights vs max(projected, rad) normalised: largest relative difference %.3g; "
		       "%zu of %zu cells take the rad weight; vs lnf's weights %.3g\n", bright ? "glossy" : "rt_truth", worst, nrad, F, worst_p);
		assert_true(worst <= 1e-9);
		if (bright)
			assert_true(nrad > 0 && nrad < F);
		else
			assert_true(nrad == 0 && worst_p <= 1e-12);
		free(f);
		free(want);
		fix_free(&fp);
		fix_free(&fb);
		struct select_result r;
		size_t p0 = pick1(m, nc, ang, cost, "lnf:bright", 2, &r);
		assert_true(p0 < nc && r.npicks == 2);
		assert_int_equal(r.nbright, nrad); /* the count select reports (brdf-recon select's bright_cells) */
		select_result_free(&r);
		recon_model_free(m);
	}
}

/* The lobe gate (select_target.lobe_above_deg, session 17): 40 random candidates (θ ≤ 60°) with 24 above the bound
 * 70° interleaved (at incidences 75° and 80°: the mirror direction, 6 directions 2–7° around it, 5 far from it).
 * sel_lobe_gate keeps exactly those of the direct rule (lnf:bright's at the pair: mean_λ (d_λ c/(1 + f̂_λ c))²/amp² >
 * c, d and amp as test_lnf_bright's, through recon_eval); select_batch with the gate (lnf:bright, a route, batch 4)
 * picks bit for bit what it picks without the gate on the candidates the gate keeps (the test's own compaction, the
 * route's arrays too), indices mapped back. rt_truth (dim): none kept, so the gate gives the picks of the candidates
 * at or below the bound alone (the session's default plan, candidates to 70°); glossy (lobe_samples, sampled at 75°):
 * some kept near the mirror, none far from it. Seen failing with the rule's c halved (glossy: 3 candidates
 * more than the direct rule) and with the route passed uncompacted (the picks differ). */
static void test_lobe_gate(void **state)
{
	(void)state;
	rt_seed();
	enum { NB = 40, NG = 24, NC = NB + NG };
	size_t L = 16;
	for (int bright = 0; bright < 2; bright++) {
		struct recon_model *m = dim_or_glossy_fit(bright, L);
		double ang[NC * 4], cost[NC], below[NB * 4], bcost[NB], pos[NC * 3], base[NC], open[NC];
		unsigned char above[NC], far[NC];
		random_cands(NB, below, bcost);
		for (size_t j = 0; j < NB; j++) /* θ ≤ 60°: acos(0.5 + 0.5 u) */
			for (int k = 0; k < 4; k += 2)
				below[4 * j + k] = acos(0.5 + 0.5 * (cos(below[4 * j + k]) - 0.26) / 0.74);
		size_t ib = 0, ig = 0;
		for (size_t j = 0; j < NC; j++) {
			double *a = ang + 4 * j;
			above[j] = j % 8 >= 5 && ig < NG; /* 3 of every 8 above the bound */
			far[j] = 0;
			if (above[j]) {
				size_t g = ig++, r = g % 12;
				double ti = g < 12 ? 75 : 80, d = r == 0 ? 0 : r <= 6 ? 2 + (double)(r - 1) : 0;
				a[0] = ti * M_PI / 180;
				a[1] = 0;
				if (r <= 6) { /* the mirror direction and 2–7° around it, in and across the plane */
					a[2] = fmin(ti + (r % 2 ? d : -d * 0.5), 85) * M_PI / 180;
					a[3] = (180 + (r % 2 ? 0 : 1.5 * d)) * M_PI / 180;
				} else { /* far from it */
					far[j] = 1;
					a[2] = (10 + 12.0 * (double)(r - 7)) * M_PI / 180;
					a[3] = 40.0 * (double)(r - 7) * M_PI / 180;
				}
				cost[j] = 3 + 0.1 * (double)r;
			} else {
				assert_true(ib < NB);
				memcpy(a, below + 4 * ib, 4 * sizeof *a);
				cost[j] = bcost[ib++];
			}
			pos[3 * j] = a[0] * 180 / M_PI;
			pos[3 * j + 1] = a[2] * 180 / M_PI;
			pos[3 * j + 2] = fmod(a[3] * 180 / M_PI + 100, 360);
			base[j] = 2 + 0.01 * (double)(j % 7);
			open[j] = 3;
		}
		assert_true(ib == NB && ig == NG);
		/* the direct rule */
		struct fix fa;
		fix_make(&fa, m, NC, ang, cost, "lnf", 1);
		double f[NC * 16], abar = 0;
		struct acq_err e = { 0 };
		assert_int_equal(recon_eval(m, NC, ang, f, &e), 0);
		for (size_t l = 0; l < L; l++)
			abar += fa.s.alpha[l] / (double)L;
		unsigned char want[NC], keep[NC];
		size_t nwant = 0, nnear = 0, nfar = 0;
		for (size_t j = 0; j < NC; j++) {
			want[j] = 1;
			if (!above[j])
				continue;
			const double *a = ang + 4 * j;
			double c6[6], c = cos(a[0]) * cos(a[2]), acc = 0;
			rbf_canon(a[0], a[1], a[2], a[3], c6);
			double u = recon_unseen(recon_nearest_centre(m, c6, NULL));
			for (size_t l = 0; l < L; l++) {
				double fl = f[j * L + l], sc = recon_energy_scale(m, a[0], a[2], l);
				double x = (fl + sc * m->eps[l]) * sqrt(fa.s.alpha[l] + u * RECON_PRIOR_ALPHA) * c / (1 + fl * c);
				acc += x * x / (double)L;
			}
			double r = acc / (abar + u * RECON_PRIOR_ALPHA);
			assert_true(fabs(r / c - 1) > 1e-6); /* no tie the rounding could decide */
			want[j] = r > c;
			nwant += want[j];
			nnear += want[j] && !far[j];
			nfar += want[j] && far[j];
		}
		fix_free(&fa);
		size_t nb = 0, na = 0;
		assert_int_equal(sel_lobe_gate(m, 70 * M_PI / 180, NC, ang, keep, &nb, &na, NULL, &e), 0);
		printf("lobe gate (%s): %zu of %zu above 70° kept (direct rule %zu: %zu near the mirror, %zu far)\n",
		       bright ? "glossy" : "rt_truth", na, nb, nwant, nnear, nfar);
		assert_true(nb == NG && na == nwant);
		for (size_t j = 0; j < NC; j++)
			assert_int_equal(keep[j], want[j]);
		if (bright)
			assert_true(nnear > 0 && nfar == 0);
		else
			assert_true(nwant == 0);
		/* the gate's picks = the picks on the kept candidates alone (the test's compaction) */
		double ak[NC * 4], ck[NC], pk[NC * 3], bk[NC], ok[NC];
		size_t idx[NC], nk = 0;
		for (size_t j = 0; j < NC; j++)
			if (want[j]) {
				memcpy(ak + 4 * nk, ang + 4 * j, 4 * sizeof *ak);
				memcpy(pk + 3 * nk, pos + 3 * j, 3 * sizeof *pk);
				ck[nk] = cost[j];
				bk[nk] = base[j];
				ok[nk] = open[j];
				idx[nk++] = j;
			}
		struct select_route rt = { .pos = pos, .base = base, .open = open, .from = { 0, 40, 100 },
					   .speed = { 10, 20, 30 }, .accel = { 20, 60, 90 }, .settle = { 0.3, 0.2, 0.2 },
					   .move_s = 0.075 };
		struct select_route rk = rt;
		rk.pos = pk;
		rk.base = bk;
		rk.open = ok;
		struct fix fg, fp;
		fix_spec(&fg, "lnf:bright:le=1e-9:lobe_above=70");
		fix_spec(&fp, "lnf:bright:le=1e-9");
		assert_true(fg.t.lobe_above_deg == 70 && fp.t.lobe_above_deg == 0);
		fg.o.batch = fp.o.batch = 4;
		fg.o.route = &rt;
		fp.o.route = &rk;
		struct select_result rg, rp;
		assert_int_equal(select_batch(m, NC, ang, cost, &fg.t, &fg.o, &rg, &fg.e), 0);
		assert_int_equal(select_batch(m, nk, ak, ck, &fp.t, &fp.o, &rp, &fp.e), 0);
		printf("lobe gate (%s): picks", bright ? "glossy" : "rt_truth");
		assert_true(rg.npicks == 4 && rp.npicks == 4 && rg.nbeyond == NG && rg.nadmitted == nwant);
		for (size_t k = 0; k < rg.npicks; k++) {
			printf(" %zu", rg.picks[k].index);
			assert_int_equal(rg.picks[k].index, idx[rp.picks[k].index]);
			assert_true(rg.picks[k].gain == rp.picks[k].gain && rg.picks[k].cost == rp.picks[k].cost &&
				    rg.picks[k].predicted == rp.picks[k].predicted);
		}
		printf("\n");
		assert_true(rg.value == rp.value && rg.nunique == rp.nunique);
		select_result_free(&rg);
		select_result_free(&rp);
		recon_model_free(m);
	}
}

/* The energy prior after a pick (recon/select_prior.c, session 10): a 6 × 6 × 8 grid of rt_truth with every sample
 * within 0.45 (chordal) of the 30° mirror point removed leaves that mirror unseen (p = 1: σ_E is σ_model there).
 * A candidate at the mirror must be predicted to lower σ_E to what dhr.c gives the model refitted with that sample
 * (within a factor 2 in σ), and be picked with a predicted value below the current one; σ_E as a floor (before:
 * the GP part's update only) predicts no fall: fails. */
static void test_prior_after_pick(void **state)
{
	(void)state;
	rt_seed();
	struct recon_samples g, s;
	rt_samples_grid(&g, 6, 6, 8, NWL, 0.01, 1.0);
	double th = 30 * M_PI / 180, mir[6], tmir[6], c[6];
	rbf_canon(th, 0, th, M_PI, mir);
	rbf_tau(mir, tmir);
	size_t keep[6 * 6 * 8], n = 0;
	for (size_t k = 0; k < g.n; k++) {
		const double *a = g.ang + 4 * k;
		rbf_canon(a[0], a[1], a[2], a[3], c);
		double d1 = 0, d2 = 0;
		for (int i = 0; i < 6; i++) {
			d1 += (c[i] - mir[i]) * (c[i] - mir[i]);
			d2 += (c[i] - tmir[i]) * (c[i] - tmir[i]);
		}
		if (sqrt(fmin(d1, d2)) >= 0.45)
			keep[n++] = k;
	}
	rt_samples_alloc(&s, n + 1, NWL, 1);
	memcpy(s.wl, g.wl, NWL * sizeof *s.wl);
	for (size_t i = 0; i < n; i++) {
		memcpy(s.ang + 4 * i, g.ang + 4 * keep[i], 4 * sizeof *s.ang);
		memcpy(s.deg + 4 * i, g.deg + 4 * keep[i], 4 * sizeof *s.deg);
		memcpy(s.val + NWL * i, g.val + NWL * keep[i], NWL * sizeof *s.val);
		memcpy(s.sig + NWL * i, g.sig + NWL * keep[i], NWL * sizeof *s.sig);
	}
	csvio_samples_free(&g);
	s.n = n;
	struct recon_model *m = NULL, *m2 = NULL;
	struct acq_err e = { 0 };
	assert_int_equal(recon_fit(&s, NULL, &m, &e), 0);
	double ang[8] = { th, 0, th, M_PI, th, 0, 60 * M_PI / 180, M_PI / 2 }, cost[2] = { 1, 1 };
	struct fix f;
	fix_make(&f, m, 2, ang, cost, "dhr:30", 1);
	struct sel *sl = &f.s;
	assert_non_null(sl->prior);
	size_t jA = sl->rep[0] == 0 ? 0 : 1;
	/* the refit with candidate A measured: its σ_E per tracked channel */
	memcpy(s.ang + 4 * n, ang, 4 * sizeof *s.ang);
	for (int i = 0; i < 4; i++)
		s.deg[4 * n + i] = ang[i] * 180 / M_PI;
	for (size_t l = 0; l < NWL; l++) {
		double v = rt_truth(ang, s.wl[l], 1.0), sg = 0.01 * v + 1e-4;
		s.val[NWL * n + l] = v + sg * rt_normal();
		s.sig[NWL * n + l] = sg;
	}
	s.n = n + 1;
	assert_int_equal(recon_fit(&s, NULL, &m2, &e), 0);
	double d0[NWL], sg0[NWL], en0[NWL], d1[NWL], sg1[NWL], en1[NWL];
	struct recon_dhr_parts p0 = { .energy = en0 }, p1 = { .energy = en1 };
	assert_int_equal(recon_dhr_parts(m, 1, &th, 16, 1, d0, sg0, &p0, NULL, NULL, &e), 0);
	assert_int_equal(recon_dhr_parts(m2, 1, &th, 16, 1, d1, sg1, &p1, NULL, NULL, &e), 0);
	for (size_t k = 0; k < sl->Lc; k++) {
		size_t l = sl->chan[k];
		double now = sqrt(sel_prior_e2(sl, 0, k, SIZE_MAX)), pred = sqrt(sel_prior_e2(sl, 0, k, jA));
		printf("  %4.0f nm: σ_E %.4f (dhr %.4f), predicted with the mirror sample %.4f, refitted with it %.4f\n",
		       s.wl[l], now, en0[l], pred, en1[l]);
		assert_true(fabs(now - en0[l]) <= 1e-12 * (1 + en0[l]));
		assert_true(pred < 0.5 * now);
		assert_true(pred <= 2 * en1[l] && en1[l] <= 2 * pred);
	}
	fix_free(&f);
	struct select_result r;
	assert_int_equal(pick1(m, 2, ang, cost, "dhr:30", 1, &r), 0);
	printf("prior after a pick: value %.4f, predicted after the mirror pick %.4f\n", r.per[0], r.picks[0].predicted);
	assert_true(r.picks[0].predicted < 0.7 * r.per[0]);
	select_result_free(&r);
	recon_model_free(m);
	recon_model_free(m2);
	csvio_samples_free(&s);
}

/* The fast path against the reference (select_opts.reference), on 300 candidates (three blocks of SEL_JB):
 * sel_excess_all gives every candidate's criterion with the same bits as sel_excess (DHR with its prior and resolution
 * terms and half its functionals on their noise floor; ln f; RGB), after 0, 1 and 2 picks; the DHR functionals' covariances Z formed by blocks of
 * candidates equal Cᵀ K_QJ − Bᵀ K_nJ with every kernel value computed afresh (rbf_kernel); select_batch picks the
 * same candidates with the same gains, charges and predictions either way (a combined target, whose parts share the
 * candidates' set-up on the fast path, with a route; the RGB target); the fast path lends its DHR rule's kernel rows
 * to recon_dhr_parts (parts.kq), the reference path lets it build its own: the same value (seen failing with the
 * lent rows misplaced per incidence, session 13). */
#define FAST_NC 300
static void test_fast_path(void **state)
{
	(void)state;
	struct toy ty;
	struct recon_model *m = toy_start(&ty, 0);
	double *ang = malloc(FAST_NC * 4 * sizeof *ang), *cost = malloc(FAST_NC * sizeof *cost);
	random_cands(FAST_NC, ang, cost);
	const char *specs[] = { "dhr:8,60:le=1e-9", "lnf:le=1e-9", "rgb:le=1e-9" };
	for (size_t sp = 0; sp < 3; sp++) {
		struct fix f;
		fix_make(&f, m, FAST_NC, ang, cost, specs[sp], 3);
		struct sel *s = &f.s;
		size_t J = s->J, n = s->n, Lc = s->Lc, bad = 0;
		assert_true(J > 2 * SEL_JB);
		if (sp == 0) { /* Z's first incidence (8°) from fresh kernel values */
			struct dcoef dc;
			dcoef_make(&dc, s, 8, &f.e);
			size_t Q = (size_t)SEL_NMU * SEL_NPHI;
			double *B = calloc(Lc * n, sizeof *B), *kq = malloc(Q * sizeof *kq), *kn = malloc(n * sizeof *kn),
			       worst = 0;
			for (size_t c = 0; c < Lc; c++)
				for (size_t k = 0; k < n; k++)
					for (size_t q = 0; q < Q; q++)
						B[c * n + k] += dc.KQn[q * n + k] * dc.C[q * Lc + c];
			assert_int_equal(LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)Lc, s->A,
							(lapack_int)n, B, (lapack_int)n), 0);
			for (size_t j = 0; j < J; j++) {
				for (size_t q = 0; q < Q; q++)
					kq[q] = kern(m, dc.c6 + 6 * q, s->cu + 6 * j);
				for (size_t k = 0; k < n; k++)
					kn[k] = kern(m, m->ctr + 6 * k, s->cu + 6 * j);
				for (size_t c = 0; c < Lc; c++) {
					double z = 0, scale = 0;
					for (size_t q = 0; q < Q; q++) {
						z += dc.C[q * Lc + c] * kq[q];
						scale += fabs(dc.C[q * Lc + c] * kq[q]);
					}
					for (size_t k = 0; k < n; k++) {
						z -= B[c * n + k] * kn[k];
						scale += fabs(B[c * n + k] * kn[k]);
					}
					worst = fmax(worst, fabs(s->Z[c * J + j] - z) / scale);
				}
			}
			printf("fast path: DHR Z by blocks of %d candidates vs fresh kernel values: largest |Δ| / scale %.3g\n",
			       SEL_JB, worst);
			assert_true(worst <= 1e-12);
			free(B);
			free(kq);
			free(kn);
			dcoef_free(&dc);
		}
		if (sp == 0) /* half the functionals on their noise floor (its predicted fall then counts) */
			for (size_t x = 0; x < s->F; x += 2)
				s->sn2[x] = 100 * (s->v[x] + 1e-30);
		double *ex = malloc(J * sizeof *ex), *acc = malloc(J * sizeof *acc);
		for (size_t k = 0; k < 3; k++) {
			sel_excess_all(s, ex, acc);
			double E = sel_excess(s, SIZE_MAX, NULL), bg = -1;
			size_t best = 0;
			for (size_t j = 0; j < J; j++) {
				if (s->picked[j])
					continue;
				double r = sel_excess(s, j, NULL);
				bad += memcmp(&r, &ex[j], sizeof r) != 0;
				if (E - r > bg) {
					bg = E - r;
					best = j;
				}
			}
			if (k < 2)
				sel_update(s, best, k);
		}
		printf("fast path: %s: %zu of 3 x %zu criteria differ from sel_excess in any bit\n", specs[sp], bad, J);
		assert_int_equal(bad, 0);
		free(ex);
		free(acc);
		fix_free(&f);
	}
	/* select_batch: fast and reference paths */
	double *pos = malloc(FAST_NC * 3 * sizeof *pos), *base = malloc(FAST_NC * sizeof *base),
	       *open = malloc(FAST_NC * sizeof *open);
	for (size_t j = 0; j < FAST_NC; j++) {
		pos[3 * j] = ang[4 * j] * 180 / M_PI;
		pos[3 * j + 1] = ang[4 * j + 2] * 180 / M_PI;
		pos[3 * j + 2] = ang[4 * j + 3] * 180 / M_PI;
		base[j] = 0.2 * cost[j];
		open[j] = 1;
	}
	struct select_route rt = { .pos = pos, .base = base, .open = open, .from = { 0, 40, 100 },
				   .speed = { 10, 20, 30 }, .accel = { 20, 60, 90 }, .settle = { 0.3, 0.2, 0.2 },
				   .move_s = 0.075 };
	const char *bspecs[] = { "dhr:8,60:le=1e-9+lnf:le=1e-9", "rgb:le=1e-9" };
	for (size_t sp = 0; sp < 2; sp++) {
		struct fix f;
		fix_spec(&f, bspecs[sp]);
		f.o.batch = 6;
		f.o.route = sp == 0 ? &rt : NULL;
		struct select_result rf, rr;
		assert_int_equal(select_batch(m, FAST_NC, ang, cost, &f.t, &f.o, &rf, &f.e), 0);
		f.o.reference = 1;
		assert_int_equal(select_batch(m, FAST_NC, ang, cost, &f.t, &f.o, &rr, &f.e), 0);
		printf("fast path: %s: %zu picks (reference %zu), first %zu, last %zu\n", bspecs[sp], rf.npicks, rr.npicks,
		       rf.picks[0].index, rf.picks[rf.npicks - 1].index);
		assert_int_equal(rf.npicks, 6);
		assert_int_equal(rf.npicks, rr.npicks);
		assert_true(rf.value == rr.value && rf.nunique == rr.nunique);
		for (size_t k = 0; k < rf.npicks; k++) {
			const struct select_pick *a = &rf.picks[k], *b = &rr.picks[k];
			assert_int_equal(a->index, b->index);
			assert_true(a->gain == b->gain && a->cost == b->cost && a->predicted == b->predicted);
			assert_memory_equal(a->predicted_per, b->predicted_per, sizeof a->predicted_per);
		}
		select_result_free(&rf);
		select_result_free(&rr);
	}
	free(pos);
	free(base);
	free(open);
	free(ang);
	free(cost);
	recon_model_free(m);
}

/* The DHR's σ parts of recon_dhr_parts at th[2] with parts.gp_A/gp_Ainv = A, Ai (NULL: built there) into out[7][2L]
 * (σ, noise, model, kriging, energy, quad, res); returns the largest |Δ| / |ref| over them against ref (NULL: 0). */
#define LENT_NP 7
static double lent_sigma(const struct recon_model *m, const double *th, const double *A, const double *Ai, double *out,
			 const double *ref)
{
	size_t NL = 2 * m->nwl;
	double *dhr = malloc(NL * sizeof *dhr);
	struct recon_dhr_parts p = { .noise = out + NL, .model = out + 2 * NL, .kriging = out + 3 * NL,
				     .energy = out + 4 * NL, .quad = out + 5 * NL, .res = out + 6 * NL, .gp_A = A,
				     .gp_Ainv = Ai };
	struct acq_err e = { 0 };
	assert_int_equal(recon_dhr_parts(m, 2, th, 16, 7, dhr, out, &p, NULL, NULL, &e), 0);
	double worst = 0;
	for (size_t i = 0; ref && i < LENT_NP * NL; i++)
		if (out[i] != ref[i])
			worst = fmax(worst, fabs(out[i] - ref[i]) / fmax(fabs(ref[i]), 1e-300));
	free(dhr);
	return worst;
}

/* select lends its factor of K + ηΛ and the inverse (sel_factor, recon_gp_setup's) to recon_dhr_parts (parts.gp_A,
 * gp_Ainv), which otherwise factors the same system again: (1) the DHR's σ and every part of it (16 noise draws, which
 * solve with the factor; the kriging part, whose amplitude comes from the inverse's diagonal) equal the fresh path's
 * to 1e-12 relative, and they move when the lent factor or the inverse is perturbed by 1e-3 on its diagonal (a wrong
 * factor is seen); (2) select on a channel subset (the sub-model, which gets the whole model's factor) with noise
 * draws and the value recomputed on all channels: the fast path (lent) gives the reference path's (built in
 * recon_dhr_parts) value, per-incidence values and σ parts to the bit. Seen failing with select lending its factor
 * as the inverse (test_value_channels then too), session 14. */
static void test_lent_factor(void **state)
{
	(void)state;
	rt_seed();
	size_t L = 40, NL = 2 * L;
	struct recon_model *m = rgb_model(4, 4, 6, L);
	size_t n = m->n;
	double th[2] = { 8 * M_PI / 180, 40 * M_PI / 180 };
	double *A = malloc(n * n * sizeof *A), *Ai = malloc(n * n * sizeof *Ai), *alpha = malloc(L * sizeof *alpha);
	double *ref = malloc(LENT_NP * NL * sizeof *ref), *out = malloc(LENT_NP * NL * sizeof *out);
	struct acq_err e = { 0 };
	assert_int_equal(recon_gp_setup(m, "test", A, Ai, alpha, &e), 0);
	lent_sigma(m, th, NULL, NULL, ref, NULL);
	double same = lent_sigma(m, th, A, Ai, out, ref);
	for (size_t i = 0; i < NL; i++) /* every σ and its kriging part non-zero: the comparison compares something */
		assert_true(ref[i] > 0 && ref[3 * NL + i] > 0 && isfinite(ref[i]));
	for (size_t k = 0; k < n; k++)
		A[k * n + k] *= 1 + 1e-3;
	double badA = lent_sigma(m, th, A, Ai, out, ref);
	for (size_t k = 0; k < n; k++) {
		A[k * n + k] /= 1 + 1e-3;
		Ai[k * n + k] *= 1 + 1e-3;
	}
	double badAi = lent_sigma(m, th, A, Ai, out, ref);
	printf("lent factor: largest relative difference of the σ parts from the fresh path's %.3g; factor's diagonal "
	       "+1e-3: %.3g; inverse's diagonal +1e-3: %.3g\n", same, badA, badAi);
	assert_true(same <= 1e-12);
	assert_true(badA > 1e-6 && badAi > 1e-6);
	/* (2) select: fast (lent) vs reference path on a channel subset, noise draws on */
	const char *spec = "dhr:8,40:le=1"; /* far below the value: recomputed on all channels (SEL_VALUE_CHECK) */
	struct fix f[2];
	for (int ref_path = 0; ref_path < 2; ref_path++) {
		fix_spec(&f[ref_path], spec);
		f[ref_path].o.batch = 0;
		f[ref_path].o.nvalue = 30;
		f[ref_path].o.reference = ref_path;
		fix_sel(&f[ref_path], m, 0, NULL, NULL);
	}
	const struct sel *a = &f[0].s, *b = &f[1].s;
	printf("lent factor: select on 30 of %zu channels, value %.9g (reference %.9g), checked on all %d\n", L,
	       f[0].r.value, f[1].r.value, f[0].r.value_checked);
	assert_int_equal(f[0].r.value_checked, 1);
	assert_true(f[0].r.value == f[1].r.value);
	assert_memory_equal(f[0].r.per, f[1].r.per, sizeof f[0].r.per);
	assert_memory_equal(a->v, b->v, a->F * sizeof *a->v);
	assert_memory_equal(a->sn2, b->sn2, a->F * sizeof *a->sn2);
	assert_memory_equal(a->rest, b->rest, a->F * sizeof *a->rest);
	assert_memory_equal(a->kappa, b->kappa, a->nth * sizeof *a->kappa);
	fix_free(&f[0]);
	fix_free(&f[1]);
	free(A);
	free(Ai);
	free(alpha);
	free(ref);
	free(out);
	recon_model_free(m);
}

/* recon_big_alloc (select's rows and posterior arrays): any size usable to its last byte, an array of at least
 * RECON_BIG_PAGE aligned to it (the huge page advice needs the alignment; whether the kernel then gives huge pages is
 * its choice, not checked here). */
static void test_big_alloc(void **state)
{
	(void)state;
	size_t sizes[] = { 0, 1, 4096, RECON_BIG_PAGE - 1, RECON_BIG_PAGE, 3 * RECON_BIG_PAGE + 5 };
	for (size_t i = 0; i < sizeof sizes / sizeof *sizes; i++) {
		unsigned char *p = recon_big_alloc(sizes[i]);
		assert_non_null(p);
		if (sizes[i] >= RECON_BIG_PAGE)
			assert_int_equal((uintptr_t)p % RECON_BIG_PAGE, 0);
		memset(p, 0xa5, sizes[i]);
		for (size_t k = 0; k < sizes[i]; k += 4093)
			assert_int_equal(p[k], 0xa5);
		free(p);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_rank_one_lnf),    cmocka_unit_test(test_rank_one_dhr),
		cmocka_unit_test(test_known_information), cmocka_unit_test(test_cost_weighting),
		cmocka_unit_test(test_reciprocity),     cmocka_unit_test(test_extremes),
		cmocka_unit_test(test_rgb_target),      cmocka_unit_test(test_value_channels),
		cmocka_unit_test(test_target_parse),     cmocka_unit_test(test_noise_fall),
		cmocka_unit_test(test_combined_target), cmocka_unit_test(test_route_increment),
		cmocka_unit_test(test_lnf_measure),     cmocka_unit_test(test_lnf_rad), cmocka_unit_test(test_lnf_mix),
		cmocka_unit_test(test_lnf_bright),      cmocka_unit_test(test_lobe_gate),
		cmocka_unit_test(test_prior_after_pick), cmocka_unit_test(test_fast_path),
		cmocka_unit_test(test_lent_factor),     cmocka_unit_test(test_big_alloc),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
