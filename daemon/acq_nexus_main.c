/* acq-nexus: export one sweep of the acquisitiond database as a NeXus/HDF5 file (daemon/nexus.md), read-only. */
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "acq_version.h"
#include "daemon/nexus.h"

static const char help[] =
	"usage: acq-nexus DATABASE SWEEP_ID -o OUT.nxs\n"
	"Export one sweep of the acquisitiond database (opened read-only; safe while the daemon runs) as a\n"
	"NeXus/HDF5 file: raw counts, darks, references, calibrated BRDF and sigma, planned and actual angles,\n"
	"wavelengths, integration times, timestamps, the configuration and plan snapshots and the events, with\n"
	"NeXus classes and units (layout: daemon/nexus.md). Readable by h5dump and h5py.\n";

int main(int argc, char **argv)
{
	const char *db = NULL, *sweep = NULL, *out = NULL;
	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
			fputs(help, stdout);
			return 0;
		} else if (!strcmp(argv[i], "--version")) {
			printf("acq-nexus %s\n", ACQ_VERSION);
			return 0;
		} else if (!strcmp(argv[i], "-o") && i + 1 < argc) {
			out = argv[++i];
		} else if (!db) {
			db = argv[i];
		} else if (!sweep) {
			sweep = argv[i];
		} else {
			fprintf(stderr, "acq-nexus: unexpected argument '%s'\n%s", argv[i], help);
			return 2;
		}
	}
	char *end;
	errno = 0;
	long long id = sweep ? strtoll(sweep, &end, 10) : 0;
	if (!db || !sweep || !out || errno || *end || id <= 0) {
		fprintf(stderr, "acq-nexus: DATABASE, a positive SWEEP_ID and -o OUT.nxs are required\n%s", help);
		return 2;
	}
	struct acq_err err = { 0 };
	struct nexus_stats st;
	if (nexus_export(db, id, out, &st, &err)) {
		fprintf(stderr, "acq-nexus: %s\n", err.msg);
		return 1;
	}
	fprintf(stderr, "acq-nexus: sweep %lld: %lld points, %lld calibrated (%d wavelengths), spectra %lld sample / %lld "
		"dark / %lld reference / %lld beam (%d pixels), %lld events, %lld devices -> %s\n", id, (long long)st.points,
		(long long)st.calibrated, st.nwl, (long long)st.spectra[0], (long long)st.spectra[1],
		(long long)st.spectra[2], (long long)st.spectra[3], st.npix, (long long)st.events, (long long)st.devices,
		out);
	return 0;
}
