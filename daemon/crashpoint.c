/* crashpoint: ACQ_CRASH_AT's step counter (crashpoint.h). */
#include "daemon/crashpoint.h"

#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/log.h"

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
