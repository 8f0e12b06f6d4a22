/* select_target: the target spec of brdf-recon select and the adaptive plan ("dhr:8,30,60:le=X", "lnf", "rgb",
 * combined "dhr:...:le=X+lnf[:rad|:mix|:bright]:le=Y", any of them ending in the lobe gate ":lobe_above=DEG") parsed
 * into struct select_target. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/select.h"

static int parse_num(const char *s, const char *end, double *out)
{
	char buf[64];
	size_t len = (size_t)(end - s);
	if (len == 0 || len >= sizeof buf)
		return -1;
	memcpy(buf, s, len);
	buf[len] = '\0';
	char *e;
	double v = strtod(buf, &e);
	if (*e || !isfinite(v))
		return -1;
	*out = v;
	return 0;
}

static int target_parse_one(const char *spec, struct select_target *t, struct acq_err *err);

static int target_parse_parts(const char *spec, struct select_target *t, struct acq_err *err);

int select_target_parse(const char *spec, struct select_target *t, struct acq_err *err)
{
	static const char gate[] = ":lobe_above=";
	const char *g = spec ? strstr(spec, gate) : NULL;
	if (!g)
		return target_parse_parts(spec, t, err);
	char body[512];
	double deg;
	const char *x = g + strlen(gate);
	if ((size_t)(g - spec) >= sizeof body)
		return acq_errf(err, ACQ_E_INVAL, "target '%s': too long", spec);
	if (parse_num(x, x + strlen(x), &deg) || !(deg > 0 && deg < 90))
		return acq_errf(err, ACQ_E_INVAL, "target '%s': lobe_above= needs a number of degrees in (0, 90), last",
				spec);
	memcpy(body, spec, (size_t)(g - spec));
	body[g - spec] = '\0';
	if (target_parse_parts(body, t, err))
		return -1;
	t->lobe_above_deg = deg;
	return 0;
}

/* select_target_parse without the lobe gate's suffix. */
static int target_parse_parts(const char *spec, struct select_target *t, struct acq_err *err)
{
	const char *plus = spec ? strchr(spec, '+') : NULL;
	if (!plus)
		return target_parse_one(spec, t, err);
	char first[512];
	struct select_target t2;
	if ((size_t)(plus - spec) >= sizeof first)
		return acq_errf(err, ACQ_E_INVAL, "target '%s': too long", spec);
	memcpy(first, spec, (size_t)(plus - spec));
	first[plus - spec] = '\0';
	if (target_parse_one(first, t, err) || target_parse_one(plus + 1, &t2, err))
		return -1;
	if (t->kind != SELECT_DHR || t2.kind != SELECT_LNF || !isfinite(t->threshold) || !isfinite(t2.threshold))
		return acq_errf(err, ACQ_E_INVAL, "target '%s': a combined target is dhr:THETA[,...]:le=X+lnf:le=Y (both "
				"thresholds given: both must be met)", spec);
	t->lnf_threshold = t2.threshold;
	t->lnf_rad = t2.lnf_rad;
	return 0;
}

static int target_parse_one(const char *spec, struct select_target *t, struct acq_err *err)
{
	memset(t, 0, sizeof *t);
	t->threshold = NAN;
	if (!spec || !*spec)
		return acq_errf(err, ACQ_E_INVAL, "target: empty (dhr:8,30,60, lnf or rgb, optionally :le=X)");
	const char *p = spec, *le = strstr(spec, ":le=");
	const char *body_end = le ? le : spec + strlen(spec);
	if (le) {
		const char *x = le + 4;
		if (parse_num(x, x + strlen(x), &t->threshold) || !(t->threshold > 0))
			return acq_errf(err, ACQ_E_INVAL, "target '%s': le= needs a positive number", spec);
	}
	static const char *const lnf_names[] = { [SELECT_LNF_PROJECTED] = "lnf", [SELECT_LNF_RAD] = "lnf:rad",
						 [SELECT_LNF_MIX] = "lnf:mix", [SELECT_LNF_BRIGHT] = "lnf:bright" };
	for (int w = 0; w < (int)(sizeof lnf_names / sizeof lnf_names[0]); w++)
		if ((size_t)(body_end - p) == strlen(lnf_names[w]) && !strncmp(p, lnf_names[w], strlen(lnf_names[w]))) {
			t->kind = SELECT_LNF;
			t->lnf_rad = w;
			return 0;
		}
	if ((size_t)(body_end - p) == 3 && !strncmp(p, "rgb", 3)) {
		t->kind = SELECT_RGB;
		return 0;
	}
	if (strncmp(p, "dhr:", 4) || body_end <= p + 4)
		return acq_errf(err, ACQ_E_INVAL, "target '%s': expected dhr:THETA[,THETA...], lnf or rgb, optionally :le=X",
				spec);
	t->kind = SELECT_DHR;
	for (const char *a = p + 4; a < body_end;) {
		const char *c = memchr(a, ',', (size_t)(body_end - a));
		const char *e = c ? c : body_end;
		double th;
		if (t->nth == SELECT_MAX_THETA)
			return acq_errf(err, ACQ_E_INVAL, "target '%s': at most %d incidences", spec, SELECT_MAX_THETA);
		if (parse_num(a, e, &th) || th < 0 || th > 90)
			return acq_errf(err, ACQ_E_INVAL, "target '%s': incidence '%.*s' is not a number of degrees in [0, 90]",
					spec, (int)(e - a), a);
		t->theta_deg[t->nth++] = th;
		a = c ? c + 1 : body_end;
		if (c && a == body_end)
			return acq_errf(err, ACQ_E_INVAL, "target '%s': empty incidence after ','", spec);
	}
	return 0;
}
