/* check: the property checker of a model: non-negativity and reciprocity at random pairs, the albedo ≤ 1 by an
 * independent quadrature (adaptive cubature, quad.c). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/recon_int.h"
#include "recon/rng.h"

/* Cells per chunk of channels of the checker's cubature (≈ 1 KB each): a channel still above its error target
 * then is counted in alb_unresolved. */
#define CHECK_CELLS 16384

int recon_check(const struct recon_model *m, size_t npairs, size_t nalb, uint64_t seed,
		struct recon_check_report *rep, recon_progress_fn progress, void *pctx, struct acq_err *err)
{
	memset(rep, 0, sizeof *rep);
	size_t L = m->nwl, B = 1024;
	double *ang = malloc(B * 4 * sizeof *ang), *swp = malloc(B * 4 * sizeof *swp);
	double *f1 = malloc(B * L * sizeof *f1), *f2 = malloc(B * L * sizeof *f2), *alb = malloc(2 * L * sizeof *alb);
	int rc = -1;
	struct albedo_ws ws = { 0 };
	if (!ang || !swp || !f1 || !f2 || !alb) {
		acq_errf(err, ACQ_E_NOMEM, "check: out of memory");
		goto out;
	}
	/* the independent quadrature: adaptive cubature to TAB_TOL (absolute below an albedo of 1: only the comparison
	 * with 1 matters) from cells three times the spacing of a 48 × 96 rule raised to the narrowest lobe the model
	 * can make (a cell of 17 nodes for 3 × 3 nodes of that rule) */
	int cmu = 48, cphi = 96;
	size_t cq;
	recon_lobe_rule(m, ALB_NMU_MAX, 0, &cmu, &cphi, &cq);
	if (recon_albedo_ws_init(&ws, m, 4096, err))
		goto out;
	struct recon_rng r;
	recon_rng_seed(&r, seed);
	rep->min_value = INFINITY;
	rep->max_albedo = -INFINITY;
	rep->energy_excess = -INFINITY;
	for (size_t p0 = 0; p0 < npairs; p0 += B) {
		size_t b = npairs - p0 < B ? npairs - p0 : B;
		if (progress)
			progress(pctx, "pairs", (double)p0 / (double)npairs);
		for (size_t i = 0; i < b; i++) {
			/* uniform on the hemisphere: cosθ uniform; φ uniform on [0, 2π) for both directions */
			double *a = ang + 4 * i;
			a[0] = acos(recon_rng_unif(&r));
			a[1] = 2 * M_PI * recon_rng_unif(&r);
			a[2] = acos(recon_rng_unif(&r));
			a[3] = 2 * M_PI * recon_rng_unif(&r);
			double *s = swp + 4 * i;
			s[0] = a[2];
			s[1] = a[3];
			s[2] = a[0];
			s[3] = a[1];
		}
		if (recon_eval(m, b, ang, f1, err) || recon_eval(m, b, swp, f2, err))
			goto out;
		for (size_t i = 0; i < b * L; i++) {
			if (!isfinite(f1[i]) || !isfinite(f2[i])) {
				rep->nonfinite++;
				continue;
			}
			if (f1[i] < rep->min_value)
				rep->min_value = f1[i];
			if (f2[i] < rep->min_value)
				rep->min_value = f2[i];
			double d = fabs(f1[i] - f2[i]), mx = fmax(fabs(f1[i]), fabs(f2[i]));
			if (d > rep->max_recip_abs)
				rep->max_recip_abs = d;
			if (mx > 1e-300 && d / mx > rep->max_recip_rel)
				rep->max_recip_rel = d / mx;
		}
		rep->npairs += b;
	}
	for (size_t t = 0; t < nalb + 2; t++) {
		if (progress)
			progress(pctx, "albedo", (double)t / (double)(nalb + 2));
		double th = t == 0 ? 0.0 : t == 1 ? M_PI / 2 : asin(recon_rng_unif(&r)) ; /* sinθ uniform: more grazing */
		size_t un;
		if (recon_albedo_cubature(m, th, (cmu + 2) / 3, (cphi + 2) / 3, 1, TAB_TOL, 1.0, CHECK_CELLS, &ws, alb,
					  alb + L, &un, err))
			goto out;
		rep->alb_unresolved += un;
		for (size_t l = 0; l < L; l++) {
			if (!isfinite(alb[l])) {
				rep->nonfinite++;
				continue;
			}
			/* the cubature's own error: it stops once its estimate is within TAB_TOL relative, so on a model
			 * of huge dynamic range the check and the energy table can differ by that much */
			double q = 2.0 * fabs(alb[L + l]);
			if (alb[l] > rep->max_albedo) {
				rep->max_albedo = alb[l];
				rep->max_albedo_theta = th;
				rep->max_albedo_wl = m->wl[l];
				rep->max_albedo_qerr = q;
			}
			if (alb[l] - q - 1.0 > rep->energy_excess)
				rep->energy_excess = alb[l] - q - 1.0;
		}
		rep->nalb++;
	}
	rc = 0;
out:
	free(ang);
	free(swp);
	free(f1);
	free(f2);
	free(alb);
	recon_albedo_ws_free(&ws);
	return rc;
}

