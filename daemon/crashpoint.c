/* crashpoint: ACQ_CRASH_AT's step counter (crashpoint.h). */
#include "daemon/crashpoint.h"

#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "daemon/log.h"
#include "daemon/store.h"

void crash_point(const char *step)
{
	static bool init;
	static char want_step[32];
	static int want, seen;
	if (!init) {
		init = true;
		const char *e = getenv("ACQ_CRASH_AT");
		if (!e || sscanf(e, "%31[a-z_]:%d", want_step, &want) != 2)
			want_step[0] = 0;
	}
	if (!want_step[0] || !step || strcmp(step, want_step) || ++seen != want)
		return;
	log_msg(LOG_WARNING, "ACQ_CRASH_AT=%s:%d: SIGKILL now", want_step, want);
	raise(SIGKILL);
}

static int slow_sync(void *ctx, char *why, size_t n)
{
	(void)why;
	(void)n;
	long ms = *(const long *)ctx;
	struct timespec ts = { ms / 1000, (ms % 1000) * 1000000L };
	while (nanosleep(&ts, &ts) && ts.tv_nsec + ts.tv_sec > 0) {
	}
	return 0;
}

void crash_slow_sync(struct store *st)
{
	static long ms;
	const char *e = getenv("ACQ_SLOW_SYNC_MS");
	if (!e || sscanf(e, "%ld", &ms) != 1 || ms <= 0 || ms > 60000)
		return;
	log_msg(LOG_WARNING, "ACQ_SLOW_SYNC_MS=%ld: every fsync of the database's commits waits %ld ms first", ms, ms);
	store_sync_set_hook(st, slow_sync, &ms);
}
