/* brdf-recon: command-line front end of the reconstruction library (fit, eval, dhr, check, info, merl,
 * render). Only this file prints. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <sys/stat.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "acq_version.h"
#include "recon/budget.h"
#include "recon/colour.h"
#include "recon/csvio.h"
#include "recon/merl.h"
#include "recon/plot.h"
#include "recon/recon.h"
#include "recon/render.h"
#include "recon/rgbeval.h"
#include "recon/brdf_recon/cli.h"
#include "recon/exrio.h"
#include "recon/sky.h"

static const char *prog = "brdf-recon";

/* fontconfig (behind cairo's text in dhr --plot) keeps process-lifetime caches that LeakSanitizer reports;
 * they are not ours. This hook is read by LSan only in sanitizer builds. */
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void)
{
	return "leak:libfontconfig.so\n";
}

void progress(void *ctx, const char *stage, double frac)
{
	(void)ctx;
	if (!isatty(2))
		return;
	fprintf(stderr, "\r  %-14s %3d%%%s", stage, (int)(100 * frac + 0.5), frac >= 1.0 ? "\n" : "");
	fflush(stderr);
}

void progress_end(void)
{
	if (isatty(2))
		fprintf(stderr, "\r%40s\r", "");
}

int fail(const struct acq_err *e)
{
	progress_end();
	fprintf(stderr, "%s: %s\n", prog, e->msg[0] ? e->msg : "error");
	return 1;
}

int usage_err(const char *cmd, const char *msg)
{
	fprintf(stderr, "%s %s: %s (see %s %s --help)\n", prog, cmd, msg, prog, cmd);
	return 2;
}

int parse_double(const char *s, double *out)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end || errno || !isfinite(v))
		return -1;
	*out = v;
	return 0;
}

int parse_u64(const char *s, uint64_t *out)
{
	char *end;
	errno = 0;
	if (!*s || *s == '-')
		return -1;
	unsigned long long v = strtoull(s, &end, 10);
	if (*end || errno)
		return -1;
	*out = v;
	return 0;
}

/* Open the output: stdout for NULL or "-"; an existing file that is not a regular file (/dev/null, a FIFO, a
 * terminal) directly, since renaming over it would replace the device (as root, /dev/null became a regular
 * file); else a temporary file renamed on success. */
struct out {
	FILE *f;
	const char *path;
	char tmp[4096];
	int direct;
};

static int out_open(struct out *o, const char *path, struct acq_err *err)
{
	o->path = path;
	o->direct = 0;
	if (!path || !strcmp(path, "-")) {
		o->f = stdout;
		o->path = NULL;
		return 0;
	}
	struct stat st;
	if (stat(path, &st) == 0 && !S_ISREG(st.st_mode)) {
		if (S_ISDIR(st.st_mode))
			return acq_errf(err, ACQ_E_IO, "%s: is a directory", path);
		o->direct = 1;
		o->f = fopen(path, "w");
		return o->f ? 0 : acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(errno));
	}
	snprintf(o->tmp, sizeof o->tmp, "%s.tmp.%ld", path, (long)getpid());
	o->f = fopen(o->tmp, "w");
	if (!o->f)
		return acq_errf(err, ACQ_E_IO, "%s: %s", o->tmp, strerror(errno));
	return 0;
}

static int out_close(struct out *o, int ok, struct acq_err *err)
{
	if (!o->path) {
		fflush(stdout);
		return ok ? 0 : -1;
	}
	int bad = fclose(o->f) != 0;
	if (o->direct)
		return !ok ? -1 : bad ? acq_errf(err, ACQ_E_IO, "%s: write failed", o->path) : 0;
	if (!ok || bad) {
		unlink(o->tmp);
		return ok ? acq_errf(err, ACQ_E_IO, "%s: write failed", o->path) : -1;
	}
	if (rename(o->tmp, o->path)) {
		unlink(o->tmp);
		return acq_errf(err, ACQ_E_IO, "%s: %s", o->path, strerror(errno));
	}
	return 0;
}

/* ---- fit ---- */
static const char fit_help[] =
	"usage: brdf-recon fit SAMPLES.csv -o MODEL [options]\n"
	"       brdf-recon fit --db FILE --sweep ID -o MODEL [options]\n"
	"Fit a reconstruction to sparse spectral BRDF samples (CSV interchange format, design.md).\n"
	"  -o, --output MODEL      model file to write (required)\n"
	"  --kernel K              wendland (default, positive definite), exp, gauss, paper (Gaussian of d_Rec,\n"
	"                          the paper's literal construction, not guaranteed positive definite)\n"
	"  --transform T           log (default: interpolate ln(f+eps)) or sqrt\n"
	"  --trend T               auto (default), ggx or none. ggx: interpolate relative to a fitted Lambertian\n"
	"                          + GGX lobe + coated diffuse, so a lobe narrower than the sampling keeps a\n"
	"                          microfacet shape; none: the plain interpolant (the only choice with sqrt);\n"
	"                          auto: whichever has the lower leave-one-out error (log transform)\n"
	"  --shape X|auto          kernel shape parameter (default auto: Rippa leave-one-out over a grid)\n"
	"  --smoothing X|auto|sigma  eta in (K + eta*diag(r)) w = g, r from the uncertainties: a number, auto\n"
	"                          (default: leave-one-out), or sigma (Lambda = the transformed variances over\n"
	"                          the prior variance of the data; needs sigma_<nm> columns)\n"
	"  --max-cond X            largest accepted condition number (default 1e12)\n"
	"  --db FILE --sweep ID    read a sweep from the daemon's database instead of a CSV file\n";

static int cmd_fit(int argc, char **argv)
{
	static const struct option lo[] = {
		{ "output", required_argument, 0, 'o' }, { "kernel", required_argument, 0, 'k' },
		{ "transform", required_argument, 0, 't' }, { "shape", required_argument, 0, 's' },
		{ "smoothing", required_argument, 0, 'm' }, { "max-cond", required_argument, 0, 'c' },
		{ "db", required_argument, 0, 'd' }, { "sweep", required_argument, 0, 'w' },
		{ "trend", required_argument, 0, 'r' }, { "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	o.progress = progress;
	const char *outp = NULL, *db = NULL;
	uint64_t sweep = 0;
	int have_sweep = 0, c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': outp = optarg; break;
		case 'k':
			if ((o.kernel = rbf_kernel_from_name(optarg)) < 0)
				return usage_err("fit", "unknown kernel");
			break;
		case 't':
			if ((o.transform = recon_transform_from_name(optarg)) < 0)
				return usage_err("fit", "unknown transform");
			break;
		case 'r':
			if (strcmp(optarg, "auto") && (o.trend = trend_from_name(optarg)) < 0)
				return usage_err("fit", "unknown trend (auto, ggx or none)");
			if (!strcmp(optarg, "auto"))
				o.trend = -1;
			break;
		case 's':
			if (!strcmp(optarg, "auto"))
				o.shape = 0;
			else if (parse_double(optarg, &o.shape) || !(o.shape > 0))
				return usage_err("fit", "--shape needs a positive number or auto");
			break;
		case 'm':
			if (!strcmp(optarg, "auto"))
				o.smoothing = -1;
			else if (!strcmp(optarg, "sigma"))
				o.smoothing = RECON_SMOOTHING_SIGMA;
			else if (parse_double(optarg, &o.smoothing) || o.smoothing < 0)
				return usage_err("fit", "--smoothing needs a number >= 0, auto or sigma");
			break;
		case 'c':
			if (parse_double(optarg, &o.max_cond) || !(o.max_cond >= 1))
				return usage_err("fit", "--max-cond needs a number >= 1");
			break;
		case 'd': db = optarg; break;
		case 'w':
			if (parse_u64(optarg, &sweep))
				return usage_err("fit", "--sweep needs an id");
			have_sweep = 1;
			break;
		case 'h': fputs(fit_help, stdout); return 0;
		default: return usage_err("fit", "bad option");
		}
	}
	if (!outp)
		return usage_err("fit", "-o MODEL is required");
	struct acq_err err = { 0 };
	struct recon_samples s;
	if (db) {
		if (!have_sweep || optind != argc)
			return usage_err("fit", "--db needs --sweep ID and no CSV file");
		if (recon_load_db(db, (long long)sweep, &s, &err))
			return fail(&err);
		o.source = db;
	} else {
		if (optind != argc - 1)
			return usage_err("fit", "one SAMPLES.csv expected");
		o.source = argv[optind];
		if (csvio_read_samples(argv[optind], &s, &err))
			return fail(&err);
	}
	struct recon_model *m = NULL;
	int rc = recon_fit(&s, &o, &m, &err);
	csvio_samples_free(&s);
	if (rc)
		return fail(&err);
	progress_end();
	if (recon_model_save(m, outp, &err)) {
		recon_model_free(m);
		return fail(&err);
	}
	fprintf(stderr, "fit: %zu directions, %zu wavelengths, kernel %s shape %.3g, transform %s, trend %s (alpha %.3g), "
		"smoothing %.3g, leave-one-out RMS %.4g, rcond %.3g -> %s\n", m->n, m->nwl, rbf_kernel_name(m->kernel),
		m->shape, recon_transform_name(m->transform), trend_name(m->trend), m->trend_alpha, m->eta, m->loo_rms,
		m->rcond, outp);
	for (const char *p = strstr(m->meta, "warning="); p; p = strstr(p + 1, "\nwarning=")) {
		const char *b = strchr(p, '=') + 1, *e = strchr(b, '\n');
		fprintf(stderr, "fit: warning: %.*s\n", e ? (int)(e - b) : (int)strlen(b), b);
	}
	recon_model_free(m);
	return 0;
}

/* ---- eval ---- */
static const char eval_help[] =
	"usage: brdf-recon eval MODEL QUERIES.csv [-o OUT.csv]\n"
	"Evaluate the model at the directions of QUERIES.csv (columns theta_i,phi_i,theta_o,phi_o in degrees;\n"
	"other columns ignored). Writes CSV (stdout by default): the four angle columns, then one column per\n"
	"model wavelength (sr^-1).\n";

static int write_header_wl(FILE *f, const struct recon_model *m)
{
	for (size_t l = 0; l < m->nwl; l++)
		fprintf(f, ",%.10g", m->wl[l]);
	return fputc('\n', f) == EOF ? -1 : 0;
}

static int cmd_eval(int argc, char **argv)
{
	static const struct option lo[] = { { "output", required_argument, 0, 'o' },
					    { "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	const char *outp = NULL;
	int c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		if (c == 'o')
			outp = optarg;
		else if (c == 'h') {
			fputs(eval_help, stdout);
			return 0;
		} else
			return usage_err("eval", "bad option");
	}
	if (optind != argc - 2)
		return usage_err("eval", "MODEL and QUERIES.csv expected");
	struct acq_err err = { 0 };
	struct recon_model *m;
	if (recon_model_load(argv[optind], &m, &err))
		return fail(&err);
	struct recon_samples q;
	if (csvio_read_queries(argv[optind + 1], &q, &err)) {
		recon_model_free(m);
		return fail(&err);
	}
	size_t L = m->nwl, B = 4096;
	double *vals = malloc(B * L * sizeof *vals);
	struct out o;
	int ok = vals && !out_open(&o, outp, &err);
	if (!vals)
		acq_errf(&err, ACQ_E_NOMEM, "eval: out of memory");
	if (ok) {
		fputs("theta_i,phi_i,theta_o,phi_o", o.f);
		write_header_wl(o.f, m);
		for (size_t q0 = 0; ok && q0 < q.n; q0 += B) {
			size_t b = q.n - q0 < B ? q.n - q0 : B;
			progress(NULL, "eval", (double)q0 / (double)q.n);
			if (recon_eval(m, b, q.ang + 4 * q0, vals, &err)) {
				ok = 0;
				break;
			}
			char buf[64];
			for (size_t i = 0; ok && i < b; i++) {
				for (int a = 0; a < 4; a++)
					fprintf(o.f, a ? ",%.10g" : "%.10g", q.deg[(q0 + i) * 4 + a]);
				for (size_t l = 0; l < L; l++) {
					if (csvio_fmt(buf, sizeof buf, vals[i * L + l])) {
						acq_errf(&err, ACQ_E_NUMERIC, "eval: non-finite value at query %zu", q0 + i + 1);
						ok = 0;
						break;
					}
					fprintf(o.f, ",%s", buf);
				}
				fputc('\n', o.f);
			}
		}
		if (out_close(&o, ok, &err))
			ok = 0;
	}
	progress_end();
	free(vals);
	csvio_samples_free(&q);
	recon_model_free(m);
	return ok ? 0 : fail(&err);
}

/* ---- dhr ---- */
static const char dhr_help[] =
	"usage: brdf-recon dhr MODEL [--theta-i 8,30,60] [--draws N] [--seed S] [-o OUT.csv] [budget options]\n"
	"                      [--reference REF.csv [--reference-theta 8] [--z-out Z.csv]] [--plot OUT.png]\n"
	"Directional-hemispherical reflectance DHR(theta_i, lambda) of the model with its uncertainty budget.\n"
	"Quadrature: Gauss-Legendre 32 in cos(theta_o) x 48 azimuth midpoints (exact for a Lambertian), doubled\n"
	"per wavelength up to 256 x 384 until two rules agree to 1e-3 (narrow lobes).\n"
	"Output CSV (stdout by default), standard uncertainties per wavelength (recon/reconstruction.md):\n"
	"  theta_i,wavelength_nm,dhr,sigma, then the budget:\n"
	"  sigma_noise   the samples' sigma columns (counting, dark and white-reference noise: the files carry\n"
	"                their sum) propagated by Monte Carlo through the one factorisation (--draws, --seed);\n"
	"  sigma_model   interpolation between samples (GP posterior; with the prior on the unseen hemisphere);\n"
	"  sigma_quad    quadrature;  sigma_misfit  samples the model does not honour;\n"
	"  sigma_res     resolution in theta_i (a lobe narrower than the incidence spacing);\n"
	"  sigma_cert    the white standard's certificate (correlated: one factor for all wavelengths);\n"
	"  sigma_drift   source drift between reference and samples (correlated likewise);\n"
	"  sigma_wlcal   wavelength calibration, |dDHR/dlambda| x its uncertainty;  sigma_nonlin  nonlinearity.\n"
	"  sigma = sqrt(max(noise, model)^2 + quad^2 + misfit^2 + res^2 + cert^2 + drift^2 + wlcal^2 + nonlin^2).\n"
	"Budget options (the sample file and database carry none of these: each is 0 unless given):\n"
	"  --cert CERT.csv       the white standard's certificate, columns wavelength_nm,rho,u\n"
	"  --cert-rel X          or its relative standard uncertainty at every wavelength\n"
	"  --drift-rel X         relative standard uncertainty of the source between reference and samples\n"
	"  --wl-cal-nm X         standard uncertainty of the wavelength calibration (nm)\n"
	"  --nonlin-rel X        relative residual of the nonlinearity correction\n"
	"  --reference REF.csv   compare with a measured DHR (columns wavelength_nm,dhr,sigma, e.g. a\n"
	"                        spectrophotometer at 8 degrees: acq-sim truth MATERIAL --spectrophotometer) at\n"
	"                        --reference-theta (default 8, must be among --theta-i): prints the agreement (share\n"
	"                        of wavelengths with |z| < 2, z with both uncertainties) and chi2/n with the\n"
	"                        correlated components as one common factor; per-wavelength z to --z-out (or stderr)\n"
	"  --plot OUT.png        the curves with +-2 sigma bands, the reference band and a panel of the residual in\n"
	"                        units of sigma\n";

/* The model's curve at the reference wavelengths (linear in λ, the model's grid): value, total σ, correlated σ. */
static void at_reference(const struct recon_model *m, const double *y, const double *s, const double *c, double wl,
			 double *yo, double *so, double *co)
{
	size_t L = m->nwl, j = 0;
	while (j + 1 < L && m->wl[j + 1] < wl)
		j++;
	size_t j2 = j + 1 < L ? j + 1 : j;
	double u = j2 > j ? (wl - m->wl[j]) / (m->wl[j2] - m->wl[j]) : 0;
	*yo = (1 - u) * y[j] + u * y[j2];
	*so = (1 - u) * s[j] + u * s[j2];
	*co = (1 - u) * c[j] + u * c[j2];
}

enum { DB_NOISE, DB_MODEL, DB_QUAD, DB_MISFIT, DB_RES, DB_CERT, DB_DRIFT, DB_WLCAL, DB_NONLIN, DB_N };
static const char *const db_names[DB_N] = { "sigma_noise", "sigma_model",  "sigma_quad",  "sigma_misfit", "sigma_res",
					    "sigma_cert",  "sigma_drift", "sigma_wlcal", "sigma_nonlin" };

/* DHR and budget of model m at nth incidences th (degrees) into dhr, sig (total) and part[DB_N][nth*L]. */
static int dhr_budget(const struct recon_model *m, size_t nth, const double *th, uint64_t draws, uint64_t seed,
		      const struct recon_budget_opts *bo, double *dhr, double *sig, double **part, struct acq_err *err)
{
	double thr[64];
	for (size_t t = 0; t < nth; t++)
		thr[t] = th[t] * M_PI / 180.0;
	struct recon_dhr_parts parts = { .noise = part[DB_NOISE], .model = part[DB_MODEL], .quad = part[DB_QUAD],
					 .misfit = part[DB_MISFIT], .res = part[DB_RES] };
	double *srec = malloc(nth * m->nwl * sizeof *srec);
	int rc = !srec ? acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory")
		 : recon_dhr_parts(m, nth, thr, (int)draws, seed, dhr, srec, &parts, progress, NULL, err) ||
			 recon_budget(nth, m->nwl, m->wl, dhr, srec, bo, part[DB_CERT], part[DB_DRIFT], part[DB_WLCAL],
				      part[DB_NONLIN], sig, err)
		 ? -1
		 : 0;
	free(srec);
	return rc;
}

static int cmd_dhr(int argc, char **argv)
{
	static const struct option lo[] = {
		{ "output", required_argument, 0, 'o' }, { "theta-i", required_argument, 0, 't' },
		{ "draws", required_argument, 0, 'n' }, { "seed", required_argument, 0, 's' },
		{ "reference", required_argument, 0, 'r' }, { "reference-theta", required_argument, 0, 'R' },
		{ "z-out", required_argument, 0, 'z' }, { "plot", required_argument, 0, 'p' },
		{ "cert", required_argument, 0, 'C' }, { "cert-rel", required_argument, 0, 'c' },
		{ "drift-rel", required_argument, 0, 'd' }, { "wl-cal-nm", required_argument, 0, 'w' },
		{ "nonlin-rel", required_argument, 0, 'N' }, { "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	const char *outp = NULL, *refp = NULL, *zout = NULL, *plot = NULL, *certp = NULL;
	double th[64] = { 8, 30, 60 }, ref_th = 8;
	size_t nth = 3;
	uint64_t draws = 64, seed = 1;
	struct recon_budget_opts bo = { 0 };
	int c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': outp = optarg; break;
		case 't': {
			nth = 0;
			char *save = NULL, *dup = strdup(optarg);
			for (char *tok = strtok_r(dup, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
				if (nth == 64 || parse_double(tok, &th[nth]) || th[nth] < 0 || th[nth] > 90) {
					free(dup);
					return usage_err("dhr", "--theta-i needs up to 64 angles in [0, 90]");
				}
				nth++;
			}
			free(dup);
			if (!nth)
				return usage_err("dhr", "--theta-i is empty");
			break;
		}
		case 'n':
			if (parse_u64(optarg, &draws) || draws > 100000)
				return usage_err("dhr", "--draws needs 0..100000");
			break;
		case 's':
			if (parse_u64(optarg, &seed))
				return usage_err("dhr", "--seed needs an unsigned integer");
			break;
		case 'r': refp = optarg; break;
		case 'R':
			if (parse_double(optarg, &ref_th))
				return usage_err("dhr", "--reference-theta needs a number");
			break;
		case 'z': zout = optarg; break;
		case 'p': plot = optarg; break;
		case 'C': certp = optarg; break;
		case 'c':
			if (parse_double(optarg, &bo.cert_rel) || !(bo.cert_rel >= 0 && bo.cert_rel < 1))
				return usage_err("dhr", "--cert-rel needs a number in [0, 1)");
			break;
		case 'd':
			if (parse_double(optarg, &bo.drift_rel) || !(bo.drift_rel >= 0 && bo.drift_rel < 1))
				return usage_err("dhr", "--drift-rel needs a number in [0, 1)");
			break;
		case 'w':
			if (parse_double(optarg, &bo.wl_cal_nm) || !(bo.wl_cal_nm >= 0 && bo.wl_cal_nm < 100))
				return usage_err("dhr", "--wl-cal-nm needs a number in [0, 100)");
			break;
		case 'N':
			if (parse_double(optarg, &bo.nonlin_rel) || !(bo.nonlin_rel >= 0 && bo.nonlin_rel < 1))
				return usage_err("dhr", "--nonlin-rel needs a number in [0, 1)");
			break;
		case 'h': fputs(dhr_help, stdout); return 0;
		default: return usage_err("dhr", "bad option");
		}
	}
	if (optind != argc - 1)
		return usage_err("dhr", "one MODEL expected");
	struct acq_err err = { 0 };
	double *cert = NULL;
	size_t ncert = 0;
	if (certp) {
		static const char *const cn[3] = { "wavelength_nm", "rho", "u" };
		if (csvio_read_columns(certp, cn, 3, &ncert, &cert, &err))
			return fail(&err);
		double *cw = malloc(3 * ncert * sizeof *cw);
		if (!cw || !ncert) {
			free(cert);
			free(cw);
			acq_errf(&err, ACQ_E_INVAL, "dhr: --cert %s: no rows", certp);
			return fail(&err);
		}
		for (size_t i = 0; i < ncert; i++) { /* rows → columns */
			cw[i] = cert[3 * i];
			cw[ncert + i] = cert[3 * i + 1];
			cw[2 * ncert + i] = cert[3 * i + 2];
		}
		free(cert);
		cert = cw;
		bo.cert_wl = cert;
		bo.cert_rho = cert + ncert;
		bo.cert_u = cert + 2 * ncert;
		bo.ncert = ncert;
	}
	struct recon_model *m;
	if (recon_model_load(argv[optind], &m, &err)) {
		free(cert);
		return fail(&err);
	}
	size_t L = m->nwl, NL = nth * L;
	double *dhr = malloc(NL * sizeof *dhr), *sig = malloc(NL * sizeof *sig), *pbuf = malloc(DB_N * NL * sizeof *pbuf);
	double *part[DB_N], *ref = NULL, *corr = malloc(NL * sizeof *corr);
	size_t nref = 0;
	int ok = dhr && sig && pbuf && corr;
	if (!ok)
		acq_errf(&err, ACQ_E_NOMEM, "dhr: out of memory");
	for (int k = 0; k < DB_N; k++)
		part[k] = pbuf ? pbuf + (size_t)k * NL : NULL;
	if (ok && dhr_budget(m, nth, th, draws, seed, &bo, dhr, sig, part, &err))
		ok = 0;
	progress_end();
	for (size_t i = 0; ok && i < NL; i++) /* the correlated part: one common factor (certificate, drift) */
		corr[i] = hypot(part[DB_CERT][i], part[DB_DRIFT][i]);
	struct out o;
	if (ok && !out_open(&o, outp, &err)) {
		fputs("theta_i,wavelength_nm,dhr,sigma", o.f);
		for (int k = 0; k < DB_N; k++)
			fprintf(o.f, ",%s", db_names[k]);
		fputc('\n', o.f);
		char b[64];
		for (size_t t = 0; ok && t < nth; t++)
			for (size_t l = 0; ok && l < L; l++) {
				size_t i = t * L + l;
				fprintf(o.f, "%.10g,%.10g", th[t], m->wl[l]);
				for (int k = -2; ok && k < DB_N; k++) {
					double v = k == -2 ? dhr[i] : k == -1 ? sig[i] : part[k][i];
					if (csvio_fmt(b, sizeof b, v)) {
						acq_errf(&err, ACQ_E_NUMERIC, "dhr: non-finite value");
						ok = 0;
					} else {
						fprintf(o.f, ",%s", b);
					}
				}
				fputc('\n', o.f);
			}
		if (out_close(&o, ok, &err))
			ok = 0;
	} else if (ok) {
		ok = 0;
	}
	if (ok && !certp && bo.cert_rel == 0 && bo.drift_rel == 0 && bo.wl_cal_nm == 0 && bo.nonlin_rel == 0)
		fprintf(stderr, "dhr: no --cert/--cert-rel, --drift-rel, --wl-cal-nm, --nonlin-rel given: those components "
			"are 0 (the samples carry no input for them)\n");
	size_t tref = nth;
	double *zr = NULL, *zwl = NULL;
	if (ok && refp) {
		static const char *const names[3] = { "wavelength_nm", "dhr", "sigma" };
		for (tref = 0; tref < nth; tref++)
			if (fabs(th[tref] - ref_th) < 1e-9)
				break;
		if (tref == nth) {
			acq_errf(&err, ACQ_E_INVAL, "dhr: --reference-theta %g is not among --theta-i", ref_th);
			ok = 0;
		} else if (csvio_read_columns(refp, names, 3, &nref, &ref, &err)) {
			ok = 0;
		}
	}
	if (ok && ref) {
		/* the reference's wavelengths inside the model's range */
		double *cmp = malloc(8 * (nref ? nref : 1) * sizeof *cmp);
		if (!cmp) {
			acq_errf(&err, ACQ_E_NOMEM, "dhr: out of memory");
			ok = 0;
		}
		size_t nc = 0;
		double *cw = cmp, *md = cmp + nref, *ms = cmp + 2 * nref, *mc = cmp + 3 * nref, *rv = cmp + 4 * nref,
		       *rs = cmp + 5 * nref, *z = cmp + 6 * nref;
		for (size_t i = 0; ok && i < nref; i++) {
			double wl = ref[3 * i];
			if (!(wl >= m->wl[0] && wl <= m->wl[L - 1]) || !isfinite(ref[3 * i + 1]) || !(ref[3 * i + 2] >= 0))
				continue;
			cw[nc] = wl;
			at_reference(m, dhr + tref * L, sig + tref * L, corr + tref * L, wl, &md[nc], &ms[nc], &mc[nc]);
			rv[nc] = ref[3 * i + 1];
			rs[nc] = ref[3 * i + 2];
			nc++;
		}
		struct recon_agreement ag;
		if (ok)
			recon_agreement(nc, cw, md, ms, mc, rv, rs, z, &ag);
		FILE *zf = stderr;
		struct out zo;
		if (ok && zout) {
			if (out_open(&zo, zout, &err))
				ok = 0;
			else
				zf = zo.f;
		}
		if (ok) {
			fprintf(zf, "wavelength_nm,dhr_model,sigma_model,dhr_ref,sigma_ref,z\n");
			for (size_t i = 0; i < nc; i++)
				fprintf(zf, "%.10g,%.10g,%.10g,%.10g,%.10g,%.6g\n", cw[i], md[i], ms[i], rv[i], rs[i], z[i]);
		}
		if (ok && zout && out_close(&zo, ok, &err))
			ok = 0;
		if (ok)
			fprintf(stderr, "reference %s at theta_i=%g: %zu wavelengths compared, agreement %.1f%% within |z| <= 2 "
				"(z with both uncertainties), RMS z %.3g, max |z| %.3g at %g nm, chi2/n %.3g with the "
				"correlated components (certificate, drift) as one common factor\n", refp, ref_th, ag.n,
				ag.n ? 100.0 * (double)ag.within2 / (double)ag.n : 0.0, ag.rms_z, ag.max_z, ag.max_z_wl,
				ag.chi2_n);
		if (ok && plot) { /* keep the residual for the plot */
			zr = malloc((nc ? nc : 1) * sizeof *zr);
			zwl = malloc((nc ? nc : 1) * sizeof *zwl);
			if (zr && zwl) {
				memcpy(zr, z, nc * sizeof *zr);
				memcpy(zwl, cw, nc * sizeof *zwl);
				nref = nc;
			}
		}
		free(cmp);
	}
	if (ok && plot) {
		struct plot_curve curves[64], refc, resc;
		char labels[64][32];
		double *refwl = NULL, *refy = NULL, *refs = NULL;
		for (size_t t = 0; t < nth; t++) {
			snprintf(labels[t], sizeof labels[t], "\u03b8i = %g\u00b0", th[t]);
			curves[t] = (struct plot_curve){ labels[t], m->wl, dhr + t * L, sig + t * L, L };
		}
		if (ref) {
			size_t nr = 0;
			static const char *const names[3] = { "wavelength_nm", "dhr", "sigma" };
			double *all = NULL;
			if (csvio_read_columns(refp, names, 3, &nr, &all, &err) == 0) {
				refwl = malloc(nr * sizeof *refwl);
				refy = malloc(nr * sizeof *refy);
				refs = malloc(nr * sizeof *refs);
				if (refwl && refy && refs) {
					for (size_t i = 0; i < nr; i++) {
						refwl[i] = all[3 * i];
						refy[i] = all[3 * i + 1];
						refs[i] = all[3 * i + 2];
					}
					refc = (struct plot_curve){ "reference", refwl, refy, refs, nr };
				}
			}
			free(all);
		}
		struct plot_dhr_opts po;
		plot_dhr_opts_default(&po);
		po.title = "Directional-hemispherical reflectance (bands: \u00b12\u03c3)";
		if (zr && zwl) {
			resc = (struct plot_curve){ "(model \u2212 ref) / \u03c3", zwl, zr, NULL, nref };
			po.residual = &resc;
			po.height = 720;
		}
		if (plot_dhr_png(plot, curves, nth, refwl && refy && refs ? &refc : NULL, &po, NULL, &err))
			ok = 0;
		free(refwl);
		free(refy);
		free(refs);
	}
	free(zr);
	free(zwl);
	free(ref);
	free(cert);
	free(dhr);
	free(sig);
	free(pbuf);
	free(corr);
	recon_model_free(m);
	return ok ? 0 : fail(&err);
}

/* ---- check ---- */
static const char check_help[] =
	"usage: brdf-recon check MODEL [--pairs N] [--thetas N] [--seed S]\n"
	"Verify the three physical properties of the evaluated model: non-negativity and reciprocity at N random\n"
	"direction pairs (default 100000), energy conservation (albedo <= 1 at every wavelength) at N random\n"
	"incidences plus 0 and 90 degrees (default 16) with an independent finer quadrature (Gauss-Legendre 48\n"
	"in cos^2(theta_o) x 96 azimuths). Prints the worst violation of each; exit 1 if any property fails.\n";

static int cmd_check(int argc, char **argv)
{
	static const struct option lo[] = {
		{ "pairs", required_argument, 0, 'p' }, { "thetas", required_argument, 0, 't' },
		{ "seed", required_argument, 0, 's' }, { "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	uint64_t pairs = 100000, thetas = 16, seed = 1;
	int c;
	while ((c = getopt_long(argc, argv, "h", lo, NULL)) != -1) {
		switch (c) {
		case 'p':
			if (parse_u64(optarg, &pairs) || pairs > 100000000)
				return usage_err("check", "--pairs needs a count");
			break;
		case 't':
			if (parse_u64(optarg, &thetas) || thetas > 100000)
				return usage_err("check", "--thetas needs a count");
			break;
		case 's':
			if (parse_u64(optarg, &seed))
				return usage_err("check", "--seed needs an unsigned integer");
			break;
		case 'h': fputs(check_help, stdout); return 0;
		default: return usage_err("check", "bad option");
		}
	}
	if (optind != argc - 1)
		return usage_err("check", "one MODEL expected");
	struct acq_err err = { 0 };
	struct recon_model *m;
	if (recon_model_load(argv[optind], &m, &err))
		return fail(&err);
	struct recon_check_report r;
	int rc = recon_check(m, pairs, thetas, seed, &r, progress, NULL, &err);
	progress_end();
	recon_model_free(m);
	if (rc)
		return fail(&err);
	int nonneg = r.min_value >= 0 && r.nonfinite == 0, recip = r.max_recip_abs == 0.0,
	    energy = r.max_albedo <= 1.0;
	printf("check: %zu random pairs, %zu incidences (seed %llu)\n", r.npairs, r.nalb, (unsigned long long)seed);
	printf("non-negativity:  %s  min f = %.6g sr^-1, non-finite values: %zu\n", nonneg ? "ok  " : "FAIL",
	       r.min_value, r.nonfinite);
	printf("reciprocity:     %s  max |f(wi,wo) - f(wo,wi)| = %.3g (relative %.3g)\n", recip ? "ok  " : "FAIL",
	       r.max_recip_abs, r.max_recip_rel);
	printf("energy:          %s  max albedo = %.6f at theta_i = %.2f deg, %g nm (violation %.3g)\n",
	       energy ? "ok  " : "FAIL", r.max_albedo, r.max_albedo_theta * 180 / M_PI, r.max_albedo_wl,
	       r.max_albedo > 1 ? r.max_albedo - 1 : 0.0);
	return nonneg && recip && energy ? 0 : 1;
}

/* ---- info ---- */
static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

static int cmd_info(int argc, char **argv)
{
	int budget = 1;
	if (argc == 3 && !strcmp(argv[2], "--no-budget")) {
		budget = 0;
		argc--;
	}
	if (argc == 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
		puts("usage: brdf-recon info MODEL [--no-budget]\nPrint a model's parameters and metadata (warnings of the "
		     "fit included), and the DHR uncertainty budget at theta_i = 8 deg (16 draws; the median and largest\n"
		     "standard uncertainty of each component over the wavelengths; brdf-recon dhr --help names them; the\n"
		     "instrument's systematic components are 0 there, brdf-recon dhr takes them as options).");
		return 0;
	}
	if (argc != 2)
		return usage_err("info", "one MODEL expected");
	struct acq_err err = { 0 };
	struct recon_model *m;
	if (recon_model_load(argv[1], &m, &err))
		return fail(&err);
	printf("directions=%zu\nwavelengths=%zu (%g..%g nm)\nkernel=%s\nshape=%.6g\ntransform=%s\nsmoothing=%.6g\n%s",
	       m->n, m->nwl, m->wl[0], m->wl[m->nwl - 1], rbf_kernel_name(m->kernel), m->shape,
	       recon_transform_name(m->transform), m->eta, m->meta);
	int ok = 1;
	if (budget) {
		size_t L = m->nwl;
		double th = 8, *buf = malloc((DB_N + 3) * L * sizeof *buf), *part[DB_N];
		struct recon_budget_opts bo = { 0 };
		ok = buf != NULL;
		if (!ok)
			acq_errf(&err, ACQ_E_NOMEM, "info: out of memory");
		for (int k = 0; ok && k < DB_N; k++)
			part[k] = buf + (size_t)k * L;
		if (ok && dhr_budget(m, 1, &th, 16, 1, &bo, buf + DB_N * L, buf + (DB_N + 1) * L, part, &err))
			ok = 0;
		progress_end();
		if (ok) {
			double *tmp = buf + (DB_N + 2) * L;
			printf("budget at theta_i=8 deg (standard uncertainty over %zu wavelengths: median, max):\n", L);
			for (int k = -2; k < DB_N; k++) {
				memcpy(tmp, k == -2 ? buf + DB_N * L : k == -1 ? buf + (DB_N + 1) * L : part[k], L * sizeof *tmp);
				qsort(tmp, L, sizeof *tmp, cmp_double);
				printf("  %-13s %.3g  %.3g\n", k == -2 ? "dhr" : k == -1 ? "sigma" : db_names[k], tmp[L / 2],
				       tmp[L - 1]);
			}
		}
		free(buf);
	}
	recon_model_free(m);
	return ok ? 0 : fail(&err);
}

/* Colour options shared by merl and render: --colour key=value (colour_opts_set keys). */
static int colour_arg(struct colour_opts *co, const char *arg, struct acq_err *err)
{
	char key[64];
	const char *eq = strchr(arg, '=');
	if (!eq || (size_t)(eq - arg) >= sizeof key)
		return acq_errf(err, ACQ_E_INVAL, "--colour needs key=value, got '%s'", arg);
	memcpy(key, arg, (size_t)(eq - arg));
	key[eq - arg] = '\0';
	return colour_opts_set(co, key, eq + 1, err);
}

/* Write the colour decisions and the reduction figures next to an output (path + ".colour.json"). */
static int write_decisions(const char *out, const struct colour_opts *co, const struct recon_rgb *R, int full,
			   double bin_nm, const struct render_opts *ro, const struct colour_stats *tone, const char *exr,
			   struct acq_err *err)
{
	char p[4096];
	snprintf(p, sizeof p, "%s.colour.json", out);
	struct out o;
	if (out_open(&o, p, err))
		return -1;
	size_t nc, r;
	recon_rgb_sizes(R, &nc, &r);
	fprintf(o.f, "{");
	int ok = 1;
	if (ro) { /* a rendered image: first what the image itself is */
		fprintf(o.f, "\"image\": ");
		ok = render_write_json(o.f, ro, tone, out, exr, err) == 0;
		fprintf(o.f, ", \"brdf_to_rgb\": ");
	} else {
		fprintf(o.f, "\"colour\": ");
	}
	ok = ok && colour_opts_write_json(o.f, co, NULL, err) == 0;
	fprintf(o.f, ", \"spectral_path\": \"%s\", \"bin_nm\": %g, \"channels\": %zu, \"rank\": %zu, "
		"\"reduction_max_rel_error\": %.3g, \"batch_precision\": \"%s\", \"single_precision_max_abs_error_ln_f\": %.3g}\n",
		full ? "full" : "reduced", bin_nm, nc, r, recon_rgb_reduction_error(R), recon_rgb_f32(R) ? "single" : "double",
		recon_rgb_f32_error(R));
	return out_close(&o, ok, err);
}

static const char merl_help[] =
	"usage: brdf-recon merl MODEL -o FILE.binary [--colour key=value]... [--threads N] [--bin-nm X]\n"
	"                        [--direct|--full-spectrum] [--double]\n"
	"Write the model as a MERL isotropic RGB table (90 x 90 x 180 cells, 34,992,012 bytes). Only cells whose\n"
	"two directions are above the horizon are evaluated (the others hold -1, \"no data\"). Spectra go through\n"
	"the colour chain (default: D65, CIE 1931 2 deg, Bradford, absolute sr^-1, clamp, keep, linear); the\n"
	"model is reduced to what RGB needs (visible channels averaged in --bin-nm bins, default 5 nm, error\n"
	"about bin^2/8 f''/f; low-rank weights), the error of the reduction measured and printed, and evaluated\n"
	"in batches. --direct: one callback per cell (same values, slower); --full-spectrum: every model\n"
	"channel per cell (reference path, slowest). The batches multiply in single precision when its error,\n"
	"measured at 2048 random pairs, is <= 1e-4 in ln f (a relative error in f); --double forces double.\n"
	"The decisions are written to FILE.binary.colour.json. Colour keys: illum gap adapt norm white max_albedo\n"
	"target exposure gamut range reinhard_white srgb_encode.\n";

static const char render_help[] =
	"usage: brdf-recon render MODEL -o OUT.png [--exr OUT.exr] [--size N] [--exposure X] [--spp N] [--seed S]\n"
	"                         [--env MAP.exr [--env-scale X]] [--sun-elevation DEG] [--sun-azimuth DEG] [--no-sun]\n"
	"                         [--lights] [--colour key=value]... [--threads N] [--bin-nm X] [--direct | --full-spectrum]\n"
	"Preview of the model on a sphere: tone-mapped sRGB PNG (sRGB/gAMA/cHRM chunks) and, with --exr, the linear\n"
	"HDR radiance as OpenEXR (float RGB, Rec. 709 chromaticities). Lighting: a smooth procedural sky with a sun\n"
	"(default; azimuth 0 = toward the camera, 90 = right), or a lat-long EXR environment map (--env; centre\n"
	"column looks away from the camera), sampled by importance (sky luminance, sun cone, GGX lobe, cosine;\n"
	"--spp samples per pixel, default 64). --lights: the old two lights + 64-direction gradient sky.\n"
	"OUT.png.colour.json records the image's colour decisions, its lighting and the BRDF-to-RGB chain.\n"
	"By default the model is tabulated as a MERL table in memory (batched) and rendered through its nearest-cell\n"
	"lookup; --direct evaluates the reduced model per ray, --full-spectrum every channel per ray.\n";

static int cmd_output(const char *cmd, int argc, char **argv)
{
	static const struct option lo[] = {
		{ "output", required_argument, 0, 'o' }, { "colour", required_argument, 0, 'c' },
		{ "threads", required_argument, 0, 't' }, { "full-spectrum", no_argument, 0, 'f' },
		{ "size", required_argument, 0, 's' }, { "exposure", required_argument, 0, 'e' },
		{ "direct", no_argument, 0, 'd' }, { "bin-nm", required_argument, 0, 'b' },
		{ "double", no_argument, 0, 'D' }, { "help", no_argument, 0, 'h' }, { "exr", required_argument, 0, 'X' },
		{ "spp", required_argument, 0, 'P' }, { "seed", required_argument, 0, 'S' },
		{ "env", required_argument, 0, 'E' }, { "env-scale", required_argument, 0, 'K' },
		{ "sun-elevation", required_argument, 0, 'A' }, { "sun-azimuth", required_argument, 0, 'Z' },
		{ "no-sun", no_argument, 0, 'N' }, { "lights", no_argument, 0, 'L' }, { 0, 0, 0, 0 } };
	int direct = 0, dbl = 0, no_sun = 0, old_lights = 0;
	const char *exr = NULL, *env = NULL;
	double env_scale = 1, sun_el = 40, sun_az = -36;
	uint64_t spp = 64, rseed = 1;
	double bin_nm = 5;
	int is_merl = !strcmp(cmd, "merl");
	const char *outp = NULL;
	struct acq_err err = { 0 };
	struct colour_opts co;
	colour_opts_brdf(&co);
	uint64_t threads = 2, size = 256;
	double exposure = 1;
	int full = 0, c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': outp = optarg; break;
		case 'c':
			if (colour_arg(&co, optarg, &err))
				return fail(&err);
			break;
		case 't':
			if (parse_u64(optarg, &threads) || threads < 1 || threads > 16)
				return usage_err(cmd, "--threads needs 1..16");
			break;
		case 'f': full = 1; break;
		case 'd': direct = 1; break;
		case 'D': dbl = 1; break;
		case 'b':
			if (parse_double(optarg, &bin_nm) || !(bin_nm >= 0.5 && bin_nm <= 50))
				return usage_err(cmd, "--bin-nm needs 0.5..50");
			break;
		case 's':
			if (is_merl || parse_u64(optarg, &size) || size < 8 || size > 4096)
				return usage_err(cmd, "--size needs 8..4096 (render only)");
			break;
		case 'e':
			if (is_merl || parse_double(optarg, &exposure) || !(exposure > 0))
				return usage_err(cmd, "--exposure needs a positive number (render only)");
			break;
		case 'h': fputs(is_merl ? merl_help : render_help, stdout); return 0;
		case 'X': exr = optarg; break;
		case 'E': env = optarg; break;
		case 'N': no_sun = 1; break;
		case 'L': old_lights = 1; break;
		case 'P': case 'S':
			if (parse_u64(optarg, c == 'P' ? &spp : &rseed) || (c == 'P' && (spp < 8 || spp > 4096)))
				return usage_err(cmd, "--spp needs 8..4096, --seed an unsigned integer");
			break;
		case 'K': case 'A': case 'Z': {
			double *t = c == 'K' ? &env_scale : c == 'A' ? &sun_el : &sun_az;
			if (parse_double(optarg, t) || (c == 'K' && !(env_scale > 0)) || (c == 'A' && !(sun_el > 0 && sun_el <= 90)))
				return usage_err(cmd, "--env-scale needs a positive number, --sun-elevation 0..90, --sun-azimuth degrees");
			break;
		}
		default: return usage_err(cmd, "bad option");
		}
	}
	if (optind != argc - 1 || !outp)
		return usage_err(cmd, "MODEL and -o OUT expected");
	if (is_merl && (exr || env || old_lights))
		return usage_err(cmd, "--exr, --env and --lights are render options");
	struct recon_model *m;
	if (recon_model_load(argv[optind], &m, &err))
		return fail(&err);
	struct sky *sky = NULL;
	struct sky_opts so;
	sky_opts_default(&so);
	double el = sun_el * M_PI / 180, az = sun_az * M_PI / 180;
	so.sun_dir[0] = cos(el) * sin(az);
	so.sun_dir[1] = sin(el);
	so.sun_dir[2] = cos(el) * cos(az);
	if (no_sun)
		so.sun_rgb[0] = so.sun_rgb[1] = so.sun_rgb[2] = 0;
	if (!is_merl && !old_lights && (env ? sky_envmap(env, env_scale, no_sun ? NULL : &so, &sky, &err)
					  : sky_procedural(&so, &sky, &err))) {
		recon_model_free(m);
		return fail(&err);
	}
	struct recon_rgb *R = NULL;
	int ok = recon_rgb_new(m, &co, bin_nm, &R, &err) == 0;
	if (ok) {
		size_t nc, r;
		if (dbl)
			recon_rgb_set_f32(R, 0);
		recon_rgb_sizes(R, &nc, &r);
		fprintf(stderr, "%s: %s path, %zu of %zu channels (%g nm bins), spectral rank %zu, reduction error %.2g "
			"(relative); batch GEMM in %s precision (single-precision error %.2g in ln f)\n", cmd,
			full ? "full-spectrum" : "reduced", nc, m->nwl, bin_nm, r, recon_rgb_reduction_error(R),
			recon_rgb_f32(R) ? "single" : "double", recon_rgb_f32_error(R));
	}
	/* default: the table is computed in batches (GEMMs) and both outputs read it: the MERL writer through
	 * the reference lookup (which returns each cell's own value at the cell centres it asks for), the
	 * renderer through the same nearest-cell lookup. --full-spectrum / --direct: per-direction callbacks. */
	struct merl_table table = { NULL };
	struct colour_stats st = { 0 };
	if (ok && !full && !direct) {
		ok = recon_rgb_merl_table_ex(R, &table, 0, (int)threads, &st, progress, NULL, &err) == 0;
		progress_end();
	}
	merl_rgb_fn fn = full ? recon_rgb_full_fn : direct ? recon_rgb_fn : merl_table_fn;
	void *ctx = (full || direct) ? (void *)R : (void *)&table;
	if (ok && is_merl) {
		struct merl_write_opts mo;
		merl_write_opts_default(&mo);
		mo.threads = (int)threads;
		/* the table is already in the writer's cells and units: written as it is (no per-cell lookup) */
		ok = (table.data ? merl_write_table(outp, &table, &err) : merl_write_ex(outp, fn, ctx, &mo, &err)) == 0;
	}
	struct render_opts ro;
	struct colour_stats tone = { 0 };
	render_opts_default(&ro);
	float *lin = NULL;
	if (ok && !is_merl) {
		ro.width = ro.height = (int)size;
		ro.exposure = exposure;
		ro.threads = (int)threads;
		ro.sky = sky;
		ro.spp = (int)spp;
		ro.seed = rseed;
		ro.lobe_alpha = m->trend != RECON_TREND_NONE && m->trend_alpha >= 0.01 && m->trend_alpha <= 1 ? m->trend_alpha : 0.3;
		lin = malloc((size_t)size * (size_t)size * 3 * sizeof *lin);
		if (!lin)
			ok = acq_errf(&err, ACQ_E_NOMEM, "render: out of memory") == 0;
		ok = ok && render_sphere(&ro, fn, ctx, outp, lin, &tone, &err) == 0;
		if (ok && exr) {
			char note[1024];
			snprintf(note, sizeof note, "brdf-recon render of %s: linear scene-referred radiance x exposure %g, "
				 "Rec. 709 primaries, D65; lighting: %s", argv[optind], exposure,
				 sky ? sky->desc : "two lights + gradient sky");
			ok = exrio_write_rgb(exr, lin, ro.width, ro.height, note, &err) == 0;
		}
	}
	merl_free(&table);
	if (ok)
		ok = write_decisions(outp, &co, R, full, bin_nm, is_merl ? NULL : &ro, &tone, exr, &err) == 0;
	free(lin);
	sky_free(sky);
	recon_rgb_free(R);
	recon_model_free(m);
	if (!ok)
		return fail(&err);
	fprintf(stderr, "%s: wrote %s\n", cmd, outp);
	return 0;
}

static const char main_help[] =
	"usage: brdf-recon COMMAND [options]   (brdf-recon COMMAND --help for each)\n"
	"Reconstruct a complete spectral BRDF from sparse samples with radial basis functions on the product of\n"
	"two hemispheres: non-negative, reciprocal and energy conserving by construction.\n"
	"commands:\n"
	"  fit     SAMPLES.csv -o MODEL     fit a model (or --db FILE --sweep ID)\n"
	"  eval    MODEL QUERIES.csv        evaluate at given directions (CSV)\n"
	"  dhr     MODEL                    DHR(theta_i, lambda) with uncertainty; compare with a reference\n"
	"  check   MODEL                    verify non-negativity, reciprocity, energy conservation\n"
	"  info    MODEL                    print parameters and metadata\n"
	"  merl    MODEL -o FILE.binary     MERL table (RGB)\n"
	"  render  MODEL -o OUT.png         preview render of a sphere\n"
	"  rgl     MODEL -o FILE.bsdf       spectral RGL tabulated BRDF (Mitsuba 3, pbrt-v4)\n"
	"  slices  MODEL -o OUT.png         in-plane slices and polar plots with samples and uncertainty\n";

int main(int argc, char **argv)
{
	if (argc < 2) {
		fputs(main_help, stderr);
		return 2;
	}
	const char *cmd = argv[1];
	if (!strcmp(cmd, "--help") || !strcmp(cmd, "-h") || !strcmp(cmd, "help")) {
		fputs(main_help, stdout);
		return 0;
	}
	if (!strcmp(cmd, "--version")) {
		printf("brdf-recon %s\n", ACQ_VERSION);
		return 0;
	}
	argc--;
	argv++;
	if (!strcmp(cmd, "fit"))
		return cmd_fit(argc, argv);
	if (!strcmp(cmd, "eval"))
		return cmd_eval(argc, argv);
	if (!strcmp(cmd, "dhr"))
		return cmd_dhr(argc, argv);
	if (!strcmp(cmd, "check"))
		return cmd_check(argc, argv);
	if (!strcmp(cmd, "info"))
		return cmd_info(argc, argv);
	if (!strcmp(cmd, "rgl"))
		return cmd_rgl(argc, argv);
	if (!strcmp(cmd, "slices"))
		return cmd_slices(argc, argv);
	if (!strcmp(cmd, "merl") || !strcmp(cmd, "render"))
		return cmd_output(cmd, argc, argv);
	fprintf(stderr, "%s: unknown command '%s'\n%s", prog, cmd, main_help);
	return 2;
}
