/* quad: hemisphere quadrature of the albedo, adaptive per channel, with the starting rule sized from the
 * narrowest lobe the model can make. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/recon_int.h"

/* Nodes per kernel block of the quadrature (the GEMM's rows): 4 × RECON_EVAL_BLOCK, so the weights (channels ×
 * centres, 5 MB at 1000 × 651) are packed for the GEMM a quarter as often. */
#define QUAD_BLOCK (4 * RECON_EVAL_BLOCK)

/*
 * Hemisphere quadrature of the albedo a(θi) = ∫ f cosθo dωo = ∫₀¹ ∫₀^{2π} f μ dφ dμ (μ = cosθo).
 * μ: Gauss-Legendre with nmu nodes, exact for polynomials of degree 2·nmu − 1 in μ (so exact for a
 * Lambertian, and for cosⁿ lobes about the normal with n < 2·nmu − 1). φ: the integrand is 2π-periodic and
 * even in Δφ (isotropy and mirror), so nphi midpoints on [0, π] are the trapezoid rule with 2·nphi points on
 * the circle, whose error decays faster than any power for smooth integrands (exact for trigonometric
 * polynomials of degree < 2·nphi). The error is therefore set by the narrowest lobe of the interpolant:
 * about (lobe width / node spacing) must stay above ~2; the DHR rule (32 × 48: 2.8° in φ, ~3° in θ near the
 * horizon) resolves lobes down to ~6°, far narrower than a 10 × 10 × 10 angular sampling can reconstruct.
 * The albedo table estimates its own error against a doubled rule and adds it as a margin.
 */
int recon_hemi_nodes(double theta_i, int nmu, int nphi, int square_rule, double *c6, double *wt)
{
	double x[256], w[256];
	if (rbf_gauss_legendre01(nmu, x, w))
		return -1;
	size_t k = 0;
	for (int i = 0; i < nmu; i++) {
		double mu, wmu;
		if (square_rule) { /* independent rule: Gauss-Legendre in t = μ², dt = 2μ dμ */
			mu = sqrt(x[i]);
			wmu = 0.5 * w[i];
		} else {
			mu = x[i];
			wmu = w[i] * mu;
		}
		double to = acos(mu);
		for (int j = 0; j < nphi; j++) {
			double d = (j + 0.5) * M_PI / nphi;
			rbf_canon(theta_i, 0.0, to, d, c6 + 6 * k);
			wt[k] = wmu * 2.0 * M_PI / nphi;
			k++;
		}
	}
	return 0;
}

/* The plain rule's independent twin (ws->alt_rule): Gauss-Legendre with nmu nodes in t = cos²θo × the trapezoid rule
 * with nphi intervals on [0, π] (its end points included: the midpoints' shift by half a step), so no node is shared
 * with recon_hemi_nodes' rule of the same size and the same accuracy. nmu × (nphi + 1) nodes. */
static int hemi_nodes_alt(double theta_i, int nmu, int nphi, double *c6, double *wt);

/*
 * The nested rule of the energy table, R(N, M): Clenshaw-Curtis with N intervals in μ = cosθo (nodes
 * sin²(kπ/2N), exact for polynomials of degree N; for integrands analytic near [0, 1] it converges like
 * Gauss-Legendre with as many nodes: Trefethen, SIAM Review 50, 2008) × the trapezoid rule with M intervals in
 * azimuth on [0, π], doubled by the mirror (2M equally spaced points on the circle: the same accuracy as M
 * midpoints). R(N, M) ⊂ R(2N, 2M): a doubling evaluates only the 3/4 of its nodes that are new, so a node rule
 * and its doubling cost 4 units instead of Gauss-Legendre's 1 + 4. The horizon node (weight 0 with the cosine)
 * is left out and the pole is one node (every azimuth is the same direction there). Near the pole a row of
 * azimuths is a circle of radius sinθo: rows with sinθo ≤ 1/2 (≤ 1/4) take M/2 (M/4) intervals, so no row's
 * spacing in arc, sinθo·π/M_k, exceeds the equator's π/M (M a multiple of 4; a row keeps its share at every
 * level, so the rules stay nested): ~16 % fewer nodes.
 */
#define CC_NMAX 1024
static int cc01(int N, double *x, double *w)
{
	if (N < 1 || N > CC_NMAX)
		return -1;
	for (int k = 0; k <= N; k++) {
		double th = k * M_PI / N, s = 0;
		for (int j = 1; 2 * j <= N; j++)
			s += (2 * j == N ? 1.0 : 2.0) / (4.0 * j * j - 1.0) * cos(2.0 * j * th);
		w[k] = 0.5 * (k == 0 || k == N ? 1.0 : 2.0) / N * (1.0 - s);
		double h = sin(0.5 * th);
		x[k] = h * h;
	}
	return 0;
}

/* Azimuth weight (mirror included) of node j of the trapezoid rule with M intervals on [0, π]. */
static double trap_w(int j, int M)
{
	return (j == 0 || j == M ? 0.5 : 1.0) * 2.0 * M_PI / M;
}

static int hemi_nodes_alt(double theta_i, int nmu, int nphi, double *c6, double *wt)
{
	double x[256], w[256];
	if (rbf_gauss_legendre01(nmu, x, w))
		return -1;
	size_t k = 0;
	for (int i = 0; i < nmu; i++) {
		double to = acos(sqrt(x[i]));
		for (int j = 0; j <= nphi; j++) {
			rbf_canon(theta_i, 0.0, to, j * M_PI / nphi, c6 + 6 * k);
			wt[k++] = 0.5 * w[i] * trap_w(j, nphi);
		}
	}
	return 0;
}

/* Azimuth intervals of row μ = x of R(·, M): M / 2^p, 2^p·sinθo ≤ 1, p ≤ 2 (M not a multiple of 4: M). */
static int cc_row_m(double x, int M)
{
	double s = sqrt(fmax(0.0, (1.0 - x) * (1.0 + x)));
	return M % 4 ? M : s <= 0.25 ? M / 4 : s <= 0.5 ? M / 2 : M;
}

/* Nodes of R(N, M) (only_new: those not in R(N/2, M/2); N, M even), in the order k = 1 … N−1, j = 0 … M_k, then
 * the pole; the count, or −1 on a bad size. */
static long cc_nodes(double theta_i, int N, int M, int only_new, double *c6, double *wt)
{
	double x[CC_NMAX + 1], w[CC_NMAX + 1];
	if (cc01(N, x, w) || M < 1 || (only_new && (N % 2 || M % 2)))
		return -1;
	long q = 0;
	for (int k = 1; k < N; k++) {
		double to = acos(x[k]);
		int mk = cc_row_m(x[k], M);
		for (int j = 0; j <= mk; j++) {
			if (only_new && !(k & 1) && !(j & 1))
				continue;
			rbf_canon(theta_i, 0.0, to, j * M_PI / mk, c6 + 6 * q);
			wt[q++] = w[k] * x[k] * trap_w(j, mk);
		}
	}
	if (!only_new) {
		rbf_canon(theta_i, 0.0, 0.0, 0.0, c6 + 6 * q);
		wt[q++] = w[N] * 2.0 * M_PI;
	}
	return q;
}

void recon_albedo_ws_free(struct albedo_ws *ws)
{
	free(ws->bright);
	free(ws->cand);
	free(ws->c6);
	free(ws->wt);
	free(ws->work);
	free(ws->vals);
	free(ws->wsub);
	free(ws->fine);
	free(ws->chan);
	free(ws->keep);
	free(ws->step);
	free(ws->alt);
	for (int k = 0; k < 257; k++)
		free(ws->gl[k]);
	memset(ws, 0, sizeof *ws);
}

int recon_albedo_ws_init(struct albedo_ws *ws, const struct recon_model *m, size_t qmax, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl;
	memset(ws, 0, sizeof *ws);
	ws->qmax = qmax;
	ws->L = L;
	ws->c6 = malloc(qmax * 6 * sizeof *ws->c6);
	ws->wt = malloc(qmax * sizeof *ws->wt);
	ws->work = malloc((size_t)QUAD_BLOCK * n * sizeof *ws->work);
	ws->vals = malloc((size_t)QUAD_BLOCK * L * sizeof *ws->vals);
	ws->wsub = malloc(L * n * sizeof *ws->wsub);
	ws->fine = malloc(L * sizeof *ws->fine);
	ws->chan = malloc(L * sizeof *ws->chan);
	ws->bright = malloc(n * sizeof *ws->bright);
	ws->cand = malloc(2 * n * 3 * sizeof *ws->cand);
	ws->step = malloc((m->ntab + 1) * sizeof *ws->step);
	ws->alt = malloc(L * sizeof *ws->alt);
	if (!ws->c6 || !ws->wt || !ws->work || !ws->vals || !ws->wsub || !ws->fine || !ws->chan || !ws->bright ||
	    !ws->cand || !ws->step || !ws->alt) {
		recon_albedo_ws_free(ws);
		return acq_errf(err, ACQ_E_NOMEM, "albedo: out of memory");
	}
	/* each centre's brightness: the largest value the interpolant's data take there (the map back of g) */
	for (size_t k = 0; k < n; k++) {
		double b[TREND_NB], v = 0;
		trend_at(m, m->ctr + 6 * k, b);
		for (size_t l = 0; l < L; l++) {
			double f = untransform(m->transform, m->g ? m->g[l * n + k] : 0.0, m->eps[l], trend_factor(m, b, l));
			if (f > v)
				v = f;
		}
		ws->bright[k] = v;
	}
	return 0;
}

/* Make room for Q nodes (-1 on failure). */
static int ws_reserve(struct albedo_ws *ws, size_t Q)
{
	if (Q <= ws->qmax)
		return 0;
	double *c6 = realloc(ws->c6, Q * 6 * sizeof *c6);
	if (!c6)
		return -1;
	ws->c6 = c6;
	double *wt = realloc(ws->wt, Q * sizeof *wt);
	if (!wt)
		return -1;
	ws->wt = wt;
	ws->qmax = Q;
	return 0;
}

static int cmp_dbl(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

static int cmp_cand_desc(const void *a, const void *b)
{
	double x = ((const double *)a)[2], y = ((const double *)b)[2];
	return (x < y) - (x > y);
}

/*
 * Probes at the data's brightest directions, and the boxes they call for (the mechanism that finds lobes narrower
 * than a rule). A lobe narrower than the spacing h of the starting rule makes the coarse rules agree by both
 * stepping over it, so refinement alone cannot find it; but the interpolant's narrow lobes sit on the data: by
 * reciprocity and isotropy a centre (θi', φi', θo', φo') puts its value at ωo = (θo', |φo' − φi'|) when θi' is
 * near θi, and at (θi', |φo' − φi'|) when θo' is. The 2·RECON_BOX_MAX brightest such directions (value × cosθ,
 * each at least a box half-width from a brighter one; centres within the half-width of θi) are probed: the
 * integrand there is compared with the starting rule's four nodes around it. A probe calls for a box where, in
 * some channel, it is more than twice those nodes (a lobe narrower than about h/2, which a rule of spacing h
 * integrates badly) and the mass one node would give it, value × node weight, exceeds tol · max(|estimate|,
 * floor). A box has half-width RECON_BOX_HW·h in θ (the same arc in φ) and RECON_BOX_N nodes per dimension,
 * doubled with the rule: about 5 times the starting density there. A model without such lobes gets no box and
 * the plain rules, unchanged; the half-vector rule gets none (it is already centred on the mirror).
 * Returns the number of boxes (ws->nbox), or -1 with err.
 */
#define RECON_BOX_HW 2.5
#define RECON_BOX_N 24
#define RECON_BOX_PEAK 2.0
static int albedo_boxes(const struct recon_model *m, double theta_i, int nmu, int nphi, int square_rule, int scaled,
			double tol, double fl, struct albedo_ws *ws, const double *est, struct acq_err *err)
{
	ws->nbox = 0;
	ws->boxn = RECON_BOX_N >> ws->box_fine;
	if (recon_part_hv(ws->part) || !m->ang || !ws->bright)
		return 0;
	double h = fmax((M_PI / 2) / nmu, M_PI / nphi), hw = RECON_BOX_HW * h / (1 << ws->box_fine);
	size_t nc = 0, L = m->nwl;
	for (size_t k = 0; k < m->n; k++) {
		const double *a = m->ang + 4 * k;
		double d = fabs(remainder(a[3] - a[1], 2.0 * M_PI));
		if (!(ws->bright[k] > 0) || !isfinite(d))
			continue;
		for (int side = 0; side < 2; side++) { /* side 0: the sample's incidence is near θi; 1: its outgoing */
			double tin = a[side ? 2 : 0], tout = a[side ? 0 : 2];
			if (!(fabs(tin - theta_i) <= hw) || !(tout >= 0 && tout <= M_PI / 2))
				continue;
			ws->cand[3 * nc] = tout;
			ws->cand[3 * nc + 1] = d > M_PI ? M_PI : d;
			ws->cand[3 * nc + 2] = ws->bright[k] * cos(tout);
			nc++;
		}
	}
	if (nc == 0)
		return 0;
	qsort(ws->cand, nc, 3 * sizeof *ws->cand, cmp_cand_desc);
	/* the probes: distinct directions, each with the starting rule's four nodes around it */
	enum { NP = 2 * RECON_BOX_MAX };
	double dir[NP][3], pt[NP][2], wn[NP][4], chw = cos(hw), x[CC_NMAX + 1], w[CC_NMAX + 1];
	int cc = ws->nested && !square_rule, nx = cc ? nmu + 1 : nmu; /* the rule's rows */
	int np = 0;
	for (size_t c = 0; c < nc && np < NP; c++) {
		double t = ws->cand[3 * c], p = ws->cand[3 * c + 1];
		double v[3] = { sin(t) * cos(p), sin(t) * sin(p), cos(t) };
		int near = 0;
		for (int b = 0; b < np && !near; b++)
			near = v[0] * dir[b][0] + v[1] * dir[b][1] + v[2] * dir[b][2] >= chw;
		if (near)
			continue;
		memcpy(dir[np], v, sizeof v);
		pt[np][0] = t;
		pt[np][1] = p;
		np++;
	}
	if ((cc ? cc01(nmu, x, w) : rbf_gauss_legendre01(nmu, x, w)) || ws_reserve(ws, (size_t)np * 5))
		return acq_errf(err, ACQ_E_NOMEM, "albedo: out of memory for the probes");
	for (int b = 0; b < np; b++) {
		double xc = cos(pt[b][0]);
		if (square_rule)
			xc *= xc;
		int i = 0;
		while (i + 2 < nx && x[i + 1] <= xc)
			i++;
		rbf_canon(theta_i, 0.0, pt[b][0], pt[b][1], ws->c6 + 6 * (5 * b));
		for (int u = 0; u < 4; u++) { /* the two nearest azimuths of rows i and i + 1 (the nested rule's rows differ) */
			int ii = i + (u & 1) < nx ? i + (u & 1) : nx - 1, mr = cc ? cc_row_m(x[ii], nphi) : nphi;
			int nr = cc ? mr + 1 : mr, j = (int)floor(pt[b][1] * mr / M_PI - (cc ? 0.0 : 0.5));
			j = j < 0 ? 0 : j + 1 >= nr ? (nr > 1 ? nr - 2 : 0) : j;
			int jj = j + (u >> 1) < nr ? j + (u >> 1) : nr - 1;
			double mu = square_rule ? sqrt(x[ii]) : x[ii];
			wn[b][u] = (square_rule ? 0.5 * w[ii] : w[ii] * mu) * 2.0 * M_PI / mr;
			rbf_canon(theta_i, 0.0, acos(fmin(mu, 1.0)), (jj + (cc ? 0.0 : 0.5)) * M_PI / mr,
				  ws->c6 + 6 * (5 * b + 1 + u));
		}
	}
	recon_eval_block_part(m, (size_t)np * 5, ws->c6, scaled, ws->part, L, ws->chan, ws->wsub, ws->vals, ws->work);
	ws->evals += 5.0 * np * (double)m->n * (1.0 + (double)L / 64.0);
	for (int b = 0; b < np && ws->nbox < RECON_BOX_MAX; b++) {
		int need = 0;
		for (size_t l = 0; l < L && !need; l++) {
			double fc = ws->vals[(5 * b) * L + l], fn = 0, wbar = 0;
			for (int u = 0; u < 4; u++) {
				fn = fmax(fn, ws->vals[(5 * b + 1 + u) * L + l]);
				wbar += 0.25 * wn[b][u];
			}
			need = fc > RECON_BOX_PEAK * fn && fc * wbar > tol * fmax(fabs(est[l]), fl);
		}
		if (!need)
			continue;
		double t = pt[b][0], p = pt[b][1];
		double tlo = fmax(t - hw, 0), thi = fmin(t + hw, M_PI / 2);
		double xlo = cos(thi), xhi = cos(tlo);
		if (square_rule) {
			xlo *= xlo;
			xhi *= xhi;
		}
		double s = sin(t), dp = s > sin(hw) ? hw / s : M_PI; /* the same arc in azimuth */
		double *B = ws->box[ws->nbox++];
		B[0] = xlo;
		B[1] = xhi;
		B[2] = fmax(p - dp, 0);
		B[3] = fmin(p + dp, M_PI);
	}
	return ws->nbox;
}

/* Gauss-Legendre's n nodes on [0, 1] (*x) and weights (*w), from ws's cache (computed at the first use); -1 on a
 * bad size or no memory. */
static int ws_gl(struct albedo_ws *ws, int n, const double **x, const double **w)
{
	if (n < 1 || n > 256)
		return -1;
	if (!ws->gl[n]) {
		double *g = malloc(2 * (size_t)n * sizeof *g);
		if (!g || rbf_gauss_legendre01(n, g, g + n)) {
			free(g);
			return -1;
		}
		ws->gl[n] = g;
	}
	*x = ws->gl[n];
	*w = ws->gl[n] + n;
	return 0;
}

/* Nodes of the composite rule with boxes: the cells between the boxes' edges (and the energy factor's steps in x),
 * each with Gauss-Legendre in x (cosθo, or cos²θo for the square rule) and in azimuth over [0, π] (doubled by the
 * mirror); a cell inside a box
 * gets the box's density boxn per box width, the others the density of the plain rule nmu × nphi (≥ 2 nodes a
 * side). Returns the node count, or 0 on failure. */
static size_t box_nodes(double theta_i, int nmu, int nphi, int square_rule, struct albedo_ws *ws)
{
	double pb[2 + 2 * RECON_BOX_MAX], *xb = malloc((2 + 2 * RECON_BOX_MAX + (size_t)ws->nstep) * sizeof *xb);
	double box[RECON_BOX_MAX][4];
	if (!xb)
		return 0;
	/* the independent twin (ws->alt_rule, square_rule 0): the same cells in t = x² (every edge squared), one more
	 * azimuth node a cell */
	int alt = ws->alt_rule && !square_rule, sq = square_rule || alt;
	int nx = 0, np = 0;
	xb[nx++] = 0;
	xb[nx++] = 1;
	pb[np++] = 0;
	pb[np++] = M_PI;
	for (int b = 0; b < ws->nbox; b++) {
		memcpy(box[b], ws->box[b], sizeof box[b]);
		if (alt) {
			box[b][0] *= box[b][0];
			box[b][1] *= box[b][1];
		}
		xb[nx++] = box[b][0];
		xb[nx++] = box[b][1];
		pb[np++] = box[b][2];
		pb[np++] = box[b][3];
	}
	for (int k = 0; k < ws->nstep; k++)
		xb[nx++] = alt ? ws->step[k] * ws->step[k] : ws->step[k];
	qsort(xb, (size_t)nx, sizeof *xb, cmp_dbl);
	qsort(pb, (size_t)np, sizeof *pb, cmp_dbl);
	size_t Q = 0;
	const double *gx, *gwx, *gp, *gwp;
	for (int i = 0; i + 1 < nx; i++) {
		double a = xb[i], bx = xb[i + 1];
		if (!(bx - a > 1e-12))
			continue;
		for (int j = 0; j + 1 < np; j++) {
			double c = pb[j], d = pb[j + 1];
			if (!(d - c > 1e-12))
				continue;
			double fx = 0, fp = 0; /* the densest box holding the cell */
			for (int b = 0; b < ws->nbox; b++) {
				const double *B = box[b];
				if (a >= B[0] - 1e-12 && bx <= B[1] + 1e-12 && c >= B[2] - 1e-12 && d <= B[3] + 1e-12) {
					fx = fmax(fx, ws->boxn / (B[1] - B[0]));
					fp = fmax(fp, ws->boxn / (B[3] - B[2]));
				}
			}
			if (fx == 0) {
				fx = nmu;
				fp = nphi / M_PI;
			}
			int mx = (int)fmin(256, fmax(ws->cell_min, ceil(fx * (bx - a) - 1e-9)));
			int mp = (int)fmin(256, fmax(ws->cell_min, ceil(fp * (d - c) - 1e-9)) + alt);
			if (ws_reserve(ws, Q + (size_t)mx * (size_t)mp) || ws_gl(ws, mx, &gx, &gwx) || ws_gl(ws, mp, &gp, &gwp)) {
				free(xb);
				return 0;
			}
			for (int u = 0; u < mx; u++) {
				double x = a + (bx - a) * gx[u], wx = (bx - a) * gwx[u];
				double mu = sq ? sqrt(x) : x, wmu = sq ? 0.5 * wx : wx * mu;
				double to = acos(fmin(mu, 1.0));
				for (int v = 0; v < mp; v++) {
					rbf_canon(theta_i, 0.0, to, c + (d - c) * gp[v], ws->c6 + 6 * Q);
					ws->wt[Q++] = wmu * (d - c) * gwp[v] * 2.0;
				}
			}
		}
	}
	free(xb);
	return Q;
}

/* acc[k] = albedo of channel chan[k] (k < nch) by the rule nmu × nphi; the weights of those channels are
 * already packed in ws->wsub. Evaluated block by block: memory does not grow with the rule. */
static int albedo_rule_cc(const struct recon_model *m, double theta_i, int N, int M, int scaled, size_t nch,
			  struct albedo_ws *ws, double *acc, struct acq_err *err);

static int albedo_rule(const struct recon_model *m, double theta_i, int nmu, int nphi, int square_rule,
		       int scaled, size_t nch, struct albedo_ws *ws, double *acc, struct acq_err *err)
{
	size_t Q = (size_t)nmu * (size_t)nphi;
	int composite = ws->nbox > 0 || ws->nstep > 0;
	if (composite)
		ws->keep_n = 0; /* the composite rules are not nested */
	else if (ws->nested && !square_rule && !recon_part_hv(ws->part) && !ws->alt_rule)
		return albedo_rule_cc(m, theta_i, nmu, nphi, scaled, nch, ws, acc, err);
	if (composite) {
		if (!(Q = box_nodes(theta_i, nmu, nphi, square_rule, ws)))
			return acq_errf(err, ACQ_E_NOMEM, "albedo: out of memory for a %d × %d rule with boxes", nmu, nphi);
	} else if (ws->alt_rule) {
		Q = (size_t)nmu * (size_t)(nphi + 1);
		if (ws_reserve(ws, Q) || hemi_nodes_alt(theta_i, nmu, nphi, ws->c6, ws->wt))
			return acq_errf(err, ACQ_E_NOMEM, "albedo: no room for a %d × %d rule", nmu, nphi + 1);
	} else if (Q > ws->qmax ||
		   (recon_part_hv(ws->part) ? recon_hv_nodes(theta_i, ws->part == RECON_PART_BASE ? m->trend_alpha2
											   : trend_hv_alpha(m->trend, m->trend_alpha),
							      nmu, nphi, ws->c6, ws->wt)
						: recon_hemi_nodes(theta_i, nmu, nphi, square_rule, ws->c6, ws->wt)))
		return acq_errf(err, ACQ_E_INVAL, "albedo: quadrature size %d × %d out of range", nmu, nphi);
	for (size_t k = 0; k < nch; k++)
		acc[k] = 0;
	for (size_t q0 = 0; q0 < Q; q0 += QUAD_BLOCK) {
		size_t b = Q - q0 < QUAD_BLOCK ? Q - q0 : QUAD_BLOCK;
		recon_eval_block_part(m, b, ws->c6 + 6 * q0, scaled, ws->part, nch, ws->chan, ws->wsub, ws->vals, ws->work);
		ws->evals += (double)b * (double)m->n * (1.0 + (double)nch / 64.0);
		for (size_t q = 0; q < b; q++)
			for (size_t k = 0; k < nch; k++)
				acc[k] += ws->wt[q0 + q] * ws->vals[q * nch + k];
	}
	return 0;
}

/* albedo_rule on the nested rule R(N, M) (nmu, nphi read as interval counts). The rule that ws->store asks for
 * keeps every channel's values at its nodes (ws->keep; all channels are active then); the doubling after it
 * evaluates only its new nodes and adds the kept values with its own weights. */
static int albedo_rule_cc(const struct recon_model *m, double theta_i, int N, int M, int scaled, size_t nch,
			  struct albedo_ws *ws, double *acc, struct acq_err *err)
{
	size_t L = ws->L;
	int reuse = ws->keep_n > 0 && 2 * ws->keep_n == N && 2 * ws->keep_m == M;
	if (ws_reserve(ws, (size_t)N * (size_t)(M + 1) + 1))
		return acq_errf(err, ACQ_E_NOMEM, "albedo: out of memory for a %d × %d rule", N, M);
	long Q = cc_nodes(theta_i, N, M, reuse, ws->c6, ws->wt);
	if (Q < 0)
		return acq_errf(err, ACQ_E_INVAL, "albedo: quadrature size %d × %d out of range", N, M);
	int store = ws->store && !reuse && nch == L;
	if (store && ws->keep_cap < (size_t)Q * L) {
		double *k = realloc(ws->keep, (size_t)Q * L * sizeof *k);
		if (k) {
			ws->keep = k;
			ws->keep_cap = (size_t)Q * L;
		} else {
			store = 0; /* the doubling then evaluates every node */
		}
	}
	for (size_t k = 0; k < nch; k++)
		acc[k] = 0;
	for (size_t q0 = 0; q0 < (size_t)Q; q0 += QUAD_BLOCK) {
		size_t b = (size_t)Q - q0 < QUAD_BLOCK ? (size_t)Q - q0 : QUAD_BLOCK;
		recon_eval_block_part(m, b, ws->c6 + 6 * q0, scaled, ws->part, nch, ws->chan, ws->wsub, ws->vals, ws->work);
		ws->evals += (double)b * (double)m->n * (1.0 + (double)nch / 64.0);
		for (size_t q = 0; q < b; q++)
			for (size_t k = 0; k < nch; k++)
				acc[k] += ws->wt[q0 + q] * ws->vals[q * nch + k];
		if (store)
			memcpy(ws->keep + q0 * L, ws->vals, b * L * sizeof *ws->vals);
	}
	if (reuse) { /* the kept nodes, in cc_nodes' order, at this rule's weights */
		double x[CC_NMAX + 1], w[CC_NMAX + 1];
		cc01(N, x, w);
		size_t idx = 0;
		for (int k = 2; k < N; k += 2)
			for (int j = 0, mk = cc_row_m(x[k], M); j <= mk; j += 2, idx++) {
				double wq = w[k] * x[k] * trap_w(j, mk);
				for (size_t c = 0; c < nch; c++)
					acc[c] += wq * ws->keep[idx * L + ws->chan[c]];
			}
		for (size_t c = 0; c < nch; c++)
			acc[c] += w[N] * 2.0 * M_PI * ws->keep[idx * L + ws->chan[c]];
	}
	ws->keep_n = store ? N : 0;
	ws->keep_m = store ? M : 0;
	return 0;
}

/*
 * The starting rule for this model: the narrowest lobe of e^g. Near a peak of height H the C² Wendland
 * kernel of length ℓ gives g ≈ H(1 − 10 d²/ℓ²), so e^g is a Gaussian of width ℓ/√(20H): nodes are spaced
 * by that width (H = the largest range of g over the centres, log transform; the sqrt transform squares,
 * far milder). Two rules that both step over a lobe agree with each other, so refinement alone cannot
 * find it: the start must resolve it. The trend's GGX lobe has a half width ≈ 2α in ωo (D falls to a quarter
 * at tanθh = α): nodes α/2 apart when the lobe can carry 1e-4 of albedo (its albedo is ≤ the sum of its coefficients).
 * nmu, nphi are raised to it (at most nmu_max/2 so one doubling fits); *qmax is the size of the finest rule
 * the ladder can reach.
 */
double recon_trend_lobe_coef(const struct recon_model *m)
{
	double lobe = 0;
	for (size_t l = 0; l < m->nwl && m->trend != RECON_TREND_NONE; l++) {
		double sum = 0; /* the lobe terms' albedo is ≤ the sum of their coefficients */
		for (int j = trend_lobe_first(m->trend); j < TREND_NB; j++)
			sum += m->tcoef[l * TREND_NB + j];
		lobe = fmax(lobe, sum);
	}
	return lobe;
}

void recon_lobe_rule(const struct recon_model *m, int nmu_max, int no_trend_lobe, int *nmu, int *nphi, size_t *qmax)
{
	double H = 0;
	if (m->transform != RECON_T_SQRT)
		for (size_t l = 0; l < m->nwl; l++) {
			const double *g = m->g + l * m->n;
			double lo = g[0], hi = g[0];
			for (size_t k = 1; k < m->n; k++) {
				lo = fmin(lo, g[k]);
				hi = fmax(hi, g[k]);
			}
			H = fmax(H, hi - lo);
		}
	double s = m->shape / sqrt(20.0 * (H + 1.0)); /* radians */
	if (m->trend != RECON_TREND_NONE && !no_trend_lobe) {
		if (recon_trend_lobe_coef(m) >= 1e-4)
			s = fmin(s, m->trend == RECON_TREND_GGX ? TREND_RULE_SPACING * m->trend_alpha
							       : trend_rule_step(m->trend, m->trend_alpha));
	}
	/* a two-lobe trend's broad lobe (b1, b2) is on this rule unless the caller integrates it apart (no_trend_lobe 2:
	 * the energy table, session 15; the DHR keeps it here, honest session 7) */
	if (trend_two_lobes(m->trend) && no_trend_lobe != 2) {
		double base = 0;
		for (size_t l = 0; l < m->nwl; l++)
			base = fmax(base, m->tcoef[l * TREND_NB + 1] + m->tcoef[l * TREND_NB + 2]);
		if (base >= 1e-4)
			s = fmin(s, trend_base_step(m->trend, m->trend_alpha2));
	}
	double a = ceil((M_PI / 2) / s), b = ceil(M_PI / s);
	if (a > *nmu)
		*nmu = a < nmu_max / 2 ? (int)a : nmu_max / 2;
	if (b > *nphi)
		*nphi = b < 4 * nmu_max ? (int)b : 4 * nmu_max;
	int tm = *nmu, tp = *nphi;
	while (2 * tm <= nmu_max) {
		tm *= 2;
		tp *= 2;
	}
	*qmax = (size_t)tm * (size_t)tp;
}

/*
 * The steps of the energy factor s(θi, θo) = 1/max(1, A(θi), A(θo)) in θo at this θi (scaled rules): A is the
 * table's bound, constant over each of its intervals, so s steps at a table node where some channel's s differs
 * on its two sides (only where A(θo) > max(1, A(θi)): never on a model whose table stays ≤ 1). A rule that
 * integrates across a step converges only like its spacing, and two rules land on either side of it by chance:
 * on the spike of test_dynamic_range (A up to ~10² about 35°, the factor stepping inside the 2° lobe) rules
 * from 32 × 48 to 256 × 384 scattered by 1 % and two successive ones agreed to 6e-4 while 1.2 % off (unscaled,
 * the same rules agreed with the cubature to 1e-5). So every rule is cut there (box_nodes). Fills ws->step
 * (x = cosθo, or cos²θo) and returns the count.
 */
static int energy_steps(const struct recon_model *m, double theta_i, int square_rule, struct albedo_ws *ws)
{
	int ns = 0;
	for (size_t j = 1; j < m->ntab; j++) {
		double t = m->tab_theta[j], tp = 0.5 * (m->tab_theta[j - 1] + t);
		if (!(t > 0 && t < M_PI / 2))
			continue;
		int step = 0;
		for (size_t l = 0; l < m->nwl && !step; l++)
			step = recon_energy_scale(m, theta_i, t, l) != recon_energy_scale(m, theta_i, tp, l);
		if (step) {
			double x = cos(t);
			ws->step[ns++] = square_rule ? x * x : x;
		}
	}
	return ns;
}

/*
 * Albedo of every channel at θi, starting with the rule nmu × nphi and doubling both while a channel
 * disagrees with the doubled rule by more than tol · max(|value|, floor) (relative above floor, absolute
 * below: floor 1 when only the comparison with 1 matters) and the doubled nmu stays ≤ nmu_max. Only
 * the channels still disagreeing are evaluated again, so one narrow lobe does not make every channel pay
 * for the finest rule. A channel is also done once fine + 4·|fine − coarse| ≤ below with |fine − coarse| ≤
 * TAB_BELOW_DIFF (the energy table only
 * compares its bound, fine + 2·|fine − coarse|, with 1: a value clearly below needs no more digits; with
 * ws->offset the rest of a split albedo is added to the comparison; −∞ turns
 * this off). out[l] is the finest value; diff[l] (may be NULL) the last |fine − coarse|, or 0 when no
 * doubling fits under nmu_max. With ws->indep (the DHR's) the coarser rule's independent twin (hemi_nodes_alt: no
 * node shared) must agree with the finer rule as well, and diff is the larger disagreement: two nested-like rules
 * can agree by chance in a rule's pre-asymptotic range (test_dynamic_range's spike, sqrt transform: from 32 × 48 the
 * last step read 4e-6 against an error of 5.8e-5; with the twin 2.7e-5), at one more coarse rule per doubling.
 */
int recon_albedo_adaptive(const struct recon_model *m, double theta_i, int nmu, int nphi, int nmu_max,
			   int square_rule, int scaled, double tol, double floor, double below, struct albedo_ws *ws,
			   double *out,
			   double *diff, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl, nch = L;
	for (size_t l = 0; l < L; l++) {
		ws->chan[l] = l;
		if (diff)
			diff[l] = 0;
	}
	memcpy(ws->wsub, m->w, L * n * sizeof *ws->wsub);
	/* the plain starting rule, then the probes at the data's brightest directions; where they find a lobe it
	 * missed, the starting rule again with boxes there (and every doubling after it) */
	ws->nbox = 0;
	ws->keep_n = 0;
	ws->cell_min = 2;
	ws->nstep = scaled && !recon_part_hv(ws->part) && ws->step ? energy_steps(m, theta_i, square_rule, ws) : 0;
	ws->store = ws->nested; /* the starting rule keeps its values for the first doubling (nested rules) */
	if (ws->nested && !square_rule && !recon_part_hv(ws->part))
		nphi = (nphi + 3) / 4 * 4; /* fewer azimuths near the pole (cc_row_m) */
	int rc = albedo_rule(m, theta_i, nmu, nphi, square_rule, scaled, nch, ws, out, err);
	ws->store = 0;
	if (rc)
		return -1;
	int nb = albedo_boxes(m, theta_i, nmu, nphi, square_rule, scaled, tol, floor, ws, out, err);
	if (nb < 0 || (nb > 0 && albedo_rule(m, theta_i, nmu, nphi, square_rule, scaled, nch, ws, out, err)))
		return -1;
	int indep = ws->indep && !square_rule && !recon_part_hv(ws->part);
	while (nch > 0 && 2 * nmu <= nmu_max) {
		if (indep) { /* the coarser rule's independent twin, for the channels still open */
			ws->alt_rule = 1;
			rc = albedo_rule(m, theta_i, nmu, nphi, square_rule, scaled, nch, ws, ws->alt, err);
			ws->alt_rule = 0;
			if (rc)
				return -1;
		}
		nmu *= 2;
		nphi *= 2;
		ws->boxn = ws->boxn * 2 <= 256 ? ws->boxn * 2 : 256;
		ws->cell_min = ws->cell_min * 2 <= 128 ? ws->cell_min * 2 : 128;
		if (albedo_rule(m, theta_i, nmu, nphi, square_rule, scaled, nch, ws, ws->fine, err))
			return -1;
		size_t keep = 0;
		for (size_t k = 0; k < nch; k++) {
			size_t l = ws->chan[k];
			double d = fabs(ws->fine[k] - out[l]), ref = fmax(fabs(ws->fine[k]), floor);
			if (indep)
				d = fmax(d, fabs(ws->fine[k] - ws->alt[k]));
			if (ws->floor_ch)
				ref = fmax(ref, ws->floor_ch[l]);
			out[l] = ws->fine[k];
			if (diff)
				diff[l] = d;
			double off = ws->offset ? ws->offset[l] : 0.0; /* the rest of a split albedo (fine + 4d) */
			if (!(d <= tol * ref) && !(ws->fine[k] + 4.0 * d + off <= below && d <= TAB_BELOW_DIFF)) {
				if (keep != k) {
					ws->chan[keep] = l;
					memmove(ws->wsub + keep * n, ws->wsub + k * n, n * sizeof *ws->wsub);
				}
				keep++;
			}
		}
		nch = keep;
	}
	return 0;
}

int recon_hv_nodes(double theta_i, double alpha, int nu, int nphi, double *c6, double *wt)
{
	double x[256], w[256];
	if (nu > 256 || rbf_gauss_legendre01(nu, x, w) || !(alpha > 0))
		return -1;
	double si = sin(theta_i), ci = cos(theta_i), wi[3] = { si, 0, ci }, a2 = alpha * alpha;
	size_t k = 0;
	for (int i = 0; i < nu; i++) {
		/* tan²θh = α² u/(1 − u); dωh = sinθh dθh dφ = (α² + t²)² / (2α²(1 + t²)^{3/2}) du dφ, t = tanθh */
		double u = x[i], t2 = a2 * u / (1 - u), t = sqrt(t2), ch = 1 / sqrt(1 + t2), sh = t * ch;
		double jac = (a2 + t2) * (a2 + t2) / (2 * a2 * (1 + t2) * sqrt(1 + t2));
		for (int j = 0; j < nphi; j++) {
			double p = (j + 0.5) * M_PI / nphi;
			double h[3] = { sh * cos(p), sh * sin(p), ch }; /* about the normal, the specular half vector */
			double d = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2];
			double wo[3] = { 2 * d * h[0] - wi[0], 2 * d * h[1] - wi[1], 2 * d * h[2] - wi[2] };
			double weight = 0;
			if (d > 0 && wo[2] > 1e-12) {
				weight = w[i] * jac * (2.0 * M_PI / nphi) * 4 * d * wo[2];
			} else {
				wo[0] = -wi[0];
				wo[1] = 0;
				wo[2] = wi[2] > 1e-12 ? wi[2] : 1e-12; /* any valid point; weight 0 */
			}
			double to = acos(fmin(1, fmax(0, wo[2] / sqrt(wo[0] * wo[0] + wo[1] * wo[1] + wo[2] * wo[2]))));
			double po = atan2(wo[1], wo[0]);
			rbf_canon(theta_i, 0.0, to, po, c6 + 6 * k);
			wt[k] = weight;
			k++;
		}
	}
	return 0;
}

int recon_albedo(const struct recon_model *m, double theta_i, int nmu, int nphi, int scaled, double *out,
		 struct acq_err *err)
{
	if (!(theta_i >= 0 && theta_i <= M_PI / 2) || nmu < 1 || nphi < 1 || nmu > ALB_NMU_MAX || nphi > 4096)
		return acq_errf(err, ACQ_E_INVAL, "albedo: bad incidence or quadrature size");
	int top = nmu, tphi = nphi;
	while (2 * top <= ALB_NMU_MAX) {
		top *= 2;
		tphi *= 2;
	}
	struct albedo_ws ws;
	if (recon_albedo_ws_init(&ws, m, (size_t)top * (size_t)tphi, err))
		return -1;
	int rc = recon_albedo_adaptive(m, theta_i, nmu, nphi, ALB_NMU_MAX, 0, scaled, TAB_TOL, 1e-300, -HUGE_VAL, &ws, out, NULL,
				 err);
	recon_albedo_ws_free(&ws);
	return rc;
}


/*
 * The checker's albedo (recon_albedo_cubature): globally adaptive cubature on cells of (μ = cosθo, φ) ∈ [0, 1] × [0, π]
 * (mirror doubled), each cell integrated by Genz and Malik's degree-7 rule with its embedded degree-5 rule (17 nodes
 * in two dimensions; J. Comput. Appl. Math. 6, 1980; the error estimate |I7 − I5| as in hcubature). The cell of
 * largest relative error is halved along the axis of its larger fourth difference. Unlike the fixed rules doubled
 * globally, cells gather where the integrand bends: at grazing incidence the interpolant's lobe about the mirror
 * can be a few hundredths wide in μ and in azimuth (the log-uniform random model at θi = 90°: Gauss-Legendre in
 * cos²θo up to 192 × 384 read 1.49 where this reads 1.9737, which finer adaptive references confirm to 1e-8).
 */
#define GM_N 17
static const double gm_l2 = 0.35856858280031809, gm_l4 = 0.94868329805051380, gm_l5 = 0.68824720161168529;
/* weights of the degree-7 and degree-5 rules (normalised to the cell's area), two dimensions */
static const double gm_w7[5] = { -3816.0 / 19683, 980.0 / 6561, 1020.0 / 19683, 200.0 / 19683, 6859.0 / 19683 / 4 };
static const double gm_w5[5] = { -971.0 / 729, 245.0 / 486, 65.0 / 1458, 25.0 / 729, 0 };

/* Node k of the rule on [−1, 1]²: (u, v) and its weight class. */
static int gm_node(int k, double *u, double *v)
{
	static const signed char s[4][2] = { { 1, 0 }, { -1, 0 }, { 0, 1 }, { 0, -1 } };
	static const signed char d[4][2] = { { 1, 1 }, { 1, -1 }, { -1, 1 }, { -1, -1 } };
	if (k == 0) {
		*u = *v = 0;
		return 0;
	}
	if (k <= 8) {
		double l = k <= 4 ? gm_l2 : gm_l4;
		*u = l * s[(k - 1) % 4][0];
		*v = l * s[(k - 1) % 4][1];
		return k <= 4 ? 1 : 2;
	}
	double l = k <= 12 ? gm_l4 : gm_l5;
	*u = l * d[(k - 9) % 4][0];
	*v = l * d[(k - 9) % 4][1];
	return k <= 12 ? 3 : 4;
}

struct gm_cell {
	double x0, x1, p0, p1; /* μ and φ ranges */
	int axis;              /* axis of the larger fourth difference (0: μ, 1: φ) */
	double score;          /* largest error over the channels, relative to their targets */
};

/* Integrate cells cs[0..nc) for the nch channels chan[] (weights packed in ws->wsub): I[c·nch + k] and the error
 * estimate E[c·nch + k]; each cell's split axis from the fourth differences, channel k weighted by iw[k]. */
static void gm_eval(const struct recon_model *m, double theta_i, int scaled, struct gm_cell *cs, size_t nc, size_t nch,
		    const double *iw, struct albedo_ws *ws, double *I, double *E)
{
	const size_t per = QUAD_BLOCK / GM_N; /* cells per block */
	const double r = gm_l2 * gm_l2 / (gm_l4 * gm_l4);
	for (size_t c0 = 0; c0 < nc; c0 += per) {
		size_t cb = nc - c0 < per ? nc - c0 : per, q = 0;
		for (size_t c = c0; c < c0 + cb; c++)
			for (int k = 0; k < GM_N; k++, q++) {
				double u, v;
				gm_node(k, &u, &v);
				double mu = 0.5 * (cs[c].x0 + cs[c].x1) + 0.5 * (cs[c].x1 - cs[c].x0) * u;
				double ph = 0.5 * (cs[c].p0 + cs[c].p1) + 0.5 * (cs[c].p1 - cs[c].p0) * v;
				rbf_canon(theta_i, 0.0, acos(fmin(fmax(mu, 0.0), 1.0)), ph, ws->c6 + 6 * q);
				ws->wt[q] = mu * 2.0; /* cosθo, and the mirror half of the azimuths */
			}
		for (size_t q0 = 0; q0 < q; q0 += RECON_EVAL_BLOCK) {
			size_t b = q - q0 < RECON_EVAL_BLOCK ? q - q0 : RECON_EVAL_BLOCK;
			recon_eval_block_part(m, b, ws->c6 + 6 * q0, scaled, RECON_PART_ALL, nch, ws->chan, ws->wsub,
					      ws->vals + q0 * nch, ws->work);
		}
		ws->evals += (double)q * (double)m->n * (1.0 + (double)nch / 64.0);
		for (size_t c = c0; c < c0 + cb; c++) {
			const double *f = ws->vals + (c - c0) * GM_N * nch, *wq = ws->wt + (c - c0) * GM_N;
			double area = (cs[c].x1 - cs[c].x0) * (cs[c].p1 - cs[c].p0), d4[2] = { 0, 0 };
			for (size_t k = 0; k < nch; k++) {
				double s7 = 0, s5 = 0, v[GM_N];
				for (int j = 0; j < GM_N; j++) {
					double u, w;
					int cl = gm_node(j, &u, &w);
					v[j] = f[(size_t)j * nch + k] * wq[j];
					s7 += gm_w7[cl] * v[j];
					s5 += gm_w5[cl] * v[j];
				}
				I[c * nch + k] = s7 * area;
				E[c * nch + k] = fabs(s7 - s5) * area;
				/* fourth differences along μ (nodes 1, 2 and 5, 6) and along φ (3, 4 and 7, 8) */
				d4[0] += iw[k] * fabs(v[1] + v[2] - 2 * v[0] - r * (v[5] + v[6] - 2 * v[0]));
				d4[1] += iw[k] * fabs(v[3] + v[4] - 2 * v[0] - r * (v[7] + v[8] - 2 * v[0]));
			}
			cs[c].axis = d4[1] > d4[0];
		}
	}
}

/* Cubature of the channels chan[0..nch) (weights in ws->wsub): out[k], errest[k]; 1 when every channel met its
 * target, 0 when the cells ran out, −1 on allocation failure. */
static int gm_chunk(const struct recon_model *m, double theta_i, int ncx, int ncp, int scaled, double tol, double floor,
		    size_t max_cells, size_t nch, struct albedo_ws *ws, double *out, double *errest)
{
	size_t n0 = (size_t)ncx * (size_t)ncp, cap = max_cells > n0 ? max_cells : n0;
	struct gm_cell *cs = malloc(cap * sizeof *cs), *nw = malloc(cap * sizeof *nw);
	double *I = malloc(cap * nch * sizeof *I), *E = malloc(cap * nch * sizeof *E);
	double *nI = malloc(cap * nch * sizeof *nI), *nE = malloc(cap * nch * sizeof *nE);
	double *iw = malloc(nch * sizeof *iw);
	size_t *idx = malloc(cap * sizeof *idx);
	int rc = -1;
	if (!cs || !nw || !I || !E || !nI || !nE || !iw || !idx)
		goto out;
	for (size_t k = 0; k < nch; k++)
		iw[k] = 1.0;
	size_t nc = 0;
	for (int i = 0; i < ncx; i++)
		for (int j = 0; j < ncp; j++)
			cs[nc++] = (struct gm_cell){ (double)i / ncx, (double)(i + 1) / ncx, M_PI * j / ncp, M_PI * (j + 1) / ncp,
						     0, 0 };
	gm_eval(m, theta_i, scaled, cs, nc, nch, iw, ws, I, E);
	for (;;) {
		/* totals (summed afresh: no drift), targets, and which channels still miss theirs */
		int open = 0;
		for (size_t k = 0; k < nch; k++) {
			double s = 0, e = 0;
			for (size_t c = 0; c < nc; c++) {
				s += I[c * nch + k];
				e += E[c * nch + k];
			}
			out[k] = s;
			errest[k] = e;
			double t = tol * fmax(fabs(s), floor);
			iw[k] = e > t ? 1.0 / t : 0.0;
			open |= e > t;
		}
		if (!open) {
			rc = 1;
			break;
		}
		double smax = 0;
		for (size_t c = 0; c < nc; c++) {
			double sc = 0;
			for (size_t k = 0; k < nch; k++)
				sc = fmax(sc, E[c * nch + k] * iw[k]);
			cs[c].score = sc;
			smax = fmax(smax, sc);
		}
		/* halve every cell within a factor 4 of the worst, as far as the cells last */
		size_t ns = 0;
		for (size_t c = 0; c < nc && nc + ns < cap; c++)
			if (cs[c].score >= 0.25 * smax)
				idx[ns++] = c;
		if (ns == 0) {
			rc = 0;
			break;
		}
		for (size_t s = 0; s < ns; s++) {
			struct gm_cell a = cs[idx[s]], b = a;
			if (a.axis)
				a.p1 = b.p0 = 0.5 * (a.p0 + a.p1);
			else
				a.x1 = b.x0 = 0.5 * (a.x0 + a.x1);
			nw[2 * s] = a;
			nw[2 * s + 1] = b;
		}
		gm_eval(m, theta_i, scaled, nw, 2 * ns, nch, iw, ws, nI, nE);
		for (size_t s = 0; s < ns; s++) {
			size_t c = idx[s], d = nc + s;
			cs[c] = nw[2 * s];
			cs[d] = nw[2 * s + 1];
			memcpy(I + c * nch, nI + 2 * s * nch, nch * sizeof *I);
			memcpy(E + c * nch, nE + 2 * s * nch, nch * sizeof *E);
			memcpy(I + d * nch, nI + (2 * s + 1) * nch, nch * sizeof *I);
			memcpy(E + d * nch, nE + (2 * s + 1) * nch, nch * sizeof *E);
		}
		nc += ns;
	}
out:
	free(cs);
	free(nw);
	free(I);
	free(E);
	free(nI);
	free(nE);
	free(iw);
	free(idx);
	return rc;
}

int recon_albedo_cubature(const struct recon_model *m, double theta_i, int ncx, int ncp, int scaled, double tol,
			  double floor, size_t max_cells, struct albedo_ws *ws, double *out, double *errest,
			  size_t *unresolved, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl;
	if (!(theta_i >= 0 && theta_i <= M_PI / 2) || ncx < 1 || ncp < 1)
		return acq_errf(err, ACQ_E_INVAL, "albedo cubature: bad incidence or cell grid");
	if (ws_reserve(ws, QUAD_BLOCK))
		return acq_errf(err, ACQ_E_NOMEM, "albedo cubature: out of memory");
	*unresolved = 0;
	for (size_t l0 = 0; l0 < L; l0 += RECON_CUB_CHUNK) {
		size_t nch = L - l0 < RECON_CUB_CHUNK ? L - l0 : RECON_CUB_CHUNK;
		for (size_t k = 0; k < nch; k++)
			ws->chan[k] = l0 + k;
		memcpy(ws->wsub, m->w + l0 * n, nch * n * sizeof *ws->wsub);
		int rc = gm_chunk(m, theta_i, ncx, ncp, scaled, tol, floor, max_cells, nch, ws, out + l0, errest + l0);
		if (rc < 0)
			return acq_errf(err, ACQ_E_NOMEM, "albedo cubature: out of memory for %zu cells", max_cells);
		if (rc == 0)
			for (size_t k = 0; k < nch; k++)
				*unresolved += errest[l0 + k] > tol * fmax(fabs(out[l0 + k]), floor);
	}
	return 0;
}
