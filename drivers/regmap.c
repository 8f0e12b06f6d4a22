/* regmap: parse a controller register map from the configuration; encode and decode register values. */
#include "drivers/regmap.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const field_names[RM__NFIELDS] = {
	"target", "speed", "accel", "decel", "op_type", "op_data", "current", "trigger",
	"actual", "command_pos", "status", "alarm_code", "serial", "firmware",
};
static const char *const bit_names[RM__NBITS] = {
	"ready", "busy", "move", "in_position", "alarm", "homed", "limit_pos", "limit_neg", "stall",
};
static const char *const cmd_names[RM__NCMDS] = { "start", "home", "stop", "alarm_reset" };

const char *regmap_field_name(int id) { return id >= 0 && id < RM__NFIELDS ? field_names[id] : "?"; }
const char *regmap_cmd_name(int id) { return id >= 0 && id < RM__NCMDS ? cmd_names[id] : "?"; }

enum addressing { ADDR_ZERO, ADDR_ONE, ADDR_MODICON };

int regmap_width(const struct regmap_field *f)
{
	return f->type == REGMAP_INT16 || f->type == REGMAP_UINT16 ? 1 : 2;
}

/* Turn a configured address into a 0-based protocol address; with modicon numbering the leading digit
 * also gives the space (*space is checked against it, or set when fc was not given: *space < 0). */
static int resolve_addr(struct yc_node *spec, int addressing, long long a, int *space, uint16_t *out,
			struct acq_err *err)
{
	struct yc_node *an = yc_get(spec, "addr");
	if (addressing == ADDR_ONE) {
		if (a < 1 || a > 65536)
			return yc_errf(err, an, "1-based address %lld outside [1, 65536]", a);
		a -= 1;
	} else if (addressing == ADDR_MODICON) {
		int sp;
		long long base;
		if (a >= 400001 && a <= 465536) { sp = REGMAP_HOLDING; base = 400001; }
		else if (a >= 300001 && a <= 365536) { sp = REGMAP_INPUT; base = 300001; }
		else if (a >= 40001 && a <= 49999) { sp = REGMAP_HOLDING; base = 40001; }
		else if (a >= 30001 && a <= 39999) { sp = REGMAP_INPUT; base = 30001; }
		else if (a >= 1 && a <= 9999) { sp = REGMAP_COIL; base = 1; }
		else
			return yc_errf(err, an, "modicon address %lld: expected 0xxxx (coil), 3xxxx (input) or 4xxxx "
				       "(holding)", a);
		if (*space >= 0 && *space != sp)
			return yc_errf(err, an, "modicon address %lld names another register space than `fc`", a);
		*space = sp;
		a -= base;
	}
	if (a < 0 || a > 65535)
		return yc_errf(err, an, "address %lld outside [0, 65535]", a);
	*out = (uint16_t)a;
	return 0;
}

static int parse_space(struct yc_node *spec, bool allow_coil, int *space, struct acq_err *err)
{
	static const char *const spaces[] = { "holding", "input", "coil", NULL };
	int sp = -1;
	if (yc_enum(spec, "fc", false, spaces, &sp, err))
		return -1;
	if (sp == REGMAP_COIL && !allow_coil)
		return yc_errf(err, yc_get(spec, "fc"), "coils are only supported for commands");
	if (sp == REGMAP_INPUT && allow_coil)
		return yc_errf(err, yc_get(spec, "fc"), "a command cannot be written to an input register");
	*space = sp;
	return 0;
}

static int parse_field(struct yc_node *spec, int id, int addressing, struct regmap_field *f, struct acq_err *err)
{
	static const char *const types[] = { "int16", "uint16", "int32", "uint32", "float32", NULL };
	static const char *const orders[] = { "big", "little", NULL };
	char what[64];
	snprintf(what, sizeof what, "field %s", field_names[id]);
	if (yc_expect_map(spec, what, err))
		return -1;
	long long addr = 0, sign = 1;
	int space = -1, order = 0, type = REGMAP_UINT16;
	memset(f, 0, sizeof *f);
	f->scale = 1.0;
	if (yc_int(spec, "addr", true, 0, 465536, &addr, err) || parse_space(spec, false, &space, err) ||
	    yc_enum(spec, "type", false, types, &type, err) || yc_enum(spec, "word_order", false, orders, &order, err) ||
	    yc_bool(spec, "byte_swap", false, &f->byte_swap, err) ||
	    yc_double(spec, "scale", false, -1e9, 1e9, &f->scale, err) ||
	    yc_double(spec, "offset", false, -1e6, 1e6, &f->offset, err) ||
	    yc_int(spec, "sign", false, -1, 1, &sign, err))
		return -1;
	if (yc_get(spec, "value")) {
		if (yc_double(spec, "value", true, -4294967296.0, 4294967296.0, &f->value, err))
			return -1;
		f->has_value = true;
	}
	if (sign == 0)
		return yc_errf(err, yc_get(spec, "sign"), "%s: sign must be 1 or -1", what);
	if (f->scale == 0)
		return yc_errf(err, yc_get(spec, "scale"), "%s: scale must not be 0", what);
	if (resolve_addr(spec, addressing, addr, &space, &f->addr, err))
		return -1;
	f->space = space < 0 ? REGMAP_HOLDING : space;
	f->type = type;
	f->word_swap = order == 1;
	f->sign = (int)sign;
	f->present = true;
	if (regmap_width(f) == 2 && f->addr == 65535)
		return yc_errf(err, yc_get(spec, "addr"), "%s: a 32-bit field cannot start at 65535", what);
	bool writes = id < RM_MOVE_FIELDS_END;
	if (writes && f->space != REGMAP_HOLDING)
		return yc_errf(err, spec, "%s is written, so it must be a holding register", what);
	if ((id == RM_OP_TYPE || id == RM_OP_DATA || id == RM_CURRENT || id == RM_TRIGGER) && !f->has_value)
		return yc_errf(err, spec, "%s needs a constant `value`", what);
	if (f->has_value && !writes)
		return yc_errf(err, yc_get(spec, "value"), "%s is read, a constant `value` makes no sense", what);
	if (f->has_value) {
		uint16_t tmp[2];
		if (regmap_encode_raw(f, f->value, tmp, err))
			return yc_errf(err, yc_get(spec, "value"), "%s: value %g does not fit type %s", what, f->value,
				       types[type]);
	}
	return yc_check_unknown(spec, what, err);
}

static int parse_cmd(struct yc_node *spec, int id, int addressing, struct regmap_cmd *c, struct acq_err *err)
{
	static const char *const modes[] = { "level", "pulse", NULL };
	char what[64];
	snprintf(what, sizeof what, "command %s", cmd_names[id]);
	if (yc_expect_map(spec, what, err))
		return -1;
	long long addr = 0, value = 1;
	int space = -1, mode = 1;
	if (yc_int(spec, "addr", true, 0, 465536, &addr, err) || parse_space(spec, true, &space, err) ||
	    yc_int(spec, "value", space != REGMAP_COIL, 0, 65535, &value, err) ||
	    yc_enum(spec, "mode", false, modes, &mode, err))
		return -1;
	if (resolve_addr(spec, addressing, addr, &space, &c->addr, err))
		return -1;
	c->space = space < 0 ? REGMAP_HOLDING : space;
	if (c->space == REGMAP_INPUT)
		return yc_errf(err, spec, "%s: a command cannot be written to an input register", what);
	if (c->space == REGMAP_COIL && value > 1)
		return yc_errf(err, yc_get(spec, "value"), "%s: a coil value is 0 or 1", what);
	if (value == 0)
		return yc_errf(err, yc_get(spec, "value"), "%s: value 0 cannot be told from \"no command\"", what);
	c->value = (uint16_t)value;
	c->level = mode == 0;
	c->present = true;
	return yc_check_unknown(spec, what, err);
}

static int copy_str(struct yc_node *map, const char *key, char *dst, size_t len, struct acq_err *err)
{
	const char *s = NULL;
	if (yc_string(map, key, false, &s, err))
		return -1;
	if (s)
		snprintf(dst, len, "%s", s);
	return 0;
}

static int parse_map(struct yc_node *node, struct regmap *m, struct acq_err *err)
{
	static const char *const addrs[] = { "zero_based", "one_based", "modicon", NULL };
	static const char *const writes[] = { "single", "block", NULL };
	int addressing = ADDR_ZERO, wmode = 0;
	if (yc_expect_map(node, "register map", err) || copy_str(node, "vendor", m->vendor, sizeof m->vendor, err) ||
	    copy_str(node, "model", m->model, sizeof m->model, err) ||
	    yc_enum(node, "addressing", false, addrs, &addressing, err) ||
	    yc_enum(node, "write", false, writes, &wmode, err))
		return -1;
	m->block = wmode == 1;
	struct yc_node *blk = yc_get(node, "block");
	if (m->block) {
		long long start = 0, count = 0;
		if (!blk)
			return yc_errf(err, yc_get(node, "write"), "write: block needs `block: {start, count}`");
		if (yc_expect_map(blk, "block", err) || yc_int(blk, "start", true, 0, 465536, &start, err) ||
		    yc_int(blk, "count", true, 1, 123, &count, err) || yc_check_unknown(blk, "block", err))
			return -1;
		uint16_t a;
		/* resolve_addr reports on the key `addr`; block uses `start`: check bounds here. */
		if (addressing == ADDR_ONE)
			start -= 1;
		else if (addressing == ADDR_MODICON)
			start -= start >= 400001 ? 400001 : 40001;
		if (start < 0 || start + count > 65536)
			return yc_errf(err, blk, "block [%lld, +%lld) outside the address space", start, count);
		a = (uint16_t)start;
		m->block_start = a;
		m->block_count = (uint16_t)count;
	} else if (blk) {
		return yc_errf(err, blk, "`block` given but write is not `block`");
	}

	struct yc_node *fields = yc_get(node, "fields");
	if (!fields)
		return yc_errf(err, node, "register map has no `fields`");
	if (yc_expect_map(fields, "fields", err))
		return -1;
	for (int i = 0; i < RM__NFIELDS; i++) {
		struct yc_node *spec = yc_get(fields, field_names[i]);
		if (spec && parse_field(spec, i, addressing, &m->f[i], err))
			return -1;
	}
	if (yc_check_unknown(fields, "fields", err))
		return -1;
	static const int required[] = { RM_TARGET, RM_ACTUAL, RM_STATUS };
	for (size_t i = 0; i < sizeof required / sizeof required[0]; i++)
		if (!m->f[required[i]].present)
			return yc_errf(err, fields, "fields: `%s` is required", field_names[required[i]]);
	if (m->f[RM_STATUS].type == REGMAP_FLOAT32)
		return yc_errf(err, yc_get(fields, "status"), "status word cannot be float32");
	/* Block writes: every move field lies inside the block, and none overlap. */
	if (m->block) {
		uint32_t used[8] = { 0 }; /* 123 registers max → 4 words would do; keep it simple */
		for (int i = 0; i < RM_MOVE_FIELDS_END; i++) {
			const struct regmap_field *f = &m->f[i];
			if (!f->present)
				continue;
			int w = regmap_width(f);
			if (f->addr < m->block_start || f->addr + w > m->block_start + m->block_count)
				return yc_errf(err, yc_get(fields, field_names[i]), "field %s (0x%04x) lies outside the "
					       "write block [0x%04x, 0x%04x]", field_names[i], f->addr, m->block_start,
					       m->block_start + m->block_count - 1);
			for (int k = 0; k < w; k++) {
				int off = f->addr + k - m->block_start;
				if (used[off / 32] & (1u << (off % 32)))
					return yc_errf(err, yc_get(fields, field_names[i]), "field %s overlaps another "
						       "field of the write block", field_names[i]);
				used[off / 32] |= 1u << (off % 32);
			}
		}
		if (!m->f[RM_TRIGGER].present && !yc_get(yc_get(node, "commands"), "start"))
			return yc_errf(err, node, "write: block needs a `trigger` field or a `start` command");
	}

	for (int i = 0; i < RM__NBITS; i++)
		m->bit[i] = -1;
	struct yc_node *bits = yc_get(node, "status_bits");
	if (!bits)
		return yc_errf(err, node, "register map has no `status_bits`");
	if (yc_expect_map(bits, "status_bits", err))
		return -1;
	int maxbit = regmap_width(&m->f[RM_STATUS]) * 16 - 1;
	for (int i = 0; i < RM__NBITS; i++) {
		long long b = -1;
		if (yc_int(bits, bit_names[i], false, 0, maxbit, &b, err))
			return -1;
		m->bit[i] = (int)b;
	}
	if (yc_check_unknown(bits, "status_bits", err))
		return -1;
	if (m->bit[RM_BIT_BUSY] < 0 && m->bit[RM_BIT_MOVE] < 0)
		return yc_errf(err, bits, "status_bits: `busy` or `move` is required");
	if (m->bit[RM_BIT_ALARM] < 0)
		return yc_errf(err, bits, "status_bits: `alarm` is required");

	struct yc_node *cmds = yc_get(node, "commands");
	if (cmds) {
		if (yc_expect_map(cmds, "commands", err))
			return -1;
		for (int i = 0; i < RM__NCMDS; i++) {
			struct yc_node *spec = yc_get(cmds, cmd_names[i]);
			if (spec && parse_cmd(spec, i, addressing, &m->cmd[i], err))
				return -1;
		}
		if (yc_check_unknown(cmds, "commands", err))
			return -1;
	}
	if (!m->block && !m->cmd[RM_CMD_START].present && !m->f[RM_TRIGGER].present)
		return yc_errf(err, node, "write: single needs a `start` command or a `trigger` field");
	if (!m->cmd[RM_CMD_STOP].present)
		return yc_errf(err, cmds ? cmds : node, "commands: `stop` is required");
	return yc_check_unknown(node, "register map", err);
}

int regmap_parse(struct yc_node *maps, const char *name, const struct yc_node *ref, struct regmap **out,
		 struct acq_err *err)
{
	if (!maps)
		return yc_errf(err, ref, "register map '%s': no `register_maps` section", name);
	if (yc_expect_map(maps, "register_maps", err))
		return -1;
	/* Look the name up by hand: yc_get() would remember the name pointer, which belongs to another
	 * document (the axis's) that may be freed before this one. */
	struct yc_node *node = NULL;
	for (size_t i = 0; i < maps->n; i++)
		if (maps->keys[i]->value && !strcmp(maps->keys[i]->value, name)) {
			node = maps->items[i];
			maps->used[i] = true;
			break;
		}
	if (!node)
		return yc_errf(err, ref, "register map '%s' is not defined in register_maps", name);
	struct regmap *m = calloc(1, sizeof *m);
	if (!m)
		return acq_errf(err, ACQ_E_NOMEM, "register map '%s': out of memory", name);
	snprintf(m->name, sizeof m->name, "%s", name);
	if (parse_map(node, m, err)) {
		acq_err_prefix(err, "register map '%s': ", name);
		free(m);
		return -1;
	}
	*out = m;
	return 0;
}

void regmap_free(struct regmap *m)
{
	free(m);
}

static uint16_t bswap16(uint16_t v)
{
	return (uint16_t)((v >> 8) | (v << 8));
}

static void put32(const struct regmap_field *f, uint32_t u, uint16_t *regs)
{
	uint16_t hi = (uint16_t)(u >> 16), lo = (uint16_t)u;
	if (f->byte_swap) {
		hi = bswap16(hi);
		lo = bswap16(lo);
	}
	regs[0] = f->word_swap ? lo : hi;
	regs[1] = f->word_swap ? hi : lo;
}

static uint32_t get32(const struct regmap_field *f, const uint16_t *regs)
{
	uint16_t hi = f->word_swap ? regs[1] : regs[0], lo = f->word_swap ? regs[0] : regs[1];
	if (f->byte_swap) {
		hi = bswap16(hi);
		lo = bswap16(lo);
	}
	return (uint32_t)hi << 16 | lo;
}

int regmap_encode_raw(const struct regmap_field *f, double raw, uint16_t *regs, struct acq_err *err)
{
	if (!isfinite(raw))
		return acq_errf(err, ACQ_E_RANGE, "field value is not finite");
	if (f->type == REGMAP_FLOAT32) {
		if (fabs(raw) > 3.4e38)
			return acq_errf(err, ACQ_E_RANGE, "value %g does not fit float32", raw);
		float fl = (float)raw;
		uint32_t u;
		memcpy(&u, &fl, sizeof u);
		put32(f, u, regs);
		return 0;
	}
	double r = nearbyint(raw);
	static const double lo[] = { -32768.0, 0.0, -2147483648.0, 0.0 }, hi[] = { 32767.0, 65535.0, 2147483647.0,
										4294967295.0 };
	if (r < lo[f->type] || r > hi[f->type])
		return acq_errf(err, ACQ_E_RANGE, "value %g does not fit the register type (range [%g, %g])", r,
				lo[f->type], hi[f->type]);
	if (f->type == REGMAP_INT16 || f->type == REGMAP_UINT16) {
		uint16_t v = (uint16_t)(int32_t)r;
		regs[0] = f->byte_swap ? bswap16(v) : v;
		return 0;
	}
	uint32_t u = f->type == REGMAP_INT32 ? (uint32_t)(int32_t)r : (uint32_t)r;
	put32(f, u, regs);
	return 0;
}

int regmap_encode(const struct regmap_field *f, double value, uint16_t *regs, struct acq_err *err)
{
	return regmap_encode_raw(f, (double)f->sign * f->scale * (value - f->offset), regs, err);
}

double regmap_decode_raw(const struct regmap_field *f, const uint16_t *regs)
{
	switch (f->type) {
	case REGMAP_INT16: return (double)(int16_t)(f->byte_swap ? bswap16(regs[0]) : regs[0]);
	case REGMAP_UINT16: return (double)(f->byte_swap ? bswap16(regs[0]) : regs[0]);
	case REGMAP_INT32: return (double)(int32_t)get32(f, regs);
	case REGMAP_UINT32: return (double)get32(f, regs);
	default: {
		uint32_t u = get32(f, regs);
		float fl;
		memcpy(&fl, &u, sizeof fl);
		return (double)fl;
	}
	}
}

double regmap_decode(const struct regmap_field *f, const uint16_t *regs)
{
	return f->offset + regmap_decode_raw(f, regs) / ((double)f->sign * f->scale);
}
