/* acqd_options: acquisitiond's command line and its one-shot modes (--check-config, --laser-off). */
#include "daemon/acquisitiond/acqd.h"

#include <getopt.h>
#include <stdio.h>

#include "acq_version.h"
#include "daemon/store.h"
#include "drivers/laser.h"
#include "proto/proto.h"

static void usage(FILE *f)
{
	fprintf(f, "usage: acquisitiond -c FILE [-f] [--sim PORTS.json]\n"
		   "       acquisitiond --check-config FILE [--sim PORTS.json]\n"
		   "       acquisitiond --laser-off -c FILE [--sim PORTS.json]\n"
		   "  -c, --config FILE     configuration (bench, devices, daemon, sweep, recon)\n"
		   "  -f, --foreground      log to stderr even when started by systemd (it never forks)\n"
		   "      --sim PORTS.json  use the simulator's endpoints (acq-sim's ports file)\n"
		   "      --check-config F  validate F and exit 0 (valid) or 1\n"
		   "      --laser-off       switch the configured laser's emission off and exit 0 (confirmed) or 1\n"
		   "                        (the unit's ExecStopPost=, after any exit of the daemon)\n"
		   "  -V, --version         print the version\n");
}

int acqd_options_parse(int argc, char **argv, struct acqd_options *o)
{
	static const struct option opts[] = { { "config", required_argument, NULL, 'c' },
					      { "foreground", no_argument, NULL, 'f' },
					      { "sim", required_argument, NULL, 's' },
					      { "check-config", required_argument, NULL, 'k' },
					      { "laser-off", no_argument, NULL, 'L' },
					      { "version", no_argument, NULL, 'V' },
					      { "help", no_argument, NULL, 'h' },
					      { NULL, 0, NULL, 0 } };
	*o = (struct acqd_options){ 0 };
	int c;
	while ((c = getopt_long(argc, argv, "c:fVh", opts, NULL)) != -1) {
		switch (c) {
		case 'c': o->conf_path = optarg; break;
		case 'f': o->foreground = true; break;
		case 's': o->sim_path = optarg; break;
		case 'k': o->check = optarg; break;
		case 'L': o->laser_off = true; break;
		case 'V': printf("acquisitiond %s (protocol %d, schema %d)\n", ACQ_VERSION, PROTO_VERSION,
				 STORE_SCHEMA_VERSION); return 0;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (optind < argc || (!o->conf_path && !o->check)) {
		usage(stderr);
		return 2;
	}
	return -1;
}

/* The configuration at path, or NULL with its error printed to stderr after prefix. */
static struct conf *load_or_say(const char *path, const struct conf_sim *sim, const char *prefix)
{
	struct conf *c = NULL;
	struct acq_err err = { 0 };
	if (conf_load(path, sim, &c, &err)) {
		fprintf(stderr, "%s%s\n", prefix, err.msg);
		return NULL;
	}
	return c;
}

int acqd_check_config(const char *path, const struct conf_sim *sim)
{
	struct conf *c = load_or_say(path, sim, "");
	if (!c)
		return 1;
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		if (c->devnote[d][0])
			printf("note: %s: %s\n", conf_dev_name((enum conf_dev)d), c->devnote[d]);
	if (c->bench.deprecated[0])
		printf("warning: deprecated keys (still accepted): %s\n", c->bench.deprecated);
	printf("%s: ok\n", path);
	conf_free(c);
	return 0;
}

int acqd_laser_off(const char *path, const struct conf_sim *sim)
{
	struct conf *c = load_or_say(path, sim, "acquisitiond --laser-off: ");
	if (!c)
		return 1;
	struct acq_err err = { 0 };
	int rc = 0;
	struct laser *l = NULL;
	if (!c->laser) {
		fprintf(stderr, "acquisitiond --laser-off: no laser configured: nothing to switch off\n");
	} else if (laser_open(c->laser, &l, &err)) {
		fprintf(stderr, "acquisitiond --laser-off: laser emission off NOT confirmed: %s\n", err.msg);
		rc = 1;
	} else {
		struct laser_status st;
		if (laser_status(l, &st, &err) || st.emission) {
			fprintf(stderr, "acquisitiond --laser-off: laser emission off NOT confirmed: %s\n",
				err.msg[0] ? err.msg : "it still reports emission");
			rc = 1;
		} else {
			printf("acquisitiond --laser-off: laser emission off (confirmed by its status)\n");
		}
		laser_close(l);
	}
	conf_free(c);
	return rc;
}
