/* What the two misuse hosts share (misuse.c: FMI 2.0, misuse3.c: FMI 3.0): the print lock,
 * the CRC-32 of serialised states and result hashes, and the "threads" command, which
 * runs the host's own run_one (one instance through init and its steps) in N threads. */
#ifndef MISUSE_COMMON_H
#define MISUSE_COMMON_H

#include <pthread.h>
#include <stdio.h>

static pthread_mutex_t print_lock = PTHREAD_MUTEX_INITIALIZER;

static unsigned long crc32(const unsigned char *p, size_t n)
{
    unsigned long crc = 0xFFFFFFFFul;
    for (size_t i = 0; i < n; i++) {
        crc ^= p[i];
        for (int k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xEDB88320ul & (0ul - (crc & 1ul)));
    }
    return crc ^ 0xFFFFFFFFul;
}

/* One thread's run: its steps of h, then whether every call answered OK and the hash of
   the values it read. */
typedef struct { int steps; double h; unsigned long hash; int ok; } Run;

/* N threads (at most 64) of run_one, joined; prints "thread K OK|failed HASH" for each. */
static void run_threads(int n, int steps, double h, void *(*run_one)(void *))
{
    Run runs[64];
    pthread_t ids[64];
    if (n > 64) n = 64;
    for (int k = 0; k < n; k++) {
        runs[k] = (Run){steps, h, 0, 0};
        pthread_create(&ids[k], NULL, run_one, &runs[k]);
    }
    for (int k = 0; k < n; k++) {
        pthread_join(ids[k], NULL);
        printf("thread %d %s %08lx\n", k, runs[k].ok ? "OK" : "failed", runs[k].hash);
    }
}

#endif
