/* sockprobe: is a daemon serving on a Unix socket path, or is the file a killed one's leftover? */
#ifndef ACQ_DAEMON_SOCKPROBE_H
#define ACQ_DAEMON_SOCKPROBE_H

#include <sys/un.h>

enum sockprobe {
	SOCKPROBE_STALE,   /* nothing accepts there (any more): the file may be replaced */
	SOCKPROBE_SERVING, /* a peer accepted and wrote (a daemon's banner) */
	SOCKPROBE_SILENT,  /* something kept accepting without a word for the whole wait */
};

/* Connects to sa repeatedly for up to wait_s seconds: SERVING as soon as a connection brings bytes, STALE as
 * soon as a connect fails, SILENT if every connection stays mute until wait_s. */
enum sockprobe sockprobe_unix(const struct sockaddr_un *sa, double wait_s);

#endif
