/* eta: a sweep's remaining time in wall-clock seconds at any time scale — the planner's remaining duration at
 * first, then what the sweep measures per point while it runs (paused or faulted time does not count). */
#ifndef ETA_H
#define ETA_H

#include <stdbool.h>

struct eta {
	double t0_loop, t0_real;   /* first sample of the two clocks (the loop's may run time-scale faster) */
	double scale;              /* loop seconds per real second, measured; 1 until known */
	double last_real;          /* real time of the last running sample; NAN when not running */
	int last_done;
	double run_real;           /* real seconds spent running between samples */
	int measured;              /* points completed in run_real */
};

/* A new sweep (or a resumed one): nothing measured yet. */
void eta_reset(struct eta *e);
/* The sweep runs (true) or stops running (pause, fault: false) at these clock readings with done points. */
void eta_running(struct eta *e, bool running, int done, double loop_now, double real_now);
/* After a point: wall seconds left for total - done points; plan_left_s is the planner's estimate of the rest
 * in bench seconds (NAN: unknown). NAN when nothing can be said yet. */
double eta_update(struct eta *e, int done, int total, double plan_left_s, double loop_now, double real_now);

#endif
