/* Unit tests for daemon/exposure.c: averaging, auto-exposure, multi-exposure merge around saturation, darks. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "tests/unit/synth.h"

static uint64_t seed;

static const struct synth_det det = { .npix = 1024, .offset = 1500, .dc_per_ms = 0.2, .read_sigma = 8, .full = 65535 };

/* A spectrum with a sharp peak and weak wings: rate(p) in counts/ms, spanning ~3 decades. */
static void peaked_rate(double *rate, int npix, double peak)
{
	for (int p = 0; p < npix; p++) {
		double x = (p - npix * 0.4) / (npix * 0.05);
		rate[p] = peak * (0.002 + exp(-0.5 * x * x));
	}
}

static void test_avg_chan_equals_direct(void **state)
{
	(void)state;
	struct synth_rng r = { .s = seed };
	enum { NP = 64, NS = 24 };
	static double scans[NS][NP];
	for (int k = 0; k < NS; k++)
		for (int p = 0; p < NP; p++)
			scans[k][p] = 100 * p + 30 * synth_gauss(&r);
	static struct exp_avg one, chunks;
	exp_avg_init(&one, NP, 5.0);
	for (int k = 0; k < NS; k++)
		assert_int_equal(exp_avg_add(&one, scans[k], NULL, 1, NULL, 5.0, NULL), 0);
	/* the same scans delivered as device-averaged frames of 8 scans (mean + sample std) */
	exp_avg_init(&chunks, NP, 5.0);
	for (int c = 0; c < NS / 8; c++) {
		double m[NP];
		float s[NP];
		for (int p = 0; p < NP; p++) {
			double sum = 0, ss = 0;
			for (int k = 0; k < 8; k++)
				sum += scans[c * 8 + k][p];
			m[p] = sum / 8;
			for (int k = 0; k < 8; k++)
				ss += (scans[c * 8 + k][p] - m[p]) * (scans[c * 8 + k][p] - m[p]);
			s[p] = (float)sqrt(ss / 7);
		}
		assert_int_equal(exp_avg_add(&chunks, m, s, 8, NULL, 5.0, NULL), 0);
	}
	for (int p = 0; p < NP; p++) {
		double sum = 0, ss = 0;
		for (int k = 0; k < NS; k++)
			sum += scans[k][p];
		double mean = sum / NS;
		for (int k = 0; k < NS; k++)
			ss += (scans[k][p] - mean) * (scans[k][p] - mean);
		double sd = sqrt(ss / (NS - 1));
		assert_true(fabs(one.mean[p] - mean) < 1e-9 * fmax(1, fabs(mean)));
		assert_true(fabs(exp_avg_std(&one, p) - sd) < 1e-9 * sd);
		assert_true(fabs(chunks.mean[p] - mean) < 1e-6 * fmax(1, fabs(mean)));
		assert_true(fabs(exp_avg_std(&chunks, p) - sd) < 1e-5 * sd);
	}
	assert_int_equal(one.n, NS);
	struct acq_err err = { 0 };
	assert_int_equal(exp_avg_add(&one, scans[0], NULL, 1, NULL, 6.0, &err), -1); /* other time */
	assert_int_equal(err.code, ACQ_E_INVAL);
}

/* Simulate one noiseless frame of the peaked spectrum at t (counts clipped, saturated flagged). */
static void frame_at(struct spectro_frame *f, const double *rate, double t)
{
	memset(f, 0, sizeof *f);
	f->npix = det.npix;
	f->meas.integration_ms = t;
	f->meas.averages = 1;
	for (int p = 0; p < det.npix; p++) {
		double v = det.offset + det.dc_per_ms * t + rate[p] * t;
		if (v >= SPECTRO_SATURATED) {
			v = det.full;
			f->saturated[p] = 1;
			f->nsaturated++;
		}
		f->counts[p] = v;
	}
}

static void test_auto_exposure_converges_to_target(void **state)
{
	(void)state;
	struct exp_policy pol;
	exp_policy_defaults(&pol);
	pol.probe_ms = 10;
	pol.max_ms = 5000;
	static double rate[SPECTRO_MAX_PIXELS], dark[SPECTRO_MAX_PIXELS];
	static struct spectro_frame f;
	struct synth_rng r = { .s = seed };
	/* peaks from very weak (needs > max_step) to very strong (saturates the probe) */
	const double peaks[] = { 0.5, 20, 400, 6000, 200000, 5e6 };
	for (size_t i = 0; i < sizeof peaks / sizeof *peaks; i++) {
		double peak = peaks[i] * (1 + 0.1 * synth_gauss(&r));
		peaked_rate(rate, det.npix, peak);
		double t = pol.probe_ms, next = 0;
		int probes = 0, rc;
		do {
			probes++;
			frame_at(&f, rate, t);
			for (int p = 0; p < det.npix; p++)
				dark[p] = det.offset + det.dc_per_ms * t;
			rc = exp_probe_next(&pol, &f, dark, det.full, probes, &next, NULL);
			assert_true(rc == EXP_PROBE_DONE || rc == EXP_PROBE_AGAIN);
			assert_true(next >= pol.min_ms && next <= pol.max_ms);
			t = next;
		} while (rc == EXP_PROBE_AGAIN && probes < 10);
		assert_int_equal(rc, EXP_PROBE_DONE);
		assert_true(probes <= pol.max_probes);
		frame_at(&f, rate, t);
		double maxc = 0;
		for (int p = 0; p < det.npix; p++)
			maxc = fmax(maxc, f.counts[p]);
		double frac = maxc / det.full;
		print_message("peak rate %g: %d probes → %g ms, peak at %.3f of full scale\n", peak, probes, t, frac);
		if (t > pol.min_ms * 1.0001 && t < pol.max_ms * 0.9999) {
			/* dark current grows a little between probe and chosen time: within 1 % of the target */
			assert_true(frac > 0.79 && frac < 0.81);
		} else if (t >= pol.max_ms * 0.9999) {
			assert_true(frac < 0.81); /* weak source: clamped at the longest time, below target */
		} else {
			assert_true(peak * pol.min_ms > 0.8 * det.full - det.offset); /* clamped short: truly too bright */
		}
	}
	/* bad input never crashes */
	f.meas.integration_ms = 0;
	assert_int_equal(exp_probe_next(&pol, &f, NULL, det.full, 1, &rate[0], NULL), -1);
}

static void test_plan_times(void **state)
{
	(void)state;
	struct exp_policy pol;
	exp_policy_defaults(&pol);
	pol.max_exposures = 3;
	pol.hdr_ratio = 8;
	pol.low_counts = 1000;
	pol.low_quantile = 0.0;
	static struct exp_rate base;
	base.npix = 100;
	for (int p = 0; p < 100; p++) {
		base.valid[p] = 1;
		base.rate[p] = 100; /* at 10 ms: 1000 counts, enough */
	}
	double t[8];
	assert_int_equal(exp_plan_times(&pol, &base, NULL, 10, t, 8), 1);
	base.rate[17] = 100.0 / 20; /* needs 200 ms: 10 → 80 → 640 */
	assert_int_equal(exp_plan_times(&pol, &base, NULL, 10, t, 8), 3);
	assert_true(t[0] == 10 && t[1] == 80 && t[2] == 640);
	unsigned char roi[100] = { 0 };
	for (int p = 20; p < 100; p++)
		roi[p] = 1;
	assert_int_equal(exp_plan_times(&pol, &base, roi, 10, t, 8), 1); /* weak pixel outside the roi */
	base.rate[17] = 100.0 / 3; /* needs 30 ms: one more exposure */
	assert_int_equal(exp_plan_times(&pol, &base, NULL, 10, t, 8), 2);
	pol.max_ms = 50;
	base.rate[17] = 1e-3;
	assert_int_equal(exp_plan_times(&pol, &base, NULL, 10, t, 8), 2);
	assert_true(t[1] == 50); /* clamped at the longest time, then no more */
	pol.max_exposures = 1;
	assert_int_equal(exp_plan_times(&pol, &base, NULL, 10, t, 8), 1);
}

/* Merge of exposures across saturation: the recovered rate of every pixel agrees with the truth within its
 * stated uncertainty (z-scores over seeded draws), saturated pixels come only from exposures where they are
 * not saturated, and pixels saturated everywhere are invalid. */
static void test_merge_around_saturation(void **state)
{
	(void)state;
	struct exp_policy pol;
	exp_policy_defaults(&pol);
	static double rate[SPECTRO_MAX_PIXELS];
	static float sd[SPECTRO_MAX_PIXELS];
	static struct exp_avg avg;
	static struct exp_darks darks;
	static struct exp_rate er[3], merged;
	struct synth_rng r = { .s = seed ^ 0x5eed };
	peaked_rate(rate, det.npix, 6000); /* 10 ms: peak ~61500 raw, wings 12 counts/ms·t */
	const double times[3] = { 8, 64, 512 };
	double sz = 0, sz2 = 0;
	long nz = 0;
	const int draws = 40;
	for (int d = 0; d < draws; d++) {
		exp_darks_clear(&darks);
		const struct exp_rate *list[3];
		for (int k = 0; k < 3; k++) {
			synth_take(&r, &det, NULL, times[k], 20, &avg);
			const struct exp_dark *dk = exp_dark_store(&darks, &avg, 0);
			synth_take(&r, &det, rate, times[k], 20, &avg);
			synth_frame(&avg, sd);
			assert_int_equal(exp_net_rate(&pol, avg.mean, sd, avg.n, avg.saturated, det.npix, times[k], dk, det.full,
						      &er[k], NULL), 0);
			list[k] = &er[k];
		}
		assert_true(er[2].ninvalid > er[1].ninvalid && er[1].ninvalid > 0 && er[0].ninvalid == 0);
		assert_int_equal(exp_merge(list, 3, &merged, NULL), 0);
		assert_int_equal(merged.ninvalid, 0);
		for (int p = 0; p < det.npix; p++) {
			assert_true(merged.valid[p]);
			/* the pixel comes from the longest exposure in which it is valid */
			int best = er[2].valid[p] ? 2 : er[1].valid[p] ? 1 : 0;
			assert_true(merged.t_ms[p] == times[best]);
			assert_true(merged.rate[p] == er[best].rate[p]);
			double u = hypot(merged.u_noise[p], merged.u_dark[p]);
			double z = (merged.rate[p] - rate[p]) / u;
			sz += z;
			sz2 += z * z;
			nz++;
		}
	}
	double mean = sz / nz, var = sz2 / nz - mean * mean;
	print_message("merge: %ld z-scores, mean %.4f, variance %.4f\n", nz, mean, var);
	assert_true(fabs(mean) < 0.05);
	/* the std is estimated from 20 scans: z is t-distributed with 19 dof, variance 19/17 ≈ 1.12 */
	assert_true(var > 0.95 && var < 1.25);

	/* a pixel saturated in every exposure stays invalid */
	er[0].valid[5] = er[1].valid[5] = er[2].valid[5] = 0;
	const struct exp_rate *list2[3] = { &er[0], &er[1], &er[2] };
	assert_int_equal(exp_merge(list2, 3, &merged, NULL), 0);
	assert_int_equal(merged.ninvalid, 1);
	assert_false(merged.valid[5]);
	assert_true(isnan(merged.rate[5]));
	er[1].npix = 7;
	assert_int_equal(exp_merge(list2, 3, &merged, NULL), -1);
}

static void test_net_rate_rejects_saturation_and_mismatch(void **state)
{
	(void)state;
	struct exp_policy pol;
	exp_policy_defaults(&pol);
	static struct exp_avg a;
	static struct exp_darks darks;
	static struct exp_rate out;
	exp_darks_clear(&darks);
	exp_avg_init(&a, 4, 10);
	double c[4] = { 1000, 0.96 * 65535, 2000, 3000 };
	unsigned char s[4] = { 0, 0, 1, 0 };
	exp_avg_add(&a, c, NULL, 1, NULL, 10, NULL);
	const struct exp_dark *dk = exp_dark_store(&darks, &a, 0);
	assert_int_equal(exp_net_rate(&pol, c, NULL, 1, s, 4, 10, dk, 65535, &out, NULL), 0);
	assert_true(out.valid[0] && !out.valid[1] && !out.valid[2] && out.valid[3]);
	assert_int_equal(out.ninvalid, 2);
	struct acq_err err = { 0 };
	assert_int_equal(exp_net_rate(&pol, c, NULL, 1, s, 4, 20, dk, 65535, &out, &err), -1); /* dark at 10 ms */
	assert_int_equal(exp_net_rate(&pol, c, NULL, 1, s, 4, 10, NULL, 65535, &out, &err), -1);
	assert_int_equal(exp_net_rate(&pol, c, NULL, 1, s, 5000, 10, dk, 65535, &out, &err), -1);
}

static void test_dark_refresh_decisions(void **state)
{
	(void)state;
	struct exp_policy pol;
	exp_policy_defaults(&pol);
	pol.dark_max_age_s = 100;
	pol.dark_max_dtemp_c = 0.5;
	static struct exp_darks d;
	static struct exp_avg a;
	exp_darks_clear(&d);
	assert_int_equal(exp_dark_check(&d, &pol, 10, 0, 5.0), EXP_DARK_MISSING);
	exp_avg_init(&a, 8, 10);
	a.temperature_c = 5.0;
	double c[8] = { 1, 2, 3, 4, 5, 6, 7, 8 };
	exp_avg_add(&a, c, NULL, 1, NULL, 10, NULL);
	exp_dark_store(&d, &a, 1000);
	assert_int_equal(exp_dark_check(&d, &pol, 10, 1050, 5.2), EXP_DARK_FRESH);
	assert_int_equal(exp_dark_check(&d, &pol, 10, 1050, 5.6), EXP_DARK_TEMP);
	assert_int_equal(exp_dark_check(&d, &pol, 10, 1050, 4.4), EXP_DARK_TEMP);
	assert_int_equal(exp_dark_check(&d, &pol, 10, 1050, NAN), EXP_DARK_FRESH); /* unknown: age decides */
	assert_int_equal(exp_dark_check(&d, &pol, 10, 1101, 5.0), EXP_DARK_AGED);
	assert_int_equal(exp_dark_check(&d, &pol, 10.5, 1050, 5.0), EXP_DARK_MISSING);
	/* replacing refreshes; filling past capacity evicts the oldest */
	exp_dark_store(&d, &a, 1200);
	assert_int_equal(exp_dark_check(&d, &pol, 10, 1250, 5.0), EXP_DARK_FRESH);
	for (int k = 0; k < EXP_DARK_SLOTS; k++) {
		exp_avg_init(&a, 8, 20.0 + k);
		exp_avg_add(&a, c, NULL, 1, NULL, 20.0 + k, NULL);
		exp_dark_store(&d, &a, 1300 + k);
	}
	assert_null(exp_dark_find(&d, 10));
	assert_non_null(exp_dark_find(&d, 20.0 + EXP_DARK_SLOTS - 1));
	assert_string_equal(exp_dark_need_name(EXP_DARK_TEMP), "temperature");
}

static void test_policy_parse(void **state)
{
	(void)state;
	struct exp_policy p;
	exp_policy_defaults(&p);
	struct acq_err err = { 0 };
	const char *ok = "acquisition:\n  target_frac: 0.7\n  max_exposures: 2\n  averages: 5\n";
	struct yc_doc *doc = NULL;
	assert_int_equal(yc_load_string("a.yaml", ok, strlen(ok), &doc, &err), 0);
	assert_int_equal(exp_policy_parse(yc_get(yc_root(doc), "acquisition"), &p, &err), 0);
	assert_true(p.target_frac == 0.7 && p.max_exposures == 2 && p.averages == 5);
	yc_free(doc);
	const char *bad = "acquisition:\n  target_frac: 0.99\n  sat_frac: 0.9\n";
	assert_int_equal(yc_load_string("b.yaml", bad, strlen(bad), &doc, &err), 0);
	struct exp_policy before = p;
	assert_int_equal(exp_policy_parse(yc_get(yc_root(doc), "acquisition"), &p, &err), -1);
	assert_non_null(strstr(err.msg, "b.yaml:2:"));
	assert_true(p.target_frac == before.target_frac);
	yc_free(doc);
}

/* The probe pooled into the exposure (exp_probe_reusable, exp_frame_pool; executor_acq.c): a one-scan probe at the
 * exposure's own time is one more scan of it. With the simulator's noise model (sim_physics.c phys_measure: each
 * scan Gaussian about its mean with the shot and read noise, rounded; a device-averaged frame carries the mean and the
 * sample std over its scans, as a float) the probe + a frame of N − 1 scans pooled is the N-scan frame itself (mean
 * to 1e-9, std to float precision), and its net rates stand against the truth as an N-scan exposure's: z mean 0, std
 * 1, and the pooled noise variance unbiased (tolerances: 5σ of those statistics over the values drawn). */
static void test_probe_pooled_is_one_more_scan(void **state)
{
	(void)state;
	struct synth_rng r = { .s = seed ^ 0x5eedu };
	struct exp_policy pol;
	exp_policy_defaults(&pol);
	enum { N = 4, TRIALS = 24 };
	const double t = 8.0, fs = det.full;
	static double rate[SPECTRO_MAX_PIXELS];
	peaked_rate(rate, det.npix, 3000.0); /* peak 24000 + offset: unsaturated at 8 ms */
	static struct spectro_frame probe, frame;
	static struct exp_avg a, dk;
	static struct exp_darks darks;
	static struct exp_rate out;
	static double sc[N][SPECTRO_MAX_PIXELS];
	exp_darks_clear(&darks);
	double zs = 0, zs2 = 0, vr = 0;
	long nz = 0;
	for (int trial = 0; trial < TRIALS; trial++) {
		synth_take(&r, &det, NULL, t, 8, &dk); /* a dark of 8 scans per trial: the values are independent */
		const struct exp_dark *dark = exp_dark_store(&darks, &dk, 0);
		for (int k = 0; k < N; k++)
			for (int p = 0; p < det.npix; p++) {
				double sig = rate[p] * t, mean = det.offset + det.dc_per_ms * t + sig;
				double sd = sqrt(det.read_sigma * det.read_sigma + sig + det.dc_per_ms * t);
				sc[k][p] = floor(mean + sd * synth_gauss(&r) + 0.5);
			}
		memset(&probe, 0, sizeof probe);
		memset(&frame, 0, sizeof frame);
		probe.npix = frame.npix = det.npix;
		probe.meas = (struct spectro_meas){ t, 1, true };
		frame.meas = (struct spectro_meas){ t, N - 1, true };
		for (int p = 0; p < det.npix; p++) {
			probe.counts[p] = sc[0][p];
			double m = (sc[1][p] + sc[2][p] + sc[3][p]) / 3, ss = 0;
			for (int k = 1; k < N; k++)
				ss += (sc[k][p] - m) * (sc[k][p] - m);
			frame.counts[p] = m;
			frame.stddev[p] = (float)sqrt(ss / 2);
		}
		assert_true(exp_probe_reusable(&pol, &probe, fs, t));
		assert_int_equal(exp_frame_pool(&a, &frame, &probe, NULL), 0);
		assert_int_equal(frame.meas.averages, N);
		for (int p = 0; p < det.npix; p++) {
			double m = (sc[0][p] + sc[1][p] + sc[2][p] + sc[3][p]) / N, ss = 0;
			for (int k = 0; k < N; k++)
				ss += (sc[k][p] - m) * (sc[k][p] - m);
			double sd = sqrt(ss / (N - 1));
			assert_true(fabs(frame.counts[p] - m) < 1e-9 * m);
			assert_true(fabs(frame.stddev[p] - sd) <= 1e-5 * sd + 1e-6);
		}
		assert_int_equal(exp_net_rate(&pol, frame.counts, frame.stddev, frame.meas.averages, frame.saturated,
					      frame.npix, t, dark, fs, &out, NULL), 0);
		for (int p = 0; p < det.npix; p++) {
			double sig = rate[p] * t;
			double s_scan = sqrt(det.read_sigma * det.read_sigma + sig + det.dc_per_ms * t) / sqrt(N) / t;
			double s_dark = sqrt(det.read_sigma * det.read_sigma + det.dc_per_ms * t) / sqrt(8.0) / t;
			double z = (out.rate[p] - rate[p]) / sqrt(s_scan * s_scan + s_dark * s_dark);
			zs += z;
			zs2 += z * z;
			vr += out.u_noise[p] * out.u_noise[p] / (s_scan * s_scan);
			nz++;
		}
	}
	double zm = zs / nz, zsd = sqrt(zs2 / nz - zm * zm);
	print_message("  pooled N=%d: %ld values, z mean %.4f std %.4f, u_noise^2 / truth %.4f\n", N, nz, zm, zsd, vr / nz);
	assert_true(fabs(zm) < 5 / sqrt((double)nz));
	assert_true(fabs(zsd - 1) < 5 / sqrt(2.0 * nz));
	assert_true(fabs(vr / nz - 1) < 5 * sqrt(2.0 / (N - 1) / nz));
	/* the rule: at the exposure's own time only, one unsaturated scan */
	assert_false(exp_probe_reusable(&pol, &probe, fs, t * M_SQRT2)); /* the next rung */
	assert_false(exp_probe_reusable(&pol, &probe, fs, t / M_SQRT2));
	probe.saturated[17] = 1;
	probe.nsaturated = 1;
	assert_false(exp_probe_reusable(&pol, &probe, fs, t)); /* flagged saturated */
	probe.saturated[17] = 0;
	probe.nsaturated = 0;
	probe.counts[17] = pol.sat_frac * fs; /* raw counts in the nonlinear region */
	assert_false(exp_probe_reusable(&pol, &probe, fs, t));
	probe.counts[17] = 1000;
	probe.meas.averages = 2; /* not one scan */
	assert_false(exp_probe_reusable(&pol, &probe, fs, t));
	probe.meas.averages = 1;
	assert_true(exp_probe_reusable(&pol, &probe, fs, t));
	/* pooling needs the same time and pixels; a frame with no std (0: unknown) keeps it unknown */
	struct acq_err err = { 0 };
	frame.meas.integration_ms = 2 * t;
	assert_int_equal(exp_frame_pool(&a, &frame, &probe, &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
	frame.meas = (struct spectro_meas){ t, N - 1, true };
	memset(frame.stddev, 0, sizeof frame.stddev);
	assert_int_equal(exp_frame_pool(&a, &frame, &probe, NULL), 0);
	assert_true(frame.stddev[100] == 0 && frame.meas.averages == N);
}

int main(void)
{
	seed = synth_seed("test_exposure");
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_avg_chan_equals_direct),
		cmocka_unit_test(test_auto_exposure_converges_to_target),
		cmocka_unit_test(test_plan_times),
		cmocka_unit_test(test_merge_around_saturation),
		cmocka_unit_test(test_net_rate_rejects_saturation_and_mismatch),
		cmocka_unit_test(test_dark_refresh_decisions),
		cmocka_unit_test(test_policy_parse),
		cmocka_unit_test(test_probe_pooled_is_one_more_scan),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
