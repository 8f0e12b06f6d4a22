/* AvaSpec driver under umockdev: real libusb-1.0 against the golden device and exchanges of
 * tests/golden/avaspec/ (written by gen_golden.py). Each cmocka case re-executes this binary as
 * `umockdev-run -d avaspec.umockdev -i /dev/bus/usb/001/002=<case>.ioctl -- test_avaspec_usb --case <case>`;
 * an OUT the driver sends that differs from the golden bytes fails the transfer, so the traffic is diffed. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>
#include <cmocka.h>

#include "drivers/spectro.h"

#define NPIX 2048

static const char *self_path;

static const char cfg_text[] =
	"backend: avaspec-usb\n"
	"vendor_id: 0x1992\n"
	"product_ids: [0x0667]\n"
	"serial: BRDF0001\n"
	"timeout_margin_ms: 500\n"
	"dark_pixels: [2, 3, 4, 5]\n";

/* The device's spectrum as gen_golden.py defines it. */
static double raw_at(int p)
{
	if (p == 100)
		return 0xFFFF;
	if (p >= 2 && p <= 5)
		return 1000 + p;
	return 1000 + (37 * p) % 20000;
}

/* ---- the inner side: runs under umockdev-run, exit 0 when the case ends as expected ---------------- */

#define CHECK(c) do { if (!(c)) { fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #c); \
	goto out; } } while (0)

struct rig {
	struct yc_doc *doc;
	struct spectro_cfg *cfg;
	struct spectro *s;
	struct acq_err err;
};

static int rig_open(struct rig *r)
{
	memset(r, 0, sizeof *r);
	if (yc_load_string("avaspec.yaml", cfg_text, strlen(cfg_text), &r->doc, &r->err) ||
	    spectro_cfg_parse(yc_root(r->doc), &r->cfg, &r->err) || spectro_open(r->cfg, &r->s, &r->err)) {
		fprintf(stderr, "open: %s\n", r->err.msg);
		return -1;
	}
	return 0;
}

static void rig_close(struct rig *r)
{
	spectro_close(r->s);
	spectro_cfg_free(r->cfg);
	yc_free(r->doc);
}

static int expect_fetch_error(struct rig *r, int code, const char *needle)
{
	static struct spectro_frame f;
	struct spectro_meas m = { .integration_ms = 10, .averages = 1, .saturation_detection = true };
	if (spectro_start(r->s, &m, 0, &r->err)) {
		fprintf(stderr, "start: %s\n", r->err.msg);
		return -1;
	}
	int rc = spectro_fetch(r->s, &f, 0.001, &r->err);
	fprintf(stderr, "fetch -> %d: %s (%s)\n", rc, r->err.msg, acq_errname(r->err.code));
	return rc == -1 && r->err.code == code && strstr(r->err.msg, needle) ? 0 : -1;
}

static int run_case(const char *name)
{
	static struct spectro_frame f;
	struct rig r;
	int ok = -1;
	if (rig_open(&r))
		goto out;
	const struct spectro_info *info = spectro_info(r.s);
	CHECK(info->npix == NPIX);
	CHECK(!strcmp(info->serial, "BRDF0001"));
	CHECK(!strcmp(info->model, "AvaSpec-ULS2048CL-EVO"));
	CHECK(fabs(spectro_wavelength(info, 1000) - (450 + 320 - 1.0)) < 1e-3);
	CHECK(info->nonlin_enabled && info->nonlin_coef[0] == 1.0 && info->nonlin_low == 1000);
	CHECK(info->ndark_pixels == 4);
	if (!strcmp(name, "stale_reset")) {
		ok = 0;
	} else if (!strcmp(name, "cycle") || !strcmp(name, "averaged")) {
		bool avg = !strcmp(name, "averaged");
		struct spectro_meas m = { .integration_ms = avg ? 2.5 : 10, .averages = avg ? 4 : 1,
					  .saturation_detection = !avg };
		CHECK(spectro_start(r.s, &m, 0, &r.err) == 0);
		int rc = spectro_fetch(r.s, &f, 0.001, &r.err);
		if (rc != 1)
			fprintf(stderr, "fetch: %d %s\n", rc, r.err.msg);
		CHECK(rc == 1);
		CHECK(f.npix == NPIX);
		CHECK(f.dark_pixel_corrected && f.nonlin_applied);
		CHECK(fabs(f.dark_pixel_level - 1003.5 - (avg ? 0.375 : 0)) < 1e-9);
		CHECK(f.nsaturated == 1 && f.saturated[100] && !f.saturated[99]);
		CHECK(fabs(f.device_time_s - (avg ? 777e-5 : 123456e-5)) < 1e-12);
		for (int p = 0; p < NPIX; p++) {
			double raw = raw_at(p) + (avg ? (p % 4) / 4.0 : 0);
			double c = raw - f.dark_pixel_level;
			double x = c < 1000 ? 1000 : c > 60000 ? 60000 : c;
			double want = c / (1 + 1e-6 * x);
			if (fabs(f.counts[p] - want) > 1e-6) {
				fprintf(stderr, "pixel %d: %g, expected %g\n", p, f.counts[p], want);
				goto out;
			}
		}
		CHECK(f.meas.averages == m.averages && f.meas.integration_ms == m.integration_ms);
		ok = 0;
	} else if (!strcmp(name, "error_reply")) {
		struct spectro_meas m = { .integration_ms = 10, .averages = 1, .saturation_detection = true };
		CHECK(spectro_start(r.s, &m, 0, &r.err) == -1);
		fprintf(stderr, "start: %s\n", r.err.msg);
		CHECK(r.err.code == ACQ_E_DEVICE && r.err.detail == 7 + 1);
		CHECK(strstr(r.err.msg, "invalid integration time"));
		ok = 0;
	} else if (!strcmp(name, "short_data")) {
		ok = expect_fetch_error(&r, ACQ_E_PROTO, "short");
	} else if (!strcmp(name, "oversized_data")) {
		ok = expect_fetch_error(&r, ACQ_E_PROTO, "oversized");
	} else if (!strcmp(name, "vanish")) {
		ok = expect_fetch_error(&r, ACQ_E_DISCONNECTED, "disconnected");
	} else {
		fprintf(stderr, "unknown case %s\n", name);
	}
out:
	rig_close(&r);
	return ok;
}

/* ---- the outer side: cmocka cases that run the inner side under umockdev-run ----------------------- */

static void run_under_umockdev(const char *name)
{
	if (system("command -v umockdev-run >/dev/null 2>&1") != 0) {
		printf("skip: umockdev-run is not installed (make deps installs umockdev)\n");
		skip();
	}
	const char *src = getenv("ACQ_SRC") ? getenv("ACQ_SRC") : ".";
	char dev[4096], ioc[4096];
	snprintf(dev, sizeof dev, "%s/tests/golden/avaspec/avaspec.umockdev", src);
	snprintf(ioc, sizeof ioc, "/dev/bus/usb/001/002=%s/tests/golden/avaspec/%s.ioctl", src, name);
	pid_t pid = fork();
	assert_true(pid >= 0);
	if (pid == 0) {
		/* The umockdev preload library comes before the sanitizer runtime in the library list. */
		const char *a = getenv("ASAN_OPTIONS");
		char opts[1024];
		snprintf(opts, sizeof opts, "%s%sverify_asan_link_order=0", a ? a : "", a && *a ? ":" : "");
		setenv("ASAN_OPTIONS", opts, 1);
		execlp("umockdev-run", "umockdev-run", "-d", dev, "-i", ioc, "--", self_path, "--case", name, (char *)NULL);
		_exit(127);
	}
	int st = 0;
	assert_int_equal(waitpid(pid, &st, 0), pid);
	assert_true(WIFEXITED(st));
	assert_int_equal(WEXITSTATUS(st), 0);
}

static void test_cycle(void **state) { (void)state; run_under_umockdev("cycle"); }
static void test_averaged(void **state) { (void)state; run_under_umockdev("averaged"); }
static void test_error_reply(void **state) { (void)state; run_under_umockdev("error_reply"); }
static void test_short_data(void **state) { (void)state; run_under_umockdev("short_data"); }
static void test_oversized_data(void **state) { (void)state; run_under_umockdev("oversized_data"); }
static void test_vanish(void **state) { (void)state; run_under_umockdev("vanish"); }
static void test_stale_reset(void **state) { (void)state; run_under_umockdev("stale_reset"); }

int main(int argc, char **argv)
{
	if (argc == 3 && !strcmp(argv[1], "--case"))
		return run_case(argv[2]) ? 1 : 0;
	static char exe[4096];
	ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
	self_path = n > 0 ? (exe[n] = 0, exe) : argv[0];
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_cycle),          cmocka_unit_test(test_averaged),
		cmocka_unit_test(test_error_reply),    cmocka_unit_test(test_short_data),
		cmocka_unit_test(test_oversized_data), cmocka_unit_test(test_vanish),
		cmocka_unit_test(test_stale_reset),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
