/* sim_arm: test access to a simulated arm controller (sim_arm_new() is declared in sim/sim.h). */
#ifndef SIM_ARM_H
#define SIM_ARM_H

#include <stdint.h>

#include "sim/sim.h"
#include "sim/sim_motion.h"

/* The motion model of axis i (0: theta, 1: phi) of an arm service, NULL if none. */
struct simmot *simarm_motion(struct sim_service *svc, int axis);
/* Alarm code of axis i (0 none, -1 no such axis). */
int simarm_alarm(struct sim_service *svc, int axis);
/* Moves axis i was commanded (triggers that started or were refused), -1 if no such axis. */
int simarm_moves(struct sim_service *svc, int axis);
/* TCP port the arm listens on (0 for RTU). */
int simarm_port(struct sim_service *svc);

#endif
