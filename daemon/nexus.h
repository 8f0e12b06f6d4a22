/* nexus: one sweep of the database exported as a NeXus/HDF5 file (layout in daemon/nexus.md). */
#ifndef DAEMON_NEXUS_H
#define DAEMON_NEXUS_H

#include <stdint.h>

#include "config/acq_err.h"

/* What went into the file. */
struct nexus_stats {
	int64_t points, calibrated, events, devices;
	int64_t spectra[4]; /* sample, dark, reference, beam */
	int npix, nwl;
};

/* Export sweep `sweep` of the database db_path (opened read-only) to out_path (written to a temporary file
 * beside it, then renamed). 0, or -1 with err (nothing left at out_path). */
int nexus_export(const char *db_path, int64_t sweep, const char *out_path, struct nexus_stats *st,
		 struct acq_err *err);

#endif
