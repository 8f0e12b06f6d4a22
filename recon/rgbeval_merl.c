/* rgbeval_merl: a MERL table filled from the reduced RGB evaluator (rgbeval.c): θh rows as jobs of the thread pool,
 * one batch each, the mirror half of the φd cells copied. */
#include "recon/rgbeval.h"

#include <math.h>
#include <stdlib.h>

#include "recon/pool.h"

/* One θh row of the MERL table (all its θd, φd cells): a job of the table's pool. Cells below the horizon get
 * MERL_NO_DATA; with !all_cells the half iφd ≥ 90 is left for the mirror copy. The row is evaluated in one
 * recon_rgb_batch call, so the result does not depend on the number of threads. */
#define MERL_ROW_CELLS ((size_t)MERL_N_THETA_D * MERL_N_PHI_D)

/* Scratch of one worker of the MERL table. */
struct merl_scratch {
	double wi[MERL_ROW_CELLS * 3], wo[MERL_ROW_CELLS * 3], rgb[MERL_ROW_CELLS * 3];
	size_t idx[MERL_ROW_CELLS];
	struct colour_stats stats;
};

struct merl_job {
	const struct recon_rgb *R;
	struct merl_table *t;
	int all_cells;
	struct merl_scratch *ws; /* [threads] */
};

static int merl_row(const struct recon_rgb *R, struct merl_table *t, int all_cells, int ith, double *wi, double *wo,
		    double *rgb, size_t *idx, struct colour_stats *stats, struct acq_err *err)
{
	size_t nb = 0;
	/* the cells' directions as merl_cell_dirs gives them, with the sines and cosines once per angle */
	double th_sc[2], td_sc[MERL_N_THETA_D][2], pd_sc[MERL_N_PHI_D][2];
	for (int i = 0; i < MERL_N_PHI_D; i++) {
		double th, td, pd;
		merl_cell_angles(ith, i < MERL_N_THETA_D ? i : 0, i, &th, &td, &pd);
		if (i == 0) {
			th_sc[0] = sin(th);
			th_sc[1] = cos(th);
		}
		if (i < MERL_N_THETA_D) {
			td_sc[i][0] = sin(td);
			td_sc[i][1] = cos(td);
		}
		pd_sc[i][0] = sin(pd);
		pd_sc[i][1] = cos(pd);
	}
	for (int itd = 0; itd < MERL_N_THETA_D; itd++)
		for (int ipd = 0; ipd < MERL_N_PHI_D; ipd++) {
			size_t flat = (size_t)ipd + (size_t)MERL_N_PHI_D * ((size_t)itd + (size_t)MERL_N_THETA_D * (size_t)ith);
			int has = merl_dirs_from_trig(th_sc, td_sc[itd], pd_sc[ipd], wi + 3 * nb, wo + 3 * nb) == 1;
			if (!has) {
				for (int c = 0; c < 3; c++)
					t->data[(size_t)c * MERL_N_CELLS + flat] = MERL_NO_DATA;
			} else if (all_cells || ipd < MERL_N_PHI_D / 2) {
				idx[nb++] = flat;
			} /* else: filled from its mirror cell afterwards */
		}
	if (!nb)
		return 0;
	if (recon_rgb_batch(R, nb, wi, wo, rgb, stats, err))
		return -1;
	for (size_t q = 0; q < nb; q++)
		for (int c = 0; c < 3; c++) {
			double v = rgb[3 * q + c] / merl_scale[c];
			if (!isfinite(v) || v < 0)
				return acq_errf(err, ACQ_E_NUMERIC, "merl table: bad value at cell %zu", idx[q]);
			t->data[(size_t)c * MERL_N_CELLS + idx[q]] = v;
		}
	return 0;
}

static int merl_row_job(void *arg, int worker, size_t row, struct acq_err *err)
{
	struct merl_job *J = arg;
	struct merl_scratch *w = &J->ws[worker];
	return merl_row(J->R, J->t, J->all_cells, (int)row, w->wi, w->wo, w->rgb, w->idx, &w->stats, err);
}

int recon_rgb_merl_table(const struct recon_rgb *R, struct merl_table *t, int all_cells, struct colour_stats *stats,
			 recon_progress_fn progress, void *pctx, struct acq_err *err)
{
	return recon_rgb_merl_table_ex(R, t, all_cells, 1, stats, progress, pctx, err);
}

int recon_rgb_merl_table_ex(const struct recon_rgb *R, struct merl_table *t, int all_cells, int threads,
			    struct colour_stats *stats, recon_progress_fn progress, void *pctx, struct acq_err *err)
{
	if (threads < 1 || threads > 16)
		return acq_errf(err, ACQ_E_INVAL, "merl table: threads must be in 1..16");
	t->data = malloc(3 * (size_t)MERL_N_CELLS * sizeof *t->data);
	struct merl_job J = { .R = R, .t = t, .all_cells = all_cells, .ws = calloc((size_t)threads, sizeof *J.ws) };
	int rc = -1;
	if (!t->data || !J.ws) {
		acq_errf(err, ACQ_E_NOMEM, "merl table: out of memory");
		goto out;
	}
	/* Rows of θh are independent jobs (pool.h); each row is one batch whatever the number of threads, so the
	 * table is bit-identical for any count. */
	struct pool_progress pr = { .fn = progress, .ctx = pctx, .stage = "merl", .every = 8 };
	if (pool_run(threads, MERL_N_THETA_H, merl_row_job, &J, &pr, err) != 0)
		goto out;
	if (stats)
		for (int i = 0; i < threads; i++) {
			stats->n += J.ws[i].stats.n;
			stats->out_of_gamut += J.ws[i].stats.out_of_gamut;
			stats->clipped += J.ws[i].stats.clipped;
			stats->nonfinite += J.ws[i].stats.nonfinite;
		}
	/*
	 * Only half of the φd cells are evaluated: for a BRDF that is isotropic (mirror φ → −φ) and reciprocal,
	 * f(θh, θd, φd) = f(θh, θd, −φd) = f(θh, θd, π − φd), and the cell centres of iφd and 179 − iφd are
	 * exactly φd and π − φd. The model has both symmetries by construction, so the copy is exact (to
	 * rounding); test_recon_rgb checks it against evaluating every cell.
	 */
	if (!all_cells)
		for (size_t flat = 0; flat < MERL_N_CELLS; flat++) {
			size_t ipd = flat % MERL_N_PHI_D;
			if (ipd < MERL_N_PHI_D / 2)
				continue;
			size_t mirror = flat - ipd + (MERL_N_PHI_D - 1 - ipd);
			for (int c = 0; c < 3; c++) {
				double *dst = &t->data[(size_t)c * MERL_N_CELLS + flat];
				double src = t->data[(size_t)c * MERL_N_CELLS + mirror];
				if (*dst == MERL_NO_DATA)
					continue;
				if (src == MERL_NO_DATA) { /* cannot happen (the horizon test is symmetric); never guess */
					acq_errf(err, ACQ_E_NUMERIC, "merl table: mirror of cell %zu has no data", flat);
					goto out;
				}
				*dst = src;
			}
		}
	rc = 0;
out:
	free(J.ws);
	if (rc) {
		free(t->data);
		t->data = NULL;
	}
	return rc;
}
