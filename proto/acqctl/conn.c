/* conn: acqctl's connection to acquisitiond — connect (waiting if asked), check the banner, one request and its
 * reply (with a descriptor passed along), see acqctl.h. */
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "proto/acqctl/acqctl.h"

double conn_mono(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

int conn_open(struct conn *c, struct acq_err *err)
{
	proto_lines_init(&c->pl);
	c->pl.max = PROTO_MAX_REPLY;
	c->banner = NULL;
	double deadline = conn_mono() + acqctl_o.wait_s;
	while ((c->fd = proto_client_connect(acqctl_o.sock, err)) < 0 && conn_mono() < deadline)
		usleep(100000);
	if (c->fd < 0)
		return -1;
	c->banner = proto_client_read(c->fd, &c->pl, acqctl_o.timeout_ms, err);
	if (!c->banner || json_integer_value(json_object_get(c->banner, "protocol")) != PROTO_VERSION) {
		/* A refusal before the banner ("too many clients", "not authorised") is a one-line error reply. */
		json_t *e = json_object_get(c->banner, "error");
		if (e)
			acq_errf(err, ACQ_E_STATE, "%s", json_string_value(json_object_get(e, "message")));
		else if (c->banner)
			acq_errf(err, ACQ_E_PROTO, "unsupported protocol version");
		return -1;
	}
	return 0;
}

void conn_close(struct conn *c)
{
	if (c->fd >= 0)
		close(c->fd);
	c->fd = -1;
	proto_lines_free(&c->pl);
	json_decref(c->banner);
	c->banner = NULL;
}

/* Send req (borrowed) and read its reply; passed receives a descriptor sent with it (NULL: none expected). */
json_t *conn_call(struct conn *c, json_t *req, int *passed, struct acq_err *err)
{
	char *line = json_dumps(req, JSON_COMPACT);
	if (!line) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		return NULL;
	}
	size_t n = strlen(line);
	line[n] = '\n'; /* json_dumps' NUL becomes the newline (the request is sent by length) */
	int rc = proto_write_all(c->fd, line, n + 1, err);
	free(line);
	if (rc) {
		/* The daemon may have refused us and closed: its reason is still to be read. */
		struct acq_err e2 = { 0 };
		json_t *why = proto_client_read_fd(c->fd, &c->pl, 1000, passed, &e2);
		if (why && json_is_false(json_object_get(why, "ok")))
			return why;
		json_decref(why);
		return NULL;
	}
	return proto_client_read_fd(c->fd, &c->pl, acqctl_o.timeout_ms, passed, err);
}
