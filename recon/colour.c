/* colour: spectral → XYZ → linear sRGB → normalised, gamut-mapped, range-mapped RGB (paper Fig. 2). */
#include "recon/colour.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "config/yconf.h"
#include "recon/cie_tables.h"

/* XYZ → linear sRGB (D65 white), from the CIE README (primaries and white of IEC 61966-2-1). */
static const double srgb_from_xyz[3][3] = {
	{ 3.2409699, -1.5373832, -0.4986108 },
	{ -0.9692436, 1.8759675, 0.0415551 },
	{ 0.0556301, -0.2039770, 1.0569715 },
};

/* Bradford cone response matrix (Lam 1985), used for the von Kries-type white adaptation. */
static const double bradford[3][3] = {
	{ 0.8951, 0.2664, -0.1614 },
	{ -0.7502, 1.7135, 0.0367 },
	{ 0.0389, -0.0685, 1.0296 },
};

static const char *const illum_names[] = { "D65", "E", NULL };
static const char *const gap_names[] = { "extend", "zero", NULL };
static const char *const adapt_names[] = { "bradford", "none", NULL };
static const char *const norm_names[] = { "white", "absolute", "max_albedo", NULL };
static const char *const gamut_names[] = { "clamp", "desaturate", NULL };
static const char *const range_names[] = { "keep", "clip", "reinhard", NULL };

void colour_opts_default(struct colour_opts *o)
{
	memset(o, 0, sizeof(*o));
	o->illum = COLOUR_ILLUM_D65;
	o->gap = COLOUR_GAP_EXTEND;
	o->adapt = COLOUR_ADAPT_BRADFORD;
	o->norm = COLOUR_NORM_WHITE;
	o->white = 1.0 / M_PI;
	o->max_albedo = 1.0;
	o->target = 1.0;
	o->exposure = 1.0;
	o->gamut = COLOUR_GAMUT_CLAMP;
	o->range = COLOUR_RANGE_KEEP;
	o->reinhard_white = 4.0;
	o->srgb_encode = false;
}

void colour_opts_brdf(struct colour_opts *o)
{
	colour_opts_default(o);
	o->norm = COLOUR_NORM_ABSOLUTE;
	o->gamut = COLOUR_GAMUT_CLAMP;
	o->range = COLOUR_RANGE_KEEP;
	o->srgb_encode = false;
}

static int positive(double v)
{
	return isfinite(v) && v > 0;
}

int colour_opts_check(const struct colour_opts *o, struct acq_err *err)
{
	if (!o)
		return acq_errf(err, ACQ_E_INVAL, "colour: no options");
	if ((unsigned)o->illum > COLOUR_ILLUM_E || (unsigned)o->gap > COLOUR_GAP_ZERO ||
	    (unsigned)o->adapt > COLOUR_ADAPT_NONE || (unsigned)o->norm > COLOUR_NORM_MAX_ALBEDO ||
	    (unsigned)o->gamut > COLOUR_GAMUT_DESATURATE || (unsigned)o->range > COLOUR_RANGE_REINHARD)
		return acq_errf(err, ACQ_E_INVAL, "colour: an option has an unknown value");
	if (!positive(o->white))
		return acq_errf(err, ACQ_E_INVAL, "colour: white must be finite and > 0 (got %g)", o->white);
	if (!positive(o->exposure))
		return acq_errf(err, ACQ_E_INVAL, "colour: exposure must be finite and > 0 (got %g)", o->exposure);
	if (o->norm == COLOUR_NORM_MAX_ALBEDO && (!positive(o->max_albedo) || !positive(o->target)))
		return acq_errf(err, ACQ_E_INVAL, "colour: max_albedo (%g) and target (%g) must be finite and > 0",
				o->max_albedo, o->target);
	if (o->range == COLOUR_RANGE_REINHARD && !positive(o->reinhard_white))
		return acq_errf(err, ACQ_E_INVAL, "colour: reinhard_white must be finite and > 0 (got %g)",
				o->reinhard_white);
	return 0;
}

static int pick(const char *const *names, int count, const char *key, const char *value, int *out,
		struct acq_err *err)
{
	for (int i = 0; i < count; i++) {
		if (strcasecmp(names[i], value) == 0) {
			*out = i;
			return 0;
		}
	}
	return acq_errf(err, ACQ_E_INVAL, "colour: %s: unknown value \"%s\"", key, value);
}

static int number(const char *key, const char *value, double *out, struct acq_err *err)
{
	char *end = NULL;
	errno = 0;
	double v = strtod(value, &end);
	if (end == value || *end != '\0' || errno != 0 || !positive(v))
		return acq_errf(err, ACQ_E_INVAL, "colour: %s: expected a finite number > 0, got \"%s\"", key, value);
	*out = v;
	return 0;
}

int colour_opts_set(struct colour_opts *o, const char *key, const char *value, struct acq_err *err)
{
	int v = 0;
	if (!o || !key || !value)
		return acq_errf(err, ACQ_E_INVAL, "colour: option key or value missing");
#define ENUMOPT(name, arr, field, type)                                                        \
	if (strcmp(key, name) == 0) {                                                          \
		if (pick(arr, (int)(sizeof(arr) / sizeof(arr[0])) - 1, key, value, &v, err) != 0) \
			return -1;                                                             \
		o->field = (type)v;                                                            \
		return 0;                                                                      \
	}
	ENUMOPT("illum", illum_names, illum, enum colour_illum)
	ENUMOPT("gap", gap_names, gap, enum colour_gap)
	ENUMOPT("adapt", adapt_names, adapt, enum colour_adapt)
	ENUMOPT("norm", norm_names, norm, enum colour_norm)
	ENUMOPT("gamut", gamut_names, gamut, enum colour_gamut)
	ENUMOPT("range", range_names, range, enum colour_range)
#undef ENUMOPT
	if (strcmp(key, "white") == 0)
		return number(key, value, &o->white, err);
	if (strcmp(key, "max_albedo") == 0)
		return number(key, value, &o->max_albedo, err);
	if (strcmp(key, "target") == 0)
		return number(key, value, &o->target, err);
	if (strcmp(key, "exposure") == 0)
		return number(key, value, &o->exposure, err);
	if (strcmp(key, "reinhard_white") == 0)
		return number(key, value, &o->reinhard_white, err);
	if (strcmp(key, "srgb_encode") == 0) {
		if (strcmp(value, "true") == 0 || strcmp(value, "1") == 0)
			o->srgb_encode = true;
		else if (strcmp(value, "false") == 0 || strcmp(value, "0") == 0)
			o->srgb_encode = false;
		else
			return acq_errf(err, ACQ_E_INVAL, "colour: srgb_encode: expected true or false, got \"%s\"",
					value);
		return 0;
	}
	return acq_errf(err, ACQ_E_INVAL, "colour: unknown option \"%s\"", key);
}

int colour_opts_from_yaml(struct yc_node *map, struct colour_opts *o, struct acq_err *err)
{
	if (!map)
		return 0;
	if (yc_expect_map(map, "colour", err) != 0)
		return -1;
	int v;
#define YENUM(key, arr, field, type)                                  \
	v = (int)o->field;                                           \
	if (yc_enum(map, key, false, arr, &v, err) != 0)             \
		return -1;                                           \
	o->field = (type)v;
	YENUM("illum", illum_names, illum, enum colour_illum)
	YENUM("gap", gap_names, gap, enum colour_gap)
	YENUM("adapt", adapt_names, adapt, enum colour_adapt)
	YENUM("norm", norm_names, norm, enum colour_norm)
	YENUM("gamut", gamut_names, gamut, enum colour_gamut)
	YENUM("range", range_names, range, enum colour_range)
#undef YENUM
	const double big = 1e300, tiny = 1e-300;
	if (yc_double(map, "white", false, tiny, big, &o->white, err) != 0 ||
	    yc_double(map, "max_albedo", false, tiny, big, &o->max_albedo, err) != 0 ||
	    yc_double(map, "target", false, tiny, big, &o->target, err) != 0 ||
	    yc_double(map, "exposure", false, tiny, big, &o->exposure, err) != 0 ||
	    yc_double(map, "reinhard_white", false, tiny, big, &o->reinhard_white, err) != 0 ||
	    yc_bool(map, "srgb_encode", false, &o->srgb_encode, err) != 0 || yc_check_unknown(map, "colour", err) != 0)
		return -1;
	return colour_opts_check(o, err);
}

static const char *name_of(const char *const *names, unsigned count, unsigned v)
{
	return v < count ? names[v] : "invalid";
}
#define NAME(arr, v) name_of(arr, (unsigned)(sizeof(arr) / sizeof(arr[0]) - 1), (unsigned)(v))

/* A JSON number, or null for a non-finite value (JSON has no NaN/Inf). */
static const char *jnum(char buf[32], double v)
{
	if (isfinite(v))
		snprintf(buf, 32, "%.17g", v);
	else
		snprintf(buf, 32, "null");
	return buf;
}

int colour_opts_json(const struct colour_opts *o, const struct colour_stats *stats, char *buf, size_t len)
{
	char st[256] = "", n1[32], n2[32], n3[32], n4[32], n5[32];
	if (stats)
		snprintf(st, sizeof(st),
			 ",\"stats\":{\"colours\":%zu,\"out_of_gamut\":%zu,\"clipped\":%zu,\"nonfinite\":%zu}",
			 stats->n, stats->out_of_gamut, stats->clipped, stats->nonfinite);
	return snprintf(buf, len,
			"{\"observer\":\"CIE 1931 2deg, 1 nm, 360-830 nm\",\"spectrum\":\"piecewise linear, "
			"1 nm bin means\",\"illuminant\":\"%s\",\"gap\":\"%s\",\"adaptation\":\"%s\","
			"\"xyz_to_rgb\":\"linear sRGB (IEC 61966-2-1, D65)\",\"normalisation\":\"%s\","
			"\"white\":%s,\"max_albedo\":%s,\"target\":%s,\"exposure\":%s,"
			"\"out_of_gamut\":\"%s\",\"dynamic_range\":\"%s\",\"reinhard_white\":%s,"
			"\"encoding\":\"%s\"%s}",
			NAME(illum_names, o->illum), NAME(gap_names, o->gap), NAME(adapt_names, o->adapt),
			NAME(norm_names, o->norm), jnum(n1, o->white), jnum(n2, o->max_albedo), jnum(n3, o->target),
			jnum(n4, o->exposure), NAME(gamut_names, o->gamut), NAME(range_names, o->range),
			jnum(n5, o->reinhard_white), o->srgb_encode ? "sRGB transfer curve" : "linear", st);
}

int colour_opts_write_json(FILE *f, const struct colour_opts *o, const struct colour_stats *stats,
			   struct acq_err *err)
{
	int n = colour_opts_json(o, stats, NULL, 0);
	char *buf = n > 0 ? malloc((size_t)n + 1) : NULL;
	if (!buf)
		return acq_errf(err, ACQ_E_NOMEM, "colour: out of memory writing metadata");
	colour_opts_json(o, stats, buf, (size_t)n + 1);
	int rc = fputs(buf, f) < 0 ? acq_errf(err, ACQ_E_IO, "colour: writing metadata: %s", strerror(errno)) : 0;
	free(buf);
	return rc;
}

/* Illuminant relative power at integer wavelength nm (360..830); D65 interpolated linearly from 5 nm. */
static double illum_at(enum colour_illum illum, int nm)
{
	if (illum == COLOUR_ILLUM_E)
		return 1.0;
	int off = nm - CIE_D65_FIRST_NM;
	int i = off / CIE_D65_STEP_NM;
	int r = off % CIE_D65_STEP_NM;
	if (r == 0 || i + 1 >= CIE_D65_N)
		return cie_d65_spd[i];
	double t = (double)r / CIE_D65_STEP_NM;
	return cie_d65_spd[i] * (1 - t) + cie_d65_spd[i + 1] * t;
}

void colour_illum_white_xyz(enum colour_illum illum, double xyz[3])
{
	double s[3] = { 0, 0, 0 };
	for (int j = 0; j < CIE_CMF_N; j++) {
		double e = illum_at(illum, CIE_CMF_FIRST_NM + j);
		for (int c = 0; c < 3; c++)
			s[c] += e * cie_cmf_1931_2deg[j][c];
	}
	for (int c = 0; c < 3; c++)
		xyz[c] = s[c] / s[1];
}

int colour_xyz_weights(enum colour_illum illum, enum colour_gap gap, const double *wl, size_t n, double *Wxyz,
		       double *ynorm, struct acq_err *err)
{
	if (!wl || !Wxyz || n == 0)
		return acq_errf(err, ACQ_E_INVAL, "colour: empty wavelength grid");
	if ((unsigned)illum > COLOUR_ILLUM_E || (unsigned)gap > COLOUR_GAP_ZERO)
		return acq_errf(err, ACQ_E_INVAL, "colour: unknown illuminant or gap rule");
	for (size_t k = 0; k < n; k++) {
		if (!isfinite(wl[k]))
			return acq_errf(err, ACQ_E_INVAL, "colour: wavelength %zu is not finite", k);
		if (k > 0 && !(wl[k] > wl[k - 1]))
			return acq_errf(err, ACQ_E_INVAL, "colour: wavelengths not strictly ascending at %zu (%g after %g)",
					k, wl[k], wl[k - 1]);
	}
	memset(Wxyz, 0, 3 * n * sizeof(*Wxyz));
	double ysum = 0;
	size_t k0 = 0;
	for (int j = 0; j < CIE_CMF_N; j++) {
		double lc = CIE_CMF_FIRST_NM + j, a = lc - 0.5, b = lc + 0.5;
		double e = illum_at(illum, CIE_CMF_FIRST_NM + j);
		double ec[3] = { e * cie_cmf_1931_2deg[j][0], e * cie_cmf_1931_2deg[j][1], e * cie_cmf_1931_2deg[j][2] };
		ysum += ec[1];
#define ADD(idx, len)                                              \
	do {                                                       \
		for (int c_ = 0; c_ < 3; c_++)                     \
			Wxyz[(size_t)c_ * n + (idx)] += ec[c_] * (len); \
	} while (0)
		/* Parts of the 1 nm bin outside the sampled range: the recorded gap rule. */
		if (gap == COLOUR_GAP_EXTEND && a < wl[0])
			ADD(0, fmin(b, wl[0]) - a);
		if (gap == COLOUR_GAP_EXTEND && b > wl[n - 1])
			ADD(n - 1, b - fmax(a, wl[n - 1]));
		/* Inside: exact integral of the piecewise-linear interpolant over the bin. */
		while (k0 + 1 < n && wl[k0 + 1] <= a)
			k0++;
		for (size_t k = k0; k + 1 < n && wl[k] < b; k++) {
			double u = fmax(a, wl[k]), v = fmin(b, wl[k + 1]);
			if (v <= u)
				continue;
			double h = wl[k + 1] - wl[k];
			double tm = ((u - wl[k]) + (v - wl[k])) / (2 * h); /* mean of t over [u, v] */
			ADD(k, (v - u) * (1 - tm));
			ADD(k + 1, (v - u) * tm);
		}
#undef ADD
	}
	if (ynorm)
		*ynorm = ysum;
	return 0;
}

static void mat3_mul(const double a[3][3], const double b[3][3], double out[3][3])
{
	double t[3][3];
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++)
			t[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
	memcpy(out, t, sizeof(t));
}

static void mat3_inv(const double m[3][3], double out[3][3])
{
	double c00 = m[1][1] * m[2][2] - m[1][2] * m[2][1];
	double c01 = m[1][2] * m[2][0] - m[1][0] * m[2][2];
	double c02 = m[1][0] * m[2][1] - m[1][1] * m[2][0];
	double det = m[0][0] * c00 + m[0][1] * c01 + m[0][2] * c02;
	out[0][0] = c00 / det;
	out[1][0] = c01 / det;
	out[2][0] = c02 / det;
	out[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det;
	out[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det;
	out[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det;
	out[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det;
	out[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det;
	out[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det;
}

/* The linear 3 × 3 part after integration: k · M_srgb · A_adapt (XYZ → normalised linear sRGB). */
static void linear_matrix(const struct colour_opts *o, double ynorm, double m[3][3])
{
	double adapt[3][3] = { { 1, 0, 0 }, { 0, 1, 0 }, { 0, 0, 1 } };
	if (o->adapt == COLOUR_ADAPT_BRADFORD) {
		double src[3], dst[3] = { 0.3127 / 0.3290, 1.0, (1 - 0.3127 - 0.3290) / 0.3290 };
		colour_illum_white_xyz(o->illum, src);
		double cs[3], cd[3];
		for (int i = 0; i < 3; i++) {
			cs[i] = bradford[i][0] * src[0] + bradford[i][1] * src[1] + bradford[i][2] * src[2];
			cd[i] = bradford[i][0] * dst[0] + bradford[i][1] * dst[1] + bradford[i][2] * dst[2];
		}
		double d[3][3] = { { cd[0] / cs[0], 0, 0 }, { 0, cd[1] / cs[1], 0 }, { 0, 0, cd[2] / cs[2] } };
		double inv[3][3];
		mat3_inv(bradford, inv);
		mat3_mul(d, bradford, adapt);
		mat3_mul(inv, adapt, adapt);
	}
	double scale = 1.0;
	if (o->norm == COLOUR_NORM_WHITE)
		scale = 1.0 / o->white;
	else if (o->norm == COLOUR_NORM_MAX_ALBEDO)
		scale = o->target / (o->max_albedo * o->white);
	scale *= o->exposure / ynorm;
	mat3_mul(srgb_from_xyz, adapt, m);
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++)
			m[i][j] *= scale;
}

int colour_weights(const struct colour_opts *o, const double *wl, size_t n, double *W, struct acq_err *err)
{
	if (colour_opts_check(o, err) != 0)
		return -1;
	if (!W || n == 0)
		return acq_errf(err, ACQ_E_INVAL, "colour: empty wavelength grid");
	double *xyz = malloc(3 * n * sizeof(*xyz));
	if (!xyz)
		return acq_errf(err, ACQ_E_NOMEM, "colour: out of memory for %zu wavelengths", n);
	double ynorm = 1;
	if (colour_xyz_weights(o->illum, o->gap, wl, n, xyz, &ynorm, err) != 0) {
		free(xyz);
		return -1;
	}
	double m[3][3];
	linear_matrix(o, ynorm, m);
	for (int c = 0; c < 3; c++)
		for (size_t k = 0; k < n; k++)
			W[(size_t)c * n + k] = m[c][0] * xyz[k] + m[c][1] * xyz[n + k] + m[c][2] * xyz[2 * n + k];
	free(xyz);
	return 0;
}

void colour_apply_weights(const double *W, size_t n, const double *s, double rgb_lin[3])
{
	for (int c = 0; c < 3; c++) {
		double acc = 0;
		const double *w = W + (size_t)c * n;
		for (size_t k = 0; k < n; k++)
			acc += w[k] * s[k];
		rgb_lin[c] = acc;
	}
}

double colour_luminance(const double rgb[3])
{
	return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
}

double colour_srgb_encode(double v)
{
	if (!(v > 0))
		return 0;
	return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1 / 2.4) - 0.055;
}

double colour_srgb_decode(double v)
{
	if (!(v > 0))
		return 0;
	return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

void colour_finish(const struct colour_opts *o, const double lin[3], double out[3], struct colour_stats *stats)
{
	double r[3] = { lin[0], lin[1], lin[2] };
	if (stats)
		stats->n++;
	if (!isfinite(r[0]) || !isfinite(r[1]) || !isfinite(r[2]) || fabs(r[0]) > 1e300 || fabs(r[1]) > 1e300 ||
	    fabs(r[2]) > 1e300) {
		if (stats)
			stats->nonfinite++;
		out[0] = out[1] = out[2] = 0;
		return;
	}
	/* Stage 5: out of gamut. */
	double mn = fmin(r[0], fmin(r[1], r[2]));
	if (mn < 0) {
		if (stats)
			stats->out_of_gamut++;
		if (o->gamut == COLOUR_GAMUT_DESATURATE) {
			double y = colour_luminance(r);
			double t = y > 0 ? y / (y - mn) : 0;
			for (int c = 0; c < 3; c++)
				r[c] = y > 0 ? y + t * (r[c] - y) : 0;
		}
		for (int c = 0; c < 3; c++)
			r[c] = fmax(r[c], 0); /* CLAMP, and rounding residue of DESATURATE */
	}
	/* Stage 6: dynamic range. */
	if (o->range == COLOUR_RANGE_REINHARD) {
		double y = colour_luminance(r), lw = o->reinhard_white;
		double f = (1 + y / (lw * lw)) / (1 + y);
		for (int c = 0; c < 3; c++)
			r[c] *= f;
	}
	if (o->range != COLOUR_RANGE_KEEP && fmax(r[0], fmax(r[1], r[2])) > 1) {
		if (stats)
			stats->clipped++;
		for (int c = 0; c < 3; c++)
			r[c] = fmin(r[c], 1);
	}
	/* Stage 7: encoding. */
	for (int c = 0; c < 3; c++)
		out[c] = o->srgb_encode ? colour_srgb_encode(r[c]) : r[c];
}

int colour_spectrum_rgb(const struct colour_opts *o, const double *wl, const double *s, size_t n, double rgb[3],
			struct colour_stats *stats, struct acq_err *err)
{
	if (!s || n == 0)
		return acq_errf(err, ACQ_E_INVAL, "colour: empty spectrum");
	double *W = malloc(3 * n * sizeof(*W));
	if (!W)
		return acq_errf(err, ACQ_E_NOMEM, "colour: out of memory for %zu wavelengths", n);
	if (colour_weights(o, wl, n, W, err) != 0) {
		free(W);
		return -1;
	}
	double lin[3];
	colour_apply_weights(W, n, s, lin);
	colour_finish(o, lin, rgb, stats);
	free(W);
	return 0;
}
