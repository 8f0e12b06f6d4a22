/* sim_truth: the library part of `acq-sim truth` (see sim_truth.h). */
#include "sim/sim_truth.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "config/bench.h"
#include "recon/csvio.h"
#include "recon/merl.h"
#include "sim/sim_rng.h"
#include "sim/sim_sphere.h"

int truth_wavelengths(const char *s, double **out, int *n, struct acq_err *err)
{
	char *end;
	double a = strtod(s, &end), b = a, st = 1;
	int bad = end == s;
	if (!bad && *end == ':') {
		const char *q = end + 1;
		b = strtod(q, &end);
		bad = end == q || *end != ':';
		if (!bad) {
			q = end + 1;
			st = strtod(q, &end);
			bad = end == q;
		}
	}
	if (bad || *end || !isfinite(a) || !isfinite(b) || !isfinite(st) || !(st > 0) || a < MAT_WL_MIN - 1e-9 ||
	    b > MAT_WL_MAX + 1e-9 || b < a || floor((b - a) / st + 1e-9) + 1 > TRUTH_MAX_WL)
		return acq_errf(err, ACQ_E_INVAL, "--wavelengths: expected A:B:STEP (or one value) within 450..1100 nm, "
						  "at most %d wavelengths, got '%s'", TRUTH_MAX_WL, s);
	*n = (int)(floor((b - a) / st + 1e-9) + 1);
	if (!(*out = malloc(sizeof(double) * (size_t)*n)))
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	for (int i = 0; i < *n; i++)
		(*out)[i] = a + st * i;
	return 0;
}

int truth_thetas(const char *list, double *th, int *n, struct acq_err *err)
{
	char buf[512];
	*n = 0;
	snprintf(buf, sizeof buf, "%s", list);
	for (char *save = NULL, *t = strtok_r(buf, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
		char *end;
		double v = strtod(t, &end);
		if (end == t || *end || !(v >= 0 && v <= 90) || *n >= TRUTH_MAX_THETAS)
			return acq_errf(err, ACQ_E_INVAL, "--theta-i: expected up to %d comma-separated zeniths in [0, 90] "
							  "degrees, got '%s'", TRUTH_MAX_THETAS, t);
		th[(*n)++] = v;
	}
	return *n ? 0 : acq_errf(err, ACQ_E_INVAL, "--theta-i: empty list");
}

/* One count of a grid spec at *p: decimal digits only (no sign, no space), 1..max; *p advanced past it. */
static int grid_count(const char **p, long max, int *out)
{
	if (**p < '0' || **p > '9')
		return -1;
	char *end;
	errno = 0;
	long v = strtol(*p, &end, 10); /* strtol, not sscanf %d: a count past INT_MAX wrapped (4294967297 read as 1) */
	if (errno || v < 1 || v > max)
		return -1;
	*p = end;
	*out = (int)v;
	return 0;
}

int truth_grid_size(const char *spec, struct truth_grid *g, struct acq_err *err)
{
	const char *p = spec;
	int ni, no, np;
	if (grid_count(&p, 90, &ni) || *p++ != 'x' || grid_count(&p, 90, &no) || *p++ != 'x' || grid_count(&p, 360, &np) ||
	    *p)
		return acq_errf(err, ACQ_E_INVAL, "--grid: expected NIxNOxNP (e.g. 10x10x10; each 1..90, NP 1..360), got '%s'",
				spec);
	g->ni = ni, g->no = no, g->np = np;
	return 0;
}

static int stream_ok(FILE *f, struct acq_err *err)
{
	return ferror(f) ? acq_errf(err, ACQ_E_IO, "write error: %s", strerror(errno)) : 0;
}

/* n doubles or an out-of-memory error */
static double *alloc_d(int n, struct acq_err *err)
{
	double *p = malloc(sizeof(double) * (size_t)(n > 0 ? n : 1));
	if (!p)
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
	return p;
}

int truth_write_sphere(FILE *f, const struct mat *m, uint64_t seed, const double *wl, int nwl, struct acq_err *err)
{
	double *v = alloc_d(nwl, err), *s = v ? alloc_d(nwl, err) : NULL;
	int rc = -1;
	if (s && !sphere_measure(m, nwl, wl, seed, v, s, err)) {
		fprintf(f, "wavelength_nm,dhr,sigma\n");
		for (int l = 0; l < nwl; l++)
			fprintf(f, "%.10g,%.10g,%.4g\n", wl[l], v[l], s[l]);
		rc = stream_ok(f, err);
	}
	free(v);
	free(s);
	return rc;
}

int truth_write_dhr(FILE *f, const struct mat *m, const double *th, int nth, int level, const double *wl, int nwl,
		    struct acq_err *err)
{
	double *d = alloc_d(nwl, err), *s = d ? alloc_d(nwl, err) : NULL;
	int rc = -1;
	if (!s)
		goto done;
	fprintf(f, "# acq-sim truth %s: directional-hemispherical reflectance; sigma = quadrature error bound\n"
		   "# quadrature: sim/material.h, level %d vs %d\n"
		   "theta_i,wavelength_nm,dhr,sigma\n", mat_name(mat_id_of(m)), level + 1, level);
	for (int t = 0; t < nth; t++) {
		if (mat_dhr(m, th[t] * M_PI / 180, level, d, s, err))
			goto done;
		for (int l = 0; l < nwl; l++)
			fprintf(f, "%.10g,%.10g,%.12g,%.3g\n", th[t], wl[l], d[l], s[l]);
	}
	rc = stream_ok(f, err);
done:
	free(d);
	free(s);
	return rc;
}

int truth_write_eval(FILE *f, const struct mat *m, const char *queries, const double *wl, int nwl,
		     struct acq_err *err)
{
	struct recon_samples q = { 0 };
	if (csvio_read_queries(queries, &q, err))
		return -1;
	double *v = alloc_d(nwl, err);
	int rc = -1;
	if (!v)
		goto done;
	fprintf(f, "theta_i,phi_i,theta_o,phi_o");
	for (int l = 0; l < nwl; l++)
		fprintf(f, ",%.10g", wl[l]);
	fputc('\n', f);
	for (size_t r = 0; r < q.n; r++) {
		const double *a = q.ang + 4 * r, *dg = q.deg + 4 * r;
		double wi[3], wo[3];
		mat_dir(a[0], a[1], wi);
		mat_dir(a[2], a[3], wo);
		mat_eval(m, wi, wo, v);
		fprintf(f, "%.10g,%.10g,%.10g,%.10g", dg[0], dg[1], dg[2], dg[3]);
		for (int l = 0; l < nwl; l++)
			fprintf(f, ",%.9g", v[l]);
		fputc('\n', f);
	}
	rc = stream_ok(f, err);
done:
	free(v);
	csvio_samples_free(&q);
	return rc;
}

static double angle_deg(const double a[3], const double b[3])
{
	double c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
	double x[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
	return atan2(sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]), c) * 180.0 / M_PI;
}

int truth_write_grid(FILE *fo, const struct mat *m, const struct truth_grid *g, const double *wl, int nwl, int *rows,
		     int *dropped, struct acq_err *err)
{
	struct bench_geom geo;
	bench_defaults(&geo);
	double blind = fmax(geo.detector_body_halfwidth_deg + geo.beam_halfwidth_deg,
			    geo.laser_body_halfwidth_deg + geo.fov_halfwidth_deg);
	const struct refdrift_cfg *cal = &g->cal;
	double *f = alloc_d(nwl, err), *v = f ? alloc_d(nwl, err) : NULL, *s = v ? alloc_d(nwl, err) : NULL,
	       *rf = s ? alloc_d(nwl, err) : NULL;
	int rc = -1;
	*rows = *dropped = 0;
	if (!rf || refdrift_reference(cal, nwl, wl, rf, err))
		goto done;
	/* relative calibration against the standard: f_cal = f rho_cert / rho_true (rf: rho_true - rho_cert) */
	for (int l = 0; l < nwl; l++) {
		double rc_ = mat_rho_d(MAT_WHITE, wl[l]);
		rf[l] = rc_ / (rc_ + rf[l]);
	}
	struct sim_rng r;
	sim_rng_seed(&r, g->seed);
	fprintf(fo, "# acq-sim truth %s: grid %dx%dx%d, theta in (0, 80) deg at cell centres, phi_i = %g deg; noise: value x "
		    "(1 + %g N) + %g N, seed %llu; blind zones (< %g deg between wi and wo) %s\n",
		mat_name(mat_id_of(m)), g->ni, g->no, g->np, geo.laser_phi_deg, g->rel, g->floor_,
		(unsigned long long)g->seed, blind, g->keep_blind ? "kept" : "dropped");
	if (cal->ref_u > 0 || cal->drift_amp > 0)
		fprintf(fo, "# systematic errors (not in the sigma columns; sim/sim_refdrift.h): reference standard u %g "
			    "(correlation %g nm, seed %llu); source drift rms %g (tilt %g, period %g s, seed %llu), sample k at "
			    "bench time k x %g s after the reference\n", cal->ref_u, cal->ref_corr_nm,
			(unsigned long long)cal->ref_seed, cal->drift_amp, cal->drift_tilt, cal->drift_period_s,
			(unsigned long long)cal->drift_seed, g->point_s);
	fprintf(fo, "theta_i,phi_i,theta_o,phi_o");
	for (int l = 0; l < nwl; l++)
		fprintf(fo, ",%.10g", wl[l]);
	for (int l = 0; l < nwl; l++)
		fprintf(fo, ",sigma_%.10g", wl[l]);
	fputc('\n', fo);
	for (int a = 0; a < g->ni; a++)
		for (int b = 0; b < g->no; b++)
			for (int c = 0; c < g->np; c++) {
				double ti = 80.0 * (a + 0.5) / g->ni, to = 80.0 * (b + 0.5) / g->no, po = 360.0 * c / g->np;
				double wi[3], wo[3];
				mat_dir(ti * M_PI / 180, geo.laser_phi_deg * M_PI / 180, wi);
				mat_dir(to * M_PI / 180, po * M_PI / 180, wo);
				if (!g->keep_blind && angle_deg(wi, wo) < blind) {
					(*dropped)++;
					continue;
				}
				mat_eval(m, wi, wo, f);
				double t = (*rows + 1) * g->point_s;
				for (int l = 0; l < nwl; l++) {
					f[l] *= rf[l] * refdrift_source(cal, t, wl[l]);
					s[l] = sqrt(g->rel * g->rel * f[l] * f[l] + g->floor_ * g->floor_);
					v[l] = f[l] * (1.0 + g->rel * sim_rng_gauss(&r)) + g->floor_ * sim_rng_gauss(&r);
				}
				fprintf(fo, "%.10g,%.10g,%.10g,%.10g", ti, geo.laser_phi_deg, to, po);
				for (int l = 0; l < nwl; l++)
					fprintf(fo, ",%.9g", v[l]);
				for (int l = 0; l < nwl; l++)
					fprintf(fo, ",%.3g", s[l]);
				fputc('\n', fo);
				(*rows)++;
			}
	rc = stream_ok(fo, err);
done:
	free(f);
	free(v);
	free(s);
	free(rf);
	return rc;
}

/* MERL export: the spectral BRDF reduced to linear sRGB in sr^-1 by recon/colour.h (colour_opts_brdf: D65,
 * Bradford, absolute, negatives clamped, range kept). The reduction is linear, so it is folded in before the
 * evaluation: f(l) = sum_k w_k S_k(l, c_k) (mat_terms) gives rgb = sum_k w_k (W S_k(., c_k)), with W S_k
 * computed once for the fixed spectra and tabulated over c in [0, 1] for the Fresnel factors (MERL_FT + 1
 * nodes, linear interpolation: relative error < 1e-6). */
#define MERL_FT 4096

struct merl_ctx {
	const struct mat *m;
	double *ftab[MAT_S__COUNT]; /* 3 x (MERL_FT + 1) per Fresnel spectrum, 3 for a fixed one */
	bool varies[MAT_S__COUNT];
	struct colour_opts o;
	struct colour_stats st;
};

static int merl_cb(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	struct merl_ctx *x = ctx;
	struct mat_term t[MAT_MAX_TERMS];
	double lin[3] = { 0, 0, 0 };
	int nt = mat_terms(x->m, wi, wo, t);
	for (int j = 0; j < nt; j++) {
		if (!(t[j].w > 0))
			continue;
		const double *f = x->ftab[t[j].spec];
		if (!x->varies[t[j].spec]) {
			for (int k = 0; k < 3; k++)
				lin[k] += t[j].w * f[k];
			continue;
		}
		double u = fmin(fmax(t[j].c, 0.0), 1.0) * MERL_FT;
		int i = (int)u;
		if (i >= MERL_FT)
			i = MERL_FT - 1;
		double a = u - i;
		for (int k = 0; k < 3; k++) {
			const double *fk = f + k * (MERL_FT + 1);
			lin[k] += t[j].w * (fk[i] + a * (fk[i + 1] - fk[i]));
		}
	}
	colour_finish(&x->o, lin, rgb, &x->st);
	return 0;
}

int truth_write_merl(const char *path, const struct mat *m, const double *wl, int nwl, struct colour_opts *o,
		     struct colour_stats *st, struct acq_err *err)
{
	struct merl_ctx x = { .m = m };
	colour_opts_brdf(&x.o);
	double *W = malloc(sizeof(double) * 3 * (size_t)nwl), *sp = malloc(sizeof(double) * (size_t)nwl);
	int rc = -1, oom = !W || !sp;
	for (int s = 0; s < MAT_S__COUNT; s++) {
		x.varies[s] = s == MAT_S_DIEL || s == MAT_S_COND;
		x.ftab[s] = malloc(sizeof(double) * 3 * (x.varies[s] ? MERL_FT + 1 : 1));
		oom |= !x.ftab[s];
	}
	if (oom) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto done;
	}
	if (colour_weights(&x.o, wl, (size_t)nwl, W, err))
		goto done;
	for (int s = 0; s < MAT_S__COUNT; s++) {
		int nc = x.varies[s] ? MERL_FT + 1 : 1;
		for (int j = 0; j < nc; j++) {
			double rgb[3];
			mat_spectrum(m, (enum mat_spec)s, (double)j / MERL_FT, sp);
			colour_apply_weights(W, (size_t)nwl, sp, rgb);
			for (int k = 0; k < 3; k++)
				x.ftab[s][k * nc + j] = rgb[k];
		}
	}
	if (merl_write(path, merl_cb, &x, err))
		goto done;
	*o = x.o;
	*st = x.st;
	rc = 0;
done:
	free(W);
	free(sp);
	for (int s = 0; s < MAT_S__COUNT; s++)
		free(x.ftab[s]);
	return rc;
}
