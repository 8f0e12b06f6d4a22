/* brdf-recon rgl: the model as a spectral RGL .bsdf (recon/rgl.c). */
#include <getopt.h>
#include <stdint.h>
#include <stdio.h>

#include "recon/brdf_recon/cli.h"
#include "recon/recon.h"
#include "recon/rgl.h"

/* ---- rgl ---- */
static const char rgl_help[] =
	"usage: brdf-recon rgl MODEL -o FILE.bsdf [--wavelengths FIRST:LAST:STEP|A,B,...] [--resolution N]\n"
	"                      [--theta-i N] [--ndf N] [--threads N] [--rgb]\n"
	"Write the model as a spectral RGL tabulated BRDF (Dupuy & Jakob 2018; Mitsuba 3 'measured', pbrt-v4),\n"
	"isotropic. Tables from the model: NDF (retro-reflection fixed point) and its projected area, the VNDF\n"
	"per incidence, the CIE Y luminance and the spectra on each incidence's warped grid.\n"
	"  --wavelengths      nm, inside the model's range (default: the model's own channels)\n"
	"  --resolution N     nodes per side of the warped grid (default 32)\n"
	"  --theta-i N        incidence nodes k*90/N deg (default 30)\n"
	"  --ndf N            nodes per side of the ndf/sigma tables (default 128)\n"
	"  --rgb              an RGB file (field rgb, linear sRGB, D65; no wavelengths): Mitsuba 3's RGB variants\n"
	"                     load only these, its spectral variants and pbrt-v4 only spectral files\n";

int cmd_rgl(int argc, char **argv)
{
	static const struct option lo[] = {
		{ "output", required_argument, 0, 'o' }, { "wavelengths", required_argument, 0, 'w' },
		{ "resolution", required_argument, 0, 'r' }, { "theta-i", required_argument, 0, 't' },
		{ "ndf", required_argument, 0, 'n' }, { "threads", required_argument, 0, 'j' },
		{ "rgb", no_argument, 0, 'c' }, { "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	struct rgl_opts o;
	rgl_opts_default(&o);
	static double wl[RGL_MAX_WL];
	const char *outp = NULL;
	struct acq_err err = { 0 };
	uint64_t v;
	int c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': outp = optarg; break;
		case 'w':
			if (rgl_parse_wavelengths(optarg, wl, RGL_MAX_WL, &o.nwl, &err))
				return cli_fail(&err);
			o.wl = wl;
			break;
		case 'r': case 't': case 'n': case 'j':
			if (cli_parse_u64(optarg, &v) || v > 4096)
				return cli_usage_err("rgl", "--resolution, --theta-i, --ndf and --threads need a count");
			*(c == 'r' ? &o.res : c == 't' ? &o.ntheta : c == 'n' ? &o.ndf_res : &o.threads) = (int)v;
			break;
		case 'c': o.rgb = 1; break;
		case 'h': fputs(rgl_help, stdout); return 0;
		default: return cli_usage_err("rgl", "bad option");
		}
	}
	if (optind != argc - 1 || !outp)
		return cli_usage_err("rgl", "MODEL and -o FILE.bsdf expected");
	struct recon_model *m;
	if (recon_model_load(argv[optind], &m, &err))
		return cli_fail(&err);
	o.source = argv[optind];
	struct rgl_stats st;
	int rc = rgl_write(m, &o, outp, &st, &err);
	recon_model_free(m);
	if (rc)
		return cli_fail(&err);
	fprintf(stderr, "rgl: %zu incidences x %zu wavelengths%s on a %zux%zu warped grid (ndf %zux%zu), %zu nodes below "
		"the horizon, %zu bytes -> %s\n", st.ntheta, st.nwl, o.rgb ? " as linear sRGB" : "", st.res, st.res,
		st.ndf_res, st.ndf_res, st.zero_nodes, st.bytes, outp);
	if (o.rgb && st.rgb_clamped)
		fprintf(stderr, "rgl: %zu RGB table values below 0 (out of the sRGB gamut) written as 0\n", st.rgb_clamped);
	return 0;
}
