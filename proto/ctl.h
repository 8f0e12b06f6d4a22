/* ctl: acqctl's presentation layer — readable values (local ISO 8601 times, h:mm:ss durations, rounded angles
 * with units), one human rendering per reply, the live `watch` view, and the exit codes (sysexits). Never
 * talks to the daemon itself. */
#ifndef CTL_H
#define CTL_H

#include <jansson.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>

/* Exit codes of acqctl (sysexits.h values; documented in acqctl(1)). */
#define CTL_EXIT_OK 0
#define CTL_EXIT_REFUSED 1       /* the daemon answered with an error */
#define CTL_EXIT_USAGE 64        /* EX_USAGE: bad command line */
#define CTL_EXIT_DATAERR 65      /* EX_DATAERR: a local input (plan, bench file) is invalid */
#define CTL_EXIT_NOINPUT 66      /* EX_NOINPUT: a local input file cannot be read */
#define CTL_EXIT_UNAVAILABLE 69  /* EX_UNAVAILABLE: no daemon answers on the socket */
#define CTL_EXIT_SOFTWARE 70     /* EX_SOFTWARE: out of memory, internal error */
#define CTL_EXIT_CANTCREAT 73    /* EX_CANTCREAT: the -o output file cannot be written */
#define CTL_EXIT_PROTOCOL 76     /* EX_PROTOCOL: the daemon's reply is not what the protocol says */

/* Local ISO 8601 time with offset ("2026-12-01T18:02:03+01:00") of Unix seconds t; "-" if t is not > 0. */
void ctl_fmt_time(double t, char *buf, size_t cap);
/* Duration as h:mm:ss ("1:02:03"; below 10 s "2.35 s"); "-" if s is not finite or negative. */
void ctl_fmt_dur(double s, char *buf, size_t cap);
/* Angle rounded to 0.01° with its unit ("45.00°"); "-" if not finite. */
void ctl_fmt_angle(double deg, char *buf, size_t cap);
/* A JSON value for humans, by its key's unit suffix (_at time, _s duration, _deg angle, _ms, _nm, _pct, _mm)
 * and axis names (degrees); strings as is, reals rounded to 6 significant digits. */
void ctl_fmt_value(const char *key, json_t *v, char *buf, size_t cap);

/* Make text printable in place: each control character but newline and tab (an escape sequence a sweep name, an
 * event or a device could carry to the operator's terminal) becomes '?'. */
void ctl_printable(char *text);
/* Print the human form of a successful reply to command cmd (protocol name, e.g. "sweep.list") on f (the reply's
 * strings are first made printable, ctl_printable). */
void ctl_print_human(FILE *f, const char *cmd, json_t *rep);
/* Print the human form of a plan dry run (the "plan" object of the plan reply); steps listed if present. */
void ctl_print_plan(FILE *f, json_t *plan);

/* The live view of `acqctl watch`: state fed by events, redrawn on a terminal. */
struct ctl_view;
/* A view drawing on f; tty: full-screen redraw, else nothing is drawn (the caller prints JSON lines). */
struct ctl_view *ctl_view_new(FILE *f, const char *where);
/* Free the view. NULL is fine. */
void ctl_view_free(struct ctl_view *v);
/* Seed the view from a status reply and a devices reply (either may be NULL). */
void ctl_view_status(struct ctl_view *v, json_t *status, json_t *devices);
/* Feed one event (borrowed). */
void ctl_view_event(struct ctl_view *v, json_t *ev);
/* Note the connection state ("connected", "reconnecting: why"). */
void ctl_view_link(struct ctl_view *v, const char *text);
/* Redraw the whole view (terminal escape sequences) at wall time now. */
void ctl_view_draw(struct ctl_view *v, double now);

#endif
