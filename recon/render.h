/* render: preview of an RGB BRDF on a sphere under directional lights and a gradient sky, tone-mapped sRGB PNG. */
#ifndef RECON_RENDER_H
#define RECON_RENDER_H

#include <stddef.h>

#include <stdint.h>
#include <stdio.h>

#include "config/acq_err.h"
#include "recon/colour.h"
#include "recon/merl.h"
#include "recon/sky.h"

/*
 * Scene (world frame: x right, y up, z toward the camera). Orthographic camera looking along −z; a unit
 * sphere at the origin fills `radius_frac` of the half of the smaller image side. Pixel (i, j) (j down)
 * samples its centre: x = (i + 0.5 − W/2)/R, y = −(j + 0.5 − H/2)/R, R = radius_frac·min(W, H)/2; inside the
 * disk the normal is n = (x, y, √(1 − x² − y²)) and ωo = (0, 0, 1) in world, both expressed in a local
 * frame with z = n (tangent from the branchless orthonormal basis of Duff et al. 2017; the BRDF is
 * expected isotropic).
 * Radiance (linear RGB): L = Σ_lights f(ωi, ωo)·E·cosθi  +  Σ_sky f(ωi, ωo)·L_sky(ωi)·cosθi·4π/K
 * over a fixed Fibonacci set of K directions on the whole sphere (those below the local horizon drop out);
 * L_sky = mix(horizon, zenith, y) above the world horizon, `ground` below. No shadows (a convex sphere).
 * Then ×exposure, then colour_finish(tone) (gamut, dynamic range, sRGB encoding), 8-bit.
 * Outside the disk: `background` (linear RGB) through the same tone stages.
 * Cost: about 0.785·W·H·(n_lights + K/2) callback evaluations.
 *
 * With a sky (o->sky, sky.h) the lights and the Fibonacci set are not used: each pixel takes spp directions
 * from four strategies, combined by the power heuristic (β = 2) of multiple importance sampling (Veach 1997):
 * the sky map by its luminance (3/8 of spp, 1/2 without a sun), the sun's cone (1/8), a GGX lobe of roughness
 * lobe_alpha around the mirror direction (3/8; cosine-weighted instead if lobe_alpha is 0) and the cosine-
 * weighted hemisphere (1/8). L = Σ_samples w_s·f·L_sky·cosθi / (n_s·p_s), w_s = (n_s p_s)² / Σ_k (n_k p_k)². Each pixel has its own random stream
 * (seed, pixel index): the image does not depend on the thread count. Cost: about 0.785·W·H·spp evaluations.
 */

#define RENDER_MAX_LIGHTS 8

struct render_light {
	double dir[3]; /* toward the light, world frame (normalised inside) */
	double rgb[3]; /* irradiance on a surface facing the light (linear RGB) */
};

struct render_opts {
	int width, height;                            /* pixels, 8..4096; default 256 × 256 */
	double radius_frac;                           /* (0, 1]; default 0.9 */
	struct render_light lights[RENDER_MAX_LIGHTS];
	int n_lights;                                 /* default 2: key (upper left) and fill (right) */
	double sky_zenith[3], sky_horizon[3], ground[3]; /* sky radiance (linear RGB) */
	int sky_samples;                              /* K, 0..4096 (0 = no sky); default 64 */
	double exposure;                              /* default 1 */
	struct colour_opts tone;                      /* only gamut, range, reinhard_white, srgb_encode used;
						       * default clamp, REINHARD (white 2), sRGB encoded */
	double background[3];                         /* linear RGB; default 0.05 grey */
	int threads;                                  /* 1..16, > 1 only for a thread-safe callback; default 1 */
	const struct sky *sky;                        /* environment lighting (NULL: lights + gradient sky) */
	int spp;                                      /* samples per pixel with a sky, 8..4096; default 64 */
	double lobe_alpha;                            /* GGX roughness of the lobe strategy, 0 or 0.01..1; 0.3 */
	uint64_t seed;                                /* of the per-pixel random streams; default 1 */
};

/* Fill o with the defaults above. */
void render_opts_default(struct render_opts *o);

/* Render fn on the sphere. png_path (may be NULL) receives the tone-mapped image (atomic write);
 * linear (may be NULL; width·height·3 floats, row-major, top row first) receives the linear radiance
 * after exposure, before tone mapping (background pixels: background·exposure). A callback error or a
 * non-finite value is an error (ACQ_E_NUMERIC, pixel named); stats (may be NULL) counts tone events.
 * 0, or -1 with err. */
int render_sphere(const struct render_opts *o, merl_rgb_fn fn, void *ctx, const char *png_path, float *linear,
		  struct colour_stats *stats, struct acq_err *err);

/* The image's own decisions as one JSON object (render_meta.c): PNG colour space and chunks, tone stages with
 * their counters (tone_stats may be NULL), the EXR's encoding (exr_path NULL = none), exposure, lighting and
 * sampling. 0, or -1 with err. */
int render_write_json(FILE *f, const struct render_opts *o, const struct colour_stats *tone_stats,
		      const char *png_path, const char *exr_path, struct acq_err *err);

/* Surface normal (world) at the centre of pixel (i, j); 1 inside the sphere's disk, 0 outside. */
int render_pixel_normal(const struct render_opts *o, int i, int j, double n[3]);

#endif
