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
	struct cli_out o;
	if (cli_out_open(&o, p, err))
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
	double e[3];
	recon_rgb_reduction_error_rgb(R, e);
	fprintf(o.f, ", \"spectral_path\": \"%s\", \"bin_nm\": %g, \"channels\": %zu, \"rank\": %zu, "
		"\"reduction_max_rel_error\": %.3g, \"reduction_max_rel_error_rgb\": [%.3g, %.3g, %.3g], "
		"\"reduction_error_definition\": \"" RECON_RGB_RED_DEFINITION "\", \"batch_precision\": \"%s\", "
		"\"single_precision_max_abs_error_ln_f\": %.3g}\n",
		full ? "full" : "reduced", bin_nm, nc, r, recon_rgb_reduction_error(R), e[0], e[1], e[2],
		recon_rgb_f32(R) ? "single" : "double", recon_rgb_f32_error(R));
	return cli_out_close(&o, ok, err);
}

static const char merl_help[] =
	"usage: brdf-recon merl MODEL -o FILE.binary [--colour key=value]... [--threads N] [--bin-nm X]\n"
	"                        [--direct|--full-spectrum] [--double]\n"
	"Write the model as a MERL isotropic RGB table (90 x 90 x 180 cells, 34,992,012 bytes). Only cells whose\n"
	"two directions are above the horizon are evaluated (the others hold -1, \"no data\"). Spectra go through\n"
	"the colour chain (default: D65, CIE 1931 2 deg, Bradford, absolute sr^-1, clamp, keep, linear); the\n"
	"model is reduced to what RGB needs (visible channels averaged in --bin-nm bins, default 5 nm, each channel\n"
	"read back as a local quadratic; low-rank weights), the error of the reduction measured per R, G, B channel\n"
	"against the full path and printed (--bin-nm 1: exact for a 1 nm model), and evaluated in batches.\n"
	"--direct: one callback per cell (same values, slower); --full-spectrum: every model channel per cell\n"
	"(reference path, slowest). The batches multiply in single precision when its error,\n"
	"measured at 2048 random pairs, is <= 1e-4 in ln f (a relative error in f); --double forces double.\n"
	"The decisions are written to FILE.binary.colour.json. Colour keys: illum gap adapt norm white max_albedo\n"
	"target exposure gamut range reinhard_white srgb_encode.\n";

static const char render_help[] =
	"usage: brdf-recon render MODEL -o OUT.png [--exr OUT.exr] [--size N] [--exposure X] [--spp N] [--seed S]\n"
	"                         [--env MAP.exr [--env-scale X] [--sun]] [--sun-elevation DEG] [--sun-azimuth DEG]\n"
	"                         [--no-sun]\n"
	"                         [--lights] [--colour key=value]... [--threads N] [--bin-nm X] [--direct | --full-spectrum]\n"
	"Preview of the model on a sphere: tone-mapped sRGB PNG (sRGB/gAMA/cHRM chunks) and, with --exr, the linear\n"
	"HDR radiance as OpenEXR (float RGB, Rec. 709 chromaticities). Lighting: a smooth procedural sky with a sun\n"
	"(default; azimuth 0 = toward the camera, 90 = right; --no-sun: the sky alone), or a lat-long EXR environment\n"
	"map (--env; centre column looks away from the camera) as it is: a captured map holds its own sun; --sun adds\n"
	"the procedural one to it. Sampled by importance (sky luminance, sun cone, GGX lobe, cosine;\n"
	"--spp samples per pixel, default 64). --lights: the old two lights + 64-direction gradient sky.\n"
	"OUT.png.colour.json records the image's colour decisions, its lighting and the BRDF-to-RGB chain.\n"
	"By default the model is tabulated as a MERL table in memory (batched) and rendered through its nearest-cell\n"
	"lookup; --direct evaluates the reduced model per ray, --full-spectrum every channel per ray.\n";

/* What one merl or render invocation asked for (parse_args). */
struct output_args {
	const char *cmd;   /* "merl" or "render" */
	int is_merl;
	const char *model, *outp, *exr, *env;
	struct colour_opts co;
	uint64_t threads, size, spp, rseed;
	double bin_nm, exposure, env_scale, sun_el, sun_az;
	int full, direct, dbl, no_sun, sun, old_lights;
};

/* Read the options into a (defaults first): -1 to go on, or the exit status (help, a usage error, a bad --colour). */
static int parse_args(const char *cmd, int argc, char **argv, struct output_args *a)
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
		{ "no-sun", no_argument, 0, 'N' }, { "sun", no_argument, 0, 'U' }, { "lights", no_argument, 0, 'L' },
		{ 0, 0, 0, 0 } };
	*a = (struct output_args){ .cmd = cmd, .is_merl = !strcmp(cmd, "merl"), .threads = 2, .size = 256, .spp = 64,
				   .rseed = 1, .bin_nm = 5, .exposure = 1, .env_scale = 1, .sun_el = 40, .sun_az = -36 };
	colour_opts_brdf(&a->co);
	struct acq_err err = { 0 };
	int c;
	while ((c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1) {
		switch (c) {
		case 'o': a->outp = optarg; break;
		case 'c':
			if (colour_arg(&a->co, optarg, &err))
				return cli_fail(&err);
			break;
		case 't':
			if (cli_parse_u64(optarg, &a->threads) || a->threads < 1 || a->threads > 16)
				return cli_usage_err(cmd, "--threads needs 1..16");
			break;
		case 'f': a->full = 1; break;
		case 'd': a->direct = 1; break;
		case 'D': a->dbl = 1; break;
		case 'b':
			if (cli_parse_double(optarg, &a->bin_nm) || !(a->bin_nm >= 0.5 && a->bin_nm <= 50))
				return cli_usage_err(cmd, "--bin-nm needs 0.5..50");
			break;
		case 's':
			if (a->is_merl || cli_parse_u64(optarg, &a->size) || a->size < 8 || a->size > 4096)
				return cli_usage_err(cmd, "--size needs 8..4096 (render only)");
			break;
		case 'e':
			if (a->is_merl || cli_parse_double(optarg, &a->exposure) || !(a->exposure > 0))
				return cli_usage_err(cmd, "--exposure needs a positive number (render only)");
			break;
		case 'h': fputs(a->is_merl ? merl_help : render_help, stdout); return 0;
		case 'X': a->exr = optarg; break;
		case 'E': a->env = optarg; break;
		case 'N': a->no_sun = 1; break;
		case 'U': a->sun = 1; break;
		case 'L': a->old_lights = 1; break;
		case 'P': case 'S':
			if (cli_parse_u64(optarg, c == 'P' ? &a->spp : &a->rseed) || (c == 'P' && (a->spp < 8 || a->spp > 4096)))
				return cli_usage_err(cmd, "--spp needs 8..4096, --seed an unsigned integer");
			break;
		case 'K': case 'A': case 'Z': {
			double *t = c == 'K' ? &a->env_scale : c == 'A' ? &a->sun_el : &a->sun_az;
			if (cli_parse_double(optarg, t) || (c == 'K' && !(a->env_scale > 0)) ||
			    (c == 'A' && !(a->sun_el > 0 && a->sun_el <= 90)))
				return cli_usage_err(cmd, "--env-scale needs a positive number, --sun-elevation 0..90, --sun-azimuth degrees");
			break;
		}
		default: return cli_usage_err(cmd, "bad option");
		}
	}
	if (optind != argc - 1 || !a->outp)
		return cli_usage_err(cmd, "MODEL and -o OUT expected");
	if (a->is_merl && (a->exr || a->env || a->old_lights || a->sun || a->no_sun))
		return cli_usage_err(cmd, "--exr, --env, --sun, --no-sun and --lights are render options");
	if (a->sun && a->no_sun)
		return cli_usage_err(cmd, "--sun and --no-sun exclude each other");
	if (a->sun && !a->env)
		return cli_usage_err(cmd, "--sun adds the procedural sun to an --env map (the procedural sky has it already)");
	a->model = argv[optind];
	return -1;
}

/* render's lighting into *sky: the procedural sky with its sun (unless --no-sun), or the --env map as it is (a
 * captured map holds its own sun; --sun adds the procedural one); NULL for merl and --lights. 0, or -1 with err. */
static int make_sky(const struct output_args *a, struct sky **sky, struct acq_err *err)
{
	struct sky_opts so;
	sky_opts_default(&so);
	double el = a->sun_el * M_PI / 180, az = a->sun_az * M_PI / 180;
	so.sun_dir[0] = cos(el) * sin(az);
	so.sun_dir[1] = sin(el);
	so.sun_dir[2] = cos(el) * cos(az);
	if (a->no_sun)
		so.sun_rgb[0] = so.sun_rgb[1] = so.sun_rgb[2] = 0;
	*sky = NULL;
	if (a->is_merl || a->old_lights)
		return 0;
	return a->env ? sky_envmap(a->env, a->env_scale, a->sun ? &so : NULL, sky, err) : sky_procedural(&so, sky, err);
}

/* The model reduced to what RGB needs (*R), its sizes and errors reported on stderr. 0, or -1 with err set. */
static int make_rgb(const struct output_args *a, const struct recon_model *m, struct recon_rgb **R,
		    struct acq_err *err)
{
	if (recon_rgb_new(m, &a->co, a->bin_nm, R, err))
		return -1;
	size_t nc, r;
	if (a->dbl)
		recon_rgb_set_f32(*R, 0);
	recon_rgb_sizes(*R, &nc, &r);
	double e[3];
	recon_rgb_reduction_error_rgb(*R, e);
	fprintf(stderr, "%s: %s path, %zu of %zu channels (%g nm bins), spectral rank %zu, reduction error R %.2g "
		"G %.2g B %.2g (relative, per channel); batch GEMM in %s precision (single-precision error %.2g in ln f)\n",
		a->cmd, a->full ? "full-spectrum" : "reduced", nc, m->nwl, a->bin_nm, r, e[0], e[1], e[2],
		recon_rgb_f32(*R) ? "single" : "double", recon_rgb_f32_error(*R));
	return 0;
}

/* The MERL file: the batched table as it is, else one callback per cell (fn, ctx). 0, or -1 with err set. */
static int write_merl(const struct output_args *a, const struct merl_table *table, merl_rgb_fn fn, void *ctx,
		      struct acq_err *err)
{
	struct merl_write_opts mo;
	merl_write_opts_default(&mo);
	mo.threads = (int)a->threads;
	/* the table is already in the writer's cells and units: written as it is (no per-cell lookup) */
	if (table->data)
		return merl_write_table(a->outp, table, err) ? -1 : 0;
	return merl_write_ex(a->outp, fn, ctx, &mo, err) ? -1 : 0;
}

/* The preview: the sphere through (fn, ctx) under sky to the PNG (and the linear radiance to --exr); ro and tone
 * are filled for the decisions file. 0, or -1 with err set. */
static int write_render(const struct output_args *a, const struct recon_model *m, struct sky *sky, merl_rgb_fn fn,
			void *ctx, struct render_opts *ro, struct colour_stats *tone, struct acq_err *err)
{
	ro->width = ro->height = (int)a->size;
	ro->exposure = a->exposure;
	ro->threads = (int)a->threads;
	ro->sky = sky;
	ro->spp = (int)a->spp;
	ro->seed = a->rseed;
	ro->lobe_alpha = m->trend != RECON_TREND_NONE && m->trend_alpha >= 0.01 && m->trend_alpha <= 1 ? m->trend_alpha : 0.3;
	float *lin = malloc((size_t)a->size * (size_t)a->size * 3 * sizeof *lin);
	int ok = 1;
	if (!lin)
		ok = acq_errf(err, ACQ_E_NOMEM, "render: out of memory") == 0;
	ok = ok && render_sphere(ro, fn, ctx, a->outp, lin, tone, err) == 0;
	if (ok && a->exr) {
		char note[1024];
		snprintf(note, sizeof note, "brdf-recon render of %s: linear scene-referred radiance x exposure %g, "
			 "Rec. 709 primaries, D65; lighting: %s", a->model, a->exposure,
			 sky ? sky->desc : "two lights + gradient sky");
		ok = exrio_write_rgb(a->exr, lin, ro->width, ro->height, note, err) == 0;
	}
	free(lin);
	return ok ? 0 : -1;
}

int cmd_output(const char *cmd, int argc, char **argv)
{
	struct output_args a;
	int rc = parse_args(cmd, argc, argv, &a);
	if (rc >= 0)
		return rc;
	struct acq_err err = { 0 };
	struct recon_model *m;
	if (recon_model_load(a.model, &m, &err))
		return cli_fail(&err);
	struct sky *sky;
	if (make_sky(&a, &sky, &err)) {
		recon_model_free(m);
		return cli_fail(&err);
	}
	struct recon_rgb *R = NULL;
	int ok = make_rgb(&a, m, &R, &err) == 0;
	/* default: the table is computed in batches (GEMMs) and both outputs read it: the MERL writer through
	 * the reference lookup (which returns each cell's own value at the cell centres it asks for), the
	 * renderer through the same nearest-cell lookup. --full-spectrum / --direct: per-direction callbacks. */
	struct merl_table table = { NULL };
	struct colour_stats st = { 0 };
	if (ok && !a.full && !a.direct) {
		ok = recon_rgb_merl_table_ex(R, &table, 0, (int)a.threads, &st, cli_progress, NULL, &err) == 0;
		cli_progress_end();
	}
	merl_rgb_fn fn = a.full ? recon_rgb_full_fn : a.direct ? recon_rgb_fn : merl_table_fn;
	void *ctx = (a.full || a.direct) ? (void *)R : (void *)&table;
	struct render_opts ro;
	struct colour_stats tone = { 0 };
	render_opts_default(&ro);
	if (ok)
		ok = (a.is_merl ? write_merl(&a, &table, fn, ctx, &err)
				: write_render(&a, m, sky, fn, ctx, &ro, &tone, &err)) == 0;
	merl_free(&table);
	if (ok)
		ok = write_decisions(a.outp, &a.co, R, a.full, a.bin_nm, a.is_merl ? NULL : &ro, &tone, a.exr, &err) == 0;
	sky_free(sky);
	recon_rgb_free(R);
	recon_model_free(m);
	if (!ok)
		return cli_fail(&err);
	fprintf(stderr, "%s: wrote %s\n", cmd, a.outp);
	return 0;
}
