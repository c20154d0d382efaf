/* A robot process's view of mems-odometry, in C: subscribe to the odometry state, sleep on its
 * event, print each live state's position with its 1-sigma (revisions skipped; "not aligned
 * yet" before the odometry's gravity alignment, when the position is held at zero). It says
 * once on stderr which service and namespace it waits on.
 *
 *   cargo build --release -p mems-client-c
 *   cc -O2 -I ipc-types/include ipc-types/examples/c/subscribe_odometry.c \
 *      -L target/release -lmems_client -Wl,-rpath,$PWD/target/release -o subscribe_odometry
 *   ./subscribe_odometry [COUNT]      (honours MEMS_NAMESPACE; Ctrl-C stops it)
 */
#include <stdio.h>
#include <stdlib.h>

#include "mems_client.h"

int main(int argc, char **argv) {
    long count = argc > 1 ? atol(argv[1]) : -1;
    mems_odometry_subscriber *sub = mems_odometry_subscribe(NULL);
    if (sub == NULL) {
        fprintf(stderr, "subscribe_odometry: %s\n", mems_last_error());
        return 1;
    }
    const char *ns = getenv("MEMS_NAMESPACE");
    fprintf(stderr,
            "subscribe_odometry: waiting for states on %s%smems/odometry/state (namespace \"%s\"; "
            "start mems-stack with the same namespace)\n",
            ns ? ns : "", ns && *ns ? "/" : "", ns ? ns : "");
    long seen = 0;
    int status = 0;
    while (count < 0 || seen < count) {
        int32_t woken = mems_odometry_wait(sub, 100);
        if (woken == -2) {
            break; /* SIGINT or SIGTERM */
        }
        if (woken < 0) {
            fprintf(stderr, "subscribe_odometry: %s\n", mems_last_error());
            status = 1;
            break;
        }
        mems_odometry_state s;
        int32_t got;
        while ((count < 0 || seen < count) && (got = mems_odometry_receive(sub, &s)) == 1) {
            if (s.flags & MEMS_ODOMETRY_REVISION) {
                continue;
            }
            if (!(s.flags & MEMS_ODOMETRY_ALIGNED)) {
                printf("seq %llu not aligned yet\n", (unsigned long long)s.seq);
                seen++;
                continue;
            }
            printf("seq %llu position (%+.3f, %+.3f, %+.3f) m +- (%.3f, %.3f, %.3f)\n",
                   (unsigned long long)s.seq, s.position_m[0], s.position_m[1], s.position_m[2],
                   s.position_sigma_m[0], s.position_sigma_m[1], s.position_sigma_m[2]);
            seen++;
        }
        fflush(stdout);
    }
    mems_odometry_unsubscribe(sub);
    return status;
}
