/* tmpdir: a unit test's scratch folder under /tmp, made by mkdtemp and removed with all it holds. */
#ifndef TESTS_TMPDIR_H
#define TESTS_TMPDIR_H

#include <ftw.h>
#include <stdio.h>
#include <stdlib.h>

/* Make /tmp/NAME.XXXXXX into dir (len bytes); 0, or -1 with errno. */
static inline int ut_tmpdir_make(char *dir, size_t len, const char *name)
{
	snprintf(dir, len, "/tmp/%s.XXXXXX", name);
	return mkdtemp(dir) ? 0 : -1;
}

static inline int ut_tmpdir_rm1(const char *path, const struct stat *sb, int type, struct FTW *ftw)
{
	(void)sb;
	(void)type;
	(void)ftw;
	return remove(path);
}

/* Remove dir and everything in it (symbolic links are removed, not followed); 0, or -1. */
static inline int ut_tmpdir_remove(const char *dir)
{
	return nftw(dir, ut_tmpdir_rm1, 16, FTW_DEPTH | FTW_PHYS);
}

#ifdef UT_TMPDIR_NAME
/* For a test that defines UT_TMPDIR_NAME before including this file: cmocka group set-up and tear-down of the
 * scratch folder ut_dir (/tmp/UT_TMPDIR_NAME.XXXXXX), made before the first test and removed after the last. */
static char ut_dir[256];

static int ut_dir_setup(void **state)
{
	(void)state;
	return ut_tmpdir_make(ut_dir, sizeof ut_dir, UT_TMPDIR_NAME);
}

static int ut_dir_teardown(void **state)
{
	(void)state;
	return ut_tmpdir_remove(ut_dir);
}
#endif

#endif
