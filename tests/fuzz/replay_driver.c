/* Plain driver for libFuzzer targets: replays a corpus, then seeded mutations of it (used by make check). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <dirent.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define REPLAY_MAX_INPUT 65536

static uint64_t rng_state;

static uint64_t rng_next(void)
{
	uint64_t x = rng_state;
	x ^= x << 13;
	x ^= x >> 7;
	x ^= x << 17;
	return rng_state = x;
}

static size_t mutate(uint8_t *buf, size_t len, size_t cap)
{
	int n = 1 + (int)(rng_next() % 8);
	for (int i = 0; i < n; i++) {
		size_t pos = len ? rng_next() % len : 0;
		switch (rng_next() % 6) {
		case 0: if (len) buf[pos] = (uint8_t)rng_next(); break;
		case 1: if (len) buf[pos] ^= (uint8_t)(1u << (rng_next() % 8)); break;
		case 2: if (len < cap) { memmove(buf + pos + 1, buf + pos, len - pos); buf[pos] = (uint8_t)rng_next(); len++; } break;
		case 3: if (len) { memmove(buf + pos, buf + pos + 1, len - pos - 1); len--; } break;
		case 4: len = pos; break;
		case 5: { /* interesting bytes */
			static const uint8_t magic[] = { 0, 0xff, 0x7f, 0x80, ':', '\n', '"', '{', '[', '-' };
			if (len) buf[pos] = magic[rng_next() % sizeof magic];
		} break;
		}
	}
	return len;
}

int main(int argc, char **argv)
{
	unsigned long long seed = 1;
	long mutations = 0, ran = 0;
	static uint8_t inputs[256][REPLAY_MAX_INPUT];
	static size_t lens[256];
	int ninputs = 0;

	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "--seed") && i + 1 < argc) { seed = strtoull(argv[++i], NULL, 10); continue; }
		if (!strcmp(argv[i], "--mutations") && i + 1 < argc) { mutations = strtol(argv[++i], NULL, 10); continue; }
		DIR *d = opendir(argv[i]);
		if (!d) { fprintf(stderr, "replay: cannot open corpus %s\n", argv[i]); return 1; }
		struct dirent *e;
		while ((e = readdir(d)) && ninputs < 256) {
			if (e->d_name[0] == '.') continue;
			char path[4096];
			snprintf(path, sizeof path, "%s/%s", argv[i], e->d_name);
			FILE *f = fopen(path, "rb");
			if (!f) continue;
			lens[ninputs] = fread(inputs[ninputs], 1, REPLAY_MAX_INPUT, f);
			fclose(f);
			LLVMFuzzerTestOneInput(inputs[ninputs], lens[ninputs]);
			ninputs++; ran++;
		}
		closedir(d);
	}
	rng_state = seed ? seed : 1;
	static uint8_t buf[REPLAY_MAX_INPUT];
	for (long m = 0; m < mutations && ninputs > 0; m++) {
		int k = (int)(rng_next() % (uint64_t)ninputs);
		memcpy(buf, inputs[k], lens[k]);
		size_t len = mutate(buf, lens[k], REPLAY_MAX_INPUT);
		/* exact-size heap copy so ASan sees any overread */
		uint8_t *copy = malloc(len ? len : 1);
		memcpy(copy, buf, len);
		LLVMFuzzerTestOneInput(copy, len);
		free(copy);
		ran++;
	}
	printf("%ld inputs (%d corpus files, seed %llu)\n", ran, ninputs, seed);
	return 0;
}
