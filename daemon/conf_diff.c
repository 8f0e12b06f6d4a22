/* conf_diff: the settings that differ between two YAML trees (see conf_diff.h). */
#include "daemon/conf_diff.h"

#include <stdio.h>
#include <string.h>

struct diff {
	int n, max;
	json_t *lines;
};

/* Scalar settings under n (1 for a scalar). */
static int count_leaves(const struct yc_node *n)
{
	if (!n)
		return 0;
	if (n->type == YC_SCALAR)
		return 1;
	int c = 0;
	for (size_t i = 0; i < n->n; i++)
		c += count_leaves(n->items[i]);
	return c;
}

/* A short form of n: its value (cut at 60 characters) or "N settings". */
static void brief(const struct yc_node *n, char *buf, size_t cap)
{
	if (n->type == YC_SCALAR) {
		snprintf(buf, cap, "%s%.60s%s", n->value[0] ? "" : "''", n->value, strlen(n->value) > 60 ? "…" : "");
	} else {
		int c = count_leaves(n);
		snprintf(buf, cap, "%d setting%s", c, c == 1 ? "" : "s");
	}
}

/* One difference: "path: what" (appended while fewer than max). */
static void add(struct diff *d, const char *path, const char *what)
{
	if (d->n++ >= d->max)
		return;
	char line[768];
	snprintf(line, sizeof line, "%s: %s", path[0] ? path : "(the whole file)", what);
	json_array_append_new(d->lines, json_string(line));
}

/* Whether two trees hold the same settings (mapping keys in any order). */
static bool same(const struct yc_node *a, const struct yc_node *b)
{
	if (a->type != b->type || a->n != b->n)
		return false;
	if (a->type == YC_SCALAR)
		return !strcmp(a->value, b->value);
	for (size_t i = 0; i < a->n; i++) {
		const struct yc_node *bi = NULL;
		if (a->type == YC_SEQ)
			bi = b->items[i];
		else
			for (size_t j = 0; j < b->n && !bi; j++)
				if (!strcmp(a->keys[i]->value, b->keys[j]->value))
					bi = b->items[j];
		if (!bi || !same(a->items[i], bi))
			return false;
	}
	return true;
}

static void walk(struct diff *d, const char *path, const struct yc_node *a, const struct yc_node *b)
{
	char x[96], y[96], what[256];
	if (!a && !b)
		return;
	if (!a || !b) {
		brief(a ? a : b, x, sizeof x);
		snprintf(what, sizeof what, a ? "removed (was %s)" : "added (%s)", x);
		add(d, path, what);
		return;
	}
	if (a->type == YC_MAP && b->type == YC_MAP) {
		char sub[512];
		for (size_t i = 0; i < a->n; i++) {
			const struct yc_node *bi = NULL;
			for (size_t j = 0; j < b->n && !bi; j++)
				if (!strcmp(a->keys[i]->value, b->keys[j]->value))
					bi = b->items[j];
			snprintf(sub, sizeof sub, "%s%s%s", path, path[0] ? "." : "", a->keys[i]->value);
			walk(d, sub, a->items[i], bi);
		}
		for (size_t j = 0; j < b->n; j++) {
			bool in_a = false;
			for (size_t i = 0; i < a->n && !in_a; i++)
				in_a = !strcmp(a->keys[i]->value, b->keys[j]->value);
			snprintf(sub, sizeof sub, "%s%s%s", path, path[0] ? "." : "", b->keys[j]->value);
			if (!in_a)
				walk(d, sub, NULL, b->items[j]);
		}
		return;
	}
	if (same(a, b))
		return;
	if (a->type == YC_SEQ && b->type == YC_SEQ && a->n == b->n) {
		char sub[512];
		for (size_t i = 0; i < a->n; i++) {
			snprintf(sub, sizeof sub, "%s[%zu]", path, i);
			walk(d, sub, a->items[i], b->items[i]);
		}
		return;
	}
	brief(a, x, sizeof x);
	brief(b, y, sizeof y);
	if (a->type == YC_SEQ && b->type == YC_SEQ)
		snprintf(x, sizeof x, "%zu items", a->n), snprintf(y, sizeof y, "%zu items", b->n);
	snprintf(what, sizeof what, "%s → %s", x, y);
	add(d, path, what);
}

int conf_diff(const struct yc_node *a, const struct yc_node *b, int max, json_t *lines)
{
	struct diff d = { 0, max, lines };
	walk(&d, "", a, b);
	return d.n;
}
