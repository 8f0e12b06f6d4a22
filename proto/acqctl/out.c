/* out: acqctl's outputs — one JSON document, the client's own errors, an export stream or inline export copied to
 * a file or stdout, a spectrum as CSV (see acqctl.h). */
#include <errno.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "proto/acqctl/acqctl.h"
#include "proto/ctl.h"

void out_json(json_t *o)
{
	char *s = json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(10));
	puts(s ? s : "{\"ok\":false}");
	free(s);
	fflush(stdout);
}

/* An error of the client itself (no daemon, bad input): stderr, and the JSON document with --json. */
int out_fail(int rc, const char *code, const char *fmt, ...)
{
	char msg[1024];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	fprintf(stderr, "acqctl: %s\n", msg);
	if (acqctl_o.json) {
		json_t *o = json_pack("{s:b,s:{s:s,s:s}}", "ok", 0, "error", "code", code, "message", msg);
		out_json(o);
		json_decref(o);
	}
	return rc;
}

/* -o FILE of an export, opened before the request (out_prepare) and kept until the stream comes. */
static int prep_fd = -1;
static bool prep_created; /* out_prepare made the file: removed again if the export never starts */

int out_prepare(void)
{
	if (!acqctl_o.out)
		return 0;
	struct stat st;
	bool existed = stat(acqctl_o.out, &st) == 0;
	/* no O_TRUNC yet: a refused export leaves an existing file as it was */
	prep_fd = open(acqctl_o.out, O_WRONLY | O_CREAT | O_CLOEXEC, 0666);
	if (prep_fd < 0)
		return out_fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", acqctl_o.out, strerror(errno));
	prep_created = !existed;
	return 0;
}

void out_abandon(void)
{
	if (prep_fd < 0)
		return;
	close(prep_fd);
	prep_fd = -1;
	if (prep_created)
		unlink(acqctl_o.out);
}

/* The output: stdout (1), the prepared -o file emptied, else -o opened now; -1 with errno. */
static int out_open(const char *path)
{
	if (!path)
		return 1;
	if (prep_fd >= 0) {
		int fd = prep_fd;
		prep_fd = -1;
		if (ftruncate(fd, 0) && errno != EINVAL) { /* EINVAL: not a regular file (a FIFO, /dev/null) */
			int e = errno;
			close(fd);
			errno = e;
			return -1;
		}
		return fd;
	}
	return open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
}

/* Copy the export stream to the output; the stream must carry the reply's rows (header and comment lines
 * aside), else the daemon stopped early. */
int out_export(json_t *rep, int src)
{
	int out = out_open(acqctl_o.out);
	if (out < 0)
		return out_fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", acqctl_o.out, strerror(errno));
	char buf[65536];
	long long bytes = 0, lines = 0;
	ssize_t n;
	int rc = 0;
	while ((n = read(src, buf, sizeof buf)) != 0) {
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0) {
			rc = out_fail(CTL_EXIT_PROTOCOL, "io", "export stream: %s", strerror(errno));
			break;
		}
		for (ssize_t i = 0; i < n; i++)
			lines += buf[i] == '\n';
		bytes += n;
		struct acq_err err = { 0 };
		if (proto_write_all(out, buf, (size_t)n, &err)) {
			rc = out_fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", acqctl_o.out ? acqctl_o.out : "stdout", err.msg);
			break;
		}
	}
	long long rows = json_integer_value(json_object_get(rep, "rows"));
	long long head = json_integer_value(json_object_get(rep, "header_lines"));
	bool nexus = json_is_string(json_object_get(rep, "format"));
	long long want = json_integer_value(json_object_get(rep, "bytes"));
	if (!rc && nexus && bytes != want)
		rc = out_fail(CTL_EXIT_PROTOCOL, "io", "NeXus export of sweep %lld: %lld of %lld bytes received",
			  (long long)json_integer_value(json_object_get(rep, "sweep")), bytes, want);
	else if (!rc && !nexus && lines != rows + head)
		rc = out_fail(CTL_EXIT_PROTOCOL, "io", "export of sweep %lld ended after %lld of %lld rows (see the daemon's log)",
			  (long long)json_integer_value(json_object_get(rep, "sweep")), lines - head, rows);
	if (acqctl_o.out && close(out) && !rc)
		rc = out_fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", acqctl_o.out, strerror(errno));
	if (!rc) {
		json_object_set_new(rep, "bytes", json_integer(bytes));
		json_object_set_new(rep, "output", acqctl_o.out ? json_string(acqctl_o.out) : json_null());
		if (acqctl_o.json)
			out_json(rep);
		else if (acqctl_o.out && nexus)
			fprintf(stdout, "sweep %lld: NeXus, %lld points, %lld calibrated, %lld bytes written to %s\n",
				(long long)json_integer_value(json_object_get(rep, "sweep")),
				(long long)json_integer_value(json_object_get(rep, "points")),
				(long long)json_integer_value(json_object_get(rep, "calibrated")), bytes, acqctl_o.out);
		else if (acqctl_o.out)
			fprintf(stdout, "sweep %lld: %lld rows, %lld bytes written to %s\n",
				(long long)json_integer_value(json_object_get(rep, "sweep")), rows, bytes, acqctl_o.out);
	}
	return rc;
}

/* A small export sent inline (over TCP, where no descriptor can be passed). */
int out_inline(json_t *rep)
{
	const char *csv = json_string_value(json_object_get(rep, "csv"));
	int out = out_open(acqctl_o.out);
	struct acq_err err = { 0 };
	if (out < 0 || proto_write_all(out, csv, strlen(csv), &err) || (acqctl_o.out && close(out)))
		return out_fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", acqctl_o.out ? acqctl_o.out : "stdout", out < 0 ? strerror(errno) : err.msg);
	json_int_t len = (json_int_t)strlen(csv);
	json_object_del(rep, "csv");
	json_object_set_new(rep, "bytes", json_integer(len));
	json_object_set_new(rep, "output", acqctl_o.out ? json_string(acqctl_o.out) : json_null());
	if (acqctl_o.json)
		out_json(rep);
	return 0;
}

int out_spectrum_csv(json_t *rep)
{
	json_t *s = json_object_get(rep, "spectrum");
	json_t *wl = json_object_get(s, "wavelength_nm"), *ct = json_object_get(s, "counts");
	json_t *sd = json_object_get(s, "stddev");
	if (!json_is_array(wl) || !json_is_array(ct) || json_array_size(wl) != json_array_size(ct))
		return out_fail(CTL_EXIT_PROTOCOL, "protocol", "spectrum reply without matching wavelength_nm and counts");
	FILE *f = acqctl_o.out ? fopen(acqctl_o.out, "w") : stdout;
	if (!f)
		return out_fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", acqctl_o.out, strerror(errno));
	fprintf(f, "# acquisitiond spectrum %lld (%s)\nwavelength_nm,counts%s\n",
		(long long)json_integer_value(json_object_get(s, "id")), json_string_value(json_object_get(s, "kind")),
		json_is_array(sd) ? ",stddev" : "");
	for (size_t i = 0; i < json_array_size(wl); i++) {
		fprintf(f, "%.6g,%.9g", json_number_value(json_array_get(wl, i)), json_number_value(json_array_get(ct, i)));
		if (json_is_array(sd))
			fprintf(f, ",%.6g", json_number_value(json_array_get(sd, i)));
		fputc('\n', f);
	}
	if ((acqctl_o.out ? fclose(f) : fflush(f)) != 0)
		return out_fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", acqctl_o.out ? acqctl_o.out : "stdout", strerror(errno));
	if (acqctl_o.out)
		printf("spectrum %lld: %zu rows written to %s\n", (long long)json_integer_value(json_object_get(s, "id")),
		       json_array_size(wl), acqctl_o.out);
	return 0;
}
