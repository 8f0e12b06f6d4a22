/* calib: counts → BRDF with an uncertainty budget, relative or absolute method, binned to a wavelength grid. */
#include "daemon/calib.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define DEG (M_PI / 180.0)

void calib_cfg_defaults(struct calib_cfg *c)
{
	memset(c, 0, sizeof *c);
	c->method = CALIB_RELATIVE;
	c->rho_ref.n = 1;
	c->rho_ref.wl[0] = 550.0;
	c->rho_ref.val[0] = 0.99;
	c->rho_ref.u[0] = 0.005;
	c->ref_theta_o_deg = NAN;
	c->omega_det_sr = 1e-3;
	c->u_omega_rel = 0.02;
	c->angle_rel_per_deg = 0.0;
	c->sigma_pos_deg = 0.005;
	c->grid_min_nm = 450.0;
	c->grid_max_nm = 1100.0;
	c->grid_step_nm = 1.0;
}

const char *calib_method_name(enum calib_method m)
{
	return m == CALIB_ABSOLUTE ? "absolute" : "relative";
}

int calib_grid_size(const struct calib_cfg *c)
{
	if (!(c->grid_step_nm > 0) || !(c->grid_max_nm >= c->grid_min_nm))
		return 0;
	double n = floor((c->grid_max_nm - c->grid_min_nm) / c->grid_step_nm + 1e-9) + 1;
	return n > CALIB_MAX_GRID ? 0 : (int)n;
}

static int parse_table(struct yc_node *seq, struct calib_table *t, struct acq_err *err)
{
	if (yc_expect_seq(seq, "calibration.reference.table", err))
		return -1;
	if (seq->n < 1 || seq->n > CALIB_MAX_TABLE)
		return yc_errf(err, seq, "reference table: expected 1 to %d rows [nm, reflectance, u]", CALIB_MAX_TABLE);
	struct calib_table tmp = { .n = (int)seq->n };
	for (size_t i = 0; i < seq->n; i++) {
		struct yc_node *row = seq->items[i];
		if (yc_expect_seq(row, "reference table row", err))
			return -1;
		if (row->n != 3)
			return yc_errf(err, row, "reference table row: expected [nm, reflectance, u]");
		if (yc_node_double(row->items[0], "wavelength", 100, 3000, &tmp.wl[i], err) ||
		    yc_node_double(row->items[1], "reflectance", 0, 1.5, &tmp.val[i], err) ||
		    yc_node_double(row->items[2], "uncertainty", 0, 1, &tmp.u[i], err))
			return -1;
		if (i > 0 && !(tmp.wl[i] > tmp.wl[i - 1]))
			return yc_errf(err, row, "reference table: wavelengths must increase");
	}
	*t = tmp;
	return 0;
}

int calib_cfg_parse(struct yc_node *node, struct calib_cfg *c, struct acq_err *err)
{
	if (!node)
		return 0;
	if (yc_expect_map(node, "calibration", err))
		return -1;
	struct calib_cfg q = *c;
	static const char *const methods[] = { "relative", "absolute", NULL };
	int m = (int)q.method;
	if (yc_enum(node, "method", false, methods, &m, err))
		return -1;
	q.method = (enum calib_method)m;
	struct yc_node *ref = yc_get(node, "reference");
	if (ref) {
		if (yc_expect_map(ref, "calibration.reference", err))
			return -1;
		double rho = q.rho_ref.val[0], u = q.rho_ref.u[0];
		struct yc_node *table = yc_get(ref, "table");
		if (yc_double(ref, "reflectance", false, 0, 1.5, &rho, err) ||
		    yc_double(ref, "u_reflectance", false, 0, 1, &u, err) ||
		    yc_double(ref, "theta_o_deg", false, 0, 89, &q.ref_theta_o_deg, err))
			return -1;
		if (table) {
			if (parse_table(table, &q.rho_ref, err))
				return -1;
		} else {
			q.rho_ref.n = 1;
			q.rho_ref.wl[0] = 550;
			q.rho_ref.val[0] = rho;
			q.rho_ref.u[0] = u;
		}
		if (yc_check_unknown(ref, "calibration.reference", err))
			return -1;
	}
	struct yc_node *grid = yc_get(node, "grid");
	if (grid) {
		if (yc_expect_map(grid, "calibration.grid", err) ||
		    yc_double(grid, "min_nm", false, 100, 3000, &q.grid_min_nm, err) ||
		    yc_double(grid, "max_nm", false, 100, 3000, &q.grid_max_nm, err) ||
		    yc_double(grid, "step_nm", false, 0.01, 1000, &q.grid_step_nm, err) ||
		    yc_check_unknown(grid, "calibration.grid", err))
			return -1;
	}
	if (yc_double(node, "omega_det_sr", false, 1e-12, 6.3, &q.omega_det_sr, err) ||
	    yc_double(node, "u_omega_rel", false, 0, 1, &q.u_omega_rel, err) ||
	    yc_double(node, "angle_rel_per_deg", false, 0, 10, &q.angle_rel_per_deg, err) ||
	    yc_double(node, "sigma_pos_deg", false, 0, 10, &q.sigma_pos_deg, err))
		return -1;
	if (calib_grid_size(&q) == 0)
		return yc_errf(err, grid ? grid : node, "calibration grid: need min_nm <= max_nm and at most %d points",
			       CALIB_MAX_GRID);
	if (yc_check_unknown(node, "calibration", err))
		return -1;
	*c = q;
	return 0;
}

void calib_table_eval(const struct calib_table *t, double wl, double *val, double *u)
{
	if (t->n <= 0) {
		*val = NAN;
		*u = NAN;
		return;
	}
	if (t->n == 1 || wl <= t->wl[0]) {
		*val = t->val[0];
		*u = t->u[0];
		return;
	}
	if (wl >= t->wl[t->n - 1]) {
		*val = t->val[t->n - 1];
		*u = t->u[t->n - 1];
		return;
	}
	int lo = 0, hi = t->n - 1;
	while (hi - lo > 1) {
		int mid = (lo + hi) / 2;
		if (t->wl[mid] <= wl)
			lo = mid;
		else
			hi = mid;
	}
	double w = (wl - t->wl[lo]) / (t->wl[hi] - t->wl[lo]);
	*val = t->val[lo] + w * (t->val[hi] - t->val[lo]);
	*u = t->u[lo] + w * (t->u[hi] - t->u[lo]); /* the table's uncertainty is one correlated curve */
}

static void px_invalid(struct calib_px *o, int i)
{
	o->valid[i] = 0;
	o->f[i] = o->u_noise[i] = o->u_dark[i] = o->u_refn[i] = o->u_refs[i] = o->u_angle[i] = NAN;
}

/* A reference (or beam) pixel clearly above its noise: the only ones with light to compare with. */
static bool ref_usable(const struct exp_rate *r, int i)
{
	return r->valid[i] && r->rate[i] > 0 && r->rate[i] > 3 * hypot(r->u_noise[i], r->u_dark[i]);
}

/* Per-pixel BRDF from the sample's net rate and the reference's (relative) or the direct beam's (absolute)
 * net rate measured on the same pixels; wl: pixel wavelengths. Pixels where either input is invalid or the
 * reference is not positive are invalid. 0 or -1 on bad input. */
static int calib_pixels(const struct calib_cfg *c, const double *wl, const struct exp_rate *s,
			const struct exp_rate *r, const struct calib_geom *g, struct calib_px *o, struct acq_err *err)
{
	if (s->npix <= 0 || s->npix > SPECTRO_MAX_PIXELS || r->npix != s->npix)
		return acq_errf(err, ACQ_E_INVAL, "calibration: sample has %d pixels, reference %d", s->npix, r->npix);
	if (!isfinite(g->theta_i) || !isfinite(g->theta_o) || fabs(g->theta_i) >= 90 || fabs(g->theta_o) >= 90)
		return acq_errf(err, ACQ_E_RANGE, "calibration: geometry θi %g°, θo %g° outside the hemisphere",
				g->theta_i, g->theta_o);
	double co = cos(g->theta_o * DEG);
	double geo, geo_rel_sens; /* cosine factor and its relative sensitivity per radian */
	if (c->method == CALIB_RELATIVE) {
		if (isfinite(c->ref_theta_o_deg)) {
			geo = cos(c->ref_theta_o_deg * DEG) / co;
			geo_rel_sens = fabs(tan(g->theta_o * DEG));
		} else {
			geo = 1.0;
			geo_rel_sens = 0.0;
		}
	} else {
		if (!(c->omega_det_sr > 0))
			return acq_errf(err, ACQ_E_INVAL, "calibration: absolute method needs Ω_det > 0");
		geo = 1.0 / (c->omega_det_sr * co);
		geo_rel_sens = fabs(tan(g->theta_o * DEG));
	}
	double sig_rad = c->sigma_pos_deg * DEG;
	o->npix = s->npix;
	for (int i = 0; i < s->npix; i++) {
		if (!s->valid[i] || !ref_usable(r, i) || !isfinite(s->rate[i])) {
			px_invalid(o, i);
			continue;
		}
		double scale, u_scale_rel;
		if (c->method == CALIB_RELATIVE) {
			double rho, urho;
			calib_table_eval(&c->rho_ref, wl[i], &rho, &urho);
			scale = rho / M_PI * geo;
			u_scale_rel = rho > 0 ? urho / rho : 0.0;
		} else {
			scale = geo;
			u_scale_rel = c->u_omega_rel;
		}
		double k = scale / r->rate[i]; /* ∂f/∂R_s */
		double f = s->rate[i] * k;
		o->valid[i] = 1;
		o->f[i] = f;
		o->u_noise[i] = fabs(k) * s->u_noise[i];
		o->u_dark[i] = fabs(k) * s->u_dark[i];
		double ur = hypot(r->u_noise[i], r->u_dark[i]);
		o->u_refn[i] = fabs(f) * ur / r->rate[i];
		o->u_refs[i] = fabs(f) * u_scale_rel;
		o->u_angle[i] = fabs(f) * hypot(c->angle_rel_per_deg * c->sigma_pos_deg, geo_rel_sens * sig_rad);
	}
	return 0;
}

/* Recompute the combined u from the four components. */
static void calib_combine(struct calib_spectrum *s)
{
	for (int k = 0; k < s->n; k++) {
		double a = s->u_noise[k], b = s->u_dark[k], r = s->u_ref[k], g = s->u_angle[k];
		s->u[k] = isfinite(s->f[k]) ? sqrt(a * a + b * b + r * r + g * g) : NAN;
	}
}

static void bin_nan(struct calib_spectrum *o, int k)
{
	o->f[k] = o->u[k] = o->u_noise[k] = o->u_dark[k] = o->u_ref[k] = o->u_angle[k] = NAN;
	o->npix[k] = 0;
	o->vfac[k] = NAN;
}

/* Accumulators of one bin while binning. */
struct bin_acc {
	double sx, sxx; /* Σ x, Σ x² of the valid pixels, x = λ_pixel − λ_bin (nm) */
	double sf, sn, sd, srn, srs, sa, sw2;
	int m, inbin;
};

/* The weight of a pixel at x = λ − λ_bin in its bin: the least-squares line through the bin's pixels evaluated at
 * the bin's centre, w = 1/m − x̄ (x − x̄) / Σ(x − x̄)². A plain mean is the value at the pixels' centroid x̄, which
 * sits up to ±0.17 nm off λ_bin with ~3 pixels per 1 nm bin, in a pattern fixed by the pixel grid: on a spectrum
 * with slope f'/f that is a relative error (f'/f) x̄ common to every sample of a sweep (1.6e-3 rms at 450–600 nm on
 * green paint, s16 refnoise2). Σ w = 1, Σ w x = 0: exact for a spectrum linear within the bin. */
static double bin_weight(const struct bin_acc *a, double x)
{
	double xm = a->sx / a->m, sxx = a->sxx - a->m * xm * xm;
	if (a->m < 2 || !(sxx > 1e-12))
		return 1.0 / a->m;
	return 1.0 / a->m - xm * (x - xm) / sxx;
}

int calib_resample(const struct calib_cfg *c, const double *wl, const struct calib_px *px,
		   struct calib_spectrum *o, struct acq_err *err)
{
	int n = calib_grid_size(c);
	if (n <= 0)
		return acq_errf(err, ACQ_E_INVAL, "calibration: empty or too large wavelength grid");
	if (px->npix <= 0 || px->npix > SPECTRO_MAX_PIXELS)
		return acq_errf(err, ACQ_E_INVAL, "calibration: %d pixels", px->npix);
	struct bin_acc *acc = calloc((size_t)n, sizeof *acc);
	if (!acc)
		return acq_errf(err, ACQ_E_NOMEM, "calibration: out of memory");
	o->n = n;
	o->method = c->method;
	double h = c->grid_step_nm / 2, lo = c->grid_min_nm - h;
	/* Two passes over the pixels: bin k holds [λk − step/2, λk + step/2); the first finds each bin's valid
	 * pixels' centroid and spread, the second sums with bin_weight. */
	for (int pass = 0; pass < 2; pass++)
		for (int i = 0; i < px->npix; i++) {
			double x = (wl[i] - lo) / c->grid_step_nm;
			if (!(x >= 0) || x >= n)
				continue;
			int k = (int)x;
			struct bin_acc *a = &acc[k];
			double d = wl[i] - (c->grid_min_nm + k * c->grid_step_nm);
			if (pass == 0) {
				a->inbin++;
				if (px->valid[i]) {
					a->m++;
					a->sx += d;
					a->sxx += d * d;
				}
				continue;
			}
			if (!px->valid[i])
				continue;
			double w = bin_weight(a, d);
			a->sf += w * px->f[i];
			a->sn += w * w * px->u_noise[i] * px->u_noise[i];
			a->sd += w * w * px->u_dark[i] * px->u_dark[i];
			a->srn += w * w * px->u_refn[i] * px->u_refn[i];
			a->srs += w * px->u_refs[i];
			a->sa += w * px->u_angle[i];
			a->sw2 += w * w;
		}
	for (int k = 0; k < n; k++) {
		double lam = c->grid_min_nm + k * c->grid_step_nm;
		const struct bin_acc *a = &acc[k];
		o->wl[k] = lam;
		if (a->m > 0) {
			o->f[k] = a->sf;
			o->u_noise[k] = sqrt(a->sn);
			o->u_dark[k] = sqrt(a->sd);
			o->u_ref[k] = hypot(sqrt(a->srn), fabs(a->srs));
			o->u_angle[k] = fabs(a->sa);
			o->npix[k] = a->m;
			o->vfac[k] = a->sw2;
			continue;
		}
		bin_nan(o, k);
		if (a->inbin > 0)
			continue; /* only invalid (saturated) pixels here: not measured */
		/* Pixels coarser than the grid: linear interpolation between the nearest pixels either side. */
		int below = -1, above = -1;
		for (int i = 0; i < px->npix; i++) {
			if (wl[i] < lam) {
				if (below < 0 || wl[i] > wl[below])
					below = i;
			} else if (above < 0 || wl[i] < wl[above]) {
				above = i;
			}
		}
		if (below < 0 || above < 0 || !px->valid[below] || !px->valid[above] || !(wl[above] > wl[below]))
			continue;
		double w2 = (lam - wl[below]) / (wl[above] - wl[below]), w1 = 1 - w2;
		int p = below, q = above;
		o->f[k] = w1 * px->f[p] + w2 * px->f[q];
		o->u_noise[k] = hypot(w1 * px->u_noise[p], w2 * px->u_noise[q]);
		o->u_dark[k] = hypot(w1 * px->u_dark[p], w2 * px->u_dark[q]);
		o->u_ref[k] = hypot(hypot(w1 * px->u_refn[p], w2 * px->u_refn[q]), w1 * px->u_refs[p] + w2 * px->u_refs[q]);
		o->u_angle[k] = w1 * px->u_angle[p] + w2 * px->u_angle[q];
		o->vfac[k] = w1 * w1 + w2 * w2;
	}
	free(acc);
	calib_combine(o);
	return 0;
}

int calib_ref_noise(const struct calib_cfg *c, const double *wl, const struct exp_rate *ref, double *u_rel,
		    struct acq_err *err)
{
	if (ref->npix <= 0 || ref->npix > SPECTRO_MAX_PIXELS)
		return acq_errf(err, ACQ_E_INVAL, "calibration: reference has %d pixels", ref->npix);
	struct calib_px *px = malloc(sizeof *px);
	struct calib_spectrum *sp = malloc(sizeof *sp);
	int rc = -1;
	if (!px || !sp) {
		acq_errf(err, ACQ_E_NOMEM, "calibration: out of memory");
		goto out;
	}
	/* A flat unit "sample" on the reference's pixels: u_refn is then the reference's relative noise, with the
	 * same pixel choice (calib_pixels' test) and the same binning as every sample's. */
	px->npix = ref->npix;
	for (int i = 0; i < ref->npix; i++) {
		if (!ref_usable(ref, i)) {
			px_invalid(px, i);
			continue;
		}
		double ur = hypot(ref->u_noise[i], ref->u_dark[i]);
		px->valid[i] = 1;
		px->f[i] = 1.0;
		px->u_noise[i] = px->u_dark[i] = px->u_refs[i] = px->u_angle[i] = 0.0;
		px->u_refn[i] = ur / ref->rate[i];
	}
	if (calib_resample(c, wl, px, sp, err))
		goto out;
	/* The per-pixel std is estimated from a few scans (4 in make demo: 3 degrees of freedom each), so one bin's
	 * u_rel is itself noisy and z = e/u_rel too wide (E[u²/û²] = ν/(ν − 2) ≈ 1.3 for a bin of 2–3 pixels). The
	 * relative noise of a white reference under a continuum source varies slowly in λ: a bin with pixels takes the
	 * per-pixel variance pooled over the bins with pixels within ±CALIB_REFN_POOL_NM (each bin's u_ref² / vfac, weighted
	 * by its pixel count), times its own vfac (Σ w² of its pixel weights). */
	for (int k = 0; k < sp->n; k++) {
		u_rel[k] = isfinite(sp->f[k]) ? sp->u_ref[k] : NAN;
		if (!isfinite(u_rel[k]) || sp->npix[k] <= 0)
			continue;
		int j0 = k, j1 = k, m = 0; /* the bins within ±CALIB_REFN_POOL_NM */
		while (j0 > 0 && sp->wl[k] - sp->wl[j0 - 1] <= CALIB_REFN_POOL_NM)
			j0--;
		while (j1 + 1 < sp->n && sp->wl[j1 + 1] - sp->wl[k] <= CALIB_REFN_POOL_NM)
			j1++;
		double v = 0;
		for (int j = j0; j <= j1; j++)
			if (sp->npix[j] > 0 && isfinite(sp->u_ref[j])) {
				v += sp->npix[j] * sp->u_ref[j] * sp->u_ref[j] / sp->vfac[j];
				m += sp->npix[j];
			}
		u_rel[k] = sqrt(v / m * sp->vfac[k]);
	}
	rc = 0;
out:
	free(px);
	free(sp);
	return rc;
}

int calib_spectrum(const struct calib_cfg *c, const double *wl, const struct exp_rate *sample,
		   const struct exp_rate *ref, const struct calib_geom *g, struct calib_spectrum *out,
		   struct acq_err *err)
{
	struct calib_px *px = malloc(sizeof *px);
	if (!px)
		return acq_errf(err, ACQ_E_NOMEM, "calibration: out of memory");
	int rc = calib_pixels(c, wl, sample, ref, g, px, err) ? -1 : calib_resample(c, wl, px, out, err);
	free(px);
	return rc;
}
