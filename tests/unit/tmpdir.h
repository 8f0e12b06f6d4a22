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

#endif
