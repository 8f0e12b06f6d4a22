/* brdf-recon merl and render: the model as a MERL RGB table or a preview render of a sphere. */
#include <getopt.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon/brdf_recon/cli.h"
#include "recon/colour.h"
#include "recon/exrio.h"
#include "recon/merl.h"
#include "recon/recon.h"
#include "recon/render.h"
#include "recon/rgbeval.h"
#include "recon/sky.h"

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

int cmd_output(const char *cmd, int argc, char **argv)
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

