/* sky: environment lighting for the preview render: a tabulated lat-long radiance map (a smooth procedural sky,
 * or a user's EXR) sampled by importance, plus an optional sun disc sampled uniformly in its cone. */
#ifndef RECON_SKY_H
#define RECON_SKY_H

#include "config/acq_err.h"
#include "recon/warp2d.h"

/*
 * World frame of render.h: x right, y up, z toward the camera. A direction d maps to the lat-long square by
 * u = (φ + π)/2π with φ = atan2(d.x, −d.z) (the map's centre column looks along −z, away from the camera),
 * v = θ/π with θ = acos(d.y) (top row = up). Pixel (i, j) of a W × H map holds the radiance at its centre
 * ((i + ½)/W, (j + ½)/H), bilinear in between (wrapping in u). Radiances are linear RGB (sRGB primaries).
 */
struct sky_opts {
	double zenith[3], horizon[3], ground[3]; /* procedural sky radiance (linear RGB) */
	double glow;            /* circumsolar glow: + glow·sun colour·exp(−(γ/20°)²) at angle γ from the sun */
	double sun_dir[3];      /* toward the sun (normalised inside); y must be > 0 for a sun above the horizon */
	double sun_rgb[3];      /* irradiance of the sun on a surface facing it; all 0 = no sun */
	double sun_radius_deg;  /* angular radius of the disc, 0.05..10; default 1.5 (a soft preview sun) */
	int width, height;      /* procedural map size, 8..4096; default 256 × 128 */
};

struct sky {
	int w, h;
	float *map;             /* [h*w*3] radiance */
	struct warp2d wp;       /* importance of the map: luminance·sinθ at the (w+1) × (h+1) cell corners */
	int has_sun;
	double sun_dir[3], sun_L[3], sun_cos; /* unit direction, disc radiance, cos of the radius */
	char desc[512];         /* what lights the scene, for the image's sidecar */
};

/* Defaults: blue-grey gradient sky, warm-white sun upper left (irradiance 2.5), glow 0.4, 256 × 128. */
void sky_opts_default(struct sky_opts *o);
/* The procedural sky (and sun) of o. 0, or -1 with err. */
int sky_procedural(const struct sky_opts *o, struct sky **out, struct acq_err *err);
/* A user's lat-long EXR (exrio_read_rgb) times scale, plus the sun of o if o is not NULL and its sun_rgb is
 * not zero. 0, or -1 with err. */
int sky_envmap(const char *path, double scale, const struct sky_opts *o, struct sky **out, struct acq_err *err);
/* Release (NULL is fine). */
void sky_free(struct sky *s);
/* Radiance arriving from direction d (unit, world): the map plus the sun disc. */
void sky_radiance(const struct sky *s, const double d[3], double L[3]);
/* Importance sample of the map: uniform u in [0,1)² to a direction d; returns its solid-angle pdf. */
double sky_sample_map(const struct sky *s, const double u[2], double d[3]);
/* Solid-angle pdf of sky_sample_map at d. */
double sky_pdf_map(const struct sky *s, const double d[3]);
/* Uniform sample of the sun's cone; returns its pdf (0 without a sun). */
double sky_sample_sun(const struct sky *s, const double u[2], double d[3]);
/* Solid-angle pdf of sky_sample_sun at d (0 outside the cone or without a sun). */
double sky_pdf_sun(const struct sky *s, const double d[3]);

#endif
