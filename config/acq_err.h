/* acq_err: the error record every library in this project fills instead of logging (style habit 6). */
#ifndef ACQ_ERR_H
#define ACQ_ERR_H

#include <stddef.h>

/* Error classes shared by all modules; a module may add detail in the message and its own sub-code. */
enum acq_errcode {
	ACQ_OK = 0,
	ACQ_E_INVAL,       /* bad argument or bad input data */
	ACQ_E_CONFIG,      /* configuration error (message names file:line:col) */
	ACQ_E_IO,          /* operating-system I/O error */
	ACQ_E_TIMEOUT,     /* a device or peer did not answer in time */
	ACQ_E_DEVICE,      /* a device answered with an error or an alarm */
	ACQ_E_PROTO,       /* malformed or unexpected protocol data */
	ACQ_E_NOMEM,       /* allocation failed */
	ACQ_E_RANGE,       /* value outside limits (soft limit, blind zone, buffer size) */
	ACQ_E_STATE,       /* operation not allowed in the current state */
	ACQ_E_UNSUPPORTED, /* feature or reply not supported */
	ACQ_E_NOTFOUND,    /* no such device, file, sweep or key */
	ACQ_E_NUMERIC,     /* numerical failure (singular system, non-finite result) */
	ACQ_E_DISCONNECTED,/* the link to a device was lost */
	ACQ_E__COUNT
};

struct acq_err {
	int code;        /* enum acq_errcode, 0 when no error */
	int detail;      /* module-specific sub-code (e.g. an AvaSpec error reason), 0 if none */
	char msg[512];   /* human-readable, says what and where */
};

/* Fill err (may be NULL) with code and a printf-style message; always returns -1. */
int acq_errf(struct acq_err *err, int code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* Prefix the existing message with printf-style context ("loading x: " + old); returns -1. */
int acq_err_prefix(struct acq_err *err, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* Reset err to "no error". */
void acq_err_clear(struct acq_err *err);

/* Stable lower-case name of an error code ("timeout", "config", ...), for replies and logs. */
const char *acq_errname(int code);

#endif
