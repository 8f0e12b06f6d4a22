/* log: the daemon's only log sink — stderr with levels in the foreground, the journal under systemd. */
#ifndef LOG_H
#define LOG_H

#include <stdbool.h>
#include <syslog.h>

/* Start logging: level is a syslog priority (LOG_ERR..LOG_DEBUG); journal true sends to sd_journal. */
void log_init(int level, bool journal);
/* Change the threshold (after a configuration reload). */
void log_set_level(int level);
/* Whether a message at priority level would be logged (to skip gathering what only such a message reports). */
bool log_enabled(int level);
/* Log one message at priority level (dropped when above the threshold). */
void log_msg(int level, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Stop logging (flush). */
void log_finish(void);

#endif
