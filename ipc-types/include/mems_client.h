/* The C API of mems-odometry's clients: libmems_client.so (crate ipc-types/c).
 *
 * Subscribe to the odometry state, sleep on its event until the odometry publishes, take the
 * states. SIGINT/SIGTERM are caught: a wait then returns -2. Errors: NULL or -1, with the
 * message in mems_last_error(). Example: ipc-types/examples/c/subscribe_odometry.c. */
#ifndef MEMS_CLIENT_H
#define MEMS_CLIENT_H

#include <stdint.h>

#include "mems_ipc.h"

typedef struct MemsOdometrySubscriber mems_odometry_subscriber;

/* Subscribes in `ns` (NULL: $MEMS_NAMESPACE, else none). NULL on error. */
mems_odometry_subscriber *mems_odometry_subscribe(const char *ns);
/* Sleeps until a publication (1), at most timeout_ms (0); -2 after SIGINT/SIGTERM, -1 error. */
int32_t mems_odometry_wait(mems_odometry_subscriber *sub, uint32_t timeout_ms);
/* The next state into *out: 1, or 0 if none is waiting; -1 on error. */
int32_t mems_odometry_receive(mems_odometry_subscriber *sub, mems_odometry_state *out);
/* Ends the subscription (NULL is ignored). */
void mems_odometry_unsubscribe(mems_odometry_subscriber *sub);
/* This thread's last error message ("" if none). */
const char *mems_last_error(void);

#endif
