/* brdf-recon dhr: directional-hemispherical reflectance with its uncertainty budget, compared with a
 * reference. */
#include <getopt.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon/brdf_recon/cli.h"
#include "recon/brdf_recon/dhr_budget.h"
#include "recon/budget.h"
#include "recon/csvio.h"
#include "recon/plot.h"
#include "recon/recon.h"

/* ---- dhr ---- */
static const char dhr_help[] =
	"usage: brdf-recon dhr MODEL [--theta-i 8,30,60] [--draws N] [--seed S] [-o OUT.csv] [budget options]\n"
	"                      [--reference REF.csv [--reference-theta 8] [--reference-corr U[,L]] [--z-out Z.csv]]\n"
	"                      [--plot OUT.png]\n"
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
	"  sigma_wlcal   wavelength calibration, |dDHR/dlambda| x its uncertainty;  sigma_nonlin  nonlinearity;\n"
	"  sigma_refnoise  the white reference's own measurement noise, |DHR| x u_rel(lambda) (--ref-noise): one\n"
	"                reference spectrum serves every sample of a sweep, so this part does not average away over\n"
	"                the samples as sigma_noise does (common to all incidences, independent across wavelengths).\n"
	"  sigma = sqrt(max(noise, model)^2 + quad^2 + misfit^2 + res^2 + cert^2 + drift^2 + wlcal^2 + nonlin^2\n"
	"               + refnoise^2).\n"
	"Budget options (the sample file and database carry none of these: each is 0 unless given):\n"
	"  --cert CERT.csv       the white standard's certificate, columns wavelength_nm,rho,u\n"
	"  --cert-rel X          or its relative standard uncertainty at every wavelength\n"
	"  --drift-rel X         relative standard uncertainty of the source between reference and samples\n"
	"  --wl-cal-nm X         standard uncertainty of the wavelength calibration (nm)\n"
	"  --nonlin-rel X        relative residual of the nonlinearity correction\n"
	"  --ref-noise FILE.csv  the white reference's relative standard uncertainty per wavelength, columns\n"
	"                        wavelength_nm,u_rel (linear in lambda, the nearest end outside); acquisitiond writes\n"
	"                        it as reference-noise.csv beside a sweep's samples.csv\n"
	"  --reference REF.csv   compare with a measured DHR (columns wavelength_nm,dhr,sigma, e.g. a\n"
	"                        spectrophotometer at 8 degrees: acq-sim truth MATERIAL --spectrophotometer) at\n"
	"                        --reference-theta (default 8, must be among --theta-i): prints the agreement (share\n"
	"                        of wavelengths with |z| < 2, z with both uncertainties) and chi2/n with the\n"
	"                        correlated components as one common factor; per-wavelength z to --z-out (or stderr)\n"
	"  --reference-corr U[,L]  the reference's stated sigma holds a calibration part of relative standard\n"
	"                        uncertainty U correlated across wavelengths (squared exponential, length L nm,\n"
	"                        default 150: acq-sim's spectrophotometer is 0.003,150): chi2 with the full\n"
	"                        covariance and P(chi2) judge the agreement\n"
	"  --plot OUT.png        the curves with +-2 sigma bands, the reference band and a panel of the residual in\n"
	"                        units of sigma\n";

/* The model's curve at the reference wavelengths (linear in λ, the model's grid): value, total σ (with the linear
 * interpolation's own error, u(1 − u)/2 × the curve's second difference at the nearer node, in quadrature),
 * correlated σ; the lower node j and weight u; the interpolation error alone in *eo. */
static void at_reference(const struct recon_model *m, const double *y, const double *s, const double *c, double wl,
			 double *yo, double *so, double *co, size_t *jo, double *uo, double *eo)
{
	size_t L = m->nwl, j = 0;
	while (j + 1 < L && m->wl[j + 1] < wl)
		j++;
	size_t j2 = j + 1 < L ? j + 1 : j;
	double u = j2 > j ? (wl - m->wl[j]) / (m->wl[j2] - m->wl[j]) : 0;
	*yo = (1 - u) * y[j] + u * y[j2];
	*so = (1 - u) * s[j] + u * s[j2];
	*co = (1 - u) * c[j] + u * c[j2];
	size_t k = u < 0.5 ? j : j2; /* the curve's second difference at the nearer node (interior) */
	k = k < 1 ? 1 : k + 1 >= L ? (L > 2 ? L - 2 : k) : k;
	double d2 = L >= 3 && k >= 1 && k + 1 < L ? y[k - 1] - 2 * y[k] + y[k + 1] : 0.0;
	*eo = 0.5 * u * (1 - u) * fabs(d2);
	*so = hypot(*so, *eo);
	*jo = j;
	*uo = u;
}

/* dhr's command line. */
struct dhr_args {
	const char *model, *outp, *refp, *zout, *plot, *certp, *refnp;
	double th[64], ref_th, ref_u, ref_len;
	size_t nth;
	uint64_t draws, seed;
	struct recon_budget_opts bo;
};

/* --theta-i's list into a->th; 0, or a usage error's status. */
static int dhr_parse_theta(const char *arg, struct dhr_args *a)
{
	a->nth = 0;
	char *save = NULL, *dup = strdup(arg);
	for (char *tok = strtok_r(dup, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
		if (a->nth == 64 || cli_parse_double(tok, &a->th[a->nth]) || a->th[a->nth] < 0 || a->th[a->nth] > 90) {
			free(dup);
			return cli_usage_err("dhr", "--theta-i needs up to 64 angles in [0, 90]");
		}
		a->nth++;
	}
	free(dup);
	if (!a->nth)
		return cli_usage_err("dhr", "--theta-i is empty");
	return 0;
}

/* A budget option's number into *v: 0, or -1 unless it is a number in [0, hi). */
static int dhr_parse_in(const char *arg, double *v, double hi)
{
	return cli_parse_double(arg, v) || !(*v >= 0 && *v < hi) ? -1 : 0;
}

/* The options and the model's path into a (defaults first); -1 to go on, or the exit status (help: 0, a usage
 * error: 2). */
static int dhr_parse(int argc, char **argv, struct dhr_args *a)
{
	static const struct option lo[] = {
		{ "output", required_argument, 0, 'o' }, { "theta-i", required_argument, 0, 't' },
		{ "draws", required_argument, 0, 'n' }, { "seed", required_argument, 0, 's' },
		{ "reference", required_argument, 0, 'r' }, { "reference-theta", required_argument, 0, 'R' },
		{ "z-out", required_argument, 0, 'z' }, { "plot", required_argument, 0, 'p' },
		{ "cert", required_argument, 0, 'C' }, { "cert-rel", required_argument, 0, 'c' },
		{ "drift-rel", required_argument, 0, 'd' }, { "wl-cal-nm", required_argument, 0, 'w' },
		{ "nonlin-rel", required_argument, 0, 'N' }, { "reference-corr", required_argument, 0, 'K' },
		{ "ref-noise", required_argument, 0, 'F' },
		{ "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	*a = (struct dhr_args){ .th = { 8, 30, 60 }, .nth = 3, .ref_th = 8, .ref_u = 0, .ref_len = 150, .draws = 64,
				.seed = 1 };
	struct recon_budget_opts *bo = &a->bo;
	int c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': a->outp = optarg; break;
		case 't':
			if (dhr_parse_theta(optarg, a))
				return 2;
			break;
		case 'n':
			if (cli_parse_u64(optarg, &a->draws) || a->draws > 100000)
				return cli_usage_err("dhr", "--draws needs 0..100000");
			break;
		case 's':
			if (cli_parse_u64(optarg, &a->seed))
				return cli_usage_err("dhr", "--seed needs an unsigned integer");
			break;
		case 'r': a->refp = optarg; break;
		case 'R':
			if (cli_parse_double(optarg, &a->ref_th))
				return cli_usage_err("dhr", "--reference-theta needs a number");
			break;
		case 'z': a->zout = optarg; break;
		case 'p': a->plot = optarg; break;
		case 'C': a->certp = optarg; break;
		case 'F': a->refnp = optarg; break;
		case 'c':
			if (dhr_parse_in(optarg, &bo->cert_rel, 1))
				return cli_usage_err("dhr", "--cert-rel needs a number in [0, 1)");
			break;
		case 'd':
			if (dhr_parse_in(optarg, &bo->drift_rel, 1))
				return cli_usage_err("dhr", "--drift-rel needs a number in [0, 1)");
			break;
		case 'w':
			if (dhr_parse_in(optarg, &bo->wl_cal_nm, 100))
				return cli_usage_err("dhr", "--wl-cal-nm needs a number in [0, 100)");
			break;
		case 'N':
			if (dhr_parse_in(optarg, &bo->nonlin_rel, 1))
				return cli_usage_err("dhr", "--nonlin-rel needs a number in [0, 1)");
			break;
		case 'K': {
			char *comma = strchr(optarg, ',');
			if (comma)
				*comma = 0;
			if (cli_parse_double(optarg, &a->ref_u) || !(a->ref_u >= 0 && a->ref_u < 1) ||
			    (comma && (cli_parse_double(comma + 1, &a->ref_len) || !(a->ref_len > 0 && a->ref_len < 1e6))))
				return cli_usage_err("dhr", "--reference-corr needs U[,LENGTH_NM]: U in [0, 1), length > 0 nm");
			break;
		}
		case 'h': fputs(dhr_help, stdout); return 0;
		default: return cli_usage_err("dhr", "bad option");
		}
	}
	if (optind != argc - 1)
		return cli_usage_err("dhr", "one MODEL expected");
	a->model = argv[optind];
	return -1;
}

/* The certificate file (wavelength_nm,rho,u rows) into bo as columns, in *cert (caller frees); 0 or -1 with err. */
static int dhr_cert_load(const char *certp, struct recon_budget_opts *bo, double **cert, struct acq_err *err)
{
	static const char *const cn[3] = { "wavelength_nm", "rho", "u" };
	size_t n = 0;
	if (csvio_read_columns_cm(certp, cn, 3, &n, cert, err))
		return -1;
	bo->cert_wl = *cert;
	bo->cert_rho = *cert + n;
	bo->cert_u = *cert + 2 * n;
	bo->ncert = n;
	return 0;
}

/* The reference-noise file (wavelength_nm,u_rel rows: wavelengths increasing, u_rel in [0, 1)) into bo as columns,
 * in *refn (caller frees); 0 or -1 with err naming the file and the data row. */
static int dhr_refn_load(const char *path, struct recon_budget_opts *bo, double **refn, struct acq_err *err)
{
	static const char *const cn[2] = { "wavelength_nm", "u_rel" };
	size_t n = 0;
	double *cw = NULL;
	if (csvio_read_columns_cm(path, cn, 2, &n, &cw, err))
		return -1;
	for (size_t i = 0; i < n; i++)
		if (!(cw[n + i] >= 0 && cw[n + i] < 1) || (i && !(cw[i] > cw[i - 1]))) {
			acq_errf(err, ACQ_E_INVAL, "dhr: --ref-noise %s: data row %zu (%g nm, u_rel %g): wavelengths must "
				 "increase and u_rel be in [0, 1)", path, i + 1, cw[i], cw[n + i]);
			free(cw);
			return -1;
		}
	*refn = cw;
	bo->refn_wl = cw;
	bo->refn_u = cw + n;
	bo->nrefn = n;
	return 0;
}

/* The CSV: theta_i, wavelength_nm, dhr, sigma and the budget's columns, to outp (stdout when NULL); 0 or -1 with
 * err (a non-finite value, or the output failing). */
static int dhr_write(const char *outp, const struct recon_model *m, const struct dhr_args *a, const double *dhr,
		     const double *sig, double *const *part, struct acq_err *err)
{
	size_t L = m->nwl;
	struct cli_out o;
	if (cli_out_open(&o, outp, err))
		return -1;
	int ok = 1;
	fputs("theta_i,wavelength_nm,dhr,sigma", o.f);
	for (int k = 0; k < DB_N; k++)
		fprintf(o.f, ",%s", dhr_budget_names[k]);
	fputc('\n', o.f);
	char b[64];
	for (size_t t = 0; ok && t < a->nth; t++)
		for (size_t l = 0; ok && l < L; l++) {
			size_t i = t * L + l;
			fprintf(o.f, "%.10g,%.10g", a->th[t], m->wl[l]);
			for (int k = -2; ok && k < DB_N; k++) {
				double v = k == -2 ? dhr[i] : k == -1 ? sig[i] : part[k][i];
				if (csvio_fmt(b, sizeof b, v)) {
					acq_errf(err, ACQ_E_NUMERIC, "dhr: non-finite value");
					ok = 0;
				} else {
					fprintf(o.f, ",%s", b);
				}
			}
			fputc('\n', o.f);
		}
	if (cli_out_close(&o, ok, err))
		ok = 0;
	return ok ? 0 : -1;
}

/* The reference file for --reference: its columns wavelength_nm, dhr, sigma (*nref values each, one after the other)
 * in *ref, and the index of --reference-theta among --theta-i in *tref; 0 or -1 with err. */
static int dhr_ref_read(const struct dhr_args *a, size_t *tref, double **ref, size_t *nref, struct acq_err *err)
{
	static const char *const names[3] = { "wavelength_nm", "dhr", "sigma" };
	for (*tref = 0; *tref < a->nth; (*tref)++)
		if (fabs(a->th[*tref] - a->ref_th) < 1e-9)
			break;
	if (*tref == a->nth)
		return acq_errf(err, ACQ_E_INVAL, "dhr: --reference-theta %g is not among --theta-i", a->ref_th);
	return csvio_read_columns_cm(a->refp, names, 3, nref, ref, err) ? -1 : 0;
}

/* The residual (model − reference) / σ per compared wavelength, kept for the plot. */
struct dhr_resid {
	double *z, *wl;
	size_t n;
};

/* The model at incidence tref against the reference's columns (dhr_ref_read): per-wavelength z to --z-out (or stderr), the agreement and
 * χ² lines on stderr; the residual into *res when a plot is asked for. 0 or -1 with err. */
static int dhr_compare(const struct dhr_args *a, const struct recon_model *m, const double *dhr, const double *sig,
		       const double *corr, size_t tref, const double *ref, size_t nref, struct dhr_resid *res,
		       struct acq_err *err)
{
	size_t L = m->nwl;
	int ok = 1;
	/* the reference's wavelengths inside the model's range */
	double *cmp = malloc(10 * (nref ? nref : 1) * sizeof *cmp), *nsig = malloc(L * sizeof *nsig);
	size_t *ji = malloc((nref ? nref : 1) * sizeof *ji);
	if (!cmp || !nsig || !ji) {
		acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory");
		ok = 0;
	}
	size_t nc = 0;
	double *cw = cmp, *md = cmp + nref, *ms = cmp + 2 * nref, *mc = cmp + 3 * nref, *rv = cmp + 4 * nref,
	       *rs = cmp + 5 * nref, *z = cmp + 6 * nref, *ui = cmp + 8 * nref, *ei = cmp + 9 * nref;
	for (size_t i = 0; ok && i < nref; i++) {
		double wl = ref[i], rdhr = ref[nref + i], rsig = ref[2 * nref + i];
		if (!(wl >= m->wl[0] && wl <= m->wl[L - 1]) || !isfinite(rdhr) || !(rsig >= 0))
			continue;
		cw[nc] = wl;
		at_reference(m, dhr + tref * L, sig + tref * L, corr + tref * L, wl, &md[nc], &ms[nc], &mc[nc], &ji[nc],
			     &ui[nc], &ei[nc]);
		rv[nc] = rdhr;
		rs[nc] = rsig;
		nc++;
	}
	for (size_t l = 0; ok && l < L; l++) { /* the model's independent σ at its own wavelengths */
		double s = sig[tref * L + l], cc = fmin(corr[tref * L + l], s);
		nsig[l] = sqrt(fmax(0.0, s * s - cc * cc));
	}
	struct recon_ref_interp ip = { ji, ui, nsig, ei, L };
	struct recon_agreement ag;
	if (ok && recon_agreement_ref(nc, cw, md, ms, mc, rv, rs, a->ref_u, a->ref_len, &ip, z, &ag, err))
		ok = 0;
	FILE *zf = stderr;
	struct cli_out zo;
	if (ok && a->zout) {
		if (cli_out_open(&zo, a->zout, err))
			ok = 0;
		else
			zf = zo.f;
	}
	if (ok) {
		fprintf(zf, "wavelength_nm,dhr_model,sigma_model,dhr_ref,sigma_ref,z\n");
		for (size_t i = 0; i < nc; i++)
			fprintf(zf, "%.10g,%.10g,%.10g,%.10g,%.10g,%.6g\n", cw[i], md[i], ms[i], rv[i], rs[i], z[i]);
	}
	if (ok && a->zout && cli_out_close(&zo, ok, err))
		ok = 0;
	if (ok)
		fprintf(stderr, "reference %s at theta_i=%g: %zu wavelengths compared, agreement %.1f%% within |z| <= 2 "
			"(z with both uncertainties), RMS z %.3g, max |z| %.3g at %g nm, chi2/n %.3g with the "
			"correlated components (certificate, drift%s) as one common factor\n", a->refp, a->ref_th, ag.n,
			ag.n ? 100.0 * (double)ag.within2 / (double)ag.n : 0.0, ag.rms_z, ag.max_z, ag.max_z_wl,
			ag.chi2_n, ag.ref_corr ? "; the reference's calibration correlated over wavelengths" : "");
	if (ok)
		fprintf(stderr, "reference %s: chi2 %.4g for %zu wavelengths, P(chi2 >= that | agreement) = %.3g: %s at "
			"the 1%% level%s\n", a->refp, ag.chi2_n * (double)ag.n, ag.n, ag.chi2_p,
			ag.chi2_p >= 0.01 ? "consistent" : "NOT consistent",
			ag.ref_corr ? "" : " (no --reference-corr: the reference's sigma taken as independent across "
					  "wavelengths; a calibration error correlated over wavelengths then moves many "
					  "z together and the share within |z| <= 2 varies from one instrument to the next)");
	if (ok && a->plot) { /* keep the residual for the plot */
		res->z = malloc((nc ? nc : 1) * sizeof *res->z);
		res->wl = malloc((nc ? nc : 1) * sizeof *res->wl);
		if (res->z && res->wl) {
			memcpy(res->z, z, nc * sizeof *res->z);
			memcpy(res->wl, cw, nc * sizeof *res->wl);
			res->n = nc;
		}
	}
	free(cmp);
	free(nsig);
	free(ji);
	return ok ? 0 : -1;
}

/* --plot: the curves with their bands, the reference (its columns from dhr_ref_read, nref rows; NULL: none) and
 * the residual panel (when kept); 0 or -1 with err. */
static int dhr_plot(const struct dhr_args *a, const struct recon_model *m, const double *dhr, const double *sig,
		    const double *ref, size_t nref, const struct dhr_resid *res, struct acq_err *err)
{
	size_t L = m->nwl;
	struct plot_curve curves[64], refc, resc;
	char labels[64][32];
	for (size_t t = 0; t < a->nth; t++) {
		snprintf(labels[t], sizeof labels[t], "\u03b8i = %g\u00b0", a->th[t]);
		curves[t] = (struct plot_curve){ labels[t], m->wl, dhr + t * L, sig + t * L, L };
	}
	if (ref)
		refc = (struct plot_curve){ "reference", ref, ref + nref, ref + 2 * nref, nref };
	struct plot_dhr_opts po;
	plot_dhr_opts_default(&po);
	po.title = "Directional-hemispherical reflectance (bands: \u00b12\u03c3)";
	if (res->z && res->wl) {
		resc = (struct plot_curve){ "(model \u2212 ref) / \u03c3", res->wl, res->z, NULL, res->n };
		po.residual = &resc;
		po.height = 720;
	}
	return plot_dhr_png(a->plot, curves, a->nth, ref ? &refc : NULL, &po, NULL, err) ? -1 : 0;
}

int cmd_dhr(int argc, char **argv)
{
	struct dhr_args a;
	int rc = dhr_parse(argc, argv, &a);
	if (rc >= 0)
		return rc;
	struct acq_err err = { 0 };
	double *cert = NULL, *refn = NULL;
	if (a.certp && dhr_cert_load(a.certp, &a.bo, &cert, &err))
		return cli_fail(&err);
	if (a.refnp && dhr_refn_load(a.refnp, &a.bo, &refn, &err)) {
		free(cert);
		return cli_fail(&err);
	}
	struct recon_model *m;
	if (recon_model_load(a.model, &m, &err)) {
		free(cert);
		free(refn);
		return cli_fail(&err);
	}
	size_t L = m->nwl, NL = a.nth * L;
	double *dhr = malloc(NL * sizeof *dhr), *sig = malloc(NL * sizeof *sig), *pbuf = malloc(DB_N * NL * sizeof *pbuf);
	double *part[DB_N], *ref = NULL, *corr = malloc(NL * sizeof *corr);
	size_t nref = 0;
	int ok = dhr && sig && pbuf && corr;
	if (!ok)
		acq_errf(&err, ACQ_E_NOMEM, "dhr: out of memory");
	for (int k = 0; k < DB_N; k++)
		part[k] = pbuf ? pbuf + (size_t)k * NL : NULL;
	if (ok && dhr_budget(m, a.nth, a.th, a.draws, a.seed, &a.bo, dhr, sig, part, &err))
		ok = 0;
	cli_progress_end();
	for (size_t i = 0; ok && i < NL; i++) /* the correlated part: one common factor (certificate, drift) */
		corr[i] = hypot(part[DB_CERT][i], part[DB_DRIFT][i]);
	if (ok && dhr_write(a.outp, m, &a, dhr, sig, part, &err))
		ok = 0;
	if (ok && !a.certp && a.bo.cert_rel == 0 && a.bo.drift_rel == 0 && a.bo.wl_cal_nm == 0 && a.bo.nonlin_rel == 0 &&
	    !a.refnp)
		fprintf(stderr, "dhr: no --cert/--cert-rel, --drift-rel, --wl-cal-nm, --nonlin-rel, --ref-noise given: those "
			"components are 0 (the samples carry no input for them)\n");
	size_t tref = a.nth;
	struct dhr_resid res = { 0 };
	if (ok && a.refp && dhr_ref_read(&a, &tref, &ref, &nref, &err))
		ok = 0;
	if (ok && ref && dhr_compare(&a, m, dhr, sig, corr, tref, ref, nref, &res, &err))
		ok = 0;
	if (ok && a.plot && dhr_plot(&a, m, dhr, sig, ref, nref, &res, &err))
		ok = 0;
	free(res.z);
	free(res.wl);
	free(ref);
	free(cert);
	free(refn);
	free(dhr);
	free(sig);
	free(pbuf);
	free(corr);
	recon_model_free(m);
	return ok ? 0 : cli_fail(&err);
}
