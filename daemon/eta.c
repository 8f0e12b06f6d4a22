/* eta: remaining wall-clock time of a sweep (see eta.h). The planner's figure is in bench seconds: it is
 * divided by the measured ratio of the loop's clock to the real one (the simulator's time scale, 1 on a real
 * bench); then every point left gets the time per point the sweep has measured beyond the plan (running time
 * only), with the weight n/(n + 5) after n measured points (the plan alone at first). The excess is added per
 * point, not as a ratio: what the plan misses is a cost per point (the host's time, which a loaded machine
 * stretches; an auto-exposure sample that needs longer exposures than the plan's estimate, and the darks and
 * HDR exposures that follow), whereas a ratio would also stretch the long moves the plan times well.
 * The excess per point is a recent average, not the sweep's whole mean: each measured interval of k points weighs
 * 1 - exp(-k/M) in the averages of its real and planned seconds per point, the older ones' weights decayed by
 * exp(-k/M), the averages normalised by the weights' sum (so the first intervals weigh alike; before session 10
 * the first one stood for all the history before it and weighed 0.9 after the second: an incidence's first
 * point, darks the model prices by expectation, then swung a short sweep's ETA by 10 %), M = an
 * eighth of the sweep's points (at least 10, at most 120): the host's time drifts along a long sweep (a machine
 * loaded, then not; measured at time scale 35: one incidence of the paper's plan 15 % slower than another), and
 * the mean of the whole past keeps the early rate for the rest of the sweep; an eighth of the sweep still averages
 * over about one incidence (the paper's 10x10x10: 108 points), so the darks and HDR exposures that cluster at some
 * viewing angles do not swing it much. Replayed on nine first sweeps of session 7 the two differ little (19 vs 20
 * of 27 checkpoints within 5 %); on repeats whose first half the previous sweep's reconstruction slowed, the recent
 * average halves the error at 50 and 75 % (tests/bench/bench_duration.py, the notes of session 8).
 * The host's part of the excess is robust (session 14): a point's real time splits into its bench work (the
 * exposures it took as the planner prices them and its planned moves, eta_work, at the time scale) and the host's
 * time, and the excess is the recent average less the host's recent average plus the median of the host's time over
 * the recent memory's last M points. A loaded burst shorter than M/2 points (the paper plan at time scale 35: 25 ms
 * per point instead of 5-13 for some tens of points, session 13) then does not swing the ETA of the rest; a change
 * that lasts is followed within M/2 points. The median is not taken of the excess itself: the model prices darks
 * and HDR exposures by their expectation per point, so the excess of most points is below its mean (the paper
 * plan: 97 darks of about 1 bench s over 866 points), and its median would be biased by a few ms per point.
 * Without a plan: the measured time per point times the points left. */
#include "daemon/eta.h"

#include <math.h>
#include <stdlib.h>

#define ETA_PLAN_WEIGHT 5.0   /* points of measurement worth as much as the plan's own estimate */
#define ETA_MEMORY_FRACTION 0.125 /* the recent average's memory, as a fraction of the sweep's points */
#define ETA_MEMORY_MIN 10.0
#define ETA_MEMORY_MAX 120.0

void eta_reset(struct eta *e)
{
	*e = (struct eta){ .t0_loop = NAN, .t0_real = NAN, .scale = 1, .last_real = NAN, .last_plan = NAN,
			   .recent_real = NAN, .recent_plan = NAN, .recent_work = NAN, .work_now = NAN,
			   .work_last = NAN };
}

static void clocks(struct eta *e, double loop_now, double real_now)
{
	if (!isfinite(e->t0_real)) {
		e->t0_loop = loop_now;
		e->t0_real = real_now;
	} else if (real_now - e->t0_real > 0.5) {
		double s = (loop_now - e->t0_loop) / (real_now - e->t0_real);
		if (s > 0 && isfinite(s))
			e->scale = s;
	}
}

void eta_running(struct eta *e, bool running, double loop_now, double real_now)
{
	clocks(e, loop_now, real_now);
	e->last_real = running ? real_now : NAN;
	e->skip = running;
}

/* The weighted average x of weights' sum wsum after a new value v of weight w (the older ones' weights decayed by
 * 1 - w). */
static double mix(double x, double wsum, double w, double v)
{
	return wsum > 0 ? ((1 - w) * wsum * x + w * v) / ((1 - w) * wsum + w) : v;
}

/* The recent averages' memory for a sweep of total points. */
static double memory(int total)
{
	return fmin(fmax(ETA_MEMORY_FRACTION * total, ETA_MEMORY_MIN), ETA_MEMORY_MAX);
}

/* Re-timing: the plan's seconds of the measured intervals are replayed in the new plan with the weights recent()
 * gave them, not dropped. Dropping them (session 10, first version) restarted the excess from the next few points
 * alone, which the model prices least well (an incidence's first points, where the dark model puts the darks of
 * rungs the sample visits later): on the paper plan at time scale 35 the ETA fell from +1.7 % at the re-timing to
 * -25 % ten points later. A ratio of the two plans over the last points does not replay the weights (in
 * test_sweep_retime: +11 % where the replay gives -0.6 %). */
void eta_replan(struct eta *e, double (*plan_at)(const void *ctx, int step), const void *ctx)
{
	e->skip = true;
	if (e->hist_n <= 0 || !isfinite(e->recent_plan))
		return;
	long first = e->hist_n > ETA_HISTORY ? e->hist_n - ETA_HISTORY : 0;
	double m = memory(e->total), x = 0, wsum = 0;
	for (long i = first; i < e->hist_n; i++) {
		int from = e->hist[i % ETA_HISTORY].from, to = e->hist[i % ETA_HISTORY].to, k = to - from;
		double w = 1 - exp(-k / m), v = (plan_at(ctx, to) - plan_at(ctx, from)) / k;
		x = mix(x, wsum, w, v);
		wsum = (1 - w) * wsum + w;
	}
	if (isfinite(x))
		e->recent_plan = x;
}

/* The recent averages per point after an interval of k points that took real_s running for plan_s of the plan.
 * Real and plan seconds are averaged apart and compared at the current scale: the scale is measured over the
 * sweep's first half second, and the first points may come before it is known. */
static void recent(struct eta *e, int from, int k, double real_s, double plan_s, int total)
{
	if (!isfinite(real_s) || !isfinite(plan_s))
		return;
	e->hist[e->hist_n % ETA_HISTORY].from = from;
	e->hist[e->hist_n % ETA_HISTORY].to = from + k;
	e->hist_n++;
	double w = 1 - exp(-k / memory(total)); /* the interval's weight; the older ones' decay by 1 - w */
	if (!isfinite(e->recent_real))
		e->recent_w = 0;
	e->recent_real = mix(e->recent_real, e->recent_w, w, real_s / k);
	e->recent_plan = mix(e->recent_plan, e->recent_w, w, plan_s / k);
	e->recent_w = (1 - w) * e->recent_w + w;
}

void eta_work(struct eta *e, double work_s)
{
	e->work_now = work_s;
}

/* An interval of k points that took real_s real seconds for work_s of bench work: into the window and the recent
 * average of the bench work (the interval's weight as recent() gives it). Unknown work (NAN): both forgotten, the
 * excess is the plain recent average until the host is measured again. */
static void host_sample(struct eta *e, int k, double real_s, double work_s, int total)
{
	if (!isfinite(work_s) || work_s < 0) {
		e->host_n = 0;
		e->recent_work = NAN;
		return;
	}
	for (int i = 0; i < k && i < ETA_HOST_WINDOW; i++) {
		e->host[e->host_n % ETA_HOST_WINDOW].real = (float)(real_s / k);
		e->host[e->host_n++ % ETA_HOST_WINDOW].work = (float)(work_s / k);
	}
	double w = 1 - exp(-k / memory(total));
	if (!isfinite(e->recent_work))
		e->work_w = 0;
	e->recent_work = mix(e->recent_work, e->work_w, w, work_s / k);
	e->work_w = (1 - w) * e->work_w + w;
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

/* The host's time per point (real s) over the last M points (M the recent memory, fewer at the start), at the
 * current scale, into v[0..M-1]; M (0: none yet). */
static long host_recent(const struct eta *e, double v[ETA_HOST_WINDOW])
{
	long m = lround(memory(e->total));
	if (m > ETA_HOST_WINDOW)
		m = ETA_HOST_WINDOW;
	if (m > e->host_n)
		m = e->host_n;
	for (long i = 0; i < m; i++) {
		long j = (e->host_n - m + i) % ETA_HOST_WINDOW;
		v[i] = (double)e->host[j].real - (double)e->host[j].work / e->scale;
	}
	return m > 0 ? m : 0;
}

/* The median of host_recent's times. */
static double host_median(const struct eta *e)
{
	double v[ETA_HOST_WINDOW];
	long m = host_recent(e, v);
	if (m <= 0)
		return NAN;
	qsort(v, (size_t)m, sizeof *v, cmp_double);
	return m % 2 ? v[m / 2] : 0.5 * (v[m / 2 - 1] + v[m / 2]);
}

double eta_update(struct eta *e, int done, int total, double plan_at_s, double plan_total_s, double loop_now,
		  double real_now)
{
	clocks(e, loop_now, real_now);
	e->total = total;
	if (isfinite(e->last_real) && !e->skip && done > e->last_done) {
		double real_s = real_now - e->last_real;
		double plan_s = isfinite(plan_at_s) && isfinite(e->last_plan) ? plan_at_s - e->last_plan : NAN;
		e->run_real += real_s;
		e->run_plan += plan_s;
		e->measured += done - e->last_done;
		recent(e, e->last_done, done - e->last_done, real_s, plan_s, total);
		host_sample(e, done - e->last_done, real_s, e->work_now - e->work_last, total); /* NAN: unknown */
	}
	e->work_last = e->work_now;
	e->work_now = NAN;
	e->skip = false;
	e->last_real = real_now;
	e->last_plan = plan_at_s;
	e->last_done = done;
	int left = total - done;
	if (left <= 0)
		return 0;
	bool plan = isfinite(plan_at_s) && isfinite(plan_total_s) && plan_total_s >= plan_at_s;
	if (!plan)
		return e->measured > 0 ? e->run_real / e->measured * left : NAN;
	double plan_left = (plan_total_s - plan_at_s) / e->scale;
	if (e->measured <= 0 || !(e->run_plan > 0) || !isfinite(e->recent_real))
		return plan_left;
	double w = e->measured / (e->measured + ETA_PLAN_WEIGHT);
	double excess = e->recent_real - e->recent_plan / e->scale; /* real s per point beyond the plan, recently */
	double hm = host_median(e);
	if (isfinite(hm) && isfinite(e->recent_work)) /* the host's part: its median, not its recent average */
		excess += hm - (e->recent_real - e->recent_work / e->scale);
	double t = plan_left + w * excess * left;
	return t > 0 ? t : 0;
}

void eta_forget(struct eta *e)
{
	e->recent_real = e->recent_plan = e->recent_work = NAN;
	e->recent_w = e->work_w = 0;
	e->hist_n = 0;
	e->run_real = e->run_plan = 0;
	e->measured = 0;
	e->skip = true;
}

double eta_host(const struct eta *e)
{
	/* the mean, not host_median: a plan's host figure is what the points take on average, bursts included (the
	 * green paint's paper sweep at load 10: the median 6.6 ms per point, the mean 11.0; priced at the median the
	 * ETA right after the survey was -10 %) */
	double v[ETA_HOST_WINDOW], s = 0;
	long m = host_recent(e, v);
	if (m <= 0)
		return NAN;
	for (long i = 0; i < m; i++)
		s += v[i];
	return s / (double)m;
}
