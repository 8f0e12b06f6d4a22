/* proto: the JSON-lines wire protocol shared by acquisitiond and acqctl — line framing with a bound,
 * request parsing and validation against the command table, reply/event/banner formatting. Never logs. */
#ifndef PROTO_H
#define PROTO_H

#include <jansson.h>
#include <stdbool.h>
#include <stddef.h>

#include "config/acq_err.h"

#define PROTO_VERSION 1
#define PROTO_MAX_LINE 65536   /* bytes per line, newline excluded */

/* Wire error codes (error.code of a reply). */
#define PROTO_E_PARSE "parse"                /* not JSON */
#define PROTO_E_INVALID "invalid"            /* JSON but not a valid request: shape, types, values */
#define PROTO_E_UNKNOWN "unknown_command"
#define PROTO_E_TOO_LONG "too_long"          /* line longer than PROTO_MAX_LINE */
#define PROTO_E_FORBIDDEN "forbidden"        /* peer not authorised for this command */
#define PROTO_E_UNAVAILABLE "unavailable"    /* a device or subsystem is absent or not implemented */
#define PROTO_E_NOT_FOUND "not_found"
#define PROTO_E_STATE "state"                /* not allowed now (e.g. a sweep is running) */
#define PROTO_E_RANGE "range"                /* outside soft limits or blind zones */
#define PROTO_E_IO "io"
#define PROTO_E_INTERNAL "internal"

/* ---- framing ---- */
struct proto_lines {
	char *buf;
	size_t len, cap;
	size_t taken;      /* bytes of the line handed out last time, dropped on the next call */
	bool discarding;   /* inside an oversized line: drop bytes up to its newline */
	size_t max;        /* longest line accepted; 0 = PROTO_MAX_LINE (requests). Clients raise it for replies */
};

enum proto_line_kind { PROTO_LINE_NONE = 0, PROTO_LINE_OK = 1, PROTO_LINE_TOO_LONG = 2 };

/* Empty framer. */
void proto_lines_init(struct proto_lines *pl);
/* Release the framer's buffer. */
void proto_lines_free(struct proto_lines *pl);
/* Append received bytes; memory stays bounded by PROTO_MAX_LINE + n. 0 or -1 (no memory). */
int proto_lines_feed(struct proto_lines *pl, const char *data, size_t n);
/* Next complete line: PROTO_LINE_OK (*line NUL-terminated, valid until the next call), PROTO_LINE_TOO_LONG
 * (once per oversized line, as soon as it exceeds the bound), or PROTO_LINE_NONE. */
int proto_lines_next(struct proto_lines *pl, char **line, size_t *len);

/* ---- commands ---- */
enum proto_role { PROTO_OBSERVER = 1, PROTO_CONTROLLER = 2 };
enum proto_argtype { PROTO_T_STRING, PROTO_T_INT, PROTO_T_NUMBER, PROTO_T_BOOL };

struct proto_arg {
	const char *name;
	enum proto_argtype type;
	bool required;
	double min, max;     /* numbers: inclusive range (min == max == 0: any finite); strings: max length */
	const char *alias_of; /* an old name still accepted for the argument named here (not listed by help) */
};

struct proto_cmd {
	const char *name;
	enum proto_role role;     /* the least role allowed to run it */
	const char *summary;      /* one line, for acqctl help */
	struct proto_arg args[6];
	int nargs;
};

/* The command as the operator types it ("sweep.start" -> "sweep start") into buf. Returns buf. */
char *proto_cmd_words(const char *cmd, char *buf, size_t cap);

/* The command table, terminated by an entry with name NULL. */
extern const struct proto_cmd proto_cmds[];
/* The command named name, or NULL. */
const struct proto_cmd *proto_cmd_find(const char *name);

struct proto_req {
	json_t *root;                 /* the request object (owned) */
	json_t *id;                   /* borrowed from root; NULL when absent */
	const char *cmd;              /* borrowed */
	const struct proto_cmd *def;  /* the command's definition */
};

/* Parse and validate one line against the command table. On error returns -1, sets *code to a wire code
 * and err's message, and still fills req->id when the line had a usable id. proto_req_free() either way. */
int proto_req_parse(const char *line, size_t len, struct proto_req *req, const char **code, struct acq_err *err);
/* Release a request. */
void proto_req_free(struct proto_req *req);

/* ---- formatting: each returns a malloc'd line ending in '\n', or NULL (no memory) ---- */
/* {"id": id, "ok": true, <fields of data>}; data (object or NULL) is consumed. */
char *proto_reply_ok(json_t *id, json_t *data);
/* {"id": id, "ok": false, "error": {"code": code, "message": msg}}. */
char *proto_reply_err(json_t *id, const char *code, const char *msg);
/* {"event": name, <fields of data>}; data is consumed. */
char *proto_event(const char *name, json_t *data);
/* The banner sent on connect: {"version": v, "protocol": PROTO_VERSION, "server": "acquisitiond", ...}. */
char *proto_banner(const char *version);
/* The wire code for an error record's class (ACQ_E_RANGE → "range", ...). */
const char *proto_code_of(const struct acq_err *err);

/* ---- client side (acqctl, tests) ---- */
/* Connect to a Unix socket path, or "tcp:PORT" on 127.0.0.1. fd or -1 with err. */
int proto_client_connect(const char *where, struct acq_err *err);
/* Read one complete line from fd through pl (blocking, timeout_ms < 0: forever). The returned JSON value
 * is owned by the caller. NULL with err on EOF, timeout, oversize or bad JSON. */
json_t *proto_client_read(int fd, struct proto_lines *pl, int timeout_ms, struct acq_err *err);
/* proto_client_read() that also accepts a file descriptor passed with the data (SCM_RIGHTS, e.g. an export
 * stream): it is stored in *passed if that is -1, else closed. */
json_t *proto_client_read_fd(int fd, struct proto_lines *pl, int timeout_ms, int *passed, struct acq_err *err);
/* Longest reply line acqctl accepts (a plan listing every step, a spectrum). */
#define PROTO_MAX_REPLY (64u << 20)
/* Write all of a line to fd. 0 or -1. */
int proto_write_all(int fd, const char *buf, size_t len, struct acq_err *err);

#endif
