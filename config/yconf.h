/* yconf: YAML files (through libyaml) as a tree of nodes that remember file, line and column, with typed
 * getters whose errors say what and where, and detection of unknown keys. Every config section parser in
 * the project (bench, devices, register maps, plans, daemon, simulator) is written on top of this. */
#ifndef YCONF_H
#define YCONF_H

#include <stdbool.h>
#include <stddef.h>

#include "config/acq_err.h"

enum yc_type { YC_SCALAR, YC_MAP, YC_SEQ };

struct yc_doc;

struct yc_node {
	enum yc_type type;
	char *value;              /* scalar text (NUL-terminated), NULL for maps and sequences */
	bool quoted;              /* scalar was quoted in the file (so "null"/"~" stay strings) */
	int line, col;            /* 1-based position in the file */
	size_t n;                 /* number of items (sequence) or pairs (mapping) */
	struct yc_node **keys;    /* mapping keys (scalars), n of them */
	struct yc_node **items;   /* mapping values or sequence items, n of them */
	bool *used;               /* mapping: key i was asked for (unknown-key detection) */
	const char **asked;       /* mapping: names asked for, to list the expected keys */
	size_t nasked, capasked;
	size_t cap;               /* allocated items (internal) */
	const struct yc_doc *doc;
};

/* Parse a YAML file (one document, no aliases); NULL root for an empty file. 0 or -1 with err. */
int yc_load_file(const char *path, struct yc_doc **out, struct acq_err *err);
/* Parse YAML text; name is used as the file name in messages. 0 or -1 with err. */
int yc_load_string(const char *name, const char *text, size_t len, struct yc_doc **out, struct acq_err *err);
/* 0 when text[0, len) is UTF-8 without NUL bytes (what every YAML file here must be), else -1 with err
 * "name:line:col: ..." (yc_load_string checks it first). */
int yc_check_text(const char *name, const char *text, size_t len, struct acq_err *err);
/* Free a document and all its nodes. */
void yc_free(struct yc_doc *doc);
/* The root node (NULL for an empty document). */
struct yc_node *yc_root(const struct yc_doc *doc);

/* Error prefixed "file:line:col: " of node (or of the file when node is NULL); returns -1. */
int yc_errf(struct acq_err *err, const struct yc_node *node, const char *fmt, ...)
	__attribute__((format(printf, 3, 4)));

/* Look up key in a mapping, marking it used; NULL when absent (or map is NULL). */
struct yc_node *yc_get(struct yc_node *map, const char *key);
/* 0 if node is a mapping, else -1 with "expected a mapping for <what>". */
int yc_expect_map(const struct yc_node *node, const char *what, struct acq_err *err);
/* 0 if node is a sequence, else -1 with "expected a sequence for <what>". */
int yc_expect_seq(const struct yc_node *node, const char *what, struct acq_err *err);
/* -1 naming the first key of map that no getter asked for, and the expected keys; 0 if none. */
int yc_check_unknown(const struct yc_node *map, const char *what, struct acq_err *err);

/* Typed getters. Each: key absent and !required → 0, *out untouched; absent and required → -1;
 * present but malformed or out of [min, max] → -1 with file:line:col and the expected form. */
int yc_double(struct yc_node *map, const char *key, bool required, double min, double max, double *out,
	      struct acq_err *err);
int yc_int(struct yc_node *map, const char *key, bool required, long long min, long long max, long long *out,
	   struct acq_err *err);
int yc_bool(struct yc_node *map, const char *key, bool required, bool *out, struct acq_err *err);
/* *out points into the document (valid until yc_free). */
int yc_string(struct yc_node *map, const char *key, bool required, const char **out, struct acq_err *err);
/* names is NULL-terminated; *out is the index of the matching name. */
int yc_enum(struct yc_node *map, const char *key, bool required, const char *const *names, int *out,
	    struct acq_err *err);

/* Scalar node conversions, same error conventions (what names the value in messages). */
int yc_node_double(const struct yc_node *n, const char *what, double min, double max, double *out,
		   struct acq_err *err);
int yc_node_int(const struct yc_node *n, const char *what, long long min, long long max, long long *out,
		struct acq_err *err);

#endif
