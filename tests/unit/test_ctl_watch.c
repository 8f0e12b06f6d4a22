/* Unit tests of ctl_watch.c, acqctl watch's terminal view during a sweep: the progress bar and counts, the ETA
 * counting down between events while running and not shown while paused, the current point, device states and the
 * last events; control characters in what it shows made printable. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <cmocka.h>

#include "proto/ctl.h"

static double real_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* The view drawn at wall time now (a new string). */
static char *draw(struct ctl_view *v, char **buf, size_t *len, FILE *f, double now)
{
	rewind(f);
	ctl_view_draw(v, now);
	fflush(f);
	return strndup(*buf, *len);
}

static void event(struct ctl_view *v, const char *text)
{
	json_error_t je;
	json_t *ev = json_loads(text, 0, &je);
	assert_non_null(ev);
	ctl_view_event(v, ev);
	json_decref(ev);
}

static void test_sweep_view(void **state)
{
	(void)state;
	setenv("TZ", "UTC", 1);
	tzset();
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	assert_non_null(f);
	struct ctl_view *v = ctl_view_new(f, "/run/x.sock");
	assert_non_null(v);
	ctl_view_link(v, "connected");
	event(v, "{\"event\": \"device\", \"name\": \"spectrometer\", \"available\": true, \"message\": \"\"}");
	event(v, "{\"event\": \"sweep.state\", \"sweep\": 3, \"state\": \"running\", \"kind\": \"resume\","
		 " \"reason\": \"resumed by the operator\"}");
	event(v, "{\"event\": \"sweep.progress\", \"sweep\": 3, \"state\": \"running\", \"done\": 25, \"total\": 100,"
		 " \"point\": \"point 26/100: θi 20°, θo 40°, φo 90°\", \"eta_s\": 300}");
	char *s = draw(v, &buf, &len, f, real_now() + 60);
	/* a quarter of the 40-character bar, the counts, the ETA 60 s later counted down to 4 minutes */
	assert_non_null(strstr(s, "sweep 3  running  [##########------------------------------]  25 %  25/100\n"));
	assert_non_null(strstr(s, "ETA   0:04:00 (ends about "));
	assert_non_null(strstr(s, "now   point 26/100: θi 20°, θo 40°, φo 90°\n"));
	assert_non_null(strstr(s, "  spectrometer     connected\n"));
	assert_non_null(strstr(s, "sweep 3 resume: resumed by the operator\n"));
	assert_null(strstr(s, "not known yet"));
	free(s);
	/* the rest's exposures not all known: the ETA's interval, both ends counted down with it */
	event(v, "{\"event\": \"sweep.progress\", \"sweep\": 3, \"state\": \"running\", \"done\": 25, \"total\": 100,"
		 " \"point\": \"\", \"eta_s\": 300, \"eta_low_s\": 200, \"eta_high_s\": 900}");
	s = draw(v, &buf, &len, f, real_now() + 60);
	assert_non_null(strstr(s, "ETA   0:04:00 (ends about "));
	assert_non_null(strstr(s, "; 0:02:20 to 0:14:00, exposures of the rest not known yet)\n"));
	free(s);
	/* paused: the ETA is not shown (not counting while paused); the event is listed */
	event(v, "{\"event\": \"sweep.state\", \"sweep\": 3, \"state\": \"paused\", \"kind\": \"pause\","
		 " \"reason\": \"place the sample on the stage, then resume\"}");
	s = draw(v, &buf, &len, f, real_now() + 600);
	assert_non_null(strstr(s, "sweep 3  paused   [##########"));
	assert_non_null(strstr(s, "ETA   -\n"));
	assert_null(strstr(s, "ETA   0:"));
	assert_non_null(strstr(s, "sweep 3 pause: place the sample on the stage, then resume\n"));
	free(s);
	/* a device lost, then the progress again: the ETA is back, the device's state follows */
	event(v, "{\"event\": \"device\", \"name\": \"spectrometer\", \"available\": false, \"message\": \"gone\"}");
	event(v, "{\"event\": \"sweep.progress\", \"sweep\": 3, \"state\": \"running\", \"done\": 100, \"total\": 100,"
		 " \"point\": \"\", \"eta_s\": 0}");
	s = draw(v, &buf, &len, f, real_now());
	assert_non_null(strstr(s, "[########################################] 100 %  100/100\n"));
	assert_non_null(strstr(s, "ETA   0 s (ends about "));
	assert_null(strstr(s, "not known yet")); /* a progress without the interval drops it */
	assert_non_null(strstr(s, "  spectrometer     unavailable\n"));
	assert_non_null(strstr(s, "spectrometer unavailable: gone\n"));
	free(s);
	ctl_view_free(v);
	fclose(f);
	free(buf);
}

/* An event's text (a message, a sweep's reason, the current point) with a control character (an escape sequence a
 * name stored before the daemon refused them could carry) is shown with '?' for it, not sent to the terminal. */
static void test_escapes_not_passed(void **state)
{
	(void)state;
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	struct ctl_view *v = ctl_view_new(f, "/run/x.sock");
	event(v, "{\"event\": \"sweep.fault\", \"sweep\": 4, \"device\": \"laser\", \"message\": \"bad\\u001b]0;x\\u0007"
		 "\\u001b[2Jthing\"}");
	event(v, "{\"event\": \"sweep.progress\", \"sweep\": 4, \"state\": \"running\", \"done\": 1, \"total\": 2,"
		 " \"point\": \"p\\u001b[31m1\"}");
	/* a reload that closed devices says so (daemon/app.c: the config event's warnings) */
	event(v, "{\"event\": \"config\", \"path\": \"/e/a.yaml\", \"warnings\": [\"laser: no longer configured\", \"x\"]}");
	event(v, "{\"event\": \"config\", \"path\": \"/e/b.yaml\"}");
	char *s = draw(v, &buf, &len, f, real_now());
	assert_non_null(strstr(s, "configuration reloaded from /e/a.yaml; warning: laser: no longer configured (+1 more "
				  "warnings: acqctl devices)\n"));
	assert_non_null(strstr(s, "configuration reloaded from /e/b.yaml\n"));
	assert_non_null(strstr(s, "sweep 4 fault on laser: bad?]0;x??[2Jthing\n"));
	assert_non_null(strstr(s, "now   p?[31m1\n"));
	assert_null(strstr(s, "\x1b[2Jthing"));
	assert_null(strstr(s, "\x1b[31m"));
	free(s);
	ctl_view_free(v);
	fclose(f);
	free(buf);
	/* acqctl's other outputs alike (a sweep listed by its name) */
	json_error_t je;
	json_t *rep = json_loads("{\"ok\": true, \"sweeps\": [{\"id\": 1, \"state\": \"completed\", \"name\": "
				 "\"evil\\u001b[2Jname\", \"points_done\": 1, \"points_total\": 1}]}", 0, &je);
	assert_non_null(rep);
	buf = NULL;
	f = open_memstream(&buf, &len);
	ctl_print_human(f, "sweep.list", rep);
	fclose(f);
	assert_non_null(strstr(buf, "evil?[2Jname"));
	assert_null(strchr(buf, 0x1b));
	free(buf);
	json_decref(rep);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sweep_view),
		cmocka_unit_test(test_escapes_not_passed),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
