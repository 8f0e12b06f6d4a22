/* merl: writer and reference reader of the MERL isotropic BRDF binary table (Matusik et al. 2003). */
#ifndef RECON_MERL_H
#define RECON_MERL_H

#include <stddef.h>

#include "config/acq_err.h"

/*
 * Format: three int32 little-endian 90, 90, 180 (θh, θd, φd counts), then 3 blocks (R, G, B) of
 * 1,458,000 float64 little-endian; 34,992,012 bytes. Flat index iφd + 180·iθd + 180·90·iθh.
 * Stored value = BRDF (sr⁻¹) divided by the reader scale 1/1500 (R), 1.15/1500 (G), 1.66/1500 (B).
 *
 * Writer convention: cell (iθh, iθd, iφd) stands for its centre in index space,
 *   θh = ((iθh + 0.5)/90)² · π/2,  θd = (iθd + 0.5) · (π/2)/90,  φd = (iφd + 0.5) · π/180,
 * turned into (ωi, ωo) by the Rusinkiewicz inverse with φh = 0 (isotropy): ωi = Rz(φh)·Ry(θh)·d(θd, φd),
 * ωo = 2(ωi·h)h − ωi. A cell whose ωi or ωo has z ≤ 0 (at or below the horizon) is not evaluated and is
 * stored as MERL_NO_DATA (−1, i.e. a negative value after the reader scale: "no data").
 * The reader scale multiplies back; merl_lookup uses the reference index functions of BRDFRead.cpp.
 */

#define MERL_N_THETA_H 90
#define MERL_N_THETA_D 90
#define MERL_N_PHI_D 180
#define MERL_N_CELLS (MERL_N_THETA_H * MERL_N_THETA_D * MERL_N_PHI_D) /* 1,458,000 */
#define MERL_FILE_SIZE (12 + 3 * 8 * (long long)MERL_N_CELLS)         /* 34,992,012 */
#define MERL_NO_DATA (-1.0)                                            /* stored (unscaled) "no data" */

/* Reader scales: BRDF = stored · scale[c]. */
extern const double merl_scale[3];

/* RGB BRDF callback: fill rgb (linear sRGB BRDF in sr⁻¹, finite, ≥ 0 expected; from a spectral model use
 * colour_opts_brdf() + colour_weights()) for unit vectors wi, wo in the local frame (z = normal, both
 * z > 0); return 0, or non-zero to abort the write (reported as an error). */
typedef int (*merl_rgb_fn)(void *ctx, const double wi[3], const double wo[3], double rgb[3]);

struct merl_table;

/* Options of merl_write_ex. */
struct merl_write_opts {
	int threads;      /* evaluation threads, 1..16; > 1 only if the callback is thread-safe; default 1 */
	double clamp_min; /* ≥ 0; values below it are written as it (default 0: a negative BRDF becomes 0,
			   * never a negative value that readers would take for "no data") */
};

/* Fill o with the defaults (1 thread, clamp_min 0). */
void merl_write_opts_default(struct merl_write_opts *o);

/* Evaluate fn at every existing cell and write the table to path atomically (temp file in the same
 * folder, fsync, rename). A callback failure or a NaN/Inf value aborts with an error (ACQ_E_NUMERIC) naming
 * the cell; nothing is left at path then. 0, or -1 with err. */
int merl_write(const char *path, merl_rgb_fn fn, void *ctx, struct acq_err *err);

/* merl_write with options (NULL = defaults). */
int merl_write_ex(const char *path, merl_rgb_fn fn, void *ctx, const struct merl_write_opts *o,
		  struct acq_err *err);

/* Write a table already in stored units (e.g. recon_rgb_merl_table) to path atomically, as merl_write_ex
 * would write it through merl_table_fn (the same values, without the per-cell lookups: at most one rounding
 * apart). Every value must be finite and ≥ 0 or MERL_NO_DATA (ACQ_E_NUMERIC names the cell otherwise); the
 * no-data cells are the producer's (recon_rgb_merl_table marks exactly the cells below the horizon). */
int merl_write_table(const char *path, const struct merl_table *t, struct acq_err *err);

/* Directions of cell (ith, itd, ipd) under the writer convention; returns 1 if both are above the horizon
 * (the cell has data), 0 if not, -1 for indices out of range. */
int merl_cell_dirs(int ith, int itd, int ipd, double wi[3], double wo[3]);

/* Angles (θh, θd, φd) a cell stands for under the writer convention (indices assumed in range). */
void merl_cell_angles(int ith, int itd, int ipd, double *theta_h, double *theta_d, double *phi_d);

/* merl_dirs_from_angles from {sin, cos} of θh, θd and φd (callers that sweep a row compute them once per
 * angle); the same arithmetic, so the same bits. */
int merl_dirs_from_trig(const double th_sc[2], const double td_sc[2], const double pd_sc[2], double wi[3],
			double wo[3]);
/* Inverse Rusinkiewicz map with φh = 0: (wi, wo) from (θh, θd, φd); 1 if both have z > 0, else 0. */
int merl_dirs_from_angles(double theta_h, double theta_d, double phi_d, double wi[3], double wo[3]);

/* Rusinkiewicz coordinates of (wi, wo) (unit vectors, any order): θh, φh, θd, φd (φd in (−π, π]). */
void merl_half_diff(const double wi[3], const double wo[3], double *theta_h, double *phi_h, double *theta_d,
		    double *phi_d);

/* Reference indices (BRDFRead.cpp) of (θh, θd, φd), each clamped to its range; returns the flat index. */
int merl_index(double theta_h, double theta_d, double phi_d, int *ith, int *itd, int *ipd);

/* A table in memory: data[c * MERL_N_CELLS + flat] as stored (unscaled). */
struct merl_table {
	double *data;
};

/* Read and validate a MERL file (header 90 90 180, exact size, finite values); 0, or -1 with err
 * (ACQ_E_IO / ACQ_E_NOTFOUND / ACQ_E_PROTO for a bad header or size). */
int merl_read(const char *path, struct merl_table *t, struct acq_err *err);

/* Free the table's memory (t may be NULL). */
void merl_free(struct merl_table *t);

/* Reference lookup: rgb = stored · scale at the cell of (wi, wo) (unit vectors). Returns 0 with data,
 * 1 for a "no data" cell (rgb negative), -1 if a direction is not finite or has z ≤ 0 (rgb = 0). */
int merl_lookup(const struct merl_table *t, const double wi[3], const double wo[3], double rgb[3]);

/* merl_rgb_fn over a table (ctx = const struct merl_table *): the reference lookup, with "no data" cells
 * and invalid directions given as 0 (so a MERL file can be rendered); thread-safe; always returns 0. */
int merl_table_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3]);

#endif
