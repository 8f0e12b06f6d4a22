/* Unit tests of config/acq_out: an absent or regular target is replaced only at commit (a failure or an abort
 * leaves the old file and no temporary file), a FIFO and /dev/null are written in place and stay what they are,
 * a directory is refused, a symbolic link keeps pointing at the file it names. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include "config/acq_out.h"

static char dir[512];

static void path_in(char *buf, size_t n, const char *name)
{
	snprintf(buf, n, "%s/%s", dir, name);
}

static void put_file(const char *path, const char *text, mode_t mode)
{
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs(text, f);
	assert_int_equal(fclose(f), 0);
	assert_int_equal(chmod(path, mode), 0);
}

static void assert_content(const char *path, const char *text)
{
	char buf[4096] = "";
	FILE *f = fopen(path, "r");
	assert_non_null(f);
	size_t n = fread(buf, 1, sizeof buf - 1, f);
	buf[n] = 0;
	fclose(f);
	assert_string_equal(buf, text);
}

/* Entries of the test folder other than the names given (a temporary file left behind shows here). */
static int other_entries(const char *a, const char *b)
{
	DIR *d = opendir(dir);
	assert_non_null(d);
	int n = 0;
	struct dirent *e;
	while ((e = readdir(d)))
		if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..") && (!a || strcmp(e->d_name, a)) &&
		    (!b || strcmp(e->d_name, b))) {
			printf("  unexpected entry %s\n", e->d_name);
			n++;
		}
	closedir(d);
	return n;
}

static void test_absent_target(void **state)
{
	(void)state;
	char p[600];
	path_in(p, sizeof p, "new.txt");
	struct acq_out o;
	struct acq_err err = { 0 };
	assert_int_equal(acq_out_open(&o, p, ACQ_OUT_STDIO, &err), 0);
	assert_non_null(o.tmp);
	fputs("hello\n", o.f);
	assert_int_equal(access(p, F_OK), -1); /* nothing at the target before the commit */
	assert_int_equal(acq_out_commit(&o, &err), 0);
	assert_content(p, "hello\n");
	struct stat st;
	assert_int_equal(stat(p, &st), 0);
	assert_int_equal(st.st_mode & 0777, 0644);
	assert_int_equal(other_entries("new.txt", NULL), 0);
	unlink(p);
}

static void test_regular_target(void **state)
{
	(void)state;
	char p[600];
	path_in(p, sizeof p, "old.txt");
	put_file(p, "old\n", 0640);
	struct acq_out o;
	struct acq_err err = { 0 };
	/* abort: the old file stays, no temporary file */
	assert_int_equal(acq_out_open(&o, p, 0, &err), 0);
	assert_int_equal(write(o.fd, "partial", 7), 7);
	acq_out_abort(&o);
	acq_out_abort(&o); /* idempotent */
	assert_content(p, "old\n");
	assert_int_equal(other_entries("old.txt", NULL), 0);
	/* commit: replaced, permissions kept */
	assert_int_equal(acq_out_open(&o, p, 0, &err), 0);
	assert_int_equal(write(o.fd, "new\n", 4), 4);
	assert_content(p, "old\n");
	assert_int_equal(acq_out_commit(&o, &err), 0);
	assert_content(p, "new\n");
	struct stat st;
	assert_int_equal(stat(p, &st), 0);
	assert_true(S_ISREG(st.st_mode));
	assert_int_equal(st.st_mode & 0777, 0640);
	assert_int_equal(other_entries("old.txt", NULL), 0);
	unlink(p);
}

/* A write that fails (the file-size limit: EFBIG) fails the commit; the old file and nothing else remains. */
static void test_failed_write_keeps_old(void **state)
{
	(void)state;
	char p[600];
	path_in(p, sizeof p, "keep.txt");
	put_file(p, "precious\n", 0644);
	struct rlimit old, lim;
	assert_int_equal(getrlimit(RLIMIT_FSIZE, &old), 0);
	void (*prev)(int) = signal(SIGXFSZ, SIG_IGN);
	lim = old;
	lim.rlim_cur = 1000;
	assert_int_equal(setrlimit(RLIMIT_FSIZE, &lim), 0);
	struct acq_out o;
	struct acq_err err = { 0 };
	assert_int_equal(acq_out_open(&o, p, ACQ_OUT_STDIO, &err), 0);
	for (int i = 0; i < 1000; i++)
		fputs("0123456789", o.f);
	int rc = acq_out_commit(&o, &err);
	assert_int_equal(setrlimit(RLIMIT_FSIZE, &old), 0);
	signal(SIGXFSZ, prev);
	assert_int_equal(rc, -1);
	assert_int_equal(err.code, ACQ_E_IO);
	printf("  %s\n", err.msg);
	assert_non_null(strstr(err.msg, "keep.txt"));
	assert_content(p, "precious\n");
	assert_int_equal(other_entries("keep.txt", NULL), 0);
	unlink(p);
}

struct reader {
	char path[600];
	char buf[256];
	size_t n;
};

static void *fifo_reader(void *arg)
{
	struct reader *r = arg;
	int fd = open(r->path, O_RDONLY);
	if (fd < 0)
		return NULL;
	ssize_t k;
	while ((k = read(fd, r->buf + r->n, sizeof r->buf - 1 - r->n)) > 0)
		r->n += (size_t)k;
	close(fd);
	return NULL;
}

static void test_fifo_in_place(void **state)
{
	(void)state;
	struct reader r = { .n = 0 };
	path_in(r.path, sizeof r.path, "pipe");
	assert_int_equal(mkfifo(r.path, 0600), 0);
	pthread_t th;
	assert_int_equal(pthread_create(&th, NULL, fifo_reader, &r), 0);
	struct acq_out o;
	struct acq_err err = { 0 };
	assert_int_equal(acq_out_open(&o, r.path, ACQ_OUT_STDIO, &err), 0);
	assert_null(o.tmp);
	assert_string_equal(o.name, r.path);
	fputs("through the pipe\n", o.f);
	assert_int_equal(acq_out_commit(&o, &err), 0);
	assert_int_equal(pthread_join(th, NULL), 0);
	r.buf[r.n] = 0;
	assert_string_equal(r.buf, "through the pipe\n");
	struct stat st;
	assert_int_equal(lstat(r.path, &st), 0);
	assert_true(S_ISFIFO(st.st_mode));
	assert_int_equal(other_entries("pipe", NULL), 0);
	/* a writer that needs a regular file is refused before anything is opened */
	memset(&err, 0, sizeof err);
	assert_int_equal(acq_out_open(&o, r.path, ACQ_OUT_SEEK, &err), -1);
	assert_int_equal(err.code, ACQ_E_IO);
	assert_non_null(strstr(err.msg, "not a regular file"));
	unlink(r.path);
}

static void test_dev_null_in_place(void **state)
{
	(void)state;
	struct acq_out o;
	struct acq_err err = { 0 };
	assert_int_equal(acq_out_open(&o, "/dev/null", 0, &err), 0);
	assert_null(o.tmp);
	assert_int_equal(write(o.fd, "x", 1), 1);
	assert_int_equal(acq_out_commit(&o, &err), 0);
	struct stat st;
	assert_int_equal(stat("/dev/null", &st), 0);
	assert_true(S_ISCHR(st.st_mode));
}

static void test_directory_refused(void **state)
{
	(void)state;
	struct acq_out o;
	struct acq_err err = { 0 };
	assert_int_equal(acq_out_open(&o, dir, ACQ_OUT_STDIO, &err), -1);
	assert_int_equal(err.code, ACQ_E_IO);
	assert_non_null(strstr(err.msg, "is a directory"));
	assert_int_equal(o.fd, -1);
	acq_out_abort(&o); /* harmless after a failed open */
	assert_int_equal(other_entries(NULL, NULL), 0);
	char p[600];
	path_in(p, sizeof p, "no-such-folder/x.txt");
	memset(&err, 0, sizeof err);
	assert_int_equal(acq_out_open(&o, p, 0, &err), -1);
	assert_non_null(strstr(err.msg, "no-such-folder"));
	memset(&err, 0, sizeof err);
	assert_int_equal(acq_out_open(&o, "", 0, &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
}

static void test_symlink_kept(void **state)
{
	(void)state;
	char p[600], l[600];
	path_in(p, sizeof p, "real.txt");
	path_in(l, sizeof l, "link.txt");
	put_file(p, "before\n", 0644);
	assert_int_equal(symlink("real.txt", l), 0);
	struct acq_out o;
	struct acq_err err = { 0 };
	assert_int_equal(acq_out_open(&o, l, ACQ_OUT_STDIO, &err), 0);
	fputs("after\n", o.f);
	assert_int_equal(acq_out_commit(&o, &err), 0);
	struct stat st;
	assert_int_equal(lstat(l, &st), 0);
	assert_true(S_ISLNK(st.st_mode));
	assert_content(p, "after\n");
	assert_int_equal(other_entries("real.txt", "link.txt"), 0);
	unlink(l);
	unlink(p);
}

static int group_setup(void **state)
{
	(void)state;
	const char *t = getenv("TMPDIR");
	snprintf(dir, sizeof dir, "%s/acq_out_XXXXXX", t && *t ? t : "/tmp");
	return mkdtemp(dir) ? 0 : -1;
}

static int group_teardown(void **state)
{
	(void)state;
	return rmdir(dir);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_absent_target),     cmocka_unit_test(test_regular_target),
		cmocka_unit_test(test_failed_write_keeps_old), cmocka_unit_test(test_fifo_in_place),
		cmocka_unit_test(test_dev_null_in_place), cmocka_unit_test(test_directory_refused),
		cmocka_unit_test(test_symlink_kept),
	};
	return cmocka_run_group_tests(tests, group_setup, group_teardown);
}
