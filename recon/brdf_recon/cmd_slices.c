/* brdf-recon slices: in-plane slices and polar plots of a model with its samples (recon/slices.c). */
#include <getopt.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon/brdf_recon/cli.h"
#include "recon/csvio.h"
#include "recon/recon.h"
#include "recon/slices.h"

static const char slices_help[] =
	"usage: brdf-recon slices MODEL -o OUT.png [--samples SAMPLES.csv | --db FILE --sweep ID]\n"
	"                         [--wavelength NM | --band LO:HI] [--theta-i A,B,...] [--polar OUT.png]\n"
	"                         [--csv OUT.csv] [--sigma-k K] [--phi-tol DEG] [--size WxH]\n"
	"In-plane BRDF slices (phi_o - phi_i = 0 and 180 deg; theta_o signed, + on the forward side) at each\n"
	"measured incidence, log scale: the model with its pointwise uncertainty band (Gaussian-process posterior\n"
	"of the reconstruction, +-K sigma, default 2) and the measured in-plane samples with +-K sigma error bars.\n"
	"Beyond the largest measured theta_o of an incidence the model extrapolates: drawn dotted, paler band.\n"
	"  --samples/--db      the samples (the measured incidences are their distinct theta_i)\n"
	"  --wavelength NM     one wavelength (default 550 nm, or the middle of the model's range)\n"
	"  --band LO:HI        the mean over a band (channels weighted by their trapezoid widths)\n"
	"  --theta-i A,B,...   incidences in degrees (instead of the measured ones)\n"
	"  --polar OUT.png     also one polar plot per incidence (radius: log f)\n"
	"  --csv OUT.csv       the plotted numbers (kind,theta_i,theta_o_signed,value,lo,hi,beyond_data; beyond_data\n"
	"                      1: a model point beyond the largest measured theta_o)\n";

int cmd_slices(int argc, char **argv)
{
	static const struct option lo[] = {
		{ "output", required_argument, 0, 'o' }, { "samples", required_argument, 0, 's' },
		{ "db", required_argument, 0, 'd' }, { "sweep", required_argument, 0, 'w' },
		{ "wavelength", required_argument, 0, 'l' }, { "band", required_argument, 0, 'b' },
		{ "theta-i", required_argument, 0, 't' }, { "polar", required_argument, 0, 'p' },
		{ "csv", required_argument, 0, 'c' }, { "sigma-k", required_argument, 0, 'k' },
		{ "phi-tol", required_argument, 0, 'f' }, { "size", required_argument, 0, 'z' },
		{ "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	struct slices_opts o;
	slices_opts_default(&o);
	const char *outp = NULL, *samples = NULL, *db = NULL, *polar = NULL, *csv = NULL;
	uint64_t sweep = 0;
	int have_sweep = 0, c;
	double th[SLICES_MAX_THETA];
	size_t nth = 0;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': outp = optarg; break;
		case 's': samples = optarg; break;
		case 'd': db = optarg; break;
		case 'p': polar = optarg; break;
		case 'c': csv = optarg; break;
		case 'w':
			if (cli_parse_u64(optarg, &sweep))
				return cli_usage_err("slices", "--sweep needs an id");
			have_sweep = 1;
			break;
		case 'l':
			if (cli_parse_double(optarg, &o.wl_lo) || !(o.wl_lo > 0))
				return cli_usage_err("slices", "--wavelength needs a positive number (nm)");
			o.wl_hi = o.wl_lo;
			break;
		case 'b': {
			char *end;
			o.wl_lo = strtod(optarg, &end);
			if (*end != ':' || cli_parse_double(end + 1, &o.wl_hi) || !(o.wl_lo > 0) || !(o.wl_hi > o.wl_lo))
				return cli_usage_err("slices", "--band needs LO:HI in nm with LO < HI");
			break;
		}
		case 't': {
			char *save = NULL, *dup = strdup(optarg);
			nth = 0;
			for (char *tok = strtok_r(dup, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
				double v;
				if (nth == SLICES_MAX_THETA || cli_parse_double(tok, &v) || v < 0 || v >= 90) {
					free(dup);
					return cli_usage_err("slices", "--theta-i needs up to 32 angles in [0, 90)");
				}
				th[nth++] = v * M_PI / 180;
			}
			free(dup);
			break;
		}
		case 'k':
			if (cli_parse_double(optarg, &o.band_k) || !(o.band_k > 0))
				return cli_usage_err("slices", "--sigma-k needs a positive number");
			break;
		case 'f':
			if (cli_parse_double(optarg, &o.phi_tol_deg) || !(o.phi_tol_deg > 0 && o.phi_tol_deg < 45))
				return cli_usage_err("slices", "--phi-tol needs 0..45 degrees");
			break;
		case 'z':
			if (sscanf(optarg, "%dx%d", &o.width, &o.height) != 2)
				return cli_usage_err("slices", "--size needs WxH");
			break;
		case 'h': fputs(slices_help, stdout); return 0;
		default: return cli_usage_err("slices", "bad option");
		}
	}
	if (optind != argc - 1 || !outp)
		return cli_usage_err("slices", "MODEL and -o OUT.png expected");
	if ((db != NULL) != have_sweep || (db && samples))
		return cli_usage_err("slices", "--db needs --sweep ID (and no --samples)");
	struct acq_err err = { 0 };
	struct recon_model *m;
	if (recon_model_load(argv[optind], &m, &err))
		return cli_fail(&err);
	if (isnan(o.wl_lo)) {
		double mid = 0.5 * (m->wl[0] + m->wl[m->nwl - 1]);
		o.wl_lo = o.wl_hi = (550 >= m->wl[0] && 550 <= m->wl[m->nwl - 1]) ? 550 : mid;
	}
	struct recon_samples s;
	memset(&s, 0, sizeof s);
	int have = 0, rc = 1;
	if (samples) {
		if (csvio_read_samples(samples, &s, &err))
			goto out;
		have = 1;
	} else if (db) {
		if (recon_load_db(db, (long long)sweep, &s, &err))
			goto out;
		have = 1;
	}
	struct slices_result res;
	if (slices_plot(m, have ? &s : NULL, th, nth, &o, outp, polar, csv, &res, &err))
		goto out;
	fprintf(stderr, "slices: %zu incidences, %zu in-plane samples, %zu model channels (%g..%g nm) -> %s%s%s\n", res.nth,
		res.nsamples, res.nchannels, o.wl_lo, o.wl_hi, outp, polar ? ", " : "", polar ? polar : "");
	rc = 0;
out:
	if (have)
		csvio_samples_free(&s);
	recon_model_free(m);
	return rc ? cli_fail(&err) : 0;
}
