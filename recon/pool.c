/* pool: independent jobs on a few pthreads, handed out in order by one counter under a mutex. */
#include "recon/pool.h"

#include <pthread.h>
#include <string.h>

struct pool {
	pool_job_fn fn;
	void *ctx;
	size_t njobs, next, done;
	const struct pool_progress *pr;
	pthread_mutex_t mu;
	int failed;
	struct acq_err err;
};

struct pool_worker {
	struct pool *P;
	int id;
};

static void *pool_worker(void *arg)
{
	struct pool_worker *w = arg;
	struct pool *P = w->P;
	struct acq_err e;
	for (;;) {
		pthread_mutex_lock(&P->mu);
		size_t job = P->failed ? P->njobs : P->next;
		if (job < P->njobs)
			P->next++;
		pthread_mutex_unlock(&P->mu);
		if (job >= P->njobs)
			break;
		acq_err_clear(&e);
		int bad = P->fn(P->ctx, w->id, job, &e) != 0;
		pthread_mutex_lock(&P->mu);
		P->done++;
		if (bad && !P->failed) {
			P->failed = 1;
			P->err = e;
			if (!P->err.code)
				acq_errf(&P->err, ACQ_E_NUMERIC, "job %zu failed", job);
		}
		const struct pool_progress *pr = P->pr;
		if (!bad && pr && pr->fn && (pr->every <= 1 || P->done % pr->every == 0))
			pr->fn(pr->ctx, pr->stage ? pr->stage : "", (double)P->done / (double)P->njobs);
		pthread_mutex_unlock(&P->mu);
	}
	return NULL;
}

int pool_run(int threads, size_t njobs, pool_job_fn fn, void *ctx, const struct pool_progress *progress,
	     struct acq_err *err)
{
	if (threads < 1 || threads > POOL_MAX_THREADS || !fn)
		return acq_errf(err, ACQ_E_INVAL, "pool: threads must be in 1..%d (got %d)", POOL_MAX_THREADS, threads);
	struct pool P;
	memset(&P, 0, sizeof P);
	P.fn = fn;
	P.ctx = ctx;
	P.njobs = njobs;
	P.pr = progress;
	pthread_mutex_init(&P.mu, NULL);
	struct pool_worker w[POOL_MAX_THREADS];
	pthread_t tid[POOL_MAX_THREADS];
	int started = 0;
	for (int t = 1; t < threads; t++) {
		w[started + 1] = (struct pool_worker){ .P = &P, .id = started + 1 };
		if (pthread_create(&tid[started], NULL, pool_worker, &w[started + 1]) != 0)
			break; /* fewer workers: the same jobs, the same results */
		started++;
	}
	w[0] = (struct pool_worker){ .P = &P, .id = 0 };
	pool_worker(&w[0]);
	for (int t = 0; t < started; t++)
		pthread_join(tid[t], NULL);
	pthread_mutex_destroy(&P.mu);
	if (P.failed) {
		if (err)
			*err = P.err;
		return -1;
	}
	return 0;
}
