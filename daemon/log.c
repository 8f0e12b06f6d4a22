/* log: stderr (foreground, "LEVEL: message") or the systemd journal (service), with a level threshold. */
#include "daemon/log.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <systemd/sd-journal.h>

static int log_threshold = LOG_INFO;
static bool log_journal;

static const char *const log_names[] = { "emerg", "alert", "crit", "error", "warning", "notice", "info", "debug" };

void log_init(int level, bool journal)
{
	log_threshold = level;
	log_journal = journal;
}

void log_set_level(int level)
{
	log_threshold = level;
}

bool log_enabled(int level)
{
	return level <= log_threshold;
}

void log_msg(int level, const char *fmt, ...)
{
	if (level > log_threshold)
		return;
	char buf[2048];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(buf, sizeof buf, fmt, ap);
	va_end(ap);
	if (log_journal) {
		sd_journal_print(level, "%s", buf);
		return;
	}
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	struct tm tm;
	gmtime_r(&ts.tv_sec, &tm);
	fprintf(stderr, "%02d:%02d:%02d.%03ld acquisitiond %s: %s\n", tm.tm_hour, tm.tm_min, tm.tm_sec,
		ts.tv_nsec / 1000000, log_names[level & 7], buf);
}

void log_finish(void)
{
	fflush(stderr);
}
