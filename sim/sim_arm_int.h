/* sim_arm_int: what sim_arm.c (the controller: registers, commands, axes) and sim_arm_link.c (its Modbus links)
 * share. Not for other modules. */
#ifndef SIM_ARM_INT_H
#define SIM_ARM_INT_H

#include <modbus.h>
#include <poll.h>
#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "drivers/axis_modbus.h"
#include "drivers/regmap.h"
#include "sim/sim.h"
#include "sim/sim_motion.h"

#define MAX_AXES 2
#define MAX_CLIENTS 16
#define NREG 65536

struct sim_arm;

struct sim_axis {
	struct sim_arm *arm;
	double t_last;                 /* bench time the model was last advanced to */
	struct axis_cfg *cfg;
	const struct regmap *map;
	int unit;
	modbus_mapping_t *mb;
	uint8_t valid[2][NREG / 8];   /* holding/input registers the map defines (others: exception 2) */
	uint8_t valid_coil[NREG / 8];
	struct simmot mot;
	double soft_min, soft_max;
	double *world_pos;
	int alarm;                     /* alarm code, 0 = none */
	bool homed, homing, stalled, lim_pos, lim_neg;
	int moves;                     /* moves started (for tests: proves when nothing was sent) */
	uint16_t cmd_prev[RM__NCMDS];
};

struct sim_arm {
	struct sim_world *w;
	int arm;
	const char *key;               /* "laser_arm" / "detector_arm" */
	struct sim_axis ax[MAX_AXES];
	int nax;
	int link_type;
	char device[256];
	modbus_t *ctx;
	int listen_fd;
	int clients[MAX_CLIENTS];
	int nclients;
	int port;
	bool was_colliding;
	double now;
	double rtu_quiet_until;
	void (*serve)(struct sim_arm *s, uint8_t *req, int len, double now); /* the link's requests go here */
	struct sim_service svc;
};

/* Open the link l (TCP: listen on 127.0.0.1, the port chosen in s->port; RTU: the tty) into s, each complete request
 * (ADU, its length) then handed to s->serve; 0 or -1 with err. */
int simarm_link_open(struct sim_arm *s, const struct axis_link_cfg *l, struct acq_err *err);
/* Close every TCP client (the dropped-connection fault); the listener stays. */
void simarm_link_drop(struct sim_arm *s);
/* Close the link's clients, listener and context (what simarm_link_open left open). */
void simarm_link_close(struct sim_arm *s);
/* The service's pollfds: the tty, or the listener and the clients (sim_service.pollfds). */
int simarm_pollfds(void *self, struct pollfd *fds, int max);
/* The service's handle: read and answer what the descriptors polled have (sim_service.handle). */
void simarm_handle(void *self, const struct pollfd *fds, int n, double now);

#endif
