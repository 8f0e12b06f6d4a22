/* brdf-recon fit: fit a reconstruction to samples (CSV or the daemon's database). */
#include <getopt.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "recon/brdf_recon/cli.h"
#include "recon/csvio.h"
#include "recon/recon.h"

/* ---- fit ---- */
static const char fit_help[] =
	"usage: brdf-recon fit SAMPLES.csv -o MODEL [options]\n"
	"       brdf-recon fit --db FILE --sweep ID -o MODEL [options]\n"
	"Fit a reconstruction to sparse spectral BRDF samples (CSV interchange format, design.md).\n"
	"  -o, --output MODEL      model file to write (required)\n"
	"  --kernel K              wendland (default, positive definite), exp, gauss, paper (Gaussian of d_Rec,\n"
	"                          the paper's literal construction, not guaranteed positive definite)\n"
	"  --transform T           log (default: interpolate ln(f+eps)) or sqrt\n"
	"  --trend T               auto (default), ggx, phong, sheen, rough, coat or none. ggx: interpolate relative to\n"
	"                          a fitted Lambertian + GGX lobe + coated diffuse, so a lobe narrower than the\n"
	"                          sampling keeps a microfacet shape; phong: a normalised lobe about the mirror;\n"
	"                          sheen: Charlie sheen + Oren-Nayar; rough: Oren-Nayar + Lommel-Seeliger +\n"
	"                          retro-reflection peak; coat: a narrow GGX coat lobe over a broad GGX base\n"
	"                          lobe (two roughnesses); none: the plain interpolant (the only choice with\n"
	"                          sqrt); auto: leave-one-out over all, a kind other than ggx (or none) kept\n"
	"                          only when it is better beyond the score's uncertainty (log transform)\n"
	"  --shape X|auto          kernel shape parameter (default auto: Rippa leave-one-out over a grid)\n"
	"  --smoothing X|auto|sigma  eta in (K + eta*diag(r)) w = g, r from the uncertainties: a number, auto\n"
	"                          (default: leave-one-out), or sigma (Lambda = the transformed variances over\n"
	"                          the prior variance of the data; needs sigma_<nm> columns)\n"
	"  --max-cond X            largest accepted condition number (default 1e12)\n"
	"  --db FILE --sweep ID    read a sweep from the daemon's database instead of a CSV file\n"
	"  --warm PREV.model       warm start from a previous model of the same material (an adaptive sweep's last\n"
	"                          batch): its kernel, transform and trend kind replace the trend family's leave-one-\n"
	"                          out choice; shape and smoothing are searched as in a cold fit (options given\n"
	"                          explicitly win), so the model equals a cold fit's whenever that keeps the trend\n"
	"                          kind; if the result's leave-one-out\n"
	"                          RMS exceeds 1.25x PREV's + 0.01 the settings no longer fit the data and the fit is\n"
	"                          redone with the full search (said on stderr)\n";

/* The warm start's acceptance: the warm fit's leave-one-out RMS (transformed units) at most this factor of the
 * previous model's, plus an absolute slack (a previous RMS near 0 on a handful of samples). */
#define WARM_LOO_FACTOR 1.25
#define WARM_LOO_SLACK 0.01

int cmd_fit(int argc, char **argv)
{
	static const struct option lo[] = {
		{ "output", required_argument, 0, 'o' }, { "kernel", required_argument, 0, 'k' },
		{ "transform", required_argument, 0, 't' }, { "shape", required_argument, 0, 's' },
		{ "smoothing", required_argument, 0, 'm' }, { "max-cond", required_argument, 0, 'c' },
		{ "db", required_argument, 0, 'd' }, { "sweep", required_argument, 0, 'w' },
		{ "trend", required_argument, 0, 'r' }, { "warm", required_argument, 0, 'W' },
		{ "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	o.progress = cli_progress;
	const char *outp = NULL, *db = NULL, *warm = NULL;
	uint64_t sweep = 0;
	int have_sweep = 0, c, set_kernel = 0, set_transform = 0, set_trend = 0;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': outp = optarg; break;
		case 'k':
			if ((o.kernel = rbf_kernel_from_name(optarg)) < 0)
				return cli_usage_err("fit", "unknown kernel");
			set_kernel = 1;
			break;
		case 't':
			if ((o.transform = recon_transform_from_name(optarg)) < 0)
				return cli_usage_err("fit", "unknown transform");
			set_transform = 1;
			break;
		case 'r':
			if (strcmp(optarg, "auto") && (o.trend = trend_from_name(optarg)) < 0)
				return cli_usage_err("fit", "unknown trend (auto, ggx, phong, sheen, rough, coat or none)");
			if (!strcmp(optarg, "auto"))
				o.trend = -1;
			set_trend = 1;
			break;
		case 's':
			if (!strcmp(optarg, "auto"))
				o.shape = 0;
			else if (cli_parse_double(optarg, &o.shape) || !(o.shape > 0))
				return cli_usage_err("fit", "--shape needs a positive number or auto");
			break;
		case 'm':
			if (!strcmp(optarg, "auto"))
				o.smoothing = -1;
			else if (!strcmp(optarg, "sigma"))
				o.smoothing = RECON_SMOOTHING_SIGMA;
			else if (cli_parse_double(optarg, &o.smoothing) || o.smoothing < 0)
				return cli_usage_err("fit", "--smoothing needs a number >= 0, auto or sigma");
			break;
		case 'c':
			if (cli_parse_double(optarg, &o.max_cond) || !(o.max_cond >= 1))
				return cli_usage_err("fit", "--max-cond needs a number >= 1");
			break;
		case 'd': db = optarg; break;
		case 'W': warm = optarg; break;
		case 'w':
			if (cli_parse_u64(optarg, &sweep))
				return cli_usage_err("fit", "--sweep needs an id");
			have_sweep = 1;
			break;
		case 'h': fputs(fit_help, stdout); return 0;
		default: return cli_usage_err("fit", "bad option");
		}
	}
	if (!outp)
		return cli_usage_err("fit", "-o MODEL is required");
	struct acq_err err = { 0 };
	struct recon_samples s;
	if (db) {
		if (!have_sweep || optind != argc)
			return cli_usage_err("fit", "--db needs --sweep ID and no CSV file");
		if (recon_load_db(db, (long long)sweep, &s, &err))
			return cli_fail(&err);
		o.source = db;
	} else {
		if (optind != argc - 1)
			return cli_usage_err("fit", "one SAMPLES.csv expected");
		o.source = argv[optind];
		if (csvio_read_samples(argv[optind], &s, &err))
			return cli_fail(&err);
	}
	struct recon_fit_opts cold = o;
	struct recon_model *m = NULL, *prev = NULL;
	if (warm) { /* the previous model's settings instead of the search, unless given explicitly */
		if (recon_model_load(warm, &prev, &err)) {
			csvio_samples_free(&s);
			return cli_fail(&err);
		}
		if ((set_kernel && o.kernel != prev->kernel) || (set_transform && o.transform != prev->transform)) {
			recon_model_free(prev);
			csvio_samples_free(&s);
			return cli_usage_err("fit", "--warm: the previous model has another kernel or transform than the one given");
		}
		o.kernel = prev->kernel;
		o.transform = prev->transform;
		/* the shape and the smoothing are searched again (only the trend family's choice is kept): their leave-
		 * one-out optimum moves with the data (a batch more: a smaller η, another shape), and kept from PREV they
		 * gave σ ×0.6–5.1 of a cold fit's (σ_misfit of unhonoured samples, σ_model of another kernel width); with
		 * them searched the warm model IS the cold one whenever the cold search keeps the trend kind */
		if (!set_trend)
			o.trend = prev->trend;
	}
	int rc = recon_fit(&s, &o, &m, &err);
	if (prev) {
		double lim = WARM_LOO_FACTOR * prev->loo_rms + WARM_LOO_SLACK;
		if (rc || m->loo_rms > lim) {
			cli_progress_end();
			if (rc)
				fprintf(stderr, "fit: warm start from %s failed (%s): full search\n", warm, err.msg);
			else
				fprintf(stderr, "fit: warm start from %s not leave-one-out competitive (RMS %.4g > %.4g = %.2f x "
					"previous %.4g + %.2g): full search\n", warm, m->loo_rms, lim, WARM_LOO_FACTOR,
					prev->loo_rms, WARM_LOO_SLACK);
			recon_model_free(m);
			m = NULL;
			err.msg[0] = '\0';
			rc = recon_fit(&s, &cold, &m, &err);
		} else {
			cli_progress_end();
			fprintf(stderr, "fit: warm start from %s: its kernel and trend kind kept, shape and smoothing searched "
				"(leave-one-out RMS %.4g, previous %.4g, limit %.4g)\n", warm, m->loo_rms, prev->loo_rms, lim);
		}
		recon_model_free(prev);
	}
	csvio_samples_free(&s);
	if (rc)
		return cli_fail(&err);
	cli_progress_end();
	if (recon_model_save(m, outp, &err)) {
		recon_model_free(m);
		return cli_fail(&err);
	}
	char a2[32] = ""; /* a two-lobe trend's second (base) roughness */
	if (trend_two_lobes(m->trend))
		snprintf(a2, sizeof a2, ", base %.3g", m->trend_alpha2);
	fprintf(stderr, "fit: %zu directions, %zu wavelengths, kernel %s shape %.3g, transform %s, trend %s (alpha %.3g%s), "
		"smoothing %.3g, leave-one-out RMS %.4g, rcond %.3g -> %s\n", m->n, m->nwl, rbf_kernel_name(m->kernel),
		m->shape, recon_transform_name(m->transform), trend_name(m->trend), m->trend_alpha, a2, m->eta, m->loo_rms,
		m->rcond, outp);
	for (const char *p = strstr(m->meta, "warning="); p; p = strstr(p + 1, "\nwarning=")) {
		const char *b = strchr(p, '=') + 1, *e = strchr(b, '\n');
		fprintf(stderr, "fit: warning: %.*s\n", e ? (int)(e - b) : (int)strlen(b), b);
	}
	recon_model_free(m);
	return 0;
}

