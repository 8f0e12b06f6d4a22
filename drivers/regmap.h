/* regmap: a motor controller's Modbus register map read from the configuration
 * (`devices.register_maps.<name>`), and the conversion of engineering values (degrees, degrees per second)
 * to and from registers. The axis driver (client) and the simulator (server) use the same parsed map.
 *
 * Map layout (see config/bench-sim.yaml for the Oriental Motor AZ map, config/bench-real.yaml for a
 * Leadshine-like one):
 *   addressing: zero_based | one_based | modicon      (modicon: 4xxxx holding, 3xxxx input, 0xxxx coil)
 *   write: single | block       block: {start: A, count: N}   (block: the move fields go in one FC16)
 *   fields: {<name>: {addr, fc: holding|input, type: int16|uint16|int32|uint32|float32,
 *                     word_order: big|little, byte_swap: bool, scale, offset, sign: 1|-1, value}}
 *   status_bits: {ready, busy, move, in_position, alarm, homed, limit_pos, limit_neg, stall: bit number}
 *   commands: {start|home|stop|alarm_reset: {addr, fc: holding|coil, value, mode: level|pulse}}
 *   vendor, model: identity strings.
 * Conversion: counts = sign * scale * (value - offset), value = offset + counts / (sign * scale). */
#ifndef REGMAP_H
#define REGMAP_H

#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "config/yconf.h"

enum regmap_space { REGMAP_HOLDING = 0, REGMAP_INPUT, REGMAP_COIL };
enum regmap_type { REGMAP_INT16 = 0, REGMAP_UINT16, REGMAP_INT32, REGMAP_UINT32, REGMAP_FLOAT32 };

/* Fields a map may define. Move fields (written with a move): target .. trigger. */
enum regmap_field_id {
	RM_TARGET = 0,  /* target position, degrees (required) */
	RM_SPEED,       /* running speed, degrees/s */
	RM_ACCEL,       /* acceleration, degrees/s² */
	RM_DECEL,       /* deceleration, degrees/s² */
	RM_OP_TYPE,     /* operation type (constant `value`, e.g. 1 = absolute) */
	RM_OP_DATA,     /* operation data number (constant) */
	RM_CURRENT,     /* operating current (constant) */
	RM_TRIGGER,     /* block trigger: writing it starts the move (constant) */
	RM_ACTUAL,      /* feedback (actual) position, degrees (required) */
	RM_COMMAND_POS, /* command position, degrees */
	RM_STATUS,      /* status word whose bits are status_bits (required) */
	RM_ALARM_CODE,  /* present alarm code */
	RM_SERIAL,      /* serial number (integer register) */
	RM_FIRMWARE,    /* firmware version (integer register) */
	RM__NFIELDS
};
#define RM_MOVE_FIELDS_END (RM_TRIGGER + 1)

enum regmap_bit {
	RM_BIT_READY = 0, RM_BIT_BUSY, RM_BIT_MOVE, RM_BIT_IN_POS, RM_BIT_ALARM, RM_BIT_HOMED,
	RM_BIT_LIMIT_POS, RM_BIT_LIMIT_NEG, RM_BIT_STALL, RM__NBITS
};

enum regmap_cmd_id { RM_CMD_START = 0, RM_CMD_HOME, RM_CMD_STOP, RM_CMD_ALARM_RESET, RM__NCMDS };

struct regmap_field {
	bool present;
	int space;          /* enum regmap_space (holding or input) */
	uint16_t addr;      /* 0-based protocol address */
	int type;           /* enum regmap_type */
	bool word_swap;     /* 32-bit: low word first (word_order: little) */
	bool byte_swap;     /* bytes swapped inside each word */
	double scale;       /* counts per unit */
	double offset;      /* unit offset */
	int sign;           /* +1 or -1 */
	bool has_value;     /* a constant written with each move */
	double value;
};

struct regmap_cmd {
	bool present;
	int space;          /* REGMAP_HOLDING (FC06) or REGMAP_COIL (FC05) */
	uint16_t addr;
	uint16_t value;     /* register value (coil: 1) */
	bool level;         /* level: bits stay until the driver clears them; pulse: the device clears */
};

struct regmap {
	char name[64];
	char vendor[64], model[64];
	bool block;                    /* move fields written together with one FC16 */
	uint16_t block_start, block_count;
	struct regmap_field f[RM__NFIELDS];
	int bit[RM__NBITS];            /* bit number in the status word, -1 when absent */
	struct regmap_cmd cmd[RM__NCMDS];
};

/* Parse map `name` from the `register_maps` mapping (ref: the node naming it, for messages; may be NULL).
 * Allocates *out. 0 or -1 with a file:line:col message. */
int regmap_parse(struct yc_node *maps, const char *name, const struct yc_node *ref, struct regmap **out,
		 struct acq_err *err);
/* Free a map (NULL is fine). */
void regmap_free(struct regmap *m);
/* Stable name of a field or command (for messages and the config keys). */
const char *regmap_field_name(int id);
const char *regmap_cmd_name(int id);
/* Registers a field occupies (1 or 2). */
int regmap_width(const struct regmap_field *f);
/* Engineering value → registers (regs[0..width-1]); -1 with ACQ_E_RANGE when it does not fit the type. */
int regmap_encode(const struct regmap_field *f, double value, uint16_t *regs, struct acq_err *err);
/* Raw integer (no scale) → registers, same checks. */
int regmap_encode_raw(const struct regmap_field *f, double raw, uint16_t *regs, struct acq_err *err);
/* Registers → raw count (no scale; float32 as is). */
double regmap_decode_raw(const struct regmap_field *f, const uint16_t *regs);
/* Registers → engineering value. */
double regmap_decode(const struct regmap_field *f, const uint16_t *regs);

#endif
