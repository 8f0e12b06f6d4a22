/* Benchmark of the device drivers' own overhead: laser command round trips against the simulated laser on a
 * pty (a forked child serves it), and AvaSpec start+fetch cycles of 2048-pixel spectra through the transport
 * seam (in-memory device: protocol, decoding and corrections only). Writes $ACQ_BENCH_OUT/devices.tsv. */
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "drivers/avaspec.h"
#include "drivers/avaspec_proto.h"
#include "drivers/laser.h"
#include "drivers/spectro_backend.h"
#include "sim/sim.h"

static double mono(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static int cmp_d(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

/* ---- laser ---- */
static int bench_laser(FILE *tsv)
{
	static struct sim_world w;
	struct acq_err err = { 0 };
	struct sim_service *svc = sim_laser_new(&w, NULL, NULL, &err);
	if (!svc) {
		fprintf(stderr, "sim_laser_new: %s\n", err.msg);
		return -1;
	}
	char desc[256], path[128];
	svc->describe(svc->self, desc, sizeof desc);
	if (sscanf(desc, "\"laser\": {\"device\": \"%127[^\"]\"}", path) != 1)
		return -1;
	pid_t pid = fork();
	if (pid == 0) {
		prctl(PR_SET_PDEATHSIG, SIGKILL);
		for (;;) {
			struct pollfd fds[2];
			int n = svc->pollfds(svc->self, fds, 2);
			if (poll(fds, (nfds_t)n, 5) > 0)
				svc->handle(svc->self, fds, n, 0);
			svc->tick(svc->self, 0);
		}
	}
	svc->destroy(svc->self);
	char text[256];
	snprintf(text, sizeof text, "device: %s\ntimeout_ms: 500\n", path);
	struct yc_doc *doc = NULL;
	struct laser_cfg *cfg = NULL;
	struct laser *l = NULL;
	int rc = -1;
	if (yc_load_string("b.yaml", text, strlen(text), &doc, &err) || laser_cfg_parse(yc_root(doc), &cfg, &err) ||
	    laser_open(cfg, &l, &err)) {
		fprintf(stderr, "laser: %s\n", err.msg);
		goto out;
	}
	enum { N = 2000 };
	static double lat[N];
	struct laser_status st;
	for (int i = 0; i < N; i++) {
		double t0 = mono();
		if (laser_status(l, &st, &err)) {
			fprintf(stderr, "laser_status: %s\n", err.msg);
			goto out;
		}
		lat[i] = (mono() - t0) * 1e6;
	}
	qsort(lat, N, sizeof lat[0], cmp_d);
	printf("laser_status (STATUS? + POWER?, sim on pty): %d calls, p50 %.0f us, p99 %.0f us, max %.0f us\n", N,
	       lat[N / 2], lat[N * 99 / 100], lat[N - 1]);
	fprintf(tsv, "laser_status_us\tp50\t%.1f\nlaser_status_us\tp99\t%.1f\nlaser_status_us\tmax\t%.1f\n", lat[N / 2],
		lat[N * 99 / 100], lat[N - 1]);
	rc = 0;
out:
	laser_close(l);
	laser_cfg_free(cfg);
	yc_free(doc);
	kill(pid, SIGKILL);
	waitpid(pid, NULL, 0);
	return rc;
}

/* ---- avaspec through the seam ---- */
#define NPIX 2048
struct mem {
	uint8_t *frames[8];
	size_t len[8];
	int k, nframes;
	int cycle; /* replays frames[first..] round robin after open */
	int first;
};

static int m_write(void *ctx, const uint8_t *b, size_t n, int t, struct acq_err *e)
{
	(void)ctx; (void)b; (void)n; (void)t; (void)e;
	return 0;
}

static int m_read(void *ctx, uint8_t *buf, size_t cap, int t, struct acq_err *e)
{
	(void)t; (void)e;
	struct mem *m = ctx;
	static size_t off;
	int i = m->k;
	size_t n = m->len[i] - off;
	if (n > cap)
		n = cap;
	memcpy(buf, m->frames[i] + off, n);
	off += n;
	if (off == m->len[i]) {
		off = 0;
		m->k = m->k + 1 < m->nframes ? m->k + 1 : m->first;
	}
	return (int)n;
}

static void m_close(void *ctx)
{
	(void)ctx;
}

static uint8_t *mk(struct mem *m, uint8_t cmd, const uint8_t *pl, size_t n)
{
	uint8_t *f = malloc(AVS_HDR + n);
	m->len[m->nframes] = (size_t)avs_frame(f, AVS_HDR + n, AVS_TYPE_DEV, 0, cmd, pl, n, NULL);
	m->frames[m->nframes++] = f;
	return f;
}

static int bench_avaspec(FILE *tsv)
{
	struct mem m = { 0 };
	mk(&m, 0x8F, NULL, 0);
	uint8_t id[AVS_IDENT_LEN] = { 'B' };
	mk(&m, 0x93, id, sizeof id);
	uint8_t *rec = calloc(1, AVS_DEVCFG_LEN);
	rec[AVS_CFG_OFF_NPIX] = NPIX >> 8;
	rec[AVS_CFG_OFF_NPIX + 1] = NPIX & 0xff;
	rec[AVS_CFG_OFF_NL_ENABLE] = 1;
	rec[AVS_CFG_OFF_NL_COEF] = 0x3f; /* 1.0 as big-endian double: 3F F0 00.. */
	rec[AVS_CFG_OFF_NL_COEF + 1] = 0xf0;
	mk(&m, 0x81, rec, AVS_DEVCFG_LEN);
	free(rec);
	m.first = m.nframes;
	mk(&m, 0x85, NULL, 0);
	mk(&m, 0x86, NULL, 0);
	static uint8_t pl[4 + 2 * NPIX];
	for (int i = 0; i < NPIX; i++)
		pl[4 + 2 * i] = (uint8_t)(i >> 4), pl[5 + 2 * i] = (uint8_t)i;
	mk(&m, 0xB0, pl, sizeof pl);
	struct avs_transport t = { .ctx = &m, .write = m_write, .read = m_read, .close = m_close };
	static const char yaml[] = "backend: avaspec-usb\ndark_pixels: [2, 3, 4, 5]\n";
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	void *cfg = NULL, *dev = NULL;
	struct spectro_info info;
	if (yc_load_string("b.yaml", yaml, sizeof yaml - 1, &doc, &err) ||
	    spectro_avaspec_backend.cfg_parse(yc_root(doc), &cfg, &err) ||
	    avs_open_transport(cfg, &t, &dev, &info, &err)) {
		fprintf(stderr, "avaspec: %s\n", err.msg);
		return -1;
	}
	static struct spectro_frame f;
	struct spectro_meas meas = { .integration_ms = 1, .averages = 1 };
	enum { N = 20000 };
	double t0 = mono();
	for (int i = 0; i < N; i++)
		if (spectro_avaspec_backend.start(dev, &meas, 0, &err) ||
		    spectro_avaspec_backend.fetch(dev, &f, 0, &err) != 1) {
			fprintf(stderr, "avaspec cycle %d: %s\n", i, err.msg);
			return -1;
		}
	double us = (mono() - t0) / N * 1e6;
	printf("avaspec start+fetch, %d pixels, dark + nonlinearity correction (seam): %.1f us per spectrum "
	       "(%d spectra)\n", NPIX, us, N);
	fprintf(tsv, "avaspec_cycle_us\t2048px\t%.2f\n", us);
	spectro_avaspec_backend.close(dev);
	spectro_avaspec_backend.cfg_free(cfg);
	yc_free(doc);
	for (int i = 0; i < m.nframes; i++)
		free(m.frames[i]);
	return 0;
}

int main(void)
{
	const char *outdir = getenv("ACQ_BENCH_OUT") ? getenv("ACQ_BENCH_OUT") : ".";
	char path[4096];
	snprintf(path, sizeof path, "%s/devices.tsv", outdir);
	FILE *tsv = fopen(path, "w");
	if (!tsv)
		return 1;
	fprintf(tsv, "metric\tstat\tvalue\n");
	int rc = bench_laser(tsv) | bench_avaspec(tsv);
	fclose(tsv);
	return rc ? 1 : 0;
}
