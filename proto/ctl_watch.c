/* ctl_watch: the live terminal view of `acqctl watch` — progress bar, ETA as a wall-clock time, current point,
 * device states and the last events, redrawn in place (see ctl.h). */
#include "proto/ctl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define VIEW_EVENTS 8
#define VIEW_DEVICES 8

struct ctl_view {
	FILE *f;
	char where[128];
	char link[160];
	char daemon[160];
	long long sweep, done, total;
	char state[32];
	char point[160];
	char adaptive[240];    /* an adaptive sweep: the target's value and its trend per batch */
	double eta_s, eta_at;  /* seconds left, and the wall time they were reported */
	double eta_lo, eta_hi; /* its interval where the rest's exposures are unknown (NAN: none) */
	struct {
		char name[32], state[40];
	} dev[VIEW_DEVICES];
	int ndev;
	char events[VIEW_EVENTS][200];
	int nev, evhead;
};

struct ctl_view *ctl_view_new(FILE *f, const char *where)
{
	struct ctl_view *v = calloc(1, sizeof *v);
	if (!v)
		return NULL;
	v->f = f;
	snprintf(v->where, sizeof v->where, "%s", where);
	snprintf(v->state, sizeof v->state, "idle");
	v->eta_s = v->eta_lo = v->eta_hi = NAN;
	return v;
}

void ctl_view_free(struct ctl_view *v)
{
	free(v);
}

static const char *s_of(json_t *o, const char *k)
{
	const char *s = json_string_value(json_object_get(o, k));
	return s ? s : "";
}

static double wall_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void set_dev(struct ctl_view *v, const char *name, const char *state)
{
	for (int i = 0; i < v->ndev; i++)
		if (!strcmp(v->dev[i].name, name)) {
			snprintf(v->dev[i].state, sizeof v->dev[i].state, "%s", state);
			return;
		}
	if (v->ndev < VIEW_DEVICES) {
		snprintf(v->dev[v->ndev].name, sizeof v->dev[0].name, "%s", name);
		snprintf(v->dev[v->ndev++].state, sizeof v->dev[0].state, "%s", state);
	}
}

static void set_progress(struct ctl_view *v, json_t *p, const char *idkey)
{
	json_t *x;
	if ((x = json_object_get(p, idkey)) && json_is_integer(x))
		v->sweep = json_integer_value(x);
	if ((x = json_object_get(p, "done")) && json_is_integer(x))
		v->done = json_integer_value(x);
	if ((x = json_object_get(p, "total")) && json_is_integer(x))
		v->total = json_integer_value(x);
	if (json_is_string(json_object_get(p, "state")))
		snprintf(v->state, sizeof v->state, "%s", s_of(p, "state"));
	x = json_object_get(p, "eta_s");
	v->eta_s = json_is_number(x) ? json_number_value(x) : NAN;
	x = json_object_get(p, "eta_low_s");
	v->eta_lo = json_is_number(x) ? json_number_value(x) : NAN;
	x = json_object_get(p, "eta_high_s");
	v->eta_hi = json_is_number(x) ? json_number_value(x) : NAN;
	v->eta_at = wall_now();
}

void ctl_view_status(struct ctl_view *v, json_t *status, json_t *devices)
{
	if (status) {
		snprintf(v->daemon, sizeof v->daemon, "acquisitiond %s, pid %lld%s", s_of(status, "version"),
			 (long long)json_integer_value(json_object_get(status, "pid")),
			 json_is_true(json_object_get(status, "sim")) ? " (simulated bench)" : "");
		json_t *p = json_object_get(status, "sweep");
		set_progress(v, p, "id");
		snprintf(v->point, sizeof v->point, "%s", s_of(p, "message"));
	}
	size_t i;
	json_t *d;
	json_array_foreach(json_object_get(devices, "devices"), i, d)
		set_dev(v, s_of(d, "name"), s_of(d, "state"));
}

static void add_event(struct ctl_view *v, const char *text)
{
	char t[48];
	ctl_fmt_time(wall_now(), t, sizeof t);
	/* the time of day only: the date is in the header */
	const char *tod = strchr(t, 'T');
	snprintf(v->events[v->evhead], sizeof v->events[0], "%.8s  %s", tod ? tod + 1 : t, text);
	v->evhead = (v->evhead + 1) % VIEW_EVENTS;
	if (v->nev < VIEW_EVENTS)
		v->nev++;
}

/* A "sweep.adaptive" event: the view's target line (value, threshold, trend per batch, spending) and the event's
 * text (the batch decided, or why the sweep stopped). */
static void adaptive_line(struct ctl_view *v, json_t *ev, char *text, size_t cap)
{
	json_t *trend = json_object_get(ev, "trend"), *val = json_object_get(ev, "value"), *x;
	char tr[120] = "", sp[32], bud[32] = "", vs[32] = "-";
	size_t n = json_array_size(trend), k = 0;
	for (size_t i = n > 5 ? n - 5 : 0; i < n && k < sizeof tr; i++) {
		x = json_array_get(trend, i);
		k += (size_t)snprintf(tr + k, sizeof tr - k, "%s%.4g", k ? " → " : (n > 5 ? "… " : ""),
				      json_is_number(x) ? json_number_value(x) : NAN);
	}
	if (json_is_number(val))
		snprintf(vs, sizeof vs, "%.4g", json_number_value(val));
	ctl_fmt_dur(json_number_value(json_object_get(ev, "spent_s")), sp, sizeof sp);
	if (json_is_number(json_object_get(ev, "budget_s")))
		ctl_fmt_dur(json_number_value(json_object_get(ev, "budget_s")), bud, sizeof bud);
	v->sweep = json_integer_value(json_object_get(ev, "sweep"));
	snprintf(v->adaptive, sizeof v->adaptive, "%s = %s (target ≤ %g)  trend %s  batch %lld, %lld points, %s%s%s "
		 "measured, arms waited %.1f s", s_of(ev, "target"),
		 vs,
		 json_number_value(json_object_get(ev, "threshold")), tr[0] ? tr : "-",
		 (long long)json_integer_value(json_object_get(ev, "batch")),
		 (long long)json_integer_value(json_object_get(ev, "points")), sp, bud[0] ? " of " : "", bud,
		 json_number_value(json_object_get(ev, "waited_total_s")));
	if (json_is_string(json_object_get(ev, "stop")))
		snprintf(text, cap, "adaptive sweep %lld stopped: %s", v->sweep, s_of(ev, "stop"));
	else
		snprintf(text, cap, "adaptive sweep %lld: batch %lld chosen (%s = %s)", v->sweep,
			 (long long)json_integer_value(json_object_get(ev, "batch")), s_of(ev, "target"),
			 vs);
}

void ctl_view_event(struct ctl_view *v, json_t *ev)
{
	const char *name = s_of(ev, "event");
	char text[200];
	if (!strcmp(name, "sweep.progress")) {
		set_progress(v, ev, "sweep");
		snprintf(v->point, sizeof v->point, "%s", s_of(ev, "point"));
		ctl_printable(v->point);
		return;
	}
	if (!strcmp(name, "sweep.state")) {
		v->sweep = json_integer_value(json_object_get(ev, "sweep"));
		snprintf(v->state, sizeof v->state, "%s", s_of(ev, "state"));
		if (strcmp(v->state, "running"))
			v->eta_s = v->eta_lo = v->eta_hi = NAN;
		snprintf(text, sizeof text, "sweep %lld %s: %s", v->sweep, s_of(ev, "kind"), s_of(ev, "reason"));
	} else if (!strcmp(name, "sweep.fault")) {
		snprintf(text, sizeof text, "sweep %lld fault on %s: %s",
			 (long long)json_integer_value(json_object_get(ev, "sweep")), s_of(ev, "device"), s_of(ev, "message"));
	} else if (!strcmp(name, "device")) {
		bool up = json_is_true(json_object_get(ev, "available"));
		set_dev(v, s_of(ev, "name"), up ? "connected" : "unavailable");
		snprintf(text, sizeof text, "%s %s%s%s", s_of(ev, "name"), up ? "connected" : "unavailable",
			 s_of(ev, "message")[0] ? ": " : "", s_of(ev, "message"));
	} else if (!strcmp(name, "recon")) {
		snprintf(text, sizeof text, "reconstruction of sweep %lld %s: %s",
			 (long long)json_integer_value(json_object_get(ev, "sweep")), s_of(ev, "state"), s_of(ev, "message"));
	} else if (!strcmp(name, "sweep.adaptive")) {
		adaptive_line(v, ev, text, sizeof text);
	} else if (!strcmp(name, "config")) { /* with the first device it closed or lost, and how many more */
		json_t *w = json_object_get(ev, "warnings");
		size_t nw = json_array_size(w);
		const char *w0 = nw ? json_string_value(json_array_get(w, 0)) : NULL;
		char more[48] = "";
		if (nw > 1)
			snprintf(more, sizeof more, " (+%zu more warnings: acqctl devices)", nw - 1);
		snprintf(text, sizeof text, "configuration reloaded from %s%s%s%s", s_of(ev, "path"), w0 ? "; warning: " : "",
			 w0 ? w0 : "", more);
	} else {
		char *s = json_dumps(ev, JSON_COMPACT);
		snprintf(text, sizeof text, "%s", s ? s : name);
		free(s);
	}
	ctl_printable(text); /* a name or a message with an escape sequence does not reach the terminal */
	add_event(v, text);
}

void ctl_view_link(struct ctl_view *v, const char *text)
{
	snprintf(v->link, sizeof v->link, "%s", text);
}

void ctl_view_draw(struct ctl_view *v, double now)
{
	FILE *f = v->f;
	char t[48], eta[32], at[48];
	ctl_fmt_time(now, t, sizeof t);
	fputs("\033[H\033[2J", f); /* home, clear */
	fprintf(f, "acqctl watch — %s — %s\n", v->where, t);
	fprintf(f, "%s  [%s]\n\n", v->daemon[0] ? v->daemon : "acquisitiond", v->link);
	if (v->sweep) {
		int w = 40, fill = v->total > 0 ? (int)(w * v->done / v->total) : 0;
		char bar[41];
		for (int i = 0; i < w; i++)
			bar[i] = i < fill ? '#' : '-';
		bar[w] = 0;
		fprintf(f, "sweep %lld  %-8s [%s] %3d %%  %lld/%lld\n", v->sweep, v->state, bar,
			v->total > 0 ? (int)(100 * v->done / v->total) : 0, v->done, v->total);
		/* The ETA counts down between events while running; paused or faulted it is not shown. */
		if (!strcmp(v->state, "running") && isfinite(v->eta_s)) {
			double left = v->eta_s - (now - v->eta_at);
			ctl_fmt_dur(left > 0 ? left : 0, eta, sizeof eta);
			ctl_fmt_time(v->eta_at + v->eta_s, at, sizeof at);
			if (isfinite(v->eta_lo) && isfinite(v->eta_hi)) {
				char lo[32], hi[32];
				double el = v->eta_lo - (now - v->eta_at), eh = v->eta_hi - (now - v->eta_at);
				ctl_fmt_dur(el > 0 ? el : 0, lo, sizeof lo);
				ctl_fmt_dur(eh > 0 ? eh : 0, hi, sizeof hi);
				fprintf(f, "ETA   %s (ends about %s; %s to %s, exposures of the rest not known yet)\n", eta,
					at, lo, hi);
			} else
				fprintf(f, "ETA   %s (ends about %s)\n", eta, at);
		} else {
			fprintf(f, "ETA   -\n");
		}
		fprintf(f, "now   %s\n", v->point);
		if (v->adaptive[0])
			fprintf(f, "goal  %s\n", v->adaptive);
	} else {
		fprintf(f, "no sweep loaded\n\n\n");
	}
	fprintf(f, "\ndevices\n");
	for (int i = 0; i < v->ndev; i++)
		fprintf(f, "  %-16s %s\n", v->dev[i].name, v->dev[i].state);
	fprintf(f, "\nlast events\n");
	for (int i = 0; i < v->nev; i++)
		fprintf(f, "  %s\n", v->events[(v->evhead - v->nev + i + VIEW_EVENTS) % VIEW_EVENTS]);
	fprintf(f, "\n(Ctrl-C to quit)\n");
	fflush(f);
}
