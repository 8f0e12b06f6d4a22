/* progress: the one-line rendering of a "sweep.progress" event for acqctl watch — a bar with ETA on a
 * terminal, a plain line otherwise (see proto.h). */
#include "proto/proto.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static void fmt_eta(double s, char *out, size_t cap)
{
	if (!isfinite(s) || s < 0)
		snprintf(out, cap, "--");
	else if (s >= 3600)
		snprintf(out, cap, "%dh%02dm", (int)(s / 3600), (int)fmod(s / 60, 60));
	else
		snprintf(out, cap, "%dm%02ds", (int)(s / 60), (int)fmod(s, 60));
}

int proto_progress_line(json_t *ev, bool tty, char *buf, size_t cap)
{
	const char *name = json_string_value(json_object_get(ev, "event"));
	if (!name || strcmp(name, "sweep.progress"))
		return 0;
	json_int_t done = json_integer_value(json_object_get(ev, "done"));
	json_int_t total = json_integer_value(json_object_get(ev, "total"));
	json_int_t sweep = json_integer_value(json_object_get(ev, "sweep"));
	json_t *e = json_object_get(ev, "eta_s");
	char eta[32];
	fmt_eta(json_is_number(e) ? json_number_value(e) : NAN, eta, sizeof eta);
	if (done < 0)
		done = 0;
	if (total > 0 && done > total)
		done = total;
	if (!tty) {
		snprintf(buf, cap, "sweep %lld: %lld/%lld points, ETA %s", (long long)sweep, (long long)done,
			 (long long)total, eta);
		return 1;
	}
	char bar[41];
	int w = 40, fill = total > 0 ? (int)(w * done / total) : 0;
	for (int i = 0; i < w; i++)
		bar[i] = i < fill ? '#' : '-';
	bar[w] = 0;
	snprintf(buf, cap, "\rsweep %lld [%s] %3d%% %lld/%lld  ETA %s   ", (long long)sweep, bar,
		 total > 0 ? (int)(100 * done / total) : 0, (long long)done, (long long)total, eta);
	return 1;
}
