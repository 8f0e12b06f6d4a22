/* crashpoint: crash injection for the kill tests. ACQ_CRASH_AT=STEP:N SIGKILLs the daemon when the N-th named
 * step STEP of this process is reached (the sweep's events, "point", "recon" from app.c; "reference_stored" from
 * the executor: the reference's spectra committed, its marker not yet). Unset in production: no effect. */
#ifndef CRASHPOINT_H
#define CRASHPOINT_H

/* Step named step reached (NULL: none): SIGKILL now if it is the one ACQ_CRASH_AT names, the N-th time. */
void crash_point(const char *step);

#endif
