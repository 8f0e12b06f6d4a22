/* Unit tests of the simulated spectrometer end to end: sim/sim_spectro.c (served from a thread) + physics,
 * through drivers/spectro.h with the "sim" backend: BRDF recovered from counts (z-scores), saturation,
 * occlusion, dark current vs integration time and temperature, time scale, disconnect, busy, stop, timeout,
 * and malformed replies from a fake server. */
#include <pthread.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "drivers/spectro.h"
#include "drivers/spectro_sim_proto.h"
#include "sim/material.h"
#include "sim/sim.h"
#include "sim/sim_physics.h"

static double mono(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

struct rig {
	char dir[64], sock[128];
	struct sim_world w;
	struct sim_service *svc;
	struct yc_doc *simdoc, *devdoc;
	pthread_t th;
	pthread_mutex_t mu;
	volatile int stop;
	struct spectro_cfg *cfg;
	struct spectro *sp;
};

static void *serve(void *arg)
{
	struct rig *r = arg;
	while (!r->stop) {
		struct pollfd fds[16];
		pthread_mutex_lock(&r->mu);
		int n = r->svc->pollfds(r->svc->self, fds, 16);
		pthread_mutex_unlock(&r->mu);
		int k = poll(fds, (nfds_t)n, 1);
		pthread_mutex_lock(&r->mu);
		double now = (mono() - r->w.t0_mono) * r->w.scale;
		if (k > 0)
			r->svc->handle(r->svc->self, fds, n, now);
		r->svc->tick(r->svc->self, now);
		pthread_mutex_unlock(&r->mu);
	}
	return NULL;
}

static struct yc_doc *load(const char *text)
{
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	if (yc_load_string("t.yaml", text, strlen(text), &doc, &err))
		fail_msg("%s", err.msg);
	return doc;
}

static int rig_setup(void **state)
{
	struct rig *r = calloc(1, sizeof *r);
	snprintf(r->dir, sizeof r->dir, "/tmp/acq-test-spectro.XXXXXX");
	assert_non_null(mkdtemp(r->dir));
	snprintf(r->sock, sizeof r->sock, "%s/spec.sock", r->dir);
	const char *s = getenv("ACQ_SEED");
	r->w.seed = s ? strtoull(s, NULL, 10) : 1;
	printf("ACQ_SEED=%llu\n", (unsigned long long)r->w.seed);
	r->w.scale = 100.0;
	r->w.t0_mono = mono();
	bench_defaults(&r->w.geom);
	r->w.laser_power_pct = 100;
	char text[512];
	snprintf(text, sizeof text, "socket: %s\n", r->sock);
	r->devdoc = load(text);
	r->simdoc = load("sample: white\nspectrometer: {temperature_c: 5}\n");
	struct acq_err err = { 0 };
	r->svc = sim_spectro_new(&r->w, yc_root(r->devdoc), yc_root(r->simdoc), &err);
	if (!r->svc)
		fail_msg("%s", err.msg);
	pthread_mutex_init(&r->mu, NULL);
	pthread_create(&r->th, NULL, serve, r);
	snprintf(text, sizeof text, "backend: sim\nsocket: %s\ntimeout_margin_ms: 300\n", r->sock);
	struct yc_doc *cd = load(text);
	if (spectro_cfg_parse(yc_root(cd), &r->cfg, &err))
		fail_msg("%s", err.msg);
	yc_free(cd);
	if (spectro_open(r->cfg, &r->sp, &err))
		fail_msg("%s", err.msg);
	*state = r;
	return 0;
}

static int rig_teardown(void **state)
{
	struct rig *r = *state;
	spectro_close(r->sp);
	spectro_cfg_free(r->cfg);
	r->stop = 1;
	pthread_join(r->th, NULL);
	r->svc->destroy(r->svc->self); /* frees the service too */
	yc_free(r->devdoc);
	yc_free(r->simdoc);
	rmdir(r->dir);
	free(r);
	return 0;
}

/* Change the world under the service's lock. */
static void set_world(struct rig *r, int sample, bool emission, double lt, double dt, double dp)
{
	pthread_mutex_lock(&r->mu);
	r->w.sample = sample;
	r->w.laser_emission = emission;
	r->w.laser_theta_deg = lt;
	r->w.detector_theta_deg = dt;
	r->w.detector_phi_deg = dp;
	pthread_mutex_unlock(&r->mu);
}

/* Measure and wait (the loop a daemon timer would run); returns spectro_fetch's result. */
static int measure(struct rig *r, double it_ms, unsigned avg, struct spectro_frame *f, struct acq_err *err)
{
	struct spectro_meas m = { .integration_ms = it_ms, .averages = avg };
	if (spectro_start(r->sp, &m, mono(), err))
		return -1;
	for (;;) {
		struct pollfd p = { .fd = spectro_pollfd(r->sp), .events = POLLIN };
		poll(&p, 1, 5);
		int rc = spectro_fetch(r->sp, f, mono(), err);
		if (rc)
			return rc;
	}
}

static struct spectro_frame *frame_new(void)
{
	struct spectro_frame *f = calloc(1, sizeof *f);
	assert_non_null(f);
	return f;
}

static void must_measure(struct rig *r, double it, unsigned avg, struct spectro_frame *f)
{
	struct acq_err err = { 0 };
	int rc = measure(r, it, avg, f, &err);
	if (rc != 1)
		fail_msg("measure: %s", err.msg);
}

/* f = (S - D) / (S_ref - D_ref) * rho_ref / pi matches the ground truth within the noise (z-scores). */
static void test_brdf_from_counts(void **state)
{
	struct rig *r = *state;
	const struct spectro_info *in = spectro_info(r->sp);
	assert_int_equal(in->npix, 2048);
	assert_true(fabs(spectro_wavelength(in, 4) - 450) < 0.01 && fabs(spectro_wavelength(in, 2047) - 1100) < 0.01);
	struct spectro_frame *S = frame_new(), *D = frame_new(), *R = frame_new(), *DR = frame_new();
	const double it = 20, lt = 20, dt = 40, dp = 150;
	const unsigned avg = 16;
	set_world(r, SIM_SAMPLE_WHITE, true, lt, dt, dp);
	must_measure(r, it, avg, R);
	set_world(r, SIM_SAMPLE_GREEN_PAINT, true, lt, dt, dp);
	must_measure(r, it, avg, S);
	set_world(r, SIM_SAMPLE_GREEN_PAINT, false, lt, dt, dp);
	must_measure(r, it, avg, D);
	must_measure(r, it, avg, DR);
	assert_true(S->nonlin_applied);
	double wl[2048];
	for (int i = 0; i < 2048; i++)
		wl[i] = spectro_wavelength(in, i);
	struct acq_err err = { 0 };
	struct mat *paint = mat_new(MAT_GREEN_PAINT, 2048, wl, &err);
	assert_non_null(paint);
	double wi[3], wo[3], truth[2048];
	mat_dir(lt * M_PI / 180, 0, wi);
	mat_dir(dt * M_PI / 180, dp * M_PI / 180, wo);
	mat_eval(paint, wi, wo, truth);
	double sz = 0, sz2 = 0, maxrel = 0;
	int n = 0;
	for (int i = in->ndark_pixels; i < 2048; i++) {
		double v = sqrt(avg);
		double s = S->counts[i] - D->counts[i], ref = R->counts[i] - DR->counts[i];
		double vs = (pow(S->stddev[i], 2) + pow(D->stddev[i], 2)) / avg;
		double vr = (pow(R->stddev[i], 2) + pow(DR->stddev[i], 2)) / avg;
		(void)v;
		if (ref < 50 * sqrt(vr))
			continue; /* too little reference signal for a ratio (the silicon's far NIR) */
		double rho = mat_rho_d(MAT_WHITE, wl[i]);
		double f = s / ref * rho / M_PI;
		double sf = rho / M_PI * sqrt(vs / (ref * ref) + s * s * vr / (ref * ref * ref * ref));
		double z = (f - truth[i]) / sf;
		sz += z;
		sz2 += z * z;
		n++;
		maxrel = fmax(maxrel, fabs(f - truth[i]) / truth[i]);
	}
	double mean = sz / n, sd = sqrt(sz2 / n - mean * mean);
	printf("BRDF from counts: %d pixels, z mean %.3f, z sd %.3f, max relative error %.3g\n", n, mean, sd, maxrel);
	assert_true(n > 1500);
	assert_true(fabs(mean) < 0.15);
	assert_true(sd > 0.8 && sd < 1.25);
	/* and it is the paint, not the white: the ratio is far from 1 */
	int p650 = 0;
	while (wl[p650] < 650)
		p650++;
	assert_true(truth[p650] < 0.3 * mat_rho_d(MAT_WHITE, 650) / M_PI);
	mat_free(paint);
	free(S);
	free(D);
	free(R);
	free(DR);
}

/* The metal's specular peak saturates a long exposure: pixels >= 0xFFFC flagged; a short one does not. */
static void test_saturation(void **state)
{
	struct rig *r = *state;
	struct spectro_frame *f = frame_new();
	set_world(r, SIM_SAMPLE_METAL, true, 30, 30, 180);
	must_measure(r, 100, 2, f);
	printf("metal, specular, 100 ms: %d saturated pixels\n", f->nsaturated);
	assert_true(f->nsaturated > 200);
	int flagged = 0;
	for (int i = 0; i < f->npix; i++)
		flagged += f->saturated[i];
	assert_int_equal(flagged, f->nsaturated);
	must_measure(r, 0.05, 2, f);
	assert_int_equal(f->nsaturated, 0);
	/* a saturation burst saturates the next spectrum even of a dim sample, then stops */
	set_world(r, SIM_SAMPLE_WHITE, true, 20, 40, 150);
	pthread_mutex_lock(&r->mu);
	r->w.faults.saturation_burst = 1;
	pthread_mutex_unlock(&r->mu);
	must_measure(r, 1, 1, f);
	assert_true(f->nsaturated > 1000);
	must_measure(r, 1, 1, f);
	assert_int_equal(f->nsaturated, 0);
	free(f);
}

static double mean_counts(const struct spectro_frame *f, int from, int to)
{
	double s = 0;
	for (int i = from; i < to; i++)
		s += f->counts[i];
	return s / (to - from);
}

/* Detector arm in the beam / laser arm hiding the view: only dark is seen; just outside, light again. */
static void test_occlusion(void **state)
{
	struct rig *r = *state;
	struct spectro_frame *f = frame_new(), *d = frame_new();
	set_world(r, SIM_SAMPLE_WHITE, false, 20, 22, 0);
	must_measure(r, 50, 4, d);
	set_world(r, SIM_SAMPLE_WHITE, true, 20, 22, 0); /* 2 deg from the laser arm */
	must_measure(r, 50, 4, f);
	double diff = mean_counts(f, 4, 2048) - mean_counts(d, 4, 2048);
	printf("occluded: light - dark = %.2f counts\n", diff);
	assert_true(fabs(diff) < 3.0);
	set_world(r, SIM_SAMPLE_WHITE, true, 20, 29, 0); /* 9 deg: outside every blind zone */
	must_measure(r, 50, 4, f);
	assert_true(mean_counts(f, 4, 2048) - mean_counts(d, 4, 2048) > 1000);
	/* empty holder: nothing back from the sample, the direct beam when facing the laser */
	set_world(r, SIM_SAMPLE_NONE, true, 20, 40, 150);
	must_measure(r, 50, 4, f);
	assert_true(fabs(mean_counts(f, 4, 2048) - mean_counts(d, 4, 2048)) < 3.0);
	set_world(r, SIM_SAMPLE_NONE, true, 90, 90, 180);
	pthread_mutex_lock(&r->mu);
	r->w.laser_power_pct = 1;
	pthread_mutex_unlock(&r->mu);
	must_measure(r, 0.05, 4, f);
	pthread_mutex_lock(&r->mu);
	r->w.laser_power_pct = 100;
	pthread_mutex_unlock(&r->mu);
	assert_true(mean_counts(f, 4, 2048) > 1500 + 200);
	/* laser on but its interlock open: no light */
	set_world(r, SIM_SAMPLE_WHITE, true, 20, 40, 150);
	pthread_mutex_lock(&r->mu);
	r->w.faults.laser_interlock_open = true;
	pthread_mutex_unlock(&r->mu);
	must_measure(r, 50, 4, f);
	assert_true(fabs(mean_counts(f, 4, 2048) - mean_counts(d, 4, 2048)) < 3.0);
	pthread_mutex_lock(&r->mu);
	r->w.faults.laser_interlock_open = false;
	pthread_mutex_unlock(&r->mu);
	free(f);
	free(d);
}

/* Dark rises with integration time (linearly) and with temperature (doubling every ~6 C). */
static void test_dark_current(void **state)
{
	struct rig *r = *state;
	struct spectro_frame *a = frame_new(), *b = frame_new();
	set_world(r, SIM_SAMPLE_WHITE, false, 20, 40, 150);
	must_measure(r, 10, 8, a);
	must_measure(r, 2000, 1, b);
	double bias = 1500, da = mean_counts(a, 0, 2048) - bias, db = mean_counts(b, 0, 2048) - bias;
	printf("dark above bias at 5 C: 10 ms %.2f, 2000 ms %.2f counts\n", da, db);
	assert_true(db > 50 * fmax(da, 1.0 / 200));
	assert_true(db > 300 && db < 500); /* ~198 counts/s at 5 C */
	pthread_mutex_lock(&r->mu);
	r->w.sensor_temp_c = 25;
	pthread_mutex_unlock(&r->mu);
	must_measure(r, 2000, 1, a);
	pthread_mutex_lock(&r->mu);
	r->w.sensor_temp_c = 5;
	pthread_mutex_unlock(&r->mu);
	double dh = mean_counts(a, 0, 2048) - bias;
	printf("dark above bias, 2000 ms: 5 C %.1f, 25 C %.1f (ratio %.2f)\n", db, dh, dh / db);
	assert_true(dh / db > 7 && dh / db < 14);
	assert_true(fabs(a->temperature_c - 25) < 0.5);
	free(a);
	free(b);
}

/* Time scale 100: 100 ms x 10 (1.01 bench s) returns in about 10 ms of real time. */
static void test_time_scale(void **state)
{
	struct rig *r = *state;
	struct spectro_frame *f = frame_new();
	double t0 = mono();
	must_measure(r, 100, 10, f);
	double dt = mono() - t0;
	printf("100 ms x 10 at scale 100: %.1f ms real\n", dt * 1e3);
	assert_true(dt > 0.008 && dt < 0.25);
	assert_true(f->meas.averages == 10 && f->meas.integration_ms == 100);
	free(f);
}

/* The spectrometer vanishes mid-read: fetch says so; a second client is refused as busy; reopen works. */
static void test_disconnect_busy_reopen(void **state)
{
	struct rig *r = *state;
	struct acq_err err = { 0 };
	struct spectro *other = NULL;
	assert_int_equal(spectro_open(r->cfg, &other, &err), -1);
	printf("second client: %s\n", err.msg);
	assert_non_null(strstr(err.msg, "busy"));
	struct spectro_frame *f = frame_new();
	pthread_mutex_lock(&r->mu);
	r->w.faults.spectro_disconnect = true;
	pthread_mutex_unlock(&r->mu);
	assert_int_equal(measure(r, 200, 1, f, &err), -1);
	assert_int_equal(err.code, ACQ_E_DISCONNECTED);
	printf("disconnect: %s\n", err.msg);
	struct spectro_meas m = { .integration_ms = 1, .averages = 1 };
	assert_int_equal(spectro_start(r->sp, &m, mono(), &err), -1);
	spectro_close(r->sp);
	r->sp = NULL;
	/* reopen through a ports file (the form acq-sim --ports-file writes) */
	char pf[160], text[256];
	snprintf(pf, sizeof pf, "%s/ports.json", r->dir);
	FILE *fp = fopen(pf, "w");
	assert_non_null(fp);
	fprintf(fp, "{\"pid\": 1, \"spectrometer\": {\"socket\": \"%s\", \"pixels\": 2048}}\n", r->sock);
	fclose(fp);
	snprintf(text, sizeof text, "backend: sim\nports_file: %s\n", pf);
	struct yc_doc *cd = load(text);
	struct spectro_cfg *cfg2 = NULL;
	assert_int_equal(spectro_cfg_parse(yc_root(cd), &cfg2, &err), 0);
	yc_free(cd);
	assert_int_equal(spectro_open(cfg2, &r->sp, &err), 0);
	assert_int_equal(spectro_info(r->sp)->npix, 2048);
	must_measure(r, 1, 1, f);
	spectro_close(r->sp);
	spectro_cfg_free(cfg2);
	unlink(pf);
	assert_int_equal(spectro_open(r->cfg, &r->sp, &err), 0);
	must_measure(r, 1, 1, f);
	/* stop, then a new measurement gets its own frame (not the stopped one's) */
	m.integration_ms = 300;
	assert_int_equal(spectro_start(r->sp, &m, mono(), &err), 0);
	assert_int_equal(spectro_stop(r->sp, &err), 0);
	set_world(r, SIM_SAMPLE_WHITE, false, 20, 40, 150);
	must_measure(r, 2, 3, f);
	assert_true(f->meas.integration_ms == 2 && f->meas.averages == 3);
	free(f);
}

/* A fetch past the deadline (integration x averages + read-out + margin) is a timeout, once the margin has also
 * passed in real time (a simulated bench's clock runs faster than the transport and the simulator's computing). */
static void test_timeout(void **state)
{
	struct rig *r = *state;
	struct acq_err err = { 0 };
	struct spectro_frame *f = frame_new();
	pthread_mutex_lock(&r->mu); /* freeze the bench: nothing will answer */
	struct spectro_meas m = { .integration_ms = 10, .averages = 1 };
	double t = mono();
	assert_int_equal(spectro_start(r->sp, &m, t, &err), 0);
	assert_int_equal(spectro_fetch(r->sp, f, t + 0.1, &err), 0);
	double el = mono() - t;
	int early = spectro_fetch(r->sp, f, t + 0.4, &err); /* past the deadline on the caller's clock only */
	int late = -1;
	if (early == 0) {
		while (mono() - t < 0.31)
			usleep(10000);
		late = spectro_fetch(r->sp, f, t + 0.4, &err);
	}
	pthread_mutex_unlock(&r->mu);
	if (early != 0)
		assert_true(el >= 0.25); /* only when this thread was held up past the real margin (a loaded machine) */
	assert_int_equal(late, -1);
	assert_int_equal(err.code, ACQ_E_TIMEOUT);
	printf("timeout: %s\n", err.msg);
	/* the late answer is stale and ignored by the next measurement */
	usleep(20000);
	must_measure(r, 3, 1, f);
	assert_true(f->meas.integration_ms == 3);
	free(f);
}

/* ---- malformed replies from a fake server ---- */

struct fake {
	int lfd;
	int scenario;
	char path[128];
};

static void put_identity(unsigned char *b, uint32_t npix, uint32_t len)
{
	memset(b, 0, SSP_HDR + len);
	ssp_header(b, SSP_IDENTITY, 1, len);
	unsigned char *p = b + SSP_HDR;
	memcpy(p, "FAKE", 4);
	ssp_put32(p + 96, npix);
	ssp_putd(p + 100, 450);
	ssp_putd(p + 108, 0.3);
	ssp_putd(p + 176, 65535);
}

static void *fake_serve(void *arg)
{
	struct fake *fk = arg;
	struct pollfd pl = { .fd = fk->lfd, .events = POLLIN };
	if (poll(&pl, 1, 3000) != 1)
		return NULL;
	int fd = accept(fk->lfd, NULL, NULL);
	if (fd < 0)
		return NULL;
	unsigned char b[SSP_HDR + SSP_SPECTRUM_LEN(100)], req[64];
	memset(b, 0, sizeof b);
	ssp_header(b, SSP_HELLO, 0, SSP_HELLO_LEN);
	ssp_put32(b + SSP_HDR, 1);
	if (fk->scenario == 0)
		ssp_put32(b, 0xdeadbeef);
	ssize_t w = send(fd, b, SSP_HDR + SSP_HELLO_LEN, MSG_NOSIGNAL);
	if (fk->scenario > 0 && recv(fd, req, sizeof req, 0) > 0) {
		if (fk->scenario == 1)
			put_identity(b, 1u << 20, SSP_IDENTITY_LEN); /* absurd pixel count */
		else if (fk->scenario == 2)
			put_identity(b, 100, SSP_IDENTITY_LEN - 8); /* wrong length */
		else
			put_identity(b, 100, SSP_IDENTITY_LEN);
		w = send(fd, b, SSP_HDR + ssp_get32(b + 12), MSG_NOSIGNAL);
		if (fk->scenario >= 3 && recv(fd, req, sizeof req, 0) > 0) {
			uint32_t npix = fk->scenario == 3 ? 99 : 100;
			memset(b, 0, sizeof b);
			ssp_header(b, SSP_SPECTRUM, ssp_get32(req + 8), SSP_SPECTRUM_LEN(100));
			ssp_put32(b + SSP_HDR + 28, npix);
			if (fk->scenario == 4)
				ssp_putd(b + SSP_HDR + SSP_SPECTRUM_FIXED + 8 * 5, NAN);
			if (fk->scenario == 5)
				ssp_header(b, SSP_SPECTRUM, ssp_get32(req + 8), 0x7fffffff);
			w = send(fd, b, fk->scenario == 5 ? SSP_HDR : sizeof b, MSG_NOSIGNAL);
		}
	}
	(void)w;
	usleep(100000);
	close(fd);
	return NULL;
}

static void test_bad_replies(void **state)
{
	(void)state;
	static const char *const expect[] = { "bad magic", "pixels", "identity of", "spectrum of 99 pixels",
					      "out of range", "exceeds" };
	for (int sc = 0; sc < 6; sc++) {
		struct fake fk = { .scenario = sc };
		char dir[64] = "/tmp/acq-test-fake.XXXXXX";
		assert_non_null(mkdtemp(dir));
		snprintf(fk.path, sizeof fk.path, "%s/s.sock", dir);
		struct acq_err err = { 0 };
		fk.lfd = sim_listen_unix(fk.path, &err);
		assert_true(fk.lfd >= 0);
		pthread_t th;
		pthread_create(&th, NULL, fake_serve, &fk);
		char text[256];
		snprintf(text, sizeof text, "backend: sim\nsocket: %s\nopen_timeout_ms: 2000\n", fk.path);
		struct yc_doc *cd = load(text);
		struct spectro_cfg *cfg = NULL;
		assert_int_equal(spectro_cfg_parse(yc_root(cd), &cfg, &err), 0);
		struct spectro *sp = NULL;
		int rc = spectro_open(cfg, &sp, &err);
		if (sc >= 3) {
			assert_int_equal(rc, 0);
			struct spectro_frame *f = frame_new();
			struct spectro_meas m = { .integration_ms = 1, .averages = 1 };
			assert_int_equal(spectro_start(sp, &m, mono(), &err), 0);
			double t0 = mono();
			while ((rc = spectro_fetch(sp, f, mono(), &err)) == 0 && mono() - t0 < 2)
				usleep(1000);
			assert_int_equal(rc, -1);
			free(f);
			spectro_close(sp);
		} else {
			assert_int_equal(rc, -1);
		}
		printf("scenario %d: %s\n", sc, err.msg);
		assert_non_null(strstr(err.msg, expect[sc]));
		pthread_join(th, NULL);
		close(fk.lfd);
		unlink(fk.path);
		rmdir(dir);
		spectro_cfg_free(cfg);
		yc_free(cd);
	}
}

/* Configuration errors say what and where. */
static void test_bad_config(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct spectro_cfg *cfg = NULL;
	struct yc_doc *d = load("backend: sim\nsocket: /a\nports_file: /b\n");
	assert_int_equal(spectro_cfg_parse(yc_root(d), &cfg, &err), -1);
	assert_non_null(strstr(err.msg, "not both"));
	yc_free(d);
	/* neither: the ports file of ACQ_SIM_PORTS at open time, else a clear error */
	d = load("backend: sim\n");
	assert_int_equal(spectro_cfg_parse(yc_root(d), &cfg, &err), 0);
	struct spectro *sp0 = NULL;
	unsetenv("ACQ_SIM_PORTS");
	assert_int_equal(spectro_open(cfg, &sp0, &err), -1);
	assert_non_null(strstr(err.msg, "ACQ_SIM_PORTS"));
	setenv("ACQ_SIM_PORTS", "/nonexistent/ports.json", 1);
	assert_int_equal(spectro_open(cfg, &sp0, &err), -1);
	assert_non_null(strstr(err.msg, "/nonexistent/ports.json"));
	unsetenv("ACQ_SIM_PORTS");
	spectro_cfg_free(cfg);
	yc_free(d);
	d = load("backend: sim\nsocket: /x\ntimeout_margin_ms: -5\n");
	assert_int_equal(spectro_cfg_parse(yc_root(d), &cfg, &err), -1);
	assert_non_null(strstr(err.msg, "t.yaml:3"));
	yc_free(d);
	d = load("backend: sim\nsocket: /nonexistent/x.sock\n");
	assert_int_equal(spectro_cfg_parse(yc_root(d), &cfg, &err), 0);
	struct spectro *sp = NULL;
	assert_int_equal(spectro_open(cfg, &sp, &err), -1);
	assert_non_null(strstr(err.msg, "cannot connect"));
	spectro_cfg_free(cfg);
	yc_free(d);
	/* the service's own config */
	struct sim_world w = { .scale = 1 };
	bench_defaults(&w.geom);
	d = load("sample: velvet\n");
	assert_null(sim_spectro_new(&w, NULL, yc_root(d), &err));
	assert_non_null(strstr(err.msg, "t.yaml:1"));
	yc_free(d);
	d = load("spectrometer: {pixels: 5}\n");
	assert_null(sim_spectro_new(&w, NULL, yc_root(d), &err));
	assert_non_null(strstr(err.msg, "t.yaml:1"));
	yc_free(d);
	d = load("spectrometer: {colour: red}\n");
	assert_null(sim_spectro_new(&w, NULL, yc_root(d), &err));
	assert_non_null(strstr(err.msg, "colour"));
	yc_free(d);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(test_brdf_from_counts, rig_setup, rig_teardown),
		cmocka_unit_test_setup_teardown(test_saturation, rig_setup, rig_teardown),
		cmocka_unit_test_setup_teardown(test_occlusion, rig_setup, rig_teardown),
		cmocka_unit_test_setup_teardown(test_dark_current, rig_setup, rig_teardown),
		cmocka_unit_test_setup_teardown(test_time_scale, rig_setup, rig_teardown),
		cmocka_unit_test_setup_teardown(test_disconnect_busy_reopen, rig_setup, rig_teardown),
		cmocka_unit_test_setup_teardown(test_timeout, rig_setup, rig_teardown),
		cmocka_unit_test(test_bad_replies),
		cmocka_unit_test(test_bad_config),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
