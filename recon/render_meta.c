/* render_meta: the rendered image's own colour and lighting decisions as JSON (the sidecar of a preview). */
#include "recon/render.h"

#include <stdio.h>

static void put_str(FILE *f, const char *s)
{
	fputc('"', f);
	for (; s && *s; s++) {
		if (*s == '"' || *s == '\\')
			fprintf(f, "\\%c", *s);
		else if ((unsigned char)*s < 0x20)
			fprintf(f, "\\u%04x", *s);
		else
			fputc(*s, f);
	}
	fputc('"', f);
}

int render_write_json(FILE *f, const struct render_opts *o, const struct colour_stats *tone_stats,
		      const char *png_path, const char *exr_path, struct acq_err *err)
{
	(void)err;
	fputs("{\"png\": {\"path\": ", f);
	put_str(f, png_path ? png_path : "");
	fprintf(f, ", \"pixels\": \"8-bit RGB\", \"colour_space\": \"sRGB (IEC 61966-2-1): Rec. 709 primaries, D65 white\", "
		"\"png_chunks\": [\"sRGB (perceptual intent)\", \"gAMA 45455 (1/2.2)\", \"cHRM sRGB primaries and D65\"], "
		"\"from_linear\": \"exposure, then the tone stages below (gamut, dynamic range, sRGB transfer curve), "
		"rounded to 8 bits\", \"tone\": ");
	const struct colour_opts *t = &o->tone;
	fprintf(f, "{\"out_of_gamut\": \"%s\", \"dynamic_range\": \"%s\"", t->gamut == COLOUR_GAMUT_CLAMP ? "clamp negatives to 0"
		: "desaturate toward the grey of equal luminance", t->range == COLOUR_RANGE_KEEP ? "keep (then 8-bit clip)"
		: t->range == COLOUR_RANGE_CLIP ? "clip to [0, 1]" : "Reinhard on luminance, L(1 + L/Lw^2)/(1 + L), then clip");
	if (t->range == COLOUR_RANGE_REINHARD)
		fprintf(f, ", \"reinhard_white\": %.9g", t->reinhard_white);
	fprintf(f, ", \"encoding\": \"%s\"", t->srgb_encode ? "sRGB transfer curve" : "linear (no transfer curve)");
	if (tone_stats)
		fprintf(f, ", \"pixels\": %zu, \"out_of_gamut_pixels\": %zu, \"clipped_pixels\": %zu, "
			"\"nonfinite_pixels\": %zu", tone_stats->n, tone_stats->out_of_gamut, tone_stats->clipped,
			tone_stats->nonfinite);
	fputs("}}, \"exr\": ", f);
	if (exr_path) {
		fputs("{\"path\": ", f);
		put_str(f, exr_path);
		fputs(", \"pixels\": \"32-bit float R, G, B, ZIP\", \"encoding\": \"linear, scene-referred (no tone "
		      "mapping, no clipping, no transfer curve)\", \"chromaticities\": {\"red\": [0.64, 0.33], \"green\": "
		      "[0.30, 0.60], \"blue\": [0.15, 0.06], \"white\": [0.3127, 0.3290]}}", f);
	} else {
		fputs("null", f);
	}
	fprintf(f, ", \"exposure\": %.9g, \"size\": [%d, %d], \"background_linear\": [%.6g, %.6g, %.6g], \"lighting\": ",
		o->exposure, o->width, o->height, o->background[0], o->background[1], o->background[2]);
	if (o->sky) {
		fputs("{\"kind\": ", f);
		put_str(f, o->sky->desc);
		fprintf(f, ", \"units\": \"linear RGB radiance (sRGB primaries), relative\", \"sun\": ");
		if (o->sky->has_sun)
			fprintf(f, "{\"direction\": [%.6f, %.6f, %.6f], \"cos_radius\": %.9g, \"radiance\": [%.6g, %.6g, %.6g]}",
				o->sky->sun_dir[0], o->sky->sun_dir[1], o->sky->sun_dir[2], o->sky->sun_cos, o->sky->sun_L[0],
				o->sky->sun_L[1], o->sky->sun_L[2]);
		else
			fputs("null", f);
		fprintf(f, ", \"sampling\": \"multiple importance sampling, power heuristic: sky map by luminance, sun "
			"cone, GGX lobe, cosine\", \"spp\": %d, \"lobe_alpha\": %.6g, \"seed\": %llu}", o->spp, o->lobe_alpha,
			(unsigned long long)o->seed);
	} else {
		fprintf(f, "{\"kind\": \"%d directional lights + gradient sky at %d fixed directions\"}", o->n_lights,
			o->sky_samples);
	}
	fputs(", \"shading\": \"RGB: BRDF reduced to linear sRGB by the spectral chain (brdf_to_rgb) times the "
	      "lights' linear RGB; no shadows (convex sphere)\"}", f);
	if (ferror(f))
		return acq_errf(err, ACQ_E_IO, "render: writing the sidecar failed");
	return 0;
}
