/* Fuzz target: the protocol's input path — framing in input-chosen chunk sizes, request parsing and
 * validation, and formatting the reply, exactly as the server does for each line. Must never crash. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "proto/proto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct proto_lines pl;
	proto_lines_init(&pl);
	size_t off = 0;
	/* The first byte picks the chunk size, so splits inside lines and escapes are explored. */
	size_t chunk = size ? 1 + data[0] % 97 : 1;
	while (off < size) {
		size_t n = size - off < chunk ? size - off : chunk;
		if (proto_lines_feed(&pl, (const char *)data + off, n))
			break;
		off += n;
		char *line;
		size_t len;
		int k;
		while ((k = proto_lines_next(&pl, &line, &len)) != PROTO_LINE_NONE) {
			if (k == PROTO_LINE_TOO_LONG) {
				free(proto_reply_err(NULL, PROTO_E_TOO_LONG, "too long"));
				continue;
			}
			struct proto_req req;
			const char *code;
			struct acq_err err = { 0 };
			char *reply = proto_req_parse(line, len, &req, &code, &err)
					      ? proto_reply_err(req.id, code, err.msg)
					      : proto_reply_ok(req.id, json_pack("{s:s}", "cmd", req.cmd));
			if (!reply || reply[strlen(reply) - 1] != '\n' || strchr(reply, '\n') != reply + strlen(reply) - 1)
				abort(); /* a reply is always exactly one line */
			free(reply);
			proto_req_free(&req);
		}
	}
	proto_lines_free(&pl);
	return 0;
}
