/* energy: the albedo table A(θ, λ) that bounds the unscaled interpolant's albedo, so that the evaluated BRDF
 * s·f̂, s = 1/max(1, A(θi), A(θo)), conserves energy. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/recon_int.h"

/* Albedo table: nodes every 10°, bisected; node rules from Clenshaw-Curtis 10 in cosθo × 12 azimuth intervals,
 * nested (quad.c cc_nodes: each doubling reuses the rule before it). */
#define TAB_N 10
#define TAB_NMU 10
#define TAB_NPHI 12
#define TAB_NMU_MAX 160   /* finest node rule: 160 × 192 */
#define TAB_CURV_TOL 0.01 /* largest second difference over an interval (albedo units) before bisecting */
#define TAB_DEPTH 7       /* finest interval 10°/2⁷ ≈ 0.08° */
#define TAB_MAX_NODES 96  /* node budget of the bisection (breadth first) */
/* A spiky model's table also starts at 10°/2^k, k = 1 … TAB_POLE (session 16): near the pole the canonical frame
 * (rbf_canon) turns ωo's azimuths by Δ·sinθi/(sinθi + sinθo), so the path of the albedo's integral through the
 * interpolant changes on the scale of θi itself, not of 10°: on the log-uniform random 1000 × 651 input (seed 2) one
 * channel's albedo rose 0.5 % between θi = 0 and 1° and fell back by 2°, over a bound from the nodes 0, 5 and 10°
 * (the bend test cannot see a bump between its nodes; the budget stops the bisection there). Graded nodes
 * 5, 2.5, 1.25, 0.625° give every interval near the pole a width in proportion to its distance from it. */
#define TAB_POLE 4
#define TAB_PEAKS 8       /* a spiky model's brightest samples whose zenith angles start the table (θi and θo) */
/* Work budget of the table in kernel evaluations (~3 s on one core): past it no interval is bisected and each
 * remaining node gets its starting rule only, its difference d from the half rule inside it (session 8; before, one
 * doubling beyond the starting rule). Spiky models reach it (log-uniform random values over
 * 12 decades: 5.3e9 evaluations, 19 s, without it); the paper-size fits of the simulator's materials need
 * 1e8-5e8. brdf-recon check verifies the bound with an independent rule either way; the fit warns. The budget
 * does not cut the start nodes nor the first level's midpoints: the log-uniform random 1000 × 651 input (bench_recon)
 * spent ~2.4e9 there with the nested rules (3.4e9 with Gauss-Legendre ones), 19 nodes; ~1.45e9 once the nodes past
 * the budget (12 of its 19) took the starting rule only. */
#define TAB_WORK_MAX 1e9
/* A spiky model's budget (leave-one-out RMS > 1 in ln f: held-out samples predicted only to a factor e; session 16):
 * its bound is only ever compared with 1 and its values cannot be trusted between the samples, so its table pays for
 * fewer nodes on the full rule (the random 1000 × 651 input: 4 of them instead of 10-12). The nodes past
 * a budget are bounds all the same (margin 2d + TAB_TOL; brdf-recon check verifies); only coarser. */
#define TAB_WORK_SPIKY 4e8
/* A node past the budget costs ≈ TAB_NODE_UNITS starting rules: its half rule and one doubling, with boxes at the
 * data's bright directions (quad.c; 2.5e7-3.8e7 kernel evaluations on the random 1000 × 651 input, whose starting
 * rule is 10 × 20: 13-17 units; 28 before the boxes shrank with the rule, session 16). Peak nodes are admitted as
 * far as a quarter of TAB_WORK_MAX pays for them and their midpoints at that cost. */
#define TAB_NODE_UNITS 15.0
/* The trend's GGX lobe over half vectors (recon_hv_nodes): 16 nodes in u × 16 azimuths on [0, π] to start,
 * doubled up to 64 × 64 (the largest difference from a 256 × 2048 hemisphere rule there: 9e-4, where the horizon
 * cuts a lobe of α = 0.03 at 85°; test_recon_trend). */
#define TAB_HV_NU 16
#define TAB_HV_NPHI 16
#define TAB_HV_NU_MAX 64
/* A coat's base lobe (GGX of α2 ≈ 0.3) over its own half vectors: TAB_HVB_NU × TAB_HVB_NU nodes to start, doubled
 * up to TAB_HV_NU_MAX (session 15; 8 to start read the same clear-coat table 20 % faster but its bounds up to 0.05
 * looser at 85-88°, d from the coarser pair) */
#define TAB_HVB_NU 16
#define TAB_ROOM_K 2.0   /* an interval bent past TAB_CURV_TOL is not bisected when max + K·Δ + qn ≤ 1 (below) */
#define TAB_BELOW 0.9     /* a node's channel is also done once fine + 4·|fine − coarse| ≤ this: clearly below 1 */

/*
 * The energy table: A(θ, λ) ≥ the albedo a(θ, λ) of the unscaled interpolant on each interval of θ.
 * Each node's channels come from recon_albedo_adaptive on nested rules (from 10 × 12, doubled up to 160 × 192, each
 * doubling evaluating only its new nodes, until two rules
 * agree to TAB_TOL in albedo units, relative above 1: the table is only ever compared with 1), because the
 * map back e^g can make lobes far narrower than the kernel; d is the last difference between rules. The
 * nodes start every 10°; each interval [θ_lo, θ_hi] is probed at its midpoint and, while some channel's
 * second difference Δ = |a_lo − 2a_mid + a_hi| exceeds TAB_CURV_TOL · max(1, a) (plus, where the interval
 * is clearly below 1, what the nodes' quadrature uncertainty can make of it, 3(d_lo + 2d_mid + d_hi)) (a
 * feature narrower than the interval: a spike in θi), bisected, down to 10°/2^TAB_DEPTH. Both halves then get the bound
 * max(a + 2d + TAB_TOL·max(a, 1) over the three nodes: albtab_margin) + Δ (the interpolation error h²/8·|a''| of a C² function, with a''
 * from Δ, doubled). The evaluated function is s·f̂ with s = 1/max(1, A(θi), A(θo)), whose albedo at θi is
 * ≤ a(θi)/max(1, A(θi)) ≤ 1 whenever A bounds a. `brdf-recon check` verifies it with an independent rule.
 * An interval whose bend would bisect it is closed instead when every channel has room under 1 for twice the bend,
 * max + 2Δ + 3(d_lo + 2d_mid + d_hi) ≤ 1 (TAB_ROOM_K; smooth models only: leave-one-out RMS ≤ 1 in ln f), with
 * that widened bound: s is 1 there whatever the bound's digits (session 14: clear-coat's albedo climbs 0.63 → 0.95
 * from 75° to 90°; the bisection spent 6 of its 29 nodes, a third of the table's work, tightening bounds ≤ 0.98).
 * test_recon_energy's room-rule tests build the table with and without it (recon_energy_table_room).
 * The work is bounded: intervals are bisected level by level (all of one level before the next) up to
 * TAB_MAX_NODES nodes; an interval left open keeps the bound of the probe that opened it.
 */
struct albtab {
	const struct recon_model *m;
	struct albedo_ws ws, wl, wb; /* whole (or smooth part), the trend's lobe part (split), a coat's base lobe */
	int nmu, nphi;      /* starting rule (recon_lobe_rule) */
	int split;          /* the trend's GGX lobe integrated apart, over half vectors */
	int base;           /* the coat kind's base lobe (b1, b2; GGX of α2) too, over its own half vectors */
	double *diff, *al, *dl, *off, *ab, *db;
	size_t L;
	double margin;
	double budget; /* work budget in kernel evaluations: TAB_WORK_MAX, TAB_WORK_SPIKY for a spiky model */
};

static int albtab_margin(struct albtab *T, double *a);

/* a[L] = the node's albedo plus its quadrature margin 2d. A lobe narrower than the rules (a spiky model's) is
 * found by recon_albedo_adaptive's probes at the data's brightest directions, which refine the rules there. */
static int albtab_node(struct albtab *T, double theta, double *a, struct acq_err *err)
{
	/* past the work budget every further node gets the starting rule only, its difference d from the half rule it
	 * holds (nested rules: the doubling from half the starting rule evaluates only the starting rule's nodes; d
	 * is then larger, the bound more conservative, than with one doubling beyond: 4× the work on the random
	 * 1000 × 651 input, whose nodes past the budget cost 60 % of its fit) */
	double work = T->ws.evals + T->wl.evals + T->wb.evals;
	int capped = work > T->budget, nmu = T->nmu, nphi = T->nphi;
	int nmax = capped ? (T->ws.nested ? nmu : 2 * nmu) : TAB_NMU_MAX;
	if (capped && T->ws.nested) {
		nmu = (nmu + 1) / 2;
		nphi = (nphi + 1) / 2;
		nmax = 2 * nmu;
	}
	/* and its boxes (quad.c albedo_boxes) those of the table's own starting rule, the rule it halved: boxes sized
	 * from the half rule's spacing were twice as wide at the same density, 4× their nodes (session 16: the random
	 * 1000 × 651 input's nodes past the budget took 5.3e7 kernel evaluations each, now 2.5e7-3.8e7) */
	T->ws.box_fine = capped && T->ws.nested;
	if (!T->split)
		return recon_albedo_adaptive(T->m, theta, nmu, nphi, nmax, 0, 0, TAB_TOL, 1.0, TAB_BELOW, &T->ws, a,
					     T->diff, err) ? -1 : albtab_margin(T, a);
	/* split: the smooth part on the hemisphere rule, refined to TAB_TOL absolute (a part being below 1 says nothing
	 * of the whole), then the lobe over half vectors, which stops once the whole is clearly below 1 (a coat: its
	 * narrow lobe to TAB_TOL as well, then its base lobe, which stops so) */
	if (recon_albedo_adaptive(T->m, theta, nmu, nphi, nmax, 0, 0, TAB_TOL, 1.0, -HUGE_VAL, &T->ws, a, T->diff,
				  err))
		return -1;
	for (size_t l = 0; l < T->L; l++)
		T->off[l] = a[l] + 4.0 * T->diff[l];
	T->wl.offset = T->off;
	if (recon_albedo_adaptive(T->m, theta, TAB_HV_NU, TAB_HV_NPHI, capped ? 2 * TAB_HV_NU : TAB_HV_NU_MAX,
				  0, 0, TAB_TOL, 1.0, T->base ? -HUGE_VAL : TAB_BELOW, &T->wl, T->al, T->dl, err))
		return -1;
	for (size_t l = 0; l < T->L; l++) {
		a[l] += T->al[l];
		T->diff[l] += T->dl[l];
	}
	/* a coat's base lobe (session 15): over its own half vectors (GGX of α2), last, so that it stops once the whole
	 * is clearly below 1; on the hemisphere rule it held the smooth part at 88 × 192 nodes from 87.5° on (clear-coat,
	 * its tE ≈ 0.5 there: 6.5e7 evaluations per node; now the smooth part stops at 20 × 24, 1.6e6) */
	if (T->base) {
		for (size_t l = 0; l < T->L; l++)
			T->off[l] = a[l] + 4.0 * T->diff[l];
		T->wb.offset = T->off;
		if (recon_albedo_adaptive(T->m, theta, TAB_HVB_NU, TAB_HVB_NU, capped ? 2 * TAB_HVB_NU : TAB_HV_NU_MAX, 0,
					  0, TAB_TOL, 1.0, TAB_BELOW, &T->wb, T->ab, T->db, err))
			return -1;
		for (size_t l = 0; l < T->L; l++) {
			a[l] += T->ab[l];
			T->diff[l] += T->db[l];
		}
	}
	return albtab_margin(T, a);
}

/*
 * Add the quadrature margin to a[L]; 0. The margin is 2d + TAB_TOL·max(|a|, 1): the rules stop once two of them
 * agree to TAB_TOL (relative above 1), which is all the value is known to. 2d alone holds only once the rules
 * converge (the finer one's error well below their difference); from a coarse start two rules can agree by both
 * missing the same part: at ACQ_SEED 109 of test_log_uniform_random (1000 random centres, 12 decades) the node
 * at θ = 0 read 4.4495 with d = 1.6e-3 from 10 × 16 and 20 × 32 nodes, where the check's 96 × 192 rule reads
 * 4.4539 (an error of 2.8 d): the bound 4.4531 was 2e-4 low and the check read an albedo of 1.0002.
 */
static int albtab_margin(struct albtab *T, double *a)
{
	for (size_t l = 0; l < T->L; l++) {
		double mg = 2.0 * T->diff[l] + TAB_TOL * fmax(fabs(a[l]), 1.0);
		if (mg > T->margin)
			T->margin = mg;
		a[l] += mg;
	}
	return 0;
}

/* Nodes th[n] with rows a[n·L] and their last quadrature differences dq[n·L]; interval i (node i to i+1) has
 * done[i] and bound row b[i·L]. */
struct albgrid {
	size_t n;
	double *th, *a, *dq, *b;
	unsigned char *done;
};

static void albgrid_free(struct albgrid *g)
{
	free(g->th);
	free(g->a);
	free(g->dq);
	free(g->b);
	free(g->done);
	memset(g, 0, sizeof *g);
}

static int albgrid_alloc(struct albgrid *g, size_t cap, size_t L)
{
	memset(g, 0, sizeof *g);
	g->th = malloc(cap * sizeof *g->th);
	g->a = malloc(cap * L * sizeof *g->a);
	g->dq = malloc(cap * L * sizeof *g->dq);
	g->b = calloc(cap * L, sizeof *g->b);
	g->done = calloc(cap, 1);
	return g->th && g->a && g->dq && g->b && g->done ? 0 : -1;
}

static void albgrid_push(struct albgrid *g, size_t L, double th, const double *a, const double *dq, const double *b,
			 int done)
{
	g->th[g->n] = th;
	memcpy(g->a + g->n * L, a, L * sizeof *a);
	memcpy(g->dq + g->n * L, dq, L * sizeof *dq);
	if (b)
		memcpy(g->b + g->n * L, b, L * sizeof *b);
	g->done[g->n] = (unsigned char)done;
	g->n++;
}

static int cmp_dbl(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

/* The table's starting nodes (ascending, in [0, π/2]): every 10°, and for a spiky model (leave-one-out RMS > 1
 * in ln f) also the zenith angles, θi and θo, of its npeaks (≤ TAB_PEAKS) samples highest above the trend. The
 * probes of recon_albedo_adaptive find a narrow lobe in ωo at a node's incidence; a lobe narrower than an interval
 * in θ is found only if a node lands on it, and the interpolant's narrow peaks sit on the data: by reciprocity a
 * sample's peak raises the albedo at both its θi and its θo. A spiky model also gets the graded nodes near the pole
 * (TAB_POLE). Returns the count (≤ TAB_N + TAB_POLE + 2 TAB_PEAKS). */
static size_t albtab_start_nodes(const struct recon_model *m, size_t npeaks, double *th)
{
	size_t n = 0;
	double h = (M_PI / 2) / (double)(TAB_N - 1);
	for (size_t t = 0; t < TAB_N; t++)
		th[n++] = t + 1 == TAB_N ? M_PI / 2 : h * (double)t;
	if (!(m->loo_rms > 1.0) || !m->g || !m->ang)
		return n;
	for (int k = 1; k <= TAB_POLE; k++)
		th[n++] = h / (double)(1 << k);
	if (npeaks == 0) {
		qsort(th, n, sizeof *th, cmp_dbl);
		return n;
	}
	size_t top[TAB_PEAKS], ntop = 0;
	if (npeaks > TAB_PEAKS)
		npeaks = TAB_PEAKS;
	double topv[TAB_PEAKS];
	for (size_t k = 0; k < m->n; k++) {
		double v = -HUGE_VAL;
		for (size_t l = 0; l < m->nwl; l++)
			v = fmax(v, m->g[l * m->n + k]);
		size_t j;
		if (ntop < npeaks)
			j = ntop++;
		else if (v > topv[npeaks - 1])
			j = npeaks - 1;
		else
			continue;
		for (; j > 0 && topv[j - 1] < v; j--) {
			top[j] = top[j - 1];
			topv[j] = topv[j - 1];
		}
		top[j] = k;
		topv[j] = v;
	}
	for (size_t j = 0; j < ntop; j++)
		for (int c = 0; c < 4; c += 2) {
			double a = m->ang[4 * top[j] + (size_t)c];
			if (isfinite(a) && a > 0 && a < M_PI / 2)
				th[n++] = a;
		}
	qsort(th, n, sizeof *th, cmp_dbl);
	/* merge nodes within 0.05° of the one before (the grid's own nodes are 10° apart) */
	size_t w = 0;
	for (size_t r = 0; r < n; r++)
		if (w == 0 || th[r] - th[w - 1] > 0.05 * M_PI / 180)
			th[w++] = th[r];
	return w;
}

int recon_energy_table(struct recon_model *m, struct acq_err *err, recon_progress_fn pf, void *pctx)
{
	return recon_energy_table_room(m, 1, -1, err, pf, pctx);
}

int recon_energy_table_room(struct recon_model *m, int room_rule, double budget, struct acq_err *err,
			    recon_progress_fn pf, void *pctx)
{
	size_t L = m->nwl;
	struct albtab T = { .m = m, .L = L };
	struct albgrid g = { 0 }, ng = { 0 };
	double *amid = malloc(3 * L * sizeof *amid), *bnd = amid ? amid + L : NULL, *wide = amid ? amid + 2 * L : NULL;
	T.diff = malloc(L * sizeof *T.diff);
	int rc = -1;
	size_t qmax;
	T.nmu = TAB_NMU;
	T.nphi = TAB_NPHI;
	T.budget = budget >= 0 ? budget : m->loo_rms > 1.0 ? TAB_WORK_SPIKY : TAB_WORK_MAX;
	/* the split assumes e^g smooth at the kernel's scale away from the trend's lobe; a model whose held-out samples
	 * miss by more than a factor e (leave-one-out RMS > 1 in ln f: spikes) gets the whole on one rule sized for
	 * every lobe, as before the split (at seed 2155509500 of test_recon_extremes' dynamic range, LOO RMS 9.7, the
	 * split left the bound 7 % low at 89.9°) */
	T.split = trend_hv_alpha(m->trend, m->trend_alpha) > 0 && m->loo_rms <= 1.0; /* GGX, phong (trend.h) */
	T.base = T.split && trend_two_lobes(m->trend) && m->trend_alpha2 > 0;
	recon_lobe_rule(m, TAB_NMU_MAX, T.base ? 2 : T.split, &T.nmu, &T.nphi, &qmax);
	T.al = malloc(5 * L * sizeof *T.al);
	T.dl = T.al ? T.al + L : NULL;
	T.off = T.al ? T.al + 2 * L : NULL;
	T.ab = T.al ? T.al + 3 * L : NULL;
	T.db = T.al ? T.al + 4 * L : NULL;
	size_t qhv = (size_t)TAB_HV_NU_MAX * (TAB_HV_NU_MAX / TAB_HV_NU * TAB_HV_NPHI);
	if (!amid || !T.diff || !T.al || albgrid_alloc(&g, TAB_MAX_NODES, L) || recon_albedo_ws_init(&T.ws, m, qmax, err) ||
	    (T.split && recon_albedo_ws_init(&T.wl, m, qhv, err)) || (T.base && recon_albedo_ws_init(&T.wb, m, qhv, err))) {
		acq_errf(err, ACQ_E_NOMEM, "albedo table: out of memory");
		goto out;
	}
	T.ws.part = T.base ? RECON_PART_SMOOTH : T.split ? RECON_PART_NOLOBE : RECON_PART_ALL;
	T.wb.part = RECON_PART_BASE;
	T.ws.nested = 1; /* hemisphere rules that hold the rule before them (quad.c, cc_nodes) */
	T.wl.part = RECON_PART_LOBE;
	double start[TAB_N + TAB_POLE + 2 * TAB_PEAKS];
	/* peak nodes only as far as a quarter of TAB_WORK_MAX pays for them and their midpoints past the budget (the
	 * random 1000 × 651 input: 3 peaks; 8 before session 16) */
	double node_cost = TAB_NODE_UNITS * T.nmu * T.nphi * (double)m->n * (1.0 + (double)L / 64.0);
	size_t ns = albtab_start_nodes(m, (size_t)fmin(TAB_PEAKS, TAB_WORK_MAX / 4 / (2 * node_cost)), start);
	for (size_t t = 0; t < ns; t++) {
		if (pf)
			pf(pctx, "albedo table", 0.5 * (double)t / (double)ns);
		if (albtab_node(&T, start[t], amid, err))
			goto out;
		albgrid_push(&g, L, start[t], amid, T.diff, NULL, 0);
	}
	/* breadth first: every interval of one level is probed before any of the next, so the node budget
	 * is spent evenly where the albedo bends */
	for (int depth = 0; depth <= TAB_DEPTH; depth++) {
		if (pf)
			pf(pctx, "albedo table", 0.5 + 0.5 * (double)depth / (TAB_DEPTH + 1));
		if (albgrid_alloc(&ng, TAB_MAX_NODES, L)) {
			acq_errf(err, ACQ_E_NOMEM, "albedo table: out of memory");
			goto out;
		}
		int again = 0;
		for (size_t i = 0; i + 1 < g.n; i++) {
			const double *alo = g.a + i * L, *ahi = g.a + (i + 1) * L;
			/* the first level always probes; later ones while nodes remain (one per open interval) */
			if (g.done[i] || (depth > 0 && ng.n + (g.n - i) + 1 > TAB_MAX_NODES)) {
				albgrid_push(&ng, L, g.th[i], alo, g.dq + i * L, g.b + i * L, 1);
				continue;
			}
			double tmid = 0.5 * (g.th[i] + g.th[i + 1]);
			if (albtab_node(&T, tmid, amid, err))
				goto out;
			int split = 0, room = 1;
			const double *dlo = g.dq + i * L, *dhi = g.dq + (i + 1) * L;
			for (size_t l = 0; l < L; l++) {
				double d2 = fabs(alo[l] - 2.0 * amid[l] + ahi[l]);
				double mx = fmax(alo[l], fmax(amid[l], ahi[l]));
				/* a bend beyond what the nodes' quadrature uncertainty (each a = fine + 2d, fine within
				 * ≈ d of the exact value) can make of the second difference, where the interval is clearly
				 * below 1; near 1 every bend counts (a loose bound there scales the BRDF down for nothing) */
				double qn = 3.0 * (dlo[l] + 2.0 * T.diff[l] + dhi[l]);
				wide[l] = mx + TAB_ROOM_K * d2 + qn;
				room = room && wide[l] <= 1.0;
				if (!(mx + d2 + qn <= TAB_BELOW))
					qn = 0;
				if (d2 > TAB_CURV_TOL * fmax(mx, 1.0) + qn)
					split = 1;
				bnd[l] = mx + d2;
			}
			/* a bend with room under 1 on a smooth model (leave-one-out RMS ≤ 1 in ln f, as the split):
			 * the interval closes on the widened bound max + K·Δ + qn ≤ 1, where the factor s is 1 whatever
			 * the bound's digits; bisecting would only tighten a bound that scales nothing */
			if (split && room && room_rule && m->loo_rms <= 1.0) {
				split = 0;
				memcpy(bnd, wide, L * sizeof *bnd);
			}
			int done = !split || depth == TAB_DEPTH || T.ws.evals + T.wb.evals > T.budget;
			albgrid_push(&ng, L, g.th[i], alo, dlo, bnd, done);
			albgrid_push(&ng, L, tmid, amid, T.diff, bnd, done);
			again |= !done;
		}
		albgrid_push(&ng, L, g.th[g.n - 1], g.a + (g.n - 1) * L, g.dq + (g.n - 1) * L, NULL, 1);
		albgrid_free(&g);
		g = ng;
		memset(&ng, 0, sizeof ng);
		if (!again)
			break;
	}
	m->tab_capped = T.ws.evals + T.wl.evals + T.wb.evals > T.budget;
	free(m->tab_theta);
	free(m->tab_alb);
	m->tab_theta = NULL;
	m->tab_alb = NULL;
	m->ntab = g.n;
	m->alb_margin = T.margin;
	m->tab_theta = malloc(g.n * sizeof *m->tab_theta);
	m->tab_alb = malloc((g.n - 1) * L * sizeof *m->tab_alb);
	if (!m->tab_theta || !m->tab_alb) {
		acq_errf(err, ACQ_E_NOMEM, "albedo table: out of memory");
		goto out;
	}
	memcpy(m->tab_theta, g.th, g.n * sizeof *g.th);
	memcpy(m->tab_alb, g.b, (g.n - 1) * L * sizeof *g.b);
	rc = 0;
out:
	free(amid);
	free(T.diff);
	albgrid_free(&g);
	albgrid_free(&ng);
	recon_albedo_ws_free(&T.ws);
	recon_albedo_ws_free(&T.wl);
	recon_albedo_ws_free(&T.wb);
	free(T.al);
	return rc;
}

