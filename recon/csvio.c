/* csvio: CSV read with errors that name the line and the column: the interchange format's samples and queries, and
 * tables of named numeric columns (certificates, references, candidates); the one format of a written number. */
#include "recon/csvio.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "config/acq_file.h"

#define CSV_MAX_COLS 100000
#define CSV_FIELD_MAX 128

struct field {
	const char *p;
	size_t len;
};

/* Columns of the header: role and, for wavelength/sigma columns, the wavelength index. */
enum col_role { COL_TI, COL_PI, COL_TO, COL_PO, COL_VAL, COL_SIG, COL_IGNORE };

struct col {
	int role;
	size_t wl; /* index into the sorted wavelength list */
	double nm;
};

struct lines {
	const char *text;
	size_t len, pos;
	long lineno;
};

/* Next line (without its \n and a trailing \r); returns 0 at end of text. */
static int next_line(struct lines *L, const char **p, size_t *n)
{
	if (L->pos >= L->len)
		return 0;
	const char *s = L->text + L->pos;
	const char *e = memchr(s, '\n', L->len - L->pos);
	size_t k = e ? (size_t)(e - s) : L->len - L->pos;
	L->pos += k + (e ? 1 : 0);
	L->lineno++;
	if (k > 0 && s[k - 1] == '\r')
		k--;
	*p = s;
	*n = k;
	return 1;
}

static void trim(struct field *f)
{
	while (f->len && (f->p[0] == ' ' || f->p[0] == '\t')) {
		f->p++;
		f->len--;
	}
	while (f->len && (f->p[f->len - 1] == ' ' || f->p[f->len - 1] == '\t'))
		f->len--;
}

/* Split a line on commas into fields (at most max); returns the count, or -1 if there are more. */
static long split(const char *p, size_t n, struct field *fs, size_t max)
{
	size_t k = 0, start = 0;
	for (size_t i = 0; i <= n; i++) {
		if (i == n || p[i] == ',') {
			if (k >= max)
				return -1;
			fs[k].p = p + start;
			fs[k].len = i - start;
			trim(&fs[k]);
			k++;
			start = i + 1;
		}
	}
	return (long)k;
}

static int blank(const char *p, size_t n)
{
	for (size_t i = 0; i < n; i++)
		if (!isspace((unsigned char)p[i]))
			return 0;
	return 1;
}

static int field_is(const struct field *f, const char *s)
{
	return f->len == strlen(s) && !memcmp(f->p, s, f->len);
}

/* Parse a finite number; 1 = "missing" (empty or nan), 0 = number, -1 = not a finite number. */
static int parse_num(const struct field *f, double *out)
{
	if (f->len == 0 || (f->len == 3 && !strncasecmp(f->p, "nan", 3))) {
		*out = NAN;
		return 1;
	}
	char buf[CSV_FIELD_MAX];
	if (f->len >= sizeof buf)
		return -1;
	memcpy(buf, f->p, f->len);
	buf[f->len] = '\0';
	for (size_t i = 0; i < f->len; i++) /* digits, sign, point, exponent only: no hex, inf, nan(...) */
		if (!strchr("0123456789+-.eE", buf[i]))
			return -1;
	char *end = NULL;
	errno = 0;
	double v = strtod(buf, &end);
	if (end != buf + f->len || errno == ERANGE || !isfinite(v))
		return -1;
	*out = v;
	return 0;
}

static void show(const struct field *f, char *buf, size_t size)
{
	size_t k = f->len < size - 4 ? f->len : size - 4;
	size_t j = 0;
	for (size_t i = 0; i < k; i++)
		buf[j++] = isprint((unsigned char)f->p[i]) ? f->p[i] : '?';
	if (k < f->len) {
		buf[j++] = '.';
		buf[j++] = '.';
		buf[j++] = '.';
	}
	buf[j] = '\0';
}

int csvio_samples_grow(struct recon_samples *s, size_t cap, bool values, bool sigmas)
{
	size_t width = s->nwl ? s->nwl : 1;
	double *a = realloc(s->ang, cap * 4 * sizeof *a);
	if (!a)
		return -1;
	s->ang = a;
	double *d = realloc(s->deg, cap * 4 * sizeof *d);
	if (!d)
		return -1;
	s->deg = d;
	if (values) {
		double *v = realloc(s->val, cap * width * sizeof *v);
		if (!v)
			return -1;
		s->val = v;
	}
	if (sigmas) {
		double *g = realloc(s->sig, cap * width * sizeof *g);
		if (!g)
			return -1;
		s->sig = g;
	}
	return 0;
}

void csvio_samples_free(struct recon_samples *s)
{
	if (!s)
		return;
	free(s->wl);
	free(s->ang);
	free(s->val);
	free(s->sig);
	free(s->deg);
	memset(s, 0, sizeof *s);
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

static const char *const angle_names[4] = { "theta_i", "phi_i", "theta_o", "phi_o" };

/* One parse: the text's lines, the header's columns (fs: a row's fields, maxf of them at most; cols: ncols
 * roles; wls: the nwl sorted wavelengths) and where the header was. */
struct parser {
	const char *name;
	int want_values;
	struct lines L;
	struct field *fs;
	struct col *cols;
	double *wls;
	size_t maxf, ncols, nwl;
	long header_line;
	int sig_seen_any;
	char shown[48];
};

/* The header line (comments and blank lines skipped): 0 with p, n set, or -1 with err. */
static int find_header(struct parser *P, const char **p, size_t *n, struct acq_err *err)
{
	for (;;) {
		if (!next_line(&P->L, p, n))
			return acq_errf(err, ACQ_E_INVAL, "%s: no header line (theta_i,phi_i,theta_o,phi_o,...)", P->name);
		if (*n && (*p)[0] == '#')
			continue;
		if (blank(*p, *n))
			continue;
		return 0;
	}
}

/* The header's columns: the arrays sized for its fields, each column's role (angle, wavelength, sigma or
 * ignored) and wavelength; the unsorted wavelengths in wls. 0, or -1 with err. */
static int header_columns(struct parser *P, const char *p, size_t n, struct acq_err *err)
{
	const char *name = P->name;
	P->header_line = P->L.lineno;
	P->maxf = 1;
	for (size_t i = 0; i < n; i++)
		P->maxf += p[i] == ',';
	if (P->maxf > CSV_MAX_COLS)
		return acq_errf(err, ACQ_E_INVAL, "%s:%ld: too many columns (%zu, limit %d)", name, P->L.lineno,
				P->maxf, CSV_MAX_COLS);
	P->fs = malloc(P->maxf * sizeof *P->fs);
	P->cols = malloc(P->maxf * sizeof *P->cols);
	P->wls = malloc(P->maxf * sizeof *P->wls);
	if (!P->fs || !P->cols || !P->wls)
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", name);
	struct field *fs = P->fs;
	struct col *cols = P->cols;
	P->ncols = (size_t)split(p, n, fs, P->maxf);
	int seen[4] = { 0, 0, 0, 0 };
	for (size_t c = 0; c < P->ncols; c++) {
		cols[c].role = COL_IGNORE;
		int a;
		for (a = 0; a < 4; a++)
			if (field_is(&fs[c], angle_names[a]))
				break;
		if (a < 4) {
			if (seen[a])
				return acq_errf(err, ACQ_E_INVAL, "%s:%ld: column %zu: duplicate column %s", name,
						P->L.lineno, c + 1, angle_names[a]);
			seen[a] = 1;
			cols[c].role = a;
			continue;
		}
		if (!P->want_values)
			continue;
		struct field g = fs[c];
		int is_sig = 0;
		if (g.len > 6 && !memcmp(g.p, "sigma_", 6)) {
			g.p += 6;
			g.len -= 6;
			is_sig = 1;
		}
		double nm;
		if (parse_num(&g, &nm) != 0 || !(nm > 0) || nm > 1e6) {
			show(&fs[c], P->shown, sizeof P->shown);
			return acq_errf(err, ACQ_E_INVAL,
					"%s:%ld: column %zu: header '%s' is neither an angle column, a wavelength in nm, "
					"nor sigma_<nm>", name, P->L.lineno, c + 1, P->shown);
		}
		cols[c].role = is_sig ? COL_SIG : COL_VAL;
		cols[c].nm = nm;
		if (!is_sig)
			P->wls[P->nwl++] = nm;
	}
	for (int a = 0; a < 4; a++)
		if (!seen[a])
			return acq_errf(err, ACQ_E_INVAL, "%s:%ld: missing column %s", name, P->header_line, angle_names[a]);
	return 0;
}

/* The wavelengths sorted and distinct, each wavelength and sigma column pointed at its index, at most one
 * sigma per wavelength (sig_seen_any: some). 0, or -1 with err. */
static int header_wavelengths(struct parser *P, struct acq_err *err)
{
	const char *name = P->name;
	double *wls = P->wls;
	size_t nwl = P->nwl;
	struct col *cols = P->cols;
	if (P->want_values && nwl == 0)
		return acq_errf(err, ACQ_E_INVAL, "%s:%ld: no wavelength column", name, P->header_line);
	qsort(wls, nwl, sizeof *wls, cmp_double);
	for (size_t k = 1; k < nwl; k++)
		if (wls[k] == wls[k - 1])
			return acq_errf(err, ACQ_E_INVAL, "%s:%ld: wavelength %g nm appears twice", name, P->header_line,
					wls[k]);
	unsigned char *sig_seen = P->want_values ? calloc(nwl ? nwl : 1, 1) : NULL;
	if (P->want_values && !sig_seen)
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", name);
	int rc = 0;
	for (size_t c = 0; c < P->ncols && rc == 0; c++) {
		if (cols[c].role != COL_VAL && cols[c].role != COL_SIG)
			continue;
		double *hit = bsearch(&cols[c].nm, wls, nwl, sizeof *wls, cmp_double);
		if (!hit) {
			rc = acq_errf(err, ACQ_E_INVAL, "%s:%ld: column %zu: sigma_%g has no wavelength column %g", name,
				      P->header_line, c + 1, cols[c].nm, cols[c].nm);
			break;
		}
		cols[c].wl = (size_t)(hit - wls);
		if (cols[c].role == COL_SIG) {
			if (sig_seen[cols[c].wl]) {
				rc = acq_errf(err, ACQ_E_INVAL, "%s:%ld: column %zu: duplicate sigma_%g", name,
					      P->header_line, c + 1, cols[c].nm);
				break;
			}
			sig_seen[cols[c].wl] = 1;
			P->sig_seen_any = 1;
		}
	}
	free(sig_seen);
	return rc;
}

/* One angle field's value v (pr: parse_num's result) of column c checked and stored in row r. 0 or -1. */
static int row_angle(struct parser *P, size_t c, int pr, double v, struct recon_samples *s, size_t r,
		     struct acq_err *err)
{
	const char *name = P->name;
	int role = P->cols[c].role;
	if (pr == 1)
		return acq_errf(err, ACQ_E_INVAL, "%s:%ld: column %zu: angle %s is missing", name, P->L.lineno, c + 1,
				angle_names[role]);
	int is_theta = role == COL_TI || role == COL_TO;
	if (is_theta && (v < 0 || v > 90))
		return acq_errf(err, ACQ_E_RANGE, "%s:%ld: column %zu: zenith %s = %g outside [0, 90] degrees", name,
				P->L.lineno, c + 1, angle_names[role], v);
	if (!is_theta && fabs(v) > 1e6)
		return acq_errf(err, ACQ_E_RANGE, "%s:%ld: column %zu: azimuth %g is absurd", name, P->L.lineno, c + 1,
				v);
	s->deg[r * 4 + role] = v;
	s->ang[r * 4 + role] = v * (M_PI / 180.0);
	return 0;
}

/* The data row p, n appended to s (grown as needed; *cap its capacity). 0, or -1 with err. */
static int parse_row(struct parser *P, const char *p, size_t n, struct recon_samples *s, size_t *cap,
		     struct acq_err *err)
{
	const char *name = P->name;
	size_t nwl = P->nwl, ncols = P->ncols;
	struct field *fs = P->fs;
	struct col *cols = P->cols;
	long k = split(p, n, fs, P->maxf);
	if (k != (long)ncols)
		return acq_errf(err, ACQ_E_INVAL, "%s:%ld: expected %zu fields, found %s%ld", name, P->L.lineno, ncols,
				k < 0 ? "more than " : "", k < 0 ? (long)P->maxf : k);
	if (s->n == *cap) {
		size_t nc = *cap ? 2 * *cap : 64;
		if (csvio_samples_grow(s, nc, P->want_values, P->want_values && P->sig_seen_any))
			return acq_errf(err, ACQ_E_NOMEM, "%s:%ld: out of memory", name, P->L.lineno);
		*cap = nc;
	}
	size_t r = s->n;
	for (size_t w = 0; P->want_values && w < nwl; w++) {
		s->val[r * nwl + w] = NAN;
		if (s->sig)
			s->sig[r * nwl + w] = NAN;
	}
	for (size_t c = 0; c < ncols; c++) {
		if (cols[c].role == COL_IGNORE)
			continue;
		double v;
		int pr = parse_num(&fs[c], &v);
		if (pr < 0) {
			show(&fs[c], P->shown, sizeof P->shown);
			return acq_errf(err, ACQ_E_INVAL, "%s:%ld: column %zu: '%s' is not a finite number", name,
					P->L.lineno, c + 1, P->shown);
		}
		if (cols[c].role <= COL_PO) {
			if (row_angle(P, c, pr, v, s, r, err) != 0)
				return -1;
		} else if (cols[c].role == COL_VAL) {
			s->val[r * nwl + cols[c].wl] = v;
		} else {
			if (pr == 0 && v < 0)
				return acq_errf(err, ACQ_E_RANGE, "%s:%ld: column %zu: negative uncertainty %g", name,
						P->L.lineno, c + 1, v);
			s->sig[r * nwl + cols[c].wl] = v;
		}
	}
	s->n++;
	return 0;
}

/* Shared parser: want_values = 0 reads only the angle columns (queries). */
static int parse(const char *name, const char *text, size_t len, int want_values, struct recon_samples *s,
		 struct acq_err *err)
{
	memset(s, 0, sizeof *s);
	if (!text)
		return acq_errf(err, ACQ_E_INVAL, "%s: no text", name);
	struct parser P = { .name = name, .want_values = want_values, .L = { text, len, 0, 0 } };
	size_t cap = 0;
	int rc = -1;
	const char *p;
	size_t n;

	if (len >= 3 && !memcmp(text, "\xEF\xBB\xBF", 3))
		P.L.pos = 3;
	if (find_header(&P, &p, &n, err) != 0 || header_columns(&P, p, n, err) != 0 ||
	    header_wavelengths(&P, err) != 0)
		goto out;

	/* rows */
	s->nwl = P.nwl;
	s->wl = malloc((P.nwl ? P.nwl : 1) * sizeof *s->wl);
	if (!s->wl) {
		acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", name);
		goto out;
	}
	memcpy(s->wl, P.wls, P.nwl * sizeof *P.wls);
	while (next_line(&P.L, &p, &n)) {
		if (blank(p, n) || (n && p[0] == '#'))
			continue;
		if (parse_row(&P, p, n, s, &cap, err) != 0)
			goto out;
	}
	if (s->n == 0) {
		acq_errf(err, ACQ_E_INVAL, "%s: no data rows after the header (line %ld)", name, P.header_line);
		goto out;
	}
	rc = 0;
out:
	free(P.fs);
	free(P.cols);
	free(P.wls);
	if (rc)
		csvio_samples_free(s);
	return rc;
}

int csvio_parse_samples(const char *name, const char *text, size_t len, struct recon_samples *s,
			struct acq_err *err)
{
	return parse(name, text, len, 1, s, err);
}

int csvio_parse_queries(const char *name, const char *text, size_t len, struct recon_samples *s,
			struct acq_err *err)
{
	return parse(name, text, len, 0, s, err);
}

int csvio_slurp(const char *path, char **out, size_t *len, struct acq_err *err)
{
	return acq_file_read(path, (size_t)1 << 30, 0, out, len, err);
}

/* A samples (want_values) or queries file read whole and parsed: 0, or -1 with err and *s zeroed. */
static int read_file(const char *path, int want_values, struct recon_samples *s, struct acq_err *err)
{
	char *text;
	size_t len;
	memset(s, 0, sizeof *s);
	if (csvio_slurp(path, &text, &len, err))
		return -1;
	int rc = parse(path, text, len, want_values, s, err);
	free(text);
	return rc;
}

int csvio_read_samples(const char *path, struct recon_samples *s, struct acq_err *err)
{
	return read_file(path, 1, s, err);
}

int csvio_read_queries(const char *path, struct recon_samples *s, struct acq_err *err)
{
	return read_file(path, 0, s, err);
}

int csvio_fmt(char *buf, size_t size, double v)
{
	if (!isfinite(v))
		return -1;
	snprintf(buf, size, "%.10g", v);
	return 0;
}

int csvio_read_columns(const char *path, const char *const *names, size_t k, size_t *rows, double **data,
		       struct acq_err *err)
{
	return csvio_read_columns_ex(path, names, k, 0, rows, data, err);
}

int csvio_read_columns_ex(const char *path, const char *const *names, size_t k, unsigned flags, size_t *rows,
			  double **data, struct acq_err *err)
{
	char *text;
	size_t len;
	*rows = 0;
	*data = NULL;
	if (k == 0 || k > 16)
		return acq_errf(err, ACQ_E_INVAL, "%s: bad column request", path);
	if (csvio_slurp(path, &text, &len, err))
		return -1;
	struct lines L = { text, len, 0, 0 };
	const char *p;
	size_t n, cap = 0, nr = 0;
	long pos[16];
	struct field fs[64];
	double *d = NULL;
	int rc = -1;
	for (;;) {
		if (!next_line(&L, &p, &n)) {
			acq_errf(err, ACQ_E_INVAL, "%s: no header line", path);
			goto out;
		}
		if ((n && p[0] == '#') || blank(p, n))
			continue;
		break;
	}
	long nf = split(p, n, fs, 64);
	if (nf < 0) {
		acq_errf(err, ACQ_E_INVAL, "%s:%ld: too many columns", path, L.lineno);
		goto out;
	}
	for (size_t c = 0; c < k; c++) {
		pos[c] = -1;
		for (long f = 0; f < nf; f++)
			if (field_is(&fs[f], names[c]))
				pos[c] = f;
		if (pos[c] < 0) {
			acq_errf(err, ACQ_E_INVAL, "%s:%ld: missing column %s", path, L.lineno, names[c]);
			goto out;
		}
	}
	while (next_line(&L, &p, &n)) {
		if ((n && p[0] == '#') || blank(p, n))
			continue;
		long got = split(p, n, fs, 64);
		if (got != nf) {
			acq_errf(err, ACQ_E_INVAL, "%s:%ld: expected %ld fields, found %ld", path, L.lineno, nf, got);
			goto out;
		}
		if (nr == cap) {
			cap = cap ? 2 * cap : 64;
			double *nd = realloc(d, cap * k * sizeof *nd);
			if (!nd) {
				acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", path);
				goto out;
			}
			d = nd;
		}
		for (size_t c = 0; c < k; c++) {
			double v;
			if (parse_num(&fs[pos[c]], &v) != 0) {
				char shown[48];
				show(&fs[pos[c]], shown, sizeof shown);
				acq_errf(err, ACQ_E_INVAL, "%s:%ld: column %ld: '%s' is not a finite number", path, L.lineno,
					 pos[c] + 1, shown);
				goto out;
			}
			d[nr * k + c] = v;
		}
		nr++;
	}
	if (nr == 0 && !(flags & CSVIO_EMPTY_OK)) {
		acq_errf(err, ACQ_E_INVAL, "%s: no data rows", path);
		goto out;
	}
	*rows = nr;
	*data = d;
	d = NULL;
	rc = 0;
out:
	free(d);
	free(text);
	return rc;
}

int csvio_read_columns_cm(const char *path, const char *const *names, size_t k, size_t *rows, double **data,
			  struct acq_err *err)
{
	double *rm = NULL;
	*data = NULL;
	if (csvio_read_columns(path, names, k, rows, &rm, err))
		return -1;
	size_t n = *rows;
	double *cm = malloc(n * k * sizeof *cm);
	if (!cm) {
		free(rm);
		*rows = 0;
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", path);
	}
	for (size_t i = 0; i < n; i++) /* rows → columns */
		for (size_t c = 0; c < k; c++)
			cm[c * n + i] = rm[i * k + c];
	free(rm);
	*data = cm;
	return 0;
}
