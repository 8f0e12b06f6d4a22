/* sim_truth: `acq-sim truth`: the simulator's ground truth exported, so accuracy is measured, not assumed:
 * DHR(theta_i, lambda) with its quadrature error bound, evaluation at given directions, noisy sparse samples
 * on a plan-like grid (CSV interchange format of docs/design.md), and a MERL table. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "config/bench.h"
#include "recon/colour.h"
#include "recon/merl.h"
#include "sim/material.h"
#include "sim/sim.h"
#include "sim/sim_refdrift.h"
#include "sim/sim_rng.h"
#include "sim/sim_sphere.h"

#define MAX_WL 100000

static void usage(FILE *f)
{
	fprintf(f,
		"usage: acq-sim truth MATERIAL ACTION [options]\n"
		"  MATERIAL: green-paint (or paint) | white | metal | clear-coat | rough-backscatter | cloth-sheen |\n"
		"            sharp-lobe | narrow-lines (sim/material.h)\n"
		"  actions (exactly one):\n"
		"    --dhr OUT.csv [--theta-i 8,30,60]    columns theta_i,wavelength_nm,dhr,sigma (sigma: quadrature bound)\n"
		"    --eval QUERIES.csv [-o OUT.csv]      f at the rows' theta_i,phi_i,theta_o,phi_o (degrees), 1/sr\n"
		"    --grid NIxNOxNP -o SAMPLES.csv       noisy samples: NI incidences, NO observation zeniths in (0, 80),\n"
		"          [--noise REL] [--noise-floor ABS] [--seed N] [--keep-blind]   NP azimuths; sigma_<nm> columns\n"
		"          [--reference U[,CORR_NM[,SEED]]]  calibrated against a white standard whose reflectance differs\n"
		"                                            from its certificate by a smooth deviation of std U\n"
		"          [--drift AMP[,PERIOD_S[,SEED]]] [--point-time S]  source drift (rms AMP) between the reference\n"
		"                                            (bench time 0) and sample k (time k S, default 20 s)\n"
		"          (both as acq-sim's sim.reference_standard / sim.source_drift: sim/sim_refdrift.h; off by default)\n"
		"    --merl OUT.binary                    MERL table, linear sRGB in 1/sr (D65, Bradford; recon/colour.h)\n"
		"    --spectrophotometer [-o OUT.csv] [--seed N]   a simulated d/8 integrating-sphere measurement of the DHR\n"
		"                                         at 8 deg with its own noise and stated uncertainty (sim/sim_sphere.h):\n"
		"                                         columns wavelength_nm,dhr,sigma (brdf-recon dhr --reference)\n"
		"  --wavelengths A:B:STEP   spectral sampling in nm within 450..1100 (default 450:1100:1)\n"
		"  --level N                DHR quadrature level 0..5 (default 2)\n");
}

static int parse_wavelengths(const char *s, double **out, int *n)
{
	char *end;
	double a = strtod(s, &end), b = a, st = 1;
	if (end == s)
		return -1;
	if (*end == ':') {
		const char *q = end + 1;
		b = strtod(q, &end);
		if (end == q || *end != ':')
			return -1;
		q = end + 1;
		st = strtod(q, &end);
		if (end == q)
			return -1;
	}
	if (*end || !isfinite(a) || !isfinite(b) || !isfinite(st) || !(st > 0) || a < MAT_WL_MIN - 1e-9 ||
	    b > MAT_WL_MAX + 1e-9 || b < a)
		return -1;
	double cnt = floor((b - a) / st + 1e-9) + 1;
	if (cnt > MAX_WL)
		return -1;
	*n = (int)cnt;
	*out = malloc(sizeof(double) * (size_t)*n);
	if (!*out)
		return -1;
	for (int i = 0; i < *n; i++)
		(*out)[i] = a + st * i;
	return 0;
}

static void header_wl(FILE *f, const double *wl, int n, const char *prefix)
{
	for (int i = 0; i < n; i++)
		fprintf(f, ",%s%.10g", prefix, wl[i]);
}

static int do_sphere(struct mat *m, const char *out, unsigned long long seed, const double *wl, int nwl)
{
	double *v = malloc(sizeof(double) * (size_t)nwl), *s = malloc(sizeof(double) * (size_t)nwl);
	struct acq_err err = { 0 };
	int rc = 1;
	FILE *f = NULL;
	if (!v || !s) {
		fprintf(stderr, "acq-sim truth: out of memory\n");
		goto done;
	}
	if (sphere_measure(m, nwl, wl, seed, v, s, &err)) {
		fprintf(stderr, "acq-sim truth: %s\n", err.msg);
		goto done;
	}
	if (!(f = strcmp(out, "-") ? fopen(out, "w") : stdout)) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", out, strerror(errno));
		goto done;
	}
	fprintf(f, "wavelength_nm,dhr,sigma\n");
	for (int l = 0; l < nwl; l++)
		fprintf(f, "%.10g,%.10g,%.4g\n", wl[l], v[l], s[l]);
	rc = 0;
	fprintf(stderr, "acq-sim truth: spectrophotometer (d/8 sphere, seed %llu): DHR at %g deg, stated sigma = "
			"calibration %.1f %% (correlated over %g nm) + noise (sim/sim_sphere.h)\n",
		seed, SPHERE_THETA_DEG, 100 * SPHERE_U_CAL, SPHERE_CORR_NM);
done:
	if (f && f != stdout && fclose(f)) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", out, strerror(errno));
		rc = 1;
	}
	free(v);
	free(s);
	return rc;
}

static int do_dhr(struct mat *m, const char *material, const char *out, const char *thetas, int level, const double *wl,
		  int nwl)
{
	double th[64];
	int nth = 0;
	char buf[512];
	snprintf(buf, sizeof buf, "%s", thetas);
	for (char *save = NULL, *t = strtok_r(buf, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
		char *end;
		double v = strtod(t, &end);
		if (end == t || *end || !(v >= 0 && v <= 90) || nth >= 64) {
			fprintf(stderr, "acq-sim truth: --theta-i: expected up to 64 comma-separated zeniths in [0, 90] degrees, got '%s'\n", t);
			return 2;
		}
		th[nth++] = v;
	}
	if (!nth) {
		fprintf(stderr, "acq-sim truth: --theta-i: empty list\n");
		return 2;
	}
	FILE *f = strcmp(out, "-") ? fopen(out, "w") : stdout;
	if (!f) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", out, strerror(errno));
		return 1;
	}
	double *d = malloc(sizeof(double) * (size_t)nwl), *s = malloc(sizeof(double) * (size_t)nwl);
	int rc = 0;
	if (!d || !s) {
		fprintf(stderr, "acq-sim truth: out of memory\n");
		rc = 1;
		goto done;
	}
	fprintf(f, "# acq-sim truth %s: directional-hemispherical reflectance; sigma = quadrature error bound\n"
		   "# quadrature: half-vector Gauss-Legendre x trapezoid, level %d vs %d (sim/material.h)\n"
		   "theta_i,wavelength_nm,dhr,sigma\n", material, level + 1, level);
	for (int t = 0; t < nth; t++) {
		struct acq_err err = { 0 };
		if (mat_dhr(m, th[t] * M_PI / 180, level, d, s, &err)) {
			fprintf(stderr, "acq-sim truth: %s\n", err.msg);
			rc = 1;
			goto done;
		}
		for (int l = 0; l < nwl; l++)
			fprintf(f, "%.10g,%.10g,%.12g,%.3g\n", th[t], wl[l], d[l], s[l]);
	}
done:
	free(d);
	free(s);
	if (f != stdout && fclose(f) && !rc) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", out, strerror(errno));
		rc = 1;
	}
	return rc;
}

/* Split a CSV line in place on commas (no quoting in the interchange format); trims blanks and CR. */
static int split(char *line, char **fields, int max)
{
	int n = 0;
	char *p = line;
	for (;;) {
		char *c = strchr(p, ',');
		if (c)
			*c = 0;
		while (*p == ' ' || *p == '\t')
			p++;
		size_t l = strlen(p);
		while (l && (p[l - 1] == ' ' || p[l - 1] == '\t' || p[l - 1] == '\r' || p[l - 1] == '\n'))
			p[--l] = 0;
		if (n >= max)
			return -1;
		fields[n++] = p;
		if (!c)
			return n;
		p = c + 1;
	}
}

static void eval_deg(struct mat *m, double ti, double pi_, double to, double po, double *out)
{
	double wi[3], wo[3];
	mat_dir(ti * M_PI / 180, pi_ * M_PI / 180, wi);
	mat_dir(to * M_PI / 180, po * M_PI / 180, wo);
	mat_eval(m, wi, wo, out);
}

static int do_eval(struct mat *m, const char *in, const char *out, const double *wl, int nwl)
{
	FILE *fi = fopen(in, "r");
	if (!fi) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", in, strerror(errno));
		return 1;
	}
	FILE *fo = NULL;
	char *line = NULL, **fields = NULL;
	size_t cap = 0;
	double *f = malloc(sizeof(double) * (size_t)nwl);
	int rc = 1, maxf = 1 << 16, col[4] = { -1, -1, -1, -1 }, nhead = 0;
	long lineno = 0;
	static const char *const names[4] = { "theta_i", "phi_i", "theta_o", "phi_o" };
	fields = malloc(sizeof(char *) * (size_t)maxf);
	if (!f || !fields) {
		fprintf(stderr, "acq-sim truth: out of memory\n");
		goto done;
	}
	/* header: the first line that is not a # comment */
	while (getline(&line, &cap, fi) > 0) {
		lineno++;
		if (line[0] == '#')
			continue;
		nhead = split(line, fields, maxf);
		if (nhead < 0) {
			fprintf(stderr, "acq-sim truth: %s:%ld: more than %d columns\n", in, lineno, maxf);
			goto done;
		}
		for (int k = 0; k < 4; k++)
			for (int c = 0; c < nhead; c++)
				if (!strcmp(fields[c], names[k]))
					col[k] = c;
		break;
	}
	for (int k = 0; k < 4; k++)
		if (col[k] < 0) {
			fprintf(stderr, "acq-sim truth: %s:%ld: the header has no column '%s' (expected theta_i,phi_i,theta_o,phi_o)\n",
				in, lineno, names[k]);
			goto done;
		}
	fo = strcmp(out, "-") ? fopen(out, "w") : stdout;
	if (!fo) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", out, strerror(errno));
		goto done;
	}
	fprintf(fo, "theta_i,phi_i,theta_o,phi_o");
	header_wl(fo, wl, nwl, "");
	fputc('\n', fo);
	while (getline(&line, &cap, fi) > 0) {
		lineno++;
		if (line[0] == '\n' || (line[0] == '\r' && line[1] == '\n'))
			continue;
		int n = split(line, fields, maxf);
		if (n != nhead) {
			fprintf(stderr, "acq-sim truth: %s:%ld: %d fields, the header has %d\n", in, lineno, n < 0 ? maxf : n, nhead);
			goto done;
		}
		double a[4];
		for (int k = 0; k < 4; k++) {
			char *end;
			a[k] = strtod(fields[col[k]], &end);
			if (end == fields[col[k]] || *end || !isfinite(a[k])) {
				fprintf(stderr, "acq-sim truth: %s:%ld: column %d (%s): '%s' is not a finite number\n", in, lineno,
					col[k] + 1, names[k], fields[col[k]]);
				goto done;
			}
		}
		if (a[0] < 0 || a[0] > 90 || a[2] < 0 || a[2] > 90) {
			fprintf(stderr, "acq-sim truth: %s:%ld: zenith angles must be in [0, 90] degrees\n", in, lineno);
			goto done;
		}
		eval_deg(m, a[0], a[1], a[2], a[3], f);
		fprintf(fo, "%.10g,%.10g,%.10g,%.10g", a[0], a[1], a[2], a[3]);
		for (int l = 0; l < nwl; l++)
			fprintf(fo, ",%.9g", f[l]);
		fputc('\n', fo);
	}
	rc = 0;
done:
	if (fo && fo != stdout && fclose(fo) && !rc) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", out, strerror(errno));
		rc = 1;
	}
	if (rc && fo && fo != stdout)
		unlink(out); /* no half-written result */
	fclose(fi);
	free(line);
	free(fields);
	free(f);
	return rc;
}

static double angle_deg(const double a[3], const double b[3])
{
	double c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
	double x[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
	return atan2(sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]), c) * 180.0 / M_PI;
}

/* "A[,B[,C]]" into a (required), b, c (kept when absent); c an integer. 0 or -1. */
static int parse_triple(const char *s, double *a, double *b, uint64_t *c)
{
	char *end;
	*a = strtod(s, &end);
	if (end == s || !isfinite(*a))
		return -1;
	if (*end == ',') {
		const char *q = end + 1;
		*b = strtod(q, &end);
		if (end == q || !isfinite(*b))
			return -1;
		if (*end == ',') {
			q = end + 1;
			errno = 0;
			*c = strtoull(q, &end, 10);
			if (end == q || errno || *q == '-')
				return -1;
		}
	}
	return *end ? -1 : 0;
}

static int do_grid(struct mat *m, const char *material, const char *spec, const char *out, double rel, double floor_,
		   unsigned long long seed, bool keep_blind, const struct refdrift_cfg *cal, double point_s,
		   const double *wl, int nwl)
{
	int ni, no, np;
	char tail;
	if (sscanf(spec, "%dx%dx%d%c", &ni, &no, &np, &tail) != 3 || ni < 1 || no < 1 || np < 1 || ni > 90 || no > 90 ||
	    np > 360) {
		fprintf(stderr, "acq-sim truth: --grid: expected NIxNOxNP (e.g. 10x10x10; each 1..90, NP 1..360), got '%s'\n", spec);
		return 2;
	}
	struct bench_geom g;
	bench_defaults(&g);
	double blind = fmax(g.detector_body_halfwidth_deg + g.beam_halfwidth_deg, g.laser_body_halfwidth_deg + g.fov_halfwidth_deg);
	FILE *fo = strcmp(out, "-") ? fopen(out, "w") : stdout;
	if (!fo) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", out, strerror(errno));
		return 1;
	}
	double *f = malloc(sizeof(double) * (size_t)nwl), *v = malloc(sizeof(double) * (size_t)nwl),
	       *s = malloc(sizeof(double) * (size_t)nwl), *rf = malloc(sizeof(double) * (size_t)nwl);
	struct acq_err err = { 0 };
	if (!f || !v || !s || !rf || refdrift_reference(cal, nwl, wl, rf, &err)) {
		fprintf(stderr, "acq-sim truth: %s\n", f && v && s && rf ? err.msg : "out of memory");
		free(f);
		free(v);
		free(s);
		free(rf);
		if (fo != stdout)
			fclose(fo);
		return 1;
	}
	/* relative calibration against the standard: f_cal = f rho_cert / rho_true (rf: rho_true - rho_cert) */
	for (int l = 0; l < nwl; l++) {
		double rc = mat_rho_d(MAT_WHITE, wl[l]);
		rf[l] = rc / (rc + rf[l]);
	}
	struct sim_rng r;
	sim_rng_seed(&r, seed);
	fprintf(fo, "# acq-sim truth %s: grid %s, theta in (0, 80) deg at cell centres, phi_i = %g deg; noise: value x (1 + %g N)"
		    " + %g N, seed %llu; blind zones (< %g deg between wi and wo) %s\n",
		material, spec, g.laser_phi_deg, rel, floor_, seed, blind, keep_blind ? "kept" : "dropped");
	if (cal->ref_u > 0 || cal->drift_amp > 0)
		fprintf(fo, "# systematic errors (not in the sigma columns; sim/sim_refdrift.h): reference standard u %g "
		    "(correlation %g nm, seed %llu); source drift rms %g (tilt %g, period %g s, seed %llu), sample k at "
		    "bench time k x %g s after the reference\n", cal->ref_u, cal->ref_corr_nm,
		(unsigned long long)cal->ref_seed, cal->drift_amp, cal->drift_tilt, cal->drift_period_s,
		(unsigned long long)cal->drift_seed, point_s);
	fprintf(fo, "theta_i,phi_i,theta_o,phi_o");
	header_wl(fo, wl, nwl, "");
	header_wl(fo, wl, nwl, "sigma_");
	fputc('\n', fo);
	int rows = 0, dropped = 0;
	for (int a = 0; a < ni; a++)
		for (int b = 0; b < no; b++)
			for (int c = 0; c < np; c++) {
				double ti = 80.0 * (a + 0.5) / ni, to = 80.0 * (b + 0.5) / no, po = 360.0 * c / np;
				double wi[3], wo[3];
				mat_dir(ti * M_PI / 180, g.laser_phi_deg * M_PI / 180, wi);
				mat_dir(to * M_PI / 180, po * M_PI / 180, wo);
				if (!keep_blind && angle_deg(wi, wo) < blind) {
					dropped++;
					continue;
				}
				mat_eval(m, wi, wo, f);
				double t = (rows + 1) * point_s;
				for (int l = 0; l < nwl; l++) {
					f[l] *= rf[l] * refdrift_source(cal, t, wl[l]);
					s[l] = sqrt(rel * rel * f[l] * f[l] + floor_ * floor_);
					v[l] = f[l] * (1.0 + rel * sim_rng_gauss(&r)) + floor_ * sim_rng_gauss(&r);
				}
				fprintf(fo, "%.10g,%.10g,%.10g,%.10g", ti, g.laser_phi_deg, to, po);
				for (int l = 0; l < nwl; l++)
					fprintf(fo, ",%.9g", v[l]);
				for (int l = 0; l < nwl; l++)
					fprintf(fo, ",%.3g", s[l]);
				fputc('\n', fo);
				rows++;
			}
	free(f);
	free(v);
	free(s);
	free(rf);
	fprintf(stderr, "acq-sim truth: %d samples written, %d in blind zones dropped\n", rows, dropped);
	if (fo != stdout && fclose(fo)) {
		fprintf(stderr, "acq-sim truth: %s: %s\n", out, strerror(errno));
		return 1;
	}
	return 0;
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

static int do_merl(struct mat *m, const char *out, const double *wl, int nwl)
{
	struct merl_ctx x = { .m = m };
	struct acq_err err = { 0 };
	colour_opts_brdf(&x.o);
	double *W = malloc(sizeof(double) * 3 * (size_t)nwl), *sp = malloc(sizeof(double) * (size_t)nwl);
	int rc = 1, oom = !W || !sp;
	for (int s = 0; s < MAT_S__COUNT; s++) {
		x.varies[s] = s == MAT_S_DIEL || s == MAT_S_COND;
		x.ftab[s] = malloc(sizeof(double) * 3 * (x.varies[s] ? MERL_FT + 1 : 1));
		oom |= !x.ftab[s];
	}
	if (oom) {
		fprintf(stderr, "acq-sim truth: out of memory\n");
		goto done;
	}
	if (colour_weights(&x.o, wl, (size_t)nwl, W, &err)) {
		fprintf(stderr, "acq-sim truth: --merl: %s\n", err.msg);
		goto done;
	}
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
	if (merl_write(out, merl_cb, &x, &err)) {
		fprintf(stderr, "acq-sim truth: --merl: %s\n", err.msg);
		goto done;
	}
	fprintf(stderr, "acq-sim truth: MERL table written to %s; colour decisions: ", out);
	colour_opts_write_json(stderr, &x.o, &x.st, NULL);
	fputc('\n', stderr);
	rc = 0;
done:
	free(W);
	free(sp);
	for (int s = 0; s < MAT_S__COUNT; s++)
		free(x.ftab[s]);
	return rc;
}

int sim_truth_main(int argc, char **argv)
{
	const char *dhr = NULL, *eval = NULL, *grid = NULL, *merl = NULL, *out = NULL, *thetas = "8,30,60",
		   *wls = "450:1100:1";
	double rel = 0.01, floor_ = 0;
	unsigned long long seed = 1;
	bool keep_blind = false, sphere = false;
	long level = 2;
	struct refdrift_cfg cal;
	refdrift_defaults(&cal);
	double point_s = 20;
	static const struct option opts[] = {
		{ "dhr", required_argument, NULL, 'd' },      { "eval", required_argument, NULL, 'e' },
		{ "grid", required_argument, NULL, 'g' },     { "merl", required_argument, NULL, 'm' },
		{ "theta-i", required_argument, NULL, 't' },  { "wavelengths", required_argument, NULL, 'w' },
		{ "noise", required_argument, NULL, 'n' },    { "noise-floor", required_argument, NULL, 'f' },
		{ "seed", required_argument, NULL, 's' },     { "keep-blind", no_argument, NULL, 'k' },
		{ "level", required_argument, NULL, 'L' },    { "output", required_argument, NULL, 'o' },
		{ "reference", required_argument, NULL, 'R' }, { "drift", required_argument, NULL, 'D' },
		{ "point-time", required_argument, NULL, 'P' }, { "spectrophotometer", no_argument, NULL, 'S' },
		{ "help", no_argument, NULL, 'h' },           { NULL, 0, NULL, 0 },
	};
	if (argc < 2 || !strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
		usage(argc < 2 ? stderr : stdout);
		return argc < 2 ? 2 : 0;
	}
	const char *material = argv[1];
	int id = mat_from_name(material);
	if (id < 0) {
		fprintf(stderr, "acq-sim truth: unknown material '%s' (expected %s)\n", material, mat_names_list());
		return 2;
	}
	/* options after MATERIAL: parse argv + 1 from its index 1; optind = 0 re-initialises getopt (so the
	 * function can run more than once in a process) */
	optind = 0;
	int c, nact = 0, oargc = argc - 1;
	char **oargv = argv + 1;
	while ((c = getopt_long(oargc, oargv, "o:h", opts, NULL)) != -1) {
		char *end = NULL;
		switch (c) {
		case 'd': dhr = optarg; nact++; break;
		case 'e': eval = optarg; nact++; break;
		case 'g': grid = optarg; nact++; break;
		case 'm': merl = optarg; nact++; break;
		case 't': thetas = optarg; break;
		case 'w': wls = optarg; break;
		case 'o': out = optarg; break;
		case 'k': keep_blind = true; break;
		case 'S': sphere = true; nact++; break;
		case 'n':
		case 'f': {
			double v = strtod(optarg, &end);
			if (end == optarg || *end || !(v >= 0 && v <= 10)) {
				fprintf(stderr, "acq-sim truth: --%s: expected a number in [0, 10], got '%s'\n",
					c == 'n' ? "noise" : "noise-floor", optarg);
				return 2;
			}
			*(c == 'n' ? &rel : &floor_) = v;
			break;
		}
		case 's':
			errno = 0;
			seed = strtoull(optarg, &end, 10);
			if (end == optarg || *end || errno || optarg[0] == '-') {
				fprintf(stderr, "acq-sim truth: --seed: expected a non-negative integer, got '%s'\n", optarg);
				return 2;
			}
			break;
		case 'L':
			level = strtol(optarg, &end, 10);
			if (end == optarg || *end || level < 0 || level > 5) {
				fprintf(stderr, "acq-sim truth: --level: expected 0..5, got '%s'\n", optarg);
				return 2;
			}
			break;
		case 'R':
			if (parse_triple(optarg, &cal.ref_u, &cal.ref_corr_nm, &cal.ref_seed) || !(cal.ref_u >= 0 && cal.ref_u <= 0.1) ||
			    !(cal.ref_corr_nm >= 5 && cal.ref_corr_nm <= 10000)) {
				fprintf(stderr, "acq-sim truth: --reference: expected U[,CORR_NM[,SEED]] with U in [0, 0.1], "
						"CORR_NM in [5, 10000], got '%s'\n", optarg);
				return 2;
			}
			break;
		case 'D':
			if (parse_triple(optarg, &cal.drift_amp, &cal.drift_period_s, &cal.drift_seed) ||
			    !(cal.drift_amp >= 0 && cal.drift_amp <= 0.05) || !(cal.drift_period_s >= 1 && cal.drift_period_s <= 1e7)) {
				fprintf(stderr, "acq-sim truth: --drift: expected AMP[,PERIOD_S[,SEED]] with AMP in [0, 0.05], "
						"PERIOD_S in [1, 1e7], got '%s'\n", optarg);
				return 2;
			}
			break;
		case 'P':
			point_s = strtod(optarg, &end);
			if (end == optarg || *end || !(point_s >= 0 && point_s <= 1e6)) {
				fprintf(stderr, "acq-sim truth: --point-time: expected seconds in [0, 1e6], got '%s'\n", optarg);
				return 2;
			}
			break;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (optind < oargc) {
		fprintf(stderr, "acq-sim truth: unexpected argument '%s'\n", oargv[optind]);
		return 2;
	}
	if (nact != 1) {
		fprintf(stderr, "acq-sim truth: give exactly one of --dhr, --eval, --grid, --merl, --spectrophotometer\n");
		return 2;
	}
	if (grid && !out) {
		fprintf(stderr, "acq-sim truth: --grid needs -o SAMPLES.csv (or -o - for standard output)\n");
		return 2;
	}
	double *wl = NULL;
	int nwl = 0;
	if (parse_wavelengths(wls, &wl, &nwl)) {
		fprintf(stderr, "acq-sim truth: --wavelengths: expected A:B:STEP (or one value) within 450..1100 nm, "
				"at most %d wavelengths, got '%s'\n", MAX_WL, wls);
		return 2;
	}
	struct acq_err err = { 0 };
	struct mat *m = mat_new((enum mat_id)id, nwl, wl, &err);
	int rc;
	if (!m) {
		fprintf(stderr, "acq-sim truth: %s\n", err.msg);
		rc = 1;
	} else if (dhr) {
		rc = do_dhr(m, mat_name(id), dhr, thetas, (int)level, wl, nwl);
	} else if (eval) {
		rc = do_eval(m, eval, out ? out : "-", wl, nwl);
	} else if (sphere) {
		rc = do_sphere(m, out ? out : "-", seed, wl, nwl);
	} else if (grid) {
		rc = do_grid(m, mat_name(id), grid, out, rel, floor_, seed, keep_blind, &cal, point_s, wl, nwl);
	} else {
		rc = do_merl(m, merl, wl, nwl);
	}
	mat_free(m);
	free(wl);
	return rc;
}
