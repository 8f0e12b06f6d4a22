/* select: greedy choice of the next measurements by expected variance reduction of the target per second of
 * bench time, with a rank-one update of the Gaussian-process posterior between picks. */
#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/colour.h"
#include "recon/merl.h"
#include "recon/recon_int.h"
#include "recon/select.h"

/* The DHR's fixed rule (dhr.c: the GP part of its σ is computed on it). */
#define SEL_NMU 32
#define SEL_NPHI 48
/* A candidate at a sampled incidence zeroes the DHR's resolution term there (dhr.c: within 0.25°). */
#define SEL_RES_TOL (0.25 * M_PI / 180)
/* value channels: a value within this factor of the threshold is recomputed on all channels, so the stop decision
 * never rests on the subset (white at ACQ_SEED=3: the 1100 nm edge channel, σ 0.068, weighs 1/64 in the subset
 * against 1/651: 0.0087 on 64 channels, 0.0040 on all) */
#define SEL_VALUE_CHECK 4.0
/* Canonical points this close (unit-vector coordinates) are the same measurement. */
#define SEL_SAME 1e-9
/* The ln f target's grid: θ up to 80° (beyond, no bench reaches and the prior alone speaks). */
#define LNF_TMAX 80
#define LNF_TSTEP 10
#define LNF_PSTEP 20
/* The RGB target's nodes: a 12 × 12 × 12 subset of the MERL table's cells (θh, θd, φd indices, cell centres). */
#define RGB_NODES 12

void select_opts_default(struct select_opts *o)
{
	o->batch = 16;
	o->ndraws = 16;
	o->seed = 1;
	o->nchan = 24;
	o->nvalue = 0;
}

void select_result_free(struct select_result *r)
{
	free(r->picks);
	r->picks = NULL;
	r->npicks = 0;
}

static int parse_num(const char *s, const char *end, double *out)
{
	char buf[64];
	size_t len = (size_t)(end - s);
	if (len == 0 || len >= sizeof buf)
		return -1;
	memcpy(buf, s, len);
	buf[len] = '\0';
	char *e;
	double v = strtod(buf, &e);
	if (*e || !isfinite(v))
		return -1;
	*out = v;
	return 0;
}

static int target_parse_one(const char *spec, struct select_target *t, struct acq_err *err);

int select_target_parse(const char *spec, struct select_target *t, struct acq_err *err)
{
	const char *plus = spec ? strchr(spec, '+') : NULL;
	if (!plus)
		return target_parse_one(spec, t, err);
	char first[512];
	struct select_target t2;
	if ((size_t)(plus - spec) >= sizeof first)
		return acq_errf(err, ACQ_E_INVAL, "target '%s': too long", spec);
	memcpy(first, spec, (size_t)(plus - spec));
	first[plus - spec] = '\0';
	if (target_parse_one(first, t, err) || target_parse_one(plus + 1, &t2, err))
		return -1;
	if (t->kind != SELECT_DHR || t2.kind != SELECT_LNF || !isfinite(t->threshold) || !isfinite(t2.threshold))
		return acq_errf(err, ACQ_E_INVAL, "target '%s': a combined target is dhr:THETA[,...]:le=X+lnf:le=Y (both "
				"thresholds given: both must be met)", spec);
	t->lnf_threshold = t2.threshold;
	return 0;
}

static int target_parse_one(const char *spec, struct select_target *t, struct acq_err *err)
{
	memset(t, 0, sizeof *t);
	t->threshold = NAN;
	if (!spec || !*spec)
		return acq_errf(err, ACQ_E_INVAL, "target: empty (dhr:8,30,60, lnf or rgb, optionally :le=X)");
	const char *p = spec, *le = strstr(spec, ":le=");
	const char *body_end = le ? le : spec + strlen(spec);
	if (le) {
		const char *x = le + 4;
		if (parse_num(x, x + strlen(x), &t->threshold) || !(t->threshold > 0))
			return acq_errf(err, ACQ_E_INVAL, "target '%s': le= needs a positive number", spec);
	}
	if ((size_t)(body_end - p) == 3 && !strncmp(p, "lnf", 3)) {
		t->kind = SELECT_LNF;
		return 0;
	}
	if ((size_t)(body_end - p) == 3 && !strncmp(p, "rgb", 3)) {
		t->kind = SELECT_RGB;
		return 0;
	}
	if (strncmp(p, "dhr:", 4) || body_end <= p + 4)
		return acq_errf(err, ACQ_E_INVAL, "target '%s': expected dhr:THETA[,THETA...], lnf or rgb, optionally :le=X",
				spec);
	t->kind = SELECT_DHR;
	for (const char *a = p + 4; a < body_end;) {
		const char *c = memchr(a, ',', (size_t)(body_end - a));
		const char *e = c ? c : body_end;
		double th;
		if (t->nth == SELECT_MAX_THETA)
			return acq_errf(err, ACQ_E_INVAL, "target '%s': at most %d incidences", spec, SELECT_MAX_THETA);
		if (parse_num(a, e, &th) || th < 0 || th > 90)
			return acq_errf(err, ACQ_E_INVAL, "target '%s': incidence '%.*s' is not a number of degrees in [0, 90]",
					spec, (int)(e - a), a);
		t->theta_deg[t->nth++] = th;
		a = c ? c + 1 : body_end;
		if (c && a == body_end)
			return acq_errf(err, ACQ_E_INVAL, "target '%s': empty incidence after ','", spec);
	}
	return 0;
}

/* The working state of one selection (see "Choosing the next measurements" in recon/reconstruction.md). */
struct sel {
	const struct recon_model *m;
	const struct select_target *t;
	size_t n, L, J, F, Lc, nth, batch;
	double noise;    /* η · median r: the noise of a new measurement relative to the kernel's amplitude */
	double thr2;     /* threshold², 0 without one */
	double *A;       /* [n*n] Cholesky factor of K + ηΛ (column-major, lower) */
	double *alpha;   /* [L] the GP amplitude per channel (leave-one-out) */
	size_t *chan;    /* [Lc] tracked channels */
	size_t *vchan;   /* SELECT_DHR: [LV] the channels the value is computed on (NULL: all L) */
	size_t LV;       /* their count (L without vchan) */
	size_t *cpos;    /* [Lc] each tracked channel's position among them */
	double *cu;      /* [J*6] unique candidates' canonical points */
	double *soaJ;    /* [6*J] same, structure of arrays */
	size_t *rep;     /* [J] input index of each unique candidate (the cheapest of its duplicates) */
	double *cost;    /* [J] */
	double *Kjn;     /* [J*n] k(candidate j, centre k) */
	double *G;       /* [J*n] A⁻¹ k_j (column j contiguous) */
	double *Pjj;     /* [J] posterior variance (unit amplitude) of g at candidate j */
	double *Z;       /* [F*J] posterior covariance of functional f with g at candidate j */
	double *v;       /* [F] posterior variance of functional f */
	double *U;       /* [batch*J] scaled posterior rows of the picks (the low-rank part of the update) */
	unsigned char *picked, *match; /* [J]; [nth*J] candidate j samples incidence t (SELECT_DHR) */
	/* SELECT_DHR: per (t, tracked channel): noise floor², the σ² parts the selection does not change, res² */
	double *sn2, *rest, *res2, *kappa;
	unsigned char *res_done; /* [nth] */
	double *xang;    /* SELECT_LNF, SELECT_RGB: [F*4] the grid's / nodes' pairs */
	double *xw;      /* SELECT_RGB: [F] the nodes' share of the table's projected measure (sum 1) */
	double *row, *zp; /* scratch of sel_update: [J], [F] */
	/* SELECT_DHR, the noise part's fall with n: the functional's linear noise variance q = Σ_k N_k h_k² under the
	 * GP's weights h = A⁻¹b (N_k = η λ_k, a new sample's = noise), tracked through the picks by the same block
	 * elimination as the posterior; the Monte-Carlo floor sn2 is predicted as sn2 · q/q0. */
	double *Nk;      /* [n] the samples' noise η λ_k */
	double *q, *q0, *qmin; /* [F] current, initial and smallest-so-far noise variance of each functional (the
			  * floor predicted never rises: an estimator may ignore a sample that would spread its weights) */
	double *X;       /* [F*J] Σ_k N_k h_fk w_jk over the current samples (w_j: candidate j's weights A⁻¹k_j) */
	double *Yn;      /* [J] Σ_k N_k w_jk² */
	double *Gc;      /* [J*n] w_j's part on the model's samples (the picks' parts in gn) */
	double *gn;      /* [batch*J] w_j's part on pick i */
	double *mrow, *gp; /* scratch: [J], [n] */
};

static void sel_free(struct sel *s)
{
	free(s->A);
	free(s->alpha);
	free(s->chan);
	free(s->vchan);
	free(s->cpos);
	free(s->cu);
	free(s->soaJ);
	free(s->rep);
	free(s->cost);
	free(s->Kjn);
	free(s->G);
	free(s->Pjj);
	free(s->Z);
	free(s->v);
	free(s->U);
	free(s->picked);
	free(s->match);
	free(s->sn2);
	free(s->rest);
	free(s->res2);
	free(s->kappa);
	free(s->res_done);
	free(s->xang);
	free(s->xw);
	free(s->row);
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

/* Factor K + ηΛ of the model and the leave-one-out amplitude α_λ of every channel (as dhr.c). */
static int sel_factor(struct sel *s, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, L = s->L;
	double *Ainv = malloc(n * n * sizeof *Ainv);
	s->A = malloc(n * n * sizeof *s->A);
	s->alpha = calloc(L, sizeof *s->alpha);
	if (!Ainv || !s->A || !s->alpha) {
		free(Ainv);
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
	}
	int rc = recon_gp_setup(m, "select", s->A, Ainv, s->alpha, err); /* dhr.c: the DHR's σ uses the same */
	free(Ainv);
	if (rc)
		return -1;
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
	s->Kjn = malloc(Jp * n * sizeof *s->Kjn);
	s->G = malloc(Jp * n * sizeof *s->G);
	s->Pjj = malloc(Jp * sizeof *s->Pjj);
	s->picked = calloc(Jp, 1);
	if (!s->soaJ || !s->Kjn || !s->G || !s->Pjj || !s->picked)
		return acq_errf(err, ACQ_E_NOMEM, "select: out of memory for %zu candidates", J);
	if (!J)
		return 0;
	rbf_soa(J, s->cu, s->soaJ);
	rbf_kmatrix_soa(m->kernel, m->shape, J, s->cu, n, m->soa, s->Kjn);
	memcpy(s->G, s->Kjn, J * n * sizeof *s->G);
	if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)J, s->A, (lapack_int)n, s->G,
			   (lapack_int)n) != 0)
		return acq_errf(err, ACQ_E_NUMERIC, "select: solve failed");
	for (size_t j = 0; j < J; j++) {
		double tc[6];
		rbf_tau(s->cu + 6 * j, tc);
		double p = rbf_kernel(m->kernel, m->shape, s->cu + 6 * j, s->cu + 6 * j, tc) -
			   cblas_ddot((int)n, s->Kjn + j * n, 1, s->G + j * n, 1);
		s->Pjj[j] = p > 0 ? p : 0;
	}
	return 0;
}

/* Z[f, j] = cov(φ_f, g(x_j)) − ... for functionals given by coefficients C[q*F' + f] over points c6[Q] (the
 * amplitude folded in): Z = Cᵀ K_QJ − (A⁻¹ K_nQ C)ᵀ K_nJ, rows f0..f0+F'-1 of s->Z. */
static int sel_functionals(struct sel *s, size_t Q, const double *c6, const double *KQn, const double *C, size_t Fp,
			   size_t f0, double *KQJ, struct acq_err *err)
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
	rbf_kmatrix_soa(m->kernel, m->shape, Q, c6, J, s->soaJ, KQJ);
	cblas_dgemm(CblasRowMajor, CblasTrans, CblasNoTrans, (int)Fp, (int)J, (int)Q, 1.0, C, (int)Fp, KQJ, (int)J, 0.0,
		    Z, (int)J);
	cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)Fp, (int)J, (int)n, -1.0, B, (int)n, s->Kjn, (int)n,
		    1.0, Z, (int)J);
	free(B);
	return 0;
}

/* The DHR functional at incidence th on the tracked channels: the fixed rule's nodes c6[Q*6] and weights wt[Q],
 * the kernel rows KQn[Q*n], and C[q*Lc + c] = weight × energy factor × df̂/dg at the model × √(α_λ + unseen
 * prior), as dhr.c's σ_model (scratch Y[Q*Lc], Wc[Lc*n]). */
static int sel_dhr_coef(const struct sel *s, double th, double *c6, double *wt, double *KQn, double *Y, double *Wc,
			double *C, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, Lc = s->Lc, Q = (size_t)SEL_NMU * SEL_NPHI;
	for (size_t c = 0; c < Lc; c++)
		memcpy(Wc + c * n, m->w + s->chan[c] * n, n * sizeof *Wc);
	if (recon_hemi_nodes(th, SEL_NMU, SEL_NPHI, 0, c6, wt))
		return acq_errf(err, ACQ_E_INVAL, "select: quadrature");
	rbf_kmatrix_soa(m->kernel, m->shape, Q, c6, n, m->soa, KQn);
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
	return 0;
}

/* A view of m on its channels ch[0..k-1] only (the per-channel arrays copied, the directions and the factor's inputs
 * shared): what recon_dhr_parts needs for the value on a channel subset. sub_free releases what it allocated. */
static int sub_model(const struct recon_model *m, const size_t *ch, size_t k, struct recon_model *sub,
		     struct acq_err *err)
{
	size_t n = m->n, nt = m->ntab > 1 ? m->ntab - 1 : 0;
	*sub = *m;
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

/* The DHR value on all channels (the value channels' screening said it is near the threshold): r->per and the value
 * recomputed, each incidence's κ rescaled so predictions aim at the same value; r->value_checked set. 0 or -1. */
static int sel_value_all(struct sel *s, const double *th, const struct select_opts *o, struct select_result *r,
			 struct acq_err *err)
{
	size_t L = s->L, nth = s->nth, NL = nth * L;
	double *dhr = malloc(NL * sizeof *dhr), *sig = malloc(NL * sizeof *sig);
	int rc = -1;
	if (!dhr || !sig) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	if (recon_dhr_parts(s->m, nth, th, o->ndraws, o->seed, dhr, sig, NULL, NULL, NULL, err))
		goto out;
	r->value = 0;
	for (size_t t = 0; t < nth; t++) {
		double all = 0;
		for (size_t l = 0; l < L; l++)
			all += sig[t * L + l] * sig[t * L + l];
		all /= (double)L;
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
 * factor × df̂/dg × √(α_λ + unseen prior) at the DHR's fixed rule. */
static int sel_setup_dhr(struct sel *s, const struct select_opts *o, struct select_result *r, struct acq_err *err)
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
	double *c6 = malloc(Q * 6 * sizeof *c6), *wt = malloc(Q * sizeof *wt), *KQn = malloc(Q * n * sizeof *KQn);
	double *Y = malloc(Q * Lc * sizeof *Y), *C = malloc(Q * Lc * sizeof *C), *Wc = malloc(Lc * n * sizeof *Wc);
	double *KQJ = malloc(Q * (J ? J : 1) * sizeof *KQJ);
	int rc = -1;
	if (!dhr || !sig || !sn || !sm || !sres || !c6 || !wt || !KQn || !Y || !C || !Wc || !KQJ) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	struct recon_dhr_parts parts = { .noise = sn, .model = sm, .res = sres };
	if (recon_dhr_parts(s->vchan ? &sub : m, nth, th, o->ndraws, o->seed, dhr, sig, &parts, NULL, NULL, err))
		goto out;
	r->value = 0;
	for (size_t t = 0; t < nth; t++) {
		double all = 0, part = 0;
		for (size_t l = 0; l < L; l++)
			all += sig[t * L + l] * sig[t * L + l];
		all /= (double)L;
		for (size_t c = 0; c < Lc; c++) {
			size_t i = t * L + s->cpos[c], f = t * Lc + c;
			double b = fmax(sn[i], sm[i]);
			part += sig[i] * sig[i];
			s->sn2[f] = sn[i] * sn[i];
			s->v[f] = sm[i] * sm[i];
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
	if (s->vchan && isfinite(s->t->threshold) && r->value <= SEL_VALUE_CHECK * s->t->threshold &&
	    sel_value_all(s, th, o, r, err))
		goto out;
	for (size_t t = 0; t < nth; t++) {
		if (sel_dhr_coef(s, th[t], c6, wt, KQn, Y, Wc, C, err))
			goto out;
		if (J && sel_functionals(s, Q, c6, KQn, C, Lc, t * Lc, KQJ, err))
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
	free(c6);
	free(wt);
	free(KQn);
	free(Y);
	free(C);
	free(Wc);
	free(KQJ);
	return rc;
}

/* The ln f grid: θi ≤ θo in {0, 10, …, 80°} × Δφ in {0, 20, …, 180°} (one azimuth at θi = 0). */
static size_t lnf_grid(double *ang)
{
	size_t F = 0;
	for (int ti = 0; ti <= LNF_TMAX; ti += LNF_TSTEP)
		for (int to = ti; to <= LNF_TMAX; to += LNF_TSTEP)
			for (int p = 0; p <= 180; p += LNF_PSTEP) {
				if (ti == 0 && p > 0)
					break;
				if (ang) {
					ang[4 * F] = ti * M_PI / 180;
					ang[4 * F + 1] = 0;
					ang[4 * F + 2] = to * M_PI / 180;
					ang[4 * F + 3] = p * M_PI / 180;
				}
				F++;
			}
	return F;
}

/* Point targets (ln f, RGB): the posterior variance v[x] = amp[x]² P(x, x) of g at the F points c6 (unit-amplitude
 * posterior P) and their covariances Z[x, j] = amp[x] P(x, candidate j) with the candidates. */
static int sel_point_cov(struct sel *s, const double *c6, const double *amp, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t n = s->n, F = s->F, J = s->J;
	double *KXn = malloc(F * n * sizeof *KXn), *GX = malloc(F * n * sizeof *GX);
	int rc = -1;
	if (!KXn || !GX) {
		acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		goto out;
	}
	rbf_kmatrix_soa(m->kernel, m->shape, F, c6, n, m->soa, KXn);
	memcpy(GX, KXn, F * n * sizeof *GX);
	if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)F, s->A, (lapack_int)n, GX, (lapack_int)n)) {
		acq_errf(err, ACQ_E_NUMERIC, "select: solve failed");
		goto out;
	}
	for (size_t x = 0; x < F; x++) {
		double tc[6];
		rbf_tau(c6 + 6 * x, tc);
		double p = rbf_kernel(m->kernel, m->shape, c6 + 6 * x, c6 + 6 * x, tc) -
			   cblas_ddot((int)n, KXn + x * n, 1, GX + x * n, 1);
		s->v[x] = amp[x] * amp[x] * (p > 0 ? p : 0);
	}
	if (J) {
		rbf_kmatrix_soa(m->kernel, m->shape, F, c6, J, s->soaJ, s->Z);
		cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)F, (int)J, (int)n, -1.0, GX, (int)n, s->Kjn,
			    (int)n, 1.0, s->Z, (int)J);
		for (size_t x = 0; x < F; x++)
			cblas_dscal((int)J, amp[x], s->Z + x * J, 1);
	}
	rc = 0;
out:
	free(KXn);
	free(GX);
	return rc;
}

/* The ln f target: the posterior variance of g (RMS amplitude over the channels, unseen prior included) at the
 * grid's points, and their covariances with the candidates. */
static int sel_setup_lnf(struct sel *s, struct select_result *r, struct acq_err *err)
{
	const struct recon_model *m = s->m;
	size_t F = s->F;
	double *c6 = malloc(F * 6 * sizeof *c6), *amp = calloc(F, sizeof *amp);
	int rc = -1;
	if (!c6 || !amp) {
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
	if (sel_point_cov(s, c6, amp, err))
		goto out;
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
	return rc;
}

/* The RGB target's nodes: MERL cells (iθh, iθd, iφd) = ((k + ½)·N/RGB_NODES) for k < RGB_NODES in each index, those
 * with both directions within LNF_TMAX (80°) of the normal, at the writer's cell centres (merl.h: beyond, no bench
 * reaches and the prior alone speaks, as for ln f; on green paint the grazing Fresnel cells θd > 80° held 97 % of
 * a 10 × 10 × 10 model's squared table error, a region no plan samples); ang[x*4] their pairs (θi, φi, θo,
 * φo) and w[x] the table's projected measure of the block the node stands for: the Rusinkiewicz Jacobian
 * dωi dωo = 4 cosθd sinθh sinθd dθh dθd dφd dφh (φh integrated out: isotropy), × dθh/diθh (θh is quadratic in its
 * index), × cosθi cosθo; normalised to sum 1. Either pointer may be NULL (count only). */
static size_t rgb_nodes(double *ang, double *w)
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
 * wavelengths), RMS over the three channels and over the table under its projected measure (rgb_nodes). Under the
 * GP reading the error of channel λ at x is √(α_λ + unseen prior) · df̂/dg · energy factor · z(x); the errors of
 * one point are taken as fully correlated across wavelengths (one interpolation error of the shape, the GP's
 * common kernel: a missed lobe is missed at every wavelength), so RGB_c has the amplitude
 *   a_c(x) = |Σ_λ W[c, λ] · s_λ(x) · df̂/dg(x, λ) · √(α_λ + u(x)·prior)|
 * and the value is √(Σ_x w_x P(x, x) Σ_c a_c(x)²). (Independent channels would give a value ~√(visible channels)
 * smaller; test_recon_select checks the value against the error of models of a known truth.)
 */
static int sel_setup_rgb(struct sel *s, struct select_result *r, struct acq_err *err)
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
	if (sel_point_cov(s, c6, amp, err))
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

/*
 * The criterion's value E (the target's variance above the threshold², summed over incidences or grid points)
 * with candidate j's measurement added (j = SIZE_MAX: as it is), and the predicted per-incidence values.
 */
static double sel_excess(const struct sel *s, size_t j, double *per)
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
				acc += fmax(floor2, fmax(v, 0)) + s->rest[f] - (zero_res ? s->res2[f] : 0);
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
		E += fmax(v - s->thr2, 0);
	}
	if (s->t->kind == SELECT_RGB) { /* one aggregate: the measure is folded into v */
		if (per)
			per[0] = sqrt(sum);
		return fmax(sum - s->thr2, 0);
	}
	if (per)
		per[0] = sqrt(mx);
	return E / (double)s->F;
}

/* The noise variance's terms after candidate p's measurement (the k-th pick; S its posterior variance + noise):
 * with a_f = cov(f, p)/S and b_j = P(p, j)/S (in s->zp, s->row), the functional's weights become h − a w_p and
 * a on the new sample, candidate j's w_j − b_j w_p and b_j; q, X and Yn follow (M_j = Σ N w_p w_j). */
static void sel_update_noise(struct sel *s, size_t p, size_t k, double S)
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

/* Add candidate p's measurement to the posterior: the rank-one (Schur complement) update of every tracked
 * covariance, with the k-th pick's scaled row stored in U[k]. */
static void sel_update(struct sel *s, size_t p, size_t k)
{
	double *row = s->row, *zp = s->zp;
	const struct recon_model *m = s->m;
	size_t J = s->J, n = s->n, F = s->F;
	/* P(x_p, x_j) = K(p, j) − k_pᵀ A⁻¹ k_j − Σ_i U_i(p) U_i(j) */
	rbf_krow(m->kernel, m->shape, s->cu + 6 * p, J, s->soaJ, row);
	cblas_dgemv(CblasRowMajor, CblasNoTrans, (int)J, (int)n, -1.0, s->Kjn, (int)n, s->G + p * n, 1, 1.0, row, 1);
	for (size_t i = 0; i < k; i++)
		cblas_daxpy((int)J, -s->U[i * J + p], s->U + i * J, 1, row, 1);
	double S = s->Pjj[p] + s->noise;
	if (!(S > 0))
		S = 1e-300;
	for (size_t f = 0; f < F; f++)
		zp[f] = s->Z[f * J + p];
	if (s->X)
		sel_update_noise(s, p, k, S);
	for (size_t f = 0; f < F; f++)
		s->v[f] = fmax(s->v[f] - zp[f] * zp[f] / S, 0);
	cblas_dger(CblasRowMajor, (int)F, (int)J, -1.0 / S, zp, 1, row, 1, s->Z, (int)J);
	for (size_t j = 0; j < J; j++) {
		s->Pjj[j] = fmax(s->Pjj[j] - row[j] * row[j] / S, 0);
		s->U[k * J + j] = row[j] / sqrt(S);
	}
	if (s->t->kind == SELECT_DHR)
		for (size_t t = 0; t < s->nth; t++)
			if (s->match[t * J + p])
				s->res_done[t] = 1;
	s->picked[p] = 1;
}

/* Everything before the first pick: the factorisation, the candidates, the target's functionals and their
 * covariances with the candidates, the current value into r. 0, or -1 with err (sel_free in both cases). */
static int sel_init(struct sel *s, const struct recon_model *m, size_t nc, const double *ang, const double *cost,
		    const struct select_target *t, const struct select_opts *o, struct select_result *r, struct acq_err *err)
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
	if (sel_factor(s, err) || sel_candidates(s, nc, ang, cost, err))
		return -1;
	r->nunique = s->J;
	size_t J = s->J, Jp = J ? J : 1;
	s->batch = o->batch < J ? o->batch : J;
	if (t->kind == SELECT_DHR) {
		s->F = s->nth * s->Lc;
	} else if (t->kind == SELECT_LNF) {
		s->F = lnf_grid(NULL);
		s->xang = malloc(s->F * 4 * sizeof *s->xang);
		if (!s->xang)
			return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		lnf_grid(s->xang);
	} else {
		s->F = rgb_nodes(NULL, NULL);
		s->xang = malloc(s->F * 4 * sizeof *s->xang);
		s->xw = malloc(s->F * sizeof *s->xw);
		if (!s->xang || !s->xw)
			return acq_errf(err, ACQ_E_NOMEM, "select: out of memory");
		rgb_nodes(s->xang, s->xw);
	}
	size_t F = s->F;
	if ((double)F * (double)Jp * 8.0 > 4e9)
		return acq_errf(err, ACQ_E_RANGE, "select: %zu distinct candidates × %zu target points need too much memory",
				J, F);
	s->Z = malloc(F * Jp * sizeof *s->Z);
	s->v = calloc(F, sizeof *s->v);
	s->U = malloc((s->batch ? s->batch : 1) * Jp * sizeof *s->U);
	s->match = calloc((s->nth ? s->nth : 1) * Jp, 1);
	s->sn2 = calloc(F, sizeof *s->sn2);
	s->rest = calloc(F, sizeof *s->rest);
	s->res2 = calloc(F, sizeof *s->res2);
	s->kappa = calloc(SELECT_MAX_THETA, sizeof *s->kappa);
	s->res_done = calloc(SELECT_MAX_THETA, 1);
	s->row = malloc(Jp * sizeof *s->row);
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
		s->Gc = malloc(Jp * n * sizeof *s->Gc);
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

/* A combined target's value: the larger of each part's value over its threshold. */
static double combined_value(const struct select_target *t, double dhr, double lnf)
{
	return fmax(dhr / t->threshold, lnf / t->lnf_threshold);
}

int select_batch(const struct recon_model *m, size_t nc, const double *ang, const double *cost,
		 const struct select_target *t, const struct select_opts *opts, struct select_result *r, struct acq_err *err)
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
	struct select_target tp[2] = { *t, { .kind = SELECT_LNF, .threshold = t->lnf_threshold } };
	tp[0].lnf_threshold = 0;
	struct select_result r2 = { 0 };
	struct sel s[2];
	size_t np = both ? 2 : 1;
	int rc = -1;
	memset(s, 0, sizeof s);
	if (sel_init(&s[0], m, nc, ang, cost, &tp[0], &o, r, err) ||
	    (both && sel_init(&s[1], m, nc, ang, cost, &tp[1], &o, &r2, err)))
		goto out;
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
	double E[2], E0[2], value = r->value, thr = both ? 1.0 : t->threshold;
	for (size_t k = 0; k < np; k++)
		E[k] = E0[k] = sel_excess(&s[k], SIZE_MAX, NULL);
	while (r->npicks < s[0].batch && !(isfinite(thr) && value <= thr)) {
		size_t best = SIZE_MAX;
		double bscore = 0, bgain = 0;
		for (size_t j = 0; j < J; j++) {
			if (s[0].picked[j])
				continue;
			double gain = 0;
			bool any = false;
			for (size_t k = 0; k < np; k++) {
				double g = E[k] - sel_excess(&s[k], j, NULL);
				any |= g > 1e-12 * E0[k];
				gain += both ? (E0[k] > 0 ? g / E0[k] : 0) : g;
			}
			double score = gain / s[0].cost[j];
			if (any && gain > 0 && score > bscore) {
				best = j;
				bscore = score;
				bgain = gain;
			}
		}
		if (best == SIZE_MAX)
			break; /* nothing left reduces the target */
		struct select_pick *pk = &r->picks[r->npicks];
		for (size_t k = 0; k < np; k++)
			sel_update(&s[k], best, r->npicks);
		r->npicks++;
		pk->index = s[0].rep[best];
		pk->gain = bgain;
		pk->gain_per_s = bscore;
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
	if (rc)
		select_result_free(r);
	for (size_t k = 0; k < np; k++)
		sel_free(&s[k]);
	return rc;
}
