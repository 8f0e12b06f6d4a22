/* axis_modbus_link: one Modbus connection over TCP or RTU (libmodbus), shared by the axes behind it (counted
 * references; the libmodbus context is made and freed here only), and its bounded register transactions; a
 * failure is classified and a broken link marked down (no retry here). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>

#include "drivers/axis_modbus_int.h"

struct axis_link *mb_link_new(const struct axis_cfg *c)
{
	struct axis_link *l = calloc(1, sizeof *l);
	if (!l)
		return NULL;
	l->refs = 1;
	if (c->link.type == AXIS_LINK_TCP)
		snprintf(l->where, sizeof l->where, "%s:%d", c->link.host, c->link.port);
	else
		snprintf(l->where, sizeof l->where, "%s", c->link.device);
	return l;
}

struct axis_link *mb_link_ref(struct axis_link *l)
{
	l->refs++;
	return l;
}

void mb_link_unref(struct axis_link *l)
{
	if (!l || --l->refs > 0)
		return;
	if (l->ctx) {
		modbus_close(l->ctx);
		modbus_free(l->ctx);
	}
	free(l);
}

int mb_link_connect(struct axis_link *l, const struct axis_cfg *c, struct acq_err *err)
{
	if (l->ctx) {
		modbus_close(l->ctx);
		modbus_free(l->ctx);
		l->ctx = NULL;
	}
	l->up = false;
	const struct axis_link_cfg *k = &c->link;
	if (k->type == AXIS_LINK_TCP)
		l->ctx = modbus_new_tcp(k->host, k->port);
	else
		l->ctx = modbus_new_rtu(k->device, k->baud, k->parity, k->data_bits, k->stop_bits);
	if (!l->ctx)
		return acq_errf(err, ACQ_E_INVAL, "%s: %s: cannot create a Modbus context: %s", c->name, l->where,
				modbus_strerror(errno));
	modbus_set_error_recovery(l->ctx, MODBUS_ERROR_RECOVERY_NONE);
	modbus_set_response_timeout(l->ctx, (uint32_t)(k->response_timeout_ms / 1000),
				    (uint32_t)(k->response_timeout_ms % 1000) * 1000);
	modbus_set_byte_timeout(l->ctx, (uint32_t)(k->byte_timeout_ms / 1000),
				(uint32_t)(k->byte_timeout_ms % 1000) * 1000);
	if (modbus_connect(l->ctx) != 0)
		return acq_errf(err, ACQ_E_DISCONNECTED, "%s: cannot connect to %s: %s", c->name, l->where,
				modbus_strerror(errno));
	l->up = true;
	l->needs_flush = false;
	return 0;
}

void mb_link_down(struct axis_link *l)
{
	if (l->ctx)
		modbus_close(l->ctx);
	l->up = false;
}

/* Classify a failed libmodbus call (errno) into an error record; a broken link is marked down. */
int mb_link_fail(struct axis_dev *ax, const char *what, int addr, struct acq_err *err)
{
	int e = errno;
	const struct axis_cfg *c = ax->cfg;
	const char *msg = modbus_strerror(e);
	int code;
	if (e >= EMBXILFUN && e <= EMBXGTAR) {
		code = ACQ_E_DEVICE; /* the controller answered with an exception */
	} else if (e == ETIMEDOUT) {
		code = ACQ_E_TIMEOUT;
		ax->link->needs_flush = true;
	} else if (e == EMBBADCRC || e == EMBBADDATA || e == EMBBADEXC || e == EMBMDATA || e == EMBBADSLAVE ||
		   e == EMBUNKEXC) {
		code = ACQ_E_PROTO;
		ax->link->needs_flush = true;
	} else {
		code = ACQ_E_DISCONNECTED;
		mb_link_down(ax->link);
	}
	return acq_errf(err, code, "%s (unit %d @ %s): %s at 0x%04x: %s", c->name, c->unit, ax->link->where,
			what, addr, msg);
}

int mb_link_ready(struct axis_dev *ax, struct acq_err *err)
{
	struct axis_link *l = ax->link;
	if (!l->up || !l->ctx)
		return acq_errf(err, ACQ_E_DISCONNECTED, "%s (unit %d @ %s): link is down", ax->cfg->name,
				ax->cfg->unit, l->where);
	if (l->needs_flush) {
		modbus_flush(l->ctx);
		l->needs_flush = false;
	}
	modbus_set_slave(l->ctx, ax->cfg->unit);
	return 0;
}

int mb_link_read(struct axis_dev *ax, int space, int addr, int n, uint16_t *regs, const char *what,
		     struct acq_err *err)
{
	if (mb_link_ready(ax, err))
		return -1;
	int rc = space == REGMAP_INPUT ? modbus_read_input_registers(ax->link->ctx, addr, n, regs)
				       : modbus_read_registers(ax->link->ctx, addr, n, regs);
	if (rc != n) {
		if (rc >= 0) {
			ax->link->needs_flush = true;
			return acq_errf(err, ACQ_E_PROTO, "%s (unit %d): %s at 0x%04x: %d registers instead of %d",
					ax->cfg->name, ax->cfg->unit, what, addr, rc, n);
		}
		return mb_link_fail(ax, what, addr, err);
	}
	return 0;
}

int mb_link_write(struct axis_dev *ax, int addr, int n, const uint16_t *regs, const char *what,
		      struct acq_err *err)
{
	if (mb_link_ready(ax, err))
		return -1;
	int rc = n == 1 ? modbus_write_register(ax->link->ctx, addr, regs[0])
			: modbus_write_registers(ax->link->ctx, addr, n, regs);
	if (rc != (n == 1 ? 1 : n))
		return rc >= 0 ? acq_errf(err, ACQ_E_PROTO, "%s: %s at 0x%04x: short write acknowledge",
					  ax->cfg->name, what, addr)
			       : mb_link_fail(ax, what, addr, err);
	return 0;
}
