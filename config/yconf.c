/* yconf: libyaml event stream → node tree with positions; typed getters with located errors. */
#include "config/yconf.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <yaml.h>

#include "config/acq_file.h"

#define YC_MAX_DEPTH 64
#define YC_MAX_FILE (16u << 20)

struct yc_doc {
	char *file;
	struct yc_node *root;
	struct yc_node **all;  /* every node, for freeing */
	size_t nall, capall;
};

static void *yc_grow(void *p, size_t *cap, size_t need, size_t elem)
{
	if (need <= *cap)
		return p;
	size_t c = *cap ? *cap * 2 : 8;
	while (c < need)
		c *= 2;
	void *q = realloc(p, c * elem);
	if (q)
		*cap = c;
	return q;
}

static struct yc_node *yc_new(struct yc_doc *doc, enum yc_type type, const yaml_mark_t *mark)
{
	struct yc_node *n = calloc(1, sizeof *n);
	if (!n)
		return NULL;
	struct yc_node **all = yc_grow(doc->all, &doc->capall, doc->nall + 1, sizeof *all);
	if (!all) {
		free(n);
		return NULL;
	}
	doc->all = all;
	doc->all[doc->nall++] = n;
	n->type = type;
	n->line = (int)mark->line + 1;
	n->col = (int)mark->column + 1;
	n->doc = doc;
	return n;
}

static int yc_append(struct yc_node *parent, struct yc_node *key, struct yc_node *item)
{
	if (parent->n == parent->cap) {
		size_t c = parent->cap ? parent->cap * 2 : 4;
		struct yc_node **it = realloc(parent->items, c * sizeof *it);
		if (!it)
			return -1;
		parent->items = it;
		if (parent->type == YC_MAP) {
			struct yc_node **k = realloc(parent->keys, c * sizeof *k);
			if (!k)
				return -1;
			parent->keys = k;
			bool *u = realloc(parent->used, c * sizeof *u);
			if (!u)
				return -1;
			parent->used = u;
		}
		parent->cap = c;
	}
	parent->items[parent->n] = item;
	if (parent->type == YC_MAP) {
		parent->keys[parent->n] = key;
		parent->used[parent->n] = false;
	}
	parent->n++;
	return 0;
}

void yc_free(struct yc_doc *doc)
{
	if (!doc)
		return;
	for (size_t i = 0; i < doc->nall; i++) {
		struct yc_node *n = doc->all[i];
		free(n->value);
		free(n->keys);
		free(n->items);
		free(n->used);
		free(n->asked);
		free(n);
	}
	free(doc->all);
	free(doc->file);
	free(doc);
}

struct yc_node *yc_root(const struct yc_doc *doc)
{
	return doc ? doc->root : NULL;
}

/* The file name the document was read from. */
static const char *yc_file(const struct yc_doc *doc)
{
	return doc ? doc->file : "?";
}

int yc_errf(struct acq_err *err, const struct yc_node *node, const char *fmt, ...)
{
	char body[400];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(body, sizeof body, fmt, ap);
	va_end(ap);
	if (node)
		return acq_errf(err, ACQ_E_CONFIG, "%s:%d:%d: %s", yc_file(node->doc), node->line, node->col, body);
	return acq_errf(err, ACQ_E_CONFIG, "%s", body);
}

/* Line and column (1-based, in characters as libyaml counts them) of byte offset off of text. */
static void yc_text_pos(const char *text, size_t off, size_t *line, size_t *col)
{
	*line = 1;
	*col = 1;
	for (size_t i = 0; i < off; i++)
		if (text[i] == '\n') {
			(*line)++;
			*col = 1;
		} else if (((unsigned char)text[i] & 0xC0) != 0x80) {
			(*col)++;
		}
}

/* The length of the UTF-8 sequence at s (at most n bytes), 0 when it is not one (overlong, a surrogate, beyond
 * U+10FFFF, cut short). */
static size_t yc_utf8_len(const unsigned char *s, size_t n)
{
	unsigned c = s[0];
	size_t k = c < 0x80 ? 1 : (c & 0xE0) == 0xC0 ? 2 : (c & 0xF0) == 0xE0 ? 3 : (c & 0xF8) == 0xF0 ? 4 : 0;
	if (!k || k > n)
		return 0;
	unsigned long cp = k == 1 ? c : c & (0x7Fu >> k);
	for (size_t i = 1; i < k; i++) {
		if ((s[i] & 0xC0) != 0x80)
			return 0;
		cp = cp << 6 | (s[i] & 0x3F);
	}
	static const unsigned long min_cp[5] = { 0, 0, 0x80, 0x800, 0x10000 };
	if (cp < min_cp[k] || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF))
		return 0;
	return k;
}

int yc_check_text(const char *name, const char *text, size_t len, struct acq_err *err)
{
	const unsigned char *u = (const unsigned char *)text;
	if (len >= 2 && ((u[0] == 0xFF && u[1] == 0xFE) || (u[0] == 0xFE && u[1] == 0xFF)))
		return acq_errf(err, ACQ_E_CONFIG, "%s: UTF-16 text: save the file as UTF-8", name);
	for (size_t i = 0; i < len;) {
		size_t k = u[i] ? yc_utf8_len(u + i, len - i) : 0;
		if (k) {
			i += k;
			continue;
		}
		size_t line, col;
		yc_text_pos(text, i, &line, &col);
		if (!u[i])
			return acq_errf(err, ACQ_E_CONFIG, "%s:%zu:%zu: a NUL byte: not a text file (binary, or damaged)",
					name, line, col);
		return acq_errf(err, ACQ_E_CONFIG, "%s:%zu:%zu: byte 0x%02x is not UTF-8: save the file as UTF-8", name,
				line, col, u[i]);
	}
	return 0;
}

static int yc_parse(struct yc_doc *doc, yaml_parser_t *parser, struct acq_err *err)
{
	struct yc_node *stack[YC_MAX_DEPTH];
	struct yc_node *pending_key[YC_MAX_DEPTH];
	int depth = 0, ndocs = 0;
	yaml_event_t ev;

	for (;;) {
		if (!yaml_parser_parse(parser, &ev)) {
			if (parser->error == YAML_READER_ERROR) { /* no mark: the reader counts bytes */
				size_t line, col;
				size_t n = (size_t)(parser->input.string.end - parser->input.string.start);
				yc_text_pos((const char *)parser->input.string.start,
					    parser->problem_offset < n ? parser->problem_offset : n, &line, &col);
				return acq_errf(err, ACQ_E_CONFIG, "%s:%zu:%zu: %s", doc->file, line, col,
						parser->problem ? parser->problem : "cannot read the text");
			}
			return acq_errf(err, ACQ_E_CONFIG, "%s:%zu:%zu: YAML syntax error: %s%s%s", doc->file,
					parser->problem_mark.line + 1, parser->problem_mark.column + 1,
					parser->problem ? parser->problem : "unknown",
					parser->context ? " " : "", parser->context ? parser->context : "");
		}
		struct yc_node *node = NULL;
		int rc = 0;
		switch (ev.type) {
		case YAML_STREAM_END_EVENT:
			yaml_event_delete(&ev);
			return 0;
		case YAML_DOCUMENT_START_EVENT:
			if (++ndocs > 1)
				rc = acq_errf(err, ACQ_E_CONFIG, "%s:%zu:%zu: only one YAML document per file is allowed",
					      doc->file, ev.start_mark.line + 1, ev.start_mark.column + 1);
			break;
		case YAML_ALIAS_EVENT:
			rc = acq_errf(err, ACQ_E_CONFIG, "%s:%zu:%zu: YAML aliases (*name) are not supported here",
				      doc->file, ev.start_mark.line + 1, ev.start_mark.column + 1);
			break;
		case YAML_SCALAR_EVENT:
			node = yc_new(doc, YC_SCALAR, &ev.start_mark);
			if (!node || !(node->value = strndup((const char *)ev.data.scalar.value, ev.data.scalar.length)))
				rc = acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", doc->file);
			else if (strlen(node->value) != ev.data.scalar.length)
				rc = acq_errf(err, ACQ_E_CONFIG, "%s:%d:%d: NUL byte inside a value", doc->file,
					      node->line, node->col);
			else
				node->quoted = ev.data.scalar.style != YAML_PLAIN_SCALAR_STYLE;
			break;
		case YAML_SEQUENCE_START_EVENT:
		case YAML_MAPPING_START_EVENT:
			node = yc_new(doc, ev.type == YAML_SEQUENCE_START_EVENT ? YC_SEQ : YC_MAP, &ev.start_mark);
			if (!node)
				rc = acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", doc->file);
			else if (depth >= YC_MAX_DEPTH)
				rc = acq_errf(err, ACQ_E_CONFIG, "%s:%d:%d: nesting deeper than %d levels", doc->file,
					      node->line, node->col, YC_MAX_DEPTH);
			break;
		case YAML_SEQUENCE_END_EVENT:
		case YAML_MAPPING_END_EVENT:
			node = stack[--depth];
			if (node->type == YC_MAP && pending_key[depth])
				rc = acq_errf(err, ACQ_E_CONFIG, "%s: internal: dangling key", doc->file);
			/* fall through to attach the finished container to its parent */
			break;
		default:
			break;
		}
		if (rc == 0 && node) {
			bool opening = ev.type == YAML_SEQUENCE_START_EVENT || ev.type == YAML_MAPPING_START_EVENT;
			if (opening) {
				pending_key[depth] = NULL;
				stack[depth++] = node;
			} else {
				/* scalar or a closed container: attach to the parent */
				if (depth == 0) {
					doc->root = node;
				} else {
					struct yc_node *parent = stack[depth - 1];
					if (parent->type == YC_SEQ) {
						if (yc_append(parent, NULL, node))
							rc = acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", doc->file);
					} else if (!pending_key[depth - 1]) {
						if (node->type != YC_SCALAR) {
							rc = acq_errf(err, ACQ_E_CONFIG,
								      "%s:%d:%d: a mapping key must be a plain value",
								      doc->file, node->line, node->col);
						} else {
							for (size_t i = 0; i < parent->n; i++)
								if (!strcmp(parent->keys[i]->value, node->value)) {
									rc = acq_errf(err, ACQ_E_CONFIG,
										      "%s:%d:%d: duplicate key '%s' (first at line %d)",
										      doc->file, node->line, node->col, node->value,
										      parent->keys[i]->line);
									break;
								}
							pending_key[depth - 1] = node;
						}
					} else {
						if (yc_append(parent, pending_key[depth - 1], node))
							rc = acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", doc->file);
						pending_key[depth - 1] = NULL;
					}
				}
			}
		}
		yaml_event_delete(&ev);
		if (rc)
			return rc;
	}
}

int yc_load_string(const char *name, const char *text, size_t len, struct yc_doc **out, struct acq_err *err)
{
	*out = NULL;
	if (yc_check_text(name ? name : "<string>", text, len, err))
		return -1;
	struct yc_doc *doc = calloc(1, sizeof *doc);
	if (!doc || !(doc->file = strdup(name ? name : "<string>"))) {
		free(doc);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	yaml_parser_t parser;
	if (!yaml_parser_initialize(&parser)) {
		yc_free(doc);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	yaml_parser_set_input_string(&parser, (const unsigned char *)text, len);
	int rc = yc_parse(doc, &parser, err);
	yaml_parser_delete(&parser);
	if (rc) {
		yc_free(doc);
		return -1;
	}
	*out = doc;
	return 0;
}

int yc_load_file(const char *path, struct yc_doc **out, struct acq_err *err)
{
	*out = NULL;
	char *buf;
	size_t len;
	if (acq_file_read(path, YC_MAX_FILE, 0, &buf, &len, err))
		return -1;
	int rc = yc_load_string(path, buf, len, out, err);
	free(buf);
	return rc;
}

static void yc_note_asked(struct yc_node *map, const char *key)
{
	for (size_t i = 0; i < map->nasked; i++)
		if (!strcmp(map->asked[i], key))
			return;
	const char **a = yc_grow(map->asked, &map->capasked, map->nasked + 1, sizeof *a);
	if (!a)
		return;
	map->asked = a;
	map->asked[map->nasked++] = key;
}

struct yc_node *yc_get(struct yc_node *map, const char *key)
{
	if (!map || map->type != YC_MAP)
		return NULL;
	yc_note_asked(map, key);
	for (size_t i = 0; i < map->n; i++)
		if (!strcmp(map->keys[i]->value, key)) {
			map->used[i] = true;
			return map->items[i];
		}
	return NULL;
}

static const char *yc_typename(enum yc_type t)
{
	return t == YC_MAP ? "a mapping" : t == YC_SEQ ? "a sequence" : "a scalar value";
}

int yc_expect_map(const struct yc_node *node, const char *what, struct acq_err *err)
{
	if (node && node->type == YC_MAP)
		return 0;
	if (!node)
		return acq_errf(err, ACQ_E_CONFIG, "%s: expected a mapping, found nothing", what);
	return yc_errf(err, node, "%s: expected a mapping (key: value lines), found %s", what, yc_typename(node->type));
}

int yc_expect_seq(const struct yc_node *node, const char *what, struct acq_err *err)
{
	if (node && node->type == YC_SEQ)
		return 0;
	if (!node)
		return acq_errf(err, ACQ_E_CONFIG, "%s: expected a sequence, found nothing", what);
	return yc_errf(err, node, "%s: expected a sequence (- item lines or [a, b]), found %s", what,
		       yc_typename(node->type));
}

int yc_check_unknown(const struct yc_node *map, const char *what, struct acq_err *err)
{
	if (!map || map->type != YC_MAP)
		return 0;
	for (size_t i = 0; i < map->n; i++) {
		if (map->used[i])
			continue;
		char expected[256] = "";
		size_t off = 0;
		for (size_t k = 0; k < map->nasked && off < sizeof expected; k++)
			off += (size_t)snprintf(expected + off, sizeof expected - off, "%s%s", k ? ", " : "",
						map->asked[k]);
		return yc_errf(err, map->keys[i], "unknown key '%s' in %s (expected one of: %s)", map->keys[i]->value,
			       what, map->nasked ? expected : "no keys");
	}
	return 0;
}

static int yc_scalar_of(const struct yc_node *n, const char *what, struct acq_err *err)
{
	if (n->type != YC_SCALAR)
		return yc_errf(err, n, "%s: expected a single value, found %s", what, yc_typename(n->type));
	return 0;
}

int yc_node_double(const struct yc_node *n, const char *what, double min, double max, double *out,
		   struct acq_err *err)
{
	if (yc_scalar_of(n, what, err))
		return -1;
	char *end;
	errno = 0;
	double v = strtod(n->value, &end);
	if (end == n->value || *end || errno == ERANGE || !isfinite(v) || n->quoted)
		return yc_errf(err, n, "%s: expected a finite number, found '%s'", what, n->value);
	if (v < min || v > max)
		return yc_errf(err, n, "%s: %g is outside [%g, %g]", what, v, min, max);
	*out = v;
	return 0;
}

int yc_node_int(const struct yc_node *n, const char *what, long long min, long long max, long long *out,
		struct acq_err *err)
{
	if (yc_scalar_of(n, what, err))
		return -1;
	char *end;
	errno = 0;
	long long v = strtoll(n->value, &end, 0); /* accepts 0x.. for register addresses */
	if (end == n->value || *end || errno == ERANGE || n->quoted)
		return yc_errf(err, n, "%s: expected an integer, found '%s'", what, n->value);
	if (v < min || v > max)
		return yc_errf(err, n, "%s: %lld is outside [%lld, %lld]", what, v, min, max);
	*out = v;
	return 0;
}

static struct yc_node *yc_lookup(struct yc_node *map, const char *key, bool required, int *rc,
				 struct acq_err *err)
{
	*rc = 0;
	struct yc_node *n = yc_get(map, key);
	if (!n && required) {
		if (map)
			*rc = yc_errf(err, map, "missing required key '%s'", key);
		else
			*rc = acq_errf(err, ACQ_E_CONFIG, "missing required key '%s'", key);
	}
	return n;
}

/* The scalar at key: NULL with *rc 0 (absent and optional) or -1 (missing though required, or not a scalar). */
static struct yc_node *yc_lookup_scalar(struct yc_node *map, const char *key, bool required, int *rc,
					struct acq_err *err)
{
	struct yc_node *n = yc_lookup(map, key, required, rc, err);
	if (n && yc_scalar_of(n, key, err)) {
		*rc = -1;
		return NULL;
	}
	return n;
}

int yc_double(struct yc_node *map, const char *key, bool required, double min, double max, double *out,
	      struct acq_err *err)
{
	int rc;
	struct yc_node *n = yc_lookup(map, key, required, &rc, err);
	return n ? yc_node_double(n, key, min, max, out, err) : rc;
}

int yc_int(struct yc_node *map, const char *key, bool required, long long min, long long max, long long *out,
	   struct acq_err *err)
{
	int rc;
	struct yc_node *n = yc_lookup(map, key, required, &rc, err);
	return n ? yc_node_int(n, key, min, max, out, err) : rc;
}

int yc_bool(struct yc_node *map, const char *key, bool required, bool *out, struct acq_err *err)
{
	int rc;
	struct yc_node *n = yc_lookup_scalar(map, key, required, &rc, err);
	if (!n)
		return rc;
	static const char *const t[] = { "true", "yes", "on" }, *const f[] = { "false", "no", "off" };
	for (int i = 0; i < 3; i++) {
		if (!strcasecmp(n->value, t[i])) { *out = true; return 0; }
		if (!strcasecmp(n->value, f[i])) { *out = false; return 0; }
	}
	return yc_errf(err, n, "%s: expected true or false, found '%s'", key, n->value);
}

int yc_string(struct yc_node *map, const char *key, bool required, const char **out, struct acq_err *err)
{
	int rc;
	struct yc_node *n = yc_lookup_scalar(map, key, required, &rc, err);
	if (!n)
		return rc;
	*out = n->value;
	return 0;
}

int yc_enum(struct yc_node *map, const char *key, bool required, const char *const *names, int *out,
	    struct acq_err *err)
{
	int rc;
	struct yc_node *n = yc_lookup_scalar(map, key, required, &rc, err);
	if (!n)
		return rc;
	char list[256] = "";
	size_t off = 0;
	for (int i = 0; names[i]; i++) {
		if (!strcmp(n->value, names[i])) {
			*out = i;
			return 0;
		}
		if (off < sizeof list)
			off += (size_t)snprintf(list + off, sizeof list - off, "%s%s", i ? ", " : "", names[i]);
	}
	return yc_errf(err, n, "%s: unknown value '%s' (expected one of: %s)", key, n->value, list);
}
