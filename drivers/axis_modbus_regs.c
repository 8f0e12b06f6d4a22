/* axis_modbus_regs: the register map's fields and commands on the wire: read a field, send a command (and
 * clear a level command later), write a move. */
#include <string.h>

#include "drivers/axis_modbus_int.h"

int mb_reg_read_field(struct axis_dev *ax, int id, double *value, double *raw, struct acq_err *err)
{
	const struct regmap_field *f = &ax->cfg->map->f[id];
	uint16_t regs[2];
	if (mb_link_read(ax, f->space, f->addr, regmap_width(f), regs, regmap_field_name(id), err))
		return -1;
	if (value)
		*value = regmap_decode(f, regs);
	if (raw)
		*raw = regmap_decode_raw(f, regs);
	return 0;
}

int mb_reg_send_cmd(struct axis_dev *ax, int id, bool clear_now, struct acq_err *err)
{
	const struct regmap_cmd *c = &ax->cfg->map->cmd[id];
	if (!c->present)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: register map '%s' has no `%s` command", ax->cfg->name,
				ax->cfg->map->name, regmap_cmd_name(id));
	for (int pass = 0; pass < (c->level && clear_now ? 2 : 1); pass++) {
		uint16_t v = pass ? 0 : c->value;
		if (c->space == REGMAP_COIL) {
			if (mb_link_ready(ax, err))
				return -1;
			if (modbus_write_bit(ax->link->ctx, c->addr, v ? 1 : 0) != 1)
				return mb_link_fail(ax, regmap_cmd_name(id), c->addr, err);
		} else if (mb_link_write(ax, c->addr, 1, &v, regmap_cmd_name(id), err)) {
			return -1;
		}
	}
	if (c->level && !clear_now)
		ax->clear_cmd = id;
	return 0;
}

/* Clear a level-style command bit set by the previous call (the driver owns clearing it). */
int mb_reg_clear_pending(struct axis_dev *ax, struct acq_err *err)
{
	if (ax->clear_cmd < 0)
		return 0;
	const struct regmap_cmd *c = &ax->cfg->map->cmd[ax->clear_cmd];
	int rc;
	if (mb_link_ready(ax, err))
		return -1;
	if (c->space == REGMAP_COIL)
		rc = modbus_write_bit(ax->link->ctx, c->addr, 0) == 1 ? 0 : mb_link_fail(ax, "clearing command", c->addr, err);
	else {
		uint16_t z = 0;
		rc = mb_link_write(ax, c->addr, 1, &z, "clearing command", err);
	}
	if (rc == 0)
		ax->clear_cmd = -1;
	return rc;
}

/* Write the move fields (one FC16 block or one write per field), then the start command if any. */
int mb_reg_send_move(struct axis_dev *ax, double target, struct acq_err *err)
{
	const struct axis_cfg *c = ax->cfg;
	const struct regmap *m = c->map;
	double values[RM_MOVE_FIELDS_END] = { [RM_TARGET] = target, [RM_SPEED] = c->speed, [RM_ACCEL] = c->accel,
					      [RM_DECEL] = c->decel };
	uint16_t block[128] = { 0 };
	for (int i = 0; i < RM_MOVE_FIELDS_END; i++) {
		const struct regmap_field *f = &m->f[i];
		if (!f->present)
			continue;
		uint16_t regs[2];
		int rc = f->has_value ? regmap_encode_raw(f, f->value, regs, err) : regmap_encode(f, values[i], regs, err);
		if (rc)
			return acq_err_prefix(err, "%s: %s: ", c->name, regmap_field_name(i));
		if (m->block) {
			memcpy(block + (f->addr - m->block_start), regs, sizeof(uint16_t) * (size_t)regmap_width(f));
		} else if (i != RM_TRIGGER && mb_link_write(ax, f->addr, regmap_width(f), regs, regmap_field_name(i), err)) {
			return -1;
		}
	}
	if (m->block) {
		if (mb_link_write(ax, m->block_start, m->block_count, block, "move block", err))
			return -1;
	} else if (m->f[RM_TRIGGER].present) {
		const struct regmap_field *f = &m->f[RM_TRIGGER];
		uint16_t regs[2];
		if (regmap_encode_raw(f, f->value, regs, err) ||
		    mb_link_write(ax, f->addr, regmap_width(f), regs, "trigger", err))
			return -1;
	}
	if (m->cmd[RM_CMD_START].present)
		return mb_reg_send_cmd(ax, RM_CMD_START, false, err);
	return 0;
}

bool mb_reg_bit(const struct regmap *m, uint32_t word, int b)
{
	return m->bit[b] >= 0 && (word >> m->bit[b]) & 1u;
}
