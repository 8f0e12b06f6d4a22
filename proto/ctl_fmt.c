/* ctl_fmt: acqctl's human output — readable values and one rendering per reply (see ctl.h). */
#include "proto/ctl.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

void ctl_fmt_time(double t, char *buf, size_t cap)
{
	if (!isfinite(t) || t <= 0) {
		snprintf(buf, cap, "-");
		return;
	}
	time_t s = (time_t)floor(t);
	struct tm tm;
	if (!localtime_r(&s, &tm)) {
		snprintf(buf, cap, "-");
		return;
	}
	char date[32];
	strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%S", &tm);
	long off = tm.tm_gmtoff;
	char sign = off < 0 ? '-' : '+';
	off = labs(off);
	snprintf(buf, cap, "%s%c%02ld:%02ld", date, sign, off / 3600, (off / 60) % 60);
}

void ctl_fmt_dur(double s, char *buf, size_t cap)
{
	if (!isfinite(s) || s < 0)
		snprintf(buf, cap, "-");
	else if (s < 10)
		snprintf(buf, cap, "%.3g s", s);
	else {
		long long t = (long long)(s + 0.5);
		snprintf(buf, cap, "%lld:%02lld:%02lld", t / 3600, (t / 60) % 60, t % 60);
	}
}

void ctl_fmt_angle(double deg, char *buf, size_t cap)
{
	if (!isfinite(deg))
		snprintf(buf, cap, "-");
	else
		snprintf(buf, cap, "%.2f°", fabs(deg) < 0.005 ? 0.0 : deg);
}

static bool ends_with(const char *s, const char *suf)
{
	size_t a = strlen(s), b = strlen(suf);
	return a >= b && !strcmp(s + a - b, suf);
}

static bool is_axis(const char *k)
{
	static const char *const axes[] = { "laser_theta", "detector_theta", "detector_phi", "theta_i", "phi_i",
					    "theta_o", "phi_o", "position", "laser.theta", "detector.theta",
					    "detector.phi", NULL };
	for (int i = 0; axes[i]; i++)
		if (!strcmp(k, axes[i]))
			return true;
	return false;
}

static void fmt_number(const char *key, double x, char *buf, size_t cap)
{
	const char *k = key ? key : "";
	if (ends_with(k, "_at"))
		ctl_fmt_time(x, buf, cap);
	else if (ends_with(k, "_s"))
		ctl_fmt_dur(x, buf, cap);
	else if (ends_with(k, "_deg") || is_axis(k))
		ctl_fmt_angle(x, buf, cap);
	else if (ends_with(k, "_ms"))
		snprintf(buf, cap, "%.4g ms", x);
	else if (ends_with(k, "_nm"))
		snprintf(buf, cap, "%.4g nm", x);
	else if (ends_with(k, "_pct"))
		snprintf(buf, cap, "%.4g %%", x);
	else if (ends_with(k, "_mm"))
		snprintf(buf, cap, "%.4g mm", x);
	else
		snprintf(buf, cap, "%.6g", x);
}

void ctl_fmt_value(const char *key, json_t *v, char *buf, size_t cap)
{
	if (!v || json_is_null(v))
		snprintf(buf, cap, "-");
	else if (json_is_string(v))
		snprintf(buf, cap, "%s", json_string_value(v));
	else if (json_is_boolean(v))
		snprintf(buf, cap, "%s", json_is_true(v) ? "yes" : "no");
	else if (json_is_integer(v) && !(key && (ends_with(key, "_at") || ends_with(key, "_s"))))
		snprintf(buf, cap, "%lld", (long long)json_integer_value(v));
	else if (json_is_number(v))
		fmt_number(key, json_number_value(v), buf, cap);
	else if (json_is_array(v)) {
		size_t i, n = 0;
		json_t *x;
		buf[0] = 0;
		json_array_foreach(v, i, x) {
			char one[96];
			ctl_fmt_value(key, x, one, sizeof one);
			n += (size_t)snprintf(buf + (n < cap ? n : cap), n < cap ? cap - n : 0, "%s%s", i ? ", " : "", one);
		}
		if (!json_array_size(v))
			snprintf(buf, cap, "(none)");
	} else {
		char *s = json_dumps(v, JSON_COMPACT);
		snprintf(buf, cap, "%s", s ? s : "?");
		free(s);
	}
}

/* Each line of text on its own line after indent. */
static void print_lines(FILE *f, const char *indent, const char *text)
{
	for (const char *l = text, *nl; *l; l = nl + 1) {
		nl = strchr(l, '\n');
		fprintf(f, "%s%.*s\n", indent, nl ? (int)(nl - l) : (int)strlen(l), l);
		if (!nl)
			break;
	}
}

/* ---- generic rendering: "key: value" with nested keys dotted, arrays of objects indexed ---- */
static void print_tree(FILE *f, const char *prefix, const char *key, json_t *v)
{
	const char *k;
	json_t *x;
	size_t i;
	char p[256];
	if (json_is_object(v)) {
		json_object_foreach(v, k, x) {
			snprintf(p, sizeof p, "%s%s%s", prefix, *prefix ? "." : "", k);
			print_tree(f, p, k, x);
		}
	} else if (json_is_array(v) && json_array_size(v) && json_is_object(json_array_get(v, 0))) {
		json_array_foreach(v, i, x) {
			snprintf(p, sizeof p, "%s[%zu]", prefix, i);
			print_tree(f, p, key, x);
		}
	} else {
		char val[1024];
		ctl_fmt_value(key, v, val, sizeof val);
		if (strchr(val, '\n')) { /* multi-line text (plan text): indented below its key */
			fprintf(f, "%s:\n", prefix);
			print_lines(f, "    ", val);
		} else {
			fprintf(f, "%s: %s\n", prefix, val);
		}
	}
}

/* Columns by characters, not bytes ("°", "θ" are two bytes in UTF-8): s padded to width (negative: right
 * aligned) into buf. */
static const char *pad(const char *s, int width, char *buf, size_t cap)
{
	int chars = 0;
	for (const char *p = s; *p; p++)
		chars += ((unsigned char)*p & 0xc0) != 0x80;
	int w = width < 0 ? -width : width, fill = chars < w ? w - chars : 0;
	if (width < 0)
		snprintf(buf, cap, "%*s%s", fill, "", s);
	else
		snprintf(buf, cap, "%s%*s", s, fill, "");
	return buf;
}

static const char *str(json_t *o, const char *k)
{
	const char *s = json_string_value(json_object_get(o, k));
	return s ? s : "";
}

static long long num_i(json_t *o, const char *k)
{
	json_t *v = json_object_get(o, k);
	return json_is_number(v) ? (long long)json_number_value(v) : 0;
}

static double num(json_t *o, const char *k)
{
	json_t *v = json_object_get(o, k);
	return json_is_number(v) ? json_number_value(v) : NAN;
}

/* "sweep 3 running: 120/866 points (13.9 %), ETA 0:10:05 — message" from a progress object. */
static void print_progress(FILE *f, const char *label, json_t *p)
{
	const char *state = str(p, "state");
	long long id = num_i(p, "id");
	if (!id) {
		fprintf(f, "%-10s %s\n", label, state[0] ? state : "idle");
		return;
	}
	long long done = num_i(p, "done"), total = num_i(p, "total");
	char eta[32];
	ctl_fmt_dur(num(p, "eta_s"), eta, sizeof eta);
	fprintf(f, "%-10s %lld %s: %lld/%lld points (%.1f %%)", label, id, state, done, total,
		total > 0 ? 100.0 * (double)done / (double)total : 0.0);
	if (!strcmp(state, "running") && strcmp(eta, "-")) {
		fprintf(f, ", ETA %s", eta);
		if (json_is_number(json_object_get(p, "eta_low_s")) && json_is_number(json_object_get(p, "eta_high_s"))) {
			char lo[32], hi[32]; /* the rest's exposures not all known yet */
			ctl_fmt_dur(num(p, "eta_low_s"), lo, sizeof lo);
			ctl_fmt_dur(num(p, "eta_high_s"), hi, sizeof hi);
			fprintf(f, " (%s to %s)", lo, hi);
		}
	}
	if (json_is_true(json_object_get(p, "pause_pending")))
		fprintf(f, ", pausing after this point");
	const char *msg = str(p, "message");
	if (msg[0])
		fprintf(f, " — %s", msg);
	fputc('\n', f);
}

static void print_status(FILE *f, json_t *r)
{
	char up[32], since[48];
	ctl_fmt_dur(num(r, "uptime_s"), up, sizeof up);
	ctl_fmt_time(num(r, "started_at"), since, sizeof since);
	fprintf(f, "%-10s %s, version %s, pid %lld%s, up %s since %s\n", "daemon", str(r, "daemon"), str(r, "version"),
		num_i(r, "pid"), json_is_true(json_object_get(r, "sim")) ? " (simulated bench)" : "", up, since);
	print_progress(f, "sweep", json_object_get(r, "sweep"));
	json_t *d = json_object_get(r, "devices");
	fprintf(f, "%-10s %lld of %lld available\n", "devices", num_i(d, "available"), num_i(d, "total"));
	fprintf(f, "%-10s %lld connected, %lld watching\n", "clients", num_i(r, "clients"), num_i(r, "watchers"));
	json_t *rc = json_object_get(r, "recon");
	if (json_is_true(json_object_get(rc, "running")))
		fprintf(f, "%-10s running: run %lld of sweep %lld\n", "recon", num_i(rc, "run"), num_i(rc, "sweep"));
	else if (num_i(rc, "run"))
		fprintf(f, "%-10s idle (last: run %lld of sweep %lld)\n", "recon", num_i(rc, "run"), num_i(rc, "sweep"));
	else
		fprintf(f, "%-10s idle\n", "recon");
}

static void print_devices(FILE *f, json_t *arr)
{
	fprintf(f, "%-16s %-15s %-12s %s\n", "DEVICE", "STATE", "POSITION", "IDENTITY / NOTE");
	size_t i;
	json_t *d;
	json_array_foreach(arr, i, d) {
		json_t *st = json_object_get(d, "status"), *id = json_object_get(d, "identity");
		char pos[48] = "-";
		if (json_is_number(json_object_get(st, "position_deg")))
			ctl_fmt_angle(num(st, "position_deg"), pos, sizeof pos);
		else if (json_is_boolean(json_object_get(st, "emission")))
			snprintf(pos, sizeof pos, "%s %.0f %%", json_is_true(json_object_get(st, "emission")) ? "on" : "off",
				 num(st, "power_pct"));
		char ident[256] = "";
		if (id) /* a device that does not say its vendor (the simulated laser): the model alone */
			snprintf(ident, sizeof ident, "%s%s%s, serial %s, firmware %s", str(id, "vendor"),
				 str(id, "vendor")[0] ? " " : "", str(id, "model"), str(id, "serial"), str(id, "firmware"));
		const char *note = str(d, "note");
		char pp[64];
		fprintf(f, "%-16s %-15s %s %s%s%s\n", str(d, "name"), str(d, "state"), pad(pos, 12, pp, sizeof pp), ident,
			ident[0] && note[0] ? "; " : "", note);
	}
}

static void print_sweep_list(FILE *f, json_t *arr)
{
	fprintf(f, "%5s  %-10s %-25s %-25s %9s  %s\n", "ID", "STATE", "CREATED", "FINISHED", "POINTS", "NAME");
	size_t i;
	json_t *s;
	json_array_foreach(arr, i, s) {
		char created[48], fin[48], pts[32];
		ctl_fmt_time(num(s, "created_at"), created, sizeof created);
		ctl_fmt_time(num(s, "finished_at"), fin, sizeof fin);
		snprintf(pts, sizeof pts, "%lld/%lld", num_i(s, "points_done"), num_i(s, "points_total"));
		fprintf(f, "%5lld  %-10s %-25s %-25s %9s  %s\n", num_i(s, "id"), str(s, "state"), created, fin, pts,
			str(s, "name"));
	}
	if (!json_array_size(arr))
		fprintf(f, "(no sweeps)\n");
}

/* An adaptive sweep's decisions (sweep.show's "adaptive" rows): per batch its points, the target's value from the
 * model the decision used, select's predicted value after the batch, the picks' summed predicted gain, the arms'
 * wait and the model; then why the sweep stopped. */
static void print_adaptive_decisions(FILE *f, json_t *rows)
{
	if (!json_array_size(rows))
		return;
	fprintf(f, "  decisions (adaptive, target %s):\n", str(json_array_get(rows, 0), "target_spec"));
	fprintf(f, "  %5s %6s %12s %12s %10s %8s  %s\n", "BATCH", "POINTS", "VALUE", "PREDICTED", "GAIN", "WAITED",
		"MODEL");
	size_t i, j;
	json_t *r, *p;
	json_array_foreach(rows, i, r) {
		const char *why = str(r, "stop_reason");
		if (why[0]) {
			fprintf(f, "  stop after batch %lld: %s\n", num_i(r, "batch") - 1, why);
			continue;
		}
		double gain = 0;
		size_t ng = 0;
		json_array_foreach(json_object_get(r, "picks"), j, p)
			if (json_is_number(json_object_get(p, "gain")) && json_is_integer(json_object_get(p, "order_index"))) {
				gain += num(p, "gain");
				ng++;
			}
		char v[24] = "seed", pv[24] = "-", g[24] = "-", w[24] = "-";
		if (isfinite(num(r, "target_value")))
			snprintf(v, sizeof v, "%.6g", num(r, "target_value"));
		if (isfinite(num(r, "predicted_value")))
			snprintf(pv, sizeof pv, "%.6g", num(r, "predicted_value"));
		if (ng)
			snprintf(g, sizeof g, "%.3g", gain);
		if (isfinite(num(r, "waited_s")))
			snprintf(w, sizeof w, "%.1f s", num(r, "waited_s"));
		const char *model = str(r, "model");
		fprintf(f, "  %5lld %6lld %12s %12s %10s %8s  %s%s\n", num_i(r, "batch"), num_i(r, "n_points"), v, pv, g, w,
			model[0] ? model : "-", num_i(r, "warm") == 1 ? " (warm)" : "");
	}
}

static void print_sweep_show(FILE *f, json_t *s)
{
	char a[48], b[48], c[48];
	ctl_fmt_time(num(s, "created_at"), a, sizeof a);
	ctl_fmt_time(num(s, "started_at"), b, sizeof b);
	ctl_fmt_time(num(s, "finished_at"), c, sizeof c);
	fprintf(f, "sweep %lld \"%s\": %s\n", num_i(s, "id"), str(s, "name"), str(s, "state"));
	fprintf(f, "  created %s, started %s, finished %s\n", a, b, c);
	double t0 = num(s, "started_at"), t1 = num(s, "finished_at");
	if (t0 > 0 && t1 >= t0) {
		ctl_fmt_dur(t1 - t0, a, sizeof a);
		fprintf(f, "  took %s\n", a);
	}
	fprintf(f, "  points %lld/%lld done, %lld spectra, %lld calibrated samples (%s)\n", num_i(s, "points_done"),
		num_i(s, "points_total"), num_i(s, "spectra"), num_i(s, "calibrated"), str(s, "calibration_method"));
	fprintf(f, "  software %s\n", str(s, "software_version"));
	json_t *ev = json_object_get(s, "events");
	if (json_array_size(ev)) {
		fprintf(f, "  events (latest first):\n");
		size_t i;
		json_t *e;
		json_array_foreach(ev, i, e) {
			ctl_fmt_time(num(e, "at"), a, sizeof a);
			const char *dev = str(e, "device");
			fprintf(f, "    %s  %-10s %s%s%s\n", a, str(e, "kind"), dev, dev[0] ? ": " : "", str(e, "message"));
		}
	}
	json_t *pts = json_object_get(s, "points");
	if (json_is_array(pts)) {
		fprintf(f, "  %5s %5s %s %s %s  %s\n", "ORDER", "ID", "       θi", "       θo", "       φo", "STATE");
		size_t i;
		json_t *p;
		json_array_foreach(pts, i, p) {
			char ti[24], to[24], po[24];
			ctl_fmt_angle(num(p, "theta_i"), ti, sizeof ti);
			ctl_fmt_angle(num(p, "theta_o"), to, sizeof to);
			ctl_fmt_angle(num(p, "phi_o"), po, sizeof po);
			char a1[32], a2[32], a3[32];
			fprintf(f, "  %5lld %5lld %s %s %s  %s\n", num_i(p, "order_index"), num_i(p, "id"),
				pad(ti, -9, a1, sizeof a1), pad(to, -9, a2, sizeof a2), pad(po, -9, a3, sizeof a3),
				str(p, "state"));
		}
	}
	print_adaptive_decisions(f, json_object_get(s, "adaptive"));
	const char *plan = str(s, "plan_text");
	if (plan[0]) {
		fprintf(f, "  plan:\n");
		print_lines(f, "    ", plan);
	}
}

static void pos3(json_t *p, char *buf, size_t cap)
{
	char a[24], b[24], c[24];
	bool old = !json_object_get(p, "laser.theta"); /* a daemon of before the renames: theta_i, theta_o, phi_o */
	ctl_fmt_angle(num(p, old ? "theta_i" : "laser.theta"), a, sizeof a);
	ctl_fmt_angle(num(p, old ? "theta_o" : "detector.theta"), b, sizeof b);
	ctl_fmt_angle(num(p, old ? "phi_o" : "detector.phi"), c, sizeof c);
	snprintf(buf, cap, "(θi %s, θo %s, φo %s)", a, b, c);
}

void ctl_print_plan(FILE *f, json_t *r)
{
	char a[32], b[32], c[32];
	fprintf(f, "plan %s (bench %s)\n", str(r, "plan"), str(r, "bench_config"));
	fprintf(f, "  requested %lld: kept %lld, moved %lld, dropped %lld, duplicates merged %lld; %lld to measure at "
		   "%lld incidences\n",
		num_i(r, "requested"), num_i(r, "kept"), num_i(r, "moved"), num_i(r, "dropped"), num_i(r, "duplicates"),
		num_i(r, "measured"), num_i(r, "incidences"));
	json_t *ad = json_object_get(r, "adaptive");
	if (json_is_object(ad)) {
		ctl_fmt_dur(num(ad, "worst_case_s"), a, sizeof a);
		fprintf(f, "  adaptive: the points above are the seed; then batches of %lld until %s (select's target), "
			   "the budget (%s%s%s) or nothing reachable is left; worst case %s, %lld points\n",
			num_i(ad, "batch"), str(ad, "target"),
			json_is_number(json_object_get(ad, "budget_s")) ? (ctl_fmt_dur(num(ad, "budget_s"), b, sizeof b), b)
									 : "no time limit",
			json_is_number(json_object_get(ad, "budget_points")) ? ", points " : "",
			json_is_number(json_object_get(ad, "budget_points"))
				? (snprintf(c, sizeof c, "%lld", num_i(ad, "budget_points")), c) : "",
			a, num_i(ad, "worst_case_points"));
	}
	if (json_is_number(json_object_get(r, "predicted_s"))) {
		ctl_fmt_dur(num(r, "predicted_s"), a, sizeof a);
		ctl_fmt_dur(num(r, "reference_s"), b, sizeof b);
		ctl_fmt_dur(num(r, "darks_s"), c, sizeof c);
		fprintf(f, "  predicted sweep time %s (reference %s, darks %s", a, b, c);
		if (json_is_number(json_object_get(r, "host_s"))) { /* the host's time per point, load-dependent */
			ctl_fmt_dur(num(r, "host_s"), c, sizeof c);
			fprintf(f, ", host %s", c);
		}
		fputs(" included)", f);
		double ts = num(r, "time_scale");
		if (ts > 0 && ts != 1) {
			ctl_fmt_dur(num(r, "predicted_s") / ts, a, sizeof a);
			fprintf(f, "; %s wall-clock at time scale %g", a, ts);
		}
		fputc('\n', f);
	}
	json_t *tm = json_object_get(r, "predicted_terms");
	if (json_is_object(tm)) { /* the prediction term by term (plan.h; they sum to it) */
		static const char *const keys[][2] = { { "reference_s", "reference" }, { "motion_s", "motion" },
						       { "settle_s", "settling" }, { "probes_s", "probes" },
						       { "darks_s", "darks" }, { "first_exposures_s", "first exposures" },
						       { "hdr_s", "HDR exposures" }, { "host_s", "host" } };
		fputs("  of which", f);
		for (size_t i = 0; i < sizeof keys / sizeof keys[0]; i++) {
			ctl_fmt_dur(num(tm, keys[i][0]), a, sizeof a);
			fprintf(f, "%s %s %s", i ? "," : "", keys[i][1], a);
		}
		fputc('\n', f);
	}
	json_t *pr = json_object_get(r, "exposure_prior");
	if (json_is_object(pr)) {
		fprintf(f, "  auto exposure timed from sweep %lld of sample %s (%lld points at %lld incidences: median %.3g ms, "
			   "spread %.3gx, HDR on %.0f %% of the points",
			num_i(pr, "sweep"), str(pr, "sample"), num_i(pr, "points"), num_i(pr, "incidences"),
			num(pr, "median_ms"), num(pr, "spread"), 100 * num(pr, "hdr_fraction"));
		if (json_is_number(json_object_get(pr, "host_per_point_s")))
			fprintf(f, "; the host's time per point there %.1f ms", 1000 * num(pr, "host_per_point_s"));
		fputs(")\n", f);
	}
	else if (json_is_string(json_object_get(r, "sample")))
		fprintf(f, "  auto exposure timed from the plan's estimate: no completed auto sweep of sample %s to take a "
			   "prior from (only a daemon reads its database)\n", str(r, "sample"));
	else if (json_object_get(r, "exposure_prior"))
		fputs("  auto exposure timed from the plan's estimate (name the sample, sample: NAME, and its next sweep is "
		      "timed from this one)\n", f);
	json_t *es = json_object_get(r, "estimate");
	if (json_is_object(es)) { /* a first sweep: the sample decides; the same model at half and twice the estimate */
		ctl_fmt_dur(num(es, "predicted_at_half_s"), a, sizeof a);
		ctl_fmt_dur(num(es, "predicted_at_double_s"), b, sizeof b);
		fprintf(f, "  the sample is not known before it is on the stage: this is the time for exposures as the "
			   "estimate %.3g ms says; %s if it needs half, %s if twice (%s)\n", num(es, "ms"), a, b,
			json_is_object(ad) ? "each batch is timed as it is chosen"
					   : "the sweep re-times the rest from its own exposures as it goes");
	}
	json_t *sv = json_object_get(r, "survey");
	if (json_is_object(sv)) { /* the survey measured first (plan_survey_apply), its cost and what it is for */
		json_t *sc = json_object_get(sv, "cost_s");
		double cost = json_is_number(sc) ? json_number_value(sc) : num(sv, "motion_s");
		fprintf(f, "  survey: %.0f points (up to %.0f per incidence) measured first, %s%.1f s of the time above; "
			   "then the rest is re-timed from the sample's own exposures at every incidence\n",
			num(sv, "points"), num(sv, "per_incidence"), cost >= 0 ? "+" : "", cost);
	}
	json_t *iv = json_object_get(r, "interval");
	if (json_is_object(iv)) { /* where the exposures are unknown: the duration's interval (plan_time_interval) */
		ctl_fmt_dur(num(iv, "low_s"), a, sizeof a);
		ctl_fmt_dur(num(iv, "high_s"), b, sizeof b);
		if (!strcmp(str(iv, "basis"), "policy"))
			fprintf(f, "  interval %s to %s: no exposure of the sample known yet, every exposure between the "
				   "policy's %g and %g ms\n", a, b, num(iv, "min_ms"), num(iv, "max_ms"));
		else
			fprintf(f, "  interval %s to %s: incidences the exposure prior has not measured, their exposures "
				   "within a factor exp(%.3g/deg x the distance to the nearest measured one)\n", a, b,
				num(iv, "slope_per_deg"));
	}
	ctl_fmt_dur(num(r, "duration_s"), a, sizeof a);
	ctl_fmt_dur(num(r, "raster_s"), b, sizeof b);
	ctl_fmt_dur(num(r, "lower_bound_s"), c, sizeof c);
	fprintf(f, "  ordering model: estimated duration %s; raster order %s; lower bound %s\n", a, b, c);
	ctl_fmt_dur(num(r, "dwell_s"), a, sizeof a);
	ctl_fmt_dur(num(r, "motion_s"), b, sizeof b);
	ctl_fmt_dur(num(r, "point_dwell_s"), c, sizeof c);
	fprintf(f, "  dwell %s (%s per point), motion %s (settling included), %lld detoured moves\n", a, c, b,
		num_i(r, "detours"));
	json_t *tr = json_object_get(r, "travel_deg");
	char t0[24], t1[24], t2[24];
	/* a daemon of before the renames said laser_theta, detector_theta, detector_phi */
	bool old = !json_object_get(tr, "laser.theta");
	ctl_fmt_angle(num(tr, old ? "laser_theta" : "laser.theta"), t0, sizeof t0);
	ctl_fmt_angle(num(tr, old ? "detector_theta" : "detector.theta"), t1, sizeof t1);
	ctl_fmt_angle(num(tr, old ? "detector_phi" : "detector.phi"), t2, sizeof t2);
	fprintf(f, "  travel: laser.theta %s, detector.theta %s, detector.phi %s\n", t0, t1, t2);
	json_t *steps = json_object_get(r, "steps");
	size_t limit = json_is_array(steps) ? (size_t)-1 : 20, listed = 0, i;
	json_t *q;
	char p1[96], p2[96];
	json_array_foreach(json_object_get(r, "dropped_points"), i, q) {
		if (listed++ >= limit)
			continue;
		pos3(json_object_get(q, "requested"), p1, sizeof p1);
		fprintf(f, "  dropped #%lld %s: %s%s\n", num_i(q, "index"), p1, str(q, "reason"),
			!strcmp(str(q, "role"), "reciprocal") ? " (reciprocal partner)" : "");
	}
	json_array_foreach(json_object_get(r, "moved_points"), i, q) {
		if (listed++ >= limit)
			continue;
		pos3(json_object_get(q, "requested"), p1, sizeof p1);
		pos3(json_object_get(q, "to"), p2, sizeof p2);
		ctl_fmt_angle(num(q, "by_deg"), a, sizeof a);
		fprintf(f, "  moved   #%lld %s -> %s by %s: %s\n", num_i(q, "index"), p1, p2, a, str(q, "reason"));
	}
	if (listed > limit)
		fprintf(f, "  ... and %zu more dropped or moved points (--points or --json lists them all)\n", listed - limit);
	json_array_foreach(steps, i, q) {
		ctl_fmt_dur(num(q, "t_start_s"), a, sizeof a);
		pos3(q, p1, sizeof p1);
		fprintf(f, "  %5zu at %9s  %s  move %.2f s%s\n", i, a, p1, num(q, "move_s") + num(q, "settle_s"),
			json_array_size(json_object_get(q, "waypoints")) ? "  (detour)" : "");
		size_t k;
		json_t *w;
		json_array_foreach(json_object_get(q, "waypoints"), k, w) {
			pos3(w, p2, sizeof p2);
			fprintf(f, "          via %s (%.2f s)\n", p2, num(w, "duration_s"));
		}
	}
}

static void print_spectrum(FILE *f, json_t *s)
{
	char t[48];
	ctl_fmt_time(num(s, "taken_at"), t, sizeof t);
	fprintf(f, "spectrum %lld: %s, %lld pixels, integration %.4g ms × %lld, taken %s\n", num_i(s, "id"),
		str(s, "kind"), num_i(s, "npix"), num(s, "integration_ms"), num_i(s, "averages"), t);
	if (num_i(s, "sweep"))
		fprintf(f, "  sweep %lld, point %lld\n", num_i(s, "sweep"), num_i(s, "point"));
	fprintf(f, "  peak %.6g counts, %lld saturated pixels\n", num(s, "peak"), num_i(s, "saturated"));
	fprintf(f, "  (acqctl spectrum %lld --csv prints the counts per wavelength)\n", num_i(s, "id"));
}

/* measure, dark, reference: the spectrum just taken and stored (its id for `acqctl spectrum`). */
/* A reload: the file, then what it changed (daemon/app.c app_reload: devices closed first). */
static void print_reload(FILE *f, json_t *r)
{
	fprintf(f, "configuration reloaded from %s\n", str(r, "config"));
	json_t *w = json_object_get(r, "warnings"), *c = json_object_get(r, "changes"), *x;
	size_t i;
	json_array_foreach(w, i, x)
		fprintf(f, "warning: %s\n", json_string_value(x) ? json_string_value(x) : "?");
	json_array_foreach(c, i, x)
		fprintf(f, "  %s\n", json_string_value(x) ? json_string_value(x) : "?");
	long long total = num_i(r, "changes_total");
	if (total > (long long)json_array_size(c))
		fprintf(f, "  and %lld more settings changed\n", total - (long long)json_array_size(c));
	if (json_is_array(w) && json_is_array(c) && !json_array_size(w) && !json_array_size(c))
		fprintf(f, "  no setting changed\n");
}

static void print_taken(FILE *f, json_t *r)
{
	char ms[32];
	snprintf(ms, sizeof ms, "%.4g", num(r, "integration_ms"));
	fprintf(f, "spectrum %lld: %s, %lld pixels, integration %s ms × %lld, peak %.6g counts, %lld saturated pixels\n",
		num_i(r, "spectrum_id"), str(r, "kind"), num_i(r, "npix"), ms, num_i(r, "averages"), num(r, "peak"),
		num_i(r, "saturated"));
	fprintf(f, "  (acqctl spectrum %lld shows it, --csv its counts per wavelength)\n", num_i(r, "spectrum_id"));
}

/* move, home, stop: the axes where they are now. */
static void print_positions(FILE *f, const char *cmd, json_t *r)
{
	static const char *const axes[] = { "laser.theta", "detector.theta", "detector.phi" };
	if (!strcmp(cmd, "stop"))
		fprintf(f, "%s\n", json_is_true(json_object_get(r, "stopped")) ? "stopped the running operation"
									: "nothing was running; the arms are stopped");
	json_t *ap = json_object_get(r, "apart");
	for (size_t i = 0; i < json_array_size(ap); i++) {
		char a[32];
		json_t *m = json_array_get(ap, i);
		ctl_fmt_angle(num(m, "to"), a, sizeof a);
		fprintf(f, "%s %s to %s (the arms apart before homing)\n", i ? "then moved" : "first moved", str(m, "axis"), a);
	}
	json_t *h = json_object_get(r, "homed");
	if (json_array_size(h)) {
		char list[160];
		ctl_fmt_value("homed", h, list, sizeof list);
		fprintf(f, "homed %s\n", list);
	}
	/* after a home of every axis each waits at its park (home.park): the positions below say where */
	fprintf(f, "%s", json_is_true(json_object_get(r, "parked")) ? "parked at" : "position");
	for (int i = 0; i < 3; i++) {
		char a[32];
		ctl_fmt_angle(num(r, axes[i]), a, sizeof a);
		fprintf(f, "  %s %s", axes[i], a);
	}
	fputc('\n', f);
	if (json_is_string(json_object_get(r, "warning")))
		fprintf(f, "warning: the target is in a blind zone (%s)\n", str(r, "warning"));
}

static void print_recon_run(FILE *f, json_t *r)
{
	char a[48], b[48], c[32];
	ctl_fmt_time(num(r, "started_at"), a, sizeof a);
	ctl_fmt_time(num(r, "finished_at"), b, sizeof b);
	fprintf(f, "reconstruction run %lld of sweep %lld: %s", num_i(r, "id"), num_i(r, "sweep_id"), str(r, "state"));
	if (json_is_integer(json_object_get(r, "exit_status")))
		fprintf(f, " (exit %lld)", num_i(r, "exit_status"));
	fprintf(f, "\n  program %s\n  started %s, finished %s", str(r, "program"), a, b);
	if (num(r, "finished_at") >= num(r, "started_at")) {
		ctl_fmt_dur(num(r, "finished_at") - num(r, "started_at"), c, sizeof c);
		fprintf(f, ", took %s", c);
	}
	fputc('\n', f);
	size_t i;
	json_t *o;
	json_array_foreach(json_object_get(r, "outputs"), i, o)
		fprintf(f, "  %-12s %s\n", str(o, "kind"), str(o, "path"));
	const char *tail = str(r, "output_tail");
	if (tail[0]) {
		fprintf(f, "  last output:\n");
		print_lines(f, "    ", tail);
	}
}

void ctl_printable(char *text)
{
	for (unsigned char *c = (unsigned char *)text; *c; c++)
		if ((*c < 0x20 && *c != '\n' && *c != '\t') || *c == 0x7f)
			*c = '?';
}

/* Every string in v made printable (ctl_printable), in place. */
static void printable_json(json_t *v)
{
	if (json_is_string(v)) {
		const unsigned char *s = (const unsigned char *)json_string_value(v);
		bool bad = false;
		for (size_t i = 0; s[i] && !bad; i++)
			bad = (s[i] < 0x20 && s[i] != '\n' && s[i] != '\t') || s[i] == 0x7f;
		char *c = bad ? strdup((const char *)s) : NULL;
		if (c) {
			ctl_printable(c);
			json_string_set(v, c);
			free(c);
		}
		return;
	}
	const char *k;
	json_t *x;
	size_t i;
	if (json_is_object(v))
		json_object_foreach(v, k, x)
			printable_json(x);
	else if (json_is_array(v))
		json_array_foreach(v, i, x)
			printable_json(x);
}

void ctl_print_human(FILE *f, const char *cmd, json_t *rep)
{
	json_object_del(rep, "id");
	json_object_del(rep, "ok");
	printable_json(rep);
	json_t *x;
	if (!strcmp(cmd, "status"))
		print_status(f, rep);
	else if (!strcmp(cmd, "devices"))
		print_devices(f, json_object_get(rep, "devices"));
	else if (!strcmp(cmd, "sweep.list"))
		print_sweep_list(f, json_object_get(rep, "sweeps"));
	else if (!strcmp(cmd, "sweep.show"))
		print_sweep_show(f, json_object_get(rep, "sweep"));
	else if (!strcmp(cmd, "plan"))
		ctl_print_plan(f, json_object_get(rep, "plan"));
	else if (!strcmp(cmd, "spectrum"))
		print_spectrum(f, json_object_get(rep, "spectrum"));
	else if (!strcmp(cmd, "move") || !strcmp(cmd, "home") || !strcmp(cmd, "stop"))
		print_positions(f, cmd, rep);
	else if (!strcmp(cmd, "recon.status"))
		print_recon_run(f, json_object_get(rep, "run"));
	else if ((!strcmp(cmd, "measure") || !strcmp(cmd, "dark") || !strcmp(cmd, "reference")) &&
		 json_is_integer(json_object_get(rep, "spectrum_id")))
		print_taken(f, rep);
	else if (!strcmp(cmd, "reload") && json_is_string(json_object_get(rep, "config")))
		print_reload(f, rep);
	else if (!strcmp(cmd, "laser.off") && json_is_boolean(json_object_get(rep, "emission")))
		fprintf(f, "%s\n", json_is_false(json_object_get(rep, "emission")) ? "laser emission off (confirmed by the laser)"
			: "laser off requested, but the laser still reports emission: check it");
	else if ((x = json_object_get(rep, "progress")) && json_is_object(x)) {
		if (json_object_get(rep, "sweep"))
			fprintf(f, "sweep %lld started\n", num_i(rep, "sweep"));
		print_progress(f, "sweep", x);
	} else if (!strcmp(cmd, "config") && json_is_string(json_object_get(json_object_get(rep, "config"), "text")))
		fputs(json_string_value(json_object_get(json_object_get(rep, "config"), "text")), f);
	else if (!strcmp(cmd, "version"))
		fprintf(f, "acquisitiond %s (protocol %lld, database schema %lld); you are a %s\n", str(rep, "version"),
			num_i(rep, "protocol"), num_i(rep, "schema"), str(rep, "role"));
	else
		print_tree(f, "", NULL, rep);
}
