#!/usr/bin/env python3
"""Subscribes to a mems-odometry service with the iceoryx2 Python package (0.10) and prints
each message as one JSON line. Event-driven: it sleeps in an iceoryx2 WaitSet on the
service's event (its publisher notifies it after each send) and drains the subscriber when
woken, so a message is printed as soon as it is sent and an idle subscriber uses no CPU.

    python3 ipc-types/python/subscribe.py mems/odometry/state [--namespace NS] [--count N]

Exits 0 after --count messages (or on Ctrl-C), 1 if none arrived within --timeout seconds.
It says once on stderr which service and namespace it waits on. An odometry state's
position is meaningful only once its ALIGNED flag is set (before gravity alignment it is
held at zero): it says on stderr when the stream is not aligned yet, and when it aligns.
"""

import argparse
import json
import os
import sys
import time

import iceoryx2 as iox2

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mems_ipc  # noqa: E402

TYPES = {
    mems_ipc.SERVICE_RAW: mems_ipc.RawImuSample,
    mems_ipc.SERVICE_CORRECTED: mems_ipc.CorrectedImuSample,
    mems_ipc.SERVICE_ODOMETRY: mems_ipc.OdometryState,
}


def to_dict(value):
    """A ctypes value as plain JSON-able Python data."""
    if hasattr(value, "_fields_"):
        return {name: to_dict(getattr(value, name)) for name, _ in value._fields_}
    if hasattr(value, "_length_"):
        return [to_dict(v) for v in value]
    return value


def aligned(payload):
    """Whether a message's position means something: an odometry state before gravity
    alignment holds it at zero (other services have no position)."""
    if not isinstance(payload, mems_ipc.OdometryState):
        return True
    return bool(payload.flags & mems_ipc.ODOMETRY_ALIGNED)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("service", choices=sorted(TYPES))
    parser.add_argument("--namespace", default=os.environ.get("MEMS_NAMESPACE", ""))
    parser.add_argument("--count", type=int, default=0, help="stop after N messages (0: never)")
    parser.add_argument("--timeout", type=float, default=10.0)
    args = parser.parse_args()

    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    name = mems_ipc.service_name(args.service, args.namespace)
    payload = TYPES[args.service]
    service = mems_ipc.open_service(node, name, payload)
    subscriber = service.subscriber_builder().buffer_size(mems_ipc.SUBSCRIBER_BUFFER).create()
    event = mems_ipc.open_event(node, name)
    listener = event.listener_builder().create()
    print(
        f"subscribe.py: waiting for messages on {name} (namespace {args.namespace!r}; "
        "start mems-stack with the same namespace)",
        file=sys.stderr,
        flush=True,
    )
    waitset = iox2.WaitSetBuilder.new().create(iox2.ServiceType.Ipc)
    guard = waitset.attach_notification(listener)

    received = 0
    # The stream's alignment as last said on stderr (said again when it changes).
    was_aligned = True
    started = time.monotonic()
    # The longest sleep without a notification (only to check the timeout).
    tick = iox2.Duration.from_millis(100)
    while args.count == 0 or received < args.count:
        # Consume the notifications first: a message sent after this is notified again.
        listener.try_wait()
        while args.count == 0 or received < args.count:
            sample = subscriber.receive()
            if sample is None:
                break
            message = sample.payload().contents
            if aligned(message) != was_aligned:
                was_aligned = aligned(message)
                said = "aligned" if was_aligned else "not aligned yet (position held at zero)"
                print(f"seq {message.seq}: {said}", file=sys.stderr, flush=True)
            print(json.dumps(to_dict(message)), flush=True)
            received += 1
        if args.count and received >= args.count:
            break
        if received == 0 and time.monotonic() - started > args.timeout:
            print(f"no message on {name} within {args.timeout} s", file=sys.stderr)
            sys.exit(1)
        _, result = waitset.wait_and_process_with_timeout(tick)
        if result in (iox2.WaitSetRunResult.Interrupt, iox2.WaitSetRunResult.TerminationRequest):
            break
    # Release the ports before exit, or iceoryx2 leaves a segment in /dev/shm.
    del guard
    del waitset
    del listener
    del event
    del subscriber
    del service
    del node


if __name__ == "__main__":
    main()
