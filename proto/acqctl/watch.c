/* watch: acqctl watch (the daemon's events, reconnecting) and acqctl wait (a sweep state), see acqctl.h. */
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "proto/acqctl/acqctl.h"
#include "proto/ctl.h"

static volatile sig_atomic_t stop_watch;
static void on_signal(int sig)
{
	(void)sig;
	stop_watch = 1;
}

static double wall(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void json_line_event(const char *name, const char *msg)
{
	json_t *o = json_pack("{s:s,s:s,s:f}", "event", name, "message", msg, "at", wall());
	out_json(o);
	json_decref(o);
}

/* Follow the daemon's events until interrupted, reconnecting (every second) when it goes away. */
int watch_run(void)
{
	bool tty = !acqctl_o.json && isatty(STDOUT_FILENO);
	struct ctl_view *view = tty ? ctl_view_new(stdout, acqctl_o.sock) : NULL;
	struct sigaction sa = { .sa_handler = on_signal };
	sigaction(SIGINT, &sa, NULL);
	sigaction(SIGTERM, &sa, NULL);
	bool ever = false;
	char last_err[512] = "";
	while (!stop_watch) {
		struct conn c;
		struct acq_err err = { 0 };
		json_t *req = NULL, *st = NULL, *dv = NULL, *rep = NULL;
		if (conn_open(&c, &err))
			goto lost;
		if (view) {
			req = json_pack("{s:s,s:i}", "cmd", "status", "id", 1);
			st = conn_call(&c, req, NULL, &err);
			json_decref(req);
			req = json_pack("{s:s,s:i}", "cmd", "devices", "id", 2);
			dv = st ? conn_call(&c, req, NULL, &err) : NULL;
			json_decref(req);
			if (!dv)
				goto lost;
			ctl_view_status(view, st, dv);
		}
		req = json_pack("{s:s,s:i}", "cmd", "watch", "id", 3);
		rep = conn_call(&c, req, NULL, &err);
		json_decref(req);
		if (!rep)
			goto lost;
		if (!json_is_true(json_object_get(rep, "ok"))) {
			json_t *e = json_object_get(rep, "error");
			int rc = out_fail(CTL_EXIT_REFUSED, json_string_value(json_object_get(e, "code")), "watch: %s",
				      json_string_value(json_object_get(e, "message")));
			json_decref(rep);
			conn_close(&c);
			ctl_view_free(view);
			return rc;
		}
		json_decref(rep);
		if (view)
			ctl_view_link(view, "connected");
		else if (ever)
			json_line_event("acqctl.reconnected", acqctl_o.sock);
		ever = true;
		last_err[0] = 0;
		while (!stop_watch) {
			if (view)
				ctl_view_draw(view, wall());
			json_t *ev = proto_client_read(c.fd, &c.pl, 1000, &err);
			if (!ev && err.code == ACQ_E_TIMEOUT)
				continue;
			if (!ev)
				break;
			if (view)
				ctl_view_event(view, ev);
			else
				out_json(ev);
			json_decref(ev);
		}
	lost:
		json_decref(st);
		json_decref(dv);
		conn_close(&c);
		if (stop_watch)
			break;
		if (strcmp(last_err, err.msg)) {
			snprintf(last_err, sizeof last_err, "%s", err.msg);
			char text[600];
			snprintf(text, sizeof text, "reconnecting: %s", err.msg);
			if (view)
				ctl_view_link(view, text);
			else
				json_line_event("acqctl.disconnected", err.msg);
		}
		if (view)
			ctl_view_draw(view, wall());
		sleep(1);
	}
	if (view)
		fputc('\n', stdout);
	ctl_view_free(view);
	return 0;
}

/* ---- wait: until the sweep is in a state (client side, by polling status) ---- */
int watch_wait(const char *want, double timeout_s)
{
	static const char *const states[] = { "idle", "running", "paused", "faulted", NULL };
	bool known = false;
	for (int i = 0; states[i]; i++)
		known |= !strcmp(want, states[i]);
	if (!known)
		return out_fail(CTL_EXIT_USAGE, "usage", "wait: expected idle, running, paused or faulted, got '%s'", want);
	struct conn c;
	struct acq_err err = { 0 };
	if (conn_open(&c, &err)) {
		conn_close(&c);
		return out_fail(CTL_EXIT_UNAVAILABLE, "unavailable", "cannot connect to acquisitiond: %s", err.msg);
	}
	double deadline = conn_mono() + timeout_s;
	json_t *req = json_pack("{s:s,s:i}", "cmd", "status", "id", 1);
	int rc = -1;
	while (rc < 0) {
		json_t *rep = conn_call(&c, req, NULL, &err);
		json_t *p = json_object_get(rep, "sweep");
		if (!rep)
			rc = out_fail(CTL_EXIT_UNAVAILABLE, "unavailable", "%s: %s", acqctl_o.sock, err.msg);
		else if (!strcmp(json_string_value(json_object_get(p, "state")) ?: "", want)) {
			json_object_del(rep, "id");
			if (acqctl_o.json)
				out_json(rep);
			else
				ctl_print_human(stdout, "status", rep);
			rc = 0;
		} else if (conn_mono() > deadline)
			rc = out_fail(75, "state", "wait: the sweep is still %s after %g s (wanted %s)",
				  json_string_value(json_object_get(p, "state")), timeout_s, want);
		else
			usleep(250000);
		json_decref(rep);
	}
	json_decref(req);
	conn_close(&c);
	return rc;
}

/* ---- plan without a daemon ---- */
