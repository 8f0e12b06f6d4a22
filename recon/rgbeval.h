/* rgbeval: the model reduced to what an RGB output needs (visible channels on a 5 nm grid, low-rank spectral
 * weights, the colour chain folded in), evaluated per direction pair for the MERL writer and the renderer. */
#ifndef RECON_RGBEVAL_H
#define RECON_RGBEVAL_H

#include <stddef.h>

#include "config/acq_err.h"
#include "recon/colour.h"
#include "recon/recon.h"

struct recon_rgb;

/* Build the reduced evaluator of model m under colour options co (copied). The reduction error is measured
 * against the full-spectrum path at 256 random pairs (recon_rgb_reduction_error). */
int recon_rgb_new(const struct recon_model *m, const struct colour_opts *co, struct recon_rgb **out,
		  struct acq_err *err);
/* Release (NULL is fine). */
void recon_rgb_free(struct recon_rgb *r);
/* Callback for merl_write / render_sphere (ctx = struct recon_rgb *): rgb after the whole colour chain.
 * Thread-safe. Returns 0, or -1 (allocation failure). */
int recon_rgb_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3]);
/* Same, the full-spectrum reference path (every model channel, colour weights at the model wavelengths). */
int recon_rgb_full_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3]);
/* Largest relative difference (linear RGB, relative to the largest component) between the reduced and
 * the full path found at construction. */
double recon_rgb_reduction_error(const struct recon_rgb *r);
/* Channels kept and spectral rank of the reduced evaluator. */
void recon_rgb_sizes(const struct recon_rgb *r, size_t *channels, size_t *rank);

#endif
