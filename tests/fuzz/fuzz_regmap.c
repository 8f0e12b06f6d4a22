/* Fuzz target: the register-map and axis-config loaders (drivers/regmap.c, drivers/axis_modbus_cfg.c) on arbitrary
 * YAML, then encode/decode through every field a valid map defines. Must never crash or leak. */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "config/yconf.h"
#include "drivers/axis_modbus.h"
#include "drivers/regmap.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	if (yc_load_string("fuzz.yaml", (const char *)data, size, &doc, &err))
		return 0;
	struct yc_node *root = yc_root(doc);
	struct yc_node *maps = yc_get(root, "register_maps");
	if (maps && maps->type == YC_MAP) {
		for (size_t i = 0; i < maps->n; i++) {
			const char *name = maps->keys[i]->value;
			struct regmap *m = NULL;
			if (!name || regmap_parse(maps, name, maps->keys[i], &m, &err))
				continue;
			for (int f = 0; f < RM__NFIELDS; f++) {
				if (!m->f[f].present)
					continue;
				uint16_t regs[2] = { 0x1234, 0xABCD };
				double vals[] = { 0, -1, 1e9, -1e9, 12.345, (double)size };
				for (size_t k = 0; k < sizeof vals / sizeof vals[0]; k++)
					if (regmap_encode(&m->f[f], vals[k], regs, &err) == 0)
						(void)regmap_decode(&m->f[f], regs);
				(void)regmap_decode_raw(&m->f[f], regs);
			}
			regmap_free(m);
		}
	}
	struct yc_node *arm = yc_get(root, "arm");
	if (arm) {
		struct axis_cfg *cfg[2];
		int n = 0;
		if (axis_arm_parse(arm, maps, "detector_arm", cfg, 2, &n, &err) == 0)
			for (int i = 0; i < n; i++) {
				double lo, hi;
				axis_cfg_limits(cfg[i], &lo, &hi);
				axis_cfg_free(cfg[i]);
			}
	}
	yc_free(doc);
	return 0;
}
