/* crashpoint: crash injection for the kill tests. ACQ_CRASH_AT=STEP:N SIGKILLs the daemon when the N-th named
 * step STEP of this process is reached (the sweep's events, "point", "recon" from app.c; "reference_stored" from
 * the executor: the reference's spectra committed, its marker not yet), and a slow disk (ACQ_SLOW_SYNC_MS). Unset
 * in production: no effect. */
#ifndef CRASHPOINT_H
#define CRASHPOINT_H

struct store;

/* Step named step reached (NULL: none): SIGKILL now if it is the one ACQ_CRASH_AT names, the N-th time. */
void crash_point(const char *step);
/* ACQ_SLOW_SYNC_MS=N (1..60000): the store's fsync thread waits N ms before each fsync (a slow disk; the loop must
 * keep serving meanwhile). Unset: no effect. */
void crash_slow_sync(struct store *st);

#endif
