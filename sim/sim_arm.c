/* sim_arm: a simulated arm controller served over real Modbus (libmodbus; the links, TCP on 127.0.0.1 with several
 * clients at once or RTU on a tty (one end of a socat pty pair): sim_arm_link.c). Each axis answers behind its own unit id
 * with the same register map the driver uses (drivers/regmap.h); motion runs in bench time
 * (sim/sim_motion.c) and the actual positions go to the world, where collisions between the arms are
 * detected. Faults from world->faults: timeout, dropped connection, alarm half way, stall.
 *
 * Alarm codes (Oriental AZ numbering where one exists): 0x66 hardware overtravel (hard limit),
 * 0x67 software overtravel (target outside the controller's soft limits), 0x70 abnormal operation data,
 * 0x30 overload (injected alarm half way), 0xE0 arms collided (simulator only). */
#include <errno.h>
#include <math.h>
#include <modbus.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <netinet/in.h>
#include <termios.h>
#include <unistd.h>

#include "drivers/axis_modbus.h"
#include "drivers/regmap.h"
#include "sim/sim.h"
#include "sim/sim_arm.h"
#include "sim/sim_arm_int.h"
#include "sim/sim_motion.h"

static void mark(uint8_t *bits, int addr, int n)
{
	for (int i = 0; i < n && addr + i < NREG; i++)
		bits[(addr + i) / 8] |= (uint8_t)(1u << ((addr + i) % 8));
}

static bool all_marked(const uint8_t *bits, int addr, int n)
{
	if (addr < 0 || n < 0 || addr + n > NREG)
		return false;
	for (int i = 0; i < n; i++)
		if (!(bits[(addr + i) / 8] & (1u << ((addr + i) % 8))))
			return false;
	return true;
}

static void put_field(struct sim_axis *a, int id, double value, bool raw)
{
	const struct regmap_field *f = &a->map->f[id];
	if (!f->present)
		return;
	uint16_t regs[2];
	struct acq_err e;
	int rc = raw ? regmap_encode_raw(f, value, regs, &e) : regmap_encode(f, value, regs, &e);
	if (rc)
		return; /* not representable: leave the register as it was */
	uint16_t *tab = f->space == REGMAP_INPUT ? a->mb->tab_input_registers : a->mb->tab_registers;
	memcpy(tab + f->addr, regs, sizeof(uint16_t) * (size_t)regmap_width(f));
}

static double get_field(const struct sim_axis *a, int id, bool raw)
{
	const struct regmap_field *f = &a->map->f[id];
	const uint16_t *tab = f->space == REGMAP_INPUT ? a->mb->tab_input_registers : a->mb->tab_registers;
	return raw ? regmap_decode_raw(f, tab + f->addr) : regmap_decode(f, tab + f->addr);
}

/* Model → registers: status word, positions, alarm code, identity. */
static void update_regs(struct sim_axis *a)
{
	const struct regmap *m = a->map;
	bool busy = a->mot.moving || a->stalled;
	bool bits[RM__NBITS] = {
		[RM_BIT_READY] = !busy && !a->alarm,
		[RM_BIT_BUSY] = busy,
		[RM_BIT_MOVE] = busy,
		[RM_BIT_IN_POS] = !busy && !a->alarm,
		[RM_BIT_ALARM] = a->alarm != 0,
		[RM_BIT_HOMED] = a->homed,
		[RM_BIT_LIMIT_POS] = a->lim_pos,
		[RM_BIT_LIMIT_NEG] = a->lim_neg,
		[RM_BIT_STALL] = a->stalled,
	};
	uint32_t word = 0;
	for (int i = 0; i < RM__NBITS; i++)
		if (m->bit[i] >= 0 && bits[i])
			word |= 1u << m->bit[i];
	put_field(a, RM_STATUS, (double)word, true);
	put_field(a, RM_ACTUAL, a->mot.motor, false);
	put_field(a, RM_COMMAND_POS, a->mot.moving ? a->mot.p1 : a->mot.motor, false);
	put_field(a, RM_ALARM_CODE, (double)a->alarm, true);
	put_field(a, RM_SERIAL, 1000.0 * (a->arm->arm + 1) + a->unit, true); /* 1001 laser arm, 2001-2 detector arm */
	put_field(a, RM_FIRMWARE, 102, true);
}

static void axis_tick(struct sim_axis *a, double now);

static void raise_alarm(struct sim_axis *a, int code)
{
	a->alarm = code;
	a->homing = false;
	a->stalled = false;
	simmot_halt(&a->mot);
}

static void start_move(struct sim_arm *s, struct sim_axis *a, double now)
{
	const struct regmap *m = a->map;
	a->moves++;
	if (a->alarm || a->stalled)
		return; /* a controller in alarm ignores operations */
	if (m->f[RM_OP_TYPE].present && get_field(a, RM_OP_TYPE, true) != m->f[RM_OP_TYPE].value) {
		raise_alarm(a, 0x70);
		return;
	}
	double target = get_field(a, RM_TARGET, false);
	if (!isfinite(target) || target < a->soft_min || target > a->soft_max) {
		raise_alarm(a, 0x67);
		return;
	}
	double v = m->f[RM_SPEED].present ? get_field(a, RM_SPEED, false) : 0;
	double acc = m->f[RM_ACCEL].present ? get_field(a, RM_ACCEL, false) : 0;
	double dec = m->f[RM_DECEL].present ? get_field(a, RM_DECEL, false) : 0;
	axis_tick(a, now);
	if (a->alarm)
		return;
	simmot_start(&a->mot, target, now, v, acc, dec);
	a->homing = false;
	if (target > a->mot.k.min_deg)
		a->lim_neg = false;
	if (target < a->mot.k.max_deg)
		a->lim_pos = false;
	struct sim_faults *f = &s->w->faults;
	if (f->alarm_mid_move[s->arm] && a->mot.moving) {
		simmot_schedule_halt(&a->mot, SIMMOT_HALT_ALARM, 0.5);
		f->alarm_mid_move[s->arm] = false;
	} else if (f->stall[s->arm] && a->mot.moving) {
		simmot_schedule_halt(&a->mot, SIMMOT_HALT_STALL, 0.6);
		f->stall[s->arm] = false;
	}
}

static void do_cmd(struct sim_arm *s, struct sim_axis *a, int id, double now)
{
	switch (id) {
	case RM_CMD_START:
		start_move(s, a, now);
		break;
	case RM_CMD_STOP:
		axis_tick(a, now);
		simmot_stop(&a->mot, now);
		a->stalled = false;
		a->homing = false;
		break;
	case RM_CMD_ALARM_RESET:
		a->alarm = 0;
		a->stalled = false;
		break;
	case RM_CMD_HOME:
		if (a->alarm || a->stalled)
			break;
		axis_tick(a, now);
		if (a->alarm)
			break;
		simmot_start(&a->mot, 0.0, now, a->mot.k.speed_dps / 2, 0, 0);
		a->mot.add_noise = false;
		a->homing = true;
		a->homed = false;
		if (!a->mot.moving)
			a->homed = true, a->homing = false;
		break;
	}
}

/* A write landed on [addr, addr+n) of space (holding or coil): trigger moves and commands. */
static void on_write(struct sim_arm *s, struct sim_axis *a, int space, int addr, int n, double now)
{
	const struct regmap *m = a->map;
	static const int order[] = { RM_CMD_STOP, RM_CMD_ALARM_RESET, RM_CMD_HOME, RM_CMD_START };
	for (size_t k = 0; k < sizeof order / sizeof order[0]; k++) {
		int id = order[k];
		const struct regmap_cmd *c = &m->cmd[id];
		if (!c->present || (c->space == REGMAP_COIL) != (space == REGMAP_COIL) || c->addr < addr ||
		    c->addr >= addr + n)
			continue;
		uint16_t v = c->space == REGMAP_COIL ? a->mb->tab_bits[c->addr] : a->mb->tab_registers[c->addr];
		bool fire;
		if (c->level) {
			fire = (v & c->value) == c->value && (a->cmd_prev[id] & c->value) != c->value;
			a->cmd_prev[id] = v;
		} else {
			fire = v == c->value;
			if (fire) { /* pulse semantics: the device clears the register */
				if (c->space == REGMAP_COIL)
					a->mb->tab_bits[c->addr] = 0;
				else
					a->mb->tab_registers[c->addr] = 0;
			}
		}
		if (fire)
			do_cmd(s, a, id, now);
	}
	const struct regmap_field *t = &m->f[RM_TRIGGER];
	if (space == REGMAP_HOLDING && t->present && t->addr + regmap_width(t) > addr && t->addr < addr + n &&
	    get_field(a, RM_TRIGGER, true) == t->value)
		start_move(s, a, now);
}

static struct sim_axis *find_unit(struct sim_arm *s, int unit)
{
	for (int i = 0; i < s->nax; i++)
		if (s->ax[i].unit == unit)
			return &s->ax[i];
	return NULL;
}

static int get16(const uint8_t *p)
{
	return p[0] << 8 | p[1];
}

/* Check that a request only touches registers the map defines; the exception code or 0. */
static int check_request(const struct sim_axis *a, const uint8_t *pdu)
{
	int fc = pdu[0], addr = get16(pdu + 1), n = get16(pdu + 3);
	switch (fc) {
	case 1: case 5: case 15:
		if (fc == 5)
			n = 1;
		return all_marked(a->valid_coil, addr, n) ? 0 : MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
	case 3: case 6: case 16:
		if (fc == 6)
			n = 1;
		return all_marked(a->valid[REGMAP_HOLDING], addr, n) ? 0 : MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
	case 4:
		return all_marked(a->valid[REGMAP_INPUT], addr, n) ? 0 : MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
	default:
		return MODBUS_EXCEPTION_ILLEGAL_FUNCTION;
	}
}

/* Answer one complete request (ADU in req, length len) at bench time now, as the addressed unit (the link's
 * s->serve). */
static void serve(struct sim_arm *s, uint8_t *req, int len, double now)
{
	int hl = modbus_get_header_length(s->ctx);
	if (len < hl + 1)
		return;
	if (s->w->faults.modbus_timeout[s->arm])
		return; /* the controller does not answer */
	struct sim_axis *a = find_unit(s, req[hl - 1]);
	if (!a) {
		if (s->link_type == AXIS_LINK_TCP)
			modbus_reply_exception(s->ctx, req, MODBUS_EXCEPTION_GATEWAY_TARGET);
		return; /* RTU: nobody on the bus with that address */
	}
	axis_tick(a, now);
	update_regs(a);
	const uint8_t *pdu = req + hl;
	int ex = len >= hl + 5 ? check_request(a, pdu) : MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
	if (ex) {
		modbus_reply_exception(s->ctx, req, (unsigned)ex);
		return;
	}
	if (modbus_reply(s->ctx, req, len, a->mb) < 0)
		return;
	int fc = pdu[0];
	if (fc == 6 || fc == 16)
		on_write(s, a, REGMAP_HOLDING, get16(pdu + 1), fc == 6 ? 1 : get16(pdu + 3), now);
	else if (fc == 5 || fc == 15)
		on_write(s, a, REGMAP_COIL, get16(pdu + 1), fc == 5 ? 1 : get16(pdu + 3), now);
	update_regs(a);
}

static bool colliding(const struct sim_world *w)
{
	double sep = simmot_arm_separation(w->laser_theta_deg, w->geom.laser_phi_deg, w->detector_theta_deg,
					   w->detector_phi_deg);
	return sep < w->geom.laser_body_halfwidth_deg + w->geom.detector_body_halfwidth_deg;
}

/* Contact: every axis of this arm stops with the collision alarm (the other arm sees world->collision). */
static void collide(struct sim_arm *s)
{
	for (int i = 0; i < s->nax; i++)
		raise_alarm(&s->ax[i], 0xE0);
	if (!s->w->collision)
		s->w->collisions++;
	s->w->collision = true;
	s->was_colliding = true;
}

static void axis_event(struct sim_axis *a, int ev)
{
	switch (ev) {
	case SIMMOT_DONE:
		if (a->homing) {
			a->homing = false;
			a->homed = true;
			a->mot.motor = 0;
		}
		break;
	case SIMMOT_LIMIT_POS: a->lim_pos = true; raise_alarm(a, 0x66); break;
	case SIMMOT_LIMIT_NEG: a->lim_neg = true; raise_alarm(a, 0x66); break;
	case SIMMOT_ALARMED: raise_alarm(a, 0x30); break;
	case SIMMOT_STALL: a->stalled = true; break;
	default: break;
	}
}

/* Advance an axis to bench time now in steps of at most 0.05° of travel, so that contact with the other
 * arm is caught where it happens, not one (possibly long, on a loaded machine) loop turn later. */
static void axis_tick(struct sim_axis *a, double now)
{
	struct sim_arm *s = a->arm;
	double t = a->t_last < now ? a->t_last : now;
	while (a->mot.moving) {
		double v = a->mot.vmax > 0 ? a->mot.vmax : a->mot.k.speed_dps;
		t = t + 0.05 / v < now ? t + 0.05 / v : now;
		axis_event(a, simmot_advance(&a->mot, t));
		if (a->world_pos)
			*a->world_pos = a->mot.load;
		if (!s->was_colliding && colliding(s->w)) {
			collide(s);
			break;
		}
		if (t >= now)
			break;
	}
	if (a->world_pos)
		*a->world_pos = a->mot.load;
	a->t_last = now;
}

static void arm_tick(void *self, double now)
{
	struct sim_arm *s = self;
	struct sim_world *w = s->w;
	s->now = now;
	if (w->faults.drop_connection[s->arm]) {
		w->faults.drop_connection[s->arm] = false;
		simarm_link_drop(s);
	}
	for (int i = 0; i < s->nax; i++)
		axis_tick(&s->ax[i], now);
	bool coll = colliding(w);
	if (coll && !w->collision)
		w->collisions++;
	w->collision = coll;
	if (coll && !s->was_colliding)
		for (int i = 0; i < s->nax; i++)
			raise_alarm(&s->ax[i], 0xE0);
	s->was_colliding = coll;
	for (int i = 0; i < s->nax; i++)
		update_regs(&s->ax[i]);
}

static void arm_describe(void *self, char *buf, size_t len)
{
	struct sim_arm *s = self;
	if (s->link_type == AXIS_LINK_TCP)
		snprintf(buf, len, "\"%s\": {\"port\": %d}", s->key, s->port);
	else
		snprintf(buf, len, "\"%s\": {\"device\": \"%s\"}", s->key, s->device);
}

static void arm_destroy(void *self)
{
	struct sim_arm *s = self;
	if (!s)
		return;
	simarm_link_close(s);
	for (int i = 0; i < s->nax; i++) {
		if (s->ax[i].mb)
			modbus_mapping_free(s->ax[i].mb);
		axis_cfg_free(s->ax[i].cfg);
	}
	free(s);
}

static int setup_axis(struct sim_arm *s, struct sim_axis *a, struct axis_cfg *cfg, struct acq_err *err)
{
	struct sim_world *w = s->w;
	const char *name = axis_cfg_name(cfg);
	const struct bench_axis *k;
	a->arm = s;
	a->cfg = cfg;
	a->map = axis_cfg_map(cfg);
	a->unit = axis_cfg_unit(cfg);
	axis_cfg_limits(cfg, &a->soft_min, &a->soft_max);
	if (!strcmp(name, "laser.theta")) {
		k = &w->geom.laser_theta;
		a->world_pos = &w->laser_theta_deg;
	} else if (!strcmp(name, "detector.theta")) {
		k = &w->geom.detector_theta;
		a->world_pos = &w->detector_theta_deg;
	} else if (!strcmp(name, "detector.phi")) {
		k = &w->geom.detector_phi;
		a->world_pos = &w->detector_phi_deg;
	} else {
		return acq_errf(err, ACQ_E_CONFIG, "simulated %s: unknown axis '%s' (laser arm: theta; detector "
				"arm: theta, phi)", s->key, name);
	}
	for (int i = 0; i < s->nax; i++)
		if (&s->ax[i] != a && s->ax[i].unit == a->unit)
			return acq_errf(err, ACQ_E_CONFIG, "simulated %s: unit %d used by two axes", s->key, a->unit);
	simmot_init(&a->mot, k, *a->world_pos, w->seed ^ ((uint64_t)(s->arm * 2 + (int)(a - s->ax)) << 32));
	a->mb = modbus_mapping_new(NREG, 0, NREG, NREG);
	if (!a->mb)
		return acq_errf(err, ACQ_E_NOMEM, "simulated %s: out of memory", s->key);
	const struct regmap *m = a->map;
	for (int i = 0; i < RM__NFIELDS; i++)
		if (m->f[i].present)
			mark(a->valid[m->f[i].space == REGMAP_INPUT], m->f[i].addr, regmap_width(&m->f[i]));
	if (m->block)
		mark(a->valid[REGMAP_HOLDING], m->block_start, m->block_count);
	for (int i = 0; i < RM__NCMDS; i++)
		if (m->cmd[i].present)
			mark(m->cmd[i].space == REGMAP_COIL ? a->valid_coil : a->valid[REGMAP_HOLDING], m->cmd[i].addr, 1);
	/* the move fields start with sensible defaults (a bare trigger moves to the current position) */
	put_field(a, RM_TARGET, a->mot.motor, false);
	for (int i = RM_OP_TYPE; i <= RM_CURRENT; i++)
		if (m->f[i].present)
			put_field(a, i, m->f[i].value, true);
	update_regs(a);
	return 0;
}

struct sim_service *sim_arm_new(struct sim_world *w, enum sim_arm_id arm, struct yc_node *node,
				struct yc_node *maps, struct yc_node *simcfg, struct acq_err *err)
{
	(void)simcfg;
	const char *key = arm == SIM_ARM_LASER ? "laser_arm" : "detector_arm";
	struct sim_arm *s = calloc(1, sizeof *s);
	if (!s) {
		acq_errf(err, ACQ_E_NOMEM, "simulated %s: out of memory", key);
		return NULL;
	}
	s->w = w;
	s->arm = arm;
	s->key = key;
	s->listen_fd = -1;
	struct axis_cfg *cfgs[MAX_AXES];
	int n = 0;
	if (axis_arm_parse(node, maps, key, cfgs, MAX_AXES, &n, err))
		goto fail;
	s->nax = n;
	for (int i = 0; i < n; i++)
		s->ax[i].cfg = cfgs[i];
	for (int i = 0; i < n; i++)
		if (setup_axis(s, &s->ax[i], cfgs[i], err))
			goto fail;
	s->serve = serve;
	if (simarm_link_open(s, axis_cfg_link(cfgs[0]), err))
		goto fail;
	s->svc = (struct sim_service){ .name = key, .self = s, .pollfds = simarm_pollfds, .handle = simarm_handle,
				       .tick = arm_tick, .describe = arm_describe, .destroy = arm_destroy };
	return &s->svc;
fail:
	for (int i = s->nax; i < n; i++)
		axis_cfg_free(cfgs[i]);
	arm_destroy(s);
	return NULL;
}

/* Test access to the model behind a service. */
struct simmot *simarm_motion(struct sim_service *svc, int axis)
{
	struct sim_arm *s = svc->self;
	return axis >= 0 && axis < s->nax ? &s->ax[axis].mot : NULL;
}

int simarm_alarm(struct sim_service *svc, int axis)
{
	struct sim_arm *s = svc->self;
	return axis >= 0 && axis < s->nax ? s->ax[axis].alarm : -1;
}

int simarm_moves(struct sim_service *svc, int axis)
{
	struct sim_arm *s = svc->self;
	return axis >= 0 && axis < s->nax ? s->ax[axis].moves : -1;
}

int simarm_port(struct sim_service *svc)
{
	return ((struct sim_arm *)svc->self)->port;
}
