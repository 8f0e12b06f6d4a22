/* bench_snr: per-wavelength signal-to-noise ratio of a BRDF value against integration time and averages,
 * measured on the simulator's counts model (sim/sim_physics.h: shot, read and dark noise, nonlinearity,
 * quantisation, 16-bit saturation) with dark subtraction, at two geometries of green paint (diffuse: θi =
 * 30°, θo = 30°, 90° off the plane; near-specular: θo = 30° mirror ± 6°) and of metal (near-specular).
 * For each setting, NREP independent measurements of sample and dark give the relative standard deviation
 * of S − D per pixel (the relative noise of the BRDF value); pixels saturated in any repetition are marked.
 * Writes $ACQ_BENCH_OUT/bench_snr.csv (long format, 10 nm bands: pixel values averaged over each band) and
 * prints the median SNR per setting. tests/bench/bench_tradeoff.py turns it into DHR uncertainties. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config/bench.h"
#include "sim/sim.h"
#include "sim/sim_physics.h"
#include "sim/sim_rng.h"

#define NREP 24

struct geom_case {
	const char *name;
	int sample;
	double laser_theta, det_theta, det_phi;
};

static int cmp_d(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

int main(void)
{
	const char *dir = getenv("ACQ_BENCH_OUT");
	char path[1024];
	snprintf(path, sizeof path, "%s/bench_snr.csv", dir && *dir ? dir : "build/bench");
	struct phys_cfg cfg;
	phys_defaults(&cfg);
	struct acq_err err = { 0 };
	struct phys *p = phys_new(&cfg, &err);
	if (!p) {
		fprintf(stderr, "bench_snr: %s\n", err.msg);
		return 1;
	}
	static struct sim_world w; /* zeroed: no faults */
	bench_defaults(&w.geom);
	w.laser_emission = true;
	w.laser_power_pct = 100;
	w.sensor_temp_c = 25;
	static const struct geom_case cases[] = {
		{ "paint-diffuse", SIM_SAMPLE_GREEN_PAINT, 30, 30, 90 },
		{ "paint-specular", SIM_SAMPLE_GREEN_PAINT, 30, 30, 174 },
		{ "metal-specular", SIM_SAMPLE_METAL, 30, 30, 174 },
	};
	static const double integ[] = { 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000 };
	static const unsigned avgs[] = { 1, 4, 16 };
	FILE *f = fopen(path, "w");
	if (!f) {
		perror(path);
		phys_free(p);
		return 1;
	}
	fprintf(f, "# bench_snr: relative noise of S - D per 10 nm band, sim/sim_physics.h counts model, %d repetitions\n"
		   "case,integration_ms,averages,wavelength_nm,signal_counts,snr,saturated\n", NREP);
	static struct phys_frame fr;
	int npix = cfg.npix;
	double *sum = malloc(sizeof(double) * (size_t)npix), *sq = malloc(sizeof(double) * (size_t)npix);
	double *dk = malloc(sizeof(double) * (size_t)npix);
	unsigned char *sat = malloc((size_t)npix);
	double *wl = malloc(sizeof(double) * (size_t)npix), snrs[PHYS_MAX_PIXELS];
	if (!sum || !sq || !dk || !sat || !wl) {
		fprintf(stderr, "bench_snr: out of memory\n");
		return 1;
	}
	for (int k = 0; k < npix; k++)
		wl[k] = phys_wavelength(&cfg, k);
	struct sim_rng rng;
	sim_rng_seed(&rng, (uint64_t)strtoull(getenv("ACQ_SEED") ? getenv("ACQ_SEED") : "1", NULL, 10));
	printf("%-15s %8s %4s %10s %10s %6s\n", "case", "integ_ms", "avg", "median_snr", "min_snr", "sat%");
	for (size_t c = 0; c < sizeof cases / sizeof *cases; c++)
		for (size_t a = 0; a < sizeof avgs / sizeof *avgs; a++)
			for (size_t t = 0; t < sizeof integ / sizeof *integ; t++) {
				memset(sum, 0, sizeof(double) * (size_t)npix);
				memset(sq, 0, sizeof(double) * (size_t)npix);
				memset(sat, 0, (size_t)npix);
				w.sample = cases[c].sample;
				w.laser_theta_deg = cases[c].laser_theta;
				w.detector_theta_deg = cases[c].det_theta;
				w.detector_phi_deg = cases[c].det_phi;
				for (int r = 0; r < NREP; r++) {
					w.laser_emission = false; /* dark at the same integration time */
					if (phys_measure(p, &w, integ[t], avgs[a], 1.0, &rng, &fr, &err))
						goto fail;
					for (int k = 0; k < npix; k++)
						dk[k] = fr.counts[k];
					w.laser_emission = true;
					if (phys_measure(p, &w, integ[t], avgs[a], 1.0, &rng, &fr, &err))
						goto fail;
					for (int k = 0; k < npix; k++) {
						double v = fr.counts[k] - dk[k];
						sum[k] += v;
						sq[k] += v * v;
						sat[k] |= fr.sat[k];
					}
				}
				/* 10 nm bands: mean signal and the band's mean SNR (pixels are independent) */
				int ns = 0, nsat = 0, nb = 0;
				for (double b0 = 450; b0 < 1100 - 1e-9; b0 += 10) {
					double s = 0, snr = 0;
					int cnt = 0, bs = 0;
					for (int k = PHYS_NDARK; k < npix; k++) {
						if (wl[k] < b0 || wl[k] >= b0 + 10)
							continue;
						double m = sum[k] / NREP, var = sq[k] / NREP - m * m;
						double sd = sqrt(fmax(var, 0) * NREP / (NREP - 1));
						s += m;
						snr += sd > 0 ? m / sd : 0;
						bs |= sat[k];
						cnt++;
					}
					if (!cnt)
						continue;
					s /= cnt;
					snr /= cnt;
					nb++;
					nsat += bs;
					if (!bs)
						snrs[ns++] = snr;
					fprintf(f, "%s,%g,%u,%g,%.6g,%.6g,%d\n", cases[c].name, integ[t], avgs[a], b0 + 5, s,
						bs ? 0.0 : snr, bs);
				}
				double med = 0, mn = 0;
				if (ns) {
					qsort(snrs, (size_t)ns, sizeof *snrs, cmp_d);
					med = snrs[ns / 2];
					mn = snrs[0];
				}
				printf("%-15s %8g %4u %10.1f %10.1f %6.1f\n", cases[c].name, integ[t], avgs[a], med, mn,
				       100.0 * nsat / (nb ? nb : 1));
			}
	fclose(f);
	printf("bench_snr: %s\n", path);
	phys_free(p);
	free(sum);
	free(sq);
	free(dk);
	free(sat);
	free(wl);
	return 0;
fail:
	fprintf(stderr, "bench_snr: %s\n", err.msg);
	fclose(f);
	return 1;
}
