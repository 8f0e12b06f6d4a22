/* Unit tests for proto/proto.c: framing with the line bound, request validation codes, reply formats. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <time.h>
#include <cmocka.h>

#include "proto/ctl.h"
#include "proto/proto.h"

static void test_framing(void **state)
{
	(void)state;
	struct proto_lines pl;
	proto_lines_init(&pl);
	char *line;
	size_t len;
	assert_int_equal(proto_lines_feed(&pl, "{\"a\":1}\r\n{\"b\"", 13), 0);
	assert_int_equal(proto_lines_next(&pl, &line, &len), PROTO_LINE_OK);
	assert_string_equal(line, "{\"a\":1}");
	assert_int_equal(len, 7);
	assert_int_equal(proto_lines_next(&pl, &line, &len), PROTO_LINE_NONE);
	assert_int_equal(proto_lines_feed(&pl, ":2}\n", 4), 0);
	assert_int_equal(proto_lines_next(&pl, &line, &len), PROTO_LINE_OK);
	assert_string_equal(line, "{\"b\":2}");
	/* An oversized line is reported once, as soon as it passes the bound, and the next line is intact. */
	char *big = malloc(PROTO_MAX_LINE + 10);
	memset(big, 'x', PROTO_MAX_LINE + 10);
	assert_int_equal(proto_lines_feed(&pl, big, PROTO_MAX_LINE + 10), 0);
	assert_int_equal(proto_lines_next(&pl, &line, &len), PROTO_LINE_TOO_LONG);
	assert_int_equal(proto_lines_next(&pl, &line, &len), PROTO_LINE_NONE);
	assert_int_equal(proto_lines_feed(&pl, big, 1000), 0);
	assert_int_equal(proto_lines_next(&pl, &line, &len), PROTO_LINE_NONE);
	assert_int_equal(proto_lines_feed(&pl, "tail\nok\n", 8), 0);
	assert_int_equal(proto_lines_next(&pl, &line, &len), PROTO_LINE_OK);
	assert_string_equal(line, "ok");
	/* Exactly at the bound is accepted. */
	big[PROTO_MAX_LINE] = '\n';
	assert_int_equal(proto_lines_feed(&pl, big, PROTO_MAX_LINE + 1), 0);
	assert_int_equal(proto_lines_next(&pl, &line, &len), PROTO_LINE_OK);
	assert_int_equal(len, PROTO_MAX_LINE);
	free(big);
	proto_lines_free(&pl);
}

static const char *parse_code(const char *text, json_t **id_out)
{
	struct proto_req req;
	const char *code = NULL;
	struct acq_err err = { 0 };
	int rc = proto_req_parse(text, strlen(text), &req, &code, &err);
	if (id_out)
		*id_out = req.id ? json_incref(req.id) : NULL;
	proto_req_free(&req);
	if (rc == 0)
		assert_null(code);
	else
		assert_true(err.msg[0] != 0);
	return rc == 0 ? "ok" : code;
}

static void test_validation(void **state)
{
	(void)state;
	assert_string_equal(parse_code("{\"cmd\":\"status\"}", NULL), "ok");
	assert_string_equal(parse_code("{\"cmd\":\"status\",\"id\":\"x\"}", NULL), "ok");
	assert_string_equal(parse_code("not json", NULL), PROTO_E_PARSE);
	assert_string_equal(parse_code("", NULL), PROTO_E_PARSE);
	assert_string_equal(parse_code("[1,2]", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"id\":1}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":5}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"status\",\"id\":[1]}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"status\",\"cmd\":\"move\"}", NULL), PROTO_E_PARSE);
	assert_string_equal(parse_code("{\"cmd\":\"frobnicate\"}", NULL), PROTO_E_UNKNOWN);
	/* jansson refuses \\u0000 unless asked (JSON_ALLOW_NUL): a NUL never reaches a command. */
	assert_string_equal(parse_code("{\"cmd\":\"status\\u0000x\"}", NULL), PROTO_E_PARSE);
	assert_string_equal(parse_code("{\"cmd\":\"export\",\"sweep\":1,\"path\":\"a\\u0000b\"}", NULL), PROTO_E_PARSE);
	{ /* said in the client's words, not jansson's flag name (JSON_ALLOW_NUL) */
		struct proto_req req;
		const char *code = NULL;
		struct acq_err err = { 0 };
		static const char nul[] = "{\"cmd\":\"status\\u0000x\"}";
		assert_int_equal(proto_req_parse(nul, strlen(nul), &req, &code, &err), -1);
		proto_req_free(&req);
		assert_string_equal(err.msg, "a NUL character (\\u0000) is not allowed in a request, at column 22");
	}
	assert_string_equal(parse_code("{\"cmd\":\"status\",\"extra\":1}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"move\",\"laser_theta\":\"10\"}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"move\",\"laser_theta\":1e9}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"move\",\"laser_theta\":10}", NULL), "ok"); /* the old name */
	assert_string_equal(parse_code("{\"cmd\":\"move\",\"laser.theta\":10,\"detector.phi\":-20}", NULL), "ok");
	assert_string_equal(parse_code("{\"cmd\":\"move\",\"detector.phi\":1e9}", NULL), PROTO_E_INVALID);
	/* one axis under both names: refused, not silently one of them */
	assert_string_equal(parse_code("{\"cmd\":\"move\",\"laser.theta\":10,\"laser_theta\":11}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"sweep.show\"}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"sweep.show\",\"sweep\":1.5}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"sweep.show\",\"sweep\":3,\"points\":true}", NULL), "ok");
	assert_string_equal(parse_code("{\"cmd\":\"config\",\"text\":\"yes\"}", NULL), PROTO_E_INVALID);
	/* a one-line argument with a control character (a newline forging a log line, a terminal escape) is
	 * refused; a plan's text is many lines */
	assert_string_equal(parse_code("{\"cmd\":\"sweep.start\",\"plan\":\"name: a\\nx: 1\",\"name\":\"a\\nb\"}",
				       NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"sweep.start\",\"plan\":\"name: a\\nx: 1\",\"name\":\"a\\u001b[2J\"}",
				       NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"home\",\"axis\":\"laser.theta\\t\"}", NULL), PROTO_E_INVALID);
	assert_string_equal(parse_code("{\"cmd\":\"sweep.start\",\"plan\":\"name: a\\nx: 1\",\"name\":\"\u00e9t\u00e9 A3\"}",
				       NULL), "ok");
	/* The id survives a validation error so the reply can carry it. */
	json_t *id = NULL;
	assert_string_equal(parse_code("{\"cmd\":\"nope\",\"id\":42}", &id), PROTO_E_UNKNOWN);
	assert_non_null(id);
	assert_int_equal(json_integer_value(id), 42);
	json_decref(id);
}

static void test_formatting(void **state)
{
	(void)state;
	json_t *id = json_integer(7);
	char *l = proto_reply_ok(id, json_pack("{s:i}", "x", 3));
	assert_non_null(l);
	assert_int_equal(l[strlen(l) - 1], '\n');
	json_t *v = json_loads(l, 0, NULL);
	assert_true(json_is_true(json_object_get(v, "ok")));
	assert_int_equal(json_integer_value(json_object_get(v, "id")), 7);
	assert_int_equal(json_integer_value(json_object_get(v, "x")), 3);
	json_decref(v);
	free(l);
	l = proto_reply_err(NULL, PROTO_E_RANGE, "too far \"out\"\n");
	v = json_loads(l, 0, NULL);
	assert_non_null(v);
	assert_true(json_is_null(json_object_get(v, "id")));
	assert_true(json_is_false(json_object_get(v, "ok")));
	assert_string_equal(json_string_value(json_object_get(json_object_get(v, "error"), "code")), "range");
	assert_true(strchr(l, '\n') == l + strlen(l) - 1); /* the message's newline is escaped: one line */
	json_decref(v);
	free(l);
	l = proto_banner("1.2");
	v = json_loads(l, 0, NULL);
	assert_int_equal(json_integer_value(json_object_get(v, "protocol")), PROTO_VERSION);
	assert_string_equal(json_string_value(json_object_get(v, "version")), "1.2");
	json_decref(v);
	free(l);
	json_decref(id);
	struct acq_err e = { .code = ACQ_E_RANGE };
	assert_string_equal(proto_code_of(&e), "range");
	e.code = ACQ_E_UNSUPPORTED;
	assert_string_equal(proto_code_of(&e), "unavailable");
	e.code = ACQ_E_NOTFOUND;
	assert_string_equal(proto_code_of(&e), "not_found");
}

/* acqctl's readable values: times in local ISO 8601 (TZ fixed here), h:mm:ss, angles, units by key. */
static void test_ctl_values(void **state)
{
	(void)state;
	setenv("TZ", "Europe/Paris", 1);
	tzset();
	char buf[128];
	ctl_fmt_time(1796140105.205776, buf, sizeof buf);
	assert_string_equal(buf, "2026-12-01T16:48:25+01:00");
	ctl_fmt_time(0, buf, sizeof buf);
	assert_string_equal(buf, "-");
	ctl_fmt_dur(7322.4, buf, sizeof buf);
	assert_string_equal(buf, "2:02:02");
	ctl_fmt_dur(59.5, buf, sizeof buf);
	assert_string_equal(buf, "0:01:00");
	ctl_fmt_dur(2.345, buf, sizeof buf);
	assert_string_equal(buf, "2.35 s");
	ctl_fmt_dur(NAN, buf, sizeof buf);
	assert_string_equal(buf, "-");
	ctl_fmt_angle(44.990000000000002, buf, sizeof buf);
	assert_string_equal(buf, "44.99°");
	ctl_fmt_angle(-0.001, buf, sizeof buf);
	assert_string_equal(buf, "0.00°");
	json_t *v = json_real(12.5);
	ctl_fmt_value("integration_ms", v, buf, sizeof buf);
	assert_string_equal(buf, "12.5 ms");
	ctl_fmt_value("detector_phi", v, buf, sizeof buf);
	assert_string_equal(buf, "12.50°");
	ctl_fmt_value("laser.theta", v, buf, sizeof buf);
	assert_string_equal(buf, "12.50°");
	ctl_fmt_value("uptime_s", v, buf, sizeof buf);
	assert_string_equal(buf, "0:00:13");
	ctl_fmt_value("ratio", v, buf, sizeof buf);
	assert_string_equal(buf, "12.5");
	json_decref(v);
	v = json_pack("[f,f]", -90.0, 90.0);
	ctl_fmt_value("limits_deg", v, buf, sizeof buf);
	assert_string_equal(buf, "-90.00°, 90.00°");
	json_decref(v);
	v = json_true();
	ctl_fmt_value("auto_resume", v, buf, sizeof buf);
	assert_string_equal(buf, "yes");
	json_decref(v);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_framing),
		cmocka_unit_test(test_validation),
		cmocka_unit_test(test_formatting),
		cmocka_unit_test(test_ctl_values),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
