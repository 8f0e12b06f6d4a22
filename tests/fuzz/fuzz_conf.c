/* Fuzz target: the configuration loader (YAML → every section's validation), with and without --sim
 * overrides. Must never crash; a failure must carry a message. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/conf.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	static const struct conf_sim sim = { .laser_arm_port = 1502, .detector_arm_port = 1503,
					     .laser_device = "/dev/pts/3", .spectro_socket = "/tmp/s.sock" };
	for (int pass = 0; pass < 2; pass++) {
		struct conf *c = NULL;
		struct acq_err err = { 0 };
		if (conf_load_text("fuzz.yaml", (const char *)data, size, pass ? &sim : NULL, &c, &err)) {
			if (c || !err.msg[0])
				abort();
		} else {
			if (!c || !c->d.database || !c->d.socket_path)
				abort();
			conf_free(c);
		}
	}
	return 0;
}
