/* Tests of drivers/regmap.c: the shipped maps (AZ, Leadshine-like), addressing conventions, value encoding
 * (types, word order, byte swap, scale/offset/sign) against an independent bit-level computation, and
 * malformed maps that must fail with a located, named error. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config/yconf.h"
#include "drivers/axis_modbus.h"
#include "drivers/regmap.h"

static uint64_t rng = 1;

static uint64_t next(void)
{
	rng ^= rng << 13;
	rng ^= rng >> 7;
	rng ^= rng << 17;
	return rng;
}

static struct yc_doc *load_src(const char *rel)
{
	const char *src = getenv("ACQ_SRC");
	char path[512];
	snprintf(path, sizeof path, "%s/%s", src ? src : ".", rel);
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	if (yc_load_file(path, &doc, &err))
		fail_msg("%s", err.msg);
	return doc;
}

static struct yc_node *maps_of(struct yc_doc *doc)
{
	return yc_get(yc_get(yc_root(doc), "devices"), "register_maps");
}

static void test_shipped_az_map(void **state)
{
	(void)state;
	struct yc_doc *doc = load_src("config/bench-sim.yaml");
	struct regmap *m = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(regmap_parse(maps_of(doc), "oriental_az", NULL, &m, &err), 0);
	assert_true(m->block);
	assert_int_equal(m->block_start, 0x58);
	assert_int_equal(m->block_count, 16);
	assert_int_equal(m->f[RM_TARGET].addr, 0x5C);
	assert_int_equal(m->f[RM_TARGET].type, REGMAP_INT32);
	assert_false(m->f[RM_TARGET].word_swap); /* upper word first */
	assert_int_equal(m->f[RM_TRIGGER].addr, 0x66);
	assert_true(m->f[RM_TRIGGER].has_value && m->f[RM_TRIGGER].value == 1);
	assert_int_equal(m->f[RM_OP_TYPE].value, 1);
	assert_int_equal(m->f[RM_STATUS].addr, 0x7F);
	assert_int_equal(m->bit[RM_BIT_ALARM], 7);
	assert_int_equal(m->bit[RM_BIT_IN_POS], 14);
	assert_true(m->cmd[RM_CMD_STOP].present && m->cmd[RM_CMD_STOP].level);
	assert_int_equal(m->cmd[RM_CMD_STOP].addr, 0x7D);
	assert_int_equal(m->cmd[RM_CMD_STOP].value, 0x20);
	assert_int_equal(m->cmd[RM_CMD_ALARM_RESET].value, 0x80);
	assert_false(m->cmd[RM_CMD_START].present);
	assert_string_equal(m->vendor, "Oriental Motor");
	regmap_free(m);
	/* the arms of the shipped config parse with it */
	struct axis_cfg *cfg[2];
	int n = 0;
	struct yc_node *dev = yc_get(yc_root(doc), "devices");
	assert_int_equal(axis_arm_parse(yc_get(dev, "detector_arm"), maps_of(doc), "detector_arm", cfg, 2, &n, &err), 0);
	assert_int_equal(n, 2);
	assert_string_equal(axis_cfg_name(cfg[1]), "detector.phi");
	assert_int_equal(axis_cfg_unit(cfg[1]), 2);
	for (int i = 0; i < n; i++)
		axis_cfg_free(cfg[i]);
	yc_free(doc);
}

static void test_shipped_real_config(void **state)
{
	(void)state;
	struct yc_doc *doc = load_src("config/bench-real.yaml");
	struct regmap *m = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(regmap_parse(maps_of(doc), "leadshine_like", NULL, &m, &err), 0);
	assert_false(m->block);
	assert_int_equal(m->f[RM_TARGET].addr, 0x6201);
	assert_true(m->cmd[RM_CMD_START].present && !m->cmd[RM_CMD_START].level);
	assert_int_equal(m->cmd[RM_CMD_HOME].value, 0x20);
	regmap_free(m);
	struct yc_node *dev = yc_get(yc_root(doc), "devices");
	struct axis_cfg *cfg[2];
	int n = 0;
	assert_int_equal(axis_arm_parse(yc_get(dev, "laser_arm"), maps_of(doc), "laser_arm", cfg, 2, &n, &err), 0);
	const struct axis_link_cfg *l = axis_cfg_link(cfg[0]);
	assert_int_equal(l->type, AXIS_LINK_RTU);
	assert_int_equal(l->parity, 'E');
	assert_int_equal(l->response_timeout_ms, 1000);
	axis_cfg_free(cfg[0]);
	assert_int_equal(axis_arm_parse(yc_get(dev, "detector_arm"), maps_of(doc), "detector_arm", cfg, 2, &n, &err), 0);
	assert_int_equal(n, 2);
	assert_int_equal(axis_cfg_link(cfg[0])->port, 502);
	/* the daemon points a TCP axis at the port acq-sim chose */
	assert_int_equal(axis_cfg_set_endpoint(cfg[0], 40123, NULL, &err), 0);
	assert_int_equal(axis_cfg_link(cfg[0])->port, 40123);
	assert_int_equal(axis_cfg_set_endpoint(cfg[0], 0, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
	assert_string_equal(axis_cfg_map(cfg[0])->name, "leadshine_like");
	for (int i = 0; i < n; i++)
		axis_cfg_free(cfg[i]);
	yc_free(doc);
}

/* Reference encoder written from the definitions, bit by bit, independent of regmap.c. */
static void ref_encode(int type, bool wswap, bool bswap, int64_t raw, float fl, uint16_t out[2])
{
	uint32_t u;
	if (type == REGMAP_FLOAT32)
		memcpy(&u, &fl, 4);
	else
		u = (uint32_t)raw;
	uint8_t b[4] = { (uint8_t)(u >> 24), (uint8_t)(u >> 16), (uint8_t)(u >> 8), (uint8_t)u }; /* ABCD */
	if (type == REGMAP_INT16 || type == REGMAP_UINT16) {
		out[0] = bswap ? (uint16_t)(b[3] << 8 | b[2]) : (uint16_t)(b[2] << 8 | b[3]);
		return;
	}
	uint16_t hi = bswap ? (uint16_t)(b[1] << 8 | b[0]) : (uint16_t)(b[0] << 8 | b[1]);
	uint16_t lo = bswap ? (uint16_t)(b[3] << 8 | b[2]) : (uint16_t)(b[2] << 8 | b[3]);
	out[0] = wswap ? lo : hi;
	out[1] = wswap ? hi : lo;
}

static void test_encoding_against_reference(void **state)
{
	(void)state;
	static const int64_t lo[] = { -32768, 0, INT32_MIN, 0 }, hi[] = { 32767, 65535, INT32_MAX, UINT32_MAX };
	struct acq_err err = { 0 };
	for (int type = REGMAP_INT16; type <= REGMAP_FLOAT32; type++)
		for (int ws = 0; ws < 2; ws++)
			for (int bs = 0; bs < 2; bs++)
				for (int k = 0; k < 500; k++) {
					struct regmap_field f = { .present = true, .type = type, .word_swap = ws,
								  .byte_swap = bs, .scale = 1, .sign = 1 };
					uint16_t got[2] = { 0 }, want[2] = { 0 };
					if (type == REGMAP_FLOAT32) {
						float fl = (float)((double)(int64_t)next() / 1e12);
						assert_int_equal(regmap_encode_raw(&f, fl, got, &err), 0);
						ref_encode(type, ws, bs, 0, fl, want);
						assert_true(regmap_decode_raw(&f, got) == (double)fl);
					} else {
						int64_t span = hi[type] - lo[type];
						int64_t raw = lo[type] + (int64_t)(next() % (uint64_t)(span + 1));
						assert_int_equal(regmap_encode_raw(&f, (double)raw, got, &err), 0);
						ref_encode(type, ws, bs, raw, 0, want);
						assert_true(regmap_decode_raw(&f, got) == (double)raw);
					}
					assert_int_equal(got[0], want[0]);
					if (regmap_width(&f) == 2)
						assert_int_equal(got[1], want[1]);
				}
	/* out of range for the type: named error, no write */
	struct regmap_field f16 = { .present = true, .type = REGMAP_INT16, .scale = 1, .sign = 1 };
	uint16_t r[2];
	assert_int_equal(regmap_encode_raw(&f16, 40000, r, &err), -1);
	assert_int_equal(err.code, ACQ_E_RANGE);
	assert_int_equal(regmap_encode_raw(&f16, NAN, r, &err), -1);
	struct regmap_field fu = { .present = true, .type = REGMAP_UINT32, .scale = 1, .sign = 1 };
	assert_int_equal(regmap_encode_raw(&fu, -1, r, &err), -1);
}

static void test_scale_offset_sign(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	for (int k = 0; k < 1000; k++) {
		double scale = 1 + (double)(next() % 5000) / 10.0, offset = (double)(int)(next() % 200) - 100;
		int sign = next() & 1 ? 1 : -1;
		struct regmap_field f = { .present = true, .type = REGMAP_INT32, .scale = scale, .offset = offset,
					  .sign = sign };
		double deg = (double)(int)(next() % 72000) / 100.0 - 360;
		uint16_t regs[2];
		assert_int_equal(regmap_encode(&f, deg, regs, &err), 0);
		double counts = regmap_decode_raw(&f, regs);
		assert_true(fabs(counts - nearbyint(sign * scale * (deg - offset))) < 0.5);
		assert_true(fabs(regmap_decode(&f, regs) - deg) <= 0.5 / scale + 1e-9);
	}
}

/* A minimal valid map with one replaceable line (the AZ status word shape), to test addressing. */
static int parse_text(const char *text, struct regmap **m, struct acq_err *err)
{
	struct yc_doc *doc = NULL;
	if (yc_load_string("t.yaml", text, strlen(text), &doc, err))
		return -1;
	int rc = regmap_parse(yc_root(doc), "m", NULL, m, err);
	yc_free(doc);
	return rc;
}

static void test_addressing(void **state)
{
	(void)state;
	struct regmap *m = NULL;
	struct acq_err err = { 0 };
	const char *one =
		"m:\n  addressing: one_based\n  fields:\n    target: {addr: 1, type: int32}\n"
		"    actual: {addr: 3, type: int32}\n    status: {addr: 100}\n"
		"  status_bits: {busy: 0, alarm: 1}\n"
		"  commands: {start: {addr: 10, value: 1}, stop: {addr: 10, value: 2}}\n";
	assert_int_equal(parse_text(one, &m, &err), 0);
	assert_int_equal(m->f[RM_TARGET].addr, 0);
	assert_int_equal(m->f[RM_STATUS].addr, 99);
	assert_int_equal(m->cmd[RM_CMD_START].addr, 9);
	regmap_free(m);
	const char *modicon =
		"m:\n  addressing: modicon\n  fields:\n    target: {addr: 40351, type: int32}\n"
		"    actual: {addr: 30007, type: int32}\n    status: {addr: 400005}\n"
		"  status_bits: {move: 3, alarm: 1}\n"
		"  commands: {start: {addr: 40125, value: 0x67}, stop: {addr: 40125, value: 0xE1}}\n";
	assert_int_equal(parse_text(modicon, &m, &err), 0);
	assert_int_equal(m->f[RM_TARGET].addr, 350);
	assert_int_equal(m->f[RM_TARGET].space, REGMAP_HOLDING);
	assert_int_equal(m->f[RM_ACTUAL].addr, 6);
	assert_int_equal(m->f[RM_ACTUAL].space, REGMAP_INPUT);
	assert_int_equal(m->f[RM_STATUS].addr, 4);
	assert_int_equal(m->cmd[RM_CMD_START].addr, 124);
	regmap_free(m);
}

struct bad {
	const char *text;
	const char *where;  /* "t.yaml:L:C" */
	const char *words;  /* expected in the message */
};

#define OKF "  fields:\n    target: {addr: 0x5C, type: int32}\n    actual: {addr: 0xCC, type: int32}\n" \
	    "    status: {addr: 0x7F}\n"
#define OKB "  status_bits: {busy: 8, alarm: 7}\n"
#define OKC "  commands: {start: {addr: 0x7D, value: 8}, stop: {addr: 0x7D, value: 0x20}}\n"

static void test_malformed_maps(void **state)
{
	(void)state;
	static const struct bad bad[] = {
		{ "m:\n  addressing: sideways\n" OKF OKB OKC, "t.yaml:2:15", "addressing" },
		{ "m:\n  fields:\n    target: {addr: 0x5C, type: int33}\n    actual: {addr: 0xCC}\n    status: {addr: 1}\n"
		  OKB OKC, "t.yaml:3:32", "int32" },
		{ "m:\n  fields:\n    target: {addr: 70000}\n    actual: {addr: 0xCC}\n    status: {addr: 1}\n" OKB OKC,
		  "t.yaml:3:20", "address" },
		{ "m:\n  fields:\n    target: {addr: 0x5C}\n    status: {addr: 1}\n" OKB OKC, "t.yaml:3:5", "actual" },
		{ "m:\n" OKF "  status_bits: {busy: 16, alarm: 7}\n" OKC, "t.yaml:6:23", "busy" },
		{ "m:\n" OKF "  status_bits: {busy: 1}\n" OKC, "t.yaml:6:16", "alarm" },
		{ "m:\n" OKF OKB "  commands: {start: {addr: 0x7D, value: 8}}\n", "t.yaml:7:13", "stop" },
		{ "m:\n" OKF OKB "  commands: {start: {addr: 0x7D, value: 8, mode: toggle}, stop: {addr: 1, value: 1}}\n",
		  "t.yaml:7:50", "mode" },
		{ "m:\n" OKF OKB "  commands: {start: {addr: 0x7D, value: 0}, stop: {addr: 1, value: 1}}\n",
		  "t.yaml:7:41", "value 0" },
		{ "m:\n" OKF OKB OKC "  colour: blue\n", "t.yaml:8:3", "colour" },
		{ "m:\n  write: block\n  block: {start: 0x58, count: 4}\n" OKF OKB OKC, "t.yaml:5:13", "outside" },
		{ "m:\n  write: block\n" OKF OKB OKC, "t.yaml:2:10", "block" },
		{ "m:\n  fields:\n    target: {addr: 0x5C, type: int32}\n    speed: {addr: 0x5D, type: int32}\n"
		  "    actual: {addr: 0xCC}\n    status: {addr: 1}\n  write: block\n  block: {start: 0x58, count: 16}\n"
		  OKB OKC, "t.yaml:4:12", "overlaps" },
		{ "m:\n  fields:\n    target: {addr: 0x5C, scale: 0}\n    actual: {addr: 0xCC}\n    status: {addr: 1}\n"
		  OKB OKC, "t.yaml:3:33", "scale" },
		{ "m:\n  fields:\n    target: {addr: 0x5C}\n    op_type: {addr: 0x5A}\n    actual: {addr: 0xCC}\n"
		  "    status: {addr: 1}\n" OKB OKC, "t.yaml:4:14", "value" },
		{ "m:\n  fields:\n    target: {addr: 0x5C}\n    op_type: {addr: 0x5A, type: int16, value: 70000}\n"
		  "    actual: {addr: 0xCC}\n    status: {addr: 1}\n" OKB OKC, "t.yaml:4:47", "does not fit" },
		{ "m:\n  fields:\n    target: {addr: 0x5C, fc: input}\n    actual: {addr: 0xCC}\n    status: {addr: 1}\n"
		  OKB OKC, "t.yaml:3:13", "holding" },
		{ "m:\n  addressing: modicon\n  fields:\n    target: {addr: 30001, fc: holding}\n    actual: {addr: 40001}\n"
		  "    status: {addr: 40002}\n" OKB
		  "  commands: {start: {addr: 40003, value: 8}, stop: {addr: 40003, value: 0x20}}\n",
		  "t.yaml:4:20", "modicon" },
		{ "m: [1, 2]\n", "t.yaml:1:4", "mapping" },
		{ "m:\n  fields: 3\n" OKB OKC, "t.yaml:2:11", "mapping" },
	};
	int nbad = 0;
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		struct regmap *m = NULL;
		struct acq_err err = { 0 };
		int rc = parse_text(bad[i].text, &m, &err);
		if (rc != -1 || !strstr(err.msg, bad[i].where) || !strstr(err.msg, bad[i].words) ||
		    !strstr(err.msg, "register map 'm'") || err.code != ACQ_E_CONFIG) {
			print_error("case %zu: rc %d, message \"%s\", want %s and \"%s\"\n", i, rc, err.msg,
				    bad[i].where, bad[i].words);
			nbad++;
		}
	}
	assert_int_equal(nbad, 0);
	/* a map that is not there, named by the referring node */
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	const char *t = "maps: {a: {}}\naxis: {map: b}\n";
	assert_int_equal(yc_load_string("t.yaml", t, strlen(t), &doc, &err), 0);
	struct regmap *m = NULL;
	struct yc_node *ref = yc_get(yc_get(yc_root(doc), "axis"), "map");
	assert_int_equal(regmap_parse(yc_get(yc_root(doc), "maps"), "b", ref, &m, &err), -1);
	assert_non_null(strstr(err.msg, "t.yaml:2:13"));
	assert_non_null(strstr(err.msg, "'b' is not defined"));
	yc_free(doc);
}

static void test_malformed_axis_config(void **state)
{
	(void)state;
	struct yc_doc *maps = load_src("config/bench-sim.yaml");
	static const struct bad bad[] = {
		{ "link: {type: serial}\naxes: {theta: {unit: 1, map: oriental_az}}\n", "t.yaml:1:14", "tcp" },
		{ "link: {type: tcp}\naxes: {theta: {unit: 1, map: oriental_az}}\n", "t.yaml:1:7", "port" },
		{ "link: {type: tcp, port: 502}\naxes: {theta: {unit: 300, map: oriental_az}}\n", "t.yaml:2:22", "unit" },
		{ "link: {type: tcp, port: 502}\naxes: {theta: {unit: 1, map: nope}}\n", "t.yaml:2:30", "nope" },
		{ "link: {type: tcp, port: 502}\naxes: {theta: {unit: 1, map: oriental_az, soft_min_deg: 10, "
		  "soft_max_deg: 5}}\n", "t.yaml:2:15", "soft_min_deg" },
		{ "link: {type: rtu, device: /dev/x, parity: maybe}\naxes: {theta: {unit: 1, map: oriental_az}}\n",
		  "t.yaml:1:43", "parity" },
		{ "link: {type: tcp, port: 502}\naxes: {theta: {unit: 1, map: oriental_az, speeed_dps: 3}}\n",
		  "t.yaml:2:43", "speeed_dps" },
		{ "link: {type: tcp, port: 502}\naxes: {}\n", "t.yaml:2:7", "empty" },
		{ "link: {type: tcp, port: 502}\naxes: {phi: {unit: 1, map: oriental_az, wrap_deg: 0.001}}\n",
		  "t.yaml:2:51", "wrap_deg" },
		{ "axes: {theta: {unit: 1, map: oriental_az}}\n", "t.yaml:1:1", "link" },
		{ "link: {type: tcp, port: 502}\nresponse_timeout_ms: -5\naxes: {theta: {unit: 1, map: oriental_az}}\n",
		  "t.yaml:2:22", "response_timeout_ms" },
	};
	int nbad = 0;
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		struct yc_doc *doc = NULL;
		struct acq_err err = { 0 };
		assert_int_equal(yc_load_string("t.yaml", bad[i].text, strlen(bad[i].text), &doc, &err), 0);
		struct axis_cfg *cfg[2];
		int n = 7;
		int rc = axis_arm_parse(yc_root(doc), maps_of(maps), "laser_arm", cfg, 2, &n, &err);
		if (rc != -1 || !strstr(err.msg, bad[i].where) || !strstr(err.msg, bad[i].words) || n != 0) {
			print_error("case %zu: rc %d, message \"%s\", want %s and \"%s\"\n", i, rc, err.msg,
				    bad[i].where, bad[i].words);
			nbad++;
		}
		yc_free(doc);
	}
	assert_int_equal(nbad, 0);
	yc_free(maps);
}

int main(void)
{
	const char *s = getenv("ACQ_SEED");
	rng = s ? strtoull(s, NULL, 10) * 2654435761u + 1 : 1;
	printf("test_regmap: seed %s\n", s ? s : "1");
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_shipped_az_map),
		cmocka_unit_test(test_shipped_real_config),
		cmocka_unit_test(test_encoding_against_reference),
		cmocka_unit_test(test_scale_offset_sign),
		cmocka_unit_test(test_addressing),
		cmocka_unit_test(test_malformed_maps),
		cmocka_unit_test(test_malformed_axis_config),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
