/* acqctl's own files (proto/acqctl/: conn.c the connection to the daemon, out.c the outputs, watch.c watch and
 * wait; the command line in proto/acqctl_main.c) share this; nothing else includes it. */
#ifndef PROTO_ACQCTL_ACQCTL_H
#define PROTO_ACQCTL_ACQCTL_H

#include <stdbool.h>
#include <jansson.h>

#include "config/acq_err.h"
#include "proto/proto.h"

/* The command line's options (acqctl_main.c). */
struct acqctl_opts {
	const char *sock;
	bool json, points, csv;
	const char *out;       /* -o FILE (export, spectrum --csv) */
	const char *format;    /* export --format csv|nexus */
	const char *bench;     /* plan --config */
	int timeout_ms;
	double wait_s;         /* --wait: keep trying to connect this long */
};
extern struct acqctl_opts acqctl_o;

/* ---- conn.c: one connection to the daemon */
struct conn {
	int fd;
	struct proto_lines pl;
	json_t *banner;
};
/* CLOCK_MONOTONIC seconds. */
double conn_mono(void);
/* Connect to acqctl_o.sock (retrying for acqctl_o.wait_s) and read the banner. 0, or -1 with err (a refusal
 * before the banner: its message). */
int conn_open(struct conn *c, struct acq_err *err);
/* Close (an unopened or closed c is fine). */
void conn_close(struct conn *c);
/* Send req (borrowed) and read its reply (new); passed receives a descriptor sent with it (NULL: none expected).
 * NULL with err on failure (a refusal the daemon sent before closing is returned as the reply). */
json_t *conn_call(struct conn *c, json_t *req, int *passed, struct acq_err *err);

/* ---- out.c: one output per command */
/* One compact JSON document on stdout. */
void out_json(json_t *o);
/* An error of the client itself (no daemon, bad input): "acqctl: message" on stderr, and the error document with
 * --json; returns rc. */
int out_fail(int rc, const char *code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* An export's -o FILE opened (created if missing, not emptied) before the request is sent, so a file that cannot
 * be written costs the daemon no export; 0, or the exit code (reported). Without -o: 0. */
int out_prepare(void);
/* The prepared -o file not used (the export refused or failed before its data): closed, removed if
 * out_prepare created it. */
void out_abandon(void);
/* Copy the export stream src (its reply rep) to -o or stdout, checking it carried every row; the exit code. */
int out_export(json_t *rep, int src);
/* A small export sent inline (TCP) to -o or stdout; the exit code. */
int out_inline(json_t *rep);
/* A spectrum reply as CSV to -o or stdout; the exit code. */
int out_spectrum_csv(json_t *rep);

/* ---- watch.c */
/* Follow the daemon's events until interrupted (a live view on a terminal, JSON lines otherwise), reconnecting
 * every second when it goes away; the exit code. */
int watch_run(void);
/* Wait until the sweep state is want (idle, running, paused, faulted) or timeout_s passed; the exit code. */
int watch_wait(const char *want, double timeout_s);

#endif
