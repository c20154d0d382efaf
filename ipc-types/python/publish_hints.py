#!/usr/bin/env python3
"""A robot controller publishing rest and speed hints for mems-odometry with the iceoryx2
Python package (0.10): what the controller knows (zero velocity commanded, encoders at zero,
forward speed) as mems::RobotHint.v1 on mems/robot/hint, without ever blocking.

    python3 ipc-types/python/publish_hints.py [--namespace NS] [--duration S] [--speed M_PER_S]

Publishes at 50 Hz for --duration seconds (0: until Ctrl-C). With --speed 0 (the default) every
hint says the robot is stationary (commanded and encoders) with zero forward speed; otherwise
that it moves forward at --speed (body frame x forward, m/s, 1-sigma 0.02 m/s). Each hint's
stamps.sample_ns is the time it describes on the IMU samples' clock (CLOCK_MONOTONIC, which
time.monotonic_ns reads on Linux); stamps.acquired_ns is when it was published.
"""

import argparse
import os
import sys
import time

import iceoryx2 as iox2

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mems_ipc  # noqa: E402

PERIOD_MS = 20  # 50 Hz, a typical wheel-odometry rate


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--namespace", default=os.environ.get("MEMS_NAMESPACE", ""))
    parser.add_argument("--duration", type=float, default=10.0, help="seconds (0: never stop)")
    parser.add_argument("--speed", type=float, default=0.0, help="forward speed, m/s")
    args = parser.parse_args()

    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    name = mems_ipc.service_name(mems_ipc.SERVICE_HINT, args.namespace)
    service = mems_ipc.open_service(node, name, mems_ipc.RobotHint)
    # Never blocks (as ipc_types::service::hint_publisher): a hint the odometry cannot take is
    # dropped, and the odometry treats a missing hint as a stale one.
    publisher = (
        service.publisher_builder()
        .max_loaned_samples(4)
        .backpressure_strategy(iox2.BackpressureStrategy.DiscardData)
        .create()
    )
    if args.speed == 0.0:
        flags = (
            mems_ipc.HINT_STATIONARY
            | mems_ipc.HINT_SOURCE_COMMANDED
            | mems_ipc.HINT_SOURCE_ENCODERS
            | mems_ipc.HINT_SPEED_VALID
        )
    else:
        flags = mems_ipc.HINT_SPEED_VALID

    seq = 0
    started = time.monotonic()
    try:
        while args.duration == 0 or time.monotonic() - started < args.duration:
            node.wait(iox2.Duration.from_millis(PERIOD_MS))
            now = time.monotonic_ns()
            hint = mems_ipc.RobotHint(
                stamps=mems_ipc.Stamps(sample_ns=now, acquired_ns=time.monotonic_ns()),
                seq=seq,
                forward_speed_mps=args.speed,
                forward_speed_sigma_mps=0.02,
                flags=flags,
            )
            publisher.send_copy(hint)
            seq += 1
    except iox2.NodeWaitFailure:
        pass
    print(f"published {seq} hints on {name}", flush=True)
    # Release the ports before exit, or iceoryx2 leaves a segment in /dev/shm.
    del publisher
    del service
    del node


if __name__ == "__main__":
    main()
