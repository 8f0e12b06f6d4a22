/* sim_stale: the default socket files (/tmp/acq-sim.<pid>.<service>.sock) of simulators that died without
 * removing them (SIGKILL, a crash): a SIGTERM or SIGINT removes a running simulator's own (its services'
 * destroy), these are removed at the next start: a file whose process is gone and where nobody listens. */
#include <dirent.h>
#include <errno.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "sim/sim.h"

/* Nobody listens at path: a connection is refused (a simulator in another PID namespace still answers). */
static bool refused(const char *path)
{
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	if (strlen(path) >= sizeof a.sun_path)
		return false;
	strcpy(a.sun_path, path);
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0); /* a full backlog: EAGAIN, kept */
	if (fd < 0)
		return false;
	bool r = connect(fd, (struct sockaddr *)&a, sizeof a) && errno == ECONNREFUSED;
	close(fd);
	return r;
}

int sim_stale_sockets_remove(const char *dir)
{
	DIR *d = opendir(dir);
	if (!d)
		return 0;
	int removed = 0;
	struct dirent *e;
	while ((e = readdir(d))) {
		long pid = 0;
		char svc[16], end[2];
		/* exactly acq-sim.<pid>.<lower-case service>.sock */
		if (sscanf(e->d_name, "acq-sim.%ld.%15[a-z].soc%1[k]", &pid, svc, end) != 3 || pid <= 0 ||
		    strlen(e->d_name) != (size_t)snprintf(NULL, 0, "acq-sim.%ld.%s.sock", pid, svc))
			continue;
		if (pid == (long)getpid() || kill((pid_t)pid, 0) == 0 || errno != ESRCH)
			continue; /* its simulator runs (or is not ours to judge) */
		char path[4096];
		struct stat st;
		snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
		if (lstat(path, &st) || !S_ISSOCK(st.st_mode) || st.st_uid != geteuid() || !refused(path))
			continue;
		if (!unlink(path))
			removed++;
	}
	closedir(d);
	return removed;
}
