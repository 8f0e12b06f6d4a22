/* acqd: the parts of acquisitiond's entry point (acquisitiond_main.c), one concern per file — the command line
 * and its one-shot modes (acqd_options.c), signals (acqd_signals.c), the loop's periodic duties towards systemd
 * and the laser (acqd_timers.c), the start-up in order and the stop in reverse (acqd_start.c). */
#ifndef ACQD_H
#define ACQD_H

#include <stdbool.h>

#include "config/acq_err.h"
#include "daemon/app.h"

struct loop;

/* The command line. */
struct acqd_options {
	const char *conf_path, *sim_path, *check;
	bool foreground, laser_off;
};

/* Parse argv into o; prints the usage or the version itself. -1: go on; else the exit status (0 for --help and
 * --version, 2 for a usage error). */
int acqd_options_parse(int argc, char **argv, struct acqd_options *o);
/* --check-config: validate path (against sim, NULL: none), print its notes and "PATH: ok". The exit status. */
int acqd_check_config(const char *path, const struct conf_sim *sim);
/* --laser-off (ExecStopPost=): open the configured laser, which switches emission off, confirm it by its status,
 * close it. The exit status (0: confirmed or no laser). */
int acqd_laser_off(const char *path, const struct conf_sim *sim);

/* Signals through a self-pipe on the loop: SIGTERM/SIGINT stop the loop (acqd_stop_wanted), SIGHUP reloads app,
 * SIGCHLD reaps the jobs; SIGPIPE ignored. 0 or -1 with err. */
int acqd_signals_init(struct app *app, struct acq_err *err);
/* Restore the default handlers and close the pipe (harmless when acqd_signals_init did not run). */
void acqd_signals_finish(void);
/* True once SIGTERM or SIGINT came. */
bool acqd_stop_wanted(void);

/* The loop's periodic duties: systemd's STATUS= line (every second), the watchdog (WATCHDOG_USEC or
 * daemon.watchdog_s, in real seconds) and the laser's keep-alive heartbeat (every 250 ms real time when a laser is
 * configured); rate: the loop's seconds per real second. Sends the first status line now. */
void acqd_timers_start(struct app *app, double rate);
/* The status line last sent to systemd. */
const char *acqd_timers_status(void);

/* Start the daemon for options o into app (already holding the simulator's ports when --sim): logging, the
 * configuration, the state folder, the loop and its clock, the job helper, the database, signals, the socket,
 * the devices, the sweep and its resume, the timers; READY=1 to systemd. 0, or -1 after logging why (what was
 * started is for acqd_stop). */
int acqd_start(struct app *app, const struct acqd_options *o);
/* Stop in reverse order (the sweep, the devices: laser off and arms stopped, the clients, the children, the
 * signals, the database, the loop, the configuration, the log); clean: log "stopped". */
void acqd_stop(struct app *app, bool clean);

#endif
