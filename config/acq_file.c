/* acq_file: a whole file read into memory (config/acq_file.h). */
#include "config/acq_file.h"

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The limit for a message: "16 MiB", "64 KiB" or "1000 bytes". */
static void size_words(size_t n, char *buf, size_t len)
{
	if (n >= (1u << 20) && n % (1u << 20) == 0)
		snprintf(buf, len, "%zu MiB", n >> 20);
	else if (n >= 1024 && n % 1024 == 0)
		snprintf(buf, len, "%zu KiB", n >> 10);
	else
		snprintf(buf, len, "%zu bytes", n);
}

int acq_file_read(const char *path, size_t max, int flags, char **out, size_t *len, struct acq_err *err)
{
	*out = NULL;
	if (len)
		*len = 0;
	if (max > SIZE_MAX / 4)
		max = SIZE_MAX / 4;
	int std = (flags & ACQ_FILE_STDIN) && !strcmp(path, "-");
	const char *name = std ? "standard input" : path;
	FILE *f = std ? stdin : fopen(path, "rb");
	if (!f)
		return acq_errf(err, errno == ENOENT ? ACQ_E_NOTFOUND : ACQ_E_IO, "%s: cannot open: %s", name,
				strerror(errno));
	/* cap: bytes asked of fread so far, at most max + 1 (one byte past the limit tells a file that is larger) */
	size_t cap = max < (64u << 10) ? max + 1 : (64u << 10), n = 0;
	char *buf = malloc(cap + 1);
	int rc = 0;
	while (buf) {
		n += fread(buf + n, 1, cap - n, f);
		if (n < cap)
			break;
		if (n > max) {
			char lim[32];
			size_words(max, lim, sizeof lim);
			rc = acq_errf(err, ACQ_E_RANGE, "%s: larger than %s", name, lim);
			break;
		}
		cap = cap > max / 2 ? max + 1 : cap * 2;
		char *nb = realloc(buf, cap + 1);
		if (!nb)
			free(buf);
		buf = nb;
	}
	if (!buf)
		rc = acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", name);
	else if (!rc && ferror(f))
		rc = acq_errf(err, ACQ_E_IO, "%s: read error: %s", name, strerror(errno));
	if (!std)
		fclose(f);
	else
		clearerr(f);
	if (rc) {
		free(buf);
		return -1;
	}
	buf[n] = '\0';
	*out = buf;
	if (len)
		*len = n;
	return 0;
}
