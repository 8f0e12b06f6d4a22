/* rgbeval: the model reduced to what an RGB output needs (visible channels on a 5 nm grid, low-rank spectral
 * weights, the colour chain folded in), evaluated per direction pair for the MERL writer and the renderer. */
#ifndef RECON_RGBEVAL_H
#define RECON_RGBEVAL_H

#include <stddef.h>

#include "config/acq_err.h"
#include "recon/colour.h"
#include "recon/merl.h"
#include "recon/recon.h"

struct recon_rgb;

/* Build the reduced evaluator of model m under colour options co (copied), binning the visible channels to
 * bin_nm (0 = the default 5 nm; 0.5..50). The reduction error is measured against the full-spectrum path at
 * 256 random pairs (recon_rgb_reduction_error). */
int recon_rgb_new(const struct recon_model *m, const struct colour_opts *co, double bin_nm, struct recon_rgb **out,
		  struct acq_err *err);
/* Release (NULL is fine). */
void recon_rgb_free(struct recon_rgb *r);
/* Callback for merl_write / render_sphere (ctx = struct recon_rgb *): rgb after the whole colour chain.
 * Thread-safe. Returns 0, or -1 (allocation failure). */
int recon_rgb_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3]);
/* Same, the full-spectrum reference path (every model channel, colour weights at the model wavelengths). */
int recon_rgb_full_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3]);
/* Batch evaluation (the fast path): rgb[q*3..] after the whole colour chain for nq pairs of unit vectors
 * wi[q*3..], wo[q*3..] (GEMMs over blocks of pairs); stats (may be NULL) counts the tone events. */
int recon_rgb_batch(const struct recon_rgb *r, size_t nq, const double *wi, const double *wo, double *rgb,
		    struct colour_stats *stats, struct acq_err *err);
/* Fill a MERL table in memory (t->data allocated here, free with merl_free): cells with both directions
 * above the horizon evaluated by recon_rgb_batch at the writer's cell centres (all of them if all_cells,
 * else the half iφd < 90 and the mirror cells 179 − iφd copied: exact for an isotropic reciprocal model),
 * the others MERL_NO_DATA. Write it with merl_write_ex(path, merl_table_fn, t, ...). */
int recon_rgb_merl_table(const struct recon_rgb *r, struct merl_table *t, int all_cells, struct colour_stats *stats,
			 recon_progress_fn progress, void *pctx, struct acq_err *err);
/* recon_rgb_merl_table with threads (1..16) workers over the θh rows (pthreads; the table is bit-identical
 * for any count; the progress callback is called with a lock held). */
int recon_rgb_merl_table_ex(const struct recon_rgb *r, struct merl_table *t, int all_cells, int threads,
			    struct colour_stats *stats, recon_progress_fn progress, void *pctx, struct acq_err *err);
/* Largest of recon_rgb_reduction_error_rgb's three figures. */
double recon_rgb_reduction_error(const struct recon_rgb *r);
/* Per channel (linear R, G, B) the stated bound of the reduction error: twice the largest relative difference
 * |reduced − full| / max(|full|, 1 % of the pair's largest channel) found at construction at 1024 random pairs
 * (cosθ = u², u uniform, both directions). RECON_RGB_RED_DEFINITION says so in words (for sidecars). */
void recon_rgb_reduction_error_rgb(const struct recon_rgb *r, double e[3]);
#define RECON_RGB_RED_DEFINITION                                                                                  \
	"per linear sRGB channel: 2 x the largest |reduced - full| / max(|full|, 0.01 x largest channel) at 1024 "    \
	"random direction pairs (cos theta = u^2, u uniform)"
/* Largest |g_single − g_double| (g = ln f: a relative error in f) of the single-precision batch GEMM, measured
 * at construction at 2048 random pairs. */
double recon_rgb_f32_error(const struct recon_rgb *r);
/* Batch path in single (on) or double precision; single is the default when its measured error is ≤ 1e-4,
 * and refused (−1) otherwise. The per-pair callbacks always use double. */
int recon_rgb_set_f32(struct recon_rgb *r, int on);
/* Whether the batch path multiplies in single precision. */
int recon_rgb_f32(const struct recon_rgb *r);
/* Channels kept and spectral rank of the reduced evaluator. */
void recon_rgb_sizes(const struct recon_rgb *r, size_t *channels, size_t *rank);

#endif
